"""Remapping databases: ``sweep`` (fit a grid of source materials), ``sweep-report`` (summarise and
plot one) and ``export`` (as a CSV or Parquet table)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from matremap.cli.common import (
    Subparsers,
    add_command,
    add_executor_options,
    add_fix_option,
    add_force_option,
    add_free_option,
    add_objective_option,
    add_renderer_options,
    add_scene_args,
    add_strategy_option,
    add_target_option,
    load_material,
    make_scene,
    parse_assignments,
)
from matremap.dialects import get_model
from matremap.errors import MatremapError

SWEEP_EXAMPLES = """examples:
  matremap sweep --source mitsuba06:ward,variant=ward,diffuseReflectance=0 --to mitsuba06:pbr \\
      --fix distribution=as --grid "alpha=0.005:0.99:35,specularReflectance=0.02:0.232:23" --db ward2as.sqlite
  matremap sweep --source mitsuba06:roughconductor,distribution=as --to mitsuba06:ward \\
      --grid grid.toml --db as2ward.sqlite --round-trip --dask-local 2
  (run the same command again to resume; Ctrl-C stops cleanly)"""

SWEEP_REPORT_EXAMPLES = """examples:
  matremap sweep-report ward2as.sqlite -o report/"""

EXPORT_EXAMPLES = """examples:
  matremap export ward2as.sqlite -o ward2as.csv
  matremap export ward2as.sqlite -o ward2as.parquet   (needs pyarrow)"""

#: file names a sweep database may have
DB_SUFFIXES = (".sqlite", ".sqlite3", ".db")


def add_sweep(subparsers: Subparsers) -> None:
    """The ``sweep`` command."""
    p = add_command(subparsers, "sweep", "fit a grid of source materials into a remapping database", SWEEP_EXAMPLES)
    p.add_argument(
        "--source",
        required=True,
        metavar="MATERIAL",
        help="the base source material; grid values replace its parameters",
    )
    add_target_option(p)
    p.add_argument(
        "--grid",
        required=True,
        metavar="GRID",
        help="source parameters to vary: NAME=LO:HI:COUNT[:log] (COUNT values from LO to HI, log-spaced with :log) "
        "or NAME=V1;V2;..., comma-separated, or a .toml file; docs/sweeps.md",
    )
    p.add_argument("--db", required=True, metavar="FILE.sqlite", help="the database: created, or resumed if it exists")
    add_fix_option(p, "set a target option or hold a target parameter at a value (repeatable), e.g. distribution=as")
    add_free_option(p, "also fit a target parameter the model holds by default (repeatable)")
    add_strategy_option(p)
    add_objective_option(p)
    add_renderer_options(p)
    add_executor_options(p, "fit")
    p.add_argument(
        "--continuation",
        action="store_true",
        help="start each fit from its finished neighbour along the last grid axis",
    )
    p.add_argument("--round-trip", action="store_true", help="also fit each result back onto the source model")
    p.add_argument("--no-progress", action="store_true", help="no progress bar (it is shown only on a terminal)")
    add_scene_args(p)
    p.set_defaults(func=cmd_sweep)


def cmd_sweep(args: argparse.Namespace) -> int:
    """Run (or resume) a sweep into its database with a progress bar; 130 when interrupted."""
    from tqdm import tqdm

    from matremap.renderers import renderer_for
    from matremap.sweep.executors import make_executor
    from matremap.sweep.grid import parse_grid
    from matremap.sweep.run import SweepConfig, check_grid_for, describe, run_sweep

    source = load_material(args.source)
    target = get_model(args.target).id
    config = SweepConfig(
        source=source,
        target=target,
        fix=parse_assignments(args.fix, "--fix"),
        free=tuple(args.free),
        strategy=args.strategy,
        scene=make_scene(args),
        # the database records the renderers by name, so a default is resolved here
        source_renderer=args.source_renderer or renderer_for(source.model),
        target_renderer=args.target_renderer or renderer_for(target),
        continuation=args.continuation,
        round_trip=args.round_trip,
        objective=args.objective,
    )
    grid = parse_grid(args.grid, source.spec)
    check_grid_for(config, grid)
    db = Path(args.db)
    if db.suffix.lower() not in DB_SUFFIXES:
        raise MatremapError(f"--db {db}: use a .sqlite (or .db) file name")
    if not db.parent.is_dir():
        raise MatremapError(f"cannot create {db}: folder {db.parent} does not exist")
    with make_executor(args.workers, args.scheduler, args.dask_local) as (executor, desc):
        slots = getattr(executor, "slots", 1)
        print(
            f"sweep {source.model} -> {config.target}: {len(grid)} points "
            f"({' x '.join(f'{a.label} {len(a.values)}' for a in grid.axes)}) on {desc}",
            file=sys.stderr,
        )
        with tqdm(
            total=len(grid), unit="pt", disable=args.no_progress or None, dynamic_ncols=True, smoothing=0.1
        ) as bar:
            summary = run_sweep(
                config,
                grid,
                str(db),
                executor,
                progress=bar.update,
                executor_name=desc,
                on_start=lambda skipped: bar.update(skipped),
                in_flight=2 * slots,
            )
    print(describe(summary), file=sys.stderr)
    return 130 if summary.interrupted else 0


def add_sweep_report(subparsers: Subparsers) -> None:
    """The ``sweep-report`` command."""
    p = add_command(subparsers, "sweep-report", "summarise a sweep database and plot it", SWEEP_REPORT_EXAMPLES)
    p.add_argument("db", metavar="DB", help="a sweep database (.sqlite)")
    p.add_argument("-o", "--output", required=True, metavar="DIR", help="folder for the summary and the PNG plots")
    add_force_option(p, "overwrite existing plots in DIR")
    p.set_defaults(func=cmd_sweep_report)


def cmd_sweep_report(args: argparse.Namespace) -> int:
    """Write the summary and plots of a sweep database into a folder."""
    from matremap.sweep.report import write_report

    out = Path(args.output)
    if out.exists() and not out.is_dir():
        raise MatremapError(f"{out} exists and is not a folder")
    print(write_report(args.db, out, force=args.force))
    return 0


def add_export(subparsers: Subparsers) -> None:
    """The ``export`` command."""
    p = add_command(subparsers, "export", "export a sweep database as a table", EXPORT_EXAMPLES)
    p.add_argument("db", metavar="DB", help="a sweep database (.sqlite)")
    p.add_argument("-o", "--output", required=True, metavar="FILE", help="a .csv, or a .parquet (needs pyarrow)")
    add_force_option(p, "overwrite an existing file")
    p.set_defaults(func=cmd_export)


def cmd_export(args: argparse.Namespace) -> int:
    """Write a sweep database's rows as a CSV or Parquet table."""
    from matremap.core.imageio import check_output
    from matremap.sweep.report import export_table

    out = check_output(args.output, args.force, (".csv", ".parquet"))
    n = export_table(args.db, out)
    print(f"wrote {out} ({n} rows)", file=sys.stderr)
    return 0


#: command name -> the function adding its parser
PARSERS = {"sweep": add_sweep, "sweep-report": add_sweep_report, "export": add_export}
