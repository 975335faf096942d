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
KHR_materials_variants extension maps to the material are counted too; :mod:`.uv_coverage` rasterises them.
Anything that cannot be read this way gives no coverage (every texel counts, as before).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from matremap.errors import MatremapError
from matremap.formats.gltf_container import FileReader, is_index
from matremap.formats.uv_coverage import Coverage

#: the accessor component types a TEXCOORD may have (§3.7.2.1): float, normalised unsigned byte and short
_COMPONENTS: dict[int, tuple[type, float | None]] = {
    5126: (np.float32, None),
    5121: (np.uint8, 255.0),
    5123: (np.uint16, 65535.0),
}
_INDICES = {5121: np.uint8, 5123: np.uint16, 5125: np.uint32}
_VARIANTS = "KHR_materials_variants"


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
    ctype = ctype if isinstance(ctype, int) else None  # a malformed one (a list, ...) is refused below
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


__all__ = ["material_coverage"]
