"""Spatially-varying materials rendered by the real Blender Cycles under an environment map.

The Cycles counterpart of :func:`matremap.renderers.embedded.environment.render_svbrdf` (sphere geometry only) for
``cycles:glossy`` and ``cycles:diffuse``, rendered by the bpy worker of
:class:`~matremap.renderers.cycles.probe.CyclesRenderer` (request ``{"op": "svbrdf"}``; the arrays go
through ``.npy`` files in a temporary directory). Same camera, sphere, UVs, normal-map convention and
environment orientation as the embedded renderer, so the images compare pixel by pixel.

* **camera**: the probe scene's pinhole; ``filter_width = 0.01`` (one ray through each pixel
  centre, as the embedded renderer), CPU, ``spp`` samples of the lighting, fixed ``seed``.
* **sphere**: a smooth UV sphere mesh (``geometry`` ``"SxR"``, default 512x256 segments x rings) with
  its pole along +y and UVs set per loop to the embedded ones, ``u = 0.5 + atan2(x, z) / 2 pi``,
  ``v = acos(y / r) / pi`` (Blender's v is ``1 - v``; image rows are flipped on upload).
* **textures**: float images, colour space Non-Color (values used as they are), Linear
  interpolation, Extend (clamp) wrapping; scalar maps are read through their red channel.
* **normal maps**: tangent space in [-1, 1], x along u, y up the image, stored as ``(n + 1) / 2``
  under a Normal Map node (tangent space of the UV map: MikkTSpace from dP/du, dP/dv).
* **environment**: the world's Environment Texture (equirectangular, Linear) from the EnvMap array;
  Blender's lookup direction is ``e = (-z', -x', y')`` with ``d' = R_y(-rotation) d`` built from dot
  products in the world node tree, which puts Blender's u on matremap's u and Blender's up on +y.
  The background is transparent (black), lighting is direct only (``max_bounces = 0``).
"""

from __future__ import annotations

import shutil
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from matremap.core.envmap import EnvMap
from matremap.core.material import SVMaterial
from matremap.core.models import ModelSpec
from matremap.core.scene import Scene
from matremap.dialects import cycles as cycles_dialect
from matremap.dialects import get_model
from matremap.errors import MatremapError
from matremap.renderers.base import PARTS
from matremap.renderers.cycles.client import WorkerClient, scratch_folder, shared_client
from matremap.renderers.textured import check_normal_map, check_options, split_texture_params

#: the models Cycles draws
MODELS = tuple(spec.id for spec in cycles_dialect.MODELS)

#: default samples per pixel
DEFAULT_SPP = 64


@contextmanager
def _scratch() -> Iterator[str]:
    """A folder for the arrays a request hands the worker (:func:`scratch_folder`), removed afterwards."""
    folder = scratch_folder("svbrdf")
    try:
        yield str(folder)
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def _split_params(
    spec: ModelSpec, params: Mapping[str, Any], overrides: Mapping[str, Any]
) -> tuple[dict[str, list[float]], dict[str, np.ndarray]]:
    """Constants as lists (for the worker's JSON) and textures as float32 [h, w, 3] images."""

    consts, textures = split_texture_params(spec, params, overrides)
    images = {
        k: (t if t.ndim == 3 else np.repeat(t[..., None], 3, axis=2)).astype(np.float32) for k, t in textures.items()
    }
    return {k: [float(x) for x in v] for k, v in consts.items() if k not in textures}, images


def render_svbrdf_cycles(
    model: str,
    params: Mapping[str, Any],
    options: Mapping[str, str] | None,
    env: EnvMap,
    rotation_deg: float = 0.0,
    resolution: int = 256,
    part: str = "full",
    normal_map: np.ndarray | None = None,
    spp: int = DEFAULT_SPP,
    seed: int = 0,
    renderer: WorkerClient | None = None,
    geometry: str = "512x256",
) -> np.ndarray:
    """Render a textured ``cycles:glossy`` / ``cycles:diffuse`` material on the sphere under ``env``
    turned by ``rotation_deg`` with Blender Cycles.

    Arguments as :func:`matremap.renderers.embedded.environment.render_svbrdf` (sphere only); ``spp`` samples per
    pixel, ``seed`` Cycles' seed (same seed, same image); ``renderer`` the
    :class:`~matremap.renderers.cycles.probe.CyclesRenderer` whose worker renders (default: one shared by
    this module). Returns linear radiance float32 [res, res, 3], black off the sphere.
    """

    spec = get_model(model)
    if spec.id not in MODELS:
        raise MatremapError(f"Cycles SVBRDF renders take {', '.join(MODELS)}, got {spec.id}")
    if part not in PARTS:
        raise MatremapError(f"unknown render part {part!r}; use one of {', '.join(PARTS)}")
    if not isinstance(env, EnvMap):
        raise MatremapError(f"env must be an EnvMap, got {type(env).__name__}")
    if not (isinstance(spp, (int, np.integer)) and spp >= 1):
        raise MatremapError(f"spp must be a positive integer, got {spp!r}")
    opts = check_options(spec, params, options or {})
    res = int(resolution)
    overrides = spec.part_overrides(part, params)
    if overrides is None:
        return np.zeros((res, res, 3), dtype=np.float32)
    consts, textures = _split_params(spec, params, overrides)

    nm = None if normal_map is None else check_normal_map(normal_map)
    scene = Scene(resolution=res)
    r = shared_client(renderer)
    with _scratch() as d:
        names = {}
        for i, (name, tex) in enumerate(textures.items()):
            names[name] = str(i)
            np.save(Path(d) / f"tex_{i}.npy", tex)
        if nm is not None:
            np.save(Path(d) / "normal_map.npy", ((nm + 1.0) / 2.0).astype(np.float32))
        np.save(Path(d) / "env.npy", np.asarray(env.radiance, dtype=np.float32))
        request = {
            "op": "svbrdf",
            "dir": d,
            "scene": {
                "resolution": res,
                "fov": float(scene.effective_fov),
                "camera_distance": float(scene.camera_distance),
                "sphere_radius": float(scene.sphere_radius),
            },
            "geometry": geometry,
            "model": spec.id,
            "options": dict(opts),
            "consts": consts,
            "textures": names,
            "normal_map": nm is not None,
            "rotation_deg": float(rotation_deg),
            "spp": int(spp),
            "seed": int(seed),
        }
        images = r.request(request)
    if images.shape != (1, res, res, 3):
        raise MatremapError(f"the Cycles worker returned an image of shape {images.shape}")
    return images[0].astype(np.float32, copy=False)


__all__ = ["DEFAULT_SPP", "MODELS", "render_svbrdf_cycles"]


class CyclesEnvironmentRender:
    """Cycles' :class:`~matremap.renderers.base.EnvironmentRender`: a ``cycles:*`` material drawn by real
    Blender Cycles through the bpy worker (:func:`render_svbrdf_cycles`, 64 spp, seed 0) under the
    environment map itself. The parameters and normal map are checked here, before anything renders."""

    label = f"Blender Cycles (bpy worker, {DEFAULT_SPP} spp)"

    def __init__(
        self, material: SVMaterial, env: EnvMap, resolution: int, part: str, renderer: WorkerClient | None = None
    ) -> None:
        self.renderer = renderer
        options = check_options(get_model(material.model), material.params, material.options)
        self.material = SVMaterial(material.model, material.params, options, material.normal)
        self.normal = None if material.normal is None else check_normal_map(material.normal)
        self.env, self.resolution, self.part = env, resolution, part

    def render(self, rotation_deg: float) -> np.ndarray:
        m = self.material
        return render_svbrdf_cycles(
            m.model,
            m.params,
            m.options,
            self.env,
            rotation_deg=rotation_deg,
            resolution=self.resolution,
            part=self.part,
            normal_map=self.normal,
            renderer=self.renderer,
        )
