"""Stability analysis of a sweep: which grid points are not to be trusted, and why.

:func:`analyse` takes the rows of a sweep database, the grid and the sweep configuration, places the
finished points on the grid and gives every point a list of flag reasons. It is a pure function
(no I/O). The rules, with their thresholds (module constants) and the reasoning behind them:

``failed``
    The fit raised (status is not ``ok``). Nothing else is tested on such a point.

``jump:<param>``
    A fitted target parameter jumps against its grid neighbours: the optimiser fell into another
    local minimum, or onto another branch of a non-unique solution. Each line of the grid (the
    points along one numeric axis, the others held) is tested for every channel of every fitted
    parameter, in two ways:

    *Isolated outliers.* Each point is predicted from its line neighbours alone by short
    polynomial stencils: the chord through the two neighbours, chords that skip one of them, the
    cubic through two neighbours a side, and straight and quadratic extrapolations from either
    side. The point's deviation is its distance to the *range* those predictions span (zero when
    inside). A smooth function lies between the chord and the one-sided extrapolations wherever
    its curvature keeps its sign (the chord errs on one side, tangent-like extrapolations on the
    other), so smooth curved functions such as a concave alpha2 = f(alpha1) give no deviation
    however coarse the grid, while an outlier lies outside every prediction. A prediction that
    uses a bad neighbour only widens the range, and every point keeps predictions that avoid any
    one neighbour, so the neighbours of an outlier are not flagged with it.
    Near the ends of a line nothing brackets the curvature: the end point is extrapolated
    straight, quadratically and cubically from its nearest neighbours and from stencils that skip
    the first or the second of them, the second point has fewer chords, and only the part of the
    deviation beyond the spread of the predictions counts (twice the spread at the ends). Ends
    are therefore judged conservatively: a curve with an infinite slope at its end (sqrt(x) from
    0) is still not flagged, but an end outlier must be larger than the disagreement of the
    extrapolations to be caught along that axis (a point is usually inside the grid along its
    other axis).

    *Steps.* The outliers are set aside, then between consecutive points i, i+1 with three points
    on each side, the left side is extrapolated (straight and quadratic) to i+1 and the right side
    to i. A step makes point i+1 lie beyond the left extrapolations and point i beyond the right
    ones, in opposite directions; smooth curvature puts both misses on the same side, so it is
    never taken for a step. The step size is the smaller miss less the disagreement of that
    side's two extrapolations (an inflection between coarse points looks like a soft step), and
    both points at the step are flagged. A step that leaves fewer than three points on one side
    is only caught where those points stand out as outliers.

    A deviation (or step) counts when it exceeds all of: ``JUMP_RELATIVE`` (5 %) of the local
    magnitude, max(|value|, |prediction|, a quarter of the value range along the line), so that a
    parameter that rises from ~0 is not judged against its tiny first values; ``JUMP_TYPICAL``
    (5) times the median deviation along the line, so that a line which is rough all along (a
    degenerate region) is not flagged point by point; and ``JUMP_FLOOR`` (1e-4, parameter units),
    below which differences are fit noise. Parameters with a log scale (Phong exponents) are
    tested on log(value), with the 5 % as log(1.05). Axes with geometric spacing are used in
    log(x). RGB parameters are tested per channel unless grey in every row. Lines with fewer than
    ``JUMP_MIN_POINTS`` (4) finished points (missing points are skipped over), and axes of
    options, are not tested.

``above1:<param>``
    A fitted parameter of role ``specular`` exceeds 1 on some channel. Mitsuba 0.6's Ward and
    Phong scale rho_s and rho_d by 0.99 / max(rho_s + rho_d) when that sum exceeds 1 (energy
    clamp), so above 1 only the channel ratios reach the image: the fitted value is not unique,
    its size is arbitrary and it cannot be used as it stands.

``bound:<param>``
    A fitted parameter sits within ``BOUND_TOL`` (1e-6) of the width of its range from one of its
    bounds: the optimiser wanted to go further, so the target model cannot match the source there.
    Not flagged: a value the fitter set without optimising (a stage with no evaluations, e.g. "source
    part is black; target part set to its minimum"), a lower bound of 0 of a parameter the image
    scales with (albedo, colour, F0), where 0 is simply a black part rather than a stuck fit, and a
    roughness at its bound where the source's roughness is at one of its own: the end of one range is
    the end of the other (a mirror stays a mirror, glTF roughness 1 is Cycles roughness 1), so
    excluding those points would shrink the learned domain to the grid's interior and leave a map's
    smoothest and roughest texels outside it (a glTF BoomBox onto Cycles: half its texels). Nor a roughness at its
    bound fitted as closely as the sweep's typical fit (a loss within ``LOSS_MIN`` or the median of the sweep's):
    the target's roughest (or smoothest) is then the closest it gets, and as close as anywhere, the mapping
    saturating there (a rough glTF base under a sheen onto OpenPBR: glTF roughness 0.85 to 0.99 all fitted at
    OpenPBR's 1 within 0.6 to 0.7 %, excluded before, and 30 % of Khronos SheenCloth's texels then counted outside
    the learned domain), nor any other parameter at its bound fitted so closely: a rough plastic's coat turned off
    (int_ior at 1) to draw UsdPreviewSurface's roughness-1 specular as diffuse, 0.3 % off at the grid's brightest
    diffuse colour, was excluded, and 58 % of the usd-wg TextureCoordinateTest's texels counted outside.

``loss``
    The loss is an outlier of the sweep: its robust z-score on log(loss), (log L - median) /
    (1.4826 MAD), exceeds ``LOSS_Z`` (3.5, the usual modified z-score cut of Iglewicz and Hoaglin),
    and the loss itself exceeds ``LOSS_MIN`` (0.02, i.e. 2 % relative RMSE: below it a remapping is
    close on the probe whatever the rest of the sweep does). Log, because losses spread over
    decades. The MAD is floored at ``LOSS_MIN_SPREAD`` (0.05 in log units) so that a sweep of
    near-identical losses does not flag points that differ by a few per cent. Where a whole region
    of the grid fits badly, the MAD is large and few points stand out: this rule finds single
    failed fits, not bad regions (the loss map shows those). A loss above ``LOSS_MAX`` of the sweep's
    objective (l2: 0.5, half the image's energy unexplained; ssim: 0.9 of 1 - SSIM, where a black or unrelated
    image reads about 1, for the SSIM of a lobe that only resembles its source -- a pure-specular Ward as AS
    under the mixed probe, 0.48-0.62 -- is a poor match, not none) is flagged whatever the others: a sweep
    whose every fit failed the same way (a source part drawn black, say) has no outlier, and was learned
    from.

Only fitted target parameters are tested: those the model fits by default or the configuration
frees, minus those it fixes. Rows whose swept values are not on the current grid keep their
``failed``/``above1``/``bound``/``loss`` tests but take no part in neighbour tests.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from matremap.core.models import ModelSpec, ParamSpec
from matremap.dialects import get_model
from matremap.sweep.grid import Grid

JUMP_RELATIVE = 0.05
JUMP_TYPICAL = 5.0
JUMP_FLOOR = 1e-4
JUMP_MIN_POINTS = 4
BOUND_TOL = 1e-6
ABOVE = 1.0
LOSS_Z = 3.5
LOSS_MIN = 0.02
LOSS_MIN_SPREAD = 0.05
LOSS_MAX = 0.5
#: LOSS_MAX per objective (:mod:`matremap.core.objective`): their losses are measured on their own scales
LOSS_MAX_BY_OBJECTIVE = {"l2": LOSS_MAX, "log": LOSS_MAX, "ssim": 0.9}
#: RGB values whose channels agree within this (relative) are grey
GREY_RTOL = 1e-4

CHANNEL_NAMES = "rgb"


@dataclass
class Analysis:
    """Per-point flag reasons of a sweep and what is needed to plot it.

    ``flags`` maps every row key to its reasons (empty when the point is trusted); ``details``
    says more about some (jump axis, channel and size); ``counts`` is the number of points per
    reason; ``index`` maps the keys of finished points on the grid to their grid index.
    """

    rows: list[dict[str, Any]]
    grid: Grid | None
    source: ModelSpec
    target: ModelSpec
    tested: tuple[str, ...]
    flags: dict[str, list[str]]
    details: dict[str, list[str]]
    counts: dict[str, int]
    index: dict[str, tuple[int, ...]]
    off_grid: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    # -- queries -------------------------------------------------------------------------------
    def reasons(self, key: str) -> list[str]:
        return self.flags.get(key, [])

    def is_flagged(self, key: str) -> bool:
        return bool(self.flags.get(key))

    @property
    def flagged_keys(self) -> list[str]:
        return [r["key"] for r in self.rows if self.flags.get(r["key"])]

    @property
    def ok_rows(self) -> list[dict[str, Any]]:
        return [r for r in self.rows if r["status"] == "ok"]

    @property
    def failed_rows(self) -> list[dict[str, Any]]:
        return [r for r in self.rows if r["status"] != "ok"]

    def kind_counts(self) -> dict[str, int]:
        """Points per kind of reason (``jump``, ``above1``, ...), whatever the parameter."""
        out: dict[str, int] = {}
        for reasons in self.flags.values():
            for kind in sorted({r.split(":", 1)[0] for r in reasons}):
                out[kind] = out.get(kind, 0) + 1
        return out

    def row(self, key: str) -> dict[str, Any]:
        for r in self.rows:
            if r["key"] == key:
                return r
        raise KeyError(key)

    def target_array(self, param: str, channel: int = 0) -> np.ndarray:
        """A fitted target value over the grid (NaN where there is no finished point)."""
        return self._array(lambda r: _channel(r["target"].get(param), channel))

    def loss_array(self) -> np.ndarray:
        return self._array(lambda r: r["loss"])

    def flagged_array(self) -> np.ndarray:
        """Boolean array over the grid: the point exists and is flagged."""
        if self.grid is None:
            return np.zeros((0,), dtype=bool)
        out = np.zeros(self.grid.shape, dtype=bool)
        for r in self.rows:
            ix = self._grid_index(r["key"])
            if ix is not None and self.flags.get(r["key"]):
                out[ix] = True
        return out

    def _grid_index(self, key: str) -> tuple[int, ...] | None:
        return self.index.get(key)

    def _array(self, get: Callable[[dict[str, Any]], Any]) -> np.ndarray:
        if self.grid is None:
            return np.full((0,), np.nan)
        out = np.full(self.grid.shape, np.nan)
        by_key = {r["key"]: r for r in self.rows}
        for key, ix in self.index.items():
            r = by_key[key]
            if r["status"] == "ok":
                v = get(r)
                out[ix] = np.nan if v is None else float(v)
        return out


# ---------------------------------------------------------------------------------------------
# Entry point


def analyse(rows: Sequence[Mapping[str, Any]], grid: Grid | Mapping[str, Any] | None, config: Any) -> Analysis:
    """Flag the points of a sweep (see the module docstring for the rules).

    ``grid`` is a :class:`Grid` or its JSON form (``store.grid``), or None when unknown (then no
    neighbour test); ``config`` is a :class:`~matremap.sweep.run.SweepConfig` or its JSON form.
    """
    if grid is not None and not isinstance(grid, Grid):
        grid = Grid.from_dict(grid)
    source_id, target_id, fix, free = _config_parts(config)
    source, target = get_model(source_id), get_model(target_id)
    tested = tuple(p.name for p in target.params if (p.fit or p.name in free) and p.name not in fix)
    points = [dict(r) for r in rows]
    flags: dict[str, list[str]] = {r["key"]: [] for r in points}
    details: dict[str, list[str]] = {r["key"]: [] for r in points}
    notes: list[str] = []

    index, off_grid = _place(points, grid)
    ok = [r for r in points if r["status"] == "ok" and isinstance(r.get("target"), Mapping)]
    for r in points:
        if r["status"] != "ok" or not isinstance(r.get("target"), Mapping):
            flags[r["key"]].append("failed")

    if grid is not None and index:
        _jump_tests(ok, grid, index, target, tested, flags, details, notes)
    elif grid is None:
        notes.append("no grid stored in the database: neighbour (jump) tests skipped")

    losses = [float(r["loss"]) for r in ok if r.get("loss") is not None]
    close = max(LOSS_MIN, float(np.median(losses))) if losses else LOSS_MIN
    for r in ok:
        _value_tests(r, source, target, tested, flags[r["key"]], details[r["key"]], close)
    _loss_test(ok, flags, details, LOSS_MAX_BY_OBJECTIVE.get(_objective(config), LOSS_MAX))

    # one entry per reason, in a stable order
    order = {"failed": 0, "jump": 1, "above1": 2, "bound": 3, "loss": 4}
    for key, reasons in flags.items():
        flags[key] = sorted(dict.fromkeys(reasons), key=lambda s: (order.get(s.split(":")[0], 9), s))
    counts: dict[str, int] = {}
    for reasons in flags.values():
        for reason in reasons:
            counts[reason] = counts.get(reason, 0) + 1
    counts = dict(sorted(counts.items(), key=lambda kv: (order.get(kv[0].split(":")[0], 9), kv[0])))
    return Analysis(points, grid, source, target, tested, flags, details, counts, index, off_grid, notes)


def _config_parts(config: Any) -> tuple[str, str, set[str], set[str]]:
    if isinstance(config, Mapping):
        return (
            config["source"]["model"],
            config["target"]["model"],
            set(config["target"].get("fix") or {}),
            set(config["target"].get("free") or ()),
        )
    return config.source.model, config.target, set(config.fix), set(config.free)


def _place(rows: Sequence[Mapping[str, Any]], grid: Grid | None) -> tuple[dict[str, tuple[int, ...]], list[str]]:
    """Grid index of each row from its swept values; rows off the grid are listed apart."""
    if grid is None:
        return {}, [r["key"] for r in rows]
    lookup = [{_hashable(v): i for i, v in enumerate(a.values)} for a in grid.axes]
    labels = [a.label for a in grid.axes]
    index: dict[str, tuple[int, ...]] = {}
    off: list[str] = []
    for r in rows:
        swept = r.get("swept") or {}
        if set(swept) != set(labels):
            off.append(r["key"])
            continue
        ix = []
        for label, table in zip(labels, lookup, strict=True):
            i = table.get(_hashable(swept[label]))
            if i is None:
                break
            ix.append(i)
        if len(ix) == len(labels):
            index[r["key"]] = tuple(ix)
        else:
            off.append(r["key"])
    return index, off


def _hashable(v: Any) -> Any:
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else str(v)


def _channel(value: Any, channel: int | None) -> float | None:
    if value is None:
        return None
    if isinstance(value, (list, tuple)):
        return float(value[channel if channel is not None and channel < len(value) else 0])
    return float(value)


def _channels(value: Any) -> list[float]:
    if isinstance(value, (list, tuple)):
        return [float(x) for x in value]
    return [float(value)]


# ---------------------------------------------------------------------------------------------
# Per-point tests


def _value_tests(
    row: Mapping[str, Any],
    source: ModelSpec,
    target: ModelSpec,
    tested: Iterable[str],
    reasons: list[str],
    details: list[str],
    close: float = LOSS_MIN,
) -> None:
    values = row["target"]
    optimised = _optimised(row)
    # the ends of the ranges meeting, or the closest the target gets and as close as the sweep's fits: a
    # saturation, not a stuck fit
    loss = row.get("loss")
    good = loss is not None and float(loss) <= close
    saturated = _roughness_at_bound(row.get("source"), source) or good
    for name in tested:
        if name not in values:
            continue
        p = target.param(name)
        chans = _channels(values[name])
        if p.role == "specular" and max(chans) > ABOVE:
            reasons.append(f"above1:{name}")
            details.append(f"{name} = {_fmt(chans)} > 1 (trimmed by the energy clamp)")
        if optimised is not None and name not in optimised:
            continue
        lo, hi = p.bounds
        tol = BOUND_TOL * (hi - lo)
        at_lo = [c for c in chans if c <= lo + tol]
        at_hi = [c for c in chans if c >= hi - tol]
        if at_lo and p.scales_image and lo == 0.0:
            at_lo = []  # a black part is an answer, not a stuck fit
        if (p.role == "roughness" and saturated) or good:
            at_lo, at_hi = [], []  # the end of the source's range maps to the end of the target's, or the closest
        if at_lo or at_hi:
            reasons.append(f"bound:{name}")
            details.append(
                f"{name} = {_fmt(chans)} at its {'lower' if at_lo else 'upper'} bound {lo if at_lo else hi:g}"
            )


def _roughness_at_bound(values: Any, source: ModelSpec) -> bool:
    """Whether every roughness parameter of the source that ``values`` holds sits at one of its bounds."""
    if not isinstance(values, Mapping):
        return False
    found = False
    for p in source.params_with_roles(("roughness",)):
        if p.name not in values:
            continue
        lo, hi = p.bounds
        tol = BOUND_TOL * (hi - lo)
        for c in _channels(values[p.name]):
            if lo + tol < c < hi - tol:
                return False
        found = True
    return found


def _optimised(row: Mapping[str, Any]) -> set[str] | None:
    """Parameters some stage actually optimised (None when the row has no stage records)."""
    stages = row.get("stages")
    if not stages:
        return None
    out: set[str] = set()
    for s in stages:
        if s.get("evaluations", 1):
            out.update(s.get("params") or ())
    return out


def _objective(config: Any) -> str:
    """The objective of a sweep configuration (object or JSON form); ``l2`` when it does not say."""
    value = config.get("objective", "l2") if isinstance(config, Mapping) else getattr(config, "objective", "l2")
    return str(value)


def _loss_test(
    ok: Sequence[Mapping[str, Any]],
    flags: dict[str, list[str]],
    details: dict[str, list[str]],
    loss_max: float = LOSS_MAX,
) -> None:
    losses = [(r["key"], float(r["loss"])) for r in ok if r.get("loss") is not None and r["loss"] > 0]
    for key, loss in losses:
        if loss > loss_max:  # no remapping at all, however many points share it
            flags[key].append("loss")
            details[key].append(f"loss {loss:.3g} above {loss_max:g}: the fit found no match")
    losses = [(k, v) for k, v in losses if v <= loss_max]
    if len(losses) < 3:
        return
    logs = np.log([v for _, v in losses])
    med = float(np.median(logs))
    spread = max(1.4826 * float(np.median(np.abs(logs - med))), LOSS_MIN_SPREAD)
    for (key, loss), lg in zip(losses, logs, strict=True):
        z = (lg - med) / spread
        if z > LOSS_Z and loss > LOSS_MIN:
            flags[key].append("loss")
            details[key].append(f"loss {loss:.3g}: robust z {z:.1f} (median {math.exp(med):.3g})")


def _fmt(chans: Sequence[float]) -> str:
    if all(c == chans[0] for c in chans):
        return f"{chans[0]:.4g}"
    return "[" + ", ".join(f"{c:.4g}" for c in chans) + "]"


# ---------------------------------------------------------------------------------------------
# Neighbour (jump) tests


def _jump_tests(
    ok: Sequence[Mapping[str, Any]],
    grid: Grid,
    index: Mapping[str, tuple[int, ...]],
    target: ModelSpec,
    tested: Sequence[str],
    flags: dict[str, list[str]],
    details: dict[str, list[str]],
    notes: list[str],
) -> None:
    on_grid = [r for r in ok if r["key"] in index]
    keys = np.full(grid.shape, None, dtype=object)
    for r in on_grid:
        keys[index[r["key"]]] = r["key"]
    numeric_axes = []
    for a, axis in enumerate(grid.axes):
        if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in axis.values):
            if len(axis.values) >= JUMP_MIN_POINTS:
                numeric_axes.append(a)
            else:
                notes.append(
                    f"axis {axis.label} has {len(axis.values)} values: too few for jump tests (needs {JUMP_MIN_POINTS})"
                )
        else:
            notes.append(f"axis {axis.label} is an option: no jump tests along it")
    for name in tested:
        p = target.param(name)
        for channel in _distinct_channels(on_grid, name, p):
            values = np.full(grid.shape, np.nan)
            for r in on_grid:
                v = _channel(r["target"].get(name), channel)
                if v is not None:
                    values[index[r["key"]]] = v
            use_log = p.log and bool(np.all(values[np.isfinite(values)] > 0))
            if use_log:
                values = np.log(values)
            label = name if p.channels == 1 or channel is None else f"{name}.{CHANNEL_NAMES[channel]}"
            for a in numeric_axes:
                x = _coordinates(grid.axes[a].values)
                moved = np.moveaxis(values, a, -1)
                moved_keys = np.moveaxis(keys, a, -1)
                for other in np.ndindex(moved.shape[:-1]):
                    line = moved[other]
                    found = line_jumps(x, line, log=use_log)
                    for i, kind, size in found:
                        key = moved_keys[other][i]
                        flags[key].append(f"jump:{name}")
                        details[key].append(
                            f"{label} {kind} along {grid.axes[a].label} ({size:.3g}{' in log' if use_log else ''})"
                        )


def is_grey(value: Any, rtol: float = GREY_RTOL) -> bool:
    """Whether an RGB value is grey: its channels agree within ``rtol`` (the fits' own tolerance)."""
    chans = _channels(value)
    lo, hi = min(chans), max(chans)
    return hi - lo <= rtol * max(abs(lo), abs(hi), 1e-9)


def _distinct_channels(rows: Sequence[Mapping[str, Any]], name: str, p: ParamSpec) -> list[int | None]:
    """The channels worth testing: one when the parameter is grey in every row."""
    if p.channels == 1:
        return [None]
    grey = all(is_grey(r["target"][name]) for r in rows if r["target"].get(name) is not None)
    return [0] if grey else [0, 1, 2]


def _coordinates(values: Sequence[float]) -> np.ndarray:
    """Axis coordinates for the stencils: log(x) when the axis is geometrically spaced."""
    x = np.asarray(values, dtype=float)
    if len(x) >= 3 and np.all(x > 0):
        ratios = x[1:] / x[:-1]
        geometric = np.allclose(ratios, ratios[0], rtol=1e-6) and not np.isclose(ratios[0], 1.0)
        if geometric:
            return np.log(x)
    return x


def _lagrange(xs: np.ndarray, ys: np.ndarray, x0: float) -> float:
    total = 0.0
    for j in range(len(xs)):
        w = 1.0
        for k in range(len(xs)):
            if k != j:
                w *= (x0 - xs[k]) / (xs[j] - xs[k])
        total += w * ys[j]
    return total


def _outside(v: float, preds: Sequence[float]) -> tuple[float, float]:
    """Signed distance of v outside the range of the predictions (0 inside) and the nearest one."""
    lo, hi = min(preds), max(preds)
    if v > hi:
        return v - hi, hi
    if v < lo:
        return v - lo, lo
    return 0.0, v


def _outlier_deviations(xs: np.ndarray, vs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per point: signed distance outside the range of its neighbours' predictions (less an
    allowance where that range cannot bracket curvature), and the nearest prediction."""
    m = len(vs)
    dev = np.zeros(m)
    nearest = vs.copy()

    def predict(stencil: Sequence[int], at: int) -> float:
        s = list(stencil)
        return _lagrange(xs[s], vs[s], xs[at])

    for i in range(m):
        left = [j for j in (i - 1, i - 2, i - 3, i - 4) if j >= 0]
        right = [j for j in (i + 1, i + 2, i + 3, i + 4) if j < m]
        preds = []
        if left and right:
            preds.append(predict([left[0], right[0]], i))  # the chord
        if len(left) >= 2 and len(right) >= 2:
            preds.append(predict(left[:2] + right[:2], i))  # the cubic through two a side
        for side, other in ((left, right), (right, left)):
            if len(side) >= 2:
                preds.append(predict(side[:2], i))  # straight extrapolation from one side
                if other:
                    preds.append(predict([other[0], side[1]], i))  # a chord that skips side[0]
            if len(side) >= 3:
                preds.append(predict(side[:3], i))  # quadratic extrapolation from one side
            if not other and len(side) >= 3:
                # the end of the line: extrapolations that skip side[0] or side[1] as well, so
                # that one bad neighbour never leaves only bad predictions, and a cubic one
                preds += [predict([side[j] for j in t], i) for t in ((0, 2), (1, 2))]
                if len(side) >= 4:
                    preds += [predict([side[j] for j in t], i) for t in ((1, 2, 3), (0, 1, 2, 3))]
        if not preds:
            continue
        d, nearest[i] = _outside(vs[i], preds)
        # Without two neighbours on each side the predictions need not bracket a curved function:
        # count only what lies beyond their own disagreement (twice that at the ends).
        allowance = 0.0
        if len(left) < 2 or len(right) < 2:
            allowance = (max(preds) - min(preds)) * (2.0 if not left or not right else 1.0)
        dev[i] = math.copysign(max(abs(d) - allowance, 0.0), d)
    return dev, nearest


def line_jumps(x: npt.ArrayLike, values: npt.ArrayLike, log: bool = False) -> list[tuple[int, str, float]]:
    """Jumps along one grid line: ``(position, "outlier" | "step", size)`` for each flagged point,
    the size relative to the local magnitude (absolute when ``log``: the values are logarithms).
    ``values`` may hold NaN (missing points: the line closes over them). The rules are in the
    module docstring."""
    x = np.asarray(x, dtype=float)
    v = np.asarray(values, dtype=float)
    where = np.flatnonzero(np.isfinite(v))
    if len(where) < JUMP_MIN_POINTS:
        return []
    xs, vs = x[where], v[where]
    span = float(vs.max() - vs.min())

    def magnitude(*vals: float) -> float:
        return 1.0 if log else max(max(abs(a) for a in vals), 0.25 * span)

    dev, nearest = _outlier_deviations(xs, vs)
    typical = float(np.median(np.abs(dev)))
    relative = math.log1p(JUMP_RELATIVE) if log else JUMP_RELATIVE

    def size_if_large(size: float, *vals: float) -> float:
        """The size relative to the local magnitude when it passes every threshold, else 0."""
        mag = magnitude(*vals)
        if size > relative * mag and size > JUMP_TYPICAL * typical and (log or size > JUMP_FLOOR):
            return size / mag
        return 0.0

    out: dict[int, tuple[str, float]] = {}
    for i in range(len(vs)):
        rel = size_if_large(abs(dev[i]), vs[i], nearest[i])
        if rel:
            out[i] = ("outlier", rel)

    # steps, on the line without its outliers (an outlier looks like two steps)
    keep = [i for i in range(len(vs)) if i not in out]
    ks, kv = xs[keep], vs[keep]

    def predict(stencil: Sequence[int], at: int) -> float:
        s = list(stencil)
        return _lagrange(ks[s], kv[s], ks[at])

    for i in range(len(keep) - 1):
        lefts = [j for j in (i, i - 1, i - 2) if j >= 0]
        rights = [j for j in (i + 1, i + 2, i + 3) if j < len(keep)]
        if len(lefts) < 3 or len(rights) < 3:
            continue
        to_right = [predict(lefts[:k], i + 1) for k in (2, 3)]
        to_left = [predict(rights[:k], i) for k in (2, 3)]
        miss_right, _ = _outside(kv[i + 1], to_right)
        miss_left, _ = _outside(kv[i], to_left)
        if miss_right * miss_left >= 0:  # same side (or none): curvature, not a step
            continue
        # beyond the disagreement of each side's straight and quadratic extrapolations
        size = min(abs(miss_right) - (max(to_right) - min(to_right)), abs(miss_left) - (max(to_left) - min(to_left)))
        rel = size_if_large(size, kv[i], kv[i + 1])
        if rel:
            for j in (keep[i], keep[i + 1]):
                if j not in out or out[j][1] < rel:
                    out[j] = ("step", rel)
    return [(int(where[i]), kind, size) for i, (kind, size) in sorted(out.items())]


__all__ = ["Analysis", "analyse", "is_grey", "line_jumps"]
