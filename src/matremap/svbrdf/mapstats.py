"""Streaming statistics of a map set: what a remap needs to know of its maps, in one pass of bands.

:func:`summarise` reads every map of a set band by band (:class:`~matremap.svbrdf.textures.MapReader`,
about a million texels a band) and keeps only what is bounded whatever the map size:

* per parameter map, its **exact minimum, maximum and mean** (over every channel) -- the sweep grid's
  ranges, uniform maps, a mixed metallic map, the brightest diffuse texel, a library node's held value;
* its **median** per channel (the sweep's base values), from a histogram of the values rounded to half
  floats (65,536 bins, each with the exact count and sum of the float32 values that fall in it): the
  median is the mean of the values in the bin holding the middle rank (of the two middle ranks'
  bins, averaged, for an even count, as :func:`numpy.median` does). A bin holds one value of an 8-bit
  file (any two of the 256 decoded levels, sRGB or linear, differ by more than a half-float step), so
  the median of an 8-bit map is exact; for 16-bit and float files it is within one bin's width of
  the true median, at most 2^-10 of the value (0.1 %), far below what moves a sweep's base point;
* **strided samples** (every k-th texel of every k-th row, at most ``limit`` texels a side): exactly
  :func:`matremap.svbrdf.quality.sample` of the whole map, for the gate's map checks and the
  library's domain check;
* for the evaluation renders, the maps **box-filtered** (the mean of each k x k block, as a mip level)
  to at most ``render_side`` texels a side (:func:`render_side`: 1024 for renders up to 256 pixels, the
  default being 160, else four texels per pixel), and the normal map likewise; a map that small already
  is kept as it is, so renders of maps up to that size are unchanged;
* for a parameter that specialises the model (a glTF ``metallic``), the counts of texels at its
  value, holding some metal, some dielectric, or an intermediate mix (:class:`Specialisation`).

Peak memory is a few bands plus the samples, whatever the map size: a 16K x 16K set is summarised in a
few hundred MB (``benchmarks/memory.py``).
"""

from __future__ import annotations

import math
from collections.abc import Collection, Iterator, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from matremap.dialects.mtlx import layer_weights, transmission_weight
from matremap.svbrdf.textures import MapReader, MapSet, map_values

#: the gate's map checks look at this many texels a side (:func:`matremap.svbrdf.quality.sample`)
SAMPLE_LIMIT = 512
#: the library's domain check looks at this many texels a side
LIBRARY_LIMIT = 1024
#: the evaluation renders read maps box-filtered to at most this many texels a side, or four per pixel
#: of the renders if that is more: a sphere of 160 pixels shows half the map's width across its 160
#: pixels (3 texels a pixel at 1024) and its height across them (6 a pixel)
RENDER_SIDE = 1024
#: a map counts as uniform when all its texels are within this of one value (an 8-bit step is 1/255)
TOLERANCE = 0.5 / 255
#: texels per band
BAND_TEXELS = 1 << 20
_HALF_MAX = 65504.0


def band_rows(width: int, multiple: int = 1) -> int:
    """Rows per band: about :data:`BAND_TEXELS` texels (8 to 512 rows), a multiple of ``multiple``."""
    rows = max(8, min(512, BAND_TEXELS // max(width, 1)))
    return multiple * max(1, -(-rows // multiple))


def bands(height: int, rows: int) -> Iterator[tuple[int, int]]:
    """``(y0, y1)`` of every band of ``rows`` rows."""
    for y0 in range(0, height, rows):
        yield y0, min(height, y0 + rows)


def render_side(resolution: int) -> int:
    """The most texels a side the evaluation renders at ``resolution`` pixels read (see :data:`RENDER_SIDE`)."""
    return max(RENDER_SIDE, 4 * int(resolution))


def stride(size: tuple[int, int], limit: int) -> int:
    """The step of :func:`matremap.svbrdf.quality.sample` for a map of ``size`` (H, W)."""
    return max(1, math.ceil(max(size) / limit))


def weight(values: np.ndarray, value: float, other: float) -> np.ndarray:
    """The share of the kind a specialisation ``value`` selects (a glTF metal) per texel: 1 at ``value``,
    0 at ``other`` (the other end of the parameter's range), linear between."""
    return np.clip((np.asarray(values, dtype=np.float32) - other) / (value - other), 0.0, 1.0)


@dataclass
class Specialisation:
    """Texel counts of a map of a parameter that specialises the model (``value``: the specialised kind,
    a glTF metal at metallic 1; ``other``: the other end of its range)."""

    value: float
    other: float
    texels: int = 0
    #: within :data:`TOLERANCE` of ``value``
    at_value: int = 0
    #: holding some of the specialised kind (weight above the tolerance), and some of the other kind
    some_value: int = 0
    some_other: int = 0
    #: holding both (a weight strictly between the tolerances)
    between: int = 0

    def add(self, a: np.ndarray) -> None:
        w = weight(a, self.value, self.other)
        self.texels += int(w.size)
        self.at_value += int(np.count_nonzero(np.abs(a - self.value) <= TOLERANCE))
        some, other = w > TOLERANCE, w < 1.0 - TOLERANCE
        self.some_value += int(np.count_nonzero(some))
        self.some_other += int(np.count_nonzero(other))
        self.between += int(np.count_nonzero(some & other))


class _Histogram:
    """Counts and sums of values per half-float bin, per channel (see the module doc)."""

    #: the half floats' bit patterns in increasing order of value (NaN patterns left out)
    _order: np.ndarray | None = None

    def __init__(self, channels: int) -> None:
        self.counts = np.zeros((channels, 1 << 16), dtype=np.int64)
        self.sums = np.zeros((channels, 1 << 16), dtype=np.float64)

    def add(self, a: np.ndarray) -> None:
        a = a[..., None] if a.ndim == 2 else a
        for c in range(a.shape[-1]):
            v = np.ascontiguousarray(a[..., c], dtype=np.float32).reshape(-1)
            bins = np.clip(v, -_HALF_MAX, _HALF_MAX).astype(np.float16).view(np.uint16)
            self.counts[c] += np.bincount(bins, minlength=1 << 16)
            self.sums[c] += np.bincount(bins, weights=v, minlength=1 << 16)

    @classmethod
    def order(cls) -> np.ndarray:
        if cls._order is None:
            values = np.arange(1 << 16, dtype=np.uint32).astype(np.uint16).view(np.float16).astype(np.float32)
            finite = np.flatnonzero(np.isfinite(values))
            cls._order = finite[np.argsort(values[finite], kind="stable")]
        return cls._order

    def median(self) -> np.ndarray:
        """The median of each channel (see the module doc)."""
        order = self.order()
        out = np.empty(self.counts.shape[0], dtype=np.float64)
        for c in range(self.counts.shape[0]):
            counts, sums = self.counts[c][order], self.sums[c][order]
            cum = np.cumsum(counts)
            n = int(cum[-1])
            ranks = [(n - 1) // 2] if n % 2 else [n // 2 - 1, n // 2]
            picked = [int(np.searchsorted(cum, r, side="right")) for r in ranks]
            out[c] = np.mean([sums[i] / counts[i] for i in picked])
        return out


class _BoxFilter:
    """The mean of each ``k`` x ``k`` block of a map, fed bands whose first row is a multiple of ``k``."""

    def __init__(self, k: int) -> None:
        self.k = k
        self.blocks: list[np.ndarray] = []

    def add(self, band: np.ndarray) -> None:
        if self.k == 1:
            self.blocks.append(np.array(band, dtype=np.float32))
            return
        self.blocks.append(self._sums(self._sums(np.asarray(band, dtype=np.float32), 0), 1))

    def _sums(self, a: np.ndarray, axis: int) -> np.ndarray:
        """The means of runs of ``k`` along ``axis`` (a shorter last run at the edge)."""
        k, n = self.k, a.shape[axis]
        full = n - n % k
        a = np.moveaxis(a, axis, 0)
        parts = [a[:full].reshape(full // k, k, *a.shape[1:]).mean(axis=1)] if full else []
        if full < n:
            parts.append(a[full:].mean(axis=0, keepdims=True))
        return np.moveaxis(np.concatenate(parts), 0, axis)

    def result(self) -> np.ndarray:
        return np.concatenate(self.blocks, axis=0)


@dataclass
class MapStats:
    """What :func:`summarise` keeps of one parameter map."""

    lo: float = math.inf
    hi: float = -math.inf
    total: float = 0.0
    count: int = 0
    #: the median per channel (a float for a scalar map); None when not asked for
    median: Any = None
    specialisation: Specialisation | None = None

    @property
    def mean(self) -> float:
        return self.total / max(self.count, 1)

    @property
    def range(self) -> np.ndarray:
        """``[min, max]``: stands for the map where only its extremes matter."""
        return np.array([self.lo, self.hi])


@dataclass
class MapSummary:
    """A map set's maps as :func:`summarise` read them; constants are included as they are in every
    parameter dict."""

    size: tuple[int, int]
    stats: dict[str, MapStats]
    #: limit -> parameters with each map strided to at most ``limit`` texels a side
    samples: dict[int, dict[str, Any]]
    #: parameters with each map box-filtered for the evaluation renders (None when not asked for)
    render: dict[str, Any] | None = None
    #: the normal map decoded to [-1, 1] at the render size (None without one, or when not asked for)
    render_normal: np.ndarray | None = None
    notes: list[str] = field(default_factory=list)

    @property
    def texels(self) -> int:
        return int(self.size[0] * self.size[1])

    def sample(self, limit: int = SAMPLE_LIMIT) -> dict[str, Any]:
        """The parameters with each map strided to at most ``limit`` texels a side."""
        return self.samples[limit]

    def ranges(self) -> dict[str, np.ndarray]:
        """Each map's ``[min, max]`` (see :attr:`MapStats.range`)."""
        return {name: s.range for name, s in self.stats.items()}


def summarise(
    map_set: MapSet,
    limits: Sequence[int] = (SAMPLE_LIMIT, LIBRARY_LIMIT),
    render_side: int | None = None,
    medians: bool = False,
    names: Collection[str] | None = None,
) -> MapSummary:
    """One streaming pass over ``map_set`` (see the module doc). ``limits``: the strided samples to keep;
    ``render_side``: also box-filter the maps (and the normal map) to at most this many texels a side;
    ``medians``: also take each map's median; ``names``: read only these parameters' maps."""
    spec = map_set.spec
    if names is not None:
        map_set = replace(map_set, maps={k: v for k, v in map_set.maps.items() if k in names})
    height, width = map_set.size
    constants = {k: v for k, v in map_set.constants.items() if k in spec.param_names}
    k = stride(map_set.size, render_side) if render_side else 1
    special = {name: (value, spec.param(name).bounds) for name, value, _ in spec.specialisations}
    through = transmission_weight(spec)
    # a coat, a sheen or a transmission over part of the surface: counted as a specialisation is
    for name in [*layer_weights(spec), *([through] if through else [])]:
        special.setdefault(name, (spec.param(name).bounds[1], spec.param(name).bounds))
    stats = {name: MapStats() for name in map_set.maps}
    hists: dict[str, _Histogram] = {}
    strided: dict[int, dict[str, list[np.ndarray]]] = {lim: {n: [] for n in map_set.maps} for lim in limits}
    steps = {lim: stride(map_set.size, lim) for lim in limits}
    boxes = {n: _BoxFilter(k) for n in map_set.maps} if render_side else {}
    normal_box = _BoxFilter(k) if render_side and map_set.normal is not None else None
    readers = {n: MapReader(p, map_set.colorspace.get(n)) for n, p in map_set.maps.items()}
    normal = MapReader(map_set.normal, "linear", colour=False) if normal_box and map_set.normal else None
    try:
        for y0, y1 in bands(height, band_rows(width, k)):
            for name, r in readers.items():
                a = map_values(spec, name, r.read_rows(y0, y1), r.path, y0)
                s = stats[name]
                s.lo, s.hi = min(s.lo, float(a.min())), max(s.hi, float(a.max()))
                s.total, s.count = s.total + float(a.sum(dtype=np.float64)), s.count + a.size
                if medians:
                    hists.setdefault(name, _Histogram(1 if a.ndim == 2 else a.shape[-1])).add(a)
                if name in special:
                    value, (lo, hi) = special[name]
                    if s.specialisation is None:
                        s.specialisation = Specialisation(value, lo if value == hi else hi)
                    s.specialisation.add(a)
                for lim, step in steps.items():
                    strided[lim][name].append(np.array(a[(-y0) % step :: step, ::step]))
                if name in boxes:
                    boxes[name].add(a)
            if normal is not None and normal_box is not None:
                normal_box.add(normal.read_rows(y0, y1)[..., :3])
    finally:
        for r in readers.values():
            r.close()
        if normal is not None:
            normal.close()
    for name, h in hists.items():
        m = h.median()
        stats[name].median = float(m[0]) if h.counts.shape[0] == 1 else m
    samples = {
        lim: {**constants, **{n: np.concatenate(v, axis=0) for n, v in got.items()}} for lim, got in strided.items()
    }
    summary = MapSummary((height, width), stats, samples)
    if render_side:
        summary.render = {**constants, **{n: b.result() for n, b in boxes.items()}}
        if normal_box is not None:
            from matremap.renderers.textured import decode_normal_map

            summary.render_normal = decode_normal_map(normal_box.result())
        if k > 1:
            h, w = next(iter(summary.render[n] for n in map_set.maps)).shape[:2]
            summary.notes.append(
                f"the evaluation renders read the {height} x {width} maps box-filtered to {h} x {w} (mean of "
                f"{k} x {k} texels)"
            )
    return summary


def with_medians(map_set: MapSet, summary: MapSummary) -> MapSummary:
    """``summary`` with the median of each of its maps, taken in a second pass where it was not taken
    (only a sweep needs them: its base values)."""
    missing = [name for name, stats in summary.stats.items() if stats.median is None]
    if missing:
        got = summarise(map_set, limits=(), medians=True, names=missing)
        for name in missing:
            summary.stats[name].median = got.stats[name].median
    return summary


__all__ = [
    "LIBRARY_LIMIT",
    "RENDER_SIDE",
    "SAMPLE_LIMIT",
    "TOLERANCE",
    "MapStats",
    "MapSummary",
    "Specialisation",
    "band_rows",
    "bands",
    "render_side",
    "stride",
    "summarise",
    "weight",
    "with_medians",
]
