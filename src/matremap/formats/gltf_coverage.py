"""Which texels of a glTF material's textures its surface shows: the UV coverage of the triangles that use it.

A texture atlas is often shared by several materials, each mesh using its own part (Khronos
GlassHurricaneCandleHolder: the glass and the metal frame read one 2048² atlas; the glass's triangles cover 26 % of
it, where metallic is 0 everywhere and the base colour white on 95 % of the texels, and the frame's part holds
metallic 1). Counted whole, the atlas made the glass "vary its metallic map" and refused it; the statistics a
conversion takes of its maps (the typical texel, the ranges it sweeps, the share of metal texels) and the gate's map
checks read texels no triangle shows.

The triangles are read as glTF 2.0 specifies them (§3.7.2 meshes: ``primitives`` with ``mode`` 4, 5 or 6 and the
``TEXCOORD_n`` attribute the textures use, §3.6.2 accessors: float, or normalised unsigned byte or short, with a
``byteStride``; §3.8.3: UV (0, 0) is the first texel of the image, its top-left corner), and those the
KHR_materials_variants extension maps to the material are counted too. They are rasterised at most :data:`COARSE`
texels a side, every texel a triangle touches marked, and scaled up to the maps' size. The texels beside an island
(its gutter, which bilinear filtering reads at its edge) are then filled from the island's edge
(:func:`fill_uncovered`), as atlas bakers pad them, so the coverage is not grown into them. A triangle that spans a
whole UV tile or more (a tiled texture) covers everything. Anything that cannot be read this way gives no coverage
(every texel counts, as before).
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np

from matremap.errors import MatremapError
from matremap.formats.gltf_container import FileReader, is_index

#: the raster's longest side (texels): maps up to this size are marked texel by texel, larger ones in blocks
COARSE = 1024
#: triangles whose bounding box spans at most this many coarse texels a side are marked whole (their box), the rest
#: rasterised exactly: the box is at most a texel or two wider than the triangle, which the growth covers anyway
SMALL = 3
#: the accessor component types a TEXCOORD may have (§3.7.2.1): float, normalised unsigned byte and short
_COMPONENTS: dict[int, tuple[type, float | None]] = {
    5126: (np.float32, None),
    5121: (np.uint8, 255.0),
    5123: (np.uint16, 65535.0),
}
_INDICES = {5121: np.uint8, 5123: np.uint16, 5125: np.uint32}
_VARIANTS = "KHR_materials_variants"


class Coverage:
    """The UV triangles of one material (``uv`` [T, 3, 2]) and what they cover at a map size (:meth:`mask`)."""

    def __init__(self, uv: np.ndarray) -> None:
        self.uv = np.asarray(uv, dtype=np.float64)

    def mask(self, size: tuple[int, int]) -> np.ndarray | None:
        """The texels of a map of ``size`` (H, W) the triangles show (bool [H, W]), or None when they show them all
        (a triangle spans a whole UV tile: a tiled texture)."""
        if self.uv.size == 0:
            return None
        span = self.uv.max(axis=1) - self.uv.min(axis=1)
        if np.any(span >= 1.0):
            return None
        h, w = size
        scale = min(1.0, COARSE / max(h, w))
        ch, cw = max(1, round(h * scale)), max(1, round(w * scale))
        coarse = np.zeros((ch, cw), dtype=bool)
        for tris in _tiles(self.uv):
            _mark(coarse, tris[..., 1] * ch, tris[..., 0] * cw)
        rows = np.minimum((np.arange(h) + 0.5) * ch / h, ch - 1).astype(np.intp)
        cols = np.minimum((np.arange(w) + 0.5) * cw / w, cw - 1).astype(np.intp)
        full = coarse[np.ix_(rows, cols)]
        return None if full.all() else full


def _tiles(uv: np.ndarray) -> Iterator[np.ndarray]:
    """The triangles moved into the UV tile [0, 1)² (a texture repeats, §3.8.4 REPEAT, the default wrap): each once
    per tile its bounding box reaches (a triangle spans less than one tile a side: two tiles or four)."""
    lo = np.floor(uv.min(axis=1))  # [T, 2]
    hi = np.maximum(lo, np.ceil(uv.max(axis=1)) - 1.0)  # a UV of exactly 1 is the tile's far edge, not the next
    for du in (0, 1):
        for dv in (0, 1):
            step = np.array([du, dv], dtype=np.float64)
            pick = np.all(lo + step <= hi, axis=1)
            if np.any(pick):
                yield uv[pick] - (lo[pick] + step)[:, None, :]


def _mark(grid: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> None:
    """Mark the texels of ``grid`` that triangles (texel coordinates ``rows``, ``cols`` [T, 3]) touch."""
    from skimage.draw import polygon

    h, w = grid.shape
    r0 = np.clip(np.floor(rows.min(axis=1)), 0, h - 1).astype(np.intp)
    r1 = np.clip(np.floor(rows.max(axis=1)), 0, h - 1).astype(np.intp)
    c0 = np.clip(np.floor(cols.min(axis=1)), 0, w - 1).astype(np.intp)
    c1 = np.clip(np.floor(cols.max(axis=1)), 0, w - 1).astype(np.intp)
    small = (r1 - r0 < SMALL) & (c1 - c0 < SMALL)
    for dr in range(SMALL):
        for dc in range(SMALL):
            r, c = r0[small] + dr, c0[small] + dc
            keep = (r <= r1[small]) & (c <= c1[small])
            grid[r[keep], c[keep]] = True
    for t in np.flatnonzero(~small):
        rr, cc = polygon(rows[t], cols[t], shape=grid.shape)
        grid[rr, cc] = True
        grid[np.clip(rows[t].astype(np.intp), 0, h - 1), np.clip(cols[t].astype(np.intp), 0, w - 1)] = True


def material_coverage(reader: FileReader, material: int, uv_set: int) -> Coverage | None:
    """The UV triangles of every mesh primitive drawn with ``material`` (its ``material``, or a
    KHR_materials_variants mapping to it) on ``TEXCOORD_<uv_set>``; None when no primitive draws it, one draws points
    or lines, or their UVs cannot be read (every texel counts then)."""
    doc = reader.doc.json
    meshes: list[Any] = doc["meshes"] if isinstance(doc.get("meshes"), list) else []
    found: list[np.ndarray] = []
    try:
        for m, mesh in enumerate(meshes):
            prims = mesh.get("primitives") if isinstance(mesh, dict) else None
            for p, prim in enumerate(prims if isinstance(prims, list) else []):
                if not isinstance(prim, dict) or material not in _materials(prim):
                    continue
                tris = _uv_triangles(reader, prim, uv_set, f"meshes[{m}].primitives[{p}]")
                if tris is None:
                    return None
                found.append(tris)
    except MatremapError:
        return None
    return Coverage(np.concatenate(found)) if found else None


def _materials(prim: dict[str, Any]) -> set[int]:
    """The materials a primitive is drawn with: its own and those KHR_materials_variants maps to it."""
    out = {prim["material"]} if is_index(prim.get("material")) else set()
    ext = prim.get("extensions")
    variants = ext.get(_VARIANTS) if isinstance(ext, dict) else None
    mappings = variants.get("mappings") if isinstance(variants, dict) else None
    for mapping in mappings if isinstance(mappings, list) else []:
        if isinstance(mapping, dict) and is_index(mapping.get("material")):
            out.add(mapping["material"])
    return out


def _uv_triangles(reader: FileReader, prim: dict[str, Any], uv_set: int, where: str) -> np.ndarray | None:
    """A primitive's triangles in UV space [T, 3, 2] (§3.7.2.1 modes 4 triangles, 5 strip, 6 fan), None for points
    and lines."""
    mode = prim.get("mode", 4)
    if mode not in (4, 5, 6):
        return None
    attrs = prim.get("attributes")
    key = f"TEXCOORD_{uv_set}"
    if not isinstance(attrs, dict) or key not in attrs:
        raise MatremapError(f"{reader.path}: {where} has no {key}")
    uv = _accessor(reader, attrs[key], f"{where}.attributes.{key}", uv=True)
    if "indices" in prim:
        idx = _accessor(reader, prim["indices"], f"{where}.indices", uv=False).astype(np.int64).reshape(-1)
    else:
        idx = np.arange(len(uv), dtype=np.int64)
    if idx.size and (idx.min() < 0 or idx.max() >= len(uv)):
        raise MatremapError(f"{reader.path}: {where}.indices point past its {len(uv)} vertices")
    tri: np.ndarray = np.zeros((0, 3), dtype=np.int64)
    if mode == 4:
        tri = idx[: idx.size - idx.size % 3].reshape(-1, 3)
    elif idx.size >= 3 and mode == 5:  # strip: (i, i+1, i+2), winding irrelevant here
        tri = np.stack([idx[:-2], idx[1:-1], idx[2:]], axis=1)
    elif idx.size >= 3:  # fan: (0, i+1, i+2)
        tri = np.stack([np.full(idx.size - 2, idx[0]), idx[1:-1], idx[2:]], axis=1)
    return uv[tri.astype(np.int64)]


def _accessor(reader: FileReader, index: Any, where: str, uv: bool) -> np.ndarray:
    """An accessor's elements (§3.6.2): ``uv`` a VEC2 of float or normalised unsigned byte / short ([N, 2] float),
    else a SCALAR of unsigned integers (indices, [N]). Sparse accessors are refused (MatremapError)."""
    acc = reader.item("accessors", index, where)
    if "sparse" in acc or "bufferView" not in acc:
        raise MatremapError(f"{reader.path}: accessors[{index}] is sparse or has no bufferView")
    ctype, count, kind = acc.get("componentType"), acc.get("count"), acc.get("type")
    norm: float | None = None
    dtype: np.dtype[Any]
    if uv:
        if kind != "VEC2" or ctype not in _COMPONENTS or (ctype != 5126 and not acc.get("normalized")):
            raise MatremapError(f"{reader.path}: accessors[{index}] is not a VEC2 of float or normalised integers")
        dtype, norm = np.dtype(_COMPONENTS[ctype][0]), _COMPONENTS[ctype][1]
        n = 2
    else:
        if kind != "SCALAR" or ctype not in _INDICES:
            raise MatremapError(f"{reader.path}: accessors[{index}] is not a SCALAR of unsigned integers")
        dtype, n = np.dtype(_INDICES[ctype]), 1
    if not is_index(count):
        raise MatremapError(f"{reader.path}: accessors[{index}].count is not a count")
    count = int(count or 0)
    view = reader.item("bufferViews", acc["bufferView"], where)
    data = np.frombuffer(reader.buffer_view(acc["bufferView"], where), dtype=np.uint8)
    size = dtype.itemsize * n
    stride, offset = view.get("byteStride") or size, acc.get("byteOffset", 0)
    if not is_index(offset) or not is_index(stride) or stride < size:
        raise MatremapError(f"{reader.path}: accessors[{index}] has a bad byteOffset or byteStride")
    if count == 0:
        return np.zeros((0, n) if uv else (0,), dtype=np.float64 if uv else np.int64)
    if offset + stride * (count - 1) + size > data.size:
        raise MatremapError(f"{reader.path}: accessors[{index}] runs past the end of its bufferView")
    rows = np.lib.stride_tricks.as_strided(data[offset:], shape=(count, size), strides=(stride, 1))
    out = np.ascontiguousarray(rows).view(dtype).reshape(count, n)
    if not uv:
        return out.reshape(-1)
    values = out.astype(np.float64) / norm if norm else out.astype(np.float64)
    if not np.all(np.isfinite(values)):
        raise MatremapError(f"{reader.path}: accessors[{index}] holds non-finite UVs")
    return values


def fill_uncovered(image: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """``image`` [H, W, C] with each texel outside ``mask`` replaced by its nearest covered texel (an atlas's dilation
    padding, carried over all the rest): what no triangle shows then holds only values the surface shows."""
    from scipy.ndimage import distance_transform_edt

    if mask.all() or not mask.any():
        return image
    _, (iy, ix) = distance_transform_edt(~mask, return_distances=True, return_indices=True)
    return image[iy, ix]


def covered_share(mask: np.ndarray | None) -> float:
    """The fraction of texels a coverage mask keeps (1 for None)."""
    return 1.0 if mask is None else float(np.count_nonzero(mask)) / max(mask.size, 1)


__all__ = ["COARSE", "Coverage", "covered_share", "fill_uncovered", "material_coverage"]
