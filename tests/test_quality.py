"""The quality gate's measures: each fails for the wrong result it is there to catch (black, grey, hue lost,
flat maps) and passes an identical one."""

from __future__ import annotations

import numpy as np
import pytest

from matremap.errors import MatremapError
from matremap.svbrdf.quality import (
    Check,
    Thresholds,
    Verdict,
    delta_e_2000,
    hue_shift,
    image_checks,
    luminance_error,
    map_checks,
)

pytest.importorskip("colour", reason="the quality gate needs colour-science")


@pytest.fixture
def red_sphere():
    rng = np.random.default_rng(0)
    img = np.zeros((32, 32, 3))
    img[..., 0] = 0.6 + 0.2 * rng.random((32, 32))
    img[..., 1] = 0.1
    img[..., 2] = 0.05
    mask = np.zeros((32, 32), bool)
    mask[4:28, 4:28] = True
    return img, mask


def test_identical_images_pass_every_measure(red_sphere):
    img, mask = red_sphere
    checks = image_checks([("r0", img, img.copy())], mask, Thresholds())
    assert all(c.passed and c.value == pytest.approx(0.0, abs=1e-9) for c in checks)


def test_a_black_result_fails_luminance_and_colour(red_sphere):
    img, mask = red_sphere
    checks = {c.name: c for c in image_checks([("r0", img, 0.0 * img)], mask, Thresholds())}
    assert checks["luminance_error"].value == pytest.approx(1.0) and not checks["luminance_error"].passed
    assert not checks["delta_e"].passed and checks["delta_e_fraction"].value == pytest.approx(1.0)


def test_a_grey_result_of_the_same_brightness_fails_colour_but_not_luminance(red_sphere):
    img, mask = red_sphere
    grey = np.repeat((img @ [0.2126, 0.7152, 0.0722])[..., None], 3, axis=2)
    assert luminance_error(img, grey, mask) == pytest.approx(0.0, abs=1e-9)
    assert delta_e_2000(img, grey, mask).mean() > 20.0  # a saturated red against its grey: measured 26.5
    checks = {c.name: c for c in image_checks([("r0", img, grey)], mask, Thresholds())}
    assert checks["luminance_error"].passed and not checks["delta_e"].passed


def test_hue_shift_counts_lost_and_rotated_hues():
    red = np.tile([0.8, 0.1, 0.1], (100, 1))
    assert hue_shift(red, red * 0.3) == pytest.approx(0.0)  # darker, same hue
    assert hue_shift(red, np.tile([0.1, 0.8, 0.1], (100, 1))) == pytest.approx(120.0)
    assert hue_shift(red, np.full((100, 3), 0.5)) == pytest.approx(180.0)  # grey: the hue is lost
    assert hue_shift(np.full((100, 3), 0.5), red) == 0.0  # nothing saturated in the source to keep


def test_map_checks_flag_flat_and_grey_outputs():
    rng = np.random.default_rng(1)
    base = np.stack([0.5 + 0.4 * rng.random(400), np.full(400, 0.1), np.full(400, 0.1)], -1)
    ok = {c.name: c for c in map_checks({"diffuse": base}, {"diffuse": 0.9 * base}, Thresholds())}
    assert ok["hue_shift"].passed and ok["flat"].passed
    flat = {c.name: c for c in map_checks({"diffuse": base}, {"diffuse": np.zeros_like(base)}, Thresholds())}
    assert not flat["flat"].passed and "diffuse" in flat["flat"].where
    grey = {
        c.name: c
        for c in map_checks({"diffuse": base}, {"diffuse": base.mean(-1, keepdims=True) + 0 * base}, Thresholds())
    }
    assert not grey["hue_shift"].passed


def test_verdict_line_names_the_worst_failure():
    v = Verdict(
        [
            Check("dssim", 0.1, 0.4),
            Check("luminance_error", 0.9, 0.25, "full, rotation 60"),
            Check("hue_shift", 30.0, 25.0),
        ]
    )
    assert not v.passed and len(v.failed) == 2
    assert v.line().startswith("FAILED: luminance_error 0.9 > 0.25 (full, rotation 60)")
    assert Verdict([Check("dssim", 0.1, 0.4)]).line().startswith("PASSED")


def test_thresholds_parse_and_refuse_nonsense():
    t = Thresholds.parse(["luminance_error=0.1", "hue-shift=10"])
    assert t.luminance_error == 0.1 and t.hue_shift == 10.0 and t.delta_e == Thresholds().delta_e
    for bad in ("nope=1", "delta_e", "delta_e=x", "delta_e=-1", "delta_e=nan"):
        with pytest.raises(MatremapError, match="--max-error"):
            Thresholds.parse([bad])


def test_two_black_renders_agree_and_a_black_source_says_so():
    """A mirror under directional lights renders black: 1e-21 on one side and 0 on the other read a luminance error
    of 1 (or 1e18), failing a remap between two black images. Below DARK a render is black; a target that shows
    something where the source is black fails with the reason."""
    from matremap.svbrdf.quality import Thresholds, image_checks, luminance_error

    mask = np.ones((4, 4), dtype=bool)
    black, faint, lit = np.zeros((4, 4, 3)), np.full((4, 4, 3), 1e-21), np.full((4, 4, 3), 0.2)
    assert luminance_error(faint, black, mask) == 0.0 and luminance_error(black, faint, mask) == 0.0
    lum = next(c for c in image_checks([("view", faint, black)], mask, Thresholds()) if c.name == "luminance_error")
    assert lum.value == 0.0 and lum.passed
    lum = next(c for c in image_checks([("view", black, lit)], mask, Thresholds()) if c.name == "luminance_error")
    assert lum.value == float("inf") and "the source renders black, the target does not" in lum.where
    assert luminance_error(lit, 1.1 * lit, mask) == pytest.approx(0.1)
