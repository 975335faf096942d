"""Environment maps: lat-long HDR radiance, a built-in procedural studio, deterministic light sampling.

An :class:`EnvMap` holds linear radiance, float32 ``[H, W, 3]``, in the latitude-longitude
(equirectangular) layout, +y up:

* row ``i`` is the polar angle ``theta = pi (i + 0.5) / H`` from +y (row 0 is the zenith);
* column ``j`` is the azimuth ``phi = 2 pi (j + 0.5) / W``, and the direction of (theta, phi) is
  ``(-sin theta sin phi, cos theta, sin theta cos phi)``: the centre column looks down -z (where the
  probe camera looks, i.e. what is seen behind the object), the left and right edges along +z
  (behind the camera), and the image is not mirrored when seen from inside the sphere (+x is to the
  right of the centre).

:func:`directional_lights` turns a map into a few hundred directional lights by deterministic
importance sampling, which is how the embedded renderer shades under an environment: no noise from
one render to the next, and bit-identical results on every run.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from matremap.core.imageio import oiio_name
from matremap.errors import MatremapError

#: a direction or an RGB colour, as the built-in map's lights are written
Vec3 = tuple[float, float, float]

#: Rec. 709 / sRGB luminance weights
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])

#: formats :func:`load` accepts (OpenImageIO reads them as float)
ENVMAP_SUFFIXES = (".exr", ".hdr")


@dataclass(frozen=True, eq=False)
class EnvMap:
    """A lat-long environment map: linear radiance float32 [H, W, 3], +y up (see module doc)."""

    radiance: np.ndarray
    name: str = "envmap"

    def __post_init__(self) -> None:
        r = np.asarray(self.radiance)
        if r.ndim != 3 or r.shape[2] != 3 or r.shape[0] < 2 or r.shape[1] < 2:
            raise MatremapError(f"environment map {self.name}: expected radiance [H, W, 3], got shape {r.shape}")
        if not np.all(np.isfinite(r)):
            raise MatremapError(f"environment map {self.name}: has NaN or infinite values")
        r = np.ascontiguousarray(np.maximum(r, 0.0), dtype=np.float32)
        r.flags.writeable = False
        object.__setattr__(self, "radiance", r)

    @property
    def height(self) -> int:
        return self.radiance.shape[0]

    @property
    def width(self) -> int:
        return self.radiance.shape[1]

    def directions(self) -> np.ndarray:
        """Unit directions [H, W, 3] of the texel centres."""
        theta = math.pi * (np.arange(self.height) + 0.5) / self.height
        phi = 2.0 * math.pi * (np.arange(self.width) + 0.5) / self.width
        return latlong_to_direction(theta[:, None], phi[None, :])

    def solid_angles(self) -> np.ndarray:
        """Solid angle [H] of one texel in each row (exact for the latitude band)."""
        edges = np.cos(math.pi * np.arange(self.height + 1) / self.height)
        return (edges[:-1] - edges[1:]) * (2.0 * math.pi / self.width)

    def texels(self, directions: np.ndarray, rotation_deg: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Row and column indices [...] of the texels seen along unit ``directions`` [..., 3] with the map
        turned by ``rotation_deg`` about +y (as in :func:`directional_lights`)."""
        d = rotate_y(np.asarray(directions, dtype=float), -rotation_deg)
        theta, phi = direction_to_latlong(d)
        i = np.clip((theta / math.pi * self.height).astype(int), 0, self.height - 1)
        j = np.mod((phi / (2.0 * math.pi) * self.width).astype(int), self.width)
        return i, j

    def lookup(self, directions: np.ndarray, rotation_deg: float = 0.0) -> np.ndarray:
        """Radiance [..., 3] seen along unit ``directions`` [..., 3] (nearest texel) with the map
        turned by ``rotation_deg`` about +y (as in :func:`directional_lights`)."""
        return self.radiance[self.texels(directions, rotation_deg)]

    @cached_property
    def light_density(self) -> np.ndarray:
        """Per texel [H, W], the density (per steradian) with which :func:`directional_lights` picks a
        direction there: luminance / (sum of luminance x solid angle) (read-only)."""
        dist = _distribution(self)
        out = dist.weights / (dist.total * self.solid_angles()[:, None])
        out.flags.writeable = False
        return out

    def mean_radiance(self) -> np.ndarray:
        """Solid-angle weighted mean radiance (RGB): irradiance / pi of a surface seeing it all."""
        w = self.solid_angles()
        return (np.tensordot(w, self.radiance.astype(float), axes=(0, 0)).sum(axis=0)) / (4.0 * math.pi)


def latlong_to_direction(theta: np.ndarray, phi: np.ndarray) -> np.ndarray:
    st = np.sin(theta)
    return np.stack(np.broadcast_arrays(-st * np.sin(phi), np.cos(theta), st * np.cos(phi)), axis=-1)


def direction_to_latlong(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(theta in [0, pi], phi in [0, 2 pi)) of unit directions [..., 3]."""
    theta = np.arccos(np.clip(d[..., 1], -1.0, 1.0))
    phi = np.mod(np.arctan2(-d[..., 0], d[..., 2]), 2.0 * math.pi)
    return theta, phi


def rotate_y(v: np.ndarray, angle_deg: float) -> np.ndarray:
    """Rotate vectors [..., 3] by ``angle_deg`` about +y (right-handed: +z turns towards +x).

    The angle is reduced modulo 360 first, so 360 degrees is exactly the identity."""
    a = math.radians(math.fmod(float(angle_deg), 360.0))
    if a == 0.0:
        return np.array(v, dtype=float, copy=True)
    c, s = math.cos(a), math.sin(a)
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    return np.stack([c * x + s * z, y, -s * x + c * z], axis=-1)


# ---------------------------------------------------------------------------------------------
# construction


def constant(radiance: float | tuple[float, float, float] = 1.0, height: int = 32, width: int = 64) -> EnvMap:
    """A uniform environment (the 'furnace'): every direction has the same radiance."""
    rgb = np.broadcast_to(np.asarray(radiance, dtype=np.float32), (3,))
    return EnvMap(np.broadcast_to(rgb, (height, width, 3)).copy(), name="constant")


def builtin(height: int = 128, width: int = 256) -> EnvMap:
    """A procedural studio HDR: a sky/ground gradient and a few soft area lights.

    * a warm-grey floor below the horizon (radiance ~0.05-0.15) and a cool studio sky above
      (~0.25 at the horizon to ~0.6 at the zenith);
    * a large key soft box up and to the left in front of the object (radiance 12), a dimmer fill
      box to the right (4), a rim light behind and above (8), and a long horizontal strip light
      behind the camera (3), which all make distinct highlights as the map rotates.

    Pure arithmetic on the texel directions: bit-identical on every run.
    """
    if height < 8 or width < 16:
        raise MatremapError("the builtin environment needs at least 8 x 16 texels")
    theta = math.pi * (np.arange(height) + 0.5) / height
    phi = 2.0 * math.pi * (np.arange(width) + 0.5) / width
    d = latlong_to_direction(theta[:, None], phi[None, :])  # [H, W, 3]
    y = d[..., 1]

    up = np.clip(y, 0.0, 1.0)[..., None]
    sky = (1.0 - up) * np.array([0.22, 0.25, 0.30]) + up * np.array([0.50, 0.58, 0.70])
    down = np.clip(-y, 0.0, 1.0)[..., None]
    ground = (1.0 - down) * np.array([0.15, 0.13, 0.11]) + down * np.array([0.05, 0.045, 0.04])
    # a soft horizon instead of a step
    t = (0.5 + 0.5 * np.tanh(y / 0.04))[..., None]
    rad = t * sky + (1.0 - t) * ground

    def softbox(axis: Vec3, half_angle_deg: float, colour: Vec3, power: float, sharpness: float = 6.0) -> np.ndarray:
        a = np.asarray(axis, dtype=float)
        a /= np.linalg.norm(a)
        cosang = np.clip(d @ a, -1.0, 1.0)
        ang = np.arccos(cosang) / math.radians(half_angle_deg)
        # super-Gaussian: a flat-topped disc with a soft edge
        return power * np.exp(-np.power(ang, sharpness))[..., None] * np.asarray(colour)

    def strip(axis: Vec3, half_width_deg: float, half_length_deg: float, colour: Vec3, power: float) -> np.ndarray:
        """A strip along the horizontal direction perpendicular to ``axis``."""
        a = np.asarray(axis, dtype=float)
        a /= np.linalg.norm(a)
        side = np.cross([0.0, 1.0, 0.0], a)
        side /= np.linalg.norm(side)
        upv = np.cross(a, side)
        front = d @ a
        u = np.degrees(np.arctan2(d @ side, front))
        v = np.degrees(np.arctan2(d @ upv, front))
        w = np.exp(-np.power(np.abs(u) / half_length_deg, 6.0) - np.power(np.abs(v) / half_width_deg, 6.0))
        return power * np.where(front > 0.0, w, 0.0)[..., None] * np.asarray(colour)

    rad = rad + softbox((-0.55, 0.55, 0.65), 16.0, (1.0, 0.97, 0.92), 12.0)  # key
    rad = rad + softbox((0.85, 0.15, 0.5), 12.0, (0.9, 0.95, 1.0), 4.0)  # fill
    rad = rad + softbox((0.25, 0.75, -0.6), 9.0, (1.0, 1.0, 1.0), 8.0)  # rim
    rad = rad + strip((0.0, 0.2, 1.0), 3.0, 40.0, (1.0, 1.0, 1.0), 3.0)  # strip behind the camera
    return EnvMap(rad.astype(np.float32), name="builtin")


def load(path: str | os.PathLike) -> EnvMap:
    """Read a lat-long environment map (OpenEXR or Radiance HDR) through OpenImageIO.

    Only the first three channels are used (a single-channel map is taken as grey)."""
    p = Path(path)
    if p.suffix.lower() not in ENVMAP_SUFFIXES:
        raise MatremapError(
            f"cannot use {p} as an environment map: {p.suffix or 'no suffix'!s} is not an HDR format; "
            f"give a lat-long {' or '.join(ENVMAP_SUFFIXES)} file, or 'builtin'"
        )
    if not p.is_file():
        raise MatremapError(f"environment map {p} does not exist")
    try:
        import OpenImageIO as oiio
    except ImportError:  # pragma: no cover - it is a dependency
        raise MatremapError("reading EXR/HDR environment maps needs OpenImageIO: pip install openimageio") from None
    buf = oiio.ImageBuf(oiio_name(p))
    if buf.has_error:
        raise MatremapError(f"cannot read environment map {p}: {buf.geterror()}")
    pixels = buf.get_pixels(oiio.FLOAT)
    if pixels is None or buf.has_error:
        raise MatremapError(f"cannot read environment map {p}: {buf.geterror()}")
    pixels = np.asarray(pixels, dtype=np.float32)
    if pixels.ndim == 2:
        pixels = pixels[..., None]
    if pixels.ndim != 3:
        raise MatremapError(f"environment map {p}: unsupported image layout {pixels.shape}")
    c = pixels.shape[2]
    rgb = np.repeat(pixels[..., :1], 3, axis=2) if c < 3 else pixels[..., :3]
    h, w = rgb.shape[:2]
    if not 1.5 <= w / h <= 2.5:
        raise MatremapError(
            f"environment map {p} is {w} x {h}; a lat-long map is about twice as wide as it is high "
            "(cube maps and mirror balls are not supported)"
        )
    if not np.all(np.isfinite(rgb)):
        raise MatremapError(f"environment map {p} has NaN or infinite values")
    return EnvMap(rgb, name=p.name)


def resolve(spec: str | os.PathLike | EnvMap) -> EnvMap:
    """``'builtin'``, ``'constant'`` or a file path -> :class:`EnvMap` (for the command line)."""
    if isinstance(spec, EnvMap):
        return spec
    if str(spec) == "builtin":
        return builtin()
    if str(spec) == "constant":
        return constant()
    return load(spec)


# ---------------------------------------------------------------------------------------------
# sampling


def _radical_inverse_base2(i: np.ndarray) -> np.ndarray:
    """Van der Corput sequence in base 2 for unsigned 32-bit integers."""
    b = i.astype(np.uint64) & np.uint64(0xFFFFFFFF)
    b = ((b << np.uint64(16)) | (b >> np.uint64(16))) & np.uint64(0xFFFFFFFF)
    b = ((b & np.uint64(0x00FF00FF)) << np.uint64(8)) | ((b & np.uint64(0xFF00FF00)) >> np.uint64(8))
    b = ((b & np.uint64(0x0F0F0F0F)) << np.uint64(4)) | ((b & np.uint64(0xF0F0F0F0)) >> np.uint64(4))
    b = ((b & np.uint64(0x33333333)) << np.uint64(2)) | ((b & np.uint64(0xCCCCCCCC)) >> np.uint64(2))
    b = ((b & np.uint64(0x55555555)) << np.uint64(1)) | ((b & np.uint64(0xAAAAAAAA)) >> np.uint64(1))
    return b.astype(np.float64) / 4294967296.0


def _sample_piecewise(cdf: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Invert a piecewise-constant CDF (``cdf[0] = 0``, ``cdf[-1] = 1``, length n + 1):
    bin index and the continuous position in [0, 1) within the bin."""
    n = cdf.size - 1
    k = np.clip(np.searchsorted(cdf, u, side="right") - 1, 0, n - 1)
    # skip empty bins that searchsorted may land on at their left edge
    width = cdf[k + 1] - cdf[k]
    frac = np.where(width > 0.0, (u - cdf[k]) / np.where(width > 0.0, width, 1.0), 0.5)
    return k, np.clip(frac, 0.0, 1.0 - 1e-12)


@dataclass(frozen=True, eq=False)
class _Distribution:
    """Importance of each texel (luminance x solid angle), as a marginal over rows and a
    conditional over columns in each row."""

    weights: np.ndarray  # [H, W]
    row_cdf: np.ndarray  # [H + 1]
    col_cdf: np.ndarray  # [H, W + 1]
    total: float


def _distribution(env: EnvMap) -> _Distribution:
    lum = np.tensordot(env.radiance.astype(np.float64), LUMINANCE, axes=(2, 0))
    w = np.maximum(lum, 0.0) * env.solid_angles()[:, None]
    row = w.sum(axis=1)
    total = float(row.sum())
    if not total > 0.0:
        raise MatremapError(f"environment map {env.name} is black: it cannot light anything")
    row_cdf = np.concatenate([[0.0], np.cumsum(row)]) / total
    row_cdf[-1] = 1.0
    csum = np.cumsum(w, axis=1)
    safe = np.where(row > 0.0, row, 1.0)[:, None]
    col_cdf = np.concatenate([np.zeros((env.height, 1)), csum / safe], axis=1)
    col_cdf[:, -1] = 1.0
    return _Distribution(w, row_cdf, col_cdf, total)


def directional_lights(
    env: EnvMap, count: int = 256, rotation_deg: float = 0.0, seed: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """Deterministic importance sampling of ``env`` into ``count`` directional lights.

    Returns ``(directions [L, 3] unit vectors towards the light, intensities [L, 3])`` such that
    ``sum_k intensity_k * g(direction_k)`` estimates ``integral L_env(w) g(w) dw`` for smooth ``g``;
    in particular the radiance of a Lambertian surface of albedo ``a`` with normal ``n`` is
    ``a / pi * sum_k intensity_k max(0, n . direction_k)``.

    Texels are chosen with probability proportional to luminance x solid angle (luminance x
    sin(theta)) through the marginal (rows) and conditional (columns) CDFs, at the points of a
    Hammersley set shifted by a Cranley-Patterson rotation drawn from ``seed``, so the lights are
    stratified in both directions. Each light carries the radiance of its texel divided by its
    density: ``intensity = L_texel * (sum of weights) / (count * luminance_texel)``. The map is then
    turned by ``rotation_deg`` about +y.
    """
    if not isinstance(count, (int, np.integer)) or count < 1:
        raise MatremapError(f"the number of lights must be a positive integer, got {count!r}")
    dist = _distribution(env)
    n = int(count)
    rng = np.random.default_rng(seed)
    shift = rng.random(2)
    u1 = np.mod((np.arange(n) + 0.5) / n + shift[0], 1.0)
    u2 = np.mod(_radical_inverse_base2(np.arange(n)) + shift[1], 1.0)
    i, fi = _sample_piecewise(dist.row_cdf, u1)
    j = np.empty(n, dtype=np.int64)
    fj = np.empty(n)
    for row in np.unique(i):
        sel = i == row
        j[sel], fj[sel] = _sample_piecewise(dist.col_cdf[row], u2[sel])
    # a continuous position in the texel: uniform in cos(theta) within the band (its solid angle)
    c0 = np.cos(math.pi * i / env.height)
    c1 = np.cos(math.pi * (i + 1) / env.height)
    theta = np.arccos(np.clip(c0 + fi * (c1 - c0), -1.0, 1.0))
    phi = 2.0 * math.pi * (j + fj) / env.width
    dirs = latlong_to_direction(theta, phi)
    rgb = env.radiance[i, j].astype(np.float64)
    lum = rgb @ LUMINANCE
    intensities = rgb * (dist.total / (n * lum))[:, None]
    dirs = rotate_y(dirs, rotation_deg)
    dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
    return dirs, intensities
