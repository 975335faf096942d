"""Sweep analysis output: a text summary, the paper's plots as PNG, and the export table.

``matremap sweep-report DB -o DIR`` runs the stability analysis (:mod:`matremap.sweep.stability`) on a
sweep database, prints a summary and writes, as far as the grid allows:

``specular.png``   the target's specular / F0 parameter against the source's, one curve per source
                   roughness, coloured by it (Sztrajman et al. 2019, the remapping curves);
``roughness.png``  target roughness against source roughness, one thin curve per source specular;
``loss.png``       the loss over the grid (log colour scale; a line for 1-D grids);
``roundtrip.png``  with ``--round-trip`` sweeps: recovered against original source parameters.

Flagged points are marked with a red x on every plot. Plots are drawn with matplotlib's Agg canvas
(no pyplot, no display), and every file is written under a temporary name in its folder, then moved
into place, so nothing half-written remains.

``matremap export DB -o FILE.csv|FILE.parquet`` writes one row per point (see :func:`export_table`).
"""

from __future__ import annotations

import csv
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from matremap.core.imageio import atomic_output
from matremap.core.models import ModelSpec
from matremap.errors import MatremapError
from matremap.sweep.grid import Grid
from matremap.sweep.stability import Analysis, analyse, is_grey
from matremap.sweep.store import SweepStore

if TYPE_CHECKING:  # matplotlib is imported when a plot is drawn
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

SPECULAR_ROLES = ("specular", "fresnel")
FLAG_STYLE: dict[str, Any] = {
    "marker": "x",
    "color": "red",
    "markersize": 8,
    "markeredgewidth": 1.8,
    "linestyle": "none",
    "zorder": 6,
}
REASONS = {
    "failed": "the fit raised",
    "jump": "fitted value jumps against its grid neighbours",
    "above1": "specular > 1: trimmed by the energy clamp, not unique",
    "bound": "fitted value at a bound of its range",
    "loss": "loss outlier of the sweep",
}


# ---------------------------------------------------------------------------------------------
# Loading


@dataclass
class SweepData:
    path: Path
    config: dict[str, Any]
    grid: Grid | None
    rows: list[dict[str, Any]]
    analysis: Analysis


def load(db: str | Path) -> SweepData:
    """Read a sweep database and analyse it."""
    with SweepStore.open(db) as store:
        config = store.config
        grid_dict = store.grid
        rows = store.rows()
    if not isinstance(config, Mapping):
        raise MatremapError(f"{db} holds no sweep configuration; was it written by `matremap sweep`?")
    grid = Grid.from_dict(grid_dict) if grid_dict else None
    return SweepData(Path(db), config, grid, rows, analyse(rows, grid, config))


# ---------------------------------------------------------------------------------------------
# Round trip


@dataclass(frozen=True)
class RoundTrip:
    """Recovered against original values of one swept source parameter (channel).

    ``slope``, ``intercept`` and ``r2`` are those of the least-squares line with intercept,
    recovered = slope * original + intercept (``r2`` its coefficient of determination);
    ``r2_identity`` measures the fit of the line y = x itself, 1 - SS(recovered - original) /
    SS(original - mean), so it is 1 only when the values come back unchanged.
    """

    param: str
    keys: tuple[str, ...]
    original: np.ndarray
    recovered: np.ndarray
    slope: float
    intercept: float
    r2: float
    r2_identity: float

    @property
    def n(self) -> int:
        return len(self.keys)


def round_trip_stats(rows: Sequence[Mapping[str, Any]], grid: Grid | Mapping[str, Any] | None) -> dict[str, RoundTrip]:
    """Slope and R² of recovered (``back``) against original (swept) values for every numeric grid
    axis, from the ok rows that have a round trip. An RGB parameter swept grey is reported as one
    entry when it comes back grey, else per channel (``k.r``, ``k.g``, ``k.b``)."""
    if grid is None:
        return {}
    if not isinstance(grid, Grid):
        grid = Grid.from_dict(grid)
    done = [r for r in rows if r.get("status") == "ok" and isinstance(r.get("back"), Mapping)]
    out: dict[str, RoundTrip] = {}
    for axis in grid.axes:
        if not all(_is_number(v) for v in axis.values):
            continue
        samples = [
            (r["key"], float(r["swept"][axis.label]), r["back"].get(axis.name))
            for r in done
            if axis.label in (r.get("swept") or {}) and r["back"].get(axis.name) is not None
        ]
        if not samples:
            continue
        if axis.channel is not None:
            channels: list[tuple[str, int | None]] = [(axis.label, axis.channel)]
        elif all(is_grey(b) for _, _, b in samples):
            channels = [(axis.label, None)]  # grey: the mean of the channels
        else:
            channels = [(f"{axis.name}.{c}", i) for i, c in enumerate("rgb")]
        keys = tuple(k for k, _, _ in samples)
        x = np.array([o for _, o, _ in samples], dtype=float)
        for label, ch in channels:
            y = np.array([_pick(b, ch) if ch is not None else float(np.mean(b)) for _, _, b in samples], dtype=float)
            out[label] = _line_stats(label, keys, x, y)
    return out


def _line_stats(label: str, keys: tuple[str, ...], x: np.ndarray, y: np.ndarray) -> RoundTrip:
    nan = float("nan")
    if len(x) < 2 or np.ptp(x) == 0:
        return RoundTrip(label, keys, x, y, nan, nan, nan, nan)
    slope, intercept = np.polyfit(x, y, 1)
    ss_tot_y = float(np.sum((y - y.mean()) ** 2))
    ss_res = float(np.sum((y - (slope * x + intercept)) ** 2))
    r2 = 1.0 - ss_res / ss_tot_y if ss_tot_y > 0 else (1.0 if ss_res == 0 else nan)
    ss_tot_x = float(np.sum((x - x.mean()) ** 2))
    r2_identity = 1.0 - float(np.sum((y - x) ** 2)) / ss_tot_x
    return RoundTrip(label, keys, x, y, float(slope), float(intercept), float(r2), r2_identity)


# ---------------------------------------------------------------------------------------------
# Report


def write_report(db: str | Path, out: Path, force: bool = False) -> str:
    """Analyse a sweep database, write its plots into ``out`` (created if needed) and return the
    summary text. Existing plots are only replaced with ``force``."""
    data = load(db)
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise MatremapError(f"{out} exists and is not a folder")
    plots, skipped = _plan(data)
    existing = [out / name for name, _ in plots if (out / name).exists()]
    if existing and not force:
        if len(existing) == 1:
            raise MatremapError(f"{existing[0]} already exists; pass --force to overwrite it")
        raise MatremapError(f"{', '.join(str(p) for p in existing)} already exist; pass --force to overwrite them")
    if plots:
        _matplotlib()  # fail before creating anything
        try:
            out.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise MatremapError(f"cannot create folder {out}: {e}") from None
    written = []
    for name, draw in plots:
        path = out / name
        fig = _figure()
        draw(fig)
        try:
            with atomic_output(path) as tmp:
                fig.savefig(tmp, format="png")
        except OSError as e:
            raise MatremapError(f"cannot write {path}: {e}") from None
        written.append(path)
    return summary(data, skipped, written)


def summary(data: SweepData, skipped: Sequence[str] = (), written: Sequence[Path] = ()) -> str:
    """The report's text: what was swept, how many points, the flags, losses and costs, and the round trip."""
    lines = [f"sweep {data.path}", _summary_setup(data), *_summary_points(data), *_summary_fits(data)]
    lines += _summary_round_trip(data)
    for note in list(data.analysis.notes) + list(skipped):
        lines.append(f"  note: {note}")
    if written:
        lines.append("  wrote: " + ", ".join(str(p) for p in written))
    return "\n".join(lines)


def _summary_setup(data: SweepData) -> str:
    """Source model and options -> target model, fixes, strategy and modes."""
    cfg, grid = data.config, data.grid
    src = cfg["source"]
    swept = {ax.name for ax in grid.axes} if grid is not None else set()
    opts = {k: v for k, v in src["params"].items() if isinstance(v, str) and k not in swept}
    tgt = cfg["target"]
    extras = [
        f"fix {', '.join(f'{k}={v}' for k, v in tgt.get('fix', {}).items())}" if tgt.get("fix") else "",
        f"free {', '.join(tgt['free'])}" if tgt.get("free") else "",
    ]
    modes = [m for m, on in (("continuation", cfg.get("continuation")), ("round trip", cfg.get("round_trip"))) if on]
    return (
        f"  {src['model']}{_opts(opts)} -> {tgt['model']}"
        + (f" ({'; '.join(e for e in extras if e)})" if any(extras) else "")
        + f", strategy {cfg.get('strategy')}"
        + (f", {', '.join(modes)}" if modes else "")
    )


def _summary_points(data: SweepData) -> list[str]:
    """The grid, the points done and failed, and the stability flags."""
    a, grid = data.analysis, data.grid
    lines = []
    if grid is not None:
        missing = len(grid) - len(a.index)
        lines.append(f"  grid: {' x '.join(f'{ax.label} {len(ax.values)}' for ax in grid.axes)} = {len(grid)} points")
    else:
        missing = 0
        lines.append("  grid: not stored in the database")
    counts = f"  points: {len(a.ok_rows)} ok, {len(a.failed_rows)} failed"
    if a.off_grid:
        counts += f", {len(a.off_grid)} not on the current grid (exported, not plotted)"
    if missing > 0:
        counts += f"; {missing} grid points without a result yet"
    lines.append(counts)
    if a.flagged_keys:
        lines.append(f"  flagged: {len(a.flagged_keys)} point(s)")
        width = max(len(r) for r in a.counts)
        for reason, n in a.counts.items():
            lines.append(f"    {reason:<{width}}  {n:>5}   {REASONS.get(reason.split(':')[0], '')}")
    else:
        lines.append("  flagged: none")
    return lines


def _summary_fits(data: SweepData) -> list[str]:
    """Losses, renders and seconds per fit, warm starts."""
    a = data.analysis
    ok = a.ok_rows
    lines = []
    losses = np.array([r["loss"] for r in ok if r.get("loss") is not None], dtype=float)
    if losses.size:
        lines.append(
            f"  loss (relative RMSE): median {np.median(losses):.4g}, p95 {np.percentile(losses, 95):.4g}, "
            f"max {losses.max():.4g}"
        )
    renders = [r["renders"] for r in ok if r.get("renders") is not None]
    seconds = [r["seconds"] for r in a.rows if r.get("seconds") is not None]
    if renders or seconds:
        lines.append(
            f"  per fit: median {np.median(renders) if renders else float('nan'):.0f} renders, "
            f"median {np.median(seconds) if seconds else float('nan'):.3g} s"
        )
    lines.append(f"  warm-started: {sum(1 for r in ok if r.get('warm'))} of {len(ok)}")
    return lines


def _summary_round_trip(data: SweepData) -> list[str]:
    """Round-trip regression lines, with and without the flagged points, and the back-fit losses."""
    a, grid = data.analysis, data.grid
    trips = round_trip_stats(data.rows, grid)
    if not trips:
        return ["  round trip: no finished round trip on a numeric grid axis"] if data.config.get("round_trip") else []
    lines = ["  round trip, recovered vs original (least-squares line with intercept; R² of that line, and of y = x):"]
    lines += [_trip_line(t) for t in trips.values()]
    unflagged = [r for r in data.rows if not a.flags.get(r["key"])]
    if len(unflagged) < len(data.rows):
        clean = round_trip_stats(unflagged, grid)
        lines.append(
            f"    without the {len(data.rows) - len(unflagged)} flagged points (as the paper filters unstable cases):"
        )
        lines += [_trip_line(t) for t in clean.values()]
    back = [r["back_loss"] for r in a.ok_rows if r.get("back_loss") is not None]
    if back:
        lines.append(f"    back-fit loss: median {np.median(back):.4g}, max {max(back):.4g}")
    return lines


def _trip_line(t: Any) -> str:
    return (
        f"    {t.param}: slope {t.slope:.4f}, intercept {t.intercept:+.4g}, R² {t.r2:.4f} "
        f"(y = x: {t.r2_identity:.4f}), n = {t.n}"
    )


def _opts(opts: Mapping[str, str]) -> str:
    return f" ({', '.join(f'{k}={v}' for k, v in opts.items())})" if opts else ""


# ---------------------------------------------------------------------------------------------
# Plots


def _matplotlib() -> None:
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        raise MatremapError("plots need matplotlib: pip install matplotlib") from None


def _figure(width: float = 7.0, height: float = 5.0) -> Figure:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), dpi=110, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _numeric_axes(grid: Grid | None) -> list[int]:
    if grid is None:
        return []
    return [i for i, ax in enumerate(grid.axes) if all(_is_number(v) for v in ax.values)]


def _role_axis(grid: Grid | None, spec: ModelSpec, roles: Sequence[str]) -> int | None:
    """The first numeric grid axis sweeping a source parameter with one of these roles."""
    if grid is None:
        return None
    for i in _numeric_axes(grid):
        name = grid.axes[i].name
        if name in spec.param_names and spec.param(name).role in roles:
            return i
    return None


def _role_param(a: Analysis, roles: Sequence[str]) -> str | None:
    """The target's first fitted parameter with one of these roles."""
    for name in a.tested:
        if a.target.param(name).role in roles:
            return name
    return None


def _plan(data: SweepData) -> tuple[list[tuple[str, Callable]], list[str]]:
    """The plots this sweep allows, and why the others are skipped."""
    a, grid = data.analysis, data.grid
    plots: list[tuple[str, Callable]] = []
    skipped: list[str] = []
    spec_axis = _role_axis(grid, a.source, SPECULAR_ROLES)
    rough_axis = _role_axis(grid, a.source, ("roughness",))
    spec_param = _role_param(a, SPECULAR_ROLES)
    rough_param = _role_param(a, ("roughness",))
    have_ok = bool(a.index) and any(r["status"] == "ok" for r in a.rows)

    if spec_axis is None:
        skipped.append("specular.png skipped: no grid axis sweeps a source parameter of role specular or fresnel")
    elif spec_param is None:
        skipped.append(f"specular.png skipped: {a.target.id} fits no specular or fresnel parameter")
    elif not have_ok:
        skipped.append("specular.png skipped: no finished point on the grid")
    else:
        plots.append(("specular.png", lambda fig: _curves(fig, data, spec_axis, rough_axis, spec_param, "viridis")))
    if rough_axis is None:
        skipped.append("roughness.png skipped: no grid axis sweeps a source parameter of role roughness")
    elif rough_param is None:
        skipped.append(f"roughness.png skipped: {a.target.id} fits no roughness parameter")
    elif not have_ok:
        skipped.append("roughness.png skipped: no finished point on the grid")
    else:
        plots.append(
            ("roughness.png", lambda fig: _curves(fig, data, rough_axis, spec_axis, rough_param, "plasma", thin=True))
        )
    if any(r["status"] == "ok" and r.get("loss") is not None for r in a.rows):
        plots.append(("loss.png", lambda fig: _loss_plot(fig, data, spec_axis, rough_axis)))
    else:
        skipped.append("loss.png skipped: no finished point")
    trips = round_trip_stats(data.rows, grid)
    if trips:
        plots.append(("roundtrip.png", lambda fig: _round_trip_plot(fig, data, trips)))
    elif data.config.get("round_trip"):
        skipped.append("roundtrip.png skipped: no finished round trip on a numeric grid axis")
    return plots, skipped


def _channel_for(a: Analysis, param: str, axis_channel: int | None) -> tuple[int, str]:
    """Which channel of a target parameter to plot, and its label suffix."""
    p = a.target.param(param)
    if p.channels == 1:
        return 0, ""
    ch = axis_channel if axis_channel is not None else 0
    grey = all(is_grey(r["target"][param]) for r in a.ok_rows if r["target"].get(param) is not None)
    return ch, "" if grey else f" ({'rgb'[ch]})"


def _flag_legend(ax: Axes, n: int) -> None:
    if n:
        ax.legend(loc="best", fontsize="small")


def _curves(
    fig: Figure,
    data: SweepData,
    x_axis: int,
    colour_axis: int | None,
    param: str,
    cmap_name: str,
    thin: bool = False,
) -> None:
    """Target ``param`` against the source values of ``x_axis``: one curve per other grid line,
    coloured by the value of ``colour_axis``."""
    from matplotlib import colormaps
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize

    a, grid = data.analysis, data.grid
    assert grid is not None  # _plan draws curves only along a grid axis
    axis = grid.axes[x_axis]
    ch, suffix = _channel_for(a, param, axis.channel)
    values = np.moveaxis(a.target_array(param, ch), x_axis, -1)
    flagged = np.moveaxis(a.flagged_array(), x_axis, -1)
    x = np.asarray(axis.values, dtype=float)
    ax = fig.add_subplot()
    cmap = colormaps[cmap_name]
    norm = None
    if colour_axis is not None:
        cvals = np.asarray(grid.axes[colour_axis].values, dtype=float)
        norm = Normalize(cvals.min(), cvals.max() if cvals.max() > cvals.min() else cvals.min() + 1)
        # index of the colour axis among the remaining axes after moving x_axis last
        rest = [i for i in range(len(grid.axes)) if i != x_axis]
        cpos = rest.index(colour_axis)
    fx, fy = [], []
    for other in np.ndindex(values.shape[:-1]):
        y = values[other]
        if not np.any(np.isfinite(y)):
            continue
        colour = cmap(norm(cvals[other[cpos]])) if norm is not None else "C0"
        ax.plot(x, y, "-", color=colour, lw=0.8 if thin else 1.6, marker="." if not thin else None, ms=4)
        sel = flagged[other] & np.isfinite(y)
        fx += list(x[sel])
        fy += list(y[sel])
    if fx:
        ax.plot(fx, fy, label=f"flagged ({len(fx)})", **FLAG_STYLE)
    if colour_axis is not None:
        fig.colorbar(ScalarMappable(norm=norm, cmap=cmap), ax=ax, label=f"source {grid.axes[colour_axis].label}")
    if param == axis.name:
        lo, hi = float(np.nanmin(x)), float(np.nanmax(x))
        ax.plot([lo, hi], [lo, hi], "--", color="0.6", lw=1, label="y = x")
        ax.legend(loc="best", fontsize="small")
    else:
        _flag_legend(ax, len(fx))
    ax.set_xlabel(f"source {axis.label} ({a.source.id})")
    ax.set_ylabel(f"target {param}{suffix} ({a.target.id})")
    ax.set_title(f"{a.source.id} \u2192 {a.target.id}: {param}{suffix} vs {axis.label}", fontsize="medium")
    ax.grid(True, alpha=0.3)


def _edges(v: np.ndarray) -> np.ndarray:
    """Cell edges around the axis values (midpoints; geometric midpoints on log-spaced axes)."""
    if len(v) == 1:
        return np.array([v[0] - 0.5, v[0] + 0.5]) if v[0] == 0 else np.array([v[0] * 0.9, v[0] * 1.1])
    logs = (
        np.all(v > 0)
        and np.allclose(v[1:] / v[:-1], v[1] / v[0], rtol=1e-6)
        and not np.allclose(np.diff(v), v[1] - v[0], rtol=1e-6)
    )
    w = np.log(v) if logs else v
    mid = (w[1:] + w[:-1]) / 2
    e = np.concatenate([[w[0] - (mid[0] - w[0])], mid, [w[-1] + (w[-1] - mid[-1])]])
    return np.exp(e) if logs else e


def _loss_plot(fig: Figure, data: SweepData, spec_axis: int | None, rough_axis: int | None) -> None:
    from matplotlib import colormaps
    from matplotlib.colors import LogNorm

    a, grid = data.analysis, data.grid
    numeric = _numeric_axes(grid) if a.index else []
    ax = fig.add_subplot()
    if not numeric:  # no usable grid: losses in database order
        ok = [r for r in a.rows if r["status"] == "ok" and r.get("loss") is not None]
        idx = np.arange(len(ok))
        loss = np.array([r["loss"] for r in ok], dtype=float)
        ax.semilogy(idx, loss, ".", color="C0")
        fl = [i for i, r in enumerate(ok) if a.is_flagged(r["key"])]
        if fl:
            ax.plot(idx[fl], loss[fl], label=f"flagged ({len(fl)})", **FLAG_STYLE)
        _flag_legend(ax, len(fl))
        ax.set_xlabel("point (database order)")
        ax.set_ylabel("loss (relative RMSE)")
        ax.set_title("loss per point", fontsize="medium")
        return
    assert grid is not None  # numeric axes come from a grid
    loss = a.loss_array()
    loss = np.where(loss > 0, loss, np.nan)
    flagged = a.flagged_array()
    if len(numeric) >= 2:
        xa = spec_axis if spec_axis is not None else numeric[-1]
        ya = rough_axis if rough_axis is not None and rough_axis != xa else next(i for i in numeric if i != xa)
    else:
        xa, ya = numeric[0], None
    keep = [xa] if ya is None else [ya, xa]
    others = tuple(i for i in range(len(grid.axes)) if i not in keep)
    reduced_note = ""
    order = [*others, *keep]
    loss = np.moveaxis(loss, order, list(range(len(order))))
    flagged = np.moveaxis(flagged, order, list(range(len(order))))
    if others:
        with np.errstate(all="ignore"):
            loss = np.fmax.reduce(loss.reshape(-1, *loss.shape[len(others) :]), axis=0)
            flagged = np.any(flagged.reshape(-1, *flagged.shape[len(others) :]), axis=0)
        reduced_note = f" (largest over {', '.join(grid.axes[i].label for i in others)})"
    finite = loss[np.isfinite(loss)]
    x = np.asarray(grid.axes[xa].values, dtype=float)
    if ya is None:
        ax.semilogy(x, loss, "-", marker=".", color="C0")
        sel = flagged & np.isfinite(loss)
        if np.any(sel):
            ax.plot(x[sel], loss[sel], label=f"flagged ({int(sel.sum())})", **FLAG_STYLE)
        _flag_legend(ax, int(sel.sum()))
        ax.set_xlabel(f"source {grid.axes[xa].label}")
        ax.set_ylabel("loss (relative RMSE)")
    else:
        y = np.asarray(grid.axes[ya].values, dtype=float)
        cmap = colormaps["magma"].with_extremes(bad="0.85")
        if finite.size:
            lo, hi = float(finite.min()), float(finite.max())
            norm = LogNorm(lo, hi if hi > lo else lo * 10)
        else:
            norm = LogNorm(1e-3, 1)
        mesh = ax.pcolormesh(_edges(x), _edges(y), np.ma.masked_invalid(loss), cmap=cmap, norm=norm)
        fig.colorbar(mesh, ax=ax, label="loss (relative RMSE)")
        yy, xx = np.nonzero(flagged)
        if len(xx):
            # red on a white halo, to stand out on any colour of the map
            ax.plot(x[xx], y[yy], **{**FLAG_STYLE, "color": "white", "markeredgewidth": 3.2})
            ax.plot(x[xx], y[yy], label=f"flagged ({len(xx)})", **FLAG_STYLE)
        _flag_legend(ax, len(xx))
        ax.set_xlabel(f"source {grid.axes[xa].label}")
        ax.set_ylabel(f"source {grid.axes[ya].label}")
    ax.set_title(f"{a.source.id} \u2192 {a.target.id}: loss{reduced_note}", fontsize="medium")


def _round_trip_plot(fig: Figure, data: SweepData, trips: Mapping[str, RoundTrip]) -> None:
    a = data.analysis
    n = len(trips)
    cols = min(n, 3)
    rows = math.ceil(n / cols)
    fig.set_size_inches(4.2 * cols, 4.0 * rows)
    for k, t in enumerate(trips.values()):
        ax = fig.add_subplot(rows, cols, k + 1)
        ax.plot(t.original, t.recovered, ".", color="C0", ms=5, label=f"points ({t.n})")
        lo = float(min(t.original.min(), np.nanmin(t.recovered)))
        hi = float(max(t.original.max(), np.nanmax(t.recovered)))
        ax.plot([lo, hi], [lo, hi], "--", color="0.5", lw=1, label="y = x")
        if math.isfinite(t.slope):
            xs = np.array([t.original.min(), t.original.max()])
            ax.plot(
                xs,
                t.slope * xs + t.intercept,
                "-",
                color="C1",
                lw=1.2,
                label=f"slope {t.slope:.3f}, R\u00b2 {t.r2:.3f}",
            )
        sel = np.array([a.is_flagged(key) for key in t.keys], dtype=bool)
        if np.any(sel):
            ax.plot(t.original[sel], t.recovered[sel], label=f"flagged ({int(sel.sum())})", **FLAG_STYLE)
        ax.set_xlabel(f"original {t.param}")
        ax.set_ylabel(f"recovered {t.param}")
        ax.set_title(t.param, fontsize="medium")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize="small")
    fig.suptitle(f"round trip {a.source.id} \u2192 {a.target.id} \u2192 {a.source.id}", fontsize="medium")


# ---------------------------------------------------------------------------------------------
# Export


Getter = Callable[[Mapping[str, Any]], Any]


def _getter(name: str, channel: int | None = None) -> Getter:
    """Reads ``name`` from a dict of values: as stored, or one channel of it as a float."""
    if channel is None:
        return lambda d: d.get(name)
    return lambda d: _pick(d.get(name), channel)


def _spec_columns(prefix: str, spec: ModelSpec) -> list[tuple[str, str, Getter]]:
    """(column, kind, getter) for every option and parameter channel of a model."""
    cols: list[tuple[str, str, Getter]] = []
    for o in spec.options:
        cols.append((f"{prefix}.{o.name}", "str", _getter(o.name)))
    for p in spec.params:
        if p.channels == 3:
            for i, c in enumerate("rgb"):
                cols.append((f"{prefix}.{p.name}.{c}", "float", _getter(p.name, i)))
        else:
            cols.append((f"{prefix}.{p.name}", "float", _getter(p.name, 0)))
    return cols


def _in_field(get: Getter, field: str) -> Getter:
    """Applies ``get`` to a row's ``field`` (a dict of values), or None when the row has none."""
    return lambda r: get(r[field]) if isinstance(r.get(field), Mapping) else None


def _pick(value: Any, i: int) -> float | None:
    if value is None:
        return None
    if isinstance(value, list):
        return float(value[i if i < len(value) else 0])
    return float(value)


def table(data: SweepData) -> tuple[list[str], list[str], list[list[Any]]]:
    """Column names, kinds (``float``, ``int``, ``str``, ``bool``) and rows of the export table."""
    a = data.analysis
    has_back = any(isinstance(r.get("back"), Mapping) for r in a.rows)
    groups = [("source", a.source, "source"), ("target", a.target, "target")]
    if has_back:
        groups.append(("back", a.source, "back"))
    cols: list[tuple[str, str, Getter]] = []
    for prefix, spec, field in groups:
        for name, kind, get in _spec_columns(prefix, spec):
            cols.append((name, kind, _in_field(get, field)))
    cols.append(("loss", "float", lambda r: r.get("loss")))
    if has_back:
        cols.append(("back_loss", "float", lambda r: r.get("back_loss")))
    cols += [
        ("renders", "int", lambda r: r.get("renders")),
        ("seconds", "float", lambda r: r.get("seconds")),
        ("warm", "int", lambda r: r.get("warm")),
        ("status", "str", lambda r: r.get("status")),
        ("flagged", "bool", lambda r: a.is_flagged(r["key"])),
        ("flags", "str", lambda r: ";".join(a.reasons(r["key"]))),
        ("message", "str", lambda r: r.get("message") or ""),
    ]
    rows = [[get(r) for _, _, get in cols] for r in a.rows]
    return [c[0] for c in cols], [c[1] for c in cols], rows


def export_table(db: str | Path, path: Path) -> int:
    """Write one row per point of a sweep database to ``path`` (``.csv`` or ``.parquet``):
    ``source.<param>``, ``target.<param>`` (options too, e.g. ``target.distribution``; RGB
    parameters as ``<param>.r/.g/.b``), ``back.<param>`` and ``back_loss`` for round trips, then
    ``loss``, ``renders``, ``seconds``, ``warm``, ``status``, ``flagged``, ``flags`` (the reasons,
    ';'-separated) and ``message``. Written atomically; returns the number of rows."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".csv", ".parquet"):
        raise MatremapError(f"cannot write {path}: unknown table type {path.suffix!r}; use .csv or .parquet")
    if suffix == ".parquet":
        try:
            import pyarrow as pa
            import pyarrow.parquet as pq
        except ImportError:
            raise MatremapError("writing Parquet needs pyarrow: pip install pyarrow") from None
    if not path.parent.is_dir():
        raise MatremapError(f"cannot write {path}: folder {path.parent} does not exist")
    names, kinds, rows = table(load(db))
    try:
        if suffix == ".csv":
            with atomic_output(path) as tmp, open(tmp, "w", newline="") as f:
                w = csv.writer(f)
                w.writerow(names)
                for row in rows:
                    w.writerow(["" if v is None else repr(v) if isinstance(v, float) else v for v in row])
        else:
            types = {"float": pa.float64(), "int": pa.int64(), "str": pa.string(), "bool": pa.bool_()}
            columns = {
                n: pa.array([row[i] for row in rows], type=types[k])
                for i, (n, k) in enumerate(zip(names, kinds, strict=True))
            }
            with atomic_output(path) as tmp:
                pq.write_table(pa.table(columns), tmp)
    except OSError as e:
        raise MatremapError(f"cannot write {path}: {e}") from None
    return len(rows)


__all__ = ["RoundTrip", "SweepData", "export_table", "load", "round_trip_stats", "summary", "table", "write_report"]
