"""A material that lets light through over a roughness map (issue 16): converted at levels of its roughness, each
one uniform fit on the transmission probe, interpolated per texel by a cubic spline, the midpoints measured and
refined (svbrdf/levels.py). Before, every such material was refused ("carries its look in
KHR_materials_transmission"): Khronos' TransmissionRoughnessTest, five glasses whose roughness is a grid texture."""

from __future__ import annotations

import json
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from matremap.cli import main
from matremap.core.imageio import write_image
from matremap.errors import MatremapError
from matremap.formats import read_asset
from matremap.svbrdf import levels
from matremap.svbrdf.mapstats import summarise
from matremap.svbrdf.mixed import Grid, Levels, through_levels
from matremap.svbrdf.textures import MapSet, load_map_set, read_image

sys.path.insert(0, str(Path(__file__).parent))
import corpus_checks as cc  # noqa: E402

CORPUS = Path(__file__).resolve().parent / "data" / "corpus"
TRT = CORPUS / "gltf-TransmissionRoughnessTest" / "TransmissionRoughnessTest.glb"


def test_four_levels_or_more_interpolate_by_a_cubic_spline_exact_for_a_square():
    """glTF roughness onto Mitsuba's alpha is its square: hat weights between five even levels were 11 % off at
    roughness 0.375; the spline's weights reproduce any cubic, sum to 1, and stay hats below four levels."""
    x = np.linspace(0.0, 1.0, 101, dtype=np.float32)
    five = Levels("roughness", (0.0, 0.25, 0.5, 0.75, 1.0), None)
    ws = five.weights(x)
    np.testing.assert_allclose(sum(ws), 1.0, atol=1e-5)
    np.testing.assert_allclose(sum(w * v**2 for w, v in zip(ws, five.levels, strict=True)), x**2, atol=1e-5)
    np.testing.assert_allclose(sum(w * v**3 for w, v in zip(ws, five.levels, strict=True)), x**3, atol=1e-5)
    three = Levels("roughness", (0.0, 0.5, 1.0), None).weights(x)
    assert min(float(w.min()) for w in three) >= 0.0  # hats: never negative
    np.testing.assert_allclose(three[1][25], 0.5)  # linear halfway between 0 and 0.5


def test_refinement_adds_a_level_at_each_midpoint_off_the_interpolation(monkeypatch):
    """Midpoints further off than REFINE (and OVER_FITS times their levels' errors) become levels, worst first,
    until none is: here the interpolation is off wherever two levels are more than 0.2 apart."""

    class Fit:
        loss = 0.01

    fitted: list[float] = []

    def fit_at(v: float):
        fitted.append(v)
        return None, Fit()

    monkeypatch.setattr(levels, "midpoint", lambda lv, a, b, f: 0.3 if b - a > 0.2 else 0.01)
    out, errors = levels.refine(Levels("roughness", (0.0, 0.5, 1.0), None), fit_at, lambda m: None)
    assert out.levels == (0.0, 0.125, 0.25, 0.375, 0.5, 0.625, 0.75, 0.875, 1.0)
    assert set(errors) == set(zip(out.levels, out.levels[1:], strict=False)) and max(errors.values()) == 0.01
    monkeypatch.setattr(levels, "midpoint", lambda lv, a, b, f: 0.3)  # never good enough: stops at MAX_LEVELS
    out, _ = levels.refine(Levels("roughness", (0.0, 1.0), None), fit_at, lambda m: None)
    assert len(out.levels) == levels.MAX_LEVELS


def _trt_map_set(tmp_path: Path, material: str = "Mat_IOR_1.33") -> MapSet:
    asset = read_asset(TRT, material)
    return load_map_set(asset.to_map_set(tmp_path / "source"))


def test_a_glass_over_a_roughness_map_is_levels_of_its_roughness_its_uniform_maps_held(tmp_path):
    ms = _trt_map_set(tmp_path)
    assert ms.model == "gltf:pbr" and ms.constants["transmission"] == 1.0
    through = through_levels(ms, summarise(ms))
    assert through is not None and through.name == "roughness" and through.layer is None
    assert through.levels == (0.0, 0.25, 0.5, 0.75, 1.0)  # the grid's range, five levels
    assert through.held == {"metallic": 0.0}  # the packed texture's metallic channel: uniform, held


def test_a_glass_with_another_number_varying_is_refused_in_one_line(tmp_path):
    """The roughness and one colour are converted under transmission; a map of another number (a specular
    strength) is refused before any fit, naming it."""
    ms = _trt_map_set(tmp_path)
    y, x = np.mgrid[0:64, 0:64] / 63.0  # the grid texture's size
    write_image(ms.root / "strength.exr", (0.2 + 0.8 * x)[..., None].astype(np.float32))
    doc = json.loads((ms.root / "material.json").read_text())
    doc["maps"]["specular"] = "strength.exr"
    doc["params"].pop("specular", None)
    (ms.root / "material.json").write_text(json.dumps(doc))
    varied = load_map_set(ms.root)
    with pytest.raises(MatremapError, match=r"lets light through, and its roughness, specular maps vary"):
        through_levels(varied, summarise(varied))


def test_a_grid_takes_numbers_from_the_roughness_levels_and_colours_from_the_tints():
    rough = Levels("roughness", (0.0, 0.25, 0.5, 0.75, 1.0), None)
    tint = Levels("baseColor", (0.2, 0.4, 0.6, 0.8, 1.0), None, per_channel=True, typical=(0.5, 0.5, 0.5))
    grid = Grid(rough, tint)
    r = np.array([[0.1, 0.6]], dtype=np.float32)
    c = np.array([[[0.3, 0.5, 0.9], [1.0, 0.25, 0.7]]], dtype=np.float32)
    scalar, colour = grid.band_weights({"roughness": r, "baseColor": c})
    assert len(scalar) == len(colour) == 10 and colour is not None
    np.testing.assert_allclose(sum(scalar), 1.0, atol=1e-5)
    np.testing.assert_allclose(sum(colour), 1.0, atol=1e-5)
    assert all(np.all(w == 0) for w in scalar[5:]) and all(np.all(w == 0) for w in colour[:5])
    np.testing.assert_allclose(sum(w * v for w, v in zip(scalar[:5], rough.levels, strict=True)), r, atol=1e-5)
    np.testing.assert_allclose(sum(w * v for w, v in zip(colour[5:], tint.levels, strict=True)), c, atol=1e-5)
    # a roughness level holds the median colour, a grey level the median roughness
    assert grid.params("roughness=0.25") == {"roughness": 0.25, "baseColor": [0.5, 0.5, 0.5]}


@pytest.mark.slow
def test_transmission_roughness_test_onto_roughdielectric_writes_alpha_as_the_square_of_the_grid(tmp_path, capsys):
    """Before: refused. Now: five levels fitted on the transmission probe, int_ior held (Mitsuba takes it as a
    constant only); the written alpha map is the glTF roughness texture squared (the KHR spec's alpha = roughness^2,
    Mitsuba's GGX alpha), read from the .glb independently of matremap, and the gate's fit_error names the
    transmission probe."""
    out = tmp_path / "out"
    code = main(
        ["remap", str(TRT), "--material", "Mat_IOR_1.33", "--to", "mitsuba3:roughdielectric", "-o", str(out)]
        + ["--no-evaluate"]
    )
    err = capsys.readouterr().err
    assert code == 0, err[-600:]
    assert "Traceback" not in err and "levels: int_ior 1.33" in err
    verdict = json.loads((out / "verdict.json").read_text())
    fit = next(c for c in verdict["checks"] if c["name"] == "fit_error")
    assert "transmission view" in fit["where"] and fit["value"] < 0.1
    assert {c["name"] for c in verdict["checks"]} >= {"luminance_error", "delta_e"}  # colour and energy too
    xml = ET.parse(out / "TransmissionRoughnessTest.xml").getroot()
    bsdf = next(b for b in xml.iter("bsdf") if b.get("type") == "roughdielectric")
    ior = next(f for f in bsdf.iter("float") if f.get("name") == "int_ior")
    assert float(ior.get("value")) == pytest.approx(1.33, abs=2e-3)
    alpha_file = next(t for t in bsdf.iter("texture") if t.get("name") == "alpha").find("string").get("value")
    alpha = np.atleast_3d(read_image(out / alpha_file, "linear")[0])[..., 0]
    doc, binary = cc.gltf_load(TRT)
    m = doc["materials"][cc.gltf_material_index(doc, "Mat_IOR_1.33")]
    src = doc["textures"][m["pbrMetallicRoughness"]["metallicRoughnessTexture"]["index"]]["source"]
    rough = cc._image_from_bytes(cc.gltf_image_bytes(TRT, doc, binary, src), srgb=False)[..., 1]
    assert alpha.shape == rough.shape
    # where the spheres show the texture (43 %: the rest is filled from the nearest texel they show, formats/
    # gltf_coverage.py), the written alpha is the roughness squared
    shown = read_asset(TRT, "Mat_IOR_1.33").coverage.mask(rough.shape)
    assert 0.3 < shown.mean() < 0.6
    assert np.corrcoef(alpha[shown], rough[shown] ** 2)[0, 1] > 0.999
    assert float(np.max(np.abs(alpha[shown] - rough[shown] ** 2))) < 0.03
    try:
        import mitsuba  # noqa: F401
    except ImportError:
        return  # the file's values are checked above; Mitsuba itself is optional
    ok, why = cc.mitsuba_loads(out / "TransmissionRoughnessTest.xml")
    assert ok, why


def test_a_volume_with_a_thickness_texture_is_converted_and_a_gltf_copy_keeps_the_texture(tmp_path, capsys):
    """AttenuationTest's R3_ThicknessTex_Mat (a blue volume whose thickness is a texture, which path tracers ignore:
    KHR_materials_volume, "Thickness Texture") was refused. Onto gltf:pbr (the identity: copied) the written volume
    keeps its thicknessTexture, read back by pygltflib."""
    pygltflib = pytest.importorskip("pygltflib")
    att = CORPUS / "gltf-AttenuationTest" / "AttenuationTest.glb"
    out = tmp_path / "out"
    code = main(["remap", str(att), "--material", "R3_ThicknessTex_Mat", "--to", "gltf:pbr", "-o", str(out)])
    assert code == 0, capsys.readouterr().err[-400:]
    g = pygltflib.GLTF2().load(str(out / "AttenuationTest.glb"))
    m = next(m for m in g.materials if m.name == "R3_ThicknessTex_Mat")
    volume = m.extensions["KHR_materials_volume"]
    assert volume["thicknessFactor"] == 2.0 and volume["thicknessTexture"] == {"index": 1}
    assert volume["attenuationColor"] == pytest.approx([0.1, 0.5, 0.9])


@pytest.mark.slow
def test_onto_a_model_without_transmission_the_glass_fails_the_gate_and_its_ior_stays_one_number(tmp_path, capsys):
    """glTF's ior has no texture: each level's fit set it apart, and the written glTF was refused after every fit
    (exit 2, "a map of ior cannot be written"). Held at the median's fit, the file is written and the gate fails
    what an opaque model cannot draw (exit 3)."""
    out = tmp_path / "out"
    code = main(
        ["remap", str(TRT), "--material", "Mat_IOR_1.50", "--to", "gltf:metal-rough", "-o", str(out), "--no-evaluate"]
    )
    err = capsys.readouterr().err
    assert code == 3, err[-600:]
    assert "levels: ior" in err and "Traceback" not in err
    assert (out / "TransmissionRoughnessTest.glb").is_file()
    assert not (out / "maps" / "material_ior.exr").exists()


def test_a_colours_levels_interpolate_each_channel_at_its_own_value():
    """A glass's tint: grey levels, the target's colours weighted channel by channel (RGB renderers draw each
    channel on its own), its numbers at the channel mean."""
    lv = Levels("baseColor", (0.2, 0.4, 0.6, 0.8, 1.0), None, per_channel=True, typical=(0.5, 0.5, 0.5))
    rgb = np.array([[0.25, 0.5, 0.9], [1.0, 0.2, 0.6]], dtype=np.float32)
    ws = lv.weights(rgb)
    assert ws[0].shape == rgb.shape
    np.testing.assert_allclose(sum(w * v**0.5 for w, v in zip(ws, lv.levels, strict=True)), rgb**0.5, atol=2e-3)
    mean = lv.scalar_weights(rgb)
    assert mean[0].shape == rgb.shape[:1]
    np.testing.assert_allclose(sum(w * v for w, v in zip(mean, lv.levels, strict=True)), rgb.mean(axis=-1), atol=1e-5)


def _tinted_glass(tmp_path: Path, keep_roughness: bool = False) -> Path:
    """TransmissionRoughnessTest's Mat_IOR_1.33 with a tint map (three ramps), its roughness one number (or its
    grid texture, ``keep_roughness``)."""
    ms = _trt_map_set(tmp_path)
    y, x = np.mgrid[0:64, 0:64] / 63.0
    tint = np.stack([0.2 + 0.8 * x, 0.9 - 0.6 * y, 0.3 + 0.5 * x * y], -1).astype(np.float32)
    write_image(ms.root / "tint.exr", tint)
    doc = json.loads((ms.root / "material.json").read_text())
    doc["maps"]["baseColor"] = "tint.exr"
    doc["colorspace"]["baseColor"] = "linear"
    doc["params"].pop("baseColor", None)
    if not keep_roughness:
        doc["maps"].pop("roughness")
        doc["params"]["roughness"] = 0.3
    (ms.root / "material.json").write_text(json.dumps(doc))
    return ms.root


@pytest.mark.slow
def test_a_tinted_glass_onto_roughdielectric_writes_the_square_root_of_its_tint(tmp_path):
    """Mitsuba's roughdielectric applies specular_transmittance at every refraction, glTF's base colour tints once
    where light enters: through a solid (two refractions) the transmittance is the tint's square root, channel by
    channel. Five grey levels, the texels interpolated per channel: the written map follows tint^0.5 (a power fitted
    on the files), and the target's numbers are one value each (held at the median's fit)."""
    from matremap.remap import remap

    root = _tinted_glass(tmp_path)
    res = remap(root, None, "mitsuba3:roughdielectric", tmp_path / "out", log=lambda m: None, evaluate=False)
    assert res.verdict.passed, res.verdict
    out = load_map_set(tmp_path / "out" / "maps")
    assert set(out.maps) == {"specular_transmittance"}  # alpha, int_ior: one number each
    assert out.constants["alpha"] == pytest.approx(0.09, abs=0.01)  # glTF roughness 0.3, squared
    t = np.atleast_3d(read_image(out.maps["specular_transmittance"], "linear")[0])[..., :3]
    s = np.atleast_3d(read_image(root / "tint.exr", "linear")[0])[..., :3]
    for c in range(3):
        power, _ = np.polyfit(np.log(s[..., c].ravel()), np.log(t[..., c].ravel()), 1)
        assert power == pytest.approx(0.5, abs=0.02)
        assert np.corrcoef(s[..., c].ravel() ** 0.5, t[..., c].ravel())[0, 1] > 0.995


@pytest.mark.slow
def test_a_glass_whose_roughness_and_tint_both_vary_is_a_grid_of_levels(tmp_path):
    """TransmissionRoughnessTest's roughness grid under a three-ramp tint onto roughdielectric: five roughness levels
    at the median tint and five grey levels at the median roughness; the written alpha is the roughness squared and
    the transmittance the tint's square root, each read from the files; the gate checked the corners."""
    from matremap.remap import remap

    root = _tinted_glass(tmp_path, keep_roughness=True)
    logs: list[str] = []
    res = remap(root, None, "mitsuba3:roughdielectric", tmp_path / "out", log=logs.append, evaluate=False)
    assert res.verdict.passed, res.verdict
    assert any("roughness from 0 to 1, 5 levels, and baseColor (channel by channel)" in m for m in logs)
    assert any("held at the fit at the typical texel" in m and "for the colour's levels" in m for m in logs)
    out = load_map_set(tmp_path / "out" / "maps")
    alpha = np.atleast_3d(read_image(out.maps["alpha"], "linear")[0])[..., 0]
    rough = np.atleast_3d(read_image(load_map_set(root).maps["roughness"], "linear")[0])[..., 0]
    assert float(np.max(np.abs(alpha - rough**2))) < 0.03
    t = np.atleast_3d(read_image(out.maps["specular_transmittance"], "linear")[0])[..., :3]
    s = np.atleast_3d(read_image(root / "tint.exr", "linear")[0])[..., :3]
    assert float(np.max(np.abs(t - s**0.5))) < 0.03
