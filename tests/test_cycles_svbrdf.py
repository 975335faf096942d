"""Textured spheres under an environment map rendered by the real Blender Cycles
(:func:`matremap.renderers.cycles.environment.render_svbrdf_cycles`), checked against the embedded
:func:`matremap.renderers.embedded.environment.render_svbrdf`. Skip without the bpy venv (see tests/test_cycles.py)."""

from __future__ import annotations

import numpy as np
import pytest

from matremap.core import envmap
from matremap.errors import MatremapError
from matremap.renderers.cycles.client import ENV_PYTHON, bpy_available
from matremap.renderers.cycles.environment import render_svbrdf_cycles
from matremap.renderers.cycles.probe import CyclesRenderer
from matremap.renderers.embedded.environment import render_svbrdf
from matremap.renderers.textured import object_mask

needs_bpy = pytest.mark.skipif(
    not bpy_available(),
    reason=f"no bpy venv: python3.11 -m venv .venv-bpy && .venv-bpy/bin/pip install bpy==5.0.1 (or set {ENV_PYTHON})",
)

RES = 64


@pytest.fixture(scope="module")
def cycles():
    r = CyclesRenderer(timeout=600.0)
    yield r
    r.close()


@pytest.fixture(scope="module")
def env():
    return envmap.builtin(64, 128)  # asymmetric: key light up-left, fill right, rim behind


def halves(img: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Mean over the sphere of its left, right, top and bottom halves."""
    h = img.shape[0] // 2
    parts = [
        (slice(None), slice(0, h)),
        (slice(None), slice(h, None)),
        (slice(0, h), slice(None)),
        (slice(h, None), slice(None)),
    ]
    return np.array([img[p][mask[p]].mean() for p in parts])


def test_rejects_other_models(env):
    with pytest.raises(MatremapError, match="cycles:glossy"):
        render_svbrdf_cycles("mitsuba06:ward", {}, None, env)


@needs_bpy
@pytest.mark.parametrize("rotation", [0.0, 90.0])
def test_diffuse_sphere_agrees_with_embedded(cycles, env, rotation):
    mask = object_mask("sphere", RES)
    ref = render_svbrdf("cycles:diffuse", {"Color": 0.7}, None, env, rotation_deg=rotation, resolution=RES, lights=1024)
    img = render_svbrdf_cycles(
        "cycles:diffuse", {"Color": 0.7}, None, env, rotation_deg=rotation, resolution=RES, spp=64, renderer=cycles
    )
    assert img.shape == (RES, RES, 3) and img.dtype == np.float32
    inner = mask & np.roll(mask, 1, 0) & np.roll(mask, -1, 0) & np.roll(mask, 1, 1) & np.roll(mask, -1, 1)
    assert np.mean(np.abs(img[inner] - ref[inner])) / np.mean(ref[inner]) < 0.04
    assert abs(img[mask].mean() / ref[mask].mean() - 1.0) < 0.01
    # orientation: the halves' brightness matches (the map is far from symmetric)
    np.testing.assert_allclose(halves(img, mask), halves(ref, mask), rtol=0.015)
    assert np.abs(img[~mask]).max() < 0.1  # background black (silhouette pixels aside)


@needs_bpy
def test_textured_glossy_sphere_shows_its_texture(cycles):
    env = envmap.constant(1.0)
    tex = np.zeros((16, 32, 3))
    tex[:, :16] = (0.8, 0.1, 0.1)  # u < 0.5: the left half of the visible sphere
    tex[:, 16:] = (0.1, 0.1, 0.8)
    params = {"Color": 0.05, "Roughness": 0.4, "Diffuse Color": tex}
    img = render_svbrdf_cycles("cycles:glossy", params, None, env, resolution=RES, spp=16, renderer=cycles)
    ref = render_svbrdf("cycles:glossy", params, None, env, resolution=RES)
    mask = object_mask("sphere", RES)
    left, right = img[:, : RES // 2 - 4], img[:, RES // 2 + 4 :]
    lm, rm = mask[:, : RES // 2 - 4], mask[:, RES // 2 + 4 :]
    assert left[lm][:, 0].mean() > 3 * left[lm][:, 2].mean()
    assert right[rm][:, 2].mean() > 3 * right[rm][:, 0].mean()
    # as the embedded renderer (a furnace: the diffuse part is the albedo, plus a weak grey lobe)
    for a, b, m in ((left, ref[:, : RES // 2 - 4], lm), (right, ref[:, RES // 2 + 4 :], rm)):
        np.testing.assert_allclose(a[m].mean(axis=0), b[m].mean(axis=0), rtol=0.05)


@needs_bpy
def test_rotation_changes_the_image_and_specular_part(cycles, env):
    params = {"Color": 0.9, "Roughness": 0.3, "Diffuse Color": 0.3}
    a = render_svbrdf_cycles("cycles:glossy", params, None, env, resolution=RES, spp=16, renderer=cycles)
    b = render_svbrdf_cycles(
        "cycles:glossy", params, None, env, rotation_deg=120, resolution=RES, spp=16, renderer=cycles
    )
    again = render_svbrdf_cycles("cycles:glossy", params, None, env, resolution=RES, spp=16, renderer=cycles)
    np.testing.assert_array_equal(a, again)  # fixed seed: deterministic
    mask = object_mask("sphere", RES)
    assert np.mean(np.abs(a[mask] - b[mask])) / np.mean(a[mask]) > 0.2
    spec = render_svbrdf_cycles(
        "cycles:glossy", params, None, env, resolution=RES, part="specular", spp=16, renderer=cycles
    )
    assert 0.1 * a[mask].mean() < spec[mask].mean() < 0.95 * a[mask].mean()


@needs_bpy
@pytest.mark.parametrize("tilt", [(0.5, 0.0), (0.0, 0.5)])
def test_normal_map_orientation_matches_embedded(cycles, env, tilt):
    def nmap(x, y):
        a = np.zeros((16, 32, 3))
        a[..., 0], a[..., 1], a[..., 2] = x, y, np.sqrt(1.0 - x * x - y * y)
        return a

    mask = object_mask("sphere", RES)
    yy, xx = np.mgrid[:RES, :RES]
    c = (RES - 1) / 2
    core = mask & ((xx - c) ** 2 + (yy - c) ** 2 < (0.3 * RES) ** 2)  # away from grazing angles
    img = render_svbrdf_cycles(
        "cycles:diffuse", {"Color": 0.7}, None, env, resolution=RES, spp=64, normal_map=nmap(*tilt), renderer=cycles
    )

    def err(x, y, where=core):
        ref = render_svbrdf(
            "cycles:diffuse", {"Color": 0.7}, None, env, resolution=RES, lights=1024, normal_map=nmap(x, y)
        )
        return np.mean(np.abs(img[where] - ref[where])) / np.mean(ref[where])

    # the emulation follows Cycles' bump shadowing term and geometric cut: what is left is noise
    assert err(*tilt) < 0.05 and err(*tilt, where=mask) < 0.06
    assert err(-tilt[0], -tilt[1]) > 3 * err(*tilt)


@needs_bpy
def test_normal_mapped_diffuse_has_no_bias_against_cycles(cycles, env):
    """A 30-degree bent normal: Cycles darkens the diffuse closure by its bump shadowing term, cuts
    light from below the smooth surface and keeps rim pixels whose bent normal faces away from the
    camera; the emulation does the same, so the mean agrees to well under the 6-8 % it was off."""
    nm = np.zeros((16, 32, 3))
    nm[..., 0], nm[..., 2] = 0.5, np.sqrt(0.75)
    mask = object_mask("sphere", RES)
    img = render_svbrdf_cycles(
        "cycles:diffuse", {"Color": 0.7}, None, env, resolution=RES, spp=128, normal_map=nm, renderer=cycles
    )
    ref = render_svbrdf("cycles:diffuse", {"Color": 0.7}, None, env, resolution=RES, lights=2048, normal_map=nm)
    assert abs(img[mask].mean() / ref[mask].mean() - 1.0) < 0.01


@needs_bpy
def test_probe_renders_still_work_after_an_svbrdf_request(cycles):
    from matremap.core.material import Material
    from matremap.core.scene import Scene

    scene = Scene.probe(resolution=32)
    mats = [Material("cycles:diffuse", {"Color": np.array([0.5] * 3)}, {})]
    before = cycles.render(mats, scene)
    render_svbrdf_cycles(
        "cycles:diffuse", {"Color": 0.7}, None, envmap.constant(1.0), resolution=32, spp=4, renderer=cycles
    )
    np.testing.assert_array_equal(cycles.render(mats, scene), before)


# -- matremap evaluate draws cycles:* map sets with real Cycles ------------------------------------


def _glossy_maps(distribution: str = "multi_ggx"):
    rng = np.random.default_rng(1)
    h, w = 16, 32
    rough = 0.3 + 0.3 * rng.random((h, w))
    col = np.stack([np.full((h, w), 0.9), 0.3 + 0.5 * rng.random((h, w)), np.full((h, w), 0.2)], -1)
    dif = np.stack([np.full((h, w), 0.2), np.full((h, w), 0.5), 0.1 + 0.4 * rng.random((h, w))], -1)
    return ("cycles:glossy", {"Roughness": rough, "Color": col, "Diffuse Color": dif}, {"distribution": distribution})


@needs_bpy
def test_evaluate_draws_cycles_maps_with_real_cycles(env, tmp_path, monkeypatch):
    """evaluate() sends cycles:glossy map sets to the bpy worker (said in results.json), and what
    comes back is the embedded emulation's image up to Monte Carlo noise: measured 3.0 % mean
    absolute difference at 64 spp, mean brightness within 0.1 %."""
    pytest.importorskip("skimage", reason="evaluate needs scikit-image")
    import json

    import matremap.renderers.cycles.environment as cs
    from matremap.svbrdf.evaluate import evaluate

    drawn = []
    real = cs.render_svbrdf_cycles

    def spy(*args, **kwargs):
        img = real(*args, **kwargs)
        drawn.append((args, kwargs, img))
        return img

    monkeypatch.setattr(cs, "render_svbrdf_cycles", spy)
    source = _glossy_maps()
    target = (source[0], {**source[1], "Roughness": 0.9 * source[1]["Roughness"]}, source[2])
    result = evaluate(source, target, env, [30.0], tmp_path / "ev", resolution=RES, lights=64)
    settings = json.loads((tmp_path / "ev" / "results.json").read_text())["settings"]
    assert settings["renderers"] == (
        "source: Blender Cycles (bpy worker, 64 spp), target: Blender Cycles (bpy worker, 64 spp)"
    )
    assert len(drawn) == 4  # source and target, full and specular
    assert 0.0 < result.mean_full < 0.5 and result.irradiance_scale == 1.0
    mask = object_mask("sphere", RES)
    inner = mask & np.roll(mask, 1, 0) & np.roll(mask, -1, 0) & np.roll(mask, 1, 1) & np.roll(mask, -1, 1)
    for args, kwargs, img in drawn:
        model, params, options, env_ = args
        assert kwargs["rotation_deg"] == 30.0 and kwargs["resolution"] == RES
        ref = render_svbrdf(
            model, params, options, env_, rotation_deg=30.0, resolution=RES, lights=1024, part=kwargs["part"]
        )
        assert np.mean(np.abs(img[inner] - ref[inner])) / np.mean(ref[inner]) < 0.05
        assert abs(img[mask].mean() / ref[mask].mean() - 1.0) < 0.01


def test_evaluate_falls_back_to_the_emulation_without_bpy(env, tmp_path, monkeypatch):
    """No bpy venv (or not the sphere): cycles:* maps are drawn by the embedded emulation, with a
    warning that says how to install bpy, and the report says so."""
    pytest.importorskip("skimage", reason="evaluate needs scikit-image")
    import json

    import matremap.renderers.cycles.probe as cycles_module
    from matremap.core.material import SVMaterial
    from matremap.renderers.base import EnvironmentLight
    from matremap.svbrdf.evaluate import evaluate, prepare

    monkeypatch.setattr(cycles_module, "bpy_available", lambda: False)
    source = _glossy_maps()
    with pytest.warns(RuntimeWarning, match=r"embedded emulation.*pip install bpy==5\.0\.1"):
        evaluate(source, source, env, [0.0], tmp_path / "ev", resolution=32, lights=32)
    settings = json.loads((tmp_path / "ev" / "results.json").read_text())["settings"]
    assert settings["renderers"] == "source: embedded emulation, target: embedded emulation"
    monkeypatch.undo()
    with pytest.warns(RuntimeWarning, match="sphere only"):
        r = prepare(SVMaterial.of(source), EnvironmentLight(env, 32), "plane", 32, "full")
    assert r.label == "embedded emulation"


@needs_bpy
def test_principled_maps_render_in_cycles_and_without_specular_are_its_diffuse(cycles, env):
    """cycles:principled maps are drawn by the worker's Principled node: with Specular IOR Level 0
    and Metallic 0 it is the Lambertian of its base colour, as a Diffuse BSDF of that colour."""
    rng = np.random.default_rng(3)
    base = rng.uniform(0.2, 0.8, (16, 32, 3))
    mask = object_mask("sphere", RES)
    p = render_svbrdf_cycles(
        "cycles:principled",
        {"Base Color": base, "Specular IOR Level": 0.0, "Metallic": 0.0, "Roughness": 0.5},
        None,
        env,
        resolution=RES,
        spp=64,
        renderer=cycles,
    )
    d = render_svbrdf_cycles("cycles:diffuse", {"Color": base}, None, env, resolution=RES, spp=64, renderer=cycles)
    assert abs(p[mask].mean() / d[mask].mean() - 1.0) < 0.01
    glossy = render_svbrdf_cycles(
        "cycles:principled", {"Base Color": base, "Roughness": 0.2}, None, env, resolution=RES, spp=64, renderer=cycles
    )
    assert glossy[mask].mean() > 1.02 * p[mask].mean()  # the default specular adds light


def test_raised_glossy_normals_keep_the_mirror_direction_above_the_surface():
    from matremap.renderers.embedded.environment import ensure_valid_specular_reflection

    rng = np.random.default_rng(5)
    ng = np.tile([0.0, 0.0, 1.0], (500, 1))
    view = rng.normal(size=(500, 3))
    view[:, 2] = np.abs(view[:, 2]) + 0.02
    view /= np.linalg.norm(view, axis=1, keepdims=True)
    n = rng.normal(size=(500, 3)) * [0.8, 0.8, 1.0]
    n[:, 2] = np.abs(n[:, 2]) + 0.05
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    out = ensure_valid_specular_reflection(ng, view, n)
    r = 2 * np.sum(out * view, 1)[:, None] * out - view
    threshold = np.minimum(0.9 * view[:, 2], 0.01)
    assert np.all(r[:, 2] >= threshold - 1e-6)
    np.testing.assert_allclose(np.linalg.norm(out, axis=1), 1.0, atol=1e-9)
    r_in = 2 * np.sum(n * view, 1)[:, None] * n - view
    kept = r_in[:, 2] >= threshold
    assert kept.any() and (~kept).any()
    np.testing.assert_array_equal(out[kept], n[kept])  # valid normals are left alone


@needs_bpy
def test_normal_mapped_glossy_agrees_with_cycles(cycles, env):
    """Glossy + Diffuse with a 30-degree bent normal: Cycles raises the glossy normal
    (ensure_valid_specular_reflection) and softens the diffuse one; without the raise the
    emulation was 6 % bright overall and 13-20 % on the rim."""
    nm = np.zeros((16, 32, 3))
    nm[..., 0], nm[..., 2] = 0.5, np.sqrt(0.75)
    params = {"Color": 0.8, "Roughness": 0.3, "Diffuse Color": 0.2}
    mask = object_mask("sphere", RES)
    yy, xx = np.mgrid[:RES, :RES]
    rim = mask & (np.hypot(xx - (RES - 1) / 2, yy - (RES - 1) / 2) > 0.8 * RES / 2)
    img = render_svbrdf_cycles(
        "cycles:glossy", params, None, env, resolution=RES, spp=128, normal_map=nm, renderer=cycles
    )
    ref = render_svbrdf("cycles:glossy", params, None, env, resolution=RES, lights=2048, normal_map=nm)
    assert abs(img[mask].mean() / ref[mask].mean() - 1.0) < 0.015
    assert abs(img[rim].mean() / ref[rim].mean() - 1.0) < 0.03
