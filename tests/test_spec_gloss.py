"""KHR_materials_pbrSpecularGlossiness converted to metallic-roughness (formats/gltf_extensions.spec_gloss_values,
gltf_read, gltf_write): factors and textures by the extension's README formulas, checked here against those formulas
computed independently (c_diff = diffuse (1 - max specular), F0 = specular, roughness = 1 - glossiness), and a glTF
written from it carrying the metallic-roughness material without the extension."""

from __future__ import annotations

import colorsys
import json

import numpy as np
import pytest
from test_formats_gltf import make_file, validate

from matremap.cli import main
from matremap.formats.gltf import read
from matremap.formats.gltf_write import texture_values

SG = "KHR_materials_pbrSpecularGlossiness"
FAST = ["--rotations", "0:360:2", "--size", "48", "--env-lights", "32"]
RED = {"diffuseFactor": [0.8, 0.1, 0.1, 1.0], "specularFactor": [0.05, 0.04, 0.03], "glossinessFactor": 0.6}


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def f0(values: dict) -> np.ndarray:
    """gltf:metal-rough's dielectric F0 (KHR_materials_ior and _specular): min(((ior-1)/(ior+1))^2 specularColor, 1)
    specular."""
    ior = float(np.reshape(values["ior"], -1)[0])
    base = ((ior - 1) / (ior + 1)) ** 2
    return np.minimum(base * np.asarray(values["specularColor"], dtype=float), 1.0) * float(
        np.reshape(values["specular"], -1)[0]
    )


def hue(rgb) -> float:
    return colorsys.rgb_to_hsv(*[float(x) for x in rgb])[0]


def test_uniform_spec_gloss_is_converted_by_the_readme_formulas(tmp_path):
    """Before: the extension was ignored and glTF's defaults read (a white rough metal)."""
    src = make_file(tmp_path, "m.gltf", [{"name": "red", "extensions": {SG: RED}}], extra={"extensionsUsed": [SG]})
    asset = read(src)
    assert asset.lost == [] and asset.model == "gltf:metal-rough"
    m = asset.material().values
    np.testing.assert_allclose(np.reshape(m["baseColor"], -1), RED["diffuseFactor"][:3], atol=1e-6)
    assert float(np.reshape(m["metallic"], -1)[0]) == 0.0
    assert float(np.reshape(m["roughness"], -1)[0]) == pytest.approx(1 - RED["glossinessFactor"])
    np.testing.assert_allclose(f0(m), RED["specularFactor"], atol=1e-6)  # F0 = specular
    assert any(SG in n and "converted" in n for n in asset.notes)


def test_spec_gloss_with_a_metal_rough_fallback_reads_the_extension(tmp_path):
    """The README: a client that supports the extension renders it, not the fallback beside it."""
    mat = {
        "name": "red",
        "pbrMetallicRoughness": {"baseColorFactor": [0.1, 0.1, 0.9, 1.0], "metallicFactor": 1.0},
        "extensions": {SG: RED},
    }
    m = read(make_file(tmp_path, "m.gltf", [mat])).material().values
    np.testing.assert_allclose(np.reshape(m["baseColor"], -1), RED["diffuseFactor"][:3], atol=1e-6)
    assert float(np.reshape(m["metallic"], -1)[0]) == 0.0


def gloss_images() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(3)
    diffuse = rng.integers(0, 256, size=(8, 8, 3), dtype=np.uint8)
    sg = rng.integers(0, 256, size=(8, 8, 4), dtype=np.uint8)
    sg[..., :3] //= 4  # specular colours a dielectric might have (< 0.25 before decoding)
    return {"diffuse": diffuse, "specgloss": sg}


def test_spec_gloss_textures_convert_per_texel(tmp_path):
    images = gloss_images()
    factors = {"diffuseFactor": [1.0, 0.5, 0.25, 1.0], "specularFactor": [1.0, 0.8, 0.6], "glossinessFactor": 0.9}
    ext = {**factors, "diffuseTexture": {"index": 0}, "specularGlossinessTexture": {"index": 1}}
    asset = read(make_file(tmp_path, "t.gltf", [{"name": "t", "extensions": {SG: ext}}], images))
    base = texture_values(asset.textures["baseColor"])
    want = srgb_to_linear(images["diffuse"] / 255.0) * factors["diffuseFactor"][:3]
    np.testing.assert_allclose(base, want, atol=2e-3)
    rough = texture_values(asset.textures["roughness"])[..., 0]
    np.testing.assert_allclose(rough, 1 - 0.9 * images["specgloss"][..., 3] / 255.0, atol=2e-3)
    spec = texture_values(asset.textures["specularColor"])
    specular = srgb_to_linear(images["specgloss"][..., :3] / 255.0) * factors["specularFactor"]
    values = {"ior": asset.constants["ior"], "specular": asset.constants["specular"], "specularColor": spec}
    np.testing.assert_allclose(f0(values), specular, atol=2e-3)
    assert "metallic" not in asset.textures and asset.constants["metallic"] == 0.0


@pytest.mark.parametrize("suffix", [".gltf", ".glb"])
def test_identity_onto_gltf_writes_the_metal_rough_conversion_without_the_extension(tmp_path, suffix):
    """Before: copied unchanged as an 'identity', a spec-gloss material the target read as a white metal; the
    extension was still required."""
    extra = {"extensionsUsed": [SG], "extensionsRequired": [SG]}
    src = make_file(tmp_path / "in", f"m{suffix}", [{"name": "red", "extensions": {SG: RED}}], extra=extra)
    out = tmp_path / "out"
    assert main(["remap", str(src), "--to", "gltf:metal-rough", "-o", str(out)]) == 0
    doc = validate(next(out.glob(f"*{suffix}")))
    mat = doc["materials"][0]
    assert SG not in mat.get("extensions", {})
    assert SG not in doc.get("extensionsUsed", []) and SG not in doc.get("extensionsRequired", [])
    pbr = mat["pbrMetallicRoughness"]
    rgb = pbr["baseColorFactor"][:3]
    assert hue(rgb) == pytest.approx(hue(RED["diffuseFactor"][:3]), abs=0.01)
    lum = np.dot([0.2126, 0.7152, 0.0722], rgb)
    assert lum == pytest.approx(np.dot([0.2126, 0.7152, 0.0722], RED["diffuseFactor"][:3]), rel=0.02)
    assert pbr["metallicFactor"] == 0.0 and pbr["roughnessFactor"] == pytest.approx(0.4, abs=1e-6)
    spec = mat["extensions"]["KHR_materials_specular"]
    values = {"ior": 1.5, "specular": spec.get("specularFactor", 1.0), "specularColor": spec["specularColorFactor"]}
    np.testing.assert_allclose(f0(values), RED["specularFactor"], atol=1e-5)
    assert json.loads(json.dumps(doc))


def test_a_second_spec_gloss_material_left_alone_keeps_the_extension_required(tmp_path):
    """extensionsRequired loses the extension only when no material uses it any more."""
    extra = {"extensionsUsed": [SG], "extensionsRequired": [SG]}
    mats = [{"name": "a", "extensions": {SG: RED}}, {"name": "b", "extensions": {SG: RED}}]
    src = make_file(tmp_path / "in", "m.gltf", mats, extra=extra)
    out = tmp_path / "out"
    assert main(["remap", str(src), "--to", "gltf:metal-rough", "--material", "a", "-o", str(out)]) == 0
    doc = validate(next(out.glob("*.gltf")))
    assert SG not in doc["materials"][0].get("extensions", {}) and SG in doc["materials"][1]["extensions"]
    assert SG in doc["extensionsRequired"]


def test_textured_spec_gloss_identity_onto_gltf_reads_back_the_same(tmp_path):
    images = gloss_images()
    ext = {"diffuseTexture": {"index": 0}, "specularGlossinessTexture": {"index": 1}, "glossinessFactor": 0.8}
    src = make_file(tmp_path / "in", "t.gltf", [{"name": "t", "extensions": {SG: ext}}], images)
    out = tmp_path / "out"
    assert main(["remap", str(src), "--to", "gltf:metal-rough", "-o", str(out)]) == 0
    written = next(out.glob("*.gltf"))
    validate(written)
    back, before = read(written), read(src)
    assert SG not in (back.document.json["materials"][0].get("extensions") or {})
    rough = texture_values(back.textures["roughness"])[..., 0]
    np.testing.assert_allclose(rough, 1 - 0.8 * images["specgloss"][..., 3] / 255.0, atol=3e-3)
    np.testing.assert_allclose(
        texture_values(back.textures["baseColor"]), texture_values(before.textures["baseColor"]), atol=3e-3
    )
    if "metallic" in back.textures:
        assert float(np.max(texture_values(back.textures["metallic"]))) == 0.0
    else:
        assert back.constants["metallic"] == 0.0


def test_spec_gloss_onto_openpbr_is_a_red_dielectric(tmp_path, capsys):
    """Before: refused (no fallback) or, read as the defaults, a grey metal."""
    src = make_file(tmp_path / "in", "m.gltf", [{"name": "red", "extensions": {SG: RED}}])
    out = tmp_path / "out"
    code = main(["remap", str(src), "--to", "mtlx:open_pbr_surface", "-o", str(out), *FAST])
    assert code == 0, capsys.readouterr().err
    text = next(out.glob("*.mtlx")).read_text()
    import re

    colour = re.search(r'name="base_color"[^>]*value="([^"]+)"', text)
    metal = re.search(r'name="base_metalness"[^>]*value="([^"]+)"', text)
    assert colour is not None
    rgb = [float(x) for x in colour.group(1).split(",")]
    assert hue(rgb) == pytest.approx(hue(RED["diffuseFactor"][:3]), abs=0.03)
    assert metal is None or float(metal.group(1)) < 0.05


def test_extensions_no_model_converts_are_named_in_one_note_with_their_values(tmp_path):
    """Before: one generic 'is not remapped' line each, saying nothing of what each draws or where it is lost."""
    ext = {
        "KHR_materials_iridescence": {"iridescenceFactor": 1.0},
        "KHR_materials_anisotropy": {"anisotropyStrength": 0.5},
        "KHR_materials_dispersion": {"dispersion": 0.3},
        "KHR_materials_diffuse_transmission": {"diffuseTransmissionFactor": 0.4},
    }
    asset = read(make_file(tmp_path, "m.gltf", [{"name": "x", "extensions": ext}]))
    named = [n for n in asset.notes if "not converted" in n]
    assert len(named) == 1
    for name, value in (
        ("KHR_materials_iridescence", "iridescenceFactor 1"),
        ("KHR_materials_anisotropy", "anisotropyStrength 0.5"),
        ("KHR_materials_dispersion", "dispersion 0.3"),
        ("KHR_materials_diffuse_transmission", "diffuseTransmissionFactor 0.4"),
    ):
        assert f"{name} (" in named[0] and value in named[0]
        assert not any(n.startswith(name) for n in asset.notes)  # not a second, generic line
    assert "other targets leave them out" in named[0]
    assert sorted(d.split()[0] for d in asset.dropped) == sorted(
        ["KHR_materials_anisotropy", "KHR_materials_iridescence", "KHR_materials_diffuse_transmission"]
    )


def test_textured_spec_gloss_onto_usd_keeps_its_roughness_and_colour_per_texel(tmp_path, capsys):
    """A grey specular (as most spec-gloss textures hold) over a coloured diffuse, converted per texel and swept
    onto UsdPreviewSurface: the written maps, read back, have the source's glossiness as roughness and its diffuse
    hue."""
    pytest.importorskip("pxr")
    from matremap.formats import usd

    images = gloss_images()
    sg = images["specgloss"]
    sg[..., 1] = sg[..., 0]
    sg[..., 2] = sg[..., 0]
    images = {k: np.repeat(np.repeat(v, 4, 0), 4, 1) for k, v in images.items()}
    ext = {"diffuseTexture": {"index": 0}, "specularGlossinessTexture": {"index": 1}, "glossinessFactor": 0.8}
    src = make_file(tmp_path / "in", "t.gltf", [{"name": "t", "extensions": {SG: ext}}], images)
    out = tmp_path / "out"
    code = main(["remap", str(src), "--to", "usd:preview_surface", "-o", str(out), *FAST])
    assert code == 0, capsys.readouterr().err
    back = usd.read(next(out.glob("*.usda")))
    rough = texture_values(back.textures["roughness"])[..., 0]
    want = 1 - 0.8 * images["specgloss"][..., 3] / 255.0
    assert float(np.mean(np.abs(rough - want))) < 0.05
    colour = texture_values(back.textures["diffuseColor"])
    diffuse = srgb_to_linear(images["diffuse"] / 255.0)
    bright = diffuse.max(axis=-1) > 0.2
    hues = np.array([[hue(c), hue(d)] for c, d in zip(colour[bright], diffuse[bright], strict=True)])
    shift = np.abs(hues[:, 0] - hues[:, 1])
    assert float(np.median(np.minimum(shift, 1 - shift))) < 0.03
    if "metallic" in back.textures:
        assert float(np.max(texture_values(back.textures["metallic"]))) < 0.05
    else:
        assert float(np.reshape(back.constants.get("metallic", 0.0), -1)[0]) < 0.05


GOLD = {"diffuseFactor": [0.0, 0.0, 0.0, 1.0], "specularFactor": [1.0, 0.766, 0.336], "glossinessFactor": 0.9}
WHITE_SPECULAR = {"diffuseFactor": [0.8, 0.1, 0.1, 1.0], "glossinessFactor": 0.6}  # specular 1 by default


@pytest.mark.parametrize("sg", [RED, GOLD, WHITE_SPECULAR], ids=["dielectric", "readme-gold", "default-specular"])
def test_the_converted_brdf_inputs_are_the_readmes(tmp_path, sg):
    """c_diff = diffuse (1 - max specular), F0 = specular (the README), from gltf:metal-rough's values: a metal's
    F0 is its baseColor and its c_diff 0; a dielectric's F0 is :func:`f0` and its c_diff baseColor (1 - max F0).
    Before, the gold example read as a white rough metal (glTF's defaults)."""
    m = read(make_file(tmp_path, "m.gltf", [{"name": "x", "extensions": {SG: sg}}])).material().values
    diffuse = np.array(sg["diffuseFactor"][:3])
    specular = np.array(sg.get("specularFactor", [1.0] * 3))
    base = np.reshape(m["baseColor"], -1)
    if float(np.reshape(m["metallic"], -1)[0]) == 1.0:
        got_f0, got_cdiff = base, np.zeros(3)
    else:
        got_f0 = f0(m)
        got_cdiff = base * (1 - got_f0.max())
    np.testing.assert_allclose(got_f0, specular, atol=1e-6)
    np.testing.assert_allclose(got_cdiff, diffuse * (1 - specular.max()), atol=1e-6)
    assert float(np.reshape(m["roughness"], -1)[0]) == pytest.approx(1 - sg["glossinessFactor"])


def test_a_spec_gloss_whose_light_all_goes_to_specular_is_a_metal_on_openpbr(tmp_path, capsys):
    """The default specular (1) leaves nothing to the diffuse: a white mirror-like metal at roughness 0.4. Read as a
    dielectric of specularColor 25 it failed the gate onto OpenPBR (fit_error 0.42, exit 3)."""
    src = make_file(tmp_path / "in", "m.gltf", [{"name": "w", "extensions": {SG: WHITE_SPECULAR}}])
    out = tmp_path / "out"
    code = main(["remap", str(src), "--to", "mtlx:open_pbr_surface", "-o", str(out), *FAST])
    assert code == 0, capsys.readouterr().err
    text = next(out.glob("*.mtlx")).read_text()
    import re

    metal = re.search(r'name="base_metalness"[^>]*value="([^"]+)"', text)
    colour = re.search(r'name="base_color"[^>]*value="([^"]+)"', text)
    assert metal is not None and float(metal.group(1)) > 0.95
    assert colour is not None and min(float(x) for x in colour.group(1).split(",")) > 0.9
