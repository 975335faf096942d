"""Which texels of a USD material's textures its surface shows: the st coverage of the meshes bound to it.

As for glTF (:mod:`matremap.formats.gltf_coverage`, whose rasteriser this shares): a texture is often an atlas
shared by several materials. The faces drawn with a material are those of every ``UsdGeom.Mesh`` whose bound
material (``UsdShadeMaterialBindingAPI.ComputeBoundMaterial``, the full purpose) it is, and those of its
``GeomSubset`` s of the ``materialBind`` family bound to it (USD's per-face bindings). Their ``st`` primvar (the one
the textures read) is taken with its interpolation (``vertex``, ``varying``, ``faceVarying``, ``uniform``,
``constant``) and indices (``ComputeFlattened``), each polygon split into a fan of triangles, and ``t`` flipped:
UsdUVTexture's st origin is the image's lower-left corner, the maps' row 0 its top. Anything that cannot be read so
gives no coverage (every texel counts).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from matremap.formats.uv_coverage import Coverage


def material_coverage(pxr: Any, stage: Any, material: Any, primvar: str = "st") -> Coverage | None:
    """The st triangles of every mesh face drawn with ``material`` (a UsdShade.Material), as a :class:`Coverage`;
    None when no mesh is bound to it or one has no readable ``primvar`` (every texel counts then)."""
    target = material.GetPath()
    found: list[np.ndarray] = []
    for prim in pxr.Usd.PrimRange(stage.GetPseudoRoot(), pxr.Usd.TraverseInstanceProxies()):
        if not prim.IsA(pxr.UsdGeom.Mesh):
            continue
        faces = _faces(pxr, prim, target)
        if faces is not None and faces.size == 0:
            continue
        tris = _st_triangles(pxr, pxr.UsdGeom.Mesh(prim), primvar, faces)
        if tris is None:
            return None
        found.append(tris)
    return Coverage(np.concatenate(found)) if found else None


def _bound(pxr: Any, prim: Any) -> Any:
    """The path of the material bound to a prim (None where none is)."""
    material = pxr.UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()[0]
    return material.GetPath() if material else None


def _faces(pxr: Any, prim: Any, target: Any) -> np.ndarray | None:
    """The face indices of a mesh drawn with ``target``: None for all of them (the mesh is bound to it and has no
    materialBind subset bound elsewhere), else those of its subsets bound to it (empty: none)."""
    subsets = pxr.UsdGeom.Subset.GetGeomSubsets(pxr.UsdGeom.Imageable(prim), "face", "materialBind")
    own = _bound(pxr, prim) == target
    if not subsets:
        return None if own else np.zeros(0, dtype=np.int64)
    picked = [
        np.asarray(s.GetIndicesAttr().Get() or [], dtype=np.int64)
        for s in subsets
        if _bound(pxr, s.GetPrim()) == target
    ]
    if own:  # faces in no subset take the mesh's own binding
        counts = prim.GetAttribute("faceVertexCounts").Get() or []
        inside = np.concatenate([np.asarray(s.GetIndicesAttr().Get() or [], np.int64) for s in subsets])
        picked.append(np.setdiff1d(np.arange(len(counts)), inside))
    return np.unique(np.concatenate(picked)) if picked else np.zeros(0, dtype=np.int64)


def _st_triangles(pxr: Any, mesh: Any, primvar: str, faces: np.ndarray | None) -> np.ndarray | None:
    """A mesh's faces (all, or ``faces``) as st triangles [T, 3, 2] in the maps' orientation (t flipped)."""
    counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get() or [], dtype=np.int64)
    indices = np.asarray(mesh.GetFaceVertexIndicesAttr().Get() or [], dtype=np.int64)
    pv = pxr.UsdGeom.PrimvarsAPI(mesh.GetPrim()).GetPrimvar(primvar)
    if not pv or counts.size == 0 or counts.sum() != indices.size or np.any(counts < 0):
        return None
    values = pv.ComputeFlattened()
    if values is None:
        return None
    st = np.asarray(values, dtype=np.float64).reshape(-1, 2)
    kind = pv.GetInterpolation()
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    face_of_corner = np.repeat(np.arange(counts.size), counts)
    if kind == "faceVarying":
        per_corner = np.arange(indices.size)
    elif kind in ("vertex", "varying"):
        per_corner = indices
    elif kind == "uniform":
        per_corner = face_of_corner
    elif kind == "constant":
        per_corner = np.zeros(indices.size, dtype=np.int64)
    else:
        return None
    if per_corner.size and (per_corner.max() >= len(st) or per_corner.min() < 0):
        return None
    keep = np.ones(counts.size, dtype=bool) if faces is None else np.isin(np.arange(counts.size), faces)
    n = np.where(keep, np.maximum(counts - 2, 0), 0)  # a fan of n - 2 triangles per polygon
    face = np.repeat(np.arange(counts.size), n)
    k = np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n)  # the triangle's place in its fan
    corners = np.stack([starts[face], starts[face] + k + 1, starts[face] + k + 2], axis=1)
    uv = st[per_corner[corners]]
    uv[..., 1] = 1.0 - uv[..., 1]
    return uv


__all__ = ["material_coverage"]
