"""Peak memory of ``remap`` and ``convert`` against map size (issue 19, must-have 5: a 16K x 16K map set
within 2 GB).

For each size N, a map set like ``examples/bronze`` (mitsuba06:ward: sRGB diffuse and specular colour maps,
a roughness map and a normal map, 8-bit PNG) is written at N x N by tiling the example's 256 x 256 maps
(written band by band, so the benchmark itself stays small), then

* ``matremap remap MAPS --to mitsuba06:pbr --fix distribution=as -o OUT``  (the README's main job: a
  library route, convert, the gate's map checks, evaluation renders at 160 px, the report), and
* ``matremap convert MAPS --to mitsuba06:pbr --fix distribution=as -o OUT``

run in fresh processes, each under ``/usr/bin/time -v`` and an address-space cap (``--cap-gb``, so that a
whole-map implementation fails with a MemoryError instead of taking the machine down). Two peaks are
reported: ``tree`` is the sum of the resident sets of the command and its worker processes, sampled by
psutil every 20 ms; ``main`` is the maximum resident set of the command's own process (``time -v``).

    python benchmarks/memory.py --sizes 2048 4096 8192 16384
    python benchmarks/memory.py --src OTHER/src --sizes 2048 4096 8192 16384   # another checkout

Exit codes are shown when not 0 (3 is a remap whose quality gate failed: files written).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
BRONZE = ROOT / "examples" / "bronze"


def tiled_map_set(folder: Path, size: int) -> Path:
    """``examples/bronze`` tiled to ``size`` x ``size`` (same manifest, same value distribution)."""
    import OpenImageIO as oiio

    folder.mkdir(parents=True, exist_ok=True)
    doc = json.loads((BRONZE / "material.json").read_text())
    for name in [*doc["maps"].values(), doc["normal"]]:
        src = oiio.ImageInput.open(str(BRONZE / name))
        spec = src.spec()
        tile = src.read_image(0, 0, 0, spec.nchannels, oiio.UINT8).reshape(spec.height, spec.width, spec.nchannels)
        src.close()
        row_tile = np.tile(tile, (1, -(-size // spec.width), 1))[:, :size]
        out = oiio.ImageOutput.create(str(folder / name))
        out_spec = oiio.ImageSpec(size, size, spec.nchannels, oiio.UINT8)
        out_spec.attribute("png:compressionLevel", 1)
        out.open(str(folder / name), out_spec)
        rows = max(spec.height, (1 << 24) // (size * spec.nchannels) // spec.height * spec.height)
        for y0 in range(0, size, rows):
            y1 = min(size, y0 + rows)
            band = np.tile(row_tile, (-(-(y1 - y0) // spec.height), 1, 1))[: y1 - y0]
            out.write_scanlines(y0, y1, 0, np.ascontiguousarray(band))
        out.close()
    (folder / "material.json").write_text(json.dumps(doc, indent=1))
    return folder


def measure(args: list[str], src: Path, cwd: Path, cap_gb: float) -> dict[str, object]:
    """Run ``python -m matremap ARGS`` with ``src`` on the path; its exit code, seconds and peaks (MB)."""
    import psutil

    env = {**os.environ, "PYTHONPATH": str(src), "MATREMAP_CACHE": str(cwd / "cache")}
    cap = int(cap_gb * 2**30)

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (cap, cap))

    cmd = ["/usr/bin/time", "-v", sys.executable, "-m", "matremap", *args]
    t0 = time.perf_counter()
    proc = subprocess.Popen(
        cmd, cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=limit
    )
    peak = 0
    top = psutil.Process(proc.pid)
    while proc.poll() is None:
        try:
            tree = [top, *top.children(recursive=True)]
            peak = max(peak, sum(p.memory_info().rss for p in tree[1:]))  # [0] is time itself
        except psutil.Error:
            pass
        time.sleep(0.02)
    out, err = proc.communicate()
    seconds = time.perf_counter() - t0
    found = re.search(r"Maximum resident set size \(kbytes\): (\d+)", err)
    main_mb = int(found.group(1)) / 1024 if found else float("nan")
    status = re.search(r"Exit status: (\d+)", err)
    code = int(status.group(1)) if status else proc.returncode
    last = [line for line in err.splitlines() if line.startswith("matremap:")]
    return {
        "code": code,
        "seconds": seconds,
        "tree_mb": peak / 2**20,
        "main_mb": main_mb,
        "memory_error": "MemoryError" in err or "not enough memory" in err,
        "line": last[-1] if last else "",
    }


def cell(r: dict[str, object], cap_gb: float) -> str:
    if r["memory_error"]:
        return f"> {cap_gb:g} GB cap (MemoryError)"
    text = f"{r['tree_mb']:.0f} / {r['main_mb']:.0f}"
    return text + (f" (exit {r['code']})" if r["code"] != 0 else "")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[2048, 4096, 8192, 16384])
    ap.add_argument("--src", type=Path, default=ROOT / "src", help="the matremap source folder to measure")
    ap.add_argument("--cap-gb", type=float, default=12.0, help="address-space cap per command (GB)")
    ap.add_argument("--keep", type=Path, help="keep the generated map sets here (reused when present)")
    a = ap.parse_args()
    print(f"matremap from {a.src}; peaks in MB: tree (command + workers, sampled) / main process (time -v)")
    print(f"{'map size':>12} | {'remap peak MB':>22} | {'remap s':>8} | {'convert peak MB':>22} | {'convert s':>9}")
    print(f"{'-' * 12}-+-{'-' * 22}-+-{'-' * 8}-+-{'-' * 22}-+-{'-' * 9}")
    base = Path(a.keep) if a.keep else Path(tempfile.mkdtemp(prefix="matremap-memory-"))
    try:
        for n in a.sizes:
            maps = base / f"bronze-{n}"
            if not (maps / "material.json").is_file():
                tiled_map_set(maps, n)
            with tempfile.TemporaryDirectory(prefix="matremap-memory-run-") as t:
                cwd = Path(t)
                job = ["--to", "mitsuba06:pbr", "--fix", "distribution=as"]
                r = measure(["remap", str(maps), *job, "-o", "remap-out"], a.src, cwd, a.cap_gb)
                c = measure(["convert", str(maps), *job, "-o", "convert-out"], a.src, cwd, a.cap_gb)
            print(
                f"{f'{n} x {n}':>12} | {cell(r, a.cap_gb):>22} | {r['seconds']:>8.1f} | {cell(c, a.cap_gb):>22} | "
                f"{c['seconds']:>9.1f}",
                flush=True,
            )
            for what, res in (("remap", r), ("convert", c)):
                if res["code"] not in (0, 3) and not res["memory_error"]:
                    print(f"{'':>12}   {what}: {res['line']}", flush=True)
    finally:
        if not a.keep:
            shutil.rmtree(base, ignore_errors=True)


if __name__ == "__main__":
    main()
