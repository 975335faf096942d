"""Issue 15, "done when": `matremap remap X --to Y` on a textured material for X, Y among glTF, MaterialX,
Mitsuba 3 XML and USD, each written file loading in its own library. A ring: Khronos BoxTextured (CC-BY 4.0,
an sRGB base-colour texture) goes glTF -> MaterialX -> Mitsuba 3 XML -> USD -> glTF, every file written by one
step being read by the next; at each step the file is opened by its own library, and at the end the base
colour is compared with the original's (hue and luminance, read with the test's own image code).
`python benchmarks/format_matrix.py` runs all sixteen pairs and prints the table."""

from __future__ import annotations

from pathlib import Path

import corpus_checks as cc
import pytest

from matremap.cli import main

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
FAST = ["--rotations", "0:360:2", "--size", "48", "--env-lights", "32"]


def _remap(src: Path, out: Path, target: str, name: str, *extra: str) -> Path:
    code = main(["remap", str(src), "--to", target, "-o", str(out), "--write", name, *FAST, *extra])
    assert code == 0, f"{src.name} -> {target} ({name}) exited {code}"
    written = out / name
    assert written.is_file()
    return written


@pytest.mark.slow
def test_a_textured_material_goes_round_the_four_formats_and_keeps_its_colour(tmp_path):
    pytest.importorskip("MaterialX")
    pytest.importorskip("mitsuba")
    pytest.importorskip("pxr")
    from pxr import Usd, UsdShade

    src = EXAMPLES / "brass-gltf" / "brass.gltf"
    mtlx = _remap(src, tmp_path / "1", "gltf:metal-rough", "box.mtlx")
    assert cc.mtlx_loads(mtlx)[0]
    xml = _remap(mtlx, tmp_path / "2", "mitsuba3:principled", "box.xml")
    assert cc.mitsuba_loads(xml)[0]
    usda = _remap(xml, tmp_path / "3", "usd:preview_surface", "box.usda")
    stage = Usd.Stage.Open(str(usda))
    shaders = [UsdShade.Shader(p) for p in stage.Traverse() if p.IsA(UsdShade.Shader)]
    assert any(s.GetIdAttr().Get() == "UsdPreviewSurface" for s in shaders)
    assert any(s.GetIdAttr().Get() == "UsdUVTexture" for s in shaders)  # still textured
    back = _remap(usda, tmp_path / "4", "gltf:metal-rough", "box.gltf")
    assert cc.gltf_loads(back)[0]
    before, after = cc.gltf_base_colour(src), cc.gltf_base_colour(back)
    assert cc.varies(after)  # a texture, not a constant
    assert cc.hue_difference(cc.mean_hue(before), cc.mean_hue(after)) < 10
    assert 0.8 < cc.mean_luminance(after) / cc.mean_luminance(before) < 1.25
