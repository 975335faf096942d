"""Sweep throughput on the embedded renderer: points per second with 1 and 2 workers.

1. a 1,000-point two-stage sweep (Ward -> AS, 40 alpha x 25 rho_s), with and without continuation;
2. the authors' Ward -> AS grid (35 alpha1 x 23 rho_s = 805 points, a superset of their 721 rows),
   compared with their table.

    python benchmarks/sweep.py [--workers 1 2] [--size 128]
"""

from __future__ import annotations

import argparse
import csv
import tempfile
import time
from pathlib import Path

import numpy as np

from matremap.core.material import Material
from matremap.core.scene import Scene
from matremap.sweep.executors import make_executor
from matremap.sweep.grid import parse_grid
from matremap.sweep.run import SweepConfig, run_sweep
from matremap.sweep.store import SweepStore

# the authors' published table, kept with its provenance in tests/data/README.md
TABLE = Path(__file__).resolve().parents[1] / "tests" / "data" / "reference" / "mitsuba-ward2mitsuba-as.csv"
SOURCE = Material.create("mitsuba06:ward", {"variant": "ward", "diffuseReflectance": 0.0})
GRID_1000 = "alpha=0.01:0.99:40,specularReflectance=0.02:0.25:25"
GRID_AUTHORS = "alpha=0.005:0.99:35,specularReflectance=0.02:0.232413793103:23"


def timed_sweep(grid_text: str, workers: int, size: int, continuation: bool, folder: Path) -> tuple[float, Path]:
    config = SweepConfig(
        source=SOURCE,
        target="mitsuba06:pbr",
        fix={"distribution": "as"},
        scene=Scene(resolution=size),
        continuation=continuation,
    )
    grid = parse_grid(grid_text, SOURCE.spec)
    db = folder / f"{abs(hash((grid_text, workers, continuation)))}.sqlite"
    t = time.perf_counter()
    with make_executor(workers=workers) as (ex, _):
        summary = run_sweep(config, grid, str(db), ex, in_flight=2 * workers)
    seconds = time.perf_counter() - t
    assert summary.done == len(grid) and summary.failed == 0
    return seconds, db


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--size", type=int, default=128)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        print(f"{'sweep':<44} {'workers':>7} {'seconds':>8} {'points/s':>9} {'renders/fit':>11}")
        for label, grid_text, continuation in (
            ("1,000 points, two-stage", GRID_1000, False),
            ("1,000 points, two-stage, continuation", GRID_1000, True),
            ("authors' grid (805 points), two-stage", GRID_AUTHORS, False),
        ):
            for w in args.workers:
                seconds, db = timed_sweep(grid_text, w, args.size, continuation, folder)
                rows = SweepStore.open(db).rows()
                print(
                    f"{label:<44} {w:>7} {seconds:8.1f} {len(rows) / seconds:9.1f} "
                    f"{np.mean([r['renders'] for r in rows]):11.1f}"
                )
        if TABLE.is_file():
            fitted = {
                (round(r["swept"]["alpha"], 6), round(r["swept"]["specularReflectance"], 6)): r["target"]
                for r in SweepStore.open(db).rows()
            }
            dev_a, dev_f = [], []
            with TABLE.open() as f:
                for r in csv.DictReader(f, delimiter="\t"):
                    a1, s1 = float(r["alpha1"]), float(r["specular1"])
                    t = fitted.get((round(a1, 6), round(s1, 6)))
                    if t is None or a1 < 0.03:
                        continue
                    dev_a.append(abs(t["alpha"] / float(r["alpha2"]) - 1))
                    dev_f.append(abs(t["F0"][0] / float(r["eta2"]) - 1))
            print(
                f"\nauthors' table, {len(dev_a)} rows with alpha1 >= 0.03 matched to the sweep: alpha2 max "
                f"{100 * max(dev_a):.3f}%, F0/rho_s max {100 * max(dev_f):.3f}%"
            )


if __name__ == "__main__":
    main()
