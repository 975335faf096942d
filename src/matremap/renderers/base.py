"""The renderer protocol, and the registry of renderer backends.

A renderer turns a batch of materials and a :class:`~matremap.core.scene.Scene` into linear HDR RGB
images, float32 ``[N, H, W, 3]``. The fitter only ever calls :meth:`Renderer.render`: a renderer
is a black box, and a new one is a module implementing this protocol.
"""

from __future__ import annotations

import difflib
from collections.abc import Callable, Sequence
from typing import Protocol, runtime_checkable

import numpy as np

from matremap.core.models import Material
from matremap.core.scene import Scene
from matremap.errors import MatremapError


@runtime_checkable
class Renderer(Protocol):
    #: registry name, e.g. "embedded", "mitsuba3"
    name: str

    def supports(self, model_id: str) -> bool:
        """Whether this renderer can draw materials of the model."""
        ...

    def render(self, materials: Sequence[Material], scene: Scene) -> np.ndarray:
        """Render each material on the scene's sphere: float32 [N, H, W, 3], linear radiance."""
        ...


def render_pixels(renderer: Renderer, materials: Sequence[Material], scene: Scene) -> np.ndarray:
    """The sphere pixels of a render, float32 [N, P, 3] in ``scene.pixel_indices()`` order.

    A renderer may offer this directly (method ``render_pixels``) to skip building whole images;
    it must return exactly ``render(...)`` at the sphere pixels.
    """
    fast = getattr(renderer, "render_pixels", None)
    if fast is not None:
        return fast(materials, scene)
    images = renderer.render(materials, scene)
    return np.take(images.reshape(len(materials), -1, 3), scene.pixel_indices(), axis=1)


_FACTORIES: dict[str, Callable[[], Renderer]] = {}
_INSTANCES: dict[str, Renderer] = {}


def register_renderer(name: str, factory: Callable[[], Renderer]) -> None:
    _FACTORIES[name] = factory


def renderer_names() -> list[str]:
    _load_builtin()
    return sorted(_FACTORIES)


def get_renderer(name: str | Renderer | None = None) -> Renderer:
    """A renderer by name (default: the embedded one); renderer objects pass through."""
    if name is None:
        name = "embedded"
    if not isinstance(name, str):
        return name
    _load_builtin()
    if name not in _FACTORIES:
        near = difflib.get_close_matches(name, list(_FACTORIES), n=2)
        hint = f"; did you mean {' or '.join(near)}?" if near else f"; known renderers: {', '.join(sorted(_FACTORIES))}"
        raise MatremapError(f"unknown renderer {name!r}{hint}")
    if name not in _INSTANCES:
        _INSTANCES[name] = _FACTORIES[name]()
    return _INSTANCES[name]


def check_supported(renderer: Renderer, materials: Sequence[Material]) -> None:
    for m in materials:
        if not renderer.supports(m.model):
            raise MatremapError(f"renderer {renderer.name!r} cannot render model {m.model}")


def _load_builtin() -> None:
    if "embedded" not in _FACTORIES:
        from matremap.renderers.embedded import EmbeddedRenderer

        register_renderer("embedded", EmbeddedRenderer)
    if "mitsuba3" not in _FACTORIES:
        from matremap.renderers.mitsuba3.probe import Mitsuba3Renderer  # imports Mitsuba itself only when first used

        register_renderer("mitsuba3", Mitsuba3Renderer)
    if "cycles" not in _FACTORIES:
        from matremap.renderers.cycles.probe import CyclesRenderer  # bpy runs in a worker process of its own venv

        register_renderer("cycles", CyclesRenderer)


def renderer_for(model_id: str) -> str:
    """The renderer that draws a model by default: the embedded one when it emulates the model,
    else the real renderer of the model's family (``mitsuba3:*`` -> mitsuba3)."""
    embedded = get_renderer("embedded")
    if embedded.supports(model_id):
        return "embedded"
    family = model_id.split(":", 1)[0]
    _load_builtin()
    if family in _FACTORIES:
        return family
    raise MatremapError(f"no renderer draws model {model_id}")
