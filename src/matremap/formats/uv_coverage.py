"""The texels a surface shows of its textures: UV triangles rasterised into a mask, whatever file they come from.

A texture atlas is often shared by several materials, each mesh using its own part; the statistics a conversion
takes of its maps (the typical texel, the ranges it sweeps, the share of metal texels) and the gate's map checks
should read only the texels the material's triangles show. The readers (:mod:`.gltf_coverage`,
:mod:`.usd_coverage`) give a material's UV triangles; here they are rasterised at most :data:`COARSE` texels a side,
every texel a triangle touches marked, and scaled up to the maps' size (UV (0, 0) the image's top-left texel, a
texture repeating: glTF 2.0 §3.8.3-3.8.4, USD's st with t flipped by its reader). The texels beside an island (its
gutter, which bilinear filtering reads at its edge) are then filled from the island's edge (:func:`fill_uncovered`),
as atlas bakers pad them, so the coverage is not grown into them. A triangle that spans a whole UV tile or more (a
tiled texture) covers everything.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

#: the raster's longest side (texels): maps up to this size are marked texel by texel, larger ones in blocks
COARSE = 1024
#: triangles whose bounding box spans at most this many coarse texels a side are marked whole (their box), the rest
#: rasterised exactly: the box is at most a texel or two wider than the triangle, which the growth covers anyway
SMALL = 3


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


__all__ = ["COARSE", "SMALL", "Coverage", "covered_share", "fill_uncovered"]
