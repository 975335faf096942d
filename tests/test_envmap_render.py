"""Environment maps, their sampling into directional lights, and SVBRDF renders on sphere / plane."""

from __future__ import annotations

import math

import numpy as np
import pytest

from matremap.core import envmap
from matremap.core.imageio import write_image
from matremap.errors import MatremapError
from matremap.renderers.embedded.environment import render_svbrdf
from matremap.renderers.textured import decode_normal_map, object_mask, sample_texture

RES = 48
LIGHTS = 64


@pytest.fixture(scope="module")
def studio():
    return envmap.builtin(64, 128)


# -- environment maps ---------------------------------------------------------------------------


def test_builtin_is_a_deterministic_hdr():
    a, b = envmap.builtin(), envmap.builtin()
    assert a.radiance.shape == (128, 256, 3) and a.radiance.dtype == np.float32
    assert np.array_equal(a.radiance, b.radiance)
    assert a.radiance.min() >= 0.0 and a.radiance.max() > 5.0  # bright soft boxes over a dim studio
    # brighter above the horizon than below
    assert a.radiance[:10].mean() > a.radiance[-10:].mean()


def test_constant_map_mean_radiance():
    assert np.allclose(envmap.constant((0.5, 1.0, 2.0)).mean_radiance(), (0.5, 1.0, 2.0))


def test_load_exr_round_trip(tmp_path, studio):
    path = write_image(tmp_path / "studio.exr", studio.radiance)
    loaded = envmap.load(path)
    assert loaded.name == "studio.exr"
    assert np.array_equal(loaded.radiance, studio.radiance)
    assert envmap.resolve(str(path)).radiance.shape == studio.radiance.shape
    assert envmap.resolve("builtin").name == "builtin"


def test_load_rejects_other_formats_and_shapes(tmp_path):
    with pytest.raises(MatremapError, match="not an HDR format"):
        envmap.load(tmp_path / "sky.png")
    with pytest.raises(MatremapError, match="does not exist"):
        envmap.load(tmp_path / "missing.exr")
    square = write_image(tmp_path / "cube.exr", np.ones((16, 16, 3), np.float32))
    with pytest.raises(MatremapError, match="lat-long"):
        envmap.load(square)
    with pytest.raises(MatremapError, match="black"):
        envmap.directional_lights(envmap.constant(0.0), 8)


def test_directional_lights_are_unit_deterministic_and_carry_the_power(studio):
    d, i = envmap.directional_lights(studio, 256)
    assert d.shape == (256, 3) and i.shape == (256, 3)
    assert np.allclose(np.linalg.norm(d, axis=1), 1.0)
    d2, i2 = envmap.directional_lights(studio, 256)
    assert np.array_equal(d, d2) and np.array_equal(i, i2)
    # the summed intensity is the map's power: 4 pi x mean radiance (exact for the luminance)
    lum = envmap.LUMINANCE
    assert i.sum(axis=0) @ lum == pytest.approx(4 * math.pi * studio.mean_radiance() @ lum, rel=1e-9)
    # the bright soft boxes get most of the lights
    assert np.median(i @ lum) < (4 * math.pi * studio.mean_radiance() @ lum) / 256 * 1.5


def test_lights_rotate_about_the_vertical_axis(studio):
    d0, i0 = envmap.directional_lights(studio, 32)
    d90, i90 = envmap.directional_lights(studio, 32, rotation_deg=90.0)
    assert np.array_equal(i0, i90)
    assert np.allclose(d90, envmap.rotate_y(d0, 90.0))
    assert np.allclose(d0[:, 1], d90[:, 1])
    d360, _ = envmap.directional_lights(studio, 32, rotation_deg=360.0)
    assert np.array_equal(d0, d360)
    # lookup agrees with the rotation: the radiance seen along a rotated direction is unchanged
    dirs = studio.directions()[::7, ::9].reshape(-1, 3)
    assert np.array_equal(studio.lookup(dirs), studio.lookup(envmap.rotate_y(dirs, 40.0), 40.0))


@pytest.mark.parametrize("count", [128, 256])
def test_furnace_lights(count):
    """sum I max(0, n.w) / pi = 1 for every normal under a unit constant environment."""
    d, i = envmap.directional_lights(envmap.constant(1.0), count)
    n = np.random.default_rng(3).normal(size=(2000, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    e = (i[:, 0, None] * np.maximum(0.0, d @ n.T)).sum(axis=0) / math.pi
    assert np.abs(e - 1.0).max() < 0.02


# -- renders ------------------------------------------------------------------------------------


@pytest.mark.parametrize("geometry", ["sphere", "plane"])
def test_furnace_render(geometry):
    img = render_svbrdf(
        "mitsuba06:diffuse",
        {"reflectance": 1.0},
        {},
        envmap.constant(1.0),
        geometry=geometry,
        resolution=RES,
        lights=256,
    )
    mask = object_mask(geometry, RES)
    assert img.shape == (RES, RES, 3) and img.dtype == np.float32
    assert mask.sum() > 0.3 * RES * RES
    assert np.abs(img[mask] - 1.0).max() < 0.02
    assert np.all(img[~mask] == 0.0)


def test_render_rotation_and_determinism(studio):
    kw = dict(resolution=RES, lights=LIGHTS)
    params = {"alpha": 0.15, "specularReflectance": 0.2, "diffuseReflectance": 0.3}
    a = render_svbrdf("mitsuba06:ward", params, {}, studio, 0.0, **kw)
    b = render_svbrdf("mitsuba06:ward", params, {}, studio, 0.0, **kw)
    assert np.array_equal(a, b)
    c = render_svbrdf("mitsuba06:ward", params, {}, studio, 90.0, **kw)
    assert np.abs(c - a).max() > 0.05
    d = render_svbrdf("mitsuba06:ward", params, {}, studio, 360.0, **kw)
    assert np.array_equal(a, d)


def test_specular_part(studio):
    kw = dict(resolution=32, lights=32, part="specular")
    assert not render_svbrdf("mitsuba06:diffuse", {}, {}, studio, **kw).any()
    ward_diffuse = {"specularReflectance": 0.0, "diffuseReflectance": np.full((4, 8, 3), 0.5)}
    assert not render_svbrdf("mitsuba06:ward", ward_diffuse, {}, studio, **kw).any()
    glossy = {"Roughness": 0.3, "Color": 0.5, "Diffuse Color": 0.5}
    spec = render_svbrdf("cycles:glossy", glossy, {}, studio, **kw)
    full = render_svbrdf("cycles:glossy", glossy, {}, studio, resolution=32, lights=32)
    diff = render_svbrdf("cycles:glossy", glossy, {}, studio, resolution=32, lights=32, part="diffuse")
    assert spec.max() > 0.1
    assert np.allclose(spec + diff, full, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("geometry", ["sphere", "plane"])
def test_flat_normal_map_is_no_normal_map(studio, geometry):
    kw = dict(geometry=geometry, resolution=RES, lights=LIGHTS)
    params = {"alpha": 0.2, "F0": 0.5, "diffuseReflectance": 0.2}
    plain = render_svbrdf("mitsuba06:pbr", params, {}, studio, **kw)
    flat = decode_normal_map(np.broadcast_to([0.5, 0.5, 1.0], (8, 16, 3)))
    assert np.allclose(
        render_svbrdf("mitsuba06:pbr", params, {}, studio, normal_map=flat, **kw), plain, rtol=1e-6, atol=1e-7
    )
    tilted = np.broadcast_to([0.6, 0.0, 0.8], (8, 16, 3))
    assert np.abs(render_svbrdf("mitsuba06:pbr", params, {}, studio, normal_map=tilted, **kw) - plain).max() > 0.02


def test_normal_map_tilts_towards_the_tangent():
    """A normal map leaning towards +u (right) on the plane makes a light from the right brighter."""
    env = np.zeros((32, 64, 3), np.float32)
    env[12:20, 52:56] = 50.0  # a small light at the horizon, to the right (+x) and in front (+z)
    e = envmap.EnvMap(env)
    kw = dict(geometry="plane", resolution=32, lights=64)
    plain = render_svbrdf("mitsuba06:diffuse", {"reflectance": 1.0}, {}, e, **kw)
    right = render_svbrdf(
        "mitsuba06:diffuse", {"reflectance": 1.0}, {}, e, normal_map=np.broadcast_to([0.5, 0.0, 0.866], (4, 4, 3)), **kw
    )
    left = render_svbrdf(
        "mitsuba06:diffuse",
        {"reflectance": 1.0},
        {},
        e,
        normal_map=np.broadcast_to([-0.5, 0.0, 0.866], (4, 4, 3)),
        **kw,
    )
    m = object_mask("plane", 32)
    assert right[m].mean() > plain[m].mean() > left[m].mean()


def test_textured_sphere_shows_the_texture():
    """Left half of the texture dark, right half bright: so are the halves of the sphere."""
    tex = np.full((16, 32, 3), 0.2)
    tex[:, 16:] = 0.8
    tex[:8, 16:, 0] = 0.5  # and the top right quadrant is bluer/greener
    img = render_svbrdf("mitsuba06:diffuse", {"reflectance": tex}, {}, envmap.constant(1.0), resolution=64, lights=256)
    mask = object_mask("sphere", 64)
    left = img[:, :28][mask[:, :28]]
    right = img[:, 36:][mask[:, 36:]]
    assert np.allclose(np.median(left, axis=0), 0.2, atol=0.01)
    assert np.allclose(np.median(right[:, 1:], axis=0), 0.8, atol=0.02)
    top_right = img[:28, 36:][mask[:28, 36:]]
    assert np.median(top_right[:, 0]) == pytest.approx(0.5, abs=0.02)


def test_textured_plane_and_per_pixel_rgb_energy_clamp(studio):
    tex = np.zeros((8, 8))
    tex[4:] = 1.0  # bottom half of the image
    img = render_svbrdf(
        "mitsuba06:ward",
        {"specularReflectance": 0.0, "diffuseReflectance": tex[..., None] * [0.9, 0.5, 0.2]},
        {},
        envmap.constant(1.0),
        geometry="plane",
        resolution=32,
        lights=128,
    )
    m = object_mask("plane", 32)
    top = img[:12][m[:12]]
    bottom = img[20:][m[20:]]
    assert top.max() == 0.0
    assert np.allclose(np.median(bottom, axis=0), [0.9, 0.5, 0.2], atol=0.02)
    # per-pixel energy clamp (max over channels of rho_s + rho_d > 1 rescales) works on [1, C, 1, P]
    over = render_svbrdf(
        "mitsuba06:ward",
        {"specularReflectance": 0.0, "diffuseReflectance": np.full((4, 4, 3), [1.0, 0.5, 0.5])},
        {},
        envmap.constant(1.0),
        geometry="plane",
        resolution=32,
        lights=128,
    )
    assert np.allclose(np.median(over[m], axis=0), [1.0, 0.5, 0.5], atol=0.02)


def test_sample_texture_bilinear():
    tex = np.array([[0.0, 1.0]])
    uv = np.array([[0.25, 0.5], [0.5, 0.5], [0.75, 0.5], [0.0, 0.5]])
    assert np.allclose(sample_texture(tex, uv), [0.0, 0.5, 1.0, 0.0])
    assert np.allclose(sample_texture(tex, uv, wrap_u=True), [0.0, 0.5, 1.0, 0.5])


def test_bad_inputs(studio):
    kw = dict(resolution=16, lights=4)
    with pytest.raises(MatremapError, match="no parameter"):
        render_svbrdf("mitsuba06:ward", {"roughness": 0.1}, {}, studio, **kw)
    with pytest.raises(MatremapError, match="variant"):
        render_svbrdf("mitsuba06:ward", {}, {"variant": "nope"}, studio, **kw)
    with pytest.raises(MatremapError, match="scalar parameter"):
        render_svbrdf("mitsuba06:ward", {"alpha": np.random.default_rng(0).random((4, 4, 3))}, {}, studio, **kw)
    with pytest.raises(MatremapError, match="geometry"):
        render_svbrdf("mitsuba06:ward", {}, {}, studio, geometry="teapot", **kw)
    with pytest.raises(MatremapError, match="part"):
        render_svbrdf("mitsuba06:ward", {}, {}, studio, part="glossy", **kw)
    with pytest.raises(MatremapError, match="normal map"):
        render_svbrdf("mitsuba06:ward", {}, {}, studio, normal_map=np.ones((4, 4)), **kw)


BLENDER_STUDIO = "/usr/share/blender/datafiles/studiolights/world/studio.exr"


def test_blender_studio_light_exr():
    """Debian's blender-data ships CC0 lat-long EXRs: one loads, and 256 lights reproduce its irradiance."""
    import os

    if not os.path.isfile(BLENDER_STUDIO):
        pytest.skip("Debian blender-data not installed: apt-get install blender-data")
    env = envmap.load(BLENDER_STUDIO)
    assert env.radiance.shape == (512, 1024, 3)
    small = envmap.EnvMap(env.radiance.reshape(64, 8, 128, 8, 3).mean(axis=(1, 3)))
    n = np.random.default_rng(5).normal(size=(100, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    dirs = small.directions().reshape(-1, 3)
    power = small.radiance.reshape(-1, 3) * np.repeat(small.solid_angles(), small.width)[:, None]
    reference = np.maximum(0.0, dirs @ n.T).T @ power  # [normals, 3]
    d, i = envmap.directional_lights(env, 256)
    estimate = np.maximum(0.0, d @ n.T).T @ i
    rel = np.abs(estimate - reference).sum(axis=1) / reference.sum(axis=1)
    assert rel.mean() < 0.03 and rel.max() < 0.08
