"""Textures as a renderer samples them, baked onto a plain map: UV transforms, wrap modes, node graphs.

A map set's maps are images laid on the object's UVs as they are stored (row 0 at the top). Material
files often sample their images differently -- glTF's ``KHR_texture_transform``, MaterialX's
``tiledimage`` / ``place2d``, USD's ``UsdTransform2d``, Mitsuba's bitmap ``to_uv`` -- or compute a
parameter from several images and constants (MaterialX node graphs, Mitsuba's ``checkerboard``). A
reader that meets such an input gives its :class:`~matremap.formats.asset.TextureRef` a ``bake``
callable that returns what the renderer would see at each texel of the output map; this module holds
the pieces those callables share.

Conventions. *Image space* ``(s, t)``: ``s`` from the left edge (0) to the right edge (1), ``t`` from
the top row (0) to the bottom row (1); a texel's centre is at ``((i + 0.5) / W, (j + 0.5) / H)``. A
format's own UV space has its origin at the top left (glTF 2.0 §3.8.4.2: "the origin of the UV
coordinates (0, 0) corresponds to the upper left corner of a texture image"; Mitsuba's bitmap, which
flips ``v`` on load) or at the bottom left (MaterialX 1.39, "texture coordinate space ... (0,0) at the
lower left"; USD's ``st``); :class:`UVTransform` says which. Sampling is bilinear between texel
centres with the wrap modes of OpenGL / glTF samplers (``repeat``, ``mirror``, ``clamp``) or a
constant ``border`` value outside [0, 1] (MaterialX's ``constant`` address mode, Mitsuba's ``clamp``
is ``clamp``).

Values are decoded to linear before filtering, as GPUs and offline renderers filter sRGB textures
(OpenGL 4.6 §8.24: sRGB decode happens before filtering).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from matremap.errors import MatremapError

WRAP_MODES = ("repeat", "mirror", "clamp", "border")
#: the largest side of a baked map; a lookup asking for more (a 2048-texel image tiled 4 times) is capped there
MAX_SIDE = 2048


def translate(du: float, dv: float) -> np.ndarray:
    """The 3x3 homogeneous matrix moving UVs by ``(du, dv)``."""
    return np.array([[1.0, 0.0, du], [0.0, 1.0, dv], [0.0, 0.0, 1.0]])


def scale(su: float, sv: float) -> np.ndarray:
    """The 3x3 homogeneous matrix scaling UVs by ``(su, sv)`` about the origin."""
    return np.array([[su, 0.0, 0.0], [0.0, sv, 0.0], [0.0, 0.0, 1.0]])


def rotate(radians: float) -> np.ndarray:
    """The 3x3 homogeneous matrix rotating UVs by ``radians`` about the origin (counter-clockwise
    in a frame whose second axis points the way the format's ``v`` does)."""
    c, s = np.cos(radians), np.sin(radians)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class UVTransform:
    """Where a texel of the output map samples its image, in the format's own UV convention.

    ``matrix``: 3x3 homogeneous, taking the UV at which the surface is shaded to the UV at which the
    image is looked up (compose it from :func:`translate`, :func:`scale`, :func:`rotate` in the
    order the format's specification gives); ``origin``: where the format's UV (0, 0) lies on the
    image, ``"top-left"`` or ``"bottom-left"``; ``wrap``: the wrap mode along ``u`` and ``v``."""

    matrix: np.ndarray
    origin: str = "top-left"
    wrap: tuple[str, str] = ("repeat", "repeat")
    border: float = 0.0

    def __post_init__(self) -> None:
        m = np.asarray(self.matrix, dtype=float)
        if m.shape != (3, 3) or not np.all(np.isfinite(m)):
            raise MatremapError("a texture transform must be a finite 3x3 matrix")
        if self.origin not in ("top-left", "bottom-left"):
            raise MatremapError(f"texture origin {self.origin!r} is not top-left or bottom-left")
        for w in self.wrap:
            if w not in WRAP_MODES:
                raise MatremapError(f"wrap mode {w!r} is not one of {', '.join(WRAP_MODES)}")
        object.__setattr__(self, "matrix", m)

    @property
    def identity(self) -> bool:
        return bool(np.allclose(self.matrix, np.eye(3), rtol=0, atol=1e-12))

    def lookup(self, s: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The image-space coordinates sampled for output texels at image-space ``(s, t)``."""
        u, v = (s, t) if self.origin == "top-left" else (s, 1.0 - t)
        m = self.matrix
        lu = m[0, 0] * u + m[0, 1] * v + m[0, 2]
        lv = m[1, 0] * u + m[1, 1] * v + m[1, 2]
        return (lu, lv) if self.origin == "top-left" else (lu, 1.0 - lv)


def texel_grid(size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Image-space ``(s, t)`` of the texel centres of a map of ``size`` = (height, width), each [H, W]."""
    h, w = size
    if h < 1 or w < 1:
        raise MatremapError(f"a baked map needs a positive size, not {h}x{w}")
    t, s = np.meshgrid((np.arange(h) + 0.5) / h, (np.arange(w) + 0.5) / w, indexing="ij")
    return s, t


def _wrap_index(i: np.ndarray, n: int, mode: str) -> tuple[np.ndarray, np.ndarray | None]:
    """Texel indices ``i`` (any integers) brought into [0, n) by ``mode``; for ``border``, the mask of
    those that fell outside."""
    if mode == "repeat":
        return np.mod(i, n), None
    if mode == "mirror":
        period = np.mod(i, 2 * n)
        return np.where(period < n, period, 2 * n - 1 - period), None
    inside = (i >= 0) & (i < n)
    return np.clip(i, 0, n - 1), (None if mode == "clamp" else ~inside)


def sample(
    image: np.ndarray, s: np.ndarray, t: np.ndarray, wrap: tuple[str, str] = ("repeat", "repeat"), border: float = 0.0
) -> np.ndarray:
    """Bilinear lookup of ``image`` [H, W, C] at image-space ``(s, t)`` (any equal shapes), with the
    wrap mode along s and t; returns float32 [..., C]."""
    img = np.asarray(image, dtype=np.float32)
    if img.ndim == 2:
        img = img[..., None]
    h, w, c = img.shape
    flat = img.reshape(h * w, c)
    x = np.asarray(s, dtype=np.float64) * w - 0.5
    y = np.asarray(t, dtype=np.float64) * h - 0.5
    shape = x.shape
    x, y = x.reshape(-1), y.reshape(-1)
    x0f, y0f = np.floor(x), np.floor(y)
    fx = (x - x0f).astype(np.float32)[:, None]
    fy = (y - y0f).astype(np.float32)[:, None]
    x0, y0 = x0f.astype(np.intp), y0f.astype(np.intp)
    cols = [_wrap_index(x0 + d, w, wrap[0]) for d in (0, 1)]
    rows = [_wrap_index(y0 + d, h, wrap[1]) for d in (0, 1)]

    def tap(row: tuple[np.ndarray, np.ndarray | None], col: tuple[np.ndarray, np.ndarray | None]) -> np.ndarray:
        texel = np.take(flat, row[0] * w + col[0], axis=0)
        masks = [m for m in (row[1], col[1]) if m is not None]
        if masks:
            outside = masks[0] if len(masks) == 1 else masks[0] | masks[1]
            texel[outside] = np.float32(border)
        return texel

    top = tap(rows[0], cols[0]) * (1.0 - fx) + tap(rows[0], cols[1]) * fx
    bottom = tap(rows[1], cols[0]) * (1.0 - fx) + tap(rows[1], cols[1]) * fx
    out = top * (1.0 - fy) + bottom * fy
    return out.reshape(*shape, c)


def bake_image(image: np.ndarray, transform: UVTransform, size: tuple[int, int] | None = None) -> np.ndarray:
    """``image`` [H, W, C] (linear) as seen through ``transform``, on a map of ``size`` (the
    image's own by default): float32 [h, w, C]."""
    size = size or (int(image.shape[0]), int(image.shape[1]))
    s, t = texel_grid(size)
    ls, lt = transform.lookup(s, t)
    return sample(image, ls, lt, transform.wrap, transform.border)


#: texels of an image file a streamed lookup decodes at a time (:func:`sample_file`): bands of rows of about a million
#: texels, as maps are converted
BAND_TEXELS = 1 << 20
#: lookups whose coordinates are computed at a time
_CHUNK = 1 << 18


class _Taps:
    """The bilinear taps of ``n`` lookups into an image of ``h`` x ``w`` texels with the wrap modes ``wrap``
    (along s, t): each lookup's first column and row (``x0``, ``y0``: integers, before wrapping) and its weights
    ``fx``, ``fy``, computed ``_CHUNK`` lookups at a time from ``coords(a, b)``, the image-space (s, t) of lookups
    ``a:b``, exactly as :func:`sample` computes them."""

    def __init__(
        self,
        n: int,
        h: int,
        w: int,
        wrap: tuple[str, str],
        coords: Callable[[int, int], tuple[np.ndarray, np.ndarray]],
    ) -> None:
        self.n, self.h, self.w, self.wrap = n, h, w, wrap
        self.x0 = np.empty(n, np.int64)
        self.y0 = np.empty(n, np.int64)
        self.fx = np.empty(n, np.float32)
        self.fy = np.empty(n, np.float32)
        for a in range(0, n, _CHUNK):
            b = min(n, a + _CHUNK)
            s, t = coords(a, b)
            x = np.asarray(s, dtype=np.float64).reshape(-1) * w - 0.5
            y = np.asarray(t, dtype=np.float64).reshape(-1) * h - 0.5
            x0f, y0f = np.floor(x), np.floor(y)
            self.fx[a:b] = x - x0f
            self.fy[a:b] = y - y0f
            self.x0[a:b] = x0f
            self.y0[a:b] = y0f

    def rows(self, d: int, idx: np.ndarray | slice) -> tuple[np.ndarray, np.ndarray | None]:
        """Row ``y0 + d`` of lookups ``idx``, wrapped, and where it lies outside the image (border mode)."""
        return _wrap_index(self.y0[idx] + d, self.h, self.wrap[1])

    def cols(self, d: int, idx: np.ndarray | slice) -> tuple[np.ndarray, np.ndarray | None]:
        return _wrap_index(self.x0[idx] + d, self.w, self.wrap[0])


def _tap_row(
    taps: _Taps,
    d: int,
    idx: np.ndarray | slice,
    band: np.ndarray,
    y_first: int,
    decode: Callable[[np.ndarray], np.ndarray],
    border: float,
) -> np.ndarray:
    """The two taps of row ``y0 + d`` of lookups ``idx`` (rows that ``band``, starting at image row ``y_first``,
    holds), decoded and blended along s: ``left (1 - fx) + right fx``, as :func:`sample` does."""
    row, row_out = taps.rows(d, idx)
    fx = taps.fx[idx][:, None]
    values = []
    for dc in (0, 1):
        col, col_out = taps.cols(dc, idx)
        texel = decode(band[row - y_first, col])
        masks = [m for m in (row_out, col_out) if m is not None]
        if masks:
            texel[masks[0] if len(masks) == 1 else masks[0] | masks[1]] = np.float32(border)
        values.append(texel)
    return values[0] * (1.0 - fx) + values[1] * fx


def _blend(
    out: np.ndarray,
    taps: _Taps,
    idx: np.ndarray | slice,
    band: np.ndarray,
    y_first: int,
    decode: Callable[[np.ndarray], np.ndarray],
    border: float,
    rows: tuple[int, ...] = (0, 1),
) -> None:
    """Add to ``out[idx]`` the tap rows ``rows`` (0: the top one, weighted ``1 - fy``; 1: the bottom one, ``fy``)
    of lookups ``idx``, from ``band``."""
    for d in rows:
        weight = taps.fy[idx][:, None] if d else 1.0 - taps.fy[idx][:, None]
        out[idx] += _tap_row(taps, d, idx, band, y_first, decode, border) * weight


def _sample_reader(
    reader: Any,
    n: int,
    coords: Callable[[int, int], tuple[np.ndarray, np.ndarray]],
    wrap: tuple[str, str],
    border: float,
    channels: list[int] | None,
) -> np.ndarray:
    """Bilinear lookups ``coords`` into the image ``reader`` (a :class:`~matremap.svbrdf.textures.MapReader`)
    streams, band by band: float32 [n, C]. Each lookup's two rows of taps are taken from the band holding
    them (lookups sorted by row), blended along t as :func:`sample` does (``top (1 - fy) + bottom fy``, the
    sum taken in either order: the same number)."""
    info = reader.info
    h, w = info.height, info.width
    picked = list(range(info.channels)) if channels is None else list(channels)
    taps = _Taps(n, h, w, wrap, coords)
    out = np.zeros((n, len(picked)), np.float32)
    rows = max(1, BAND_TEXELS // max(w, 1))
    if rows >= h:  # the whole image is one band
        band = reader.read_codes(0, h)
        band = band if channels is None else band[..., picked]
        for a in range(0, n, _CHUNK):
            _blend(out, taps, slice(a, min(n, a + _CHUNK)), band, 0, reader.decode, border)
        return out
    orders, starts = [], []
    for d in (0, 1):
        row = taps.rows(d, slice(None))[0]
        orders.append(np.argsort(row, kind="stable").astype(np.intp if row.size >= 2**31 else np.int32))
        starts.append(np.concatenate([[0], np.cumsum(np.bincount(row, minlength=h))]))
        del row
    for y_first in range(0, h, rows):
        y_last = min(h, y_first + rows)
        band = reader.read_codes(y_first, y_last)
        band = band if channels is None else band[..., picked]
        for d in (0, 1):
            held = orders[d][starts[d][y_first] : starts[d][y_last]]
            for a in range(0, held.size, _CHUNK):  # a chunk of lookups at a time: the temporaries stay small
                _blend(out, taps, held[a : a + _CHUNK], band, y_first, reader.decode, border, (d,))
        del band  # before the next band is read
    return out


def sample_file(
    path: str | os.PathLike,
    colorspace: str,
    s: np.ndarray,
    t: np.ndarray,
    wrap: tuple[str, str] = ("repeat", "repeat"),
    border: float = 0.0,
    channels: list[int] | None = None,
) -> np.ndarray:
    """:func:`sample` of the image file ``path`` (decoded as ``colorspace`` says, as
    :func:`~matremap.svbrdf.textures.read_image` decodes it; ``channels`` of it, all by default), the file read in
    bands of about :data:`BAND_TEXELS` texels: memory is the lookups' and one band's, not the image's. The values
    are :func:`sample`'s on the whole image, to the bit."""
    from matremap.svbrdf.textures import MapReader

    s, t = np.broadcast_arrays(np.asarray(s, dtype=np.float64), np.asarray(t, dtype=np.float64))
    shape, fs, ft = s.shape, s.reshape(-1), t.reshape(-1)
    with MapReader(path, colorspace, colour=True) as r:
        out = _sample_reader(r, fs.size, lambda a, b: (fs[a:b], ft[a:b]), wrap, border, channels)
    return out.reshape(*shape, out.shape[-1])


def bake_file(
    path: str | os.PathLike,
    colorspace: str,
    transform: UVTransform,
    size: tuple[int, int] | None = None,
    channels: list[int] | None = None,
) -> np.ndarray:
    """:func:`bake_image` of the image file ``path`` (decoded as ``colorspace`` says; ``channels`` of it), read in
    bands (:func:`sample_file`): float32 [h, w, C] at ``size`` (the image's own by default), and the lookups'
    coordinates made a chunk at a time, so memory is the output's and a band's whatever the image's size."""
    from matremap.svbrdf.textures import MapReader

    with MapReader(path, colorspace, colour=True) as r:
        h, w = size or (r.info.height, r.info.width)
        if h < 1 or w < 1:
            raise MatremapError(f"a baked map needs a positive size, not {h}x{w}")
        col_s = (np.arange(w) + 0.5) / w
        row_t = (np.arange(h) + 0.5) / h

        def coords(a: int, b: int) -> tuple[np.ndarray, np.ndarray]:
            i = np.arange(a, b)
            return transform.lookup(col_s[i % w], row_t[i // w])

        out = _sample_reader(r, h * w, coords, transform.wrap, transform.border, channels)
    return out.reshape(h, w, out.shape[-1])


def border_cover(
    size: tuple[int, int], s: np.ndarray, t: np.ndarray, wrap: tuple[str, str] = ("repeat", "repeat")
) -> np.ndarray:
    """:func:`sample` of an image of ones of ``size`` (height, width) with border 0 at ``(s, t)``, without the
    image: the share of each lookup's bilinear weight that falls inside it (1 unless a wrap mode is ``border``),
    float32 [..., 1]."""
    h, w = size
    s, t = np.broadcast_arrays(np.asarray(s, dtype=np.float64), np.asarray(t, dtype=np.float64))
    fs, ft = s.reshape(-1), t.reshape(-1)
    taps = _Taps(fs.size, h, w, wrap, lambda a, b: (fs[a:b], ft[a:b]))
    out = np.zeros((fs.size, 1), np.float32)
    ones = np.ones((1, 1, 1), np.float32)
    for d in (0, 1):
        weight = taps.fy[:, None] if d else 1.0 - taps.fy[:, None]
        out += _tap_row(_Ones(taps), d, slice(None), ones, 0, lambda v: v.copy(), 0.0) * weight
    return out.reshape(*s.shape, 1)


class _Ones(_Taps):
    """``taps`` looking every tap up in a one-texel image of ones (for :func:`border_cover`): row and column 0,
    with the taps' own outside masks."""

    def __init__(self, taps: _Taps) -> None:
        self.__dict__.update(taps.__dict__)

    def rows(self, d: int, idx: np.ndarray | slice) -> tuple[np.ndarray, np.ndarray | None]:
        row, out = super().rows(d, idx)
        return np.zeros_like(row), out

    def cols(self, d: int, idx: np.ndarray | slice) -> tuple[np.ndarray, np.ndarray | None]:
        col, out = super().cols(d, idx)
        return np.zeros_like(col), out


def shared_size(needs: list[tuple[int, int]]) -> tuple[int, int]:
    """The one size (height, width) a material's maps are made at: the largest each of them needs (its image's size
    times its tiling, :func:`texels_needed`), capped at :data:`MAX_SIDE` per side."""
    return min(max(n[0] for n in needs), MAX_SIDE), min(max(n[1] for n in needs), MAX_SIDE)


def resampled_note(names: list[str], size: tuple[int, int], needs: list[tuple[int, int]]) -> str:
    """The note that says which textures were resampled to ``size`` (and that it was capped, when it was)."""
    h, w = max(n[0] for n in needs), max(n[1] for n in needs)
    capped = f", capped at {MAX_SIDE} per side from {w}x{h}" if (h, w) != size else ""
    return (
        f"{', '.join(sorted(names))} resampled to {size[1]}x{size[0]} texels (bilinear, with the transform and wrap "
        f"each is read through{capped}): a map set's maps share one size"
    )


def texels_needed(image_size: tuple[int, int], matrix: np.ndarray) -> tuple[int, int]:
    """The map size (height, width) that keeps every texel of an image of ``image_size`` seen through the
    3x3 lookup ``matrix``: the image's size times the lookup's derivatives (a texture tiled 7 times across
    needs 7 times its width), uncapped."""
    h, w = image_size
    m = np.asarray(matrix, dtype=float)
    need_w = float(np.hypot(w * m[0, 0], h * m[1, 0]))  # image texels crossed per unit of the map's s
    need_h = float(np.hypot(w * m[0, 1], h * m[1, 1]))
    return max(1, math.ceil(need_h - 1e-6)), max(1, math.ceil(need_w - 1e-6))


__all__ = [
    "BAND_TEXELS",
    "MAX_SIDE",
    "WRAP_MODES",
    "UVTransform",
    "bake_file",
    "bake_image",
    "border_cover",
    "resampled_note",
    "shared_size",
    "rotate",
    "sample",
    "sample_file",
    "scale",
    "texel_grid",
    "texels_needed",
    "translate",
]
