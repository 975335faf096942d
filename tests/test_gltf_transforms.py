"""KHR_texture_transform, samplers' wrap modes and UV sets (matremap.formats.gltf_textures), held against
Khronos' own test assets (tests/data/corpus, licences in its README):

* TextureTransformTest (CC0, Microsoft): its README gives each quad's UVs and transform and where the
  correct result lies (the "Rotation" arrow ends on the green marker; the red one means the opposite
  direction);
* TextureTransformMultiTest (CC-BY 4.0, Ed Mackey / AGI): each row has a "Test" tile (UVs plus a transform,
  on TEXCOORD_0 or TEXCOORD_1) that must look like its "Sample" tile (plain UVs). The tiles' geometry is
  read here with pygltflib, the baked maps are sampled over each tile and compared with the sample's image
  sampled over its tile, in world space for normals.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest

from matremap.core.imageio import srgb_to_linear
from matremap.errors import MatremapError
from matremap.formats import read_asset, write_asset
from matremap.formats.gltf import read
from matremap.svbrdf.textures import load_map_set, read_image

CORPUS = Path(__file__).resolve().parent / "data" / "corpus"
TTT = CORPUS / "gltf-TextureTransformTest" / "TextureTransformTest.gltf"
TTMT = CORPUS / "gltf-TextureTransformMultiTest" / "TextureTransformMultiTest.glb"


def image_codes(path: Path) -> np.ndarray:
    """An image's code values in [0, 1], colour not premultiplied (read here with OpenImageIO)."""
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    inp = oiio.ImageInput.open(str(path), config)
    spec = inp.spec()
    a = inp.read_image(0, 0, 0, spec.nchannels, oiio.FLOAT)
    inp.close()
    return np.asarray(a, dtype=np.float32).reshape(spec.height, spec.width, spec.nchannels)


def baked(ref) -> np.ndarray:
    assert ref.bake is not None, "a transformed texture must be baked"
    return np.asarray(ref.bake(), dtype=np.float32)


# ------------------------------------------------------------------------------------------------
# TextureTransformTest


def test_offset_moves_the_lookup_by_half_the_image():
    """'Offset U': offset (0.5, 0): the map's texel (i, j) is the image's (i + W/2, j); clamped beyond."""
    asset = read(TTT, "Offset U")
    uv = image_codes(CORPUS / "gltf-TextureTransformTest" / "UV.png")
    got = baked(asset.textures["baseColor"])
    h, w = uv.shape[:2]
    want = srgb_to_linear(uv[:, w // 2 :, :3])
    np.testing.assert_allclose(got[:, : w // 2, :3], want, atol=1e-5)
    np.testing.assert_allclose(got[:, w // 2 :, :3], np.repeat(want[:, -1:], w // 2, axis=1), atol=1e-5)  # clamp
    assert any("KHR_texture_transform" in n and "clamp" in n for n in asset.notes)


def arrow_tip(image: np.ndarray) -> tuple[float, float]:
    """The (s, t) of the arrow's dark texel farthest down and right."""
    ys, xs = np.nonzero(image[..., :3].mean(-1) < 0.1)
    h, w = image.shape[:2]
    k = np.argmax(xs / w + ys / h)
    return (xs[k] + 0.5) / w, (ys[k] + 0.5) / h


def test_rotation_turns_the_arrow_onto_the_green_marker():
    """The arrow (tip at (0.69, 0.69) in Arrow.png) rotated 22.5 degrees must end near the bottom edge
    (the README's green marker), not at the right edge (the red 'opposite direction' marker)."""
    plain = image_codes(CORPUS / "gltf-TextureTransformTest" / "Arrow.png")
    assert np.allclose(arrow_tip(plain), (0.69, 0.69), atol=0.03)
    s, t = arrow_tip(baked(read(TTT, "Rotation").textures["baseColor"]))
    assert s < 0.5 and t > 0.8, (s, t)
    s, t = arrow_tip(baked(read(TTT, "Scale").textures["baseColor"]))  # scale 1.5: the tip at 0.69 / 1.5
    assert abs(s - 0.46) < 0.03 and abs(t - 0.46) < 0.03


def test_untransformed_textures_are_used_as_stored():
    asset = read(TTT, "Correct")
    assert asset.textures["baseColor"].bake is None and not any("KHR_texture_transform" in n for n in asset.notes)


# ------------------------------------------------------------------------------------------------
# TextureTransformMultiTest: every tile against its sample


class Tiles:
    """The tiles of TextureTransformMultiTest, read with pygltflib: each material's quad corners (sorted by
    position) with their UVs, and the tangent frame of a UV set."""

    def __init__(self) -> None:
        pygltflib = pytest.importorskip("pygltflib")
        self.g = pygltflib.GLTF2().load(str(TTMT))
        self.blob = self.g.binary_blob()
        self.prims = {self.g.materials[p.material].name: p for m in self.g.meshes for p in m.primitives}

    def accessor(self, i: int) -> np.ndarray:
        a = self.g.accessors[i]
        bv = self.g.bufferViews[a.bufferView]
        n = {"VEC2": 2, "VEC3": 3}[a.type]
        off = (bv.byteOffset or 0) + (a.byteOffset or 0)
        return np.frombuffer(self.blob, dtype=np.float32, count=a.count * n, offset=off).reshape(a.count, n)

    def corners(self, name: str, uv_set: int) -> tuple[np.ndarray, np.ndarray]:
        p = self.prims[name]
        pos = self.accessor(p.attributes.POSITION)
        uv = self.accessor(getattr(p.attributes, f"TEXCOORD_{uv_set}"))
        c = pos - pos.mean(0)
        order = np.lexsort((c[:, 1], c[:, 0]))
        return pos[order], uv[order]

    def lookup(self, name: str, uv_set: int, image: np.ndarray, n: int = 160) -> np.ndarray:
        """``image`` sampled (nearest texel) over the tile on an n x n grid of its corners' bilinear blend."""
        _, uv = self.corners(name, uv_set)
        a, b = np.meshgrid((np.arange(n) + 0.5) / n, (np.arange(n) + 0.5) / n, indexing="ij")
        a, b = a[..., None], b[..., None]
        g = (1 - a) * (1 - b) * uv[0] + (1 - a) * b * uv[1] + a * (1 - b) * uv[2] + a * b * uv[3]
        h, w = image.shape[:2]
        x = np.clip((g[..., 0] * w).astype(int), 0, w - 1)
        y = np.clip((g[..., 1] * h).astype(int), 0, h - 1)
        return image[y, x]

    def frame(self, name: str, uv_set: int) -> tuple[np.ndarray, np.ndarray]:
        """The world directions of the image's +X (increasing u) and +Y (up: decreasing v) on the tile."""
        pos, uv = self.corners(name, uv_set)
        d, *_ = np.linalg.lstsq(uv[1:] - uv[0], pos[1:] - pos[0], rcond=None)
        return d[0] / np.linalg.norm(d[0]), -d[1] / np.linalg.norm(d[1])


def khr_matrix(asset) -> np.ndarray:
    """The lookup T * R * S of the asset's normalTexture transform, from the KHR README's definitions."""
    ext = asset.document.json["materials"][asset.index]["normalTexture"]["extensions"]["KHR_texture_transform"]
    (ox, oy), r, (sx, sy) = ext.get("offset", [0, 0]), ext.get("rotation", 0.0), ext.get("scale", [1, 1])
    c, s = np.cos(r), np.sin(r)
    return (
        np.array([[1, 0, ox], [0, 1, oy], [0, 0, 1]])
        @ np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]])
        @ np.diag([sx, sy, 1])
    )


def best_shift_difference(a: np.ndarray, b: np.ndarray, r: int = 24) -> float:
    """The smallest mean absolute difference of ``a`` and ``b`` over shifts of up to ``r`` texels (the
    test and sample tiles are laid a few texels apart in their images)."""
    n = a.shape[0]
    best = np.inf
    for dx in range(-r, r + 1, 2):
        for dy in range(-r, r + 1, 2):
            pa = a[max(dx, 0) : n + min(dx, 0), max(dy, 0) : n + min(dy, 0)]
            pb = b[max(-dx, 0) : n + min(-dx, 0), max(-dy, 0) : n + min(-dy, 0)]
            best = min(best, float(np.abs(pa - pb).mean()))
    return best


@pytest.fixture(scope="module")
def tiles() -> Tiles:
    return Tiles()


@pytest.mark.parametrize("uv_set", [0, 1])
def test_transformed_base_colour_looks_like_the_sample(tiles, uv_set):
    test = read(TTMT, f"BaseColorTest{uv_set}Mat")
    sample = read(TTMT, "BaseColorSampleMat")
    got = tiles.lookup(test.name, uv_set, baked(test.textures["baseColor"])[..., :3])
    want = tiles.lookup(sample.name, 0, srgb_to_linear(image_codes(sample.textures["baseColor"].path)[..., :3]))
    assert np.abs(want - want.mean((0, 1))).mean() > 0.2  # the checkmark is there to compare
    assert best_shift_difference(got, want) < 0.02
    assert (uv_set == 1) == any("TEXCOORD_1" in n for n in test.notes)


def test_transformed_normal_map_is_turned_with_its_transform(tiles):
    """Rotated 90 degrees, the normal map's bumps must face the same world directions as the sample's:
    with x and y turned the difference is ~0.02; used as stored (not turned) it is 0.2."""
    test, sample = read(TTMT, "NormalTest0Mat"), read(TTMT, "NormalSampleMat")

    def world(codes: np.ndarray, name: str) -> np.ndarray:
        t, b = tiles.frame(name, 0)
        n = codes[..., :3] * 2 - 1
        return n[..., :1] * t + n[..., 1:2] * b

    got = world(tiles.lookup(test.name, 0, baked(test.normal)), test.name)
    want = world(tiles.lookup(sample.name, 0, image_codes(sample.normal.path)), sample.name)
    assert best_shift_difference(got, want) < 0.05
    from matremap.formats.bake import UVTransform, bake_image

    unturned = bake_image(image_codes(test.normal.path)[..., :3], UVTransform(khr_matrix(test)))
    assert best_shift_difference(world(tiles.lookup(test.name, 0, unturned), test.name), want) > 0.1


def test_metallic_roughness_emission_and_occlusion_follow_their_transforms(tiles):
    for kind, get in (
        ("MetalRough", lambda a: baked(a.textures["roughness"])[..., 1:2]),
        ("Emission", lambda a: baked(a.carried["emission"].texture)[..., :3]),
        ("Occlusion", lambda a: baked(a.carried["occlusion"].texture)[..., :1]),
    ):
        test, sample = read(TTMT, f"{kind}Test0Mat"), read(TTMT, f"{kind}SampleMat")
        ref = {"MetalRough": sample.textures.get("roughness")}.get(kind) or sample.carried[kind.lower()].texture
        want_image = image_codes(ref.path)
        if kind == "Emission":
            want_image = srgb_to_linear(want_image[..., :3])
        elif kind == "MetalRough":
            want_image = want_image[..., 1:2]
        else:
            want_image = want_image[..., :1]
        got = tiles.lookup(test.name, 0, get(test))
        want = tiles.lookup(sample.name, 0, want_image)
        assert best_shift_difference(got, want) < 0.03, kind


def test_clearcoat_on_another_uv_set_and_texcoord_1_carried_inputs_are_said():
    a = read(TTMT, "EmissionTest1Mat")  # emission on TEXCOORD_1, no remapped textures (maps' set 0)
    assert "emission" in a.carried and a.carried["emission"].texture is None
    assert any("emissiveTexture uses TEXCOORD_1" in n for n in a.notes)
    cc = read(TTMT, "ClearcoatTest0Mat")  # a coat mask under a texture transform: read as a map, the transform baked
    assert cc.lost == [] and cc.model == "gltf:pbr" and list(cc.textures) == ["clearcoat"]
    assert any(n.startswith("clearcoatTexture: KHR_texture_transform") and "baked" in n for n in cc.notes)


# ------------------------------------------------------------------------------------------------
# built files: wrap modes, refusals, writing


def grey_ramp(w: int = 8) -> np.ndarray:
    return np.tile(np.arange(w, dtype=np.uint8)[None, :, None] * 32, (4, 1, 3))


def one_texture_file(folder: Path, info: dict, sampler: dict | None = None, mats: list | None = None) -> Path:
    """A .gltf whose material 'm' has a metallicRoughnessTexture ``info`` on an 8x4 ramp (blue = x)."""
    from test_formats_gltf import png_bytes

    folder.mkdir(parents=True, exist_ok=True)
    (folder / "r.png").write_bytes(png_bytes(folder, grey_ramp()))
    doc = {
        "asset": {"version": "2.0"},
        "images": [{"uri": "r.png"}],
        "textures": [{"source": 0, **({"sampler": 0} if sampler is not None else {})}],
        "materials": mats or [{"name": "m", "pbrMetallicRoughness": {"metallicRoughnessTexture": info}}],
    }
    if sampler is not None:
        doc["samplers"] = [sampler]
    (folder / "a.gltf").write_text(json.dumps(doc))
    return folder / "a.gltf"


@pytest.mark.parametrize(
    "wrap, columns",
    [
        (10497, [4, 5, 6, 7, 0, 1, 2, 3]),  # repeat
        (33648, [4, 5, 6, 7, 7, 6, 5, 4]),  # mirrored repeat
        (33071, [4, 5, 6, 7, 7, 7, 7, 7]),  # clamp to edge
    ],
)
def test_wrap_modes_are_honoured_where_the_offset_leaves_the_image(tmp_path, wrap, columns):
    f = one_texture_file(
        tmp_path, {"index": 0, "extensions": {"KHR_texture_transform": {"offset": [0.5, 0]}}}, {"wrapS": wrap}
    )
    got = baked(read(f).textures["metallic"])[0, :, 2]
    np.testing.assert_allclose(got, np.array(columns) * 32 / 255, atol=1e-6)


@pytest.mark.parametrize(
    "info, sampler, match",
    [
        ({"index": 0}, {"wrapS": 1234}, r"samplers\[0\]\.wrapS is 1234"),
        ({"index": 0, "extensions": {"KHR_texture_transform": {"offset": [1]}}}, None, "offset must be 2 numbers"),
        ({"index": 0, "extensions": {"KHR_texture_transform": {"rotation": "x"}}}, None, "rotation must be a number"),
        ({"index": 0, "extensions": {"KHR_texture_transform": {"scale": [0, 1]}}}, None, "collapses the texture"),
        ({"index": 0, "extensions": {"KHR_texture_transform": {"texCoord": -1}}}, None, "texCoord must be a UV set"),
        ({"index": 0, "texCoord": "a"}, None, "texCoord must be a UV set"),
    ],
)
def test_malformed_transforms_and_samplers_are_refused_in_one_line(tmp_path, info, sampler, match):
    f = one_texture_file(tmp_path, info, sampler)
    with pytest.raises(MatremapError, match=match) as e:
        read(f)
    assert "material 'm'" in str(e.value) or "samplers[0]" in str(e.value)
    assert "\n" not in str(e.value)


def test_remapped_textures_on_two_uv_sets_are_refused(tmp_path):
    mats = [
        {
            "name": "m",
            "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}, "metallicRoughnessTexture": {"index": 0}},
            "normalTexture": {"index": 0, "texCoord": 1},
        }
    ]
    f = one_texture_file(tmp_path, {}, mats=mats)
    with pytest.raises(MatremapError, match="baseColorTexture uses TEXCOORD_0 and normalTexture TEXCOORD_1"):
        read(f)


@pytest.mark.parametrize("suffix", [".gltf", ".glb"])
def test_a_transformed_material_written_back_reads_the_same_maps(tmp_path, suffix):
    """Read -> map set -> write -> read: the written texture carries the baked values, so it has no
    transform; it keeps the sampler and the UV set (the transform's texCoord override)."""
    info = {"index": 0, "extensions": {"KHR_texture_transform": {"offset": [0.25, 0], "texCoord": 1}}}
    f = one_texture_file(tmp_path / "src", info, {"wrapS": 33648})
    doc = json.loads(f.read_text())
    doc["extensionsUsed"] = doc["extensionsRequired"] = ["KHR_texture_transform"]
    f.write_text(json.dumps(doc))
    asset = read_asset(f)
    ms = load_map_set(asset.to_map_set(tmp_path / "ms"))
    (tmp_path / "out").mkdir()
    out = write_asset(tmp_path / "out" / f"o{suffix}", ms, source=asset)
    back = read(out)
    written = back.document.json
    texinfo = written["materials"][0]["pbrMetallicRoughness"]["metallicRoughnessTexture"]
    assert texinfo.get("texCoord") == 1 and "extensions" not in texinfo
    assert written["textures"][texinfo["index"]]["sampler"] == 0
    assert "KHR_texture_transform" not in json.dumps(written)  # not used any more: not listed either
    for name in ("roughness", "metallic"):
        want, _ = read_image(ms.maps[name], ms.colorspace[name], colour=False)
        got = back.textures[name]
        got_v = image_codes(got.path)[..., got.channels[0]]
        np.testing.assert_allclose(got_v, want[..., 0], atol=0.5 / 255 + 1e-6)


def test_textures_of_other_sizes_and_tilings_become_maps_of_one_size(tmp_path):
    """glTF gives each texture its own size and transform (Khronos SheenChair: a 512² albedo tiled 7 times beside
    a 1024² normal map tiled twice); a map set needs one size: the largest any texture needs to keep its texels
    (an 8-texel ramp tiled 3 times needs 24), the others resampled there, each through its own lookup."""
    from test_formats_gltf import png_bytes

    (tmp_path / "r.png").write_bytes(png_bytes(tmp_path, grey_ramp()))  # 8 x 4, blue = x
    normal = np.zeros((16, 16, 3), np.uint8) + np.array([128, 128, 255], np.uint8)
    (tmp_path / "n.png").write_bytes(png_bytes(tmp_path, normal))
    tiled = {"index": 0, "extensions": {"KHR_texture_transform": {"scale": [3, 1]}}}
    mats = [{"name": "m", "pbrMetallicRoughness": {"metallicRoughnessTexture": tiled}, "normalTexture": {"index": 1}}]
    doc = {
        "asset": {"version": "2.0"},
        "images": [{"uri": "r.png"}, {"uri": "n.png"}],
        "textures": [{"source": 0}, {"source": 1}],
        "materials": mats,
    }
    (tmp_path / "a.gltf").write_text(json.dumps(doc))
    asset = read(tmp_path / "a.gltf")
    metal, nmap = baked(asset.textures["metallic"]), baked(asset.normal)
    assert metal.shape[:2] == nmap.shape[:2] == (16, 24)  # height from the normal map, width from the tiling
    # three whole periods of the ramp across, each of its 8 columns kept (texel centres land on the image's)
    np.testing.assert_allclose(metal[0, :, 2], np.tile(np.arange(8) * 32 / 255, 3), atol=1e-6)
    # the flat normal stays flat when resampled
    np.testing.assert_allclose(nmap, np.broadcast_to(nmap[0, 0], nmap.shape), atol=1e-6)
    assert nmap[0, 0, 2] > 0.9999
    assert any("resampled to 24x16" in n for n in asset.notes)
    ms = load_map_set(asset.to_map_set(tmp_path / "ms"))  # refused before: "textures of different sizes"
    assert ms.size == (16, 24)


def test_a_tiling_beyond_the_bake_limit_is_capped_and_said(tmp_path):
    from matremap.formats.bake import MAX_SIDE

    f = one_texture_file(tmp_path, {"index": 0, "extensions": {"KHR_texture_transform": {"scale": [400, 1]}}})
    asset = read(f)
    assert baked(asset.textures["metallic"]).shape[:2] == (4, MAX_SIDE)
    assert any(f"capped at {MAX_SIDE} per side from 3200x4" in n for n in asset.notes)
