import math

import numpy as np
import pytest

from matremap.core.material import Material
from matremap.core.scene import PointLight, Scene
from matremap.errors import MatremapError


def test_sphere_fills_the_frame_with_a_small_margin(scene):
    mask = scene.mask()
    assert mask.shape == (128, 128)
    # silhouette radius in pixels: half the image divided by the 5 % margin
    r_px = 64 / 1.05
    assert mask.sum() == pytest.approx(math.pi * r_px**2, rel=5e-3)
    assert not mask[0].any() and not mask[:, 0].any()


def test_lambertian_sphere_matches_the_radiometric_formula(scene, embedded):
    """L = rho/pi * I cos(theta_i) / d^2 for a point light, at every sphere pixel."""
    rho = 0.7
    img = embedded.render([Material.create("mitsuba06:diffuse", {"reflectance": rho})], scene)[0]
    p = scene.sphere_points()
    light = scene.light_position(scene.lights[0])
    to_light = light - p
    d2 = np.sum(to_light**2, axis=1)
    cos_i = np.sum(p / 2.0 * to_light, axis=1) / np.sqrt(d2)
    expected = rho / math.pi * scene.light_intensity(scene.lights[0]) * np.maximum(cos_i, 0) / d2
    np.testing.assert_allclose(img[scene.mask()][:, 1], expected, rtol=1e-6)
    assert img[~scene.mask()].max() == 0.0


def test_white_lambertian_facing_a_headlight_reads_one(scene, embedded):
    img = embedded.render([Material.create("mitsuba06:diffuse", {"reflectance": 1.0})], scene)[0]
    assert img[63:65, 63:65].mean() == pytest.approx(1.0, abs=2e-3)


def test_images_are_float32_batches_and_bitwise_deterministic(scene, embedded):
    a = Material.create("mitsuba06:ward", {"alpha": 0.2})
    b = Material.create("cycles:glossy", {"Roughness": 0.4})
    batch = embedded.render([a, b, a], scene)
    assert batch.dtype == np.float32 and batch.shape == (3, 128, 128, 3)
    assert np.array_equal(batch[0], batch[2])
    assert np.array_equal(batch[0], embedded.render([a], scene)[0])
    assert np.array_equal(batch[1], embedded.render([b], scene)[0])


def test_light_angle_moves_the_highlight(embedded):
    m = Material.create("mitsuba06:ward", {"alpha": 0.05, "diffuseReflectance": 0.0})
    head = embedded.render([m], Scene.probe([0]))[0, ..., 0]
    side = embedded.render([m], Scene.probe([45]))[0, ..., 0]
    assert np.unravel_index(head.argmax(), head.shape)[1] in (63, 64)
    col = np.unravel_index(side.argmax(), side.shape)[1]
    assert col > 70  # the half vector tilts towards +x: the highlight moves right
    np.testing.assert_allclose(side, side[::-1], rtol=1e-5, atol=1e-7)  # symmetric about the horizon


def test_two_lights_add_up(embedded):
    m = Material.create("mitsuba06:diffuse")
    both = embedded.render([m], Scene.probe([0, 45]))[0]
    one = embedded.render([m], Scene.probe([0]))[0] + embedded.render([m], Scene.probe([45]))[0]
    np.testing.assert_allclose(both, one, rtol=1e-6)


def test_scene_round_trips_through_a_dict():
    s = Scene(resolution=64, lights=(PointLight(45.0),))
    assert Scene.from_dict(s.to_dict()).to_dict() == s.to_dict()


@pytest.mark.parametrize("kwargs", [{"resolution": 2}, {"lights": ()}, {"lights": (PointLight(95.0),)}])
def test_bad_scenes_are_refused(kwargs):
    with pytest.raises(MatremapError):
        Scene(**kwargs)


def test_sphere_pixels_fast_path_equals_the_masked_image(scene, embedded):
    from matremap.renderers.base import render_pixels

    mats = [Material.create("mitsuba06:pbr", {"F0": [0.9, 0.5, 0.2]}), Material.create("cycles:glossy")]
    images = embedded.render(mats, scene)
    assert np.array_equal(render_pixels(embedded, mats, scene), images[:, scene.mask()])
