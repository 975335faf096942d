"""formats.write_all into a fresh file of another format carries each material's emission (issue 20 must-have 1
with issue 15's carried inputs): Khronos EmissiveStrengthTest (CC-BY 4.0) written as MaterialX, USD and Mitsuba
XML, each read back with its own library."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from matremap.core.material import Material
from matremap.formats import read_asset, write_all

SOURCE = Path(__file__).parent / "data" / "corpus" / "gltf-EmissiveStrengthTest" / "EmissiveStrengthTest.glb"
NAMES = ["Emit4", "Emit2"]


def _gltf_results() -> list[tuple[str, Material]]:
    return [(n, read_asset(SOURCE, n).material()) for n in NAMES]


def test_materialx_fresh_document_carries_emission(tmp_path):
    mx = pytest.importorskip("MaterialX")
    out = write_all(tmp_path / "all.mtlx", _gltf_results(), SOURCE)
    doc = mx.createDocument()
    mx.readFromXmlFile(doc, str(out))
    for name in NAMES:
        want = np.asarray(read_asset(SOURCE, name).carried["emission"].value)
        shader = mx.getShaderNodes(doc.getNode(name))[0]
        colour = np.array([float(x) for x in shader.getInput("emissive").getValueString().split(",")])
        strength = shader.getInput("emissive_strength")
        factor = float(strength.getValueString()) if strength is not None else 1.0
        np.testing.assert_allclose(colour * factor, want, rtol=1e-6)


def test_usd_fresh_stage_carries_emission(tmp_path):
    pytest.importorskip("pxr")
    from pxr import Usd, UsdShade

    results = [(n, Material.create("usd:preview_surface", {"diffuseColor": 0.5})) for n in NAMES]
    out = write_all(tmp_path / "all.usda", results, SOURCE)
    stage = Usd.Stage.Open(str(out))
    found = {p.GetName(): p for p in stage.Traverse() if p.IsA(UsdShade.Material)}
    assert len(found) == 2
    for name, prim in found.items():
        source_name = next(n for n in NAMES if n in name)
        want = np.asarray(read_asset(SOURCE, source_name).carried["emission"].value)
        shader = UsdShade.Material(prim).ComputeSurfaceSource()[0]
        assert shader.GetIdAttr().Get() == "UsdPreviewSurface"
        np.testing.assert_allclose(np.asarray(shader.GetInput("emissiveColor").Get(), dtype=float), want, rtol=1e-6)


def test_mitsuba_fresh_scene_carries_emission_as_area_emitters(tmp_path):
    mi = pytest.importorskip("mitsuba")
    results = [(n, Material.create("mitsuba3:diffuse", {"reflectance": 0.5})) for n in NAMES]
    out = write_all(tmp_path / "all.xml", results, SOURCE)
    text = out.read_text()
    assert text.count('type="area"') == 2
    for name in NAMES:
        want = read_asset(SOURCE, name).carried["emission"].value
        assert ", ".join(repr(float(x)) for x in want) in text
    mi.set_variant("scalar_rgb")
    scene = mi.load_file(str(out))
    assert len([s for s in scene.shapes() if s.emitter() is not None]) == 2


def test_gltf_fresh_file_carries_a_materialx_emission(tmp_path):
    pytest.importorskip("MaterialX")
    import json

    src = tmp_path / "two.mtlx"
    shaders = "".join(
        f'<gltf_pbr name="S{i}" type="surfaceshader"><input name="base_color" type="color3" value="0.5, 0.5, 0.5"/>'
        f'<input name="emissive" type="color3" value="{e}"/></gltf_pbr>'
        f'<surfacematerial name="M{i}" type="material"><input name="surfaceshader" type="surfaceshader" '
        f'nodename="S{i}"/></surfacematerial>'
        for i, e in enumerate(["0.25, 0.5, 0.75", "1, 0, 0"])
    )
    src.write_text(f'<?xml version="1.0"?><materialx version="1.39">{shaders}</materialx>')
    results = [(n, read_asset(src, n).material()) for n in ("M0", "M1")]
    out = write_all(tmp_path / "all.gltf", results, src)
    doc = json.loads(out.read_text())
    by_name = {m["name"]: m for m in doc["materials"]}
    assert by_name["M0"]["emissiveFactor"] == pytest.approx([0.25, 0.5, 0.75])
    assert by_name["M1"]["emissiveFactor"] == pytest.approx([1.0, 0.0, 0.0])
