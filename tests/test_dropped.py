"""Inputs that change a material's look and that no model here converts (an anisotropy, a subsurface, a thin film,
glTF's KHR_materials_anisotropy / _iridescence): the rest is converted and written, and the quality gate's
``dropped`` check fails it, naming them (exit 3), unless the file is copied onto its own format with them. Before,
OpenPBR's brushed aluminium went onto glTF as an isotropic metal with a note and exit 0."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from test_formats_gltf import make_file

from matremap.cli import main
from matremap.formats import read_asset
from matremap.formats.confine import Confinement

mx = pytest.importorskip("MaterialX", reason="MaterialX not installed: pip install 'matremap[materialx]'")

CORPUS = Path(__file__).resolve().parent / "data" / "corpus"
ALUMINIUM = CORPUS / "mtlx-open_pbr_aluminum_brushed" / "open_pbr_aluminum_brushed.mtlx"
WOOD = next((CORPUS / "mtlx-standard_surface_wood_tiled").rglob("standard_surface_wood_tiled.mtlx"))
JADE = next((CORPUS / "mtlx-standard_surface_jade").rglob("*.mtlx"))
FAST = ["--rotations", "0:360:2", "--size", "48", "--env-lights", "32"]


def test_a_dropped_anisotropy_fails_the_gate_and_is_accepted_when_asked(tmp_path, capsys):
    pytest.importorskip("colour", reason="the quality gate needs colour-science")
    out = tmp_path / "out"
    code = main(["remap", str(ALUMINIUM), "--to", "gltf:metal-rough", "-o", str(out), *FAST])
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert code == 3 and "dropped 1 > 0 (left out: specular_roughness_anisotropy=0.9" in last
    verdict = json.loads((out / "verdict.json").read_text())
    assert [c["name"] for c in verdict["checks"] if not c["passed"]] == ["dropped"]  # the rest converts
    assert (out / "open_pbr_aluminum_brushed.mtlx").is_file()  # written all the same
    again = tmp_path / "again"
    code = main(
        ["remap", str(ALUMINIUM), "--to", "gltf:metal-rough", "-o", str(again), "--max-error", "dropped=1", *FAST]
    )
    assert code == 0, capsys.readouterr().err[-400:]


def test_only_inputs_that_carry_the_look_are_dropped():
    """The jade's subsurface 0.4 and anisotropy 0.5 (of its full specular) are; the tiled wood's anisotropies are
    not: its specular is 0.4 and its coat 0.1, lobes too faint to carry the look (as a coat of 0.5 or less is)."""
    assert read_asset(JADE).dropped == ["specular_anisotropy=0.5", "subsurface=0.4"]
    assert read_asset(WOOD, confinement=Confinement.of([CORPUS])).dropped == []
    assert read_asset(ALUMINIUM).dropped == ["specular_roughness_anisotropy=0.9"]


def _anisotropic_gltf(folder: Path) -> Path:
    material = {
        "name": "brushed",
        "pbrMetallicRoughness": {"baseColorFactor": [0.9, 0.9, 0.9, 1], "metallicFactor": 1.0, "roughnessFactor": 0.4},
        "extensions": {"KHR_materials_anisotropy": {"anisotropyStrength": 0.6, "anisotropyRotation": 0.0}},
    }
    return make_file(folder, "brushed.gltf", [material], extra={"extensionsUsed": ["KHR_materials_anisotropy"]})


def test_a_gltf_anisotropy_is_dropped_onto_another_model_and_kept_in_a_gltf_copy(tmp_path, capsys):
    pytest.importorskip("colour", reason="the quality gate needs colour-science")
    src = _anisotropic_gltf(tmp_path / "in")
    assert read_asset(src).dropped == ["KHR_materials_anisotropy anisotropyStrength 0.6"]
    code = main(["remap", str(src), "--to", "mtlx:open_pbr_surface", "-o", str(tmp_path / "mtlx"), *FAST])
    assert code == 3 and "KHR_materials_anisotropy" in capsys.readouterr().err.strip().splitlines()[-1]
    copy = tmp_path / "copy"
    code = main(["remap", str(src), "--to", "gltf:metal-rough", "-o", str(copy), *FAST])
    assert code == 0, capsys.readouterr().err[-400:]
    written = json.loads((copy / "brushed.gltf").read_text())
    assert written["materials"][0]["extensions"]["KHR_materials_anisotropy"]["anisotropyStrength"] == 0.6


def test_a_metals_anisotropy_counts_whatever_its_dielectric_specular_weight(tmp_path):
    """Standard Surface's specular weight scales the dielectric's lobe alone; a metal's lobe (metalness 1) is drawn
    with the specular roughness and its anisotropy all the same (the MaterialX brushed-metal example sets specular 0
    on a metal: its anisotropy was not counted)."""
    doc = tmp_path / "brushed.mtlx"
    doc.write_text(
        '<?xml version="1.0"?>\n<materialx version="1.38">\n'
        '  <standard_surface name="SR_brushed" type="surfaceshader">\n'
        '    <input name="base_color" type="color3" value="0.6, 0.6, 0.6" />\n'
        '    <input name="metalness" type="float" value="1" />\n'
        '    <input name="specular" type="float" value="0" />\n'
        '    <input name="specular_roughness" type="float" value="0.3" />\n'
        '    <input name="specular_anisotropy" type="float" value="0.7" />\n'
        "  </standard_surface>\n"
        '  <surfacematerial name="Brushed" type="material">\n'
        '    <input name="surfaceshader" type="surfaceshader" nodename="SR_brushed" />\n'
        "  </surfacematerial>\n</materialx>\n"
    )
    assert read_asset(doc).dropped == ["specular_anisotropy=0.7"]
    dielectric = doc.read_text().replace(
        'name="metalness" type="float" value="1"', 'name="metalness" type="float" value="0"'
    )
    doc.write_text(dielectric)
    assert read_asset(doc).dropped == []  # a dielectric with its specular off: no lobe shows the anisotropy


def test_a_blend_principleds_subsurface_and_anisotropy_are_dropped_its_diffuse_roughness_noted():
    from matremap.formats.blend import dropped_sockets

    inputs = {"Subsurface Weight": 0.3, "Anisotropic": 0.5, "Roughness": 0.4, "Diffuse Roughness": 0.5}
    assert dropped_sockets(inputs) == ["Subsurface Weight=0.3", "Anisotropic=0.5"]
    assert dropped_sockets({**inputs, "Roughness": 0.0, "Subsurface Weight": 0.0}) == []  # a mirror shows none


@pytest.mark.parametrize(
    "ext, fallback, refused",
    [
        (
            {
                "KHR_materials_pbrSpecularGlossiness": {
                    "diffuseFactor": [0.8, 0.1, 0.1, 1],
                    "specularFactor": [0.04, 0.04, 0.04],
                    "glossinessFactor": 0.6,
                }
            },
            False,
            False,
        ),
        (
            {
                "KHR_materials_pbrSpecularGlossiness": {
                    "diffuseFactor": [0.8, 0.1, 0.1, 1],
                    "specularFactor": [0.04, 0.04, 0.04],
                    "glossinessFactor": 0.6,
                }
            },
            True,
            False,
        ),
        ({"KHR_materials_unlit": {}}, True, True),
    ],
    ids=["specgloss", "specgloss-with-fallback", "unlit"],
)
def test_another_workflows_material_is_refused_not_read_as_the_defaults(tmp_path, capsys, ext, fallback, refused):
    """A red specular-glossiness material (no metallic-roughness beside it) was read as glTF's defaults, a white
    rough metal, and went onto OpenPBR as a grey metal, PASSED, exit 0. Now converted to metallic-roughness by the
    extension's formulas (tests/test_spec_gloss.py checks the values), with or without a fallback beside it. An
    unlit material is refused: no lit model draws it."""
    material: dict = {"name": "red", "extensions": ext}
    if fallback:
        material["pbrMetallicRoughness"] = {"baseColorFactor": [0.8, 0.1, 0.1, 1], "metallicFactor": 0.0}
    src = make_file(tmp_path / "in", "m.gltf", [material], extra={"extensionsUsed": list(ext)})
    out = tmp_path / "out"
    code = main(["remap", str(src), "--to", "mtlx:open_pbr_surface", "-o", str(out), *FAST])
    last = capsys.readouterr().err.strip().splitlines()[-1]
    if refused:
        assert code == 2 and next(iter(ext)) in last and last.startswith("matremap: error:") and not out.exists()
    else:
        assert code == 0, last


def test_what_a_coat_does_to_the_base_and_a_glass_scatter_are_dropped_where_they_show(tmp_path):
    """Standard Surface 1.0.1's coat_affect_color / _roughness (the base saturated and roughened under a coat) and
    transmission_scatter / _extra_roughness (a glass's volume scattering and extra blur): none is modelled."""

    def dropped(inputs: str) -> list[str]:
        doc = tmp_path / "m.mtlx"
        doc.write_text(
            '<?xml version="1.0"?>\n<materialx version="1.38">\n'
            f'  <standard_surface name="SR" type="surfaceshader">\n{inputs}  </standard_surface>\n'
            '  <surfacematerial name="M" type="material">\n'
            '    <input name="surfaceshader" type="surfaceshader" nodename="SR" />\n'
            "  </surfacematerial>\n</materialx>\n"
        )
        return read_asset(doc).dropped

    def inp(name: str, value: str, typ: str = "float") -> str:
        return f'    <input name="{name}" type="{typ}" value="{value}" />\n'

    coat = inp("coat", "1") + inp("coat_affect_color", "0.6") + inp("coat_affect_roughness", "0.3")
    assert dropped(coat) == ["coat_affect_color=0.6", "coat_affect_roughness=0.3"]
    assert dropped(coat.replace('"coat" type="float" value="1"', '"coat" type="float" value="0.2"')) == []
    glass = inp("transmission", "1") + inp("transmission_scatter", "0.2, 0.1, 0.1", "color3")
    assert dropped(glass) == ["transmission_scatter=0.2, 0.1, 0.1"]
    assert dropped(inp("transmission_scatter", "0.2, 0.1, 0.1", "color3")) == []  # no transmission: nothing scatters
