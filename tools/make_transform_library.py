"""Regenerate matremap's transform library (src/matremap/regress/transforms/*.json).

Runs every sweep of matremap.regress.library.PAIRS (or the ones named) and learns the forward and reverse
transforms of each. Usage:

    python tools/make_transform_library.py                 # all pairs
    python tools/make_transform_library.py ward-as --out /tmp/lib
"""

from __future__ import annotations

import argparse
import time

from matremap.regress.library import LIBRARY_DIR, PAIRS, build_pair


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("pairs", nargs="*", help="pair names (default: all): " + ", ".join(p.name for p in PAIRS))
    ap.add_argument("--out", default=str(LIBRARY_DIR), help="output folder (default: the package's library)")
    ap.add_argument("--workers", type=int, default=None)
    args = ap.parse_args()
    chosen = [p for p in PAIRS if not args.pairs or p.name in args.pairs]
    unknown = set(args.pairs) - {p.name for p in PAIRS}
    if unknown:
        ap.error(f"unknown pair(s) {', '.join(sorted(unknown))}")
    t0 = time.perf_counter()
    for pair in chosen:
        t = time.perf_counter()
        build_pair(pair, args.out, workers=args.workers)
        print(f"  ({time.perf_counter() - t:.1f} s)")
    print(f"{len(chosen)} pair(s) in {time.perf_counter() - t0:.0f} s -> {args.out}")


if __name__ == "__main__":
    main()
