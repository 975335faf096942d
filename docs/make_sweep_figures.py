"""Regenerate the sweep figures of docs/sweeps.md (run from the repository root, ~1 minute on 2 cores):

    python docs/make_sweep_figures.py

(a) conductors, Ashikhmin-Shirley -> Ward, with a round trip back (paper Figs. 3-4);
(b) a dielectric intIOR sweep, rough plastic (Phong lobe) -> Ward, simple vs two-stage (paper Fig. 5-8).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from matremap.core.material import parse_material
from matremap.core.scene import Scene
from matremap.sweep.executors import make_executor
from matremap.sweep.grid import parse_grid
from matremap.sweep.report import write_report
from matremap.sweep.run import SweepConfig, run_sweep
from matremap.sweep.store import SweepStore

IMG = Path(__file__).resolve().parent / "img"


def sweep(db: Path, source: str, target: str, grid: str, **kw) -> Path:
    src = parse_material(source)
    config = SweepConfig(source=src, target=target, scene=Scene(resolution=128), **kw)
    with make_executor(workers=2) as (ex, _):
        s = run_sweep(config, parse_grid(grid, src.spec), str(db), ex, in_flight=4)
    print(f"{db.name}: {s.done} points in {s.seconds:.1f} s")
    return db


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        # (a) + (c): conductors AS -> Ward and back; k sweeps F0 from 0.01 to 0.9 (eta = 1)
        db = sweep(
            tmp / "conductors.sqlite",
            "mitsuba06:roughconductor,distribution=as,eta=1",
            "mitsuba06:ward",
            "alpha=0.05:0.6:12,k=0.2:6:20",
            fix={"variant": "ward"},
            round_trip=True,
        )
        print(write_report(db, IMG / "sweep-conductors", force=True))

        # (b): dielectric IOR sweep, simple vs two-stage
        fig, axes = plt.subplots(1, 2, figsize=(9, 3.4), constrained_layout=True)
        for strategy, colour in (("simple", "tab:red"), ("two-stage", "tab:blue"), ("three-stage", "tab:green")):
            db = sweep(
                tmp / f"plastic-{strategy}.sqlite",
                "mitsuba06:roughplastic,distribution=phong,alpha=0.1,diffuseReflectance=0.5",
                "mitsuba06:ward",
                "intIOR=1.05:2.0:60",
                strategy=strategy,
            )
            rows = sorted(SweepStore.open(db).rows("ok"), key=lambda r: r["source"]["intIOR"])
            ior = np.array([r["source"]["intIOR"] for r in rows])
            style = dict(color=colour, label=strategy, lw=1.5, ls="--" if strategy == "three-stage" else "-")
            axes[0].plot(ior, [r["target"]["specularReflectance"][0] for r in rows], **style)
            axes[1].plot(ior, [r["target"]["alpha"] for r in rows], **style)
        axes[0].set(xlabel="source intIOR (rough plastic, Phong lobe, alpha 0.1)", ylabel="Ward specularReflectance")
        axes[1].set(xlabel="source intIOR", ylabel="Ward alpha", yscale="log")
        axes[0].legend()
        fig.savefig(IMG / "sweep-dielectric-strategies.png", dpi=110)
        print("wrote", IMG / "sweep-dielectric-strategies.png")


if __name__ == "__main__":
    main()
