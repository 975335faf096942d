"""The renderer protocol: one interface with two faces.

* **Probe face** -- :meth:`Renderer.render` turns a batch of uniform materials and a
  :class:`~matremap.core.scene.Scene` (the sphere under point lights) into linear HDR RGB images,
  float32 ``[N, H, W, 3]``. The fitter only ever calls this face: a renderer is a black box.
* **Environment face** -- :meth:`Renderer.prepare_environment` takes a textured material
  (:class:`~matremap.core.material.SVMaterial`), an :class:`EnvironmentLight`, the evaluation geometry,
  resolution and part, and returns an :class:`EnvironmentRender` that draws it at any rotation of the
  environment. Evaluation only ever calls this face.

Capabilities are queries, never family names: :meth:`Renderer.can_render` (probe),
:meth:`Renderer.environment_support` (``None`` when it can draw the material under an environment, else
the reason) and :meth:`Renderer.supports_textures` (whether a parameter may be a texture map).
A new renderer is one subpackage implementing this protocol, registered in
:mod:`matremap.renderers.registry`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np

from matremap.core.envmap import EnvMap, directional_lights
from matremap.errors import MatremapError

if TYPE_CHECKING:
    from matremap.core.material import Material, SVMaterial
    from matremap.core.scene import Scene

#: the parts of a material a render can draw
PARTS = ("full", "specular", "diffuse")
#: samples per pixel about the mirror direction in the embedded renderer's environment renders
#: (:mod:`~matremap.renderers.embedded.mirror_samples`; 0: the directional lights alone)
MIRROR_SAMPLES = 64
#: the evaluation geometries
GEOMETRIES = ("sphere", "plane")


@dataclass(frozen=True, eq=False)
class EnvironmentLight:
    """An environment map as a light source. Renderers that trace the map itself (Mitsuba 3, Cycles)
    use ``env``; the embedded renderer samples it into ``lights`` directional lights (importance
    sampled with ``seed``, see :func:`~matremap.core.envmap.directional_lights`), the same set for every
    material at a given rotation, and ``mirror_samples`` directions about each pixel's mirror direction
    (:mod:`~matremap.renderers.embedded.mirror_samples`; 0: the lights alone)."""

    env: EnvMap
    lights: int = 256
    seed: int = 0
    mirror_samples: int = MIRROR_SAMPLES
    _cache: dict[float, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict, repr=False)

    def directional(self, rotation_deg: float) -> tuple[np.ndarray, np.ndarray]:
        """Unit directions towards the lights [L, 3] and their RGB intensities [L, 3] with the
        environment turned by ``rotation_deg`` about +y."""
        key = float(rotation_deg)
        if key not in self._cache:
            self._cache[key] = directional_lights(self.env, self.lights, key, self.seed)
        return self._cache[key]


@runtime_checkable
class EnvironmentRender(Protocol):
    """A textured material prepared for one renderer, geometry, resolution and part."""

    #: who draws it, for reports ("embedded emulation", "Mitsuba 3", ...)
    label: str

    def render(self, rotation_deg: float) -> np.ndarray:
        """Linear radiance float32 [res, res, 3] with the environment turned by ``rotation_deg``,
        black off the object."""
        ...


@runtime_checkable
class Renderer(Protocol):
    #: registry name, e.g. "embedded", "mitsuba3"
    name: str

    def can_render(self, model_id: str) -> bool:
        """Whether this renderer draws materials of the model (probe face)."""
        ...

    def render(self, materials: Sequence[Material], scene: Scene) -> np.ndarray:
        """Render each material on the scene's sphere: float32 [N, H, W, 3], linear radiance."""
        ...

    def environment_support(self, model_id: str, geometry: str) -> str | None:
        """None when this renderer draws the model on ``geometry`` under an environment (and is
        installed); else the reason, one line a user can act on."""
        ...

    def supports_textures(self, model_id: str, param: str) -> bool:
        """Whether the parameter may be a texture map in this renderer's environment renders."""
        ...

    def prepare_environment(
        self, material: SVMaterial, light: EnvironmentLight, geometry: str, resolution: int, part: str
    ) -> EnvironmentRender:
        """Validate ``material`` (raising before anything renders) and prepare it for environment
        renders; see :class:`EnvironmentRender`."""
        ...


def check_can_render(renderer: Renderer, materials: Sequence[Material]) -> None:
    """Raise, naming the renderer and the model, when the renderer cannot draw one of the materials."""
    for m in materials:
        if not renderer.can_render(m.model):
            raise MatremapError(f"renderer {renderer.name!r} cannot render model {m.model}")


def check_environment_args(geometry: str, resolution: int, part: str) -> None:
    """Validate the arguments every environment render takes."""
    if geometry not in GEOMETRIES:
        raise MatremapError(f"unknown geometry {geometry!r}; use one of {', '.join(GEOMETRIES)}")
    if part not in PARTS:
        raise MatremapError(f"unknown render part {part!r}; use one of {', '.join(PARTS)}")
    if not isinstance(resolution, int) or not 16 <= resolution <= 4096:
        raise MatremapError(f"the resolution must be an integer in [16, 4096], got {resolution!r}")


def check_environment(renderer: Renderer, material: SVMaterial, geometry: str, resolution: int, part: str) -> None:
    """Raise, before anything renders, when the arguments are invalid or ``renderer`` cannot draw the
    material on ``geometry`` (:meth:`Renderer.environment_support` gives the reason)."""
    check_environment_args(geometry, resolution, part)
    why = renderer.environment_support(material.model, geometry)
    if why is not None:
        raise MatremapError(why)


def render_pixels(renderer: Renderer, materials: Sequence[Material], scene: Scene) -> np.ndarray:
    """The sphere pixels of a render, float32 [N, P, 3] in ``scene.pixel_indices()`` order.

    A renderer may offer this directly (method ``render_pixels``) to skip building whole images;
    it must return exactly ``render(...)`` at the sphere pixels. A scene of several views (an environment
    probe, :meth:`~matremap.core.scene.Scene.views`) is drawn view by view, each view's pixels multiplied
    by its weight (:meth:`~matremap.core.scene.Scene.view_weights`): renderers only ever see one view.
    """
    check_probe(renderer, scene)
    views = scene.views()
    if len(views) > 1:
        parts = [w * render_pixels(renderer, materials, v) for v, w in zip(views, scene.view_weights(), strict=True)]
        return np.concatenate(parts, axis=1).astype(np.float32, copy=False)
    fast = getattr(renderer, "render_pixels", None)
    if fast is not None:
        return fast(materials, scene)
    images = renderer.render(materials, scene)
    return np.take(images.reshape(len(materials), -1, 3), scene.pixel_indices(), axis=1)


def render_images(renderer: Renderer, materials: Sequence[Material], scene: Scene) -> np.ndarray:
    """Whole probe images, float32 [N, H, V W, 3]: the views side by side, each multiplied by its weight
    (as :func:`render_pixels` draws them; a one-view scene is ``renderer.render``)."""
    check_probe(renderer, scene)
    views = scene.views()
    if len(views) == 1:
        return renderer.render(materials, scene)
    parts = [w * renderer.render(materials, v) for v, w in zip(views, scene.view_weights(), strict=True)]
    return np.concatenate(parts, axis=2).astype(np.float32, copy=False)


def probe_support(renderer: Renderer, scene: Scene) -> str | None:
    """None when ``renderer`` draws ``scene``'s probe; else the reason. A renderer that draws environment
    probes says so with ``environment_probe = True``, the transmission view with ``transmission_probe = True``;
    every renderer draws the point-light probe."""
    if scene.transmission is not None and not getattr(renderer, "transmission_probe", False):
        return (
            f"the {renderer.name} renderer does not draw the transmission probe (what a transmissive material lets "
            "through); fit with the embedded renderer"
        )
    if scene.environment is None or getattr(renderer, "environment_probe", False):
        return None
    return (
        f"the {renderer.name} renderer draws the point-light probe only, not the {scene.kind} probe; "
        "use --probe point, or fit with the embedded renderer"
    )


def check_probe(renderer: Renderer, scene: Scene) -> None:
    """Raise :func:`probe_support`'s reason when ``renderer`` cannot draw ``scene``."""
    why = probe_support(renderer, scene)
    if why is not None:
        raise MatremapError(why)


__all__ = [
    "GEOMETRIES",
    "PARTS",
    "EnvironmentLight",
    "EnvironmentRender",
    "Renderer",
    "check_can_render",
    "check_environment",
    "check_environment_args",
    "check_probe",
    "probe_support",
    "render_images",
    "render_pixels",
]
