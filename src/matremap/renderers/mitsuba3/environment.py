"""Spatially-varying materials rendered by the real Mitsuba 3 under an environment map.

The Mitsuba 3 counterpart of :func:`matremap.renderers.embedded.environment.render_svbrdf` (sphere geometry only),
for the ``mitsuba3:*`` models: the same camera, sphere, UV layout, normal-map convention and
environment orientation, so that the two renderers' images can be compared pixel by pixel.

* **camera**: the probe scene's pinhole (see :mod:`matremap.core.scene`), a ``box`` filter and a
  ``multijitter`` sampler: pixels are anti-aliased averages over the pixel (the embedded renderer
  shoots one ray through each pixel centre, so the two differ on the silhouette).
* **sphere**: Mitsuba's ``sphere`` shape (radius 2 at the origin), turned by its ``to_world`` so that
  Mitsuba's own UVs equal the embedded ones: ``u = 0.5 + atan2(x, z) / 2 pi``, ``v = acos(y / r) / pi``
  (the texture's centre column faces the camera, row 0 at the north pole). Mitsuba's local frame
  (pole along local +z, ``u = atan2(y, x) / 2 pi``) is mapped by x -> -z, y -> -x, z -> +y.
* **textures**: ``bitmap`` textures built from the numpy maps (``mi.TensorXf``; ``raw``: values are
  used as they are, no sRGB decoding; ``bilinear`` filtering at texel centres; ``clamp`` wrapping,
  which differs from the embedded renderer's wrap in u only on the seam at the back of the sphere).
* **normal maps**: tangent space in [-1, 1], x along u, y up the image (as the embedded renderer),
  stored as ``(n + 1) / 2`` in a raw bitmap under Mitsuba's ``normalmap`` BSDF (which decodes 2x - 1
  and builds its frame from ``dp/du``: the same frame as the embedded renderer's).
* **environment**: an ``envmap`` emitter from the :class:`~matremap.core.envmap.EnvMap`'s lat-long array.
  Mitsuba's envmap puts column 0 at -z and +x at u = 1/4 (matremap: column 0 at +z, -x at u = 1/4):
  a 180 degree turn about +y in the emitter's ``to_world`` maps one onto the other exactly (the
  columns' texel centres agree). Mitsuba interpolates rows as *vertices* (row i at
  ``theta = pi i / (H - 1)``) where matremap's rows are texel centres (``theta = pi (i + 0.5) / H``):
  the map is resampled to ``2H + 1`` vertex rows, which reproduces the linear interpolation
  between matremap's row centres exactly. ``rotation_deg`` turns the map about +y as
  :func:`~matremap.core.envmap.directional_lights` does.
* **integrator**: ``path`` with ``max_depth = 2`` (direct lighting only, with multiple importance
  sampling of the map and the BSDF), emitters hidden: the background is black, as in the embedded
  renderer. A fixed ``seed`` makes renders deterministic.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from typing import Any

import numpy as np

from matremap.core.envmap import EnvMap
from matremap.core.material import Material, SVMaterial
from matremap.core.models import ModelSpec, ParamSpec
from matremap.core.scene import Scene
from matremap.dialects import get_model
from matremap.errors import MatremapError
from matremap.renderers.base import PARTS
from matremap.renderers.mitsuba3.plugins import (
    MODELS,
    bsdf_dict,
    choose_variant,
    import_mitsuba,
    mitsuba_call,
    probe_sensor,
)
from matremap.renderers.textured import check_normal_map, check_options, split_texture_params

#: parameters that Mitsuba 3 takes as plain floats, not textures
NOT_TEXTURABLE = {
    "mitsuba3:roughplastic": ("alpha", "int_ior", "ext_ior"),
    "mitsuba3:principled": ("specular",),
    **{
        g: ("int_ior", "ext_ior")
        for g in ("mitsuba3:dielectric", "mitsuba3:roughdielectric", "mitsuba3:thindielectric")
    },
}

#: default samples per pixel: 1.0-1.3 % relative RMS noise (diffuse; GGX conductor alpha 0.1; builtin map, 128^2)
DEFAULT_SPP = 256


def _sphere_to_world(mi, radius: float):
    """Mitsuba's local sphere frame -> world, so that Mitsuba's UVs equal the embedded ones."""
    m = np.zeros((4, 4))
    m[:3, 0] = (0.0, 0.0, -1.0)  # local x -> -z
    m[:3, 1] = (-1.0, 0.0, 0.0)  # local y -> -x
    m[:3, 2] = (0.0, 1.0, 0.0)  # local z (the pole, v = 0) -> +y
    m[:3, :3] *= radius
    m[3, 3] = 1.0
    return mi.ScalarTransform4f(m.tolist())


def envmap_vertex_rows(env: EnvMap) -> np.ndarray:
    """The map resampled to ``2H + 1`` rows at ``theta = pi r / (2H)`` (Mitsuba's vertex rows),
    linearly interpolated between matremap's row centres (clamped at the poles)."""
    h = env.height
    x = np.arange(2 * h + 1) / 2.0 - 0.5  # continuous row index of each vertex row
    x0 = np.clip(np.floor(x).astype(int), 0, h - 1)
    x1 = np.clip(x0 + 1, 0, h - 1)
    f = np.clip(x - np.floor(x), 0.0, 1.0)[:, None, None]
    f = np.where((x < 0)[:, None, None], 0.0, f)
    rad = env.radiance.astype(np.float64)
    out = rad[x0] * (1.0 - f) + rad[x1] * f
    return np.ascontiguousarray(out, dtype=np.float32)


def _bitmap(mi, arr: np.ndarray) -> dict[str, Any]:
    data = np.ascontiguousarray(arr, dtype=np.float32)
    if data.ndim == 2:
        data = data[..., None]
    return {"type": "bitmap", "data": mi.TensorXf(data), "raw": True, "filter_type": "bilinear", "wrap_mode": "clamp"}


def _split_params(
    spec: ModelSpec, params: Mapping[str, Any], overrides: Mapping[str, Any], options: Mapping[str, str]
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """(constant values [channels], textures [h, w] or [h, w, 3]) of every model parameter, with
    Mitsuba 3's own limits on what may be a texture."""

    def check(p: ParamSpec, a: np.ndarray) -> None:
        if p.name in NOT_TEXTURABLE.get(spec.id, ()):
            raise MatremapError(f"{spec.id}: Mitsuba 3 takes {p.name} as a constant, not a texture")
        if p.name in ("eta", "k") and options.get("material", "custom") != "custom":
            raise MatremapError(f"{spec.id}: a texture for {p.name} needs material=custom")

    return split_texture_params(spec, params, overrides, check)


def scene_dict(
    mi,
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
) -> dict[str, Any] | None:
    """The ``mi.load_dict`` dictionary of the scene, or None when the part is black."""

    spec = get_model(model)
    if spec.id not in MODELS:
        raise MatremapError(f"Mitsuba 3 SVBRDF renders take mitsuba3:* models ({', '.join(MODELS)}), got {spec.id}")
    if part not in PARTS:
        raise MatremapError(f"unknown render part {part!r}; use one of {', '.join(PARTS)}")
    if not isinstance(env, EnvMap):
        raise MatremapError(f"env must be an EnvMap, got {type(env).__name__}")
    if not (isinstance(spp, (int, np.integer)) and spp >= 1):
        raise MatremapError(f"spp must be a positive integer, got {spp!r}")
    opts = check_options(spec, params, options or {})
    overrides = spec.part_overrides(part, params)
    if overrides is None:
        return None
    consts, textures = _split_params(spec, params, overrides, opts)
    bsdf, _ = bsdf_dict(spec.id, opts, Material(spec.id, consts, opts))
    for name, tex in textures.items():
        bsdf[name] = _bitmap(mi, tex)
    if normal_map is not None:
        nm = check_normal_map(normal_map)
        bsdf = {"type": "normalmap", "normalmap": _bitmap(mi, (nm + 1.0) / 2.0), "bsdf": bsdf}

    scene = Scene(resolution=int(resolution))
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 2, "hide_emitters": True},
        "sensor": probe_sensor(mi, scene, {"type": "multijitter", "sample_count": int(spp), "seed": int(seed)}),
        "sphere": {"type": "sphere", "to_world": _sphere_to_world(mi, float(scene.sphere_radius)), "bsdf": bsdf},
        "env": {
            "type": "envmap",
            "bitmap": mi.Bitmap(envmap_vertex_rows(env)),
            # 180 degrees: Mitsuba's column 0 looks down -z, matremap's down +z (see the module doc)
            "to_world": mi.ScalarTransform4f().rotate([0.0, 1.0, 0.0], 180.0 + math.fmod(float(rotation_deg), 360.0)),
        },
    }


def render_svbrdf_mitsuba3(
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
    variant: str | None = None,
) -> np.ndarray:
    """Render a textured ``mitsuba3:*`` material on the sphere under ``env`` turned by ``rotation_deg``.

    Arguments as :func:`matremap.renderers.embedded.environment.render_svbrdf` (sphere only); ``params`` maps the
    model's parameter names to constants or textures ``[h, w]`` / ``[h, w, 3]`` (row 0 at the top,
    in the model's units). ``spp`` samples per pixel, ``seed`` the sampler's seed (same seed, same
    image), ``variant`` as :class:`~matremap.renderers.mitsuba3.probe.Mitsuba3Renderer` (default
    ``$MATREMAP_MITSUBA_VARIANT``, else ``auto``: ``llvm_ad_rgb`` when usable, 0.7 s instead of 5 s
    for 160² at 256 spp, else ``scalar_rgb``).
    Note that Mitsuba's variant is process-wide. Returns linear radiance float32 [res, res, 3],
    black off the sphere.
    """
    mi = import_mitsuba()
    # many samples per pixel: the LLVM variant is ~8x faster here than scalar_rgb when it works
    v = choose_variant(mi, variant or os.environ.get("MATREMAP_MITSUBA_VARIANT") or "auto")
    if mi.variant() != v:
        mi.set_variant(v)
    d = scene_dict(mi, model, params, options, env, rotation_deg, resolution, part, normal_map, spp, seed)
    res = int(resolution)
    if d is None:
        return np.zeros((res, res, 3), dtype=np.float32)
    scene = mitsuba_call(mi, "load the SVBRDF scene", mi.load_dict, d)
    img = mitsuba_call(mi, "render", mi.render, scene, spp=int(spp), seed=int(seed))
    return np.asarray(img, dtype=np.float32).reshape(res, res, -1)[..., :3].copy()


__all__ = ["DEFAULT_SPP", "envmap_vertex_rows", "render_svbrdf_mitsuba3", "scene_dict"]


class Mitsuba3EnvironmentRender:
    """Mitsuba 3's :class:`~matremap.renderers.base.EnvironmentRender`: a ``mitsuba3:*`` material drawn
    under the environment map itself (not its discrete lights) by :func:`render_svbrdf_mitsuba3`."""

    label = "Mitsuba 3"

    def __init__(self, material: SVMaterial, env: EnvMap, resolution: int, part: str) -> None:
        self.material, self.env, self.resolution, self.part = material, env, resolution, part

    def render(self, rotation_deg: float) -> np.ndarray:
        m = self.material
        return render_svbrdf_mitsuba3(
            m.model,
            m.params,
            m.options,
            self.env,
            rotation_deg=rotation_deg,
            resolution=self.resolution,
            part=self.part,
            normal_map=m.normal,
        )
