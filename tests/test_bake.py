"""formats/bake.py: texture transforms and wrap modes baked onto maps, and TextureRef.bake in a map set."""

from __future__ import annotations

import json

import numpy as np
import pytest

from matremap.errors import MatremapError
from matremap.formats.asset import MaterialAsset, TextureRef
from matremap.formats.bake import UVTransform, bake_image, rotate, sample, scale, texel_grid, translate


def _ramp(h: int = 4, w: int = 6) -> np.ndarray:
    rng = np.random.default_rng(3)
    return rng.random((h, w, 3)).astype(np.float32)


def test_identity_reproduces_the_image_exactly():
    img = _ramp()
    out = bake_image(img, UVTransform(np.eye(3)))
    np.testing.assert_array_equal(out, img)


def test_identity_with_bottom_left_origin_is_also_the_image():
    img = _ramp()
    np.testing.assert_array_equal(bake_image(img, UVTransform(np.eye(3), origin="bottom-left")), img)


def test_translation_by_whole_texels_shifts_with_repeat():
    img = _ramp(4, 6)
    out = bake_image(img, UVTransform(translate(2 / 6, 1 / 4)))
    np.testing.assert_allclose(out, np.roll(img, (-1, -2), axis=(0, 1)), atol=1e-6)


def test_v_translation_moves_the_other_way_when_origin_is_bottom_left():
    img = _ramp(4, 6)
    top = bake_image(img, UVTransform(translate(0, 1 / 4), origin="top-left"))
    bottom = bake_image(img, UVTransform(translate(0, 1 / 4), origin="bottom-left"))
    np.testing.assert_allclose(top, np.roll(img, -1, axis=0), atol=1e-6)
    np.testing.assert_allclose(bottom, np.roll(img, 1, axis=0), atol=1e-6)


def test_tiling_repeats_the_image():
    img = _ramp(4, 4)
    out = bake_image(img, UVTransform(scale(2, 2)), size=(8, 8))
    # an 8x8 map of a 2x2 tiling: every 4x4 quadrant is the image sampled at its own texel centres
    np.testing.assert_allclose(out[:4, :4], out[4:, 4:], atol=1e-6)
    np.testing.assert_allclose(out[:4, :4], img, atol=1e-6)


def test_rotation_by_a_half_turn_about_the_centre_flips_both_axes():
    img = _ramp(4, 6)
    m = translate(0.5, 0.5) @ rotate(np.pi) @ translate(-0.5, -0.5)
    np.testing.assert_allclose(bake_image(img, UVTransform(m)), img[::-1, ::-1], atol=1e-5)


@pytest.mark.parametrize(
    ("mode", "expected"),
    [("repeat", [3.0, 2.0]), ("clamp", [0.0, 0.0]), ("mirror", [0.0, 1.0]), ("border", [-1.0, -1.0])],
)
def test_wrap_modes_outside_the_image(mode, expected):
    img = np.array([[[0.0], [1.0], [2.0], [3.0]]], dtype=np.float32)  # 1x4, one channel
    s = np.array([-0.125, -0.375])  # centres of texels -1 and -2
    t = np.array([0.5, 0.5])
    out = sample(img, s, t, (mode, "clamp"), border=-1.0)[..., 0]
    np.testing.assert_allclose(out, expected, atol=1e-6)


def test_bilinear_halfway_between_texel_centres():
    img = np.array([[[0.0], [1.0]]], dtype=np.float32)
    out = sample(img, np.array([0.5]), np.array([0.5]), ("clamp", "clamp"))
    assert out[0, 0] == pytest.approx(0.5)


def test_texel_grid_centres():
    s, t = texel_grid((2, 4))
    np.testing.assert_allclose(s[0], [0.125, 0.375, 0.625, 0.875])
    np.testing.assert_allclose(t[:, 0], [0.25, 0.75])


def test_bad_transforms_are_refused():
    with pytest.raises(MatremapError, match="3x3"):
        UVTransform(np.eye(2))
    with pytest.raises(MatremapError, match="wrap mode"):
        UVTransform(np.eye(3), wrap=("wrap", "repeat"))
    with pytest.raises(MatremapError, match="origin"):
        UVTransform(np.eye(3), origin="centre")


def test_a_baked_texture_becomes_a_map_of_its_baked_values(tmp_path):
    from matremap.svbrdf.textures import read_image

    baked = np.full((8, 8, 3), 0.25, dtype=np.float32)
    baked[:, :4] = 0.75
    ref = TextureRef(tmp_path / "doc.mtlx", colorspace="linear", scale=(1.0, 0.5, 1.0), bake=lambda: baked)
    assert not ref.plain
    asset = MaterialAsset(
        path=tmp_path / "doc.mtlx",
        format="mtlx",
        name="m",
        model="gltf:metal-rough",
        constants={"metallic": 0.0, "roughness": 0.5},
        textures={"baseColor": ref},
    )
    folder = asset.to_map_set(tmp_path / "maps")
    manifest = json.loads((folder / "material.json").read_text())
    image, _ = read_image(folder / manifest["maps"]["baseColor"], manifest["colorspace"]["baseColor"])
    np.testing.assert_allclose(image[:, :4], np.broadcast_to([0.75, 0.375, 0.75], (8, 4, 3)), atol=1e-6)
    np.testing.assert_allclose(image[:, 4:], np.broadcast_to([0.25, 0.125, 0.25], (8, 4, 3)), atol=1e-6)


def test_a_baked_texture_with_non_finite_values_is_refused(tmp_path):
    ref = TextureRef(tmp_path / "doc.mtlx", bake=lambda: np.full((2, 2, 1), np.nan, dtype=np.float32))
    asset = MaterialAsset(
        path=tmp_path / "doc.mtlx",
        format="mtlx",
        name="m",
        model="gltf:metal-rough",
        constants={},
        textures={"roughness": ref},
    )
    with pytest.raises(MatremapError, match="non-finite"):
        asset.to_map_set(tmp_path / "maps")
