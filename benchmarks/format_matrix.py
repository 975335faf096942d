"""`matremap remap X --to Y` for X, Y in glTF, MaterialX, Mitsuba 3 XML and USD on the textured example brass
(issue 15), each run as a user runs it (a fresh process, one cache for the table), with the written file opened
by its own library. Prints one row per pair: exit status, wall seconds, whether the file loads, and the written
base colour's mean hue and luminance against the brass's (read with tests/corpus_checks.py, which uses no
matremap code). tests/test_format_matrix.py asserts the same on a 64 x 64 copy; this runs the example as shipped.

    python benchmarks/format_matrix.py [--size 48] [--rotations 0:360:2]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
import corpus_checks as cc  # noqa: E402

BRASS = ROOT / "examples" / "brass-gltf" / "brass.gltf"
#: format -> (target model, file written)
TARGETS = {
    "glTF": ("gltf:metal-rough", "m.gltf"),
    "MaterialX": ("gltf:metal-rough", "m.mtlx"),
    "Mitsuba": ("mitsuba3:principled", "m.xml"),
    "USD": ("usd:preview_surface", "m.usda"),
}


def usd_colour(path: Path):
    """The UsdPreviewSurface diffuseColor texture (or value), opened with pxr."""
    import numpy as np
    from pxr import Usd, UsdShade

    stage = Usd.Stage.Open(str(path))
    for prim in stage.Traverse():
        shader = UsdShade.Shader(prim)
        if prim.IsA(UsdShade.Shader) and shader.GetIdAttr().Get() == "UsdPreviewSurface":
            inp = shader.GetInput("diffuseColor")
            if not inp.HasConnectedSource():
                return np.asarray(inp.Get(), dtype=float)[None, None, :]
            tex = UsdShade.Shader(inp.GetConnectedSource()[0].GetPrim())
            return cc.rgb(cc.read_image(tex.GetInput("file").Get().resolvedPath))
    raise ValueError(f"{path}: no UsdPreviewSurface")


def loads(path: Path) -> bool:
    if path.suffix == ".usda":
        from pxr import Usd

        return Usd.Stage.Open(str(path)) is not None
    return cc.file_loads(path)[0]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="48", help="evaluation render side, pixels (default 48)")
    ap.add_argument("--rotations", default="0:360:2", help="environment rotations (default 0:360:2)")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="format-matrix-"))
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src"), "MATREMAP_CACHE": str(tmp / "cache")}
    fast = ["--rotations", args.rotations, "--size", args.size, "--env-lights", "32"]

    def remap(src: Path, fmt: str, out: Path) -> tuple[int, float, Path]:
        target, name = TARGETS[fmt]
        argv = [sys.executable, "-m", "matremap.cli", "remap", str(src), "--to", target, "-o", str(out)]
        t0 = time.perf_counter()
        p = subprocess.run([*argv, "--write", name, *fast], env=env, capture_output=True, text=True)
        return p.returncode, time.perf_counter() - t0, out / name

    brass = cc.gltf_base_colour(BRASS)
    sources = {"glTF": BRASS}
    rows = []
    for fmt in list(TARGETS)[1:]:  # the glTF -> Y pairs make the other sources
        code, seconds, written = remap(BRASS, fmt, tmp / f"glTF-{fmt}")
        sources[fmt] = written
        rows.append(("glTF", fmt, code, seconds, written))
    for x in TARGETS:
        for y in TARGETS:
            if x == "glTF" and y != "glTF":
                continue
            code, seconds, written = remap(sources[x], y, tmp / f"{x}-{y}")
            rows.append((x, y, code, seconds, written))
    print(f"brass: hue {cc.mean_hue(brass):.1f} deg, luminance {cc.mean_luminance(brass):.3f}")
    print(f"{'from':10s} {'to':10s} {'exit':>4s} {'seconds':>8s} {'loads':>6s} {'hue':>6s} {'lum':>6s}")
    for x, y, code, seconds, written in sorted(
        rows, key=lambda r: (list(TARGETS).index(r[0]), list(TARGETS).index(r[1]))
    ):
        ok = written.is_file() and loads(written)
        colour = (usd_colour(written) if written.suffix == ".usda" else cc.material_colour(written)) if ok else None
        hue = f"{cc.mean_hue(colour):6.1f}" if colour is not None else "     -"
        lum = f"{cc.mean_luminance(colour):6.3f}" if colour is not None else "     -"
        print(f"{x:10s} {y:10s} {code:4d} {seconds:8.1f} {str(ok):>6s} {hue} {lum}")
    print(f"(files in {tmp})")


if __name__ == "__main__":
    main()
