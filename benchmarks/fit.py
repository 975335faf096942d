"""Seconds and renders per uniform fit on the embedded renderer.

For a few model pairs, 20 fixed source materials each (drawn with a fixed seed), every strategy:
prints median / 90th-percentile milliseconds, median renders and median loss per fit.

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python benchmarks/fit.py [--size 128] [--repeat 3]

(one BLAS thread: the target is "<= 20 ms per two-stage fit on one core").
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

from matremap.core.fit import STRATEGIES
from matremap.core.material import Material
from matremap.core.scene import Scene
from matremap.uniform import fit


def sources(model: str, n: int, rng: np.random.Generator) -> list[Material]:
    out = []
    for _ in range(n):
        if model == "mitsuba06:ward":
            p = {
                "variant": "ward",
                "alpha": rng.uniform(0.03, 0.9),
                "specularReflectance": rng.uniform(0.02, 0.25),
                "diffuseReflectance": rng.uniform(0.0, 0.5),
            }
        elif model == "mitsuba06:roughconductor":
            p = {
                "distribution": "as",
                "alpha": rng.uniform(0.03, 0.6),
                "eta": rng.uniform(0.2, 2.0, 3).tolist(),
                "k": rng.uniform(0.0, 1.5, 3).tolist(),
            }
        elif model == "cycles:glossy":
            p = {
                "Roughness": rng.uniform(0.2, 0.9),
                "Color": rng.uniform(0.1, 0.9, 3).tolist(),
                "Diffuse Color": rng.uniform(0.0, 0.5, 3).tolist(),
            }
        elif model == "blender27:ward":
            p = {
                "specular_slope": rng.uniform(0.03, 0.4),
                "specular_color": rng.uniform(0.1, 1.0),
                "specular_intensity": 1.0,
                "diffuse_color": rng.uniform(0.0, 0.8),
                "diffuse_intensity": 1.0,
            }
        else:
            raise ValueError(model)
        out.append(Material.create(model, p))
    return out


PAIRS = [
    ("mitsuba06:ward", "mitsuba06:pbr", {"distribution": "as"}, "grey, with diffuse"),
    ("mitsuba06:roughconductor", "mitsuba06:ward", {"variant": "ward"}, "RGB conductor"),
    ("cycles:glossy", "mitsuba06:pbr", {"distribution": "ggx"}, "RGB, with diffuse"),
    ("blender27:ward", "mitsuba06:ward", {"variant": "ward"}, "grey, cross-family"),
]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--repeat", type=int, default=3, help="runs per fit; the fastest counts")
    ap.add_argument("--count", type=int, default=20)
    args = ap.parse_args()
    scene = Scene(resolution=args.size)
    fit(sources("mitsuba06:ward", 1, np.random.default_rng(1))[0], "mitsuba06:pbr", scene=scene)  # warm up
    print(f"embedded renderer, {args.size}x{args.size}, {args.count} sources per pair, best of {args.repeat}\n")
    print(f"{'source -> target':<46} {'strategy':<12} {'median ms':>9} {'p90 ms':>7} {'renders':>7} {'loss':>8}")
    for src_model, tgt_model, fix, note in PAIRS:
        mats = sources(src_model, args.count, np.random.default_rng(0))
        for strategy in STRATEGIES:
            ms, renders, losses = [], [], []
            for m in mats:
                best = None
                for _ in range(args.repeat):
                    t = time.perf_counter()
                    r = fit(m, tgt_model, strategy=strategy, scene=scene, fix=fix)
                    dt = time.perf_counter() - t
                    best = dt if best is None else min(best, dt)
                ms.append(best * 1000)
                renders.append(r.renders)
                losses.append(r.loss)
            label = f"{src_model} -> {tgt_model} ({note})"
            print(
                f"{label:<46} {strategy:<12} {statistics.median(ms):9.1f} {np.percentile(ms, 90):7.1f} "
                f"{statistics.median(renders):7.0f} {statistics.median(losses):8.4f}"
            )


if __name__ == "__main__":
    main()
