"""Map sets that mix two kinds of material per texel: metal and dielectric texels (a glTF metallic map holding
both 0 and 1), or texels with and without a layer (a coat weight map: ClearCoatTest's Partial_Coated).

One transform maps one kind of material: a glTF metal's base colour is its F0, a dielectric's is its
albedo. :func:`remap_mixed` therefore converts the map set twice, each time with the mixed parameter
held at one end of its range (metallic 1: the metal; metallic 0: the dielectric), through the
transform of that kind, and blends the two results per texel by the source's own map:

    out = w * metal + (1 - w) * dielectric,    w = (m - m_dielectric) / (m_metal - m_dielectric)

as the glTF specification mixes its two BRDFs (``material = mix(dielectric_brdf, metal_brdf,
metallic)``); intermediate texels are blended too. A target parameter that is a constant on both
sides stays a constant when the two agree, else it becomes a map (a glTF target's own metallic
becomes the source's map); one that only one kind uses (a glTF target's ior, which a metal ignores)
takes that kind's value everywhere. The texels outside the training domain are those that take more than
:data:`OUTSIDE_SHARE` of their weight from kinds whose transforms are outside their domain there (two kinds: any
share; among levels a spline gives every level some weight at nearly every texel, and one level's extrapolation
would otherwise mark the whole map).

The target must express both kinds: one without a diffuse parameter (a conductor) cannot draw the
dielectric texels and is refused before any sweep.

A layer's weight map (:func:`layer_parameter`: a coat or sheen weight, :func:`~matremap.dialects.mtlx.layer_weights`)
is blended the same way: the map set converted with the layer at its full weight (its layer fitted once and held,
:func:`matremap.remap.hold_layers`) and without it, blended by the weight, as every layered model mixes its coat and
sheen in linearly by their weight (the target's own weight becomes the source's map times its fitted value). A kind
with no maps left (a uniform base under a coat mask) is fitted as one uniform material.

The blend reads and writes the maps in bands of rows: memory does not grow with the map size; the shares of
each kind come from counts taken while the maps were summarised (:class:`~matremap.svbrdf.mapstats.Specialisation`).
"""

from __future__ import annotations

import json
import os
import shutil
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from matremap.core.imageio import write_text
from matremap.core.models import ModelSpec
from matremap.dialects import get_model, list_models
from matremap.dialects.mtlx import transmission_weight
from matremap.errors import MatremapError
from matremap.regress import quantities as qty
from matremap.svbrdf.convert import MANIFEST_NAME, MASK_NAME, source_reference
from matremap.svbrdf.mapstats import TOLERANCE, MapSummary, Specialisation, band_rows, bands, weight
from matremap.svbrdf.textures import ImageInfo, MapReader, MapSet, MapWriter, load_map_set, map_values

#: the hidden folder inside the staging folder that holds the two kinds while they are converted
KINDS = ".kinds"

#: (map set held at one kind, output folder) -> the converted map set
ConvertKind = Callable[[MapSet, Path], MapSet]
#: (map set held at one kind, its parameter arrays) -> None, or raises what a sweep would fail on
CheckKind = Callable[[MapSet, Mapping[str, Any]], None]


@dataclass(frozen=True)
class Mixed:
    """A specialisation parameter whose map mixes values: ``metal`` is the value that specialises the
    model (no diffuse part), ``dielectric`` the other end of its range; ``counts``: its texels by kind.
    The metal's share of a texel is :meth:`weight` of its value."""

    name: str
    metal: float
    dielectric: float
    counts: Specialisation
    #: the two kinds' names: the one at ``metal``'s value, the one at ``dielectric``'s (a layer: the layer's name
    #: and "bare")
    kinds: tuple[str, str] = ("metal", "dielectric")
    #: the layer whose weight the parameter is (None: a specialisation, metal and dielectric)
    layer: str | None = None
    #: parameters the first kind holds at these values whatever the source's maps say: a metal's kind is converted
    #: without the material's transmission (a metal lets no light through in any model here)
    first_holds: Mapping[str, Any] = field(default_factory=dict)

    def weight(self, values: np.ndarray) -> np.ndarray:
        """The metal's share per texel of the mixed parameter's ``values``, in [0, 1]."""
        return weight(values, self.metal, self.dielectric)

    def weights(self, values: np.ndarray) -> list[np.ndarray]:
        """Each kind's share per texel, in the order of :attr:`kinds` (they sum to 1)."""
        w = self.weight(values)
        return [w, 1.0 - w]

    def value(self, kind: str) -> float:
        """The mixed parameter's value that holds a texel wholly at ``kind``."""
        return self.metal if kind == self.kinds[0] else self.dielectric

    @property
    def inputs(self) -> tuple[str, ...]:
        """The source maps the weights are read from."""
        return (self.name,)

    def params(self, kind: str) -> dict[str, Any]:
        """The parameters a ``kind``'s map set holds in place of :attr:`inputs` (and, for the first kind,
        :attr:`first_holds`)."""
        return {**(self.first_holds if kind == self.kinds[0] else {}), self.name: self.value(kind)}

    def band_weights(self, values: Mapping[str, np.ndarray]) -> tuple[list[np.ndarray], list[np.ndarray] | None]:
        """Each kind's weights per texel from the :attr:`inputs` maps' ``values``: for the target's numbers, and
        for its colours channel by channel (None: the same)."""
        return self.weights(values[self.name]), None

    def describe(self) -> str:
        """How the texels divide between the kinds, for the log."""
        first, second = self.kinds
        return f"{first} on {100 * self.share(first):.0f}%, {second} on {100 * self.share(second):.0f}% of the texels"

    def share(self, kind: str) -> float:
        """The fraction of texels that hold some of ``kind`` (one of :attr:`kinds`)."""
        n = self.counts.some_value if kind == self.kinds[0] else self.counts.some_other
        return n / max(self.counts.texels, 1)

    def pure(self, kind: str) -> bool:
        """Whether every texel holding some of ``kind`` holds it whole (no intermediate values)."""
        return self.counts.between == 0


@dataclass(frozen=True)
class Levels:
    """A roughness given as a map (a coat roughness texture; the base roughness of a material that lets light
    through), or the colour of a glass (its tint): the material is converted at a few ``levels`` of it, evenly over
    the map's range, and each texel takes the interpolation of the levels' values at its own (:meth:`weights`: a
    not-a-knot cubic spline through four levels or more, exact where a target's parameter is a quadratic or cubic of
    the source's, as Mitsuba's alpha is of glTF roughness; linear between two or three).

    A colour's levels are greys, and a texel is interpolated channel by channel (``per_channel``): the target's
    colours take each channel's weights at the source's same channel, its numbers the weights at the channel mean.
    That is exact where the models draw each channel on its own, as RGB renderers draw a glass's tint (glTF's base
    colour where light enters, OpenPBR's transmission_color, Mitsuba's specular_transmittance); ``typical`` (the
    map's median colour) is where the gate checks it."""

    name: str
    levels: tuple[float, ...]
    #: the layer whose roughness it is (None: the base's)
    layer: str | None
    #: maps that do not vary, held at their value in every level (parameter -> value)
    held: Mapping[str, Any] = field(default_factory=dict)
    #: a colour's levels: greys, each texel interpolated channel by channel
    per_channel: bool = False
    #: the map's median colour (a colour's levels): a texel the gate checks the channels' interpolation at
    typical: tuple[float, ...] | None = None
    #: a sheen's colour: grey levels of its brightest channel, every parameter interpolated at a texel's brightest
    #: channel, and the target's own layer colour given the texel's hue (its colour over that channel: :func:`chroma`)
    chroma: bool = False

    @property
    def colour(self) -> bool:
        """Whether the levels are greys of a colour map (channel by channel, or by brightness and hue)."""
        return self.per_channel or self.chroma

    @property
    def kinds(self) -> tuple[str, ...]:
        return tuple(f"{self.name}={v:g}" for v in self.levels)

    def value(self, kind: str) -> float:
        return self.levels[self.kinds.index(kind)]

    @property
    def inputs(self) -> tuple[str, ...]:
        return (self.name,)

    def params(self, kind: str) -> dict[str, Any]:
        """A roughness's level; a colour's level is a grey, but where it is the only one (a uniform colour map), the
        map's median colour itself."""
        v = self.value(kind)
        if self.colour and len(self.levels) == 1 and self.typical is not None:
            return {self.name: list(self.typical)}
        return {self.name: [v] * 3 if self.colour else v}

    def band_weights(self, values: Mapping[str, np.ndarray]) -> tuple[list[np.ndarray], list[np.ndarray] | None]:
        raw = values[self.name]
        return self.scalar_weights(raw), self.weights(raw) if self.per_channel else None

    def scalar_weights(self, values: np.ndarray) -> list[np.ndarray]:
        """The weights a target's numbers take per texel: :meth:`weights` of ``values``, or, for a colour's levels
        (``values`` [..., 3]), of their channel mean (:attr:`per_channel`) or brightest channel (:attr:`chroma`)."""
        return self.weights(self.level_of(values))

    def level_of(self, values: np.ndarray) -> np.ndarray:
        """Where ``values`` lie among the levels: a colour's channel mean (:attr:`per_channel`) or brightest channel
        (:attr:`chroma`), a number as it is."""
        a = np.asarray(values, dtype=np.float32)
        if self.colour and a.ndim and a.shape[-1] == 3:
            return a.max(axis=-1) if self.chroma else a.mean(axis=-1)
        return a

    def weights(self, values: np.ndarray) -> list[np.ndarray]:
        """The weight of each level per texel (they sum to 1; a spline's may be negative: the blend clips its result
        to the parameters' bounds); values outside the levels take the nearest one."""
        v = np.clip(np.asarray(values, dtype=np.float32), self.levels[0], self.levels[-1])
        if len(self.levels) == 1:
            return [np.ones_like(v)]
        if len(self.levels) >= SPLINE_LEVELS:
            from scipy.interpolate import CubicSpline

            n = len(self.levels)
            basis = CubicSpline(np.asarray(self.levels, dtype=float), np.eye(n), axis=0)  # not-a-knot
            w = basis(v.reshape(-1).astype(float)).astype(np.float32)
            return [w[:, i].reshape(v.shape) for i in range(n)]
        out = []
        for i, level in enumerate(self.levels):
            w = np.zeros_like(v)
            if i > 0:
                lo = self.levels[i - 1]
                w = np.where((v >= lo) & (v <= level), (v - lo) / (level - lo), w)
            if i + 1 < len(self.levels):
                hi = self.levels[i + 1]
                w = np.where((v >= level) & (v < hi), (hi - v) / (hi - level), w)
            out.append(w)
        return out

    def describe(self) -> str:
        whose = f"{self.layer} roughness" if self.layer else self.name
        if self.per_channel:
            whose = f"{self.name} (channel by channel)"
        elif self.chroma:
            whose = f"{self.name} (by its brightest channel, its hue kept)"
        if len(self.levels) == 1:
            return f"{whose} {self.levels[0]:g} everywhere"
        return f"{whose} from {self.levels[0]:g} to {self.levels[-1]:g}, {len(self.levels)} levels"


@dataclass(frozen=True)
class Grid:
    """A glass whose roughness and colour both vary over the maps: converted at the levels of each, the other held
    at its typical value (the roughness levels at the map's median colour, the colour's grey levels at the median
    roughness), and each texel takes the target's numbers from the roughness levels and its colours, channel by
    channel, from the colour's levels. That separates what a tint does from what roughness does, as the models draw
    them (a tint scales each channel of the light let through, whatever its blur); the gate checks it where it is
    least sure, at the corners (:func:`matremap.svbrdf.levels.checks`)."""

    rough: Levels
    tint: Levels
    #: texels of the maps (roughness, colour) where the gate checks the separation: the smoothest, the roughest,
    #: the darkest and the brightest
    corners: tuple[tuple[float, tuple[float, ...]], ...] = ()
    #: every parameter from both axes (a layer's roughness and colour over base maps, :meth:`band_weights`), not the
    #: numbers from one and the colours from the other (a glass)
    additive: bool = False

    @property
    def name(self) -> str:
        return self.rough.name

    @property
    def layer(self) -> str | None:
        return self.rough.layer

    @property
    def held(self) -> Mapping[str, Any]:
        return self.rough.held

    @property
    def inputs(self) -> tuple[str, ...]:
        return (self.rough.name, self.tint.name)

    @property
    def kinds(self) -> tuple[str, ...]:
        return (*self.rough.kinds, *self.tint.kinds)

    def axis(self, kind: str) -> Levels:
        return self.rough if kind in self.rough.kinds else self.tint

    def value(self, kind: str) -> float:
        return self.axis(kind).value(kind)

    def params(self, kind: str) -> dict[str, Any]:
        """A roughness level at the median colour (an additive grid's: the grey of its level, as the colour's levels
        are greys), a grey level at the median roughness."""
        if kind in self.rough.kinds:
            typical = np.asarray(self.tint.typical or (1.0, 1.0, 1.0), dtype=float)
            colour = [float(self.tint.level_of(typical))] * 3 if self.additive else typical.tolist()
            return {**self.rough.params(kind), self.tint.name: colour}
        return {**self.tint.params(kind), self.rough.name: self.typical_roughness}

    @property
    def axes(self) -> tuple[Levels, Levels]:
        return self.rough, self.tint

    def others(self, axis: Levels) -> dict[str, Any]:
        """What a level of ``axis`` holds of the other axis: its typical value."""
        return {k: v for k, v in self.params(axis.kinds[0]).items() if k != axis.name}

    @property
    def typical_roughness(self) -> float:
        return float(self.tint.held.get(self.rough.name, self.rough.levels[len(self.rough.levels) // 2]))

    def band_weights(self, values: Mapping[str, np.ndarray]) -> tuple[list[np.ndarray], list[np.ndarray] | None]:
        """The numbers from the roughness levels (the colour levels weigh 0), the colours from the colour's levels
        channel by channel (the roughness levels weigh 0). An :attr:`additive` grid gives every parameter the sum
        of what each axis moves it by from the typical texel, ``p(r, c) = p_r(r) + p_c(c) - p_r(r_typical)``
        (the roughness axis interpolated at the typical roughness stands for the point where the axes cross): exact
        where a parameter follows one axis only (a fuzz roughness the layer's roughness, a fuzz weight its colour)
        and to first order where it follows both (a base colour under a sheen, dimmed by the sheen's albedo)."""
        if self.additive:
            return self._additive_weights(values)
        rough = self.rough.weights(values[self.rough.name])
        tint = self.tint.weights(values[self.tint.name])
        zero_scalar, zero_colour = np.zeros_like(rough[0]), np.zeros_like(tint[0])
        return (
            [*rough, *([zero_scalar] * len(tint))],
            [*([zero_colour] * len(rough)), *tint],
        )

    def _additive_weights(self, values: Mapping[str, np.ndarray]) -> tuple[list[np.ndarray], list[np.ndarray] | None]:
        r = np.asarray(values[self.rough.name], dtype=np.float32)
        moved = self.rough.weights(r)
        crossing = self.rough.weights(np.full_like(r, self.typical_roughness))
        rough = [w - w0 for w, w0 in zip(moved, crossing, strict=True)]
        colour = values[self.tint.name]
        scalar = [*rough, *self.tint.scalar_weights(colour)]
        if not self.tint.per_channel:
            return scalar, None
        return scalar, [*(w[..., None] for w in rough), *self.tint.weights(colour)]

    def describe(self) -> str:
        return f"{self.rough.describe()}, and {self.tint.describe()}"


#: among three kinds or more (levels), the share of a texel's weight (sum of |weights|) that must come from kinds
#: outside their transforms' domain for the texel to count as outside: the levels that bracket it weigh 0.5 or more,
#: the far ones a spline reaches with 0.01-0.1
OUTSIDE_SHARE = 0.25
#: levels a layer roughness map is converted at (:class:`Levels`)
LEVELS = 5
#: from this many levels on, a texel's value is the cubic spline through the levels' (linear below)
SPLINE_LEVELS = 4


#: layers whose colour a model draws as the colour of a lobe over a grey dimming of what lies below (a sheen: OpenPBR
#: 1.1 fuzz, lerp(1, 1 - E_fuzz, fuzz_weight) under fuzz_color; glTF's sheen, 1 - max(sheenColor) E): a colour map of
#: one is converted at grey levels of its brightest channel and its hue given back (:attr:`Levels.chroma`). A coat's
#: colour tints what passes through it channel by channel (:attr:`Levels.per_channel`)
CHROMA_LAYERS = ("sheen",)


def layer_levels(map_set: MapSet, summary: MapSummary) -> Levels | Grid | None:
    """The levels a layer (a coat, a sheen) whose roughness or colour is a map that varies is converted at, or None:
    its roughness's (:class:`Levels`), its colour's (grey levels: a coat's interpolated channel by channel, a
    sheen's by its brightest channel with its hue kept), or both (an additive :class:`Grid`). Each level is the map
    set with the layer held there, its base maps converted under it (:func:`matremap.remap.hold_layers`). Two
    layers that vary over the maps are refused in one line."""
    from matremap.dialects.mtlx import LAYER_PARAMS, LAYERS

    values = {**map_set.constants, **dict.fromkeys(map_set.maps, 1.0)}
    sample = summary.sample()
    found: list[Levels | Grid] = []
    for layer, own in LAYER_PARAMS.get(map_set.model, {}).items():
        weight_name = LAYERS[map_set.model][layer]
        on = float(np.max(np.asarray(values.get(weight_name, 0.0), dtype=float))) > 0.0
        stats = summary.stats.get(own.roughness or "")
        rough = stats is not None and stats.hi - stats.lo > 2 * TOLERANCE
        colour = own.colour in map_set.maps and _varies(sample[own.colour])
        if not on or not (rough or colour):
            continue
        r_levels = Levels(own.roughness or "", _even_levels(stats), layer) if rough and stats is not None else None
        c_levels = None
        if colour and own.colour is not None:
            held = {r_levels.name: round(float(np.median(sample[r_levels.name])), 6)} if r_levels else {}
            c_levels = _colour_levels(own.colour, summary, held, layer, chroma=layer in CHROMA_LAYERS)
        if r_levels is not None and c_levels is not None:
            found.append(Grid(r_levels, c_levels, additive=True))
        else:
            found.append(r_levels or c_levels)  # type: ignore[arg-type]
    if len(found) > 1:
        names = " and ".join(f"{f.layer}'s {f.name}" for f in found)
        raise MatremapError(
            f"{map_set.model}: the {names} vary over the maps; the maps of one layer are converted at a time (its "
            "roughness and colour), so bake the other layer's to one value"
        )
    return found[0] if found else None


def _texels(values: Any) -> np.ndarray:
    """A map's sampled ``values`` (a number or a colour per texel) as rows of texels ``[n, channels]``."""
    a = np.asarray(values, dtype=float)
    return a.reshape(-1, a.shape[-1]) if a.ndim == 3 else a.reshape(-1, 1)


def _varies(values: Any) -> bool:
    """Whether a map's sampled ``values`` vary over the texels (beyond the statistics' tolerance)."""
    return bool(float(np.max(np.ptp(_texels(values), axis=0))) > 2 * TOLERANCE)


def through_levels(map_set: MapSet, summary: MapSummary) -> Levels | Grid | None:
    """The levels a map set that lets light through (its transmission weight above 0) is converted at, or None
    when it does not: each level is one uniform material fitted on the transmission probe (the sweep of maps draws
    reflection only), at :data:`LEVELS` values over the range of the map that varies: the base roughness, or a
    colour (a tinted glass's base colour; grey levels, each texel interpolated channel by channel: see
    :class:`Levels`), or both (a :class:`Grid`). Every other map must be uniform and is held at its value; any
    other that varies (a specular strength, a second colour) is refused in one line, before any fit."""
    from matremap.dialects.mtlx import layers_on

    spec = map_set.spec
    if "transmission" not in layers_on(map_set.model, {**map_set.constants, **dict.fromkeys(map_set.maps, 1.0)}):
        return None
    if not map_set.maps:
        return None
    rp = qty.roughness_param(spec)
    sample = summary.sample()
    held: dict[str, Any] = {}
    varying = []
    for name in map_set.maps:
        if _varies(sample[name]):
            varying.append(name)
        else:
            med = np.median(_texels(sample[name]), axis=0)
            held[name] = med.tolist() if spec.param(name).channels == 3 else float(med[0])
    rough = [n for n in varying if rp is not None and n == rp.name]
    colours = [n for n in varying if spec.param(n).channels == 3]
    if len(rough) + len(colours) < len(varying) or len(colours) > 1:
        maps = f"{', '.join(varying)} map{'s vary' if len(varying) > 1 else ' varies'}"
        raise MatremapError(
            f"{map_set.model} lets light through, and its {maps} over the texels: its roughness and one colour are "
            "converted under transmission (at levels of each, fitted on the transmission probe); bake the others "
            "to one value or remap the material without its transmission"
        )
    if rough and colours:
        r_levels = _even_levels(summary.stats[rough[0]])
        r = np.asarray(sample[rough[0]], dtype=float).reshape(-1)
        c = np.asarray(sample[colours[0]], dtype=float).reshape(-1, 3)
        lum = c.mean(axis=1)
        picks = dict.fromkeys(int(i) for i in (r.argmin(), r.argmax(), lum.argmin(), lum.argmax()))
        corners = tuple((round(float(r[i]), 6), tuple(round(float(v), 6) for v in c[i])) for i in picks)
        return Grid(
            Levels(rough[0], r_levels, None, held),
            _colour_levels(colours[0], summary, {**held, rough[0]: round(float(np.median(r)), 6)}),
            corners,
        )
    if not varying:  # every map uniform: one level of the first scalar map (else of the roughness), the others held
        first = next((n for n in map_set.maps if spec.param(n).channels == 1), None)
        if first is not None:
            return Levels(first, (float(held.pop(first)),), None, held)
        colour = next(iter(map_set.maps))  # a colour map alone (Khronos TransmissionTest's GreenMask: a mask in alpha)
        typical = tuple(round(float(v), 6) for v in np.broadcast_to(held.pop(colour), (3,)))
        return Levels(colour, (round(float(np.mean(typical)), 6),), None, held, per_channel=True, typical=typical)
    name = varying[0]
    if spec.param(name).channels == 3:
        return _colour_levels(name, summary, held)
    return Levels(name, _even_levels(summary.stats[name]), None, held)


def _colour_levels(
    name: str, summary: MapSummary, held: Mapping[str, Any], layer: str | None = None, chroma: bool = False
) -> Levels:
    """Grey levels over a colour map's range, interpolated channel by channel (``chroma``: over the range of its
    brightest channel, interpolated there), with its median colour to check."""
    a = np.asarray(summary.sample()[name], dtype=float).reshape(-1, 3)
    typical = tuple(round(float(v), 6) for v in np.median(a, axis=0))
    if chroma:
        top = a.max(axis=1)
        levels = tuple(dict.fromkeys(round(float(v), 6) for v in np.linspace(top.min(), top.max(), LEVELS)))
        return Levels(name, levels, layer, dict(held), typical=typical, chroma=True)
    levels = _even_levels(summary.stats[name])
    return Levels(name, levels, layer, dict(held), per_channel=True, typical=typical)


def chroma(colour: np.ndarray) -> np.ndarray:
    """A colour's hue and saturation without its brightness, ``c / max(c)`` per texel ([..., 3]; white where the
    colour is black): what :attr:`Levels.chroma` gives back to the target's layer colour."""
    c = np.asarray(colour, dtype=np.float32)
    top = c.max(axis=-1, keepdims=True)
    return np.where(top > 0, c / np.maximum(top, 1e-12), np.float32(1.0))


def _even_levels(stats: Any) -> tuple[float, ...]:
    """:data:`LEVELS` values evenly over a map's range (its :class:`~matremap.svbrdf.mapstats.MapStats`)."""
    return tuple(dict.fromkeys(round(float(v), 6) for v in np.linspace(stats.lo, stats.hi, LEVELS)))


Blend = Mixed | Levels | Grid


def mixed_parameter(map_set: MapSet, summary: MapSummary) -> Mixed | None:
    """The first specialisation parameter (a glTF ``metallic``) given as a map that is not uniform, or
    None: such maps are remapped per texel (:func:`remap_mixed`). ``summary``: the maps' statistics
    (:func:`~matremap.svbrdf.mapstats.summarise`)."""
    spec = map_set.spec
    for name, _, _ in spec.specialisations:
        if name not in map_set.maps:
            continue
        stats = summary.stats[name]
        if stats.hi - stats.lo <= 2 * TOLERANCE or stats.specialisation is None:
            continue
        counts = stats.specialisation
        through = transmission_weight(spec)
        holds = {through: 0.0} if through is not None and _lets_through(map_set, through) else {}
        return Mixed(name, float(counts.value), float(counts.other), counts, first_holds=holds)
    return None


def transmission_parameter(map_set: MapSet, summary: MapSummary) -> Mixed | None:
    """The transmission weight (:func:`~matremap.dialects.mtlx.transmission_weight`) given as a map that is not
    uniform, or None: the material is converted letting light through (weight 1: its other maps converted at levels
    on the transmission probe, :func:`through_levels`) and opaque (weight 0), and the two blended per texel by the
    map (Khronos TransmissionTest: a glass pattern over an opaque red, ``transmissionTexture``)."""
    name = transmission_weight(map_set.spec)
    stats = summary.stats.get(name or "")
    if name is None or stats is None or stats.hi - stats.lo <= 2 * TOLERANCE or stats.specialisation is None:
        return None
    counts = stats.specialisation
    return Mixed(name, float(counts.value), float(counts.other), counts, ("transmission", "bare"), "transmission")


def layer_parameter(map_set: MapSet, summary: MapSummary) -> Mixed | None:
    """The first layer weight (a coat's, a sheen's: :func:`~matremap.dialects.mtlx.layer_weights`) given as a map
    that is not uniform, or None: such maps are remapped per texel, with the layer and without it."""
    from matremap.dialects.mtlx import LAYERS, layer_weights

    layers = {w: layer for layer, w in LAYERS.get(map_set.model, {}).items()}
    for name in layer_weights(map_set.spec):
        stats = summary.stats.get(name)
        if stats is None or stats.hi - stats.lo <= 2 * TOLERANCE or stats.specialisation is None:
            continue
        counts = stats.specialisation
        layer = layers[name]
        return Mixed(name, float(counts.value), float(counts.other), counts, (layer, "bare"), layer)
    return None


def expressing_models(family: str) -> list[str]:
    """Models with a diffuse and a specular part (the target's family first)."""
    both = [s.id for s in list_models() if qty.diffuse_param(s) is not None and s.reflectance is not None]
    return sorted(both, key=lambda m: (m.split(":", 1)[0] != family, m))


def check_target(mixed: Blend, target: str, fix: Mapping[str, Any]) -> None:
    """Refuse, in one line, a target that cannot express both kinds, or that cannot take as a map the
    parameter the blend will vary (a Cycles ``Metallic`` that becomes the source's map)."""
    from matremap.renderers.registry import texture_refusal

    spec = get_model(target)
    if isinstance(mixed, Levels | Grid) or mixed.layer is not None:
        _check_layer_target(mixed, spec, fix)
        return
    if qty.diffuse_param(spec) is None:
        how = f"{mixed.name} {mixed.dielectric:g}" if mixed.pure("dielectric") else f"{mixed.name} < {mixed.metal:g}"
        raise MatremapError(
            f"{target} has no diffuse part for the dielectric texels ({how} on "
            f"{100 * mixed.share('dielectric'):.0f}% of the texels); choose a target with one, e.g. "
            + ", ".join(expressing_models(spec.family)[:3])
        )
    varied = [name for name, _, _ in spec.specialisations if name not in fix]
    why = texture_refusal(spec.id, varied)
    if why is not None:
        raise MatremapError(f"{why}, and the metal and dielectric texels need it as a map; fix it with --fix")


def _check_layer_target(mixed: Blend, spec: ModelSpec, fix: Mapping[str, Any]) -> None:
    """A layer blended per texel varies the target's own weight (or roughness) of that layer and its base
    parameters (the kinds' fits differ): each must be a map its renderers take."""
    from matremap.dialects.mtlx import LAYER_PARAMS, LAYERS
    from matremap.renderers.registry import texture_refusal

    own = LAYER_PARAMS.get(spec.id, {}).get(mixed.layer or "")
    varied = [LAYERS.get(spec.id, {}).get(mixed.layer or "")] if isinstance(mixed, Mixed) else []
    for axis in () if isinstance(mixed, Mixed) else mixed.axes if isinstance(mixed, Grid) else (mixed,):
        varied.append(None if own is None else own.colour if axis.colour else own.roughness)
    varied += [getattr(qty.roughness_param(spec), "name", None), getattr(qty.diffuse_param(spec), "name", None)]
    if spec.reflectance is not None:  # the kinds' F0 differs too (an IOR fitted under a coat and without it)
        varied.append(spec.reflectance.driven_param(spec.specialise(fix).diffuse_only is None))
    why = texture_refusal(spec.id, [n for n in varied if n is not None and n not in fix])
    if why is not None:
        whose = mixed.layer or "base"
        what = f"with and without the {whose}" if isinstance(mixed, Mixed) else f"at each level of the {whose}"
        raise MatremapError(
            f"{why}, and the texels {what} ({mixed.name} map) need it as a map; choose a target that takes it as a map"
        )


def kind_map_set(map_set: MapSet, mixed: Blend, kind: str, dest: Path) -> MapSet:
    """The map set with the mixed parameter held at one ``kind``'s value, as a manifest in ``dest`` that
    refers to the source's files (nothing is copied)."""
    dest.mkdir(parents=True, exist_ok=False)

    def rel(f: Path) -> str:
        return os.path.relpath(Path(f).resolve(), dest.resolve())

    held = mixed.held if isinstance(mixed, Levels | Grid) else {}
    fixed = mixed.params(kind)
    maps = {k: f for k, f in map_set.maps.items() if k not in mixed.inputs and k not in held and k not in fixed}
    doc: dict[str, Any] = {
        "model": map_set.model,
        "maps": {k: rel(f) for k, f in maps.items()},
        "params": {**map_set.constants, **held, **fixed},
        "colorspace": {k: map_set.colorspace[k] for k in maps if k in map_set.colorspace},
    }
    if map_set.normal is not None:
        doc["normal"] = rel(map_set.normal)
    write_text(dest / MANIFEST_NAME, json.dumps(doc, indent=1) + "\n")
    if not maps:  # a uniform kind (a uniform base under a coat mask): no maps to load, fitted as one material
        return MapSet(map_set.model, {}, dest, map_set.size, map_set.normal, dict(doc["params"]))
    return load_map_set(dest)


def remap_mixed(
    folder: Path,
    map_set: MapSet,
    params: Mapping[str, Any],
    mixed: Blend,
    target: str,
    fix: Mapping[str, Any],
    check: CheckKind,
    convert_kind: ConvertKind,
    log: Callable[[str], None],
) -> tuple[int, int]:
    """Convert ``map_set`` once as each kind (a metal and a dielectric; with the layer and bare) (``convert_kind``:
    through each kind's own transform, or one fit for a kind without maps; ``check`` runs for both before either
    is converted) and write the per-texel blend into ``folder/"maps"``. Returns the texel count and the texels
    outside the training domain."""
    check_target(mixed, target, fix)
    kinds = folder / KINDS
    sets = {kind: kind_map_set(map_set, mixed, kind, kinds / kind) for kind in mixed.kinds}
    for kind, ms in sets.items():
        check(ms, {**params, **mixed.params(kind)})
    log(
        f"mixed: {mixed.name} varies per texel ({mixed.describe()}): converting each kind through its own "
        "transform and blending them by the map"
    )
    converted = {}
    for kind, ms in sets.items():
        log(f"mixed: the {kind}")
        converted[kind] = convert_kind(ms, kinds / f"{kind}-out")
    texels = int(np.prod(map_set.size))
    outside = blend(list(converted.values()), mixed, folder / "maps", map_set)
    for kind, ms in converted.items():  # what was applied, with its provenance
        t = ms.root.parent / "transform.json"
        if t.is_file():
            shutil.copyfile(t, folder / f"transform-{kind}.json")
    shutil.rmtree(kinds)
    log(
        f"blend: {texels} texels"
        + (f"; {outside} outside the training domain (see maps/{MASK_NAME})" if outside else "")
    )
    return texels, outside


#: where a blended parameter's values come from on one side: a map (the converted set and the
#: parameter) or a constant
_Source = Any


def _sources(ms: MapSet) -> dict[str, _Source]:
    """A converted map set's parameters: each map as (map set, name), each constant as it is."""
    spec = ms.spec
    out: dict[str, _Source] = {k: v for k, v in ms.constants.items() if k in spec.param_names}
    out.update({name: (ms, name) for name in ms.maps})
    return out


def _is_map(v: _Source) -> bool:
    return isinstance(v, tuple) and len(v) == 2 and isinstance(v[0], MapSet)


def _full(value: Any, channels: int, shape: tuple[int, int]) -> np.ndarray:
    """A parameter value (a band of a map, or a constant) as an array ``[rows, W]`` or ``[rows, W, 3]``."""
    a = np.asarray(value, dtype=np.float32)
    if channels == 1:
        return np.broadcast_to(a if a.ndim == 2 else a.reshape(-1)[0], shape)
    if a.ndim == 2:
        a = a[..., None]
    return np.broadcast_to(a if a.ndim == 3 else a.reshape(-1)[:3], (*shape, 3))


def _info(spec: ModelSpec, name: str, sides: list[MapSet], constants: list[Any], weights: ImageInfo) -> ImageInfo:
    """The file format of a blended map: the converted maps' own (a float one if either side's is), else
    one like the other maps (the source's ``weights`` map where the sides have none; sRGB for colours in
    8/16-bit files; float EXR when either side's constant, and so the blend between them, lies outside [0, 1])."""
    infos = [ms.info[name] for ms in sides if name in ms.info]
    if infos:
        return next((i for i in infos if not i.integer), infos[0]).written()
    p = spec.param(name)
    base = next((i for ms in sides for i in ms.info.values()), weights).written()
    colour = p.channels == 3 and p.role in ("diffuse", "specular", "fresnel")
    info = base.like(channels=p.channels, colorspace="srgb" if colour and base.integer else "linear", path="")
    values = np.concatenate([np.asarray(c, dtype=float).reshape(-1) for c in constants])
    if info.integer and (float(values.min()) < 0.0 or float(values.max()) > 1.0):
        info = info.like(format="exr", pixel_type="float", colorspace="linear", compression=None)
    return info


def _file_name(name: str, sides: list[MapSet], info: ImageInfo, weights: Path) -> str:
    """A converted map's own file name, else ``<prefix>_<param>`` beside the other maps (or named after the
    source's ``weights`` map where the sides have none)."""
    own = next((ms.maps[name].name for ms in sides if name in ms.maps), None)
    if own is not None:
        return own
    stem = next((f.stem for ms in sides for f in ms.maps.values()), weights.stem)
    return f"{stem.rsplit('_', 1)[0] if '_' in stem else 'material'}_{name}{info.suffix}"


@dataclass
class _Blended:
    """One blended map: its parameter, where each side's values come from, its file and format."""

    name: str
    channels: int
    sources: list[_Source]
    file: str
    info: ImageInfo


def _plan(
    sides: list[MapSet], weights: Path, info: ImageInfo, borrowed: Mapping[str, list[int]] | None = None
) -> tuple[list[_Blended], dict[str, Any]]:
    """The maps to blend and the parameters that stay constants (options included); ``weights``, ``info``: the
    source's map of the mixed parameter and its format. ``borrowed``: parameters whose value each side takes from
    the side listed (a layer's colour and roughness where a side has the layer off: :func:`_borrowed`)."""
    borrowed = borrowed or {}
    spec = sides[0].spec
    found = [_sources(ms) for ms in sides]
    for option in spec.option_names:
        given = {str(ms.constants.get(option)) for ms in sides}
        if len(given) > 1:
            raise MatremapError(
                f"the kinds of texels were converted with different {option} ({' and '.join(sorted(given))}); fix "
                f"it: --fix {option}=..."
            )
    constants: dict[str, Any] = {k: v for k, v in sides[0].constants.items() if k in spec.option_names}
    roles = [spec.specialise(ms.constants) for ms in sides]  # a parameter one kind does not use takes the other's
    plan = []
    for p in spec.params:
        have = [i for i, f in enumerate(found) if p.name in f]
        if not have:
            continue
        values = [found[i][p.name] if i in have else found[have[0]][p.name] for i in range(len(sides))]
        if p.name in borrowed:
            values = [values[j] for j in borrowed[p.name]]
        used = [i for i, r in enumerate(roles) if r.param(p.name).role != "other"]
        if used and len(used) < len(sides):
            values = [values[i] if i in used else values[used[0]] for i in range(len(sides))]
        if not any(_is_map(v) for v in values) and all(np.allclose(values[0], v) for v in values[1:]):
            constants[p.name] = values[0]
            continue
        out = _info(spec, p.name, sides, [v for v in values if not _is_map(v)], info)
        plan.append(_Blended(p.name, p.channels, values, _file_name(p.name, sides, out, weights), out))
    taken: set[str] = set()
    for b in plan:  # two kinds' files of one name for two parameters (a metal's F0 and a dielectric's IOR are each
        if b.file in taken:  # kind's "specular" map): one file each, or both would be written to one and corrupt it
            b.file = f"{Path(b.file).stem}_{b.name.replace(' ', '_')}{Path(b.file).suffix}"
        taken.add(b.file)
    return plan, constants


def blend(sides: list[MapSet], mixed: Blend, dest: Path, source: MapSet) -> int:
    """Write the per-texel blend of the converted map sets (one per kind of ``mixed``, in its order) into
    ``dest`` (maps, the union of their outside-domain masks where they contribute, the normal map,
    ``material.json``), band by band; returns the number of texels outside the training domain. A failure leaves
    no ``dest``."""
    from matremap.dialects.mtlx import LAYER_PARAMS

    spec = sides[0].spec
    own = LAYER_PARAMS.get(spec.id, {}).get(mixed.layer or "")
    borrowed = _borrowed(sides, mixed, own) or _through_borrowed(sides, mixed)
    plan, constants = _plan(sides, source.maps[mixed.name], source.info[mixed.name], borrowed)
    tint = mixed.tint if isinstance(mixed, Grid) else mixed
    hue = (tint.name, own.colour) if isinstance(tint, Levels) and tint.chroma and own and own.colour else None
    if hue is not None and hue[1] in constants:  # a uniform layer colour takes the texels' hue: a map
        plan.append(_hued(spec, hue[1], constants.pop(hue[1]), sides, source.info[hue[0]], source.maps[mixed.name]))
    dest.mkdir(parents=True, exist_ok=False)
    try:
        outside = _blend_bands(plan, mixed, dest, source, sides, hue)
        doc: dict[str, Any] = {"model": spec.id, "maps": {b.name: b.file for b in plan}}
        normal = sides[0].normal
        if normal is not None:
            shutil.copyfile(normal, dest / normal.name)
            doc["normal"] = normal.name
        doc["params"] = constants
        doc["colorspace"] = {b.file: b.info.colorspace for b in plan}
        doc["provenance"] = _provenance(sides, mixed, source, outside, dest)
        write_text(dest / MANIFEST_NAME, json.dumps(doc, indent=1) + "\n")
    except BaseException:
        shutil.rmtree(dest, ignore_errors=True)
        raise
    return outside


def _borrowed(sides: list[MapSet], mixed: Blend, own: Any) -> dict[str, list[int]]:
    """For the target's layer colour and roughness (``own``: its :class:`~matremap.dialects.mtlx.Layer`), the side
    each side takes them from: where a side has the layer off they draw nothing, and blended they would pull the
    others' towards whatever that side holds (a held coat roughness became a map running to 0). With and without a
    layer (a weight map): the layered side's everywhere. Levels of the layer: an off level (a sheen's colour at
    black) takes the nearest level's with the layer on, on its own axis. A colour that is the layer's weight (glTF's
    sheenColor) is not borrowed."""
    if own is None:
        return {}
    names = [n for n in (None if own.weighted_colour else own.colour, own.roughness) if n]
    if isinstance(mixed, Mixed):
        return dict.fromkeys(names, [0] * len(sides))
    n = len(mixed.rough.kinds) if isinstance(mixed, Grid) else len(sides)
    axes = [list(range(n)), list(range(n, len(sides)))]
    on = [float(np.max(np.asarray(ms.constants.get(own.weight, 1.0), dtype=float))) > 0.0 for ms in sides]
    source = list(range(len(sides)))
    for axis in axes:
        lit = [i for i in axis if on[i]]
        for i in axis:
            if not on[i] and lit:
                source[i] = min(lit, key=lambda j: abs(j - i))
    return dict.fromkeys(names, source) if source != list(range(len(sides))) else {}


def _through_borrowed(sides: list[MapSet], mixed: Blend) -> dict[str, list[int]]:
    """Between a kind that lets light through and one that does not (a transmission weight map; a metal kind, held
    opaque, beside a dielectric glass), the side each side takes the target's transmission parameters from: the
    kind letting light through (what only the transmitted light uses: :data:`~matremap.dialects.mtlx.THROUGH_PARAMS`),
    since the other draws nothing of them and a blend would pull a texel's tint towards whatever that side holds;
    beside a metal, the weight too: every model here mixes its metal over the dielectric base and its transmission
    (OpenPBR 1.1 base_metalness, Standard Surface 1.0.1 metalness, glTF's metallic, Cycles' (1 - Metallic), Mitsuba
    3's principled), so the metal's texels hide it, and a texel half metal keeps the source's whole transmission under
    its dielectric half (blended, its weight fell to a half and showed the base colour as diffuse: TransmissionTest's
    YellowTransMetal onto Standard Surface, a yellow edge on every stripe where the source shows none). Where the
    target's transmission has a colour of its own (:data:`~matremap.dialects.mtlx.OWN_TINT`), its dielectric base
    colour is the opaque kind's (a texel wholly letting light through shows none of it), and so beside a metal where
    the glass lets all light through. Each model mixes its transmission in linearly by its weight and a metal over
    it, so the blend is then exact at every weight."""
    from matremap.dialects.mtlx import OWN_TINT, THROUGH_PARAMS

    if not isinstance(mixed, Mixed) or len(sides) != 2:
        return {}
    spec = sides[0].spec
    weight_name = transmission_weight(spec)
    if weight_name is None:
        return {}
    on = [_lets_through(ms, weight_name) for ms in sides]
    if on.count(True) != 1:
        return {}
    lit = on.index(True)
    names = [n for n in THROUGH_PARAMS.get(spec.id, ()) if n in spec.param_names]
    if mixed.layer is None:  # a metal beside a glass: the metal's own weight (0, held) is hidden under it anyway
        names.append(weight_name)
    out = dict.fromkeys(names, [lit, lit])
    diffuse = qty.diffuse_param(spec)
    metal = any(_at_least(ms, n, v) for ms in sides for n, v, _ in spec.specialisations)
    if mixed.layer == "transmission" and spec.id in OWN_TINT and diffuse is not None and not metal:
        out[diffuse.name] = [1 - lit, 1 - lit]
    elif (
        mixed.layer is None and spec.id in OWN_TINT and diffuse is not None and _wholly_through(sides[lit], weight_name)
    ):
        # a metal beside a glass that lets all light through: the glass's base colour draws nothing, and its fit
        # left it wherever the descent did (TransmissionTest's YellowTransMetal onto OpenPBR: pink under a yellow
        # tint); the metal's colour, the source's one base colour, is written there instead
        out[diffuse.name] = [1 - lit, 1 - lit]
    return out


def _wholly_through(ms: MapSet, name: str) -> bool:
    """Whether a converted kind lets all light through (its transmission weight a constant 1)."""
    return name not in ms.maps and float(np.min(np.asarray(ms.constants.get(name, 0.0), dtype=float))) >= 1.0 - 1e-6


def _lets_through(ms: MapSet, name: str) -> bool:
    """Whether a converted kind lets light through (its transmission weight, a map or a constant, above 0)."""
    return name in ms.maps or float(np.max(np.asarray(ms.constants.get(name, 0.0), dtype=float))) > 0.0


def _at_least(ms: MapSet, name: str, value: float) -> bool:
    """Whether a converted kind holds ``name`` at ``value`` somewhere (a metal: its metalness at 1): a map counts."""
    return name in ms.maps or float(np.max(np.asarray(ms.constants.get(name, 0.0), dtype=float))) >= value


def _hued(spec: ModelSpec, name: str, value: Any, sides: list[MapSet], info: ImageInfo, weights: Path) -> _Blended:
    """A constant layer colour made a map, to take each texel's hue (:func:`chroma`)."""
    out = _info(spec, name, sides, [value], info)
    return _Blended(name, 3, [value] * len(sides), _file_name(name, sides, out, weights), out)


def _key(v: _Source) -> tuple[int, str]:
    return id(v[0]), v[1]


def _band(v: _Source, read: dict[tuple[int, str], np.ndarray], channels: int, shape: tuple[int, int]) -> np.ndarray:
    """One side's values of a blended map over a band: its map's band, or its constant broadcast."""
    return _full(read[_key(v)] if _is_map(v) else v, channels, shape)


def _blend_bands(
    plan: list[_Blended],
    mixed: Blend,
    dest: Path,
    source: MapSet,
    sides: list[MapSet],
    hue: tuple[str, str] | None = None,
) -> int:
    """Stream the blend of every planned map and the outside-domain mask into ``dest``; the mask's count. ``hue``:
    (the source's layer colour, the target's) when the target's takes the source's hue per texel (:func:`chroma`)."""
    height, width = source.size
    spec = sides[0].spec
    readers: dict[tuple[int, str], MapReader] = {}
    inputs: dict[str, MapReader] = {}
    masks: list[MapReader | None] = []
    writers: list[MapWriter] = []
    outside = 0
    try:
        for v in (v for b in plan for v in b.sources if _is_map(v)):
            if _key(v) not in readers:
                readers[_key(v)] = MapReader(v[0].maps[v[1]], v[0].colorspace.get(v[1]))
        for name in mixed.inputs:
            inputs[name] = MapReader(source.maps[name], source.colorspace.get(name))
        masks = [
            MapReader(ms.root / MASK_NAME, "linear", colour=False) if (ms.root / MASK_NAME).is_file() else None
            for ms in sides
        ]
        writers = [MapWriter(dest / b.file, b.info.like(width=width, height=height)) for b in plan]
        writers.append(MapWriter(dest / MASK_NAME, ImageInfo("png", "uint8", 1, width, height, "linear")))
        for y0, y1 in bands(height, band_rows(width)):
            raw = {n: map_values(source.spec, n, r.read_rows(y0, y1), r.path, y0) for n, r in inputs.items()}
            # the target's numbers take ws; its colours wc, channel by channel, where the blend has them (a colour's
            # levels, Levels.per_channel; a glass's Grid)
            ws, wc = mixed.band_weights(raw)
            read = {k: map_values(spec, k[1], r.read_rows(y0, y1), r.path, y0) for k, r in readers.items()}
            for b, writer in zip(plan, writers, strict=False):
                shares = ws if b.channels == 1 or wc is None else wc
                parts = (
                    (w if b.channels == 1 or w.ndim == 3 else w[..., None]) * _band(v, read, b.channels, w.shape[:2])
                    for w, v in zip(shares, b.sources, strict=True)
                )
                lo, hi = spec.param(b.name).bounds  # a spline between levels may overshoot them
                value = np.clip(sum(parts), lo, hi)
                if hue is not None and b.name == hue[1]:
                    value = np.clip(value * chroma(raw[hue[0]]), lo, hi)
                writer.write_rows(y0, value)
            outside_weight, total = np.zeros(ws[0].shape, dtype=np.float32), np.zeros(ws[0].shape, dtype=np.float32)
            for mask, share in zip(masks, ws, strict=True):
                w_abs = np.where(np.abs(share) > TOLERANCE, np.abs(share), 0.0)
                total += w_abs
                if mask is not None:
                    outside_weight += np.where(mask.read_rows(y0, y1)[..., 0] > 0.5, w_abs, 0.0)
            share_out = OUTSIDE_SHARE if len(sides) > 2 else 0.0
            off = outside_weight > share_out * np.maximum(total, TOLERANCE)
            writers[-1].write_rows(y0, off.astype(np.float32))
            outside += int(np.count_nonzero(off))
        for writer in writers:
            writer.close()
    finally:
        for r in (*readers.values(), *inputs.values(), *masks):
            if r is not None:
                r.close()
        for writer in writers:
            try:
                writer.close()
            except MatremapError:  # the first error is the one to report
                pass
    return outside


def _provenance(sides: list[MapSet], mixed: Blend, source: MapSet, outside: int, dest: Path) -> dict[str, Any]:
    """The blended result's provenance (in ``dest``): the source and each kind's transform."""

    def described(ms: MapSet) -> str:
        doc = json.loads((ms.root / MANIFEST_NAME).read_text())
        return str(doc.get("provenance", {}).get("transform", "?"))

    done = {kind: described(ms) for kind, ms in zip(mixed.kinds, sides, strict=True)}
    where = ", ".join(f"{t} where {mixed.name} is {mixed.value(k):g}" for k, t in done.items())
    return {
        "source": source_reference(source.root, dest),
        "source_model": source.model,
        "transform": f"per texel by {mixed.name}: {where}, blended linearly in between",
        "transforms": done,
        "blend": {"parameter": mixed.name, **{k: mixed.value(k) for k in mixed.kinds}},
        "outside_domain": {"file": MASK_NAME, "texels": outside},
    }
