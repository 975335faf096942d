"""The textured evaluation scene every renderer draws, and textured materials' validation.

The embedded renderer's evaluation scene for SVBRDFs (paper §6): a UV-mapped sphere, or a textured
square tilted towards the sky, lit by an :class:`~matremap.core.envmap.EnvMap` sampled into directional
lights (:func:`~matremap.core.envmap.directional_lights`), shaded by the embedded dialects' evaluators.
One ray through each pixel centre, no shadows other than cos > 0: deterministic bit for bit.

Camera as in :mod:`matremap.core.scene`: a pinhole at (0, 0, 8) looking down -z, +y up, framing a
sphere of radius 2 at the origin with a 5 % margin; the background is black.

* **sphere**: radius 2 at the origin; ``u = 0.5 + atan2(x, z) / 2 pi`` (the texture's centre column
  faces the camera, u grows to the right), ``v = acos(y / r) / pi`` (row 0 at the north pole).
* **plane**: a square of half-size 1.9 at the origin, its normal tilted 30 degrees from +z towards
  +y (so it mirrors the upper environment to the camera); u to the right, v downwards, as the
  texture image is seen.

Textures are sampled bilinearly at texel centres (wrapping in u on the sphere, clamped otherwise).
Texture arrays are ``[h, w]`` (scalar or grey) or ``[h, w, 3]`` (RGB), row 0 at the top, in the
model's own units (e.g. a roughness ``alpha``, not an 8-bit code). Normal maps are tangent space,
``[h, w, 3]`` in [-1, 1] (a PNG's [0, 1] values mapped by 2x - 1: :func:`decode_normal_map`),
x along u (right), y up the image (OpenGL convention), z along the surface normal.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from matremap.core.models import ModelSpec, ParamSpec
from matremap.core.scene import Scene
from matremap.errors import MatremapError
from matremap.renderers.base import GEOMETRIES

#: half-size and tilt of the plane
PLANE_HALF_SIZE = 1.9
PLANE_TILT_DEG = 30.0

#: elements of an [L, P] array per shading chunk: bounds the evaluators' temporaries and keeps them in
#: cache (1 << 16 is 3-4x faster than 1 << 20)
CHUNK_ELEMENTS = 1 << 16


def decode_normal_map(image: np.ndarray) -> np.ndarray:
    """A normal map image with values in [0, 1] (as read from a PNG) -> vectors in [-1, 1]."""
    a = np.asarray(image, dtype=float)
    if a.ndim != 3 or a.shape[2] < 3:
        raise MatremapError(f"a normal map must be an RGB image [h, w, 3], got shape {a.shape}")
    return 2.0 * a[..., :3] - 1.0


# ---------------------------------------------------------------------------------------------
# geometry of the visible surface


@dataclass(frozen=True, eq=False)
class SurfacePixels:
    """The object's visible points: flat pixel indices [P] and per-point frames and UVs."""

    resolution: int
    pixels: np.ndarray  # flat (row-major) indices into res * res
    normal: np.ndarray  # [P, 3] geometric normal
    tangent: np.ndarray  # [P, 3] dP/du direction (unit)
    bitangent: np.ndarray  # [P, 3] "up the texture" direction (unit), tangent x bitangent = normal
    view: np.ndarray  # [P, 3] unit direction to the camera
    uv: np.ndarray  # [P, 2] texture coordinates in [0, 1]
    wrap_u: bool

    def mask(self) -> np.ndarray:
        m = np.zeros(self.resolution * self.resolution, dtype=bool)
        m[self.pixels] = True
        return m.reshape(self.resolution, self.resolution)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


@lru_cache(maxsize=8)
def surface_pixels(geometry: str, resolution: int) -> SurfacePixels:
    """The visible surface of the sphere or the plane at a resolution (cached, read-only)."""
    if geometry not in GEOMETRIES:
        raise MatremapError(f"unknown geometry {geometry!r}; use one of {', '.join(GEOMETRIES)}")
    scene = Scene(resolution=resolution)
    cam = np.array([0.0, 0.0, scene.camera_distance])
    if geometry == "sphere":
        pix = np.asarray(scene.pixel_indices())
        p = np.asarray(scene.sphere_points())
        n = _unit(p)
        phi = np.arctan2(n[:, 0], n[:, 2])
        theta = np.arccos(np.clip(n[:, 1], -1.0, 1.0))
        uv = np.stack([0.5 + phi / (2.0 * math.pi), theta / math.pi], axis=-1)
        tangent = np.stack([np.cos(phi), np.zeros_like(phi), -np.sin(phi)], axis=-1)
        bitangent = np.cross(n, tangent)  # = -dP/dv direction: up the texture
        wrap_u = True
    else:
        t = math.radians(PLANE_TILT_DEG)
        normal = np.array([0.0, math.sin(t), math.cos(t)])
        tan = np.array([1.0, 0.0, 0.0])
        bit = np.array([0.0, math.cos(t), -math.sin(t)])
        rays = scene.camera_rays().reshape(-1, 3)
        denom = rays @ normal
        with np.errstate(divide="ignore", invalid="ignore"):
            dist = -(cam @ normal) / denom
        hit = cam + dist[:, None] * rays
        a = hit @ tan
        b = hit @ bit
        s = PLANE_HALF_SIZE
        inside = (denom < 0.0) & (dist > 0.0) & (np.abs(a) < s) & (np.abs(b) < s)
        pix = np.flatnonzero(inside)
        p = hit[pix]
        uv = np.stack([(a[pix] + s) / (2.0 * s), (s - b[pix]) / (2.0 * s)], axis=-1)
        n = np.broadcast_to(normal, p.shape).copy()
        tangent = np.broadcast_to(tan, p.shape).copy()
        bitangent = np.broadcast_to(bit, p.shape).copy()
        wrap_u = False
    view = _unit(cam - p)
    out = SurfacePixels(resolution, pix, n, tangent, bitangent, view, uv, wrap_u)
    for arr in (out.pixels, out.normal, out.tangent, out.bitangent, out.view, out.uv):
        arr.flags.writeable = False
    return out


def object_mask(geometry: str = "sphere", resolution: int = 256) -> np.ndarray:
    """Boolean [res, res]: pixels that see the object."""
    return surface_pixels(geometry, resolution).mask()


def sample_texture(texture: np.ndarray, uv: np.ndarray, wrap_u: bool = False) -> np.ndarray:
    """Bilinear lookup of ``texture`` [h, w] or [h, w, C] at ``uv`` [P, 2] -> [P] or [P, C]."""
    tex = np.asarray(texture, dtype=float)
    h, w = tex.shape[:2]
    x = uv[:, 0] * w - 0.5
    y = uv[:, 1] * h - 0.5
    x0 = np.floor(x)
    y0 = np.floor(y)
    fx = x - x0
    fy = y - y0
    x0 = x0.astype(np.int64)
    y0 = y0.astype(np.int64)
    if wrap_u:
        xa, xb = np.mod(x0, w), np.mod(x0 + 1, w)
    else:
        xa, xb = np.clip(x0, 0, w - 1), np.clip(x0 + 1, 0, w - 1)
    ya, yb = np.clip(y0, 0, h - 1), np.clip(y0 + 1, 0, h - 1)
    if tex.ndim == 3:
        fx = fx[:, None]
        fy = fy[:, None]
    top = tex[ya, xa] * (1.0 - fx) + tex[ya, xb] * fx
    bot = tex[yb, xa] * (1.0 - fx) + tex[yb, xb] * fx
    return top * (1.0 - fy) + bot * fy


def check_options(spec: ModelSpec, params: Mapping[str, Any], options: Mapping[str, str]) -> dict[str, str]:
    for name in params:
        if name in spec.option_names:
            raise MatremapError(f"{spec.id}: {name} is an option; pass it in options, not as a parameter map")
        spec.param(name)  # raises for unknown names
    opts = {o.name: o.default for o in spec.options}
    for name, value in options.items():
        if name not in spec.option_names:
            raise MatremapError(
                f"{spec.id} has no option {name!r}"
                + (f"; its options are {', '.join(spec.option_names)}" if spec.options else "")
            )
        choices = spec.option(name).choices
        if value not in choices:
            raise MatremapError(f"{spec.id}: option {name} must be one of {', '.join(choices)}, got {value!r}")
        opts[name] = str(value)
    return opts


def check_normal_map(normal_map: Any) -> np.ndarray:
    """A tangent-space normal map [h, w, 3] in [-1, 1], validated (shared by every SVBRDF renderer)."""
    nm = np.asarray(normal_map, dtype=float)
    if nm.ndim != 3 or nm.shape[2] != 3:
        raise MatremapError(f"a normal map must be [h, w, 3] (tangent space, in [-1, 1]), got shape {nm.shape}")
    if not np.all(np.isfinite(nm)):
        raise MatremapError("the normal map has NaN or infinite values")
    return nm


def split_texture_params(
    spec: ModelSpec,
    params: Mapping[str, Any],
    overrides: Mapping[str, Any],
    check: Callable[[ParamSpec, np.ndarray], None] | None = None,
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Every model parameter as a constant ``[channels]`` or a texture (scalar ``[h, w]``, RGB
    ``[h, w, 3]``), validated; ``overrides`` win over ``params``, defaults fill the rest. ``check``
    adds a renderer's own rules for a texture. Texture parameters keep their default as constant."""
    consts: dict[str, np.ndarray] = {}
    textures: dict[str, np.ndarray] = {}
    for p in spec.params:
        raw = overrides[p.name] if p.name in overrides else params.get(p.name, p.default_array)
        a = np.asarray(raw, dtype=float)
        if not np.all(np.isfinite(a)):
            raise MatremapError(f"{spec.id}: {p.name} has NaN or infinite values")
        if a.ndim <= 1:
            if a.size not in (1, p.channels):
                raise MatremapError(f"{spec.id}: {p.name} takes {p.channels} value(s), got {a.size}")
            consts[p.name] = np.broadcast_to(a.reshape(-1), (p.channels,)).astype(float)
            continue
        if a.ndim == 3 and a.shape[2] == 1:
            a = a[..., 0]
        if (a.ndim == 3 and a.shape[2] != 3) or a.ndim > 3 or min(a.shape[:2]) < 1:
            raise MatremapError(f"{spec.id}: texture {p.name} must be [h, w] or [h, w, 3], got shape {a.shape}")
        if check is not None:
            check(p, a)
        if p.channels == 1:
            if a.ndim == 3:
                if not np.all(a == a[..., :1]):
                    raise MatremapError(
                        f"{spec.id}: {p.name} is a scalar parameter but its texture has different R, G, B; "
                        "give a single-channel map"
                    )
                a = a[..., 0]
        elif a.ndim == 2:
            a = np.repeat(a[..., None], 3, axis=2)
        textures[p.name] = a
        consts[p.name] = p.default_array.astype(float)
    return consts, textures
