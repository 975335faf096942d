"""Parameter sweeps: one uniform fit per grid point, into a remapping database (paper §4-5).

Work is cut into lines of the grid (the last axis varies along a line), lines into tasks submitted to
an executor (:mod:`matremap.sweep.executors`); a task's fits run in lockstep, one batched render call per
step for all of them (:func:`~matremap.core.lockstep.lockstep`); rows are stored as tasks finish
(:mod:`matremap.sweep.store`).
Running the same sweep again resumes it: finished points are skipped.

Continuation (an option, beyond the paper) fits the points of a line in order and starts each
from its finished neighbour's result instead of from the model defaults and a coarse search.
Lines are the same whatever the number of workers, so results do not depend on it.

Round trip (an option) fits each result back onto the source model, to measure how much of the
source parameters a remapping preserves.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, wait
from dataclasses import dataclass, field
from typing import Any

from matremap import __version__
from matremap.core.fit import STRATEGIES
from matremap.core.lockstep import Steps, lockstep
from matremap.core.material import Material
from matremap.core.objective import check as check_objective
from matremap.core.scene import Scene
from matremap.dialects import get_model
from matremap.errors import MatremapError, RendererUnavailable
from matremap.renderers.base import check_probe
from matremap.renderers.registry import can_draw, get_renderer, renderer_for
from matremap.sweep.executors import limit_blas_threads
from matremap.sweep.grid import Grid
from matremap.sweep.store import SweepStore, point_key
from matremap.uniform import fit_steps


@dataclass(frozen=True)
class SweepConfig:
    """Everything that decides a sweep's rows, except the grid."""

    source: Material
    target: str
    fix: Mapping[str, Any] = field(default_factory=dict)
    free: tuple[str, ...] = ()
    strategy: str = "two-stage"
    scene: Scene = field(default_factory=Scene)
    #: renderer names; None: the model's own renderer (:func:`~matremap.renderers.registry.renderer_for`),
    #: stored resolved so that the database records which renderer drew its rows
    source_renderer: str | None = None
    target_renderer: str | None = None
    continuation: bool = False
    round_trip: bool = False
    #: what each fit makes small (:mod:`matremap.core.objective`)
    objective: str = "l2"

    def __post_init__(self) -> None:
        check_objective(self.objective)
        if self.source_renderer is None:
            object.__setattr__(self, "source_renderer", renderer_for(self.source.model))
        if self.target_renderer is None:
            object.__setattr__(self, "target_renderer", renderer_for(self.target))
        if self.strategy not in STRATEGIES:
            raise MatremapError(f"unknown strategy {self.strategy!r}; choose one of {', '.join(STRATEGIES)}")
        spec = get_model(self.target)
        for name in self.fix:
            if name not in spec.option_names:
                spec.param(name)
        for name in self.free:
            spec.param(name)

    def to_dict(self) -> dict[str, Any]:
        d = {
            "source": self.source.to_dict(),
            "target": {"model": self.target, "fix": dict(sorted(self.fix.items())), "free": list(self.free)},
            "strategy": self.strategy,
            "scene": self.scene.to_dict(),
            "renderers": {"source": self.source_renderer, "target": self.target_renderer},
            "continuation": self.continuation,
            "round_trip": self.round_trip,
            "matremap": __version__,
        }
        if self.objective != "l2":  # absent for the paper's objective: keys of earlier sweeps stay valid
            d["objective"] = self.objective
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> SweepConfig:
        return cls(
            source=Material.from_dict(d["source"]),
            target=d["target"]["model"],
            fix=d["target"]["fix"],
            free=tuple(d["target"]["free"]),
            strategy=d["strategy"],
            scene=Scene.from_dict(d["scene"]),
            source_renderer=d["renderers"]["source"],
            target_renderer=d["renderers"]["target"],
            continuation=d["continuation"],
            round_trip=d["round_trip"],
            objective=d.get("objective", "l2"),
        )


# --------------------------------------------------------------------------------------------
# Work (runs in workers: plain data in, plain data out)


def fit_chain(
    cfg: SweepConfig, points: list[tuple[str, dict[str, Any], dict[str, Any]]], warm: dict[str, Any] | None
) -> Steps[list[dict[str, Any]]]:
    """Fit ``points`` (key, swept values, source params) in order, as a generator of render requests
    (:mod:`matremap.core.lockstep`); returns their rows. With continuation each point starts from the
    previous result (``warm`` for the first)."""
    rows = []
    for key, swept, source_params in points:
        t0 = time.perf_counter()
        row: dict[str, Any] = {"key": key, "swept": swept, "source": source_params, "warm": 0}
        try:
            source = Material.create(cfg.source.model, source_params)
            start = warm if cfg.continuation else None
            result = yield from fit_point(cfg, source, start)
            row.update(
                target=result.params,
                loss=result.loss,
                renders=result.renders,
                status="ok",
                message="",
                stages=[s.to_dict() for s in result.stages],
                warnings=result.warnings,
                warm=int(start is not None),
            )
            if cfg.round_trip:
                back = yield from fit_steps(
                    result.target,
                    cfg.source.model,
                    cfg.strategy,
                    cfg.scene,
                    cfg.target_renderer,
                    cfg.source_renderer,
                    fix=dict(cfg.source.options),
                    objective=cfg.objective,
                )
                row.update(back=back.params, back_loss=back.loss, renders=result.renders + back.renders)
            warm = {k: v for k, v in result.params.items() if k not in cfg.fix}
        except RendererUnavailable:
            raise  # the environment, not the point: nothing is stored, the sweep stops and says why
        except Exception as e:  # a failed point is recorded, the sweep goes on
            row.update(status="failed", message=f"{type(e).__name__}: {e}")
            warm = None
        row["seconds"] = time.perf_counter() - t0
        row["finished"] = time.time()
        rows.append(row)
    return rows


#: a layered point's fit further off than this (relative RMSE), started at the source's layer, is fitted again from
#: the target's defaults (the uniform remap's rule, :data:`matremap.remap.RESTART_LOSS`)
LAYER_RESTART_LOSS = 0.05


def fit_point(cfg: SweepConfig, source: Material, start: dict[str, Any] | None) -> Steps[Any]:
    """One point's fit. A layer of the source that the sweep frees on the target (``--free coat_weight``...) is
    started at the source's layer (:func:`~matremap.dialects.mtlx.freed_layers`) and, with the default two-stage
    strategy, fitted both three-stage and simple, the better kept, then once more from the target's defaults when
    still poor: the rule of a uniform remap (:func:`matremap.remap._fit_uniform`, measured there), so that each point
    of a sweep over a coat is fitted as remapping that one material would fit it."""
    from matremap.dialects.mtlx import freed_layers

    layered: dict[str, Any] = {}
    if start is None and cfg.free:
        _, at = freed_layers(source.model, source.values, get_model(cfg.target), held=cfg.fix)
        layered = {k: v for k, v in at.items() if k in cfg.free}
    attempts: list[tuple[str, dict[str, Any] | None]] = [(cfg.strategy, start)]
    if layered:
        strategies = ["three-stage", "simple"] if cfg.strategy == "two-stage" else [cfg.strategy]
        attempts = [(strategy, layered) for strategy in strategies]
    best = None
    for i, (strategy, begin) in enumerate([*attempts, (attempts[0][0], None)]):
        if i == len(attempts) and (not layered or best is None or best.loss <= LAYER_RESTART_LOSS):
            break  # the restart from the target's defaults: only for a layered fit that stayed poor
        r = yield from fit_steps(
            source,
            cfg.target,
            strategy,
            cfg.scene,
            cfg.source_renderer,
            cfg.target_renderer,
            fix=cfg.fix,
            free=cfg.free,
            start=begin,
            objective=cfg.objective,
        )
        if best is None or r.loss < best.loss:
            best = r
    return best


def fit_lines(
    config: dict[str, Any],
    lines: list[list[tuple[str, dict[str, Any], dict[str, Any]]]],
    warms: list[dict[str, Any] | None],
) -> list[dict[str, Any]]:
    """Fit several grid lines in lockstep (:func:`~matremap.core.lockstep.lockstep`): every step renders
    the requests of all live fits in one batched call per renderer. Without continuation every point is
    fitted independently (all at once); with it each line is a chain fitted in order. A point's
    ``seconds`` is its share of the task's time (the fits run interleaved)."""
    limit_blas_threads()
    t0 = time.perf_counter()
    cfg = SweepConfig.from_dict(config)
    if cfg.continuation:
        chains = [(line, warm) for line, warm in zip(lines, warms, strict=True)]
    else:
        chains = [([point], None) for line in lines for point in line]
    results = lockstep([fit_chain(cfg, points, warm) for points, warm in chains])
    rows: list[dict[str, Any]] = []
    for value in results:
        if isinstance(value, BaseException):  # only an unexpected error escapes a chain
            raise value
        rows += value
    share = (time.perf_counter() - t0) / max(len(rows), 1)
    for row in rows:
        row["seconds"] = share
    return rows


def fit_line(
    config: dict[str, Any], points: list[tuple[str, dict[str, Any], dict[str, Any]]], warm: dict[str, Any] | None
) -> list[dict[str, Any]]:
    """Fit the points of one grid line (:func:`fit_lines` with one line)."""
    return fit_lines(config, [points], [warm])


# --------------------------------------------------------------------------------------------
# Driver


@dataclass
class SweepSummary:
    total: int
    skipped: int
    done: int
    failed: int
    seconds: float
    interrupted: bool
    executor: str

    @property
    def rate(self) -> float:
        return self.done / self.seconds if self.seconds > 0 else 0.0

    def raise_if_interrupted(self) -> None:
        """Re-raise the interruption the sweep stopped for: nothing may be learned from, or cached after, a
        sweep cut short (its database keeps the finished points and a rerun resumes it)."""
        if self.interrupted:
            raise KeyboardInterrupt


def plan(config: SweepConfig, grid: Grid, finished: set[str]) -> tuple[list[list[tuple]], list[dict | None]]:
    """Lines of unfinished points (key, swept, source params) and each line's warm start."""
    lines: dict[tuple[int, ...], list[tuple]] = {}
    for index in grid.indices():
        swept = grid.values_at(index)
        key = point_key(swept)
        material = grid.material(config.source, index)
        lines.setdefault(index[:-1], []).append((key, swept, material.to_dict()["params"], key in finished))
    todo: list[Any] = []
    warms: list[Any] = []
    for line in lines.values():
        pending = [(k, s, p) for k, s, p, done in line if not done]
        if pending:
            todo.append(pending)
            warms.append(None)  # filled by the caller from the database when resuming
    return todo, warms


def check_renderers(config: SweepConfig) -> None:
    """Before any fit: each renderer exists, is installed and draws its model (else one error naming the
    fix; a renderer that is not installed raises :class:`~matremap.errors.RendererUnavailable`)."""
    for flag, name, model in (
        ("--source-renderer", config.source_renderer, config.source.model),
        ("--target-renderer", config.target_renderer, config.target),
    ):
        assert name is not None  # resolved in __post_init__
        if not can_draw(name, model):
            raise MatremapError(
                f"renderer {name!r} cannot draw {model}; {renderer_for(model)!r} does (drop {flag} or name it)"
            )
        check_probe(get_renderer(name), config.scene)  # starts it: one not installed says so now, not at every point


def run_sweep(
    config: SweepConfig,
    grid: Grid,
    db: str,
    executor: Any,
    progress: Callable[[int], None] | None = None,
    executor_name: str = "",
    on_start: Callable[[int], None] | None = None,
    in_flight: int = 4,
    lockstep_width: int | None = None,
) -> SweepSummary:
    """Run (or resume) a sweep; rows are committed as tasks finish. Ctrl-C stops it cleanly:
    tasks in flight are finished and saved, the rest is left for the next run.

    A task is a few grid lines whose fits run in lockstep (:func:`fit_lines`); ``lockstep_width`` caps
    the fits of one task (default :data:`LOCKSTEP_WIDTH`; 1 fits one point after another)."""
    t0 = time.perf_counter()
    check_renderers(config)
    cfg = config.to_dict()
    with SweepStore.create_or_open(db, cfg) as store:
        store.set_meta("grid", grid.to_dict())
        finished = store.finished_keys()
        lines, warms = plan(config, grid, finished)
        if config.continuation:
            warms = _warm_starts(store, config, grid, lines)
        total = len(grid)
        todo = sum(len(line) for line in lines)
        if on_start:
            on_start(total - todo)
        done = failed = 0
        interrupted = False
        work = iter(tasks(lines, warms, config.continuation, getattr(executor, "slots", 1), lockstep_width))
        pending: set[Future] = set()

        def save(fut: Future) -> None:
            nonlocal done, failed
            rows = fut.result()
            store.add(rows)
            done += len(rows)
            failed += sum(r["status"] != "ok" for r in rows)
            if progress:
                progress(len(rows))

        try:
            while True:
                # keep a few lines in flight: rows are stored as lines finish, whatever the executor
                for task_lines, task_warms in itertools.islice(work, max(in_flight - len(pending), 0)):
                    pending.add(executor.submit(fit_lines, cfg, task_lines, task_warms))
                if not pending:
                    break
                finished_now, pending = wait(pending, timeout=0.5, return_when=FIRST_COMPLETED)
                for fut in finished_now:
                    save(fut)
        except KeyboardInterrupt:
            interrupted = True
            running = [f for f in pending if not f.cancel()]
            finished_now, _ = wait(running, timeout=60)  # lines being fitted are finished and saved
            for fut in finished_now:
                if fut.exception() is None:
                    save(fut)
    return SweepSummary(total, total - todo, done, failed, time.perf_counter() - t0, interrupted, executor_name)


#: the most fits one task runs in lockstep (each holds a few probe images: ~1 MB at 128^2)
LOCKSTEP_WIDTH = 64


def tasks(
    lines: list[list[tuple]], warms: list[dict | None], continuation: bool, slots: int, width: int | None = None
) -> Iterator[tuple[list[list[tuple]], list[dict | None]]]:
    """Cut the lines into tasks (lines, their warm starts) of at most ``width`` fits in lockstep (points;
    with continuation, lines), about two tasks per executor slot when the sweep is small. Without
    continuation a long line is cut into pieces (its points are independent)."""
    width = max(1, width or LOCKSTEP_WIDTH)
    units: list[tuple[list[tuple], dict | None]] = []
    if continuation:
        units = list(zip(lines, warms, strict=True))
        size = len(units)
    else:
        units = [([p], None) for line in lines for p in line]
        size = len(units)
    per = max(1, min(width, -(-size // max(2 * slots, 1))))
    for i in range(0, len(units), per):
        chunk = units[i : i + per]
        if continuation:
            yield [u[0] for u in chunk], [u[1] for u in chunk]
        else:
            yield [[u[0][0] for u in chunk]], [None]


def _warm_starts(store: SweepStore, config: SweepConfig, grid: Grid, lines: list[list[tuple]]) -> list[dict | None]:
    """When resuming a line with continuation, its first pending point starts from the stored
    result of the point before it on the line (if that one finished)."""
    ok = {r["key"]: r["target"] for r in store.rows("ok")}
    keys_in_order = [point_key(grid.values_at(ix)) for ix in grid.indices()]
    position = {k: i for i, k in enumerate(keys_in_order)}
    last = len(grid.axes) - 1
    warms: list[dict | None] = []
    for line in lines:
        first = position[line[0][0]]
        index = list(grid.indices())[first] if first else None
        warm = None
        if index is not None and index[last] > 0:
            prev_key = keys_in_order[first - 1]
            if prev_key in ok:
                warm = {k: v for k, v in ok[prev_key].items() if k not in config.fix}
        warms.append(warm)
    return warms


def check_grid_for(config: SweepConfig, grid: Grid) -> None:
    """Refuse grid axes that the fixed source material cannot take (validated up front)."""
    for index in (tuple(0 for _ in grid.axes), tuple(n - 1 for n in grid.shape)):
        grid.material(config.source, index)


__all__ = [
    "LOCKSTEP_WIDTH",
    "SweepConfig",
    "SweepSummary",
    "check_grid_for",
    "fit_chain",
    "fit_line",
    "fit_lines",
    "plan",
    "run_sweep",
    "tasks",
]


def describe(summary: SweepSummary) -> str:
    state = "interrupted" if summary.interrupted else "done"
    return (
        f"{state}: {summary.done} points fitted ({summary.failed} failed), {summary.skipped} already in the "
        f"database, {summary.total} in the grid; {summary.seconds:.1f} s, {summary.rate:.1f} points/s "
        f"on {summary.executor}"
    )


def sources_of(grid: Grid, base: Material) -> Sequence[Material]:
    return [grid.material(base, ix) for ix in grid.indices()]
