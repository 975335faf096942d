"""usd-wg's RoughnessTest (tests/data/corpus/usd-RoughnessTest, Apache-2.0): Targa textures of another size than
the colour texture, and uniform partial metals (metallic 0.6) over a colour texture. Three of its six materials were
refused ("targa images are not supported", then "textures of different sizes") and the other three failed the gate
onto glTF (the partial metal held a dielectric: 97 % of the texels outside the learned domain)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from matremap.core.material import Material
from matremap.dialects import get_model
from matremap.formats import read_asset
from matremap.regress import quantities as qty
from matremap.svbrdf.textures import image_info, load_map_set, output_info, read_image

USDZ = Path(__file__).parent / "data" / "corpus" / "usd-RoughnessTest" / "RoughnessTest.usdz"


def test_a_targa_map_is_read_and_written_back_as_png(tmp_path):
    grey = (np.arange(64, dtype=np.uint8).reshape(8, 8) * 4).astype(np.uint8)
    Image.fromarray(grey).save(tmp_path / "rough.tga")
    info = image_info(tmp_path / "rough.tga", "linear", colour=False)
    assert info.format == "tga" and info.pixel_type == "uint8"
    assert output_info(info, None).format == "png"  # matremap writes maps as PNG, JPEG, TIFF or EXR
    values, _ = read_image(tmp_path / "rough.tga", "linear", colour=False)
    np.testing.assert_allclose(np.squeeze(values), grey / 255.0, atol=1e-6)


def test_textures_of_different_sizes_are_resampled_to_the_largest(tmp_path):
    """Tex033: a 1280x1024 colour PNG beside a 256x256 Targa roughness (its G channel): one map set at 1280x1024, the
    roughness resampled bilinearly (the Targa read here with PIL)."""
    import zipfile

    asset = read_asset(USDZ, "/Roughness/Materials/Tex033")
    assert set(asset.textures) == {"diffuseColor", "roughness"}
    assert any("roughness resampled to 1280x1024" in n for n in asset.notes)
    rough = asset.textures["roughness"].bake()
    with zipfile.ZipFile(USDZ) as z, z.open("0/roughness.tga") as f:
        g = np.asarray(Image.open(f))[..., 1] / 255.0
    assert rough.shape == (1024, 1280, 1)
    # the Targa's G is one value (153); within its outermost half texel the texture's black border (USD's wrap
    # when the file says none) is blended in, as a renderer's bilinear lookup does
    np.testing.assert_allclose(rough[3:-3, 3:-3, 0], g[0, 0], atol=1e-6)
    assert float(rough.max()) <= float(g.max()) + 1e-6
    map_set = load_map_set(asset.to_map_set(tmp_path / "maps"))
    assert {(image_info(f).height, image_info(f).width) for f in map_set.maps.values()} == {(1024, 1280)}


@pytest.mark.parametrize(
    ("model", "name"), [("gltf:metal-rough", "metallic"), ("mtlx:open_pbr_surface", "base_metalness")]
)
@pytest.mark.parametrize("metallic", [0.3, 0.6])
def test_a_partial_metal_is_written_so_that_it_reads_back(model, name, metallic):
    """A transform's target held at a partial metalness: the base colour written reads back as the F0 asked for (a
    metal's side, m >= 0.5) or the albedo (a dielectric's); before, a metal took F0 itself as base colour."""
    spec = get_model(model)
    template = {k: np.asarray(v) for k, v in Material.create(model, {name: metallic}).values.items()}
    f0 = np.array([[0.3, 0.2, 0.1], [0.5, 0.45, 0.2]])
    albedo = np.array([[0.2, 0.1, 0.05], [0.3, 0.3, 0.1]]) * (1 - metallic)
    back = qty.read(spec, qty.write(spec, {"reflectance": f0, "diffuse": albedo}, template))
    kept = ("reflectance", f0) if metallic >= 0.5 else ("diffuse", albedo)
    np.testing.assert_allclose(back[kept[0]], kept[1], atol=1e-9)


def test_a_textured_partial_metal_onto_gltf_keeps_its_metalness_and_its_colour(tmp_path):
    """Const033: UsdPreviewSurface metallic 0.6 over a colour texture. The target's metallic is fitted once at the
    maps' median texel and held, the colour texture swept at eight levels (two levels, and the darkest left out as
    poorly fitted, learned no colour: the base colour came out flat)."""
    from matremap.remap import remap_file

    out = tmp_path / "out"
    res = remap_file(
        USDZ, "gltf:metal-rough", out, material="/Roughness/Materials/Const033", cache=tmp_path / "c", evaluate=False
    )
    assert res.verdict.passed, res.verdict.line()
    written = json.loads((out / "maps" / "material.json").read_text())
    assert 0.5 < written["params"]["metallic"] < 0.75
    assert written["provenance"]["outside_domain"]["texels"] == 0
    colour, _ = read_image(out / "maps" / written["maps"]["baseColor"], "linear")
    source, _ = read_image(out / "source" / "diffuseColor_shown.exr", "linear")
    # checked apart from matremap's score: the written colour follows the source's, texel by texel
    a, b = colour.reshape(-1, 3).mean(axis=1), source.reshape(-1, 3).mean(axis=1)
    assert float(np.ptp(a)) > 0.3 and float(np.corrcoef(a, b)[0, 1]) > 0.99
