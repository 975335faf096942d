"""Objectives a fit makes small (issue 18): L2 (the paper's), log and SSIM."""

import numpy as np
import pytest
from skimage.metrics import structural_similarity

from matremap.core.material import Material
from matremap.core.objective import OBJECTIVES, SSIM_FLOOR, make
from matremap.core.scene import EnvironmentProbe, Scene
from matremap.errors import MatremapError
from matremap.renderers.base import render_images, render_pixels
from matremap.uniform import fit

WARD = Material.create(
    "mitsuba06:ward",
    {"variant": "ward", "alpha": 0.2, "specularReflectance": 0.06, "diffuseReflectance": [0.4, 0.3, 0.2]},
)
AS = Material.create("mitsuba06:pbr", {"distribution": "as", "alpha": 0.3, "F0": 0.05, "diffuseReflectance": 0.3})


def env(res=48, rotations=(30.0, 150.0), lights=24):
    return Scene(resolution=res, lights=(), environment=EnvironmentProbe("builtin", rotations, lights))


def test_ssim_residuals_are_scikit_images_ssim_per_view(embedded):
    """The ssim objective's square sum is the mean over the sphere pixels of 1 - SSIM as scikit-image computes
    it on each view's whole image (the evaluation's measure), view by view."""
    scene = env()
    src, tgt = render_pixels(embedded, [WARD, AS], scene)
    obj = make("ssim", src, scene)
    s_img, t_img = (render_images(embedded, [m], scene)[0].astype(np.float64) for m in (WARD, AS))
    res = scene.resolution
    expected = []
    for v in range(scene.view_count):
        a, b = s_img[:, v * res : (v + 1) * res], t_img[:, v * res : (v + 1) * res]
        _, full = structural_similarity(a, b, data_range=a.max() - a.min(), channel_axis=-1, full=True)
        mask = scene.views()[v].mask()
        expected.append(full[mask])
    np.testing.assert_allclose(obj.ssim(tgt[None])[0], np.concatenate(expected), atol=1e-9)
    value = float(np.sum(obj.residuals(tgt[None]) ** 2))
    assert value == pytest.approx(1.0 - np.concatenate(expected).mean(), rel=1e-9)


@pytest.mark.parametrize("name", OBJECTIVES)
def test_every_objective_is_zero_at_the_goal_and_grows_away_from_it(name, embedded):
    scene = env(res=32)
    src, tgt = render_pixels(embedded, [WARD, AS], scene)
    obj = make(name, src, scene)
    # (1 - SSIM is floored at SSIM_FLOOR under the ssim objective's root, to keep its derivative finite)
    assert float(np.sum(obj.residuals(src[None]) ** 2)) <= (SSIM_FLOOR if name == "ssim" else 0.0) + 1e-12
    assert float(np.sum(obj.residuals(tgt[None]) ** 2)) > 1e-3


def test_l2_is_the_relative_rmse_squared(embedded):
    scene = Scene(resolution=32)
    src, tgt = render_pixels(embedded, [WARD, AS], scene).astype(np.float64)
    value = float(np.sum(make("l2", src, scene).residuals(tgt[None]) ** 2))
    assert value == pytest.approx((np.linalg.norm(tgt - src) / np.linalg.norm(src)) ** 2, rel=1e-12)


def test_an_unknown_objective_is_refused():
    with pytest.raises(MatremapError, match="unknown objective 'psnr'"):
        fit(WARD, "mitsuba06:pbr", fix={"distribution": "as"}, objective="psnr")


def test_the_ssim_stage_refines_the_headlight_fit_and_never_worsens_its_measure():
    """Under an environment probe the L2 stages are made under the headlight (and, for a second start, under
    the environment); the ssim stage runs from both on the environment, keeps alpha at least half the
    headlight's (a narrower lobe would vanish between the environment's lights), and only takes steps that
    lower 1 - SSIM: it ends no worse than either start."""
    scene = env(res=32, lights=16)
    headlight = fit(WARD, "mitsuba06:pbr", "two-stage", Scene(resolution=128), fix={"distribution": "as"})
    l2 = fit(WARD, "mitsuba06:pbr", "two-stage", scene, fix={"distribution": "as"})
    ssim = fit(WARD, "mitsuba06:pbr", "two-stage", scene, fix={"distribution": "as"}, objective="ssim")
    assert [s.name for s in ssim.stages] == [
        "headlight diffuse",
        "headlight specular",
        "environment diffuse",
        "environment specular",
        "ssim",
        "ssim",
    ]
    assert ssim.objective == "ssim" and l2.objective == "l2"
    measure = make("ssim", l2_goal(scene), scene)
    from matremap.renderers.embedded import EmbeddedRenderer

    r = EmbeddedRenderer()

    def one_minus_ssim(m):
        return float(np.sum(measure.residuals(render_pixels(r, [m], scene).astype(float)) ** 2))

    assert ssim.loss == pytest.approx(one_minus_ssim(ssim.target), rel=1e-9)  # under ssim: the mean 1 - SSIM
    assert ssim.loss <= one_minus_ssim(headlight.target) + 1e-12
    assert ssim.loss <= one_minus_ssim(l2.target) + 1e-12 and ssim.loss < 0.98 * one_minus_ssim(headlight.target)
    a0, a1 = float(headlight.target.values["alpha"][0]), float(ssim.target.values["alpha"][0])
    assert a1 >= a0 / 2 - 1e-12
    assert ssim.to_dict()["objective"] == "ssim" and ssim.relative_rmse > 0
    assert l2.loss == pytest.approx(l2.relative_rmse)


def l2_goal(scene):
    from matremap.renderers.embedded import EmbeddedRenderer

    return render_pixels(EmbeddedRenderer(), [WARD], scene)[0].astype(np.float64)


def test_the_point_probe_and_l2_are_the_default_and_unchanged(embedded):
    """The paper's set-up is still the default: no objective stage, the same result as before objectives."""
    r = fit(WARD, "mitsuba06:pbr", fix={"distribution": "as"})
    assert r.objective == "l2" and r.scene.kind == "point"
    assert [s.name for s in r.stages] == ["diffuse", "specular"]
    assert r.relative_rmse == r.loss
