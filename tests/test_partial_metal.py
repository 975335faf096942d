"""A uniform partial metal (Khronos MetalRoughSpheresNoTextures, CC-BY) onto UsdPreviewSurface: its metalness is
freed from the source's and fitted jointly (remap.free_partial_metal). It was held at 0 and fitted in stages, which
split a base colour that is both diffuse and metal apart: 58 of the 98 spheres failed the gate. Checked on the
written file with pxr."""

from __future__ import annotations

from pathlib import Path

import pytest

from matremap.cli import main

CORPUS = Path(__file__).parent / "data" / "corpus"
SPHERES = CORPUS / "gltf-MetalRoughSpheresNoTextures" / "MetalRoughSpheresNoTextures.glb"


@pytest.mark.parametrize("material, metallic", [("mat_36", 0.833), ("mat_9", 0.167)])
def test_a_partial_metal_keeps_its_metalness_on_usd(tmp_path, capsys, material, metallic):
    pytest.importorskip("colour", reason="the quality gate needs colour-science")
    Usd = pytest.importorskip("pxr.Usd")
    UsdShade = pytest.importorskip("pxr.UsdShade")
    out = tmp_path / "out"
    code = main(["remap", str(SPHERES), "--material", material, "--to", "usd:preview_surface", "-o", str(out)])
    log = capsys.readouterr().err
    assert code == 0, log[-600:]
    assert f"metallic freed from the source's {metallic:.3g}" in log
    stage = Usd.Stage.Open(str(out / "MetalRoughSpheresNoTextures.usda"))
    shaders = [UsdShade.Shader(p) for p in stage.Traverse() if p.IsA(UsdShade.Shader)]
    preview = [s for s in shaders if s.GetIdAttr().Get() == "UsdPreviewSurface"]
    assert len(preview) == 1
    value = preview[0].GetInput("metallic").Get()
    assert 0.0 < value < 1.0 and abs(value - metallic) < 0.25  # a partial metal, near the source's
