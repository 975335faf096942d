"""The environment probe (issue 18): the sphere under an environment map, in views of one rotation each."""

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from matremap.core.envmap import LUMINANCE, constant, directional_lights, resolve
from matremap.core.material import Material
from matremap.core.scene import FIT_ROTATIONS, EnvironmentProbe, PointLight, Scene, parse_probe
from matremap.errors import MatremapError
from matremap.renderers.base import check_probe, probe_support, render_images, render_pixels
from matremap.renderers.embedded.environment import SVBRDFRender
from matremap.sweep.run import SweepConfig
from matremap.uniform import fit

DATA = Path(__file__).parent / "data" / "envmaps"
STUDIO = DATA / "studio_small_03_256x128.exr"
WARD = Material.create(
    "mitsuba06:ward",
    {"variant": "ward", "alpha": 0.2, "specularReflectance": 0.06, "diffuseReflectance": [0.4, 0.3, 0.2]},
)


def env_scene(res=32, rotations=(30.0,), lights=16, seed=1, env="builtin", point=()):
    probe = EnvironmentProbe.of(env, rotations=rotations, lights=lights, seed=seed)
    return Scene(resolution=res, lights=tuple(PointLight(t) for t in point), environment=probe)


def test_an_environment_view_is_the_evaluation_render_of_the_same_lights(embedded):
    """The probe's view equals the environment face's render (textured.py's sphere, the same directional
    lights), which the evaluation judges with: the fit sees what the judge sees."""
    scene = env_scene(res=48, rotations=(150.0,), lights=24)
    probe = embedded.render([WARD], scene)[0]
    d, i = directional_lights(resolve("builtin"), 24, 150.0, 1)
    evaluation = SVBRDFRender(WARD.model, dict(WARD.values), dict(WARD.options), "sphere", 48).render(d, i)
    mask = scene.mask()
    np.testing.assert_allclose(probe[mask], evaluation[mask], rtol=2e-5, atol=1e-7)
    assert probe[~mask].max() == 0.0


def test_a_white_lambertian_under_a_uniform_environment_reads_its_radiance(embedded):
    """The furnace: a white Lambertian under radiance L from every direction has radiance L; the lights are
    an estimate of that integral, and the view weight is the estimate's own mean (what the render shows)."""
    from matremap.core.scene import white_radiance

    scene = Scene(resolution=32, lights=(), environment=EnvironmentProbe("constant", (0.0,), lights=256))
    img = embedded.render([Material.create("mitsuba06:diffuse", {"reflectance": 1.0})], scene)[0]
    seen = img[scene.mask()] @ LUMINANCE
    assert seen.mean() == pytest.approx(float(constant().radiance[0, 0, 0]), rel=0.05)
    assert white_radiance(scene) == pytest.approx(float(seen.mean()), rel=1e-5)


def test_views_are_side_by_side_and_pixels_follow_the_views(embedded):
    scene = env_scene(res=24, rotations=(30.0, 150.0), lights=8, point=(0.0,))
    assert scene.kind == "mixed" and scene.view_count == 3
    images = render_images(embedded, [WARD], scene)
    assert images.shape == (1, 24, 72, 3)
    pixels = render_pixels(embedded, [WARD], scene)
    np.testing.assert_array_equal(np.take(images.reshape(1, -1, 3), scene.pixel_indices(), axis=1), pixels)
    # view by view: each view is the one-view scene's render times its weight
    views, weights = scene.views(), scene.view_weights()
    per = scene.pixel_indices().size // 3
    for k, (view, w) in enumerate(zip(views, weights, strict=True)):
        alone = render_pixels(embedded, [WARD], view)[0]
        np.testing.assert_allclose(pixels[0, k * per : (k + 1) * per], w * alone, rtol=1e-6)
    assert views[0].environment is None and views[1].environment.rotations == (30.0,)


def test_view_weights_bring_a_white_lambertian_to_one_in_every_view(embedded):
    scene = env_scene(res=32, rotations=FIT_ROTATIONS, lights=32, point=(0.0,))
    pixels = render_pixels(embedded, [Material.create("mitsuba06:diffuse", {"reflectance": 1.0})], scene)[0]
    per = pixels.shape[0] // scene.view_count
    means = [float((pixels[k * per : (k + 1) * per] @ LUMINANCE).mean()) for k in range(scene.view_count)]
    np.testing.assert_allclose(means, 1.0, rtol=1e-4)


def test_a_material_renders_the_same_alone_and_in_a_batch(embedded):
    scene = env_scene(res=32, rotations=(270.0,), lights=64)
    other = Material.create("mitsuba06:pbr", {"distribution": "as", "alpha": 0.3, "F0": 0.5})
    alone = render_pixels(embedded, [WARD], scene)
    batch = render_pixels(embedded, [other] * 5 + [WARD] + [other] * 3, scene)
    assert np.array_equal(alone[0], batch[5])


def test_the_probe_is_part_of_the_sweep_key_and_round_trips():
    point = SweepConfig(source=WARD, target="mitsuba06:pbr")
    assert "environment" not in point.to_dict()["scene"] and "objective" not in point.to_dict()
    env = SweepConfig(source=WARD, target="mitsuba06:pbr", scene=env_scene(), objective="ssim")
    d = env.to_dict()
    assert d["scene"]["environment"]["rotations"] == [30.0] and d["objective"] == "ssim"
    back = SweepConfig.from_dict(json.loads(json.dumps(d)))
    assert back.scene.environment == env.scene.environment and back.objective == "ssim"
    assert back.to_dict() == d


def test_an_environment_file_is_digested_so_an_edited_map_changes_the_key(tmp_path):
    copy = tmp_path / "studio.exr"
    copy.write_bytes(STUDIO.read_bytes())
    a = EnvironmentProbe.of(copy)
    assert len(a.digest) == 64 and a.env == str(copy.resolve())
    data = bytearray(copy.read_bytes())
    data[-100] ^= 0xFF
    copy.write_bytes(bytes(data))
    try:
        b = EnvironmentProbe.of(copy)
    except MatremapError:  # the flipped byte broke the file: refused, which is also fine
        return
    assert b.digest != a.digest


@pytest.mark.parametrize(
    "text, kind, views",
    [("point", "point", 1), ("env", "env", 3), ("mixed", "mixed", 4), (f"env:{STUDIO}", "env", 3)],
)
def test_parse_probe(text, kind, views):
    scene = parse_probe(text)
    assert scene.kind == kind and scene.view_count == views
    assert scene.resolution == (128 if kind == "point" else 64)


@pytest.mark.parametrize("text", ["area", "point:x.exr", "env:missing.exr", "env:notes.txt"])
def test_a_bad_probe_is_one_clear_error(text):
    with pytest.raises(MatremapError) as e:
        parse_probe(text)
    assert "\n" not in str(e.value)


def test_a_renderer_without_environment_probes_refuses_them_by_name(embedded):
    class PointOnly:
        name = "pointonly"

    assert probe_support(PointOnly(), Scene()) is None
    why = probe_support(PointOnly(), env_scene())
    assert why is not None and "pointonly" in why and "--probe point" in why
    with pytest.raises(MatremapError):
        check_probe(PointOnly(), env_scene())
    assert probe_support(embedded, env_scene()) is None
    m = Material.create("mitsuba06:diffuse")
    for scene in (env_scene(), env_scene(rotations=(30.0, 150.0))):  # one view or several: refused alike
        with pytest.raises(MatremapError, match="pointonly"):
            render_pixels(PointOnly(), [m], scene)
        with pytest.raises(MatremapError, match="pointonly"):
            render_images(PointOnly(), [m], scene)


def test_a_self_fit_under_a_coloured_environment_recovers_the_parameters():
    """Under coloured light a grey material renders coloured images: the fitter's grey and packed shortcuts
    must stay off (a packed basis would solve the albedo from the wrong channels)."""
    truth = Material.create(
        "mitsuba06:pbr", {"distribution": "ggx", "alpha": 0.25, "F0": 0.3, "diffuseReflectance": 0.4}
    )
    scene = env_scene(res=32, rotations=(30.0, 150.0), lights=32, env=str(STUDIO))
    assert not scene.grey_lighting
    for strategy in ("two-stage", "separable"):
        r = fit(truth, "mitsuba06:pbr", strategy, scene, fix={"distribution": "ggx"})
        assert r.loss < 1e-3, strategy
        assert float(r.target.values["alpha"][0]) == pytest.approx(0.25, rel=2e-2)
        np.testing.assert_allclose(r.target.values["diffuseReflectance"], 0.4, rtol=2e-2)


def test_fit_cli_under_the_environment_probe(tmp_path):
    out = tmp_path / "fit.json"
    run = subprocess.run(
        [
            sys.executable, "-m", "matremap", "fit", "--source",
            "mitsuba06:pbr,distribution=ggx,alpha=0.3,F0=0.2,diffuseReflectance=0.3",
            "--to", "mitsuba06:pbr", "--fix", "distribution=ggx", "--probe", "env", "--size", "32",
            "--objective", "ssim", "-o", str(out), "--json",
        ],
        capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    record = json.loads(out.read_text())
    assert record["scene"]["environment"]["env"] == "builtin"
    assert record["objective"] == "ssim" and record["loss"] < 1e-3 and record["relative_rmse"] < 1e-2
    bad = subprocess.run(
        [sys.executable, "-m", "matremap", "fit", "--source", "mitsuba06:diffuse", "--to", "mitsuba06:pbr",
         "--probe", "env:nowhere.exr"],
        capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert bad.returncode == 2 and "nowhere.exr" in bad.stderr and "Traceback" not in bad.stderr
    assert math.isfinite(record["loss"])
