"""A material that lets light through over a roughness map, converted at levels of its roughness (issue 16).

The sweep of maps draws reflection only, so such a material is not swept: it is fitted as a few uniform materials,
one per level of its roughness map, each on the transmission probe (:mod:`matremap.transmissive`), and every texel
takes the interpolation of the levels' fitted values at its own (:class:`~matremap.svbrdf.mixed.Levels`: a cubic
spline, blended by :func:`~matremap.svbrdf.mixed.remap_mixed`). What the interpolation writes between two levels was
not fitted: it is measured at each midpoint (:func:`interpolated` against the source drawn there,
:func:`~matremap.transmissive.interpolation_error`), and a midpoint further off than :data:`REFINE`, and than
:data:`OVER_FITS` times the two levels' own errors (near a mirror the fits themselves are 0.05-0.1 off), becomes a
level of its own, until none is or :data:`MAX_LEVELS` are fitted.

Measured on Khronos' TransmissionRoughnessTest (glTF roughness 0..1 onto Mitsuba 3's roughdielectric, whose alpha is
its square): interpolated linearly between five even levels, the alpha at roughness 0.375 was 11 % off and 0.31
from the source; refined, the midpoint 0.4375 was still 0.10 off at 2 % of alpha (the probe's transmission view,
drawn along fixed paths, is that sensitive: 1 % of alpha moves it by 0.04), and refinement ran to 17 levels. The
spline is exact for a square: five levels, 0.056 at worst.

The gate (:func:`checks`) takes the worst of the levels' own errors and the final midpoints' as ``fit_error``, and
the colour and energy of the levels' probe renders, as a uniform material's.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from matremap.core.material import Material
from matremap.svbrdf.mixed import Grid, Levels
from matremap.svbrdf.quality import Check, Thresholds, image_checks

#: a midpoint whose relative RMSE exceeds this, and OVER_FITS times its two levels' own, is fitted as a level too
REFINE = 0.05
OVER_FITS = 1.5
#: the most levels a map is converted at (each one fit on the transmission probe)
MAX_LEVELS = 17

#: a level's value -> the source at that level and its fit (:class:`~matremap.core.fit.FitResult`)
FitAt = Callable[[float], tuple[Material, Any]]


def interpolated(levels: Levels, x: Any, fit_at: FitAt) -> Material:
    """The target the blend writes at a texel whose value is ``x`` (a number, or a colour for a colour's levels):
    the levels' fitted targets weighted as :meth:`~matremap.svbrdf.mixed.Levels.weights` weighs them (a colour's
    levels: the target's colours channel by channel, its numbers at the channel mean), options as the first
    level's, clipped to the bounds as the blend clips."""
    x = np.asarray(x, dtype=np.float32).reshape(-1)
    scalar = [float(w.reshape(-1)[0]) for w in levels.scalar_weights(x)]
    per_channel = [w.reshape(-1) for w in levels.weights(x)] if levels.per_channel else None
    targets = [fit_at(v)[1].target for v in levels.levels]
    spec = targets[0].spec
    values: dict[str, Any] = {}
    for p in spec.params:
        ws: list[Any] = per_channel if p.channels == 3 and per_channel is not None else scalar
        v = sum(w * np.asarray(t.values[p.name], dtype=float) for w, t in zip(ws, targets, strict=True))
        v = np.clip(v, *p.bounds)
        values[p.name] = np.broadcast_to(v, (3,)).tolist() if p.channels == 3 else float(np.reshape(v, -1)[0])
    return Material.create(spec.id, {**targets[0].options, **values})


def at(levels: Levels, source: Material, x: Any) -> Material:
    """``source`` with the levels' parameter at ``x`` (a grey or a colour for a colour's levels)."""
    value = np.asarray(x, dtype=float).reshape(-1)
    if levels.colour and len(levels.levels) == 1 and levels.typical is not None and np.allclose(value, levels.levels):
        return source.with_params(levels.params(levels.kinds[0]))  # a uniform colour map: its colour itself
    if source.spec.param(levels.name).channels == 3:
        return source.with_params({levels.name: np.broadcast_to(value, (3,)).tolist()})
    return source.with_params({levels.name: float(value[0])})


def midpoint(levels: Levels, a: float, b: float, fit_at: FitAt) -> float:
    """The relative RMSE halfway between the neighbouring levels ``a`` and ``b``: the source there against what the
    blend writes there (:func:`interpolated`), on the probe level ``a`` was fitted on
    (:func:`~matremap.transmissive.interpolation_error`)."""
    from matremap.transmissive import interpolation_error

    source, fitted = fit_at(a)
    x = 0.5 * (a + b)
    return interpolation_error(at(levels, source, x), fitted, interpolated(levels, x, fit_at))


def typical_error(levels: Levels, fit_at: FitAt) -> float | None:
    """For a colour's levels, the relative RMSE at the map's median colour (:attr:`Levels.typical`), where the
    channels are interpolated each at its own value: whether the target draws them apart as the levels assume."""
    from matremap.transmissive import interpolation_error

    if not levels.per_channel or levels.typical is None:
        return None
    x = np.asarray(levels.typical, dtype=float)
    nearest = min(levels.levels, key=lambda v: abs(v - float(x.mean())))
    source, fitted = fit_at(nearest)
    return interpolation_error(at(levels, source, x), fitted, interpolated(levels, x, fit_at))


def refine(
    levels: Levels, fit_at: FitAt, log: Callable[[str], None]
) -> tuple[Levels, dict[tuple[float, float], float]]:
    """``levels`` with a level added at each midpoint further off than the interpolation should be (:data:`REFINE`,
    :data:`OVER_FITS`; worst first, at most :data:`MAX_LEVELS` in all), and the midpoint errors of the final levels
    (pair of neighbours -> error). Every midpoint is measured again after a level is added: a spline's weights
    reach past the neighbours."""
    values = sorted(levels.levels)
    for v in values:
        fit_at(v)

    def floor(pair: tuple[float, float]) -> float:
        return max(REFINE, OVER_FITS * max(float(fit_at(v)[1].loss) for v in pair))

    while True:
        current = replace(levels, levels=tuple(values))
        errors = {pair: midpoint(current, *pair, fit_at) for pair in zip(values, values[1:], strict=False)}
        worst = max(errors, key=lambda p: errors[p] - floor(p), default=None)
        if worst is None or errors[worst] <= floor(worst) or len(values) >= MAX_LEVELS:
            return current, errors
        mid = round(0.5 * (worst[0] + worst[1]), 6)
        if mid in worst:
            return current, errors
        log(f"levels: midpoint {mid:g} is {errors[worst]:.3f} off the levels around it: fitted as a level too")
        fit_at(mid)
        values = sorted([*values, mid])


#: one axis of a conversion at levels: its levels, their fits, and its midpoints' errors (:func:`refine`)
Axis = tuple[Levels, FitAt, Mapping[tuple[float, float], float]]


def corner_error(grid: Grid, roughness: float, colour: Sequence[float], rough_at: FitAt, tint_at: FitAt) -> float:
    """The relative RMSE at one texel of a :class:`~matremap.svbrdf.mixed.Grid`: the source at its roughness and
    colour against the target the blend writes there (numbers from the roughness levels, colours from the colour's
    levels channel by channel), on the probe of the roughness level nearest it."""
    from matremap.transmissive import interpolation_error

    numbers = interpolated(grid.rough, roughness, rough_at)
    colours = interpolated(grid.tint, colour, tint_at)
    spec = numbers.spec
    target = numbers.with_params({p.name: colours.values[p.name].tolist() for p in spec.params if p.channels == 3})
    nearest = min(grid.rough.levels, key=lambda v: abs(v - roughness))
    source, fitted = rough_at(nearest)
    source = at(grid.tint, at(grid.rough, source, roughness), colour)
    return interpolation_error(source, fitted, target)


def checks(
    levels: Levels | Grid, axes: Sequence[Axis], thresholds: Thresholds, log: Callable[[str], None]
) -> list[Check]:
    """The gate's checks of the conversion at ``levels`` (one :data:`Axis`, two for a Grid): ``fit_error``, the
    worst of the levels' own errors, of the midpoints', of a colour's median texel and of a Grid's corners; and the
    colour and energy of the levels' probe renders (:func:`~matremap.svbrdf.quality.image_checks`). The evaluation
    under the environment draws the maps' reflection only; this is where what the glass lets through is judged."""
    errors: list[tuple[float, str]] = []
    fits = []
    for axis, fit_at, midpoints in axes:
        prefix = f"{axis.name} " if len(axes) > 1 else ""
        found = [fit_at(v)[1] for v in axis.levels]
        fits += [(f"{prefix}level {v:g}", r) for v, r in zip(axis.levels, found, strict=True)]
        errors += [(float(r.loss), f"{prefix}level {v:g}") for v, r in zip(axis.levels, found, strict=True)]
        errors += [(e, f"{prefix}midpoint {0.5 * (a + b):g}") for (a, b), e in midpoints.items()]
        typical = typical_error(axis, fit_at)
        if typical is not None:
            errors.append((typical, f"the median colour {np.round(axis.typical or (), 3).tolist()}"))
    if isinstance(levels, Grid):
        (_, rough_at, _), (_, tint_at, _) = axes
        for r, c in levels.corners:
            e = corner_error(levels, r, c, rough_at, tint_at)
            errors.append((e, f"the texel of roughness {r:.3g} and colour {np.round(c, 3).tolist()}"))
    worst, where = max(errors)
    log(
        f"levels: relative error on the transmission probe {min(errors)[0]:.4f}-{worst:.4f} over {len(fits)} "
        f"level(s), their midpoints and typical texels (worst at {where}); the evaluation draws reflection only"
    )
    return probe_checks(fits, worst, where, thresholds)


def probe_checks(fits: Sequence[tuple[str, Any]], worst: float, where: str, thresholds: Thresholds) -> list[Check]:
    """The gate's checks of uniform fits (name, fit result) on their probe: ``fit_error`` (``worst``, at ``where``)
    and the colour and energy of each fit's probe renders (:func:`~matremap.svbrdf.quality.image_checks`)."""
    from matremap.core.fit import FULL, part
    from matremap.renderers import get_renderer
    from matremap.renderers.base import render_images

    scene = fits[0][1].scene
    pairs = []
    for name, r in fits:
        src = render_images(get_renderer(r.source_renderer), [part(r.source, FULL) or r.source], scene)[0]
        tgt = render_images(get_renderer(r.target_renderer), [r.target], scene)[0]
        pairs.append((name, src * r.irradiance_scale, tgt))
    return [
        Check("fit_error", worst, thresholds.fit_error, f"relative RMSE on the {scene.describe()}, worst at {where}"),
        *image_checks(pairs, scene.mask(), thresholds),
    ]


__all__ = [
    "MAX_LEVELS",
    "OVER_FITS",
    "REFINE",
    "Axis",
    "FitAt",
    "at",
    "checks",
    "probe_checks",
    "corner_error",
    "interpolated",
    "midpoint",
    "refine",
    "typical_error",
]
