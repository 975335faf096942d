"""Mitsuba 3 textures as the renderer samples them: ``bitmap`` (raw, to_uv, wrap_mode), ``checkerboard``,
and the shading normal of a ``bumpmap``, baked onto plain maps (:mod:`matremap.formats.bake`).

Sources: Mitsuba 3.9 ``src/textures/bitmap.cpp``, ``src/textures/checkerboard.cpp``,
``src/bsdfs/bumpmap.cpp`` and ``src/core/parser.cpp`` (``<transform>``), checked against Mitsuba 3.9.1
in tests/test_mitsuba_textures.py.

* **UVs.** A bitmap's ``uv`` (0, 0) is the first stored row's first texel, the image's top left
  (:class:`~matremap.formats.bake.UVTransform` origin ``"top-left"``); ``to_uv`` maps the surface's uv
  to the image's. A ``<transform>`` is composed as Mitsuba does (each operation multiplies from the left)
  into a 4x4 matrix, of which a texture keeps rows and columns 0, 1 and the translation column 3
  (``Transform::extract``): a 3x3 ``<matrix>`` loses its third column.
* **Wrap modes** ``repeat``, ``mirror``, ``clamp``; bilinear filtering between texel centres
  (``filter_type="nearest"`` is baked bilinearly, with a note).
* **Values.** 8/16-bit files are decoded from sRGB unless ``raw``; float files are linear. A scalar
  parameter reads a 3-channel image's luminance (Rec. 709 Y, ``eval_1``); an alpha channel is dropped.
* **checkerboard**: with ``(u, v)`` = ``to_uv`` of the surface uv, a texel shows ``color0`` where
  ``frac(u) > 0.5`` equals ``frac(v) > 0.5`` and ``color1`` elsewhere -- for colour parameters
  (``eval``); Mitsuba's ``eval_1`` (scalar parameters) swaps the two, and so does the bake. A colour
  read as a scalar is the mean of its channels (``src/spectra/srgb.cpp``, ``eval_1``).
* **bumpmap** (over a bitmap height: Mitsuba's other textures have no ``eval_1_grad``): the shading
  normal of ``dp_du' = dp_du + h_u n``, ``dp_dv' = dp_dv + h_v n`` with
  ``(h_u, h_v) = scale * grad h`` (``BumpMap::frame``), expressed in the tangent frame
  ``(s, t = n x s, n)`` of a surface whose ``|dp/du| = |dp/dv| = 1`` and whose ``dp/du x dp/dv`` points
  into the surface (uv laid out as glTF and Mitsuba's sphere have them, v growing down the image):
  ``n_t = normalize(-h_u, h_v, 1)``, stored as ``0.5 n_t + 0.5``. On a real mesh Mitsuba's bump
  strength scales with ``1/|dp/du|``; the note says so.

A texture is read into a :class:`TextureSource`; :meth:`TextureSource.ref` turns it into the
:class:`~matremap.formats.asset.TextureRef` of a map of a given size (plain when the file can be used as
it is, else with a ``bake``).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np

from matremap.errors import MatremapError
from matremap.formats.asset import TextureRef
from matremap.formats.bake import UVTransform, bake_file, texel_grid

#: Rec. 709 luminance, Mitsuba's ``luminance()`` of an RGB colour
LUMINANCE = np.array([0.212671, 0.715160, 0.072169])
#: the size a procedural texture is baked at when no bitmap of the material gives one
DEFAULT_BAKE_SIZE = (512, 512)
WRAP = ("repeat", "mirror", "clamp")


@dataclass(frozen=True)
class TextureSource:
    """A texture of a material file: where its values come from and how to sample them.

    ``path``: the file (a procedural texture's is the scene file); ``size``: (height, width) of the
    image, None for a procedural texture; ``plain``: the TextureRef when the file is the map as it is;
    ``sample``: a function of the output size returning linear float32 [H, W, C] values."""

    path: Path
    size: tuple[int, int] | None
    sample: Callable[[tuple[int, int]], np.ndarray]
    plain: TextureRef | None = None

    def ref(self, size: tuple[int, int]) -> TextureRef:
        """The TextureRef of this texture on a map of ``size``."""
        if self.plain is not None and self.size == size:
            return self.plain
        return TextureRef(self.path, None, "linear", bake=partial(_checked, self.sample, size))

    def values(self, size: tuple[int, int]) -> np.ndarray:
        return _checked(self.sample, size)


def _checked(sample: Callable[[tuple[int, int]], np.ndarray], size: tuple[int, int]) -> np.ndarray:
    out = np.asarray(sample(size), dtype=np.float32)
    return out if out.ndim == 3 else out[..., None]


def constant_source(path: Path, value: np.ndarray) -> TextureSource:
    """A uniform value as a texture (for blends of a texture with a constant)."""
    v = np.asarray(value, dtype=np.float32).reshape(-1)
    return TextureSource(path, None, lambda size: np.broadcast_to(v, (*size, v.size)).copy())


# -- <transform> ---------------------------------------------------------------------------------


def _vector(el: ET.Element, default: float) -> np.ndarray:
    value = el.get("value")
    if value is not None:
        parts = [float(x) for x in value.replace(",", " ").split()]
        if len(parts) == 1:
            parts *= 3
        if len(parts) != 3:
            raise ValueError("value needs 1 or 3 numbers")
        return np.array(parts)
    return np.array([float(el.get(k, default)) for k in "xyz"])


def _rotation(axis: np.ndarray, degrees: float) -> np.ndarray:
    """Rodrigues' rotation about ``axis`` by ``degrees`` (Mitsuba's ``Transform::rotate``)."""
    norm = np.linalg.norm(axis)
    if norm == 0:
        raise ValueError("rotation axis cannot be zero")
    x, y, z = axis / norm
    c, s = np.cos(np.radians(degrees)), np.sin(np.radians(degrees))
    k = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
    m = np.eye(4)
    m[:3, :3] = c * np.eye(3) + s * k + (1 - c) * np.outer([x, y, z], [x, y, z])
    return m


def transform_matrix(el: ET.Element, what: str) -> np.ndarray:
    """The 4x4 matrix of a ``<transform>`` element (operations applied in order)."""
    m = np.eye(4)
    try:
        for op in el:
            if not isinstance(op.tag, str):
                continue
            step = np.eye(4)
            if op.tag == "translate":
                step[:3, 3] = _vector(op, 0.0)
            elif op.tag == "scale":
                step[:3, :3] = np.diag(_vector(op, 1.0))
            elif op.tag == "rotate":
                step = _rotation(np.array([float(op.get(k, 0.0)) for k in "xyz"]), float(op.get("angle", "x")))
            elif op.tag == "matrix":
                vals = [float(x) for x in (op.get("value") or "").replace(",", " ").split()]
                if len(vals) not in (9, 16):
                    raise ValueError(f"a matrix needs 9 or 16 values, not {len(vals)}")
                n = 4 if len(vals) == 16 else 3
                step[:n, :n] = np.array(vals).reshape(n, n)
            else:
                raise ValueError(f"<{op.tag}> is not a transform a texture can take")
            m = step @ m
    except ValueError as e:
        raise MatremapError(f"{what}: {e}") from None
    if not np.all(np.isfinite(m)):
        raise MatremapError(f"{what}: the transform is not finite")
    return m


def uv_matrix(el: ET.Element, what: str) -> np.ndarray:
    """The 3x3 UV matrix a texture takes from a ``<transform name="to_uv">`` (``Transform::extract``)."""
    m = transform_matrix(el, what)
    return np.array([[m[0, 0], m[0, 1], m[0, 3]], [m[1, 0], m[1, 1], m[1, 3]], [0.0, 0.0, 1.0]])


# -- bitmap ----------------------------------------------------------------------------------------


def _bitmap_sample(path: Path, colorspace: str, luminance: bool, uv: UVTransform, size: tuple[int, int]) -> np.ndarray:
    """The bitmap's colour (its luminance when ``luminance``) as ``uv`` shows it on a map of ``size``, the file read
    in bands (:func:`~matremap.formats.bake.bake_file`: memory is the map's, not the image's)."""
    from matremap.svbrdf.textures import image_info

    channels = [0, 1, 2] if image_info(path, colorspace).channels >= 3 else None
    image = bake_file(path, colorspace, uv, size, channels=channels)
    if channels is not None and luminance:  # linear in the channels: the same before or after the lookup
        image = (image @ LUMINANCE.astype(np.float32))[..., None]
    return image


def bitmap_source(
    path: Path, raw: bool, scalar: bool, matrix: np.ndarray | None, wrap: str, notes: list[str], param: str
) -> TextureSource:
    """The texture of a ``bitmap`` for parameter ``param`` (``scalar``: one channel)."""
    from matremap.svbrdf.textures import image_info

    info = image_info(path, colour=not scalar)
    colorspace = "linear" if raw or not info.integer else "srgb"
    uv = UVTransform(np.eye(3) if matrix is None else matrix, "top-left", (wrap, wrap))
    luminance = scalar and info.channels >= 3
    sample = partial(_bitmap_sample, path.resolve(), colorspace, luminance, uv)
    size = (info.height, info.width)
    if luminance:
        notes.append(f"{path.name} for {param}: a scalar parameter reads an RGB image's luminance, as Mitsuba does")
    if not uv.identity:
        notes.append(f"{path.name} for {param}: its to_uv transform is baked into the map ({wrap} wrap)")
    plain = None if (luminance or not uv.identity) else TextureRef(path.resolve(), None, colorspace)
    return TextureSource(path.resolve(), size, sample, plain)


# -- checkerboard --------------------------------------------------------------------------------------


def _checker_sample(
    matrix: np.ndarray, colour0: np.ndarray, colour1: np.ndarray, swap: bool, size: tuple[int, int]
) -> np.ndarray:
    s, t = texel_grid(size)
    u = matrix[0, 0] * s + matrix[0, 1] * t + matrix[0, 2]
    v = matrix[1, 0] * s + matrix[1, 1] * t + matrix[1, 2]
    same = ((u - np.floor(u)) > 0.5) == ((v - np.floor(v)) > 0.5)
    first = ~same if swap else same
    return np.where(first[..., None], colour0[None, None, :], colour1[None, None, :]).astype(np.float32)


def checkerboard_source(
    path: Path, colour0: np.ndarray, colour1: np.ndarray, scalar: bool, matrix: np.ndarray | None
) -> TextureSource:
    """Mitsuba's ``checkerboard`` (module doc): colours as 1 or 3 linear values."""
    c0, c1 = (np.asarray(c, dtype=float).reshape(-1) for c in (colour0, colour1))
    if scalar:  # Mitsuba's constant colour texture answers eval_1 with the mean of its channels
        c0, c1 = (np.array([float(c.mean())]) for c in (c0, c1))
    elif c0.size != c1.size:
        c0, c1 = (np.repeat(c, 3) if c.size == 1 else c for c in (c0, c1))
    m = np.eye(3) if matrix is None else matrix
    return TextureSource(path.resolve(), None, partial(_checker_sample, m, c0, c1, scalar))


# -- bumpmap --------------------------------------------------------------------------------------------


def _bump_sample(height: TextureSource, scale: float, size: tuple[int, int]) -> np.ndarray:
    h = height.values(size)[..., 0].astype(np.float64)
    rows, cols = size
    # central differences (the mean of the bilinear derivative on both sides of a texel centre), per unit uv
    dh_dv = (np.roll(h, -1, axis=0) - np.roll(h, 1, axis=0)) * (rows / 2.0)
    dh_du = (np.roll(h, -1, axis=1) - np.roll(h, 1, axis=1)) * (cols / 2.0)
    n = np.stack([-scale * dh_du, scale * dh_dv, np.ones_like(h)], axis=-1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    return (0.5 * n + 0.5).astype(np.float32)


def bump_normal_source(height: TextureSource, scale: float) -> TextureSource:
    """The tangent-space normal map of Mitsuba's ``bumpmap`` over ``height`` (module doc)."""
    return TextureSource(height.path, height.size, partial(_bump_sample, height, float(scale)))


__all__ = [
    "DEFAULT_BAKE_SIZE",
    "LUMINANCE",
    "WRAP",
    "TextureSource",
    "bitmap_source",
    "bump_normal_source",
    "checkerboard_source",
    "constant_source",
    "transform_matrix",
    "uv_matrix",
]
