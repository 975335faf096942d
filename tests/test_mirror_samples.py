"""Environment renders of mirrors and narrow glossy lobes: the embedded renderer's samples about the mirror
direction, combined with the directional lights (renderers/embedded/mirror_samples.py). Checked against the
map itself (a mirror shows what lies along its mirror direction), a furnace, a lights-only render of many lights
(nothing diffuse moves), real Mitsuba 3 (skips without it) and the evaluation's verdict on chrome."""

from __future__ import annotations

import importlib.util
import math

import numpy as np
import pytest
from scipy.ndimage import binary_erosion

from matremap.core import envmap
from matremap.renderers.embedded import mirror_samples as ms
from matremap.renderers.embedded.environment import render_svbrdf
from matremap.renderers.textured import object_mask, surface_pixels
from matremap.svbrdf.evaluate import evaluate

RES = 48
#: a perfect mirror: GGX at the smallest alpha, Fresnel 1
MIRROR = ("mitsuba3:roughconductor", {"alpha": 0.0}, {"distribution": "ggx", "material": "none"})


@pytest.fixture(scope="module")
def studio() -> envmap.EnvMap:
    return envmap.builtin(64, 128)


def inner(res: int = RES) -> np.ndarray:
    return binary_erosion(object_mask("sphere", res), iterations=2)


def test_the_sample_density_integrates_to_one_and_the_pattern_follows_it():
    theta = np.geomspace(ms.THETA_MIN, ms.THETA_MAX, 200_001)
    total = np.trapezoid(ms.density_at(theta) * 2.0 * math.pi * np.sin(theta), theta)
    assert total == pytest.approx(1.0, rel=1e-3)
    assert ms.density_at(np.array([ms.THETA_MIN / 2, ms.THETA_MAX * 1.01])).tolist() == [0.0, 0.0]
    mirror = np.array([[0.0, 0.6, 0.8]])
    d, p = ms.samples(mirror, np.array([[1.0, 0.0, 0.0]]), 64)
    np.testing.assert_allclose(np.linalg.norm(d, axis=-1), 1.0, atol=1e-12)
    angles = np.arccos(np.clip(d[:, 0] @ mirror[0], -1.0, 1.0))
    assert angles.min() < 1e-4 and 0.5 < angles.max() <= ms.THETA_MAX  # from the narrowest lobe to a radian
    # the density the renderer uses for the lights agrees with the samples' own
    np.testing.assert_allclose(ms.density(d[-8:, 0], mirror)[:, 0], p[-8:], rtol=1e-6)


def test_a_mirror_shows_the_map_along_its_mirror_direction(studio):
    img = render_svbrdf(*MIRROR, studio, 40.0, resolution=RES)
    lights_only = render_svbrdf(*MIRROR, studio, 40.0, resolution=RES, mirror_samples=0)
    surf = surface_pixels("sphere", RES)
    r = ms.mirror_directions(surf.normal, surf.view)
    expected = np.zeros((RES * RES, 3))
    expected[surf.pixels] = studio.lookup(r, 40.0)
    expected = expected.reshape(RES, RES, 3)
    m = inner()
    # between the lights, the mirror was black; now it shows the studio, pixel by pixel
    assert lights_only[m].mean() < 0.05 * expected[m].mean()
    rel = np.abs(img[m] - expected[m]).sum(axis=-1) / expected[m].sum(axis=-1)
    assert np.median(rel) < 0.02 and np.mean(rel) < 0.1


def test_a_mirror_in_a_furnace_reflects_it_all():
    img = render_svbrdf(*MIRROR, envmap.constant(1.0), resolution=RES)
    m = inner()
    np.testing.assert_allclose(np.median(img[m]), 1.0, rtol=0.01)
    assert img[m].min() > 0.9


@pytest.mark.parametrize(
    "material",
    [
        ("mitsuba3:principled", {"base_color": [0.7, 0.4, 0.2], "roughness": 0.7}, {}),
        ("mitsuba3:roughconductor", {"alpha": 0.5}, {"distribution": "ggx", "material": "Au"}),
    ],
    ids=["rough-plastic", "rough-gold"],
)
def test_what_the_lights_resolve_does_not_move(studio, material):
    """Multiple importance sampling keeps the estimate unbiased: a rough plastic and a rough gold render as
    four times as many lights alone draw them."""
    reference = render_svbrdf(*material, studio, 10.0, resolution=RES, lights=1024, mirror_samples=0)
    img = render_svbrdf(*material, studio, 10.0, resolution=RES)
    m = inner()
    assert img[m].mean() == pytest.approx(reference[m].mean(), rel=0.01)
    assert np.abs(img[m] - reference[m]).mean() < 0.03 * reference[m].mean()


@pytest.mark.skipif(importlib.util.find_spec("mitsuba") is None, reason="Mitsuba 3 not installed")
@pytest.mark.parametrize("alpha, bound", [(0.0, 0.35), (0.02, 0.2), (0.1, 0.1)])
def test_narrow_lobes_agree_with_mitsuba3(studio, alpha, bound):
    """Real Mitsuba 3 traces the map itself. The lights alone are 0.2-3.4 off it (relative RMSE) at these
    roughnesses and draw a mirror black; with the mirror samples, what is left at alpha 0 is the pixel filter
    (Mitsuba's pixels average a footprint whose mirror directions span the soft boxes' edges)."""
    from matremap.renderers.mitsuba3.environment import render_svbrdf_mitsuba3

    model, params, options = MIRROR[0], {"alpha": alpha}, MIRROR[2]
    ref = render_svbrdf_mitsuba3(model, params, options, studio, 30.0, resolution=RES, spp=256)
    m = inner()

    def error(img: np.ndarray) -> float:
        return float(np.sqrt(((img[m] - ref[m]) ** 2).mean()) / ref[m].mean())

    img = render_svbrdf(model, params, options, studio, 30.0, resolution=RES)
    lights_only = render_svbrdf(model, params, options, studio, 30.0, resolution=RES, mirror_samples=0)
    assert img[m].mean() == pytest.approx(ref[m].mean(), rel=0.04)
    assert error(img) < bound < error(lights_only)


def test_a_model_without_a_glossy_lobe_is_drawn_by_the_lights_alone(studio):
    args = ("mitsuba3:diffuse", {"reflectance": [0.7, 0.4, 0.2]}, {}, studio, 10.0)
    np.testing.assert_array_equal(
        render_svbrdf(*args, resolution=RES), render_svbrdf(*args, resolution=RES, mirror_samples=0)
    )


def test_the_evaluation_sees_the_colour_of_chrome(tmp_path, studio):
    """A white chrome judged against a red one: under the lights alone both drew black (every check 0) and the
    colour went unseen; now the evaluation fails it on colour, and passes chrome against itself."""
    chrome = {"baseColor": [0.95, 0.95, 0.95], "metallic": 1.0, "roughness": 0.0}
    red = dict(chrome, baseColor=[0.9, 0.15, 0.1])
    same = evaluate(
        ("gltf:metal-rough", chrome), ("gltf:metal-rough", chrome), studio, [0, 120], tmp_path / "same", resolution=48
    )
    assert same.verdict.passed
    wrong = evaluate(
        ("gltf:metal-rough", chrome), ("gltf:metal-rough", red), studio, [0, 120], tmp_path / "red", resolution=48
    )
    assert not wrong.verdict.passed
    assert "delta_e" in {c.name for c in wrong.verdict.failed}


def test_a_principled_mirror_is_sampled_too(studio):
    """Mitsuba 3's principled has no specular-only part; its lobe (alpha >= 0.001) is sampled all the same: the
    lights alone draw its chrome black but for a few pixels that catch a light."""
    args = ("mitsuba3:principled", {"base_color": [0.2, 0.2, 0.2], "metallic": 1.0, "roughness": 0.0}, {}, studio)
    m = inner()
    sampled = render_svbrdf(*args, resolution=RES)[m]
    lights_only = render_svbrdf(*args, resolution=RES, mirror_samples=0)[m]
    assert np.median(sampled) > 0.02 > 100 * np.median(lights_only)
