"""Time `convert` on a 4096^2 Ward map set against copying the same data, and (with --big) measure
peak memory on a 16384^2 set.

    .venv/bin/python benchmarks/convert.py [--size 4096] [--formats png8 png16 exr] [--workers 2]
                                           [--transform T.json] [--big] [--keep DIR]

The map set: alpha (grey), specularReflectance (RGB), a normal map (RGB, copied), in each format.
For each format it prints, measured side by side in one run:

* ``numpy copy``: ``np.copy`` of the decoded file contents already in memory (the bytes the maps hold);
* ``file copy``: the same files read and written back unchanged with OpenImageIO, one process,
  no transform (the I/O floor for this format);
* ``convert``: ``matremap.svbrdf.convert.convert`` (read, transform, write the target maps and mask, copy the
  normal map), ``--workers`` processes;

and the ratios convert / numpy copy and convert / file copy. The transform is learned from a small
Ward -> Ashikhmin-Shirley sweep on the embedded renderer unless ``--transform`` names one.

``--big`` writes a 16384^2 8-bit PNG set (about 1 GB of pixels; the files are written band by
band) and converts it in a fresh process, printing its peak resident memory and that of the
largest worker process.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

from matremap.svbrdf.textures import ImageInfo, MapWriter, load_map_set

FORMATS = {"png8": ("png", "uint8"), "png16": ("png", "uint16"), "exr": ("exr", "float")}


def learn(tmp: Path):
    from matremap.core.material import Material
    from matremap.core.scene import Scene
    from matremap.regress.transform import learn_transform
    from matremap.sweep.executors import InlineExecutor
    from matremap.sweep.grid import parse_grid
    from matremap.sweep.run import SweepConfig, run_sweep

    src = Material.create("mitsuba06:ward", {"variant": "ward", "diffuseReflectance": 0.0})
    cfg = SweepConfig(source=src, target="mitsuba06:pbr", fix={"distribution": "as"}, scene=Scene(resolution=48))
    run_sweep(
        cfg,
        parse_grid("alpha=0.03:0.99:6,specularReflectance=0.02:0.232:4", src.spec),
        str(tmp / "w.sqlite"),
        InlineExecutor(),
    )
    t = learn_transform(tmp / "w.sqlite")
    t.save(tmp / "w2as.json", force=True)
    return tmp / "w2as.json"


def band_fields(y0: int, y1: int, n: int) -> dict[str, np.ndarray]:
    """Smooth-ish procedural maps with a little noise (deterministic per row)."""
    y = (np.arange(y0, y1, dtype=np.float32) / n)[:, None]
    x = (np.arange(n, dtype=np.float32) / n)[None, :]
    rng = np.random.default_rng(y0)
    noise = rng.normal(0, 0.01, (y1 - y0, n)).astype(np.float32)
    alpha = 0.05 + 0.5 * (0.5 + 0.5 * np.sin(7 * x + 3 * y)) + noise
    base = 0.5 + 0.5 * np.sin(5 * x - 4 * y)
    rho = np.stack([0.03 + 0.18 * base, 0.03 + 0.12 * base, 0.03 + 0.05 * base], axis=-1) + noise[..., None]
    normal = np.stack(
        [0.5 + 0.1 * np.sin(40 * x + 0 * y), 0.5 + 0.1 * np.cos(37 * y + 0 * x), np.full_like(base, 0.97)], axis=-1
    )
    return {"roughness": np.clip(alpha, 0.03, 0.95), "specular": np.clip(rho, 0, 1), "normal": normal}


def make_set(folder: Path, n: int, fmt: str, pixel_type: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    infos = {
        "roughness": ImageInfo(fmt, pixel_type, 1, n, n, "linear"),
        "specular": ImageInfo(fmt, pixel_type, 3, n, n, "srgb" if pixel_type != "float" else "linear"),
        "normal": ImageInfo("png" if fmt == "png" else fmt, pixel_type, 3, n, n, "linear"),
    }
    writers = {k: MapWriter(folder / f"m_{k}.{i.format}", i) for k, i in infos.items()}
    rows = max(16, (1 << 20) // n)
    for y0 in range(0, n, rows):
        y1 = min(y0 + rows, n)
        f = band_fields(y0, y1, n)
        for k, w in writers.items():
            w.write_rows(y0, f[k])
    for w in writers.values():
        w.close()
    (folder / "material.json").write_text(
        json.dumps(
            {
                "model": "mitsuba06:ward",
                "maps": {"alpha": f"m_roughness.{fmt}", "specularReflectance": f"m_specular.{fmt}"},
                "normal": f"m_normal.{fmt}",
                "params": {"variant": "ward", "diffuseReflectance": 0},
            }
        )
    )
    return folder


def raw_read(path: Path) -> tuple[np.ndarray, object]:
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    spec = inp.spec()
    data = inp.read_image(0, 0, 0, spec.nchannels, spec.format)
    inp.close()
    return data, spec


def file_copy(files: list[Path], out: Path) -> float:
    import OpenImageIO as oiio

    t = time.perf_counter()
    for f in files:
        data, spec = raw_read(f)
        o = oiio.ImageOutput.create(str(out / f.name))
        s = oiio.ImageSpec(spec.width, spec.height, spec.nchannels, spec.format)
        if f.suffix == ".png":
            s.attribute("png:compressionLevel", 3)
        o.open(str(out / f.name), s)
        o.write_image(data)
        o.close()
    return time.perf_counter() - t


def numpy_copy(files: list[Path]) -> float:
    arrays = [raw_read(f)[0] for f in files]
    best = float("inf")
    for _ in range(3):
        t = time.perf_counter()
        copies = [np.copy(a) for a in arrays]
        best = min(best, time.perf_counter() - t)
    del copies
    return best


def run_convert(folder: Path, transform: Path, out: Path, workers: int) -> tuple[float, int]:
    from matremap.regress.transform import Transform
    from matremap.svbrdf.convert import convert

    ms = load_map_set(folder)
    t = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        report = convert(ms, Transform.load(transform), out, workers=workers, force=True)
    return time.perf_counter() - t, report.outside


BIG_CHILD = """
import json, resource, sys, time, warnings
from matremap.regress.transform import Transform
from matremap.svbrdf.convert import convert
from matremap.svbrdf.textures import load_map_set
warnings.simplefilter("ignore")
t = time.perf_counter()
r = convert(load_map_set(sys.argv[1]), Transform.load(sys.argv[2]), sys.argv[3], workers=int(sys.argv[4]), force=True)
print(json.dumps({"seconds": time.perf_counter() - t, "self_kb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss,
                  "child_kb": resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, "outside": r.outside}))
"""


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=4096)
    ap.add_argument("--formats", nargs="+", default=["png8", "png16", "exr"], choices=list(FORMATS))
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--transform", type=Path)
    ap.add_argument("--big", action="store_true", help="also measure peak memory on a 16384^2 8-bit PNG set")
    ap.add_argument("--big-size", type=int, default=16384)
    ap.add_argument("--keep", type=Path, help="work in this folder instead of a temporary one")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(dir=args.keep) as tmpname:
        tmp = Path(tmpname)
        transform = args.transform or learn(tmp)
        print(f"map set {args.size}^2: alpha (1 ch), specularReflectance (3 ch), normal (3 ch); workers {args.workers}")
        print(f"{'format':7s} {'numpy copy':>11s} {'file copy':>10s} {'convert':>9s} {'/numpy':>8s} {'/file':>7s}")
        for name in args.formats:
            fmt, pixel_type = FORMATS[name]
            folder = make_set(tmp / f"in-{name}", args.size, fmt, pixel_type)
            files = sorted(p for p in folder.iterdir() if p.suffix != ".json")
            (tmp / f"copy-{name}").mkdir()
            tn = numpy_copy(files)
            tf = file_copy(files, tmp / f"copy-{name}")
            tc, _ = run_convert(folder, transform, tmp / f"out-{name}", args.workers)
            print(f"{name:7s} {tn:10.3f}s {tf:9.2f}s {tc:8.2f}s {tc / tn:7.0f}x {tc / tf:6.2f}x", flush=True)
        if args.big:
            n = args.big_size
            t = time.perf_counter()
            folder = make_set(tmp / "big", n, "png", "uint8")
            print(
                f"\n{n}^2 8-bit PNG set written in {time.perf_counter() - t:.0f}s "
                f"({sum(p.stat().st_size for p in folder.iterdir()) / 2**20:.0f} MiB on disk)",
                flush=True,
            )
            res = subprocess.run(
                [sys.executable, "-c", BIG_CHILD, str(folder), str(transform), str(tmp / "big-out"), str(args.workers)],
                capture_output=True,
                text=True,
                check=True,
            )
            r = json.loads(res.stdout.strip().splitlines()[-1])
            print(
                f"convert {n}^2: {r['seconds']:.0f}s, peak RSS main process {r['self_kb'] / 1024:.0f} MiB, "
                f"largest worker {r['child_kb'] / 1024:.0f} MiB (total at most "
                f"{(r['self_kb'] + args.workers * r['child_kb']) / 1024:.0f} MiB)"
            )
    print(f"(this benchmark process peaked at {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
