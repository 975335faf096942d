"""The embedded renderer under an environment, glossy lobes and mirrors: directional lights alone against
the lights with samples about each pixel's mirror direction (renderers/embedded/mirror_samples.py), both
against real Mitsuba 3 tracing the map itself, measured side by side in one run.

    python benchmarks/env_mirror.py [--res 96] [--spp 512] [--samples 0 32 64 128] [--rotation 30]

For each material: the mean of the sphere's inner pixels relative to Mitsuba 3's (1 is right), the relative
RMSE against it, and the embedded render's seconds (best of 2; wall-clock, on whatever else runs). Without
Mitsuba 3 the reference columns are left out and only the embedded renders and their times are printed.
What is left at alpha 0 is mostly the pixel filter: Mitsuba averages a footprint whose mirror directions
span the soft boxes' edges, the embedded renderer shades the pixel centre.
"""

from __future__ import annotations

import argparse
import importlib.util
import time

import numpy as np
from scipy.ndimage import binary_erosion

from matremap.core.envmap import builtin
from matremap.renderers.embedded.environment import render_svbrdf
from matremap.renderers.textured import object_mask

CASES = [
    *[
        (f"conductor alpha {a}", "mitsuba3:roughconductor", {"alpha": a}, {"distribution": "ggx", "material": "none"})
        for a in (0.0, 0.01, 0.05, 0.1, 0.2, 0.4)
    ],
    *[
        (f"principled roughness {r}", "mitsuba3:principled", {"roughness": r, "base_color": [0.5, 0.2, 0.1]}, {})
        for r in (0.0, 0.2, 0.5)
    ],
    (
        "principled clearcoat",
        "mitsuba3:principled",
        {"roughness": 0.5, "base_color": [0.5, 0.2, 0.1], "clearcoat": 1.0, "clearcoat_gloss": 1.0},
        {},
    ),
    ("diffuse", "mitsuba3:diffuse", {"reflectance": [0.6, 0.5, 0.4]}, {}),
]


def timed(*args, repeat: int = 2, **kwargs) -> tuple[np.ndarray, float]:
    """The embedded render of ``args`` / ``kwargs`` and its best time over ``repeat`` runs."""
    best, out = float("inf"), None
    for _ in range(repeat):
        t = time.perf_counter()
        out = render_svbrdf(*args, **kwargs)
        best = min(best, time.perf_counter() - t)
    assert out is not None
    return out, best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, default=96)
    ap.add_argument("--spp", type=int, default=512)
    ap.add_argument("--samples", type=int, nargs="+", default=[0, 32, 64, 128])
    ap.add_argument("--rotation", type=float, default=30.0)
    args = ap.parse_args()
    env = builtin()
    inner = binary_erosion(object_mask("sphere", args.res), iterations=2)
    have_mitsuba = importlib.util.find_spec("mitsuba") is not None
    if have_mitsuba:
        from matremap.renderers.mitsuba3.environment import render_svbrdf_mitsuba3
    head = f"{'material':26s}" + "".join(f" | K={k:<3d} mean   rRMSE     s" for k in args.samples)
    print(head)
    print("-" * len(head))
    for name, model, params, options in CASES:
        ref = None
        if have_mitsuba:
            ref = render_svbrdf_mitsuba3(model, params, options, env, args.rotation, resolution=args.res, spp=args.spp)
        row = f"{name:26s}"
        for k in args.samples:
            img, seconds = timed(model, params, options, env, args.rotation, resolution=args.res, mirror_samples=k)
            if ref is None:
                row += f" | {'':5s} {'-':>6s} {'-':>7s} {seconds:5.2f}"
                continue
            a, b = img[inner], ref[inner]
            rrmse = float(np.sqrt(((a - b) ** 2).mean()) / b.mean())
            row += f" | {'':5s} {a.mean() / b.mean():6.3f} {rrmse:7.3f} {seconds:5.2f}"
        print(row, flush=True)


if __name__ == "__main__":
    main()
