"""Compare our Ward -> AS fits with the table published by the paper's authors.

Source ``mitsuba06:ward`` (variant ward, no diffuse), target ``mitsuba06:pbr`` (distribution as),
headlight, two-stage (or ``--strategy``). For every row of tests/data/reference/mitsuba-ward2mitsuba-as.csv prints the
deviation of alpha2 and of the slope F0/rho_s, then max / median / 95th percentile for the rows
with alpha1 >= 0.03 and, separately, for alpha1 = 0.005 (sub-pixel highlights).

    python benchmarks/reference_table.py [--size 128] [--every 1] [--strategy two-stage] [--verbose]
"""

from __future__ import annotations

import argparse
import csv
import sys
import time
from pathlib import Path

import numpy as np

from matremap.core.material import Material
from matremap.core.scene import Scene
from matremap.uniform import fit

# the authors' published table, kept with its provenance in tests/data/README.md
TABLE = Path(__file__).resolve().parents[1] / "tests" / "data" / "reference" / "mitsuba-ward2mitsuba-as.csv"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--every", type=int, default=1, help="use every n-th row")
    ap.add_argument("--strategy", default="two-stage", help="the fit's strategy (default: two-stage, the default)")
    ap.add_argument("--verbose", action="store_true", help="print every row")
    args = ap.parse_args()
    if not TABLE.is_file():
        print(f"reference table not found at {TABLE}", file=sys.stderr)
        return 1
    with TABLE.open() as f:
        table = [
            {k: float(r[k]) for k in ("alpha1", "specular1", "alpha2", "eta2")}
            for r in csv.DictReader(f, delimiter="\t")
        ]
    rows = sorted(table, key=lambda r: (r["alpha1"], r["specular1"]))[:: args.every]
    scene = Scene(resolution=args.size)
    dev_a, dev_k, a1s, secs, renders = [], [], [], [], []
    for r in rows:
        src = Material.create(
            "mitsuba06:ward",
            {"variant": "ward", "alpha": r["alpha1"], "specularReflectance": r["specular1"], "diffuseReflectance": 0},
        )
        t = time.perf_counter()
        res = fit(src, "mitsuba06:pbr", args.strategy, scene=scene, fix={"distribution": "as"})
        secs.append(time.perf_counter() - t)
        renders.append(res.renders)
        a2, f0 = res.target.values["alpha"][0], res.target.values["F0"][0]
        dev_a.append(a2 / r["alpha2"] - 1)
        dev_k.append(f0 / r["eta2"] - 1)  # same rho_s on both sides: slope deviation = F0 deviation
        a1s.append(r["alpha1"])
        if args.verbose:
            print(
                f"alpha1 {r['alpha1']:.4f} rho_s {r['specular1']:.4f}  alpha2 {a2:.5f} vs {r['alpha2']:.5f} "
                f"({100 * dev_a[-1]:+.3f}%)  F0/rho_s {f0 / r['specular1']:.5f} vs {r['eta2'] / r['specular1']:.5f} "
                f"({100 * dev_k[-1]:+.3f}%)  loss {res.loss:.4f}"
            )
    dev_a, dev_k, a1s = np.abs(dev_a) * 100, np.abs(dev_k) * 100, np.array(a1s)
    print(
        f"\n{len(rows)} rows, {args.size}x{args.size}, {args.strategy}, median {np.median(secs) * 1000:.1f} ms and "
        f"{np.median(renders):.0f} renders per fit\n"
    )
    print(
        f"{'rows':<22} {'n':>4} {'alpha2 max %':>13} {'median %':>9} {'p95 %':>7} {'F0/rho_s max %':>15} "
        f"{'median %':>9} {'p95 %':>7}"
    )
    for label, sel in (("alpha1 >= 0.03", a1s >= 0.03), ("alpha1 = 0.005", a1s < 0.03)):
        if sel.any():
            a, k = dev_a[sel], dev_k[sel]
            print(
                f"{label:<22} {sel.sum():>4} {a.max():13.3f} {np.median(a):9.3f} {np.percentile(a, 95):7.3f} "
                f"{k.max():15.3f} {np.median(k):9.3f} {np.percentile(k, 95):7.3f}"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
