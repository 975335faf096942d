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

With ``--readers`` (all, or those named: glTF USD MaterialX Mitsuba), each reader's ``remap ASSET --to
mitsuba06:ward`` instead, ASSET a material file whose N x N texture the reader bakes (a glTF base colour over
2048 a side, a USD texture through a rotating UsdTransform2d, a MaterialX tiledimage tiled twice, a Mitsuba
bitmap through ``to_uv``), then a glTF whose JSON carries ``--json-mb`` MB of extras copied to glTF (numbers:
under the JSON value limit; pairs: over it). SECURITY.md's table per reader comes from

    python benchmarks/memory.py --readers --sizes 4096 16384 --cap-gb 8

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
from typing import Any

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


def tiled_png(path: Path, size: int, tile: Path = BRONZE / "bronze_diffuse.png") -> Path:
    """An 8-bit PNG of ``size`` x ``size``: ``tile`` repeated (written band by band)."""
    import OpenImageIO as oiio

    src = oiio.ImageInput.open(str(tile))
    spec = src.spec()
    texels = src.read_image(0, 0, 0, spec.nchannels, oiio.UINT8).reshape(spec.height, spec.width, spec.nchannels)
    src.close()
    row_tile = np.tile(texels, (1, -(-size // spec.width), 1))[:, :size]
    out = oiio.ImageOutput.create(str(path))
    out_spec = oiio.ImageSpec(size, size, spec.nchannels, oiio.UINT8)
    out_spec.attribute("png:compressionLevel", 1)
    out.open(str(path), out_spec)
    rows = max(spec.height, (1 << 24) // (size * spec.nchannels) // spec.height * spec.height)
    for y0 in range(0, size, rows):
        y1 = min(size, y0 + rows)
        band = np.tile(row_tile, (-(-(y1 - y0) // spec.height), 1, 1))[: y1 - y0]
        out.write_scanlines(y0, y1, 0, np.ascontiguousarray(band))
    out.close()
    return path


def gltf_asset(folder: Path, size: int) -> Path:
    """The issue's glTF: a base colour of ``size``² (8-bit PNG), uniform metallic and roughness (a texture over 2048
    a side is baked onto the 2048² map a glTF's textures share)."""
    folder.mkdir(parents=True, exist_ok=True)
    tiled_png(folder / "base.png", size)
    pbr = {"baseColorTexture": {"index": 0}, "metallicFactor": 0.0, "roughnessFactor": 0.5}
    doc = {
        "asset": {"version": "2.0"},
        "images": [{"uri": "base.png"}],
        "textures": [{"source": 0}],
        "materials": [{"name": "m", "pbrMetallicRoughness": pbr}],
    }
    (folder / "m.gltf").write_text(json.dumps(doc))
    return folder / "m.gltf"


def usd_asset(folder: Path, size: int) -> Path:
    """A UsdPreviewSurface whose diffuseColor is a ``size``² texture read through a UsdTransform2d (rotated 90
    degrees: baked)."""
    folder.mkdir(parents=True, exist_ok=True)
    tiled_png(folder / "base.png", size)
    (folder / "m.usda").write_text(
        """#usda 1.0
def Material "M"
{
    token outputs:surface.connect = </M/S.outputs:surface>
    def Shader "S"
    {
        uniform token info:id = "UsdPreviewSurface"
        color3f inputs:diffuseColor.connect = </M/T.outputs:rgb>
        float inputs:roughness = 0.5
        token outputs:surface
    }
    def Shader "T"
    {
        uniform token info:id = "UsdUVTexture"
        asset inputs:file = @base.png@
        float2 inputs:st.connect = </M/X.outputs:result>
        float3 outputs:rgb
    }
    def Shader "X"
    {
        uniform token info:id = "UsdTransform2d"
        float2 inputs:in.connect = </M/P.outputs:result>
        float inputs:rotation = 90
        float2 outputs:result
    }
    def Shader "P"
    {
        uniform token info:id = "UsdPrimvarReader_float2"
        token inputs:varname = "st"
        float2 outputs:result
    }
}
"""
    )
    return folder / "m.usda"


def mtlx_asset(folder: Path, size: int) -> Path:
    """A standard_surface whose base_color is a ``size``² tiledimage tiled twice (a graph: baked)."""
    folder.mkdir(parents=True, exist_ok=True)
    tiled_png(folder / "base.png", size)
    (folder / "m.mtlx").write_text(
        '<?xml version="1.0"?>\n<materialx version="1.39" colorspace="lin_rec709">\n'
        '  <tiledimage name="t" type="color3"><input name="file" type="filename" value="base.png" '
        'colorspace="srgb_texture"/>\n    <input name="uvtiling" type="vector2" value="2, 2"/></tiledimage>\n'
        '  <standard_surface name="s" type="surfaceshader"><input name="base_color" type="color3" nodename="t"/>'
        '<input name="specular_roughness" type="float" value="0.4"/></standard_surface>\n'
        '  <surfacematerial name="m" type="material"><input name="surfaceshader" type="surfaceshader" nodename="s"/>'
        "</surfacematerial>\n</materialx>\n"
    )
    return folder / "m.mtlx"


def mitsuba_asset(folder: Path, size: int) -> Path:
    """A Mitsuba 3 roughplastic whose diffuse reflectance is a ``size``² bitmap read through a ``to_uv`` scale
    (baked)."""
    folder.mkdir(parents=True, exist_ok=True)
    tiled_png(folder / "base.png", size)
    (folder / "s.xml").write_text(
        '<scene version="3.0.0"><bsdf type="roughplastic" id="m"><float name="alpha" value="0.2"/>'
        '<texture type="bitmap" name="diffuse_reflectance"><string name="filename" value="base.png"/>'
        '<transform name="to_uv"><scale x="2" y="2"/></transform></texture></bsdf></scene>'
    )
    return folder / "s.xml"


#: reader -> (builds its asset of a given size, the remap's target)
READERS: dict[str, tuple[Any, str]] = {
    "glTF": (gltf_asset, "mitsuba06:ward"),
    "USD": (usd_asset, "mitsuba06:ward"),
    "MaterialX": (mtlx_asset, "mitsuba06:ward"),
    "Mitsuba": (mitsuba_asset, "mitsuba06:ward"),
}


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


def json_gltf(folder: Path, mb: float, kind: str) -> Path:
    """A uniform glTF material whose JSON carries about ``mb`` MB of ``extras``, written compact: ``numbers`` (a
    list of floats, about 5 million values per 100 MB: under the JSON value limit) or ``pairs`` (a list of
    two-number arrays, about 50 million values per 100 MB as counted: over it)."""
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(0)
    if kind == "numbers":
        extras: Any = {"points": np.round(rng.random(int(mb * 1e6 / 19)), 15).tolist()}
    else:
        extras = {"points": [[i % 7, i % 3] for i in range(int(mb * 1e6 / 6))]}
    doc = {
        "asset": {"version": "2.0"},
        "materials": [{"name": "m", "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.3, 0.2, 1.0]}}],
        "extras": extras,
    }
    (folder / "m.gltf").write_text(json.dumps(doc, separators=(",", ":")))
    return folder / "m.gltf"


def reader_rows(a: argparse.Namespace, base: Path) -> None:
    """Each reader's remap of an asset whose texture is N x N (baked: transformed, resampled or tiled), and a
    glTF copy of a glTF whose JSON carries large extras."""
    print(f"matremap from {a.src}; peaks in MB: tree (command + workers, sampled) / main process (time -v)")
    print(f"{'reader':>10} | {'texture':>13} | {'remap peak MB':>26} | {'s':>6} | written")
    print(f"{'-' * 10}-+-{'-' * 13}-+-{'-' * 26}-+-{'-' * 6}-+-{'-' * 8}")
    for n in a.sizes:
        for name, (build, target) in READERS.items():
            if a.readers and name not in a.readers:
                continue
            folder = base / f"{name}-{n}"
            found = [f for f in folder.glob("*") if f.suffix in (".gltf", ".usda", ".mtlx", ".xml")]
            asset = found[0] if found else build(folder, n)
            with tempfile.TemporaryDirectory(prefix="matremap-memory-run-") as t:
                job = ["remap", str(asset), "--to", target, "--rotations", "0:360:2", "-o", "out"]
                r = measure(job, a.src, Path(t), a.cap_gb)
                written = sum(f.stat().st_size for f in (Path(t) / "out").rglob("*") if f.is_file())
            print(
                f"{name:>10} | {f'{n} x {n}':>13} | {cell(r, a.cap_gb):>26} | {r['seconds']:>6.0f} | "
                f"{written / 1e6:.0f} MB",
                flush=True,
            )
            if r["code"] not in (0, 3) and not r["memory_error"]:
                print(f"{'':>10}   {r['line']}", flush=True)
    for kind in ("numbers", "pairs"):
        if not a.json_mb:
            break
        src = json_gltf(base / f"json-{kind}", a.json_mb, kind)
        with tempfile.TemporaryDirectory(prefix="matremap-memory-run-") as t:
            job = ["remap", str(src), "--to", "gltf:metal-rough", "--rotations", "0:360:2", "-o", "out"]
            r = measure(job, a.src, Path(t), a.cap_gb)
            copy = Path(t) / "out" / "m.gltf"
            written = copy.stat().st_size if copy.is_file() else 0
        mb = src.stat().st_size / 1e6
        print(
            f"{'glTF JSON':>10} | {f'{mb:.0f} MB {kind}':>13} | {cell(r, a.cap_gb):>26} | {r['seconds']:>6.0f} | "
            f"{written / 1e6:.0f} MB",
            flush=True,
        )
        if r["code"] not in (0, 3) and not r["memory_error"]:
            print(f"{'':>10}   {r['line']}", flush=True)


#: the peak (MB, command and workers) a hostile-input case of :data:`HOSTILE_CASES` must stay under
HOSTILE_PEAK_MB = 2048


def hostile_case(reader: str, size: int = 16384, json_kind: str = "") -> Any:
    """A case for ``benchmarks/hostile_inputs.py``: ``reader``'s remap of an asset with a ``size``² texture (or, for
    ``json_kind``, a glTF with 100 MB of extras), under a 6 GB address-space cap: ``handled`` when it ends (exit 0 or
    3; for ``pairs``, refused in one line) under :data:`HOSTILE_PEAK_MB`, else ``MEMORY`` and its peak."""

    def case(tmp: Path) -> str:
        if json_kind:
            src, target = json_gltf(tmp / "asset", 100, json_kind), "gltf:metal-rough"
        else:
            build, target = READERS[reader]
            src = build(tmp / "asset", size)
        given = os.environ.get("PYTHONPATH", "").split(os.pathsep)[0]  # the checkout measured, as hostile_inputs says
        job = ["remap", str(src), "--to", target, "--rotations", "0:360:2", "-o", "out"]
        r = measure(job, Path(given) if given else ROOT / "src", tmp, 6)
        peak = max(float(r["tree_mb"]), float(r["main_mb"]))  # type: ignore[arg-type]
        expect = (2,) if json_kind == "pairs" else (0, 3)
        if r["memory_error"] or peak > HOSTILE_PEAK_MB:
            return f"MEMORY ({peak:.0f} MB)" if not r["memory_error"] else "MEMORY (over the 6 GB cap)"
        if r["code"] not in expect:
            return f"exit {r['code']}: {str(r['line'])[:60]}"
        return f"{'refused' if json_kind == 'pairs' else 'handled'} ({peak:.0f} MB)"

    return case


#: rows for ``benchmarks/hostile_inputs.py`` (its "memory per reader" block)
HOSTILE_CASES: list[tuple[str, str, Any]] = [
    ("glTF base colour 16384² PNG, peak < 2 GB", "memory per reader", hostile_case("glTF")),
    ("USD texture 16384², transformed, peak < 2 GB", "memory per reader", hostile_case("USD")),
    ("MaterialX tiledimage 16384², peak < 2 GB", "memory per reader", hostile_case("MaterialX")),
    ("Mitsuba bitmap 16384², to_uv, peak < 2 GB", "memory per reader", hostile_case("Mitsuba")),
    ("glTF 100 MB extras (numbers), peak < 2 GB", "memory per reader", hostile_case("glTF", json_kind="numbers")),
    ("glTF 100 MB extras (50M values), refused", "memory per reader", hostile_case("glTF", json_kind="pairs")),
]


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
    ap.add_argument("--readers", nargs="*", help="measure each reader's remap instead (all, or those named)")
    ap.add_argument("--json-mb", type=float, default=100.0, help="with --readers: the glTF JSON cases' size (0: none)")
    a = ap.parse_args()
    if a.readers is not None:
        base = Path(a.keep) if a.keep else Path(tempfile.mkdtemp(prefix="matremap-memory-"))
        try:
            reader_rows(a, base)
        finally:
            if not a.keep:
                shutil.rmtree(base, ignore_errors=True)
        return
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
