"""`matremap remap FILE` across layering (issue 16): a coated or sheen material of any of the five layered models
(OpenPBR and Standard Surface in MaterialX, glTF with KHR_materials_clearcoat / _sheen, Mitsuba 3 principled,
Cycles' Principled BSDF in a .blend) is read into its own model, its layer fitted with the target's layer (freed,
started at the source's), and written as the target's file with that layer in it.

Sources: Standard Surface's copper (MaterialX examples, Apache-2.0, tests/data/corpus) and materials written
here. Each remap fits one uniform material (a few seconds); the Cycles ones skip without the bpy venv.
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from matremap.cli import main
from matremap.core.material import Material
from matremap.dialects import get_model
from matremap.dialects.mtlx import freed_layers
from matremap.formats import read_asset, write_asset
from matremap.renderers.cycles.client import bpy_available

CORPUS = Path(__file__).resolve().parent / "data" / "corpus"
COPPER = CORPUS / "mtlx-standard_surface_copper" / "standard_surface_copper.mtlx"

needs_materialx = pytest.mark.skipif(
    importlib.util.find_spec("MaterialX") is None, reason="MaterialX not installed: pip install 'matremap[materialx]'"
)
needs_bpy = pytest.mark.skipif(not bpy_available(), reason="the bpy venv is not set up (docs/cycles.md)")
pytest.importorskip("colour", reason="the quality gate needs colour-science")

OPENPBR_VELVET = """<?xml version="1.0"?>
<materialx version="1.39" colorspace="lin_rec709">
  <open_pbr_surface name="SR_velvet" type="surfaceshader">
    <input name="base_color" type="color3" value="0.25, 0.03, 0.08" />
    <input name="specular_weight" type="float" value="0.2" />
    <input name="specular_roughness" type="float" value="0.6" />
    <input name="fuzz_weight" type="float" value="1" />
    <input name="fuzz_color" type="color3" value="0.8, 0.35, 0.45" />
    <input name="fuzz_roughness" type="float" value="0.5" />
    <input name="geometry_thin_walled" type="boolean" value="false" />
  </open_pbr_surface>
  <surfacematerial name="Velvet" type="material">
    <input name="surfaceshader" type="surfaceshader" nodename="SR_velvet" />
  </surfacematerial>
</materialx>
"""

PRINCIPLED_COAT = """<scene version="3.0.0">
  <bsdf type="principled" id="coated">
    <rgb name="base_color" value="0.7, 0.2, 0.1"/>
    <float name="roughness" value="0.45"/>
    <float name="clearcoat" value="1.0"/>
    <float name="clearcoat_gloss" value="0.8"/>
  </bsdf>
</scene>
"""


def gltf_sheen(folder: Path) -> Path:
    """A glTF dielectric with a coloured KHR_materials_sheen (velvet)."""
    folder.mkdir(parents=True, exist_ok=True)
    pbr = {"baseColorFactor": [0.1, 0.02, 0.05, 1.0], "metallicFactor": 0.0, "roughnessFactor": 0.8}
    sheen = {"sheenColorFactor": [0.9, 0.4, 0.5], "sheenRoughnessFactor": 0.5}
    doc = {
        "asset": {"version": "2.0"},
        "extensionsUsed": ["KHR_materials_sheen"],
        "materials": [{"name": "Sheen", "pbrMetallicRoughness": pbr, "extensions": {"KHR_materials_sheen": sheen}}],
    }
    path = folder / "sheen.gltf"
    path.write_text(json.dumps(doc))
    return path


def remap(capsys, src: Path, target: str, out: Path, *extra: str) -> tuple[int, str]:
    code = main(["remap", str(src), "--to", target, "-o", str(out), *extra])
    captured = capsys.readouterr()
    return code, captured.out + captured.err


def written(out: Path) -> Path:
    files = [p for p in out.iterdir() if p.suffix in (".mtlx", ".gltf", ".glb", ".xml", ".blend")]
    assert len(files) == 1, files
    return files[0]


# ------------------------------------------------------------------------------------------------
# which layer parameters are freed, and where they start


def test_a_source_layer_frees_the_targets_matching_layer_started_at_the_source():
    copper = read_asset(COPPER).material() if importlib.util.find_spec("MaterialX") else None
    values = (
        copper.values
        if copper is not None
        else {"coat": 1.0, "coat_color": [0.96, 0.38, 0.26], "coat_roughness": 0.2, "sheen": 0.0}
    )
    free, start = freed_layers("mtlx:standard_surface", values, get_model("cycles:principled"))
    assert free == ["Coat Weight", "Coat Tint", "Coat Roughness"]  # the coat, not the sheen (sheen 0)
    assert start["Coat Weight"] == 1.0 and start["Coat Roughness"] == pytest.approx(0.2)
    np.testing.assert_allclose(start["Coat Tint"], values["coat_color"], rtol=1e-6)
    # glTF's sheen colour is its weight: the source's weight times its colour; Mitsuba's gloss is 1 - roughness
    free, start = freed_layers(
        "mtlx:open_pbr_surface", {"fuzz_weight": 0.5, "fuzz_color": [1.0, 0.5, 0.5]}, get_model("gltf:pbr")
    )
    assert free == ["sheenColor", "sheenRoughness"] and start["sheenColor"] == [0.5, 0.25, 0.25]
    free, start = freed_layers(
        "gltf:pbr", {"clearcoat": 1.0, "clearcoatRoughness": 0.1}, get_model("mitsuba3:principled")
    )
    assert free == ["clearcoat", "clearcoat_gloss"] and start["clearcoat_gloss"] == pytest.approx(0.9)
    # a plain source frees nothing; a target without the layer frees nothing; --fix holds a parameter
    assert freed_layers("mtlx:standard_surface", {"coat": 0.0}, get_model("gltf:pbr")) == ([], {})
    assert freed_layers("mtlx:standard_surface", {"coat": 1.0}, get_model("gltf:metal-rough")) == ([], {})
    free, _ = freed_layers("gltf:pbr", {"clearcoat": 1.0}, get_model("gltf:pbr"), held=["clearcoatRoughness"])
    assert free == ["clearcoat"]


# ------------------------------------------------------------------------------------------------
# writers: each layered model's file holds its layers


@needs_materialx
@pytest.mark.parametrize(
    "model, values, node",
    [
        ("mtlx:open_pbr_surface", {"coat_weight": 0.7, "coat_color": [0.9, 0.5, 0.3], "fuzz_weight": 0.2}, "open_pbr"),
        ("mtlx:standard_surface", {"coat": 0.6, "sheen": 0.4, "sheen_color": [0.8, 0.2, 0.5]}, "standard_surface"),
        ("gltf:pbr", {"clearcoat": 0.9, "clearcoatRoughness": 0.2, "sheenColor": [0.5, 0.1, 0.2]}, "gltf_pbr"),
    ],
)
def test_the_materialx_writer_writes_layered_models_read_back_equal(tmp_path, model, values, node):
    m = Material.create(model, values)
    out = write_asset(tmp_path / "m.mtlx", m)
    assert f"<{node}" in out.read_text()
    back = read_asset(out)  # a layer carrying the look is read into the same model
    assert back.model == model
    for k, v in values.items():
        np.testing.assert_allclose(back.constants[k], v, rtol=1e-9)


def test_the_gltf_writer_writes_gltf_pbr_layers_as_khr_extensions(tmp_path):
    m = Material.create(
        "gltf:pbr", {"baseColor": [0.5, 0.1, 0.1], "clearcoat": 0.8, "clearcoatRoughness": 0.1, "sheenColor": 0.6}
    )
    out = write_asset(tmp_path / "m.gltf", m)
    doc = json.loads(out.read_text())
    ext = doc["materials"][0]["extensions"]
    assert ext["KHR_materials_clearcoat"] == {"clearcoatFactor": 0.8, "clearcoatRoughnessFactor": 0.1}
    assert ext["KHR_materials_sheen"]["sheenColorFactor"] == [0.6, 0.6, 0.6]
    assert "KHR_materials_transmission" not in ext and "KHR_materials_volume" not in ext  # off: not written
    assert {"KHR_materials_clearcoat", "KHR_materials_sheen"} <= set(doc["extensionsUsed"])
    back = read_asset(out)
    assert back.model == "gltf:pbr" and back.constants["clearcoat"] == 0.8


# ------------------------------------------------------------------------------------------------
# remaps across the five models, through their files


@needs_materialx
def test_standard_surface_copper_onto_gltf_pbr_keeps_its_coat_as_a_clearcoat(tmp_path, capsys):
    code, log = remap(capsys, COPPER, "gltf:pbr", tmp_path / "out")
    assert code == 0 and "PASSED" in log, log[-600:]
    assert "clearcoat, clearcoatRoughness freed" in log
    back = read_asset(written(tmp_path / "out"))  # the MaterialX document's gltf_pbr node
    assert back.model == "gltf:pbr" and back.constants["clearcoat"] > 0.5
    r, g, b = back.constants["baseColor"]
    assert r > 2 * g > 2 * b  # the copper colour of the coat went into the metal's F0


@needs_materialx
def test_openpbr_velvet_onto_gltf_pbr_fits_the_fuzz_as_a_sheen(tmp_path, capsys):
    src = tmp_path / "in" / "velvet.mtlx"
    src.parent.mkdir()
    src.write_text(OPENPBR_VELVET)
    code, log = remap(capsys, src, "gltf:pbr", tmp_path / "out")
    assert code == 0 and "PASSED" in log, log[-600:]
    back = read_asset(written(tmp_path / "out"))
    sheen = np.asarray(back.constants["sheenColor"])
    assert back.model == "gltf:pbr" and sheen.max() > 0.5 and sheen[0] > sheen[1]  # a pink sheen, as the fuzz


@needs_materialx
def test_mitsuba_clearcoat_onto_openpbr_fits_the_coat(tmp_path, capsys):
    src = tmp_path / "in" / "principled.xml"
    src.parent.mkdir()
    src.write_text(PRINCIPLED_COAT)
    code, log = remap(capsys, src, "mtlx:open_pbr_surface", tmp_path / "out")
    assert code == 0 and "PASSED" in log, log[-600:]
    back = read_asset(written(tmp_path / "out"))
    assert back.model == "mtlx:open_pbr_surface" and back.constants["coat_weight"] > 0.2


def test_a_sheen_onto_a_model_without_a_coloured_sheen_is_absorbed_and_the_gate_says_so(tmp_path, capsys):
    """glTF velvet onto Mitsuba 3's principled (a white-to-tinted Disney sheen): the fit cannot make the look;
    the result is written, the layer named as absorbed, and the gate fails it (exit 3)."""
    code, log = remap(capsys, gltf_sheen(tmp_path / "in"), "mitsuba3:principled", tmp_path / "out")
    assert code == 3 and "FAILED: fit_error" in log.strip().splitlines()[-1]


@needs_bpy
def test_gltf_sheen_onto_cycles_principled_writes_its_sheen_into_the_blend_and_reads_back(tmp_path, capsys):
    code, log = remap(capsys, gltf_sheen(tmp_path / "in"), "cycles:principled", tmp_path / "out")
    assert code == 0 and "PASSED" in log, log[-600:]
    back = read_asset(written(tmp_path / "out"))  # the .blend, read by its Principled BSDF
    assert back.model == "cycles:principled" and back.constants["Sheen Weight"] > 0.5


@needs_bpy
def test_a_blend_principled_with_a_coat_onto_gltf_pbr(tmp_path, capsys):
    src = tmp_path / "in" / "coated.blend"
    src.parent.mkdir()
    coated = {"Base Color": [0.8, 0.5, 0.35], "Metallic": 1.0, "Roughness": 0.35, "Coat Weight": 1.0}
    write_asset(src, Material.create("cycles:principled", {**coated, "Coat Roughness": 0.15}))
    asset = read_asset(src)
    assert asset.model == "cycles:principled" and asset.constants["Coat Weight"] == 1.0
    code, log = remap(capsys, src, "gltf:pbr", tmp_path / "out")
    assert code == 0 and "PASSED" in log, log[-600:]
    doc = json.loads(written(tmp_path / "out").read_text())
    assert doc["materials"][0]["extensions"]["KHR_materials_clearcoat"]["clearcoatFactor"] > 0.5


@needs_bpy
def test_a_textured_or_non_principled_blend_material_is_refused_in_one_line(tmp_path, capsys):
    src = tmp_path / "in" / "glossy.blend"
    src.parent.mkdir()
    write_asset(src, Material.create("cycles:glossy", {"Roughness": 0.3}))
    code, log = remap(capsys, src, "gltf:pbr", tmp_path / "out")
    last = log.strip().splitlines()[-1]
    assert code == 2 and "Principled BSDF" in last and "ShaderNodeAddShader" in last and not (tmp_path / "out").exists()
