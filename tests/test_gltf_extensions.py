"""glTF material extensions and carried inputs (matremap.formats.gltf_extensions, gltf_read, gltf_write):
read and validated, reported per material, kept by a glTF written over its source, written from other
formats' assets. Public files from tests/data/corpus (Khronos sample assets; licences in its README) where
they exercise the feature, built files for the malformed cases."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from test_formats_gltf import make_file, png_bytes, ramp, validate

from matremap.core.material import Material
from matremap.errors import MatremapError
from matremap.formats import CarriedInput, MaterialAsset, TextureRef, read_asset, write_asset
from matremap.formats.gltf import read, write

CORPUS = Path(__file__).resolve().parent / "data" / "corpus"
MR = "gltf:metal-rough"


# ------------------------------------------------------------------------------------------------
# reading


def test_every_listed_extension_is_read_with_its_defaults(tmp_path):
    mat = {
        "name": "all",
        "emissiveFactor": [0.2, 0.4, 0.6],
        "extensions": {
            "KHR_materials_emissive_strength": {"emissiveStrength": 5},
            "KHR_materials_clearcoat": {"clearcoatFactor": 0.5},
            "KHR_materials_sheen": {"sheenColorFactor": [0.1, 0.1, 0.1]},
            "KHR_materials_transmission": {"transmissionFactor": 0.2},
            "KHR_materials_volume": {"thicknessFactor": 0.3},
            "KHR_materials_specular": {"specularFactor": 0.5},
            "KHR_materials_ior": {"ior": 1.33},
        },
    }
    asset = read(make_file(tmp_path, "a.gltf", [mat]))
    ext = asset.document.extensions
    assert ext["KHR_materials_clearcoat"] == {"clearcoatFactor": 0.5, "clearcoatRoughnessFactor": 0.0}
    assert ext["KHR_materials_sheen"] == {"sheenColorFactor": [0.1] * 3, "sheenRoughnessFactor": 0.0}
    assert ext["KHR_materials_volume"]["attenuationDistance"] == np.inf
    assert ext["KHR_materials_volume"]["attenuationColor"] == [1.0, 1.0, 1.0]
    m = asset.material()
    assert m.values["ior"][0] == pytest.approx(1.33) and m.values["specular"][0] == 0.5
    np.testing.assert_allclose(asset.carried["emission"].value, [1.0, 2.0, 3.0])  # factor x strength
    # a transmission, even of 0.2, carries part of the look: the material is read into gltf:pbr with every
    # untextured layer (fitted on the transmission probe), not lost
    assert asset.lost == [] and asset.model == "gltf:pbr"
    notes = " | ".join(asset.notes)
    for word in (
        "read into gltf:pbr (transmission 0.2, thickness 0.3",
        "clearcoat 0.5, clearcoatRoughness 0",
        "sheenColor [0.1, 0.1, 0.1]",
        "KHR_materials_emissive_strength 5",
    ):
        assert word in notes, word


@pytest.mark.parametrize(
    "ext, match",
    [
        ({"KHR_materials_clearcoat": {"clearcoatFactor": 2}}, "KHR_materials_clearcoat.clearcoatFactor must be a"),
        ({"KHR_materials_sheen": {"sheenColorFactor": [1, 1]}}, r"sheenColorFactor must be 3 numbers in \[0, 1\]"),
        ({"KHR_materials_volume": {"attenuationDistance": 0}}, "attenuationDistance must be a number > 0"),
        ({"KHR_materials_volume": {"thicknessFactor": -1}}, "thicknessFactor must be a number >= 0"),
        ({"KHR_materials_transmission": {"transmissionFactor": None}}, "transmissionFactor must be"),
        ({"KHR_materials_emissive_strength": {"emissiveStrength": -2}}, "emissiveStrength must be a number >= 0"),
        ({"KHR_materials_ior": {"ior": 0.5}}, r"ior must be a number >= 1 \(or 0\)"),
        ({"KHR_materials_specular": {"specularColorFactor": [1, -1, 1]}}, "specularColorFactor must be 3 numbers"),
        ({"KHR_materials_clearcoat": {"clearcoatTexture": {"index": 7}}}, r"refers to textures\[7\]"),
        ({"KHR_materials_sheen": {"sheenColorTexture": {"index": 0, "texCoord": 1.5}}}, "texCoord must be"),
        ({"KHR_materials_clearcoat": [1]}, "KHR_materials_clearcoat is not an object"),
    ],
)
def test_malformed_extension_values_are_refused_naming_the_material_and_field(tmp_path, ext, match):
    f = make_file(tmp_path, "a.glb", [{"name": "bad", "extensions": ext}], {"t": ramp()}, store="bufferView")
    with pytest.raises(MatremapError, match=match) as e:
        read(f)
    assert "material 'bad'" in str(e.value) and "\n" not in str(e.value)


def test_a_textured_transmission_is_read_as_a_weight_map(tmp_path):
    """A uniform transmission is read into gltf:pbr and fitted on the transmission probe (test_transmission_fit.py); a
    textured one was lost (refused for other models): its texture's R times the factor is now gltf:pbr's
    ``transmission`` map, blended per texel between the material letting light through and opaque
    (test_transmission_maps.py)."""
    ext = {"KHR_materials_transmission": {"transmissionFactor": 0.2, "transmissionTexture": {"index": 0}}}
    asset = read(make_file(tmp_path, "a.gltf", [{"extensions": ext}], {"t": ramp()}))
    assert asset.lost == [] and asset.model == "gltf:pbr"
    ref = asset.textures["transmission"]
    assert ref.channels == (0,) and ref.scale == pytest.approx(0.2)
    assert asset.constants["transmission"] == pytest.approx(0.2)


@pytest.mark.parametrize(
    "ext, layers",
    [
        (
            {"KHR_materials_sheen": {"sheenColorFactor": [0.9, 0.2, 0.2], "sheenRoughnessFactor": 0.4}},
            {"sheenColor": [0.9, 0.2, 0.2], "sheenRoughness": 0.4},
        ),
        (
            {"KHR_materials_clearcoat": {"clearcoatFactor": 0.8, "clearcoatRoughnessFactor": 0.1}},
            {"clearcoat": 0.8, "clearcoatRoughness": 0.1},
        ),
    ],
)
def test_a_uniform_coat_or_coloured_sheen_is_read_into_gltf_pbr_and_fitted(tmp_path, ext, layers):
    """Such a layer carries the look: it is read into gltf:pbr's parameters (fitted), not left out."""
    asset = read(make_file(tmp_path, "a.gltf", [{"extensions": ext}], {"t": ramp()}))
    assert asset.model == "gltf:pbr" and asset.lost == []
    for k, v in layers.items():
        np.testing.assert_allclose(asset.constants[k], v, rtol=1e-6)
    assert any("read into gltf:pbr" in n for n in asset.notes)
    m = asset.material()
    assert m.model == "gltf:pbr"
    np.testing.assert_allclose(
        m.values[next(iter(layers))], np.broadcast_to(next(iter(layers.values())), m.values[next(iter(layers))].shape)
    )


def test_a_faint_coat_stays_a_note_on_the_metal_rough_base(tmp_path):
    ext = {"KHR_materials_clearcoat": {"clearcoatFactor": 0.3}}
    asset = read(make_file(tmp_path, "a.gltf", [{"extensions": ext}], {"t": ramp()}))
    assert asset.model == "gltf:metal-rough" and any(
        n.startswith("KHR_materials_clearcoat factor 0.3") for n in asset.notes
    )


def test_corpus_emissive_strength_is_multiplied_into_the_carried_emission():
    """EmissiveStrengthTest (CC-BY 4.0): emissiveFactor [0.1, 0.5, 0.9] at strengths 1 to 16."""
    f = CORPUS / "gltf-EmissiveStrengthTest" / "EmissiveStrengthTest.glb"
    for name, strength in (("Emit1", 1), ("Emit4", 4), ("Emit16", 16)):
        e = read(f, name).carried["emission"]
        np.testing.assert_allclose(e.value, np.array([0.1, 0.5, 0.9]) * strength, rtol=1e-6)
        assert e.settings["strength"] == strength
    assert "emission" not in read(f, "FlatBackdrop").carried


def test_corpus_alpha_mask_carries_the_texture_alpha_and_cutoff():
    """TextureLinearInterpolationTest (CC0): material 2 is alphaMode MASK over an RGBA texture."""
    asset = read(CORPUS / "gltf-TextureLinearInterpolationTest" / "TextureLinearInterpolationTest.glb", 2)
    op = asset.carried["opacity"]
    assert op.settings == {"mode": "mask", "cutoff": 0.5} and op.value == 1.0
    assert op.texture is not None and op.texture.channels == (1,)  # a grey + alpha PNG: alpha is channel 1
    from matremap.formats.gltf_write import texture_values

    alpha = texture_values(op.texture)
    assert alpha.min() < 0.5 < alpha.max()  # the mask cuts somewhere
    assert "emission" in asset.carried and asset.carried["emission"].texture is not None


def test_corpus_attenuation_and_clearcoat_are_read_into_gltf_pbr():
    a = read(CORPUS / "gltf-AttenuationTest" / "AttenuationTest.glb", 0)
    assert a.lost == [] and a.model == "gltf:pbr"
    assert any(
        n.startswith("read into gltf:pbr (transmission 1, thickness 1, attenuationColor [0.1, 0.5, 0.9]")
        for n in a.notes
    )
    textured = read(CORPUS / "gltf-AttenuationTest" / "AttenuationTest.glb", "R3_ThicknessTex_Mat")
    assert textured.lost == [] and textured.model == "gltf:pbr"  # a thickness texture is a rasteriser's hint
    assert any(n.startswith("KHR_materials_volume.thicknessTexture") for n in textured.notes)
    c = read(CORPUS / "gltf-ClearCoatTest" / "ClearCoatTest.glb", "Simple_Coated")  # a coat of factor 1: fitted
    assert c.lost == [] and c.model == "gltf:pbr" and c.constants["clearcoat"] == 1.0
    assert any(n.startswith("read into gltf:pbr (clearcoat 1") for n in c.notes)


# ------------------------------------------------------------------------------------------------
# writing: kept on glTF -> glTF, written from other formats


def test_a_gltf_copy_keeps_layers_emission_occlusion_and_alpha(tmp_path):
    rgba = ramp(seed=3, channels=4)
    mat = {
        "name": "m",
        "alphaMode": "MASK",
        "alphaCutoff": 0.3,
        "emissiveFactor": [0.5, 0.25, 0.0],
        "emissiveTexture": {"index": 0},
        "occlusionTexture": {"index": 0, "strength": 0.7},
        "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}, "baseColorFactor": [1, 1, 1, 0.8]},
        "extensions": {
            "KHR_materials_clearcoat": {"clearcoatFactor": 1.0, "clearcoatRoughnessFactor": 0.1},
            "KHR_materials_emissive_strength": {"emissiveStrength": 3.0},
            "KHR_materials_volume": {"thicknessFactor": 0.5},
        },
    }
    src = make_file(tmp_path / "src", "s.glb", [mat], {"t": rgba}, store="bufferView")
    asset = read(src)
    ms_dir = asset.to_map_set(tmp_path / "ms")
    from matremap.svbrdf.textures import load_map_set

    (tmp_path / "out").mkdir()
    out = write_asset(tmp_path / "out" / "o.glb", load_map_set(ms_dir), source=asset)
    doc = validate(out)
    m = doc["materials"][0]
    for key in ("alphaMode", "alphaCutoff", "emissiveFactor", "emissiveTexture", "occlusionTexture"):
        assert m[key] == mat[key], key
    for name, value in mat["extensions"].items():
        assert m["extensions"][name] == value
    assert m["pbrMetallicRoughness"]["baseColorFactor"][3] == 0.8
    back = read(out)
    # the new base colour texture carries the source's alpha, texel for texel
    from test_gltf_transforms import image_codes

    new_alpha = image_codes(back.carried["opacity"].texture.path)[..., 3]
    np.testing.assert_array_equal(np.round(new_alpha * 255), rgba[..., 3])
    assert back.carried["emission"].value == asset.carried["emission"].value
    assert back.document.extensions == asset.document.extensions


def mtlx_like_asset(tmp_path: Path) -> MaterialAsset:
    """An asset as a MaterialX / USD reader would give it: emission above 1 with a texture, opacity."""
    tex = tmp_path / "emit.png"
    tex.write_bytes(png_bytes(tmp_path, np.full((4, 4, 3), [255, 128, 0], np.uint8)))
    alpha = tmp_path / "alpha.png"
    alpha.write_bytes(png_bytes(tmp_path, np.tile(np.array([0, 85, 170, 255], np.uint8)[None, :, None], (4, 1, 1))))
    return MaterialAsset(
        path=tmp_path / "x.mtlx",
        format="mtlx",
        name="lamp",
        model=MR,
        constants={"baseColor": [0.5, 0.5, 0.5], "metallic": 0.0, "roughness": 0.4},
        carried={
            "emission": CarriedInput((4.0, 2.0, 1.0), TextureRef(tex, None, "srgb")),
            "opacity": CarriedInput(0.9, TextureRef(alpha, (0,), "linear"), {"mode": "blend"}),
            "occlusion": CarriedInput(0.5, TextureRef(alpha, (0,), "linear")),
        },
    )


@pytest.mark.parametrize("suffix", [".gltf", ".glb"])
def test_carried_inputs_of_another_format_are_written_and_read_back(tmp_path, suffix):
    source = mtlx_like_asset(tmp_path)
    m = Material.create(MR, {"baseColor": [0.5, 0.5, 0.5], "metallic": 0.0, "roughness": 0.4})
    out = write(tmp_path / f"o{suffix}", m, source=source)
    doc = validate(out)
    mat = doc["materials"][0]
    assert mat["name"] == "lamp" and mat["alphaMode"] == "BLEND"
    assert mat["pbrMetallicRoughness"]["baseColorFactor"] == pytest.approx([0.5, 0.5, 0.5, 0.9])
    assert mat["extensions"]["KHR_materials_emissive_strength"]["emissiveStrength"] == pytest.approx(4.0)
    assert "KHR_materials_emissive_strength" in doc["extensionsUsed"]
    back = read(out)
    e = back.carried["emission"]
    # radiance = factor x strength x texture: the texture's linear (1, 0.216, 0) times (4, 2, 1)
    assert e.texture is not None
    from matremap.formats.gltf_write import texture_values

    radiance = np.asarray(e.value) * texture_values(e.texture)[0, 0]
    np.testing.assert_allclose(radiance, [4.0, 2.0 * 0.2158605, 0.0], rtol=2e-2, atol=1e-3)
    op = back.carried["opacity"]
    assert op.value == pytest.approx(0.9) and op.settings == {"mode": "blend"}
    np.testing.assert_allclose(texture_values(op.texture)[0, :, 0], [0, 1 / 3, 2 / 3, 1], atol=1 / 255)
    occ = back.carried["occlusion"]
    assert occ.value == 0.5 and texture_values(occ.texture).shape[:2] == (4, 4)


def test_remap_of_a_transmissive_gltf_keeps_it_on_gltf_and_refuses_elsewhere(tmp_path, capsys):
    """Onto its own model (gltf:pbr) the glass is copied with its extensions; onto a model whose renderer cannot
    draw the transmission probe it is refused in one line, nothing written."""
    from matremap.cli import main

    src = CORPUS / "gltf-AttenuationTest" / "AttenuationTest.glb"
    code = main(["remap", str(src), "--to", "gltf:pbr", "--material", "0", "-o", str(tmp_path / "g")])
    assert code == 0
    out = tmp_path / "g" / "AttenuationTest.glb"
    doc = validate(out)
    before = read_asset(src, 0).document.json["materials"][0]
    assert doc["materials"][0]["extensions"] == before["extensions"]
    code = main(["remap", str(src), "--to", "mitsuba3:roughplastic", "--material", "0", "-o", str(tmp_path / "m")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and "transmits light" in err[-1] and "Traceback" not in "\n".join(err)
    assert not (tmp_path / "m").exists()
    assert json.loads(json.dumps(doc))  # the copy is plain JSON


@pytest.mark.parametrize("suffix", [".usda", ".mtlx"])
def test_a_grey_alpha_emissive_texture_is_carried_as_a_grey_colour(tmp_path, suffix):
    """TextureLinearInterpolationTest (CC0) material 2: its emissive texture is a grey + alpha PNG. The reader
    took channels (0, 1) (grey and alpha) as the emission's colour: remapping it onto usd:preview_surface ended in
    an internal error (ValueError: operands could not be broadcast ... (3,) and requested shape (2,)), as did any
    1- or 4-channel emissive texture. The colour is the grey three times, as PNG decoders expand it."""
    pytest.importorskip("pxr" if suffix == ".usda" else "MaterialX")
    from matremap.formats.gltf_write import texture_values

    asset = read(CORPUS / "gltf-TextureLinearInterpolationTest" / "TextureLinearInterpolationTest.glb", 2)
    e = asset.carried["emission"]
    assert e.texture.channels == (0, 0, 0)
    grey = texture_values(e.texture)
    assert grey.shape[-1] == 3 and np.array_equal(grey[..., 0], grey[..., 2]) and grey.std() > 0.05
    if suffix == ".usda":
        result = Material.create("usd:preview_surface", {"diffuseColor": [0.5, 0.5, 0.5], "roughness": 0.4})
    else:
        result = Material.create(MR, {"baseColor": [0.5, 0.5, 0.5], "metallic": 0.0, "roughness": 0.4})
    out = write_asset(tmp_path / f"o{suffix}", result, source=asset)
    back = read_asset(out).carried["emission"]
    assert back.texture is not None
    got = np.asarray(back.value, dtype=float) * texture_values(back.texture, grey.shape[:2])[..., :3]
    np.testing.assert_allclose(got, np.asarray(e.value) * grey, atol=2e-3)
