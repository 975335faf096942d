"""The texels a glTF material's triangles show (formats/gltf_coverage.py): a texture shared by several materials (an
atlas) is read, for each, only where its triangles map it; the rest is filled from the nearest texel they show before
anything is decided from the maps."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from matremap.cli import main
from matremap.formats import read_asset
from matremap.formats.uv_coverage import Coverage, fill_uncovered

sys.path.insert(0, str(Path(__file__).parent))
import corpus_checks as cc  # noqa: E402

CORPUS = Path(__file__).resolve().parent / "data" / "corpus"
TCT = CORPUS / "gltf-TextureCoordinateTest" / "TextureCoordinateTest.glb"


def _box(mask: np.ndarray) -> tuple[int, int, int, int]:
    rows, cols = np.nonzero(mask)
    return int(rows.min()), int(rows.max()), int(cols.min()), int(cols.max())


@pytest.mark.parametrize(
    "material, rows, cols",
    [("BottomLeftMat", (0.6, 1.0), (0.0, 0.4)), ("TopRightMat", (0.0, 0.4), (0.6, 1.0))],
)
def test_each_plane_of_the_texture_coordinate_test_shows_its_own_corner(material, rows, cols):
    """Khronos TextureCoordinateTest: four planes each show one corner of one texture (the file tests that UV
    (0, 0) is the image's top-left texel, glTF 2.0 §3.8.3). The bottom-left plane's UVs are u 0-0.4, v 0.6-1: the
    image's bottom-left corner, and nothing else (a UV of exactly 1 is the tile's far edge, not the next tile's)."""
    mask = read_asset(TCT, material).coverage.mask((500, 500))
    r0, r1, c0, c1 = _box(mask)
    assert abs(r0 - rows[0] * 500) <= 1 and abs(r1 + 1 - rows[1] * 500) <= 1
    assert abs(c0 - cols[0] * 500) <= 1 and abs(c1 + 1 - cols[1] * 500) <= 1
    assert mask.mean() == pytest.approx(0.16, abs=0.005)


def test_a_triangle_across_the_tile_edge_wraps_and_one_over_a_whole_tile_covers_all():
    across = Coverage(np.array([[[0.9, 0.1], [1.1, 0.1], [1.1, 0.3]]])).mask((100, 100))
    assert across[11, 95] and across[11, 5] and not across[11, 50]  # the repeat wrap (§3.8.4) takes it round
    assert Coverage(np.array([[[0.0, 0.0], [2.0, 0.0], [0.0, 2.0]]])).mask((100, 100)) is None
    tiny = Coverage(np.array([[[0.501, 0.501], [0.502, 0.501], [0.501, 0.502]]])).mask((100, 100))
    assert tiny.sum() >= 1 and tiny[50, 50]  # smaller than a texel: its texel still counts


def test_uncovered_texels_take_the_nearest_covered_value():
    image = np.zeros((4, 6, 1), dtype=np.float32)
    image[:, :3] = 0.25
    image[:, 3:] = 0.75
    mask = np.zeros((4, 6), dtype=bool)
    mask[:, 0] = mask[:, 5] = True
    filled = fill_uncovered(image, mask)[..., 0]
    assert np.all(filled[:, :3] == 0.25) and np.all(filled[:, 3:] == 0.75)
    image[:, 1] = 9.0  # a value no triangle shows never reaches the filled map
    assert fill_uncovered(image, mask).max() == 0.75


def test_a_file_without_meshes_counts_every_texel(tmp_path):
    """A material no primitive draws (a library of materials, a variant never mapped): nothing to restrict."""
    from test_formats_gltf import make_file, ramp

    mat = {"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}
    asset = read_asset(make_file(tmp_path, "a.gltf", [mat], {"t": ramp()}))
    assert asset.textures and asset.coverage is None


@pytest.mark.slow
def test_a_corner_of_a_shared_texture_is_converted_from_that_corner_alone(tmp_path, capsys):
    """TextureCoordinateTest's BottomLeftMat onto OpenPBR: the note says 16 % is shown; the written base colour
    holds, everywhere, only colours of the corner the plane shows (read back from the MaterialX file and the glTF's
    own image times its factor here, apart from matremap), and within that corner it is the source's."""
    out = tmp_path / "out"
    args = ["--material", "BottomLeftMat", "--to", "mtlx:open_pbr_surface", "-o", str(out), "--no-evaluate"]
    code = main(["remap", str(TCT), *args])
    err = capsys.readouterr().err
    assert code == 0, err[-800:]
    assert "triangles show 16% of its textures" in err
    doc, binary = cc.gltf_load(TCT)
    m = doc["materials"][cc.gltf_material_index(doc, "BottomLeftMat")]
    tex = doc["textures"][m["pbrMetallicRoughness"]["baseColorTexture"]["index"]]["source"]
    factor = np.asarray(m["pbrMetallicRoughness"]["baseColorFactor"][:3])
    source = cc.rgb(cc._image_from_bytes(cc.gltf_image_bytes(TCT, doc, binary, tex), srgb=True)) * factor
    h, w = source.shape[:2]
    corner = source[round(0.6 * h) :, : round(0.4 * w)]
    top = round(0.6 * h)
    # the source maps as converted: the corner as it is, above it each column its top texel (the nearest shown)
    shown = json.loads((out / "source" / "material.json").read_text())
    filled = cc.rgb(cc.read_image(out / "source" / shown["maps"]["baseColor"], srgb=False))
    left = round(0.4 * w) - 1
    np.testing.assert_allclose(filled[top + 1 :, :left], source[top + 1 :, :left], atol=2e-3)
    above = np.unique(np.round(filled[: top - 1, :left], 3).reshape(-1, 3), axis=0)  # each a texel of the corner's
    edge = np.unique(np.round(source[top : top + 3, :left], 3).reshape(-1, 3), axis=0)  # top rows (its nearest)
    assert all(np.any(np.all(np.abs(edge - v) < 2e-3, axis=1)) for v in above)
    manifest = json.loads((out / "maps" / "material.json").read_text())
    written = cc.rgb(cc.read_image(out / "maps" / manifest["maps"]["base_color"], srgb=False))
    assert written.shape[:2] == (h, w)
    inside = written[top + 2 :, : round(0.4 * w) - 2]
    assert cc.hue_difference(cc.mean_hue(inside), cc.mean_hue(corner)) < 3.0
    assert cc.mean_luminance(inside) == pytest.approx(cc.mean_luminance(corner), rel=0.1)


def test_uvs_are_read_with_their_stride_and_normalised_integers():
    """§3.6.2: a TEXCOORD may be normalised unsigned bytes, interleaved with other attributes (byteStride)."""
    from matremap.formats.gltf_coverage import _accessor

    class Reader:
        path = Path("x.gltf")
        views = [{"buffer": 0, "byteLength": 12, "byteStride": 4}]
        accessors = [{"bufferView": 0, "componentType": 5121, "normalized": True, "type": "VEC2", "count": 3}]

        def item(self, key, index, where):
            return {"accessors": self.accessors, "bufferViews": self.views}[key][index]

        def buffer_view(self, index, where):  # u, v, then two bytes of another attribute, per vertex
            return bytes([0, 255, 9, 9, 51, 102, 9, 9, 255, 0, 9, 9])

    uv = _accessor(Reader(), 0, "here", uv=True)
    np.testing.assert_allclose(uv, [[0.0, 1.0], [0.2, 0.4], [1.0, 0.0]])


@pytest.mark.parametrize("material", ["BottomLeftMat", "BottomRightMat", "TopLeftMat", "TopRightMat"])
def test_the_usd_and_gltf_texture_coordinate_tests_show_the_same_texels(material):
    """The same scene written by two third parties in two formats (Khronos' glTF, and the usd-wg assets' USD: st
    with its origin at the image's lower-left, faces bound through UsdShadeMaterialBindingAPI): each plane's
    material shows the same corner of its texture (formats/usd_coverage.py)."""
    pytest.importorskip("pxr")
    usd = CORPUS / "usd-TextureCoordinateTest" / "TextureCoordinateTest.usda"
    from matremap.formats.usd import read as read_usd

    a = read_usd(usd, f"/Asset/Materials/UsdPreviewSurface/Materials/{material}")
    m_usd = a.coverage.mask((512, 512))
    m_gltf = read_asset(TCT, material).coverage.mask((512, 512))
    union = np.count_nonzero(m_usd | m_gltf)
    assert np.count_nonzero(m_usd & m_gltf) / union > 0.98 and 0.15 < m_usd.mean() < 0.17


@pytest.mark.parametrize(
    "file, material",
    [
        ("gltf-TextureCoordinateTest/TextureCoordinateTest.glb", "TopRightMat"),
        ("gltf-MultiUVTest/MultiUVTest.glb", None),
        ("gltf-TransmissionTest/TransmissionTest.glb", "Cloth Backdrop"),
        ("gltf-SpecularTest/SpecularTest.glb", "M2_SpecTex"),
    ],
)
def test_the_independent_checker_sees_the_same_texels(file, material):
    """The real-asset checker's own reading of a material's triangles (tests/corpus_checks.py: its own accessor
    reader, PIL's polygon filler) and matremap's agree on what each surface shows."""
    path = CORPUS / file
    ours = read_asset(path, material).coverage.mask((512, 512))
    theirs = cc.gltf_shown(path, material, (512, 512))
    assert ours is not None and theirs is not None
    assert np.count_nonzero(ours & theirs) / np.count_nonzero(ours | theirs) > 0.95  # edges differ by a texel


def test_a_glass_sharing_an_atlas_with_its_metal_frame_reads_its_own_texels_only(tmp_path):
    """Khronos GlassHurricaneCandleHolder (fetched on demand): the glass and its frame share one ORM atlas whose
    metallic is 1 in the frame's part. Read whole, the glass "varied its metallic map" and was refused; read where its
    triangles show it (26 %: the checker's own count), its metallic map is 0 everywhere and it is converted at levels
    of its roughness and colour."""
    from large_assets import large_asset

    from matremap.svbrdf.mapstats import summarise
    from matremap.svbrdf.mixed import through_levels
    from matremap.svbrdf.textures import load_map_set, read_image

    path = large_asset("gltf-GlassHurricaneCandleHolder") / "GlassHurricaneCandleHolder.gltf"
    orm = cc.read_image(path.parent / "GlassHurricaneCandleHolder_orm.png", srgb=False)
    shown = cc.gltf_shown(path, "GlassHurricaneCandleHolder-glass", orm.shape[:2])
    assert shown is not None and 0.2 < shown.mean() < 0.3
    assert orm[..., 2].max() == 1.0 and orm[..., 2][shown].max() == 0.0  # metal only where the glass is not
    asset = read_asset(path, "GlassHurricaneCandleHolder-glass")
    ms = load_map_set(asset.to_map_set(tmp_path / "source"))
    assert any("triangles show 26% of its textures" in n for n in asset.notes)
    assert float(np.asarray(read_image(ms.maps["metallic"], "linear", colour=False)[0]).max()) == 0.0
    assert through_levels(ms, summarise(ms)) is not None  # converted at levels, not refused
