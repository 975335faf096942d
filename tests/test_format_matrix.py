"""Issue 15, "done when": `matremap remap X --to Y` works for X, Y in {glTF, MaterialX, Mitsuba 3 XML, USD} on a
textured material, and each written file loads in its own library -- all sixteen pairs.

One textured source is made in each format from the example brass (a glTF metal with sRGB base colour,
packed metallic-roughness and normal textures, downscaled here to 64 x 64 texels to keep the sixteen runs
short): the glTF itself, and the brass remapped by the command line into MaterialX, Mitsuba 3 XML and USD
(those three runs are the glTF -> Y pairs). Each of them is then remapped into every format. Every written
file is opened by its own library (pygltflib and the offline validator rules, MaterialX validate with the
standard libraries, ``mitsuba.load_file``, ``pxr.Usd.Stage.Open`` + UsdShade), must still be textured, and
its base colour, read back with the test's own image code (or from Mitsuba's loaded scene), keeps the
brass's hue (< 10 degrees) and luminance (within -20 %/+25 %). The sources are themselves written files, so each
pair also reads what another pair wrote (this replaces the ring glTF -> MaterialX -> Mitsuba -> USD -> glTF of
tests/test_format_ring.py, four of these pairs). Six of the pairs sweep (no library route to or from USD's
UsdPreviewSurface or Mitsuba 3's principled), with one cache for the module: about 45 s in all on 2 cores.
`python benchmarks/format_matrix.py` prints the sixteen runs of the full-size example, timed, as a table.
"""

from __future__ import annotations

from pathlib import Path

import corpus_checks as cc
import gltf_validation as gv
import pytest

from matremap.cli import main

BRASS = Path(__file__).resolve().parents[1] / "examples" / "brass-gltf"
FAST = ["--rotations", "0:360:2", "--size", "32", "--env-lights", "16"]
SIDE = 64
#: format -> (target model, file written)
TARGETS = {
    "gltf": ("gltf:metal-rough", "m.gltf"),
    "mtlx": ("gltf:metal-rough", "m.mtlx"),
    "mitsuba": ("mitsuba3:principled", "m.xml"),
    "usd": ("usd:preview_surface", "m.usda"),
}
FORMATS = list(TARGETS)


def _remap(src: Path, out: Path, fmt: str) -> Path:
    target, name = TARGETS[fmt]
    code = main(["remap", str(src), "--to", target, "-o", str(out), "--write", name, *FAST])
    assert code == 0, f"{src.name} -> {target} ({name}) exited {code}"
    assert (out / name).is_file()
    return out / name


def _small_brass(folder: Path) -> Path:
    """The example brass with every texture downscaled to SIDE x SIDE (OpenImageIO's default filter)."""
    import OpenImageIO as oiio

    folder.mkdir(parents=True)
    for f in BRASS.iterdir():
        if f.suffix == ".png":
            buf = oiio.ImageBuf(str(f))
            roi = oiio.ROI(0, SIDE, 0, SIDE, 0, 1, 0, buf.nchannels)
            assert oiio.ImageBufAlgo.resize(buf, roi=roi).write(str(folder / f.name))
        else:
            (folder / f.name).write_bytes(f.read_bytes())
    return folder / "brass.gltf"


@pytest.fixture(scope="module")
def sources(tmp_path_factory) -> dict[str, Path]:
    """The brass in each format (the glTF -> Y pairs are the runs that made them); a cache of this module's own."""
    pytest.importorskip("MaterialX")
    pytest.importorskip("mitsuba")
    pytest.importorskip("pxr")
    pytest.importorskip("pygltflib")
    root = tmp_path_factory.mktemp("matrix")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("MATREMAP_CACHE", str(root / "cache"))
        made = {"gltf": _small_brass(root / "brass")}
        for fmt in FORMATS[1:]:
            made[fmt] = _remap(made["gltf"], root / f"gltf-{fmt}", fmt)
        yield made


def _usd_base_colour(path: Path):
    """The UsdPreviewSurface diffuseColor: its UsdUVTexture's file (decoded per its sourceColorSpace) x scale,
    or its value; and whether the stage opens with every material bound to something."""
    import numpy as np
    from pxr import Usd, UsdShade

    stage = Usd.Stage.Open(str(path))
    assert stage is not None
    surfaces = [
        UsdShade.Shader(p)
        for p in stage.Traverse()
        if p.IsA(UsdShade.Shader) and UsdShade.Shader(p).GetIdAttr().Get() == "UsdPreviewSurface"
    ]
    assert len(surfaces) == 1
    inp = surfaces[0].GetInput("diffuseColor")
    if not inp.HasConnectedSource():
        return np.asarray(inp.Get(), dtype=float)[None, None, :]
    tex = UsdShade.Shader(inp.GetConnectedSource()[0].GetPrim())
    assert tex.GetIdAttr().Get() == "UsdUVTexture"
    file = tex.GetInput("file").Get()
    assert file.resolvedPath, f"USD's resolver does not find {file.path}"
    space = tex.GetInput("sourceColorSpace").Get() if tex.GetInput("sourceColorSpace") else "auto"
    image = cc.rgb(cc.read_image(file.resolvedPath, srgb=None if space == "auto" else space == "sRGB"))
    scale = tex.GetInput("scale").Get() if tex.GetInput("scale") else None
    return image * (np.asarray(scale, dtype=float)[:3] if scale is not None else 1.0)


def _loads_and_colour(path: Path):
    """Open ``path`` in its own library and return its base colour (linear, H x W x 3)."""
    if path.suffix == ".usda":
        return _usd_base_colour(path)
    if path.suffix == ".gltf":
        assert gv.offline_check(path) == []
    ok, why = cc.file_loads(path)
    assert ok, why
    return cc.material_colour(path)


@pytest.mark.slow
@pytest.mark.parametrize("y", FORMATS)
@pytest.mark.parametrize("x", FORMATS)
def test_a_textured_material_remaps_between_every_pair_of_formats(x, y, sources, tmp_path, monkeypatch):
    if x == "gltf" and y != "gltf":
        written = sources[y]  # made by the fixture: the same command
    else:
        monkeypatch.setenv("MATREMAP_CACHE", str(sources["gltf"].parents[1] / "cache"))
        written = _remap(sources[x], tmp_path / "out", y)
    colour = _loads_and_colour(written)
    brass = cc.gltf_base_colour(sources["gltf"])
    assert cc.varies(colour), "the written base colour is a constant, not a map"
    assert cc.hue_difference(cc.mean_hue(brass), cc.mean_hue(colour)) < 10
    assert 0.8 < cc.mean_luminance(colour) / cc.mean_luminance(brass) < 1.25
