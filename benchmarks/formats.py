"""Converting a glTF asset with 2K textures to Mitsuba 3 XML through a shipped transform (issue #8:
target <= 5 s), step by step.

    python benchmarks/formats.py [--side 2048] [--repeat 3]

Builds a glTF 2.0 file with a 2048^2 sRGB base-colour map and a packed metallic-roughness map
(metal everywhere), then runs ``remap_file(..., "mitsuba3:roughconductor", evaluate=False)``:
read the glTF, unpack its maps, find the library route, convert every texel, write the Mitsuba
scene with its bitmaps. Prints the best of ``--repeat`` runs and where the time goes.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from matremap.remap import remap_file
from matremap.svbrdf.textures import ImageInfo, write_image_like


def make_asset(folder: Path, side: int) -> Path:
    rng = np.random.default_rng(0)
    y, x = np.mgrid[0:side, 0:side] / (side - 1)
    noise = rng.uniform(-0.05, 0.05, (side, side))
    base = np.stack([0.7 + 0.15 * x + noise, 0.55 + 0.1 * y + noise, 0.4 + noise], -1).astype(np.float32)
    mr = np.stack([0 * x, np.clip(0.3 + 0.5 * x + noise, 0, 1), np.ones_like(x)], -1).astype(np.float32)
    write_image_like(folder / "base.png", base, ImageInfo("png", "uint8", 3, 0, 0, "srgb"))
    write_image_like(folder / "mr.png", mr, ImageInfo("png", "uint8", 3, 0, 0, "linear"))
    doc = {
        "asset": {"version": "2.0"},
        "images": [{"uri": "base.png"}, {"uri": "mr.png"}],
        "textures": [{"source": 0}, {"source": 1}],
        "materials": [
            {
                "name": "brass",
                "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}, "metallicRoughnessTexture": {"index": 1}},
            }
        ],
    }
    path = folder / "brass.gltf"
    path.write_text(json.dumps(doc))
    return path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--side", type=int, default=2048)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        (root / "in").mkdir()
        asset = make_asset(root / "in", args.side)
        runs = []
        for i in range(args.repeat):
            logs: list[str] = []
            t = time.perf_counter()
            res = remap_file(
                asset,
                "mitsuba3:roughconductor",
                root / f"out{i}",
                fix={"distribution": "ggx"},
                evaluate=False,
                log=logs.append,
            )
            runs.append((time.perf_counter() - t, res, logs))
        seconds, res, logs = min(runs, key=lambda r: r[0])
        route = next((m for m in logs if m.startswith("library:")), "library: -")
        steps = res.remap.seconds
        print(f"glTF {args.side}^2 (base colour + packed metallic-roughness) -> Mitsuba 3 XML")
        print(route)
        print(
            f"total {seconds:.2f} s (best of {args.repeat}; target <= 5 s): unpack+load {steps['load']:.2f} s, "
            f"route {steps['transform']:.2f} s, convert {steps['convert']:.2f} s, "
            f"read+write rest {seconds - steps['total']:.2f} s"
        )
        print(f"wrote {res.file.name} with {', '.join(sorted(p.name for p in res.file.parent.glob('brass_*')))}")


if __name__ == "__main__":
    main()
