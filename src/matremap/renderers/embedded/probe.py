"""The embedded renderer: pure numpy, deterministic bit for bit, no external program.

It shades each sphere pixel (one ray through the pixel centre, so no sampling noise) with the
point lights of the scene: radiance = sum over lights of I / d^2 * [f cos(theta_i)], where the
bracket is the dialect's evaluator (see :mod:`.dialects`). A batch of materials is evaluated in one
vectorised pass per (model, options) group, which makes a finite-difference Jacobian one call.

A view of an environment probe (:class:`~matremap.core.scene.EnvironmentProbe`) is shaded the same way by
the map's directional lights: radiance = sum over lights of E_rgb [f cos(theta_i)], E_rgb the light's RGB
intensity, the sum taken over chunks of lights so that the evaluators' temporaries stay bounded -- the
same estimator as the environment face's renders (:mod:`.environment`), on the probe's camera.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from matremap.core.heap import keep_heap
from matremap.core.material import Material, SVMaterial
from matremap.core.scene import Scene
from matremap.errors import MatremapError
from matremap.renderers.base import EnvironmentLight, EnvironmentRender, check_can_render, check_environment_args
from matremap.renderers.embedded.geometry import LocalGeometry


@dataclass(frozen=True, eq=False)
class SceneGeometry:
    """Shading inputs for the sphere pixels of a scene, per light: arrays [L, P]; the irradiance is
    [1, L, P] (point lights: white) or [3, L, P] (an environment's lights: RGB)."""

    local: LocalGeometry
    irradiance: np.ndarray  # I / d^2 (or the light's RGB intensity) where the light is above the surface, else 0
    lit: np.ndarray

    def chunks(self, size: int) -> list[SceneGeometry]:
        """The geometry split into runs of at most ``size`` lights (itself when it has no more)."""
        count = self.lit.shape[0]
        if count <= size:
            return [self]
        out = []
        for a in range(0, count, size):
            sl = slice(a, a + size)
            g = self.local
            frame = None if g.frame is None else tuple(f[sl] for f in g.frame)
            local = LocalGeometry(g.cos_i[sl], g.cos_o[sl], g.i_dot_o[sl], frame)  # type: ignore[arg-type]
            out.append(SceneGeometry(local, self.irradiance[:, sl], self.lit[sl]))
        return out


def _light_rows(scene: Scene, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit directions to each light [L, P, 3] and its irradiance [C, L, P] at the points ``p``."""
    if scene.environment is not None:  # a view of an environment probe: one rotation, directional lights
        (rotation,) = scene.environment.rotations
        d, i = scene.environment.directional(rotation)
        wi = np.broadcast_to(d[:, None, :], (len(d), len(p), 3))
        return wi, np.broadcast_to(i.T[:, :, None], (3, len(d), len(p)))
    wis, irr = [], []
    for light in scene.lights:
        to_light = scene.light_position(light) - p
        d2 = np.sum(to_light * to_light, axis=-1)
        wis.append(to_light / np.sqrt(d2)[:, None])
        irr.append(scene.light_intensity(light) / d2)
    return np.stack(wis), np.stack(irr)[None]


@lru_cache(maxsize=16)
def scene_geometry(scene: Scene) -> SceneGeometry:
    if scene.view_count != 1:
        raise MatremapError("the embedded renderer draws one view of a scene at a time (Scene.views)")
    p = scene.sphere_points()
    n = p / np.linalg.norm(p, axis=-1, keepdims=True)
    cam = np.array([0.0, 0.0, scene.camera_distance])
    wo = cam - p
    wo /= np.linalg.norm(wo, axis=-1, keepdims=True)
    s, t = sphere_frame(p, n)
    wi, irr = _light_rows(scene, p)
    cos_i, i_dot_o, i_s, i_t = (np.sum(wi * v, axis=-1) for v in (n, wo, s, t))
    cos_o = np.broadcast_to(np.sum(n * wo, axis=-1), cos_i.shape)
    o_s, o_t = (np.broadcast_to(np.sum(wo * v, axis=-1), cos_i.shape) for v in (s, t))
    lit = (cos_i > 0.0) & (cos_o > 0.0)
    # keep every formula finite where the point is unlit (light and view along the normal); the result is
    # masked there anyway
    cos_i, cos_o, i_dot_o = (np.where(lit, a, 1.0) for a in (cos_i, cos_o, i_dot_o))
    frame = tuple(np.where(lit, a, 0.0) for a in (i_s, i_t, o_s, o_t))
    for a in (cos_i, cos_o, i_dot_o, lit, *frame):
        a.flags.writeable = False
    local = LocalGeometry(cos_i, cos_o, i_dot_o, frame)  # type: ignore[arg-type]
    irradiance = np.where(lit[None], irr, 0.0)
    irradiance.flags.writeable = False
    return SceneGeometry(local, irradiance, lit)


#: elements of a [materials, lights, pixels] block shaded at once: bounds the evaluators' temporaries for
#: environment views (64 lights); the point-light probe's one to three lights always fit in one block
CHUNK_ELEMENTS = 1 << 21


def sphere_frame(p: np.ndarray, n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The shading frame's tangent s and bitangent t = n x s at points ``p`` [P, 3] of the probe sphere
    (centred at the origin, pole +z towards the camera), as Mitsuba 3's ``sphere`` gives them: s along
    dp/du = (-y, x, 0) (src/shapes/sphere.cpp; any direction at the pole itself)."""
    s = np.stack([-p[:, 1], p[:, 0], np.zeros(len(p))], axis=-1)
    norm = np.linalg.norm(s, axis=-1, keepdims=True)
    s = np.where(norm > 1e-12, s / np.maximum(norm, 1e-300), np.array([1.0, 0.0, 0.0]))
    return s, np.cross(n, s)


def batch_params(materials: list[Material]) -> dict[str, np.ndarray]:
    """The parameters of a batch of one model as [N, C, 1, 1] arrays, or [N, 1, 1, 1] when every value of every
    material is grey (grey parameters shade the same in every channel: one is computed and broadcast). The test
    is on Python floats: numpy's per-parameter comparisons cost more than the small renders they save."""
    names = list(materials[0].values)
    rows = [[m.values[name] for m in materials] for name in names]
    if all(len(set(v.tolist())) == 1 for row in rows for v in row):
        return {
            name: np.array([v[0] for v in row], dtype=float).reshape(-1, 1, 1, 1)
            for name, row in zip(names, rows, strict=True)
        }
    return {name: np.array(row, dtype=float)[:, :, None, None] for name, row in zip(names, rows, strict=True)}


def place(out: np.ndarray, idx: list[int], radiance: np.ndarray) -> None:
    """Write radiance [n, C, P] into the rows ``idx`` of pixels ``out`` [N, P, 3] (float32), channel by channel:
    numpy's transposed copy into the interleaved channels costs four times as much."""
    rows = slice(None) if len(idx) == len(out) else idx
    target = out[rows] if isinstance(rows, list) else out
    for c in range(3):
        target[:, :, c] = radiance[:, min(c, radiance.shape[1] - 1)]
    if isinstance(rows, list):
        out[rows] = target


class EmbeddedRenderer:
    """Numpy renderer emulating renderer dialects (``mitsuba06:*``, ``blender27:*``, ``cycles:*``)."""

    name = "embedded"
    #: draws the probe under an environment (:class:`~matremap.core.scene.EnvironmentProbe`) as well
    environment_probe = True
    #: draws the transmission view (:class:`~matremap.core.scene.TransmissionProbe`)
    transmission_probe = True
    #: materials per call a caller should batch (:func:`matremap.core.lockstep.lockstep`): larger batches'
    #: [N, C, L, P] intermediates fall out of the CPU caches (8 measured best at 128^2, 16-64 ~10 % slower)
    batch_size = 8

    def __init__(self) -> None:
        # a fit allocates probe-sized arrays thousands of times: keep them off fresh pages (core/heap.py)
        keep_heap()

    def can_render(self, model_id: str) -> bool:
        from matremap.renderers.embedded.evaluators import EVALUATORS

        return model_id in EVALUATORS

    def environment_support(self, model_id: str, geometry: str) -> str | None:
        """The embedded renderer draws every model it emulates, on every evaluation geometry."""
        return None if self.can_render(model_id) else f"model {model_id} has no embedded evaluator"

    def supports_textures(self, model_id: str, param: str) -> bool:
        return True

    def prepare_environment(
        self, material: SVMaterial, light: EnvironmentLight, geometry: str, resolution: int, part: str
    ) -> EnvironmentRender:
        from matremap.renderers.embedded.environment import EmbeddedEnvironmentRender, SVBRDFRender

        check_environment_args(geometry, resolution, part)
        prepared = SVBRDFRender(
            material.model, material.params, material.options, geometry, resolution, part, material.normal
        )
        return EmbeddedEnvironmentRender(prepared, light)

    def render(self, materials: Sequence[Material], scene: Scene) -> np.ndarray:
        materials = list(materials)
        if scene.transmission is not None:  # the transmission view (renderers/embedded/transmission.py)
            from matremap.renderers.embedded.transmission import render_view

            check_can_render(self, materials)
            return render_view(materials, scene)
        res = scene.resolution
        out = np.zeros((len(materials), res * res, 3), dtype=np.float32)
        pix = scene.pixel_indices()
        for idx, radiance in self._shade(materials, scene):  # radiance [n, C, P]
            target = out if len(idx) == len(materials) else out[idx]
            for c in range(3):
                target[:, pix, c] = radiance[:, min(c, radiance.shape[1] - 1)]
            if target is not out:
                out[idx] = target
        return out.reshape(len(materials), res, res, 3)

    def render_pixels(self, materials: Sequence[Material], scene: Scene) -> np.ndarray:
        """The sphere pixels of :meth:`render`, float32 [N, P, 3] in ``scene.pixel_indices()``
        order, without the image around them (the fitter's fast path)."""
        materials = list(materials)
        if scene.transmission is not None:
            images = self.render(materials, scene)
            return np.take(images.reshape(len(materials), -1, 3), scene.pixel_indices(), axis=1)
        out = np.zeros((len(materials), scene.pixel_indices().size, 3), dtype=np.float32)
        for idx, radiance in self._shade(materials, scene):
            place(out, idx, radiance)
        return out

    def _shade(self, materials: list[Material], scene: Scene):
        """Yield (material indices, radiance [n, C, P]) per group of materials sharing a model and
        options. Evaluators work on [N, C, L, P] arrays (channels before pixels, so that numpy's
        inner loops run over pixels): parameters come as [N, C, 1, 1], geometry as [L, P]."""
        from matremap.renderers.embedded.evaluators import EVALUATORS

        check_can_render(self, materials)
        geo = scene_geometry(scene)
        groups: dict[tuple, list[int]] = {}
        for i, m in enumerate(materials):
            groups.setdefault((m.model, tuple(sorted(m.options.items()))), []).append(i)
        for (model, options), idx in groups.items():
            params = batch_params([materials[i] for i in idx])
            radiance = None
            # runs of lights sized for a full batch whatever this one's size, so that a material's pixels
            # are summed in the same order alone or in a batch (bit for bit)
            lights = max(1, CHUNK_ELEMENTS // (self.batch_size * geo.lit.shape[1]))
            for chunk in geo.chunks(lights):
                fcos = EVALUATORS[model](params, dict(options), chunk.local)
                # unlit points have finite stand-in geometry and zero irradiance; one light (the point probes):
                # its term is the sum (numpy's sum over an axis of one copies it, at eight times the cost)
                weighted = fcos * chunk.irradiance
                part = weighted[:, :, 0] if weighted.shape[2] == 1 else weighted.sum(axis=2)
                radiance = part if radiance is None else radiance + part
            assert radiance is not None
            yield idx, radiance
