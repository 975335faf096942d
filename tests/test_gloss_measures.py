"""The gate's measures that see gloss: each view's highlight against the source's, for every model (Mitsuba 3's
principled, without a specular-only render, included), and HDR-FLIP."""

from __future__ import annotations

import numpy as np
import pytest

from matremap.core import envmap
from matremap.core.material import SVMaterial
from matremap.svbrdf.evaluate import evaluate, highlight_image, highlight_part
from matremap.svbrdf.gloss import (
    Highlight,
    energy_error,
    facing,
    flip_error,
    highlight,
    median_and_worst,
    sharpness_error,
)
from matremap.svbrdf.quality import Thresholds

pytest.importorskip("skimage", reason="the evaluation needs scikit-image")
pytest.importorskip("flip_evaluator", reason="the gate's HDR-FLIP needs flip-evaluator")

KW = dict(resolution=48, lights=48)


def _lobe(width: float, energy: float = 1.0) -> np.ndarray:
    """A sphere-sized image holding one Gaussian highlight of this width (pixels) and total ``energy``."""
    y, x = np.mgrid[0:64, 0:64] - 32.0
    g = np.exp(-(x**2 + y**2) / (2 * width**2))
    g *= energy / g.sum()
    return np.repeat(g[..., None], 3, axis=-1)


def test_a_sharper_or_duller_lobe_of_the_same_energy_changes_sharpness_not_energy():
    mask = np.ones((64, 64), dtype=bool)
    full = _lobe(4.0) + 1e-3
    base = highlight(_lobe(4.0), full, mask)
    for w, sign in ((4.0 / 1.5, 1.0), (4.0 * 1.5, -1.0)):
        other = highlight(_lobe(w), full, mask)
        assert abs(energy_error(base, other)) < 0.05
        assert sign * sharpness_error(base, other) > 0.3  # the narrower lobe is sharper, the wider duller
    assert sharpness_error(base, highlight(_lobe(4.0), full, mask)) == 0.0


def test_a_removed_or_invented_highlight_is_infinitely_off():
    seen = Highlight(energy=0.1, sharpness=5.0, full=1.0)
    none = Highlight(energy=0.0, sharpness=0.0, full=1.0)
    assert energy_error(seen, none) == float("-inf") and energy_error(none, seen) == float("inf")
    assert energy_error(none, none) == 0.0 and sharpness_error(seen, none) == 0.0


def test_flip_is_zero_for_identical_images_and_grows_with_a_change():
    rng = np.random.default_rng(0)
    img = 0.2 + rng.random((32, 32, 3)).astype(np.float32)
    mask = np.ones((32, 32), dtype=bool)
    assert flip_error(img, img.copy(), mask) == pytest.approx(0.0, abs=1e-6)
    assert flip_error(img, 0.5 * img, mask) > flip_error(img, 0.9 * img, mask) > 0.0


def test_principled_has_a_highlight_image_from_its_diffuse_part():
    """Mitsuba 3's principled has no specular-only render (its metallic lobe takes the base colour): its
    highlight is its full render less its diffuse-only render, not black."""
    plastic = SVMaterial("mitsuba3:principled", {"base_color": np.array([0.6, 0.1, 0.1]), "roughness": 0.3}, {}, None)
    assert highlight_part(plastic) == "diffuse"
    metal = SVMaterial("mitsuba3:principled", {"base_color": np.array([0.9, 0.6, 0.3]), "metallic": 1.0}, {}, None)
    assert highlight_part(metal) == "specular"  # a metal's whole render is its specular part
    assert highlight_part(SVMaterial("mitsuba06:ward", {"alpha": 0.2}, {}, None)) == "specular"
    full, diffuse = np.full((2, 2, 3), 0.5), np.full((2, 2, 3), 0.3)
    assert np.allclose(highlight_image(full, diffuse, "diffuse"), 0.2)


def test_principled_evaluation_compares_highlights(tmp_path):
    """The report's specular-only images of a principled material show its highlight (they were black), and a
    lobe 1.5 times duller fails the gate on it."""
    pytest.importorskip("mitsuba", reason="Mitsuba 3 draws principled")
    env = envmap.builtin(32, 64)
    values = {"base_color": np.array([0.6, 0.1, 0.1]), "roughness": 0.25, "specular": 0.5}
    src = ("mitsuba3:principled", values, {}, None)
    same = evaluate(src, src, env, [0.0], tmp_path / "same", **KW)
    assert same.verdict.passed, same.verdict.line()
    import OpenImageIO as oiio

    spec = oiio.ImageBuf(str(tmp_path / "same" / "images" / "r000_specular_source.png")).get_pixels()
    assert spec.max() > 0.2  # the highlight shows
    duller = ("mitsuba3:principled", {**values, "roughness": 0.25 * 1.5**0.5}, {}, None)
    bad = evaluate(src, duller, env, [0.0], tmp_path / "duller", thresholds=Thresholds.calibrated(), **KW)
    assert not bad.verdict.passed
    assert "highlight" in bad.verdict.line() or "flip" in bad.verdict.line()


def _ward(alpha: float, specular: float = 0.15) -> tuple:
    rng = np.random.default_rng(7)
    diffuse = 0.1 + 0.4 * rng.random((8, 16, 3))
    return (
        "mitsuba06:ward",
        {"alpha": alpha, "specularReflectance": specular, "diffuseReflectance": diffuse},
        {},
        None,
    )


@pytest.mark.parametrize(
    ("change", "measure"),
    [
        (_ward(0.15 * 1.5), "highlight_sharpness"),
        (_ward(0.15 / 1.5), "highlight_sharpness"),
        (_ward(0.15, 0.0), "highlight_energy"),
    ],
    ids=["duller", "sharper", "removed"],
)
def test_a_gloss_change_fails_the_gate_naming_the_measure_and_view(tmp_path, change, measure):
    """A lobe 1.5 times duller or sharper, or a highlight removed, under a turn of the environment: the old gate
    (1 - SSIM, luminance, CIEDE2000) passed each; the verdict names the measure that fails and its worst view."""
    env = envmap.builtin(32, 64)
    rotations = [0.0, 120.0, 240.0]
    limits = Thresholds.calibrated()
    ok = evaluate(_ward(0.15), _ward(0.15), env, rotations, tmp_path / "ok", thresholds=limits, **KW)
    assert ok.verdict.passed, ok.verdict.line()
    bad = evaluate(_ward(0.15), change, env, rotations, tmp_path / "bad", thresholds=limits, **KW)
    failed = {c.name: c for c in bad.verdict.failed}
    assert measure in failed, bad.verdict.line()
    assert "rotation" in failed[measure].where
    assert {c.name for c in bad.verdict.checks} >= {"highlight_energy", "highlight_sharpness", "flip", "dssim"}


def test_thresholds_take_the_new_measures():
    t = Thresholds.parse(["highlight_sharpness=0.5", "flip=0.2"])
    assert t.highlight_sharpness == 0.5 and t.flip == 0.2


def test_the_median_over_views_reads_a_change_the_same_way_in_most_views():
    """One grazing view where two models' Fresnel differ does not decide it; the view furthest the median's way is
    named."""
    value, where = median_and_worst([0.3, 0.4, -1.5, 0.35], ["r0", "r1", "r2", "r3"])
    assert value == pytest.approx(0.325) and "r1: +0.4" in where and "above" in where
    value, where = median_and_worst([-0.3, -0.5, 2.0], ["r0", "r1", "r2"])
    assert value == pytest.approx(0.3) and "r1" in where and "below" in where


def test_facing_leaves_out_the_rim_of_a_sphere():
    y, x = np.mgrid[0:64, 0:64] - 31.5
    r = np.hypot(x, y) / 30.0
    front = facing(r <= 1.0)
    assert front[r < 0.75].all() and not front[r > 0.85].any()


def test_a_coat_lost_or_invented_is_counted_where_the_target_has_one():
    from matremap.dialects import get_model
    from matremap.svbrdf.quality import layer_checks

    gltf, openpbr, ward = get_model("gltf:pbr"), get_model("mtlx:open_pbr_surface"), get_model("mitsuba06:ward")
    limits = Thresholds.calibrated()

    def count(src, sv, dst, dv):
        (check,) = layer_checks(src, sv, dst, dv, limits)
        return check.value, check.passed, check.where

    assert count(gltf, {"clearcoat": 1.0}, openpbr, {"coat_weight": 0.9})[:2] == (0.0, True)
    lost = count(gltf, {"clearcoat": 1.0}, openpbr, {"coat_weight": 0.03})
    assert lost[:2] == (1.0, False) and "coat lost" in lost[2]
    invented = count(gltf, {"clearcoat": 0.0}, openpbr, {"coat_weight": 0.8})
    assert invented[:2] == (1.0, False) and "coat invented" in invented[2]
    assert count(gltf, {"clearcoat": 1.0}, ward, {})[:2] == (0.0, True)  # no coat to keep: judged by the renders
