import math

import numpy as np
import pytest

from matremap.core.fit import COUPLED, part
from matremap.core.material import Material
from matremap.core.optics import f0_from_ior
from matremap.core.scene import Scene
from matremap.errors import MatremapError
from matremap.renderers import get_renderer
from matremap.uniform import fit


def rel(a, b):
    return np.abs(np.asarray(a) / np.asarray(b) - 1.0)


@pytest.mark.parametrize(
    "model, params, fix",
    [
        (
            "mitsuba06:ward",
            {"variant": "ward", "alpha": 0.25, "specularReflectance": 0.15, "diffuseReflectance": 0.4},
            {"variant": "ward"},
        ),
        (
            "mitsuba06:pbr",
            {"distribution": "as", "alpha": 0.3, "F0": 0.08, "diffuseReflectance": 0.2},
            {"distribution": "as"},
        ),
        ("cycles:glossy", {"Roughness": 0.45, "Color": [0.9, 0.6, 0.3], "Diffuse Color": 0.1}, {}),
        (
            "mitsuba06:roughconductor",
            {"distribution": "ggx", "alpha": 0.15, "eta": 1.0, "k": [3.0, 2.0, 1.0]},
            {"distribution": "ggx"},
        ),
        ("mitsuba06:phong", {"exponent": 80.0, "specularReflectance": 0.3, "diffuseReflectance": 0.3}, {}),
        (
            "blender27:ward",
            {
                "specular_slope": 0.2,
                "specular_color": 0.6,
                "diffuse_color": 0.5,
                "specular_intensity": 1.0,
                "diffuse_intensity": 1.0,
            },
            {},
        ),
    ],
)
def test_identity_remap_recovers_parameters(model, params, fix):
    source = Material.create(model, params)
    result = fit(source, model, fix=fix)
    for name, value in source.values.items():
        if np.any(value > 0):
            assert np.all(rel(result.target.values[name], value) < 5e-3), (name, result.target.values[name], value)
    assert result.loss < 1e-3


def test_reproduces_the_authors_ward_to_as_table(reference_rows):
    """F0/rho_s and alpha2 within 0.5 % of the published fits (rows with alpha1 >= 0.03)."""
    rows = [r for r in reference_rows if r["alpha1"] >= 0.03][::61]
    assert len(rows) >= 10
    for r in rows:
        source = Material.create(
            "mitsuba06:ward",
            {
                "variant": "ward",
                "alpha": r["alpha1"],
                "specularReflectance": r["specular1"],
                "diffuseReflectance": 0,
            },
        )
        result = fit(source, "mitsuba06:pbr", fix={"distribution": "as"})
        alpha2 = result.target.values["alpha"][0]
        f0 = result.target.values["F0"][0]
        assert rel(alpha2, r["alpha2"]) < 5e-3, r
        assert rel(f0 / r["specular1"], r["eta2"] / r["specular1"]) < 5e-3, r


@pytest.mark.parametrize("alpha", [0.1, 0.3])
@pytest.mark.parametrize("eta, k", [((1.5, 1.5, 1.5), (0.0, 0.0, 0.0)), ((1.2, 1.0, 0.9), (1.6, 1.2, 0.8))])
def test_conductor_round_trip_through_ward_recovers_f0(alpha, eta, k):
    source = Material.create("mitsuba06:roughconductor", {"distribution": "as", "alpha": alpha, "eta": eta, "k": k})
    there = fit(source, "mitsuba06:ward", fix={"variant": "ward"})
    assert there.target.values["specularReflectance"].max() < 1.0  # Ward's energy clamp stays off
    back = fit(there.target, "mitsuba06:roughconductor", fix={"distribution": "as"})
    f0 = f0_from_ior(source.values["eta"], source.values["k"])
    f0_back = f0_from_ior(back.target.values["eta"], back.target.values["k"])
    assert np.all(rel(f0_back, f0) < 0.01), (f0, f0_back)
    assert rel(back.target.values["alpha"], alpha) < 0.01


def test_two_stage_separates_diffuse_and_specular():
    source = Material.create(
        "mitsuba06:ward",
        {"variant": "ward", "alpha": 0.2, "specularReflectance": 0.1, "diffuseReflectance": [0.6, 0.4, 0.2]},
    )
    result = fit(source, "mitsuba06:pbr", fix={"distribution": "as"})
    assert [s.name for s in result.stages] == ["diffuse", "specular"]
    np.testing.assert_allclose(result.target.values["diffuseReflectance"], [0.6, 0.4, 0.2], rtol=2e-3)
    assert result.loss < 0.02


def test_strategies_run_their_stages_and_three_stage_does_not_lose():
    source = Material.create("mitsuba06:roughplastic", {"alpha": 0.2, "intIOR": 1.5, "diffuseReflectance": 0.3})
    results = {s: fit(source, "mitsuba06:ward", strategy=s) for s in ("simple", "two-stage", "three-stage")}
    assert [s.name for s in results["simple"].stages] == ["full"]
    assert [s.name for s in results["three-stage"].stages] == ["diffuse", "specular", "joint"]
    assert results["three-stage"].loss <= results["two-stage"].loss + 1e-9
    for r in results.values():
        assert r.loss < 0.1


def test_irradiance_is_matched_across_renderer_families():
    """Blender Internal's Lambert has no 1/pi: the scale is 1/pi and colours carry over."""
    source = Material.create(
        "blender27:ward", {"diffuse_color": [0.5, 0.4, 0.3], "diffuse_intensity": 1.0, "specular_intensity": 0.0}
    )
    result = fit(source, "mitsuba06:diffuse")
    assert result.irradiance_scale == pytest.approx(1 / math.pi, rel=1e-6)
    np.testing.assert_allclose(result.target.values["reflectance"], [0.5, 0.4, 0.3], rtol=1e-4)
    same = fit(Material.create("mitsuba06:diffuse"), "mitsuba06:diffuse")
    assert same.irradiance_scale == 1.0


class CountingRenderer:
    """Wraps a renderer and counts the images it makes."""

    def __init__(self, inner):
        self.inner, self.name, self.images = inner, inner.name, 0

    def can_render(self, model_id):
        return self.inner.can_render(model_id)

    def render(self, materials, scene):
        self.images += len(materials)
        return self.inner.render(materials, scene)


@pytest.mark.parametrize("strategy", ["simple", "two-stage", "three-stage"])
def test_render_count_is_every_image_rendered(strategy):
    r = CountingRenderer(get_renderer())
    source = Material.create("cycles:glossy", {"Roughness": 0.5, "Color": [0.8, 0.5, 0.2], "Diffuse Color": 0.2})
    result = fit(source, "mitsuba06:pbr", strategy=strategy, source_renderer=r, target_renderer=r)
    assert result.renders == r.images > 0


def test_fit_is_deterministic():
    source = Material.create("mitsuba06:ward", {"alpha": 0.3, "specularReflectance": [0.2, 0.1, 0.05]})
    a = fit(source, "cycles:glossy").to_dict()
    b = fit(source, "cycles:glossy").to_dict()
    for key in ("params", "loss", "renders"):
        assert a[key] == b[key]


def test_fixed_and_freed_parameters():
    source = Material.create("mitsuba06:roughconductor", {"alpha": 0.2})
    held = fit(source, "mitsuba06:roughconductor", fix={"alpha": 0.3})
    assert held.target.values["alpha"][0] == 0.3
    freed = fit(source, "mitsuba06:roughconductor", free=["eta"])
    assert "eta" in freed.stages[-1].params


def test_part_renders_use_the_models_overrides(scene, embedded):
    m = Material.create("mitsuba06:ward", {"alpha": 0.2, "specularReflectance": 0.3, "diffuseReflectance": 0.4})
    full, diffuse, specular = embedded.render([m, part(m, "diffuse"), part(m, "specular")], scene)
    np.testing.assert_allclose(full, diffuse + specular, rtol=1e-5, atol=1e-7)
    assert part(Material.create("mitsuba06:roughconductor"), "diffuse") is None


def test_a_target_without_a_diffuse_part_reports_the_unmatched_energy():
    source = Material.create("mitsuba06:ward", {"diffuseReflectance": 0.5})
    result = fit(source, "mitsuba06:roughconductor")
    assert "no such part" in result.stages[0].message
    assert result.loss > 0.3


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"strategy": "four-stage"}, "unknown strategy"),
        ({"fix": {"alpha": 0.2}, "free": ["alpha"]}, "both fixed and freed"),
        ({"target_renderer": "mitsuba7"}, "unknown renderer"),
        ({"fix": {"alpha": 0.2, "F0": 0.1, "diffuseReflectance": 0.0}}, "nothing to fit"),
    ],
)
def test_bad_fit_requests(kwargs, message):
    with pytest.raises(MatremapError, match=message):
        fit(Material.create("mitsuba06:ward"), "mitsuba06:pbr", **kwargs)


def test_scene_light_positions_change_the_fit_but_not_its_quality():
    source = Material.create(
        "mitsuba06:ward", {"variant": "ward", "alpha": 0.2, "specularReflectance": 0.1, "diffuseReflectance": 0}
    )
    side = fit(source, "mitsuba06:pbr", scene=Scene.probe([45.0]), fix={"distribution": "as"})
    assert side.scene.lights[0].theta == 45.0
    assert side.loss < 0.05


def test_a_sub_pixel_highlight_is_fitted_where_resolved_and_carried_back_to_its_width():
    """At 64x64 a Ward lobe of alpha 0.005 covers a few pixels: the fit is made at a widened lobe and the
    roughness carried back along the fitted power law; Ward onto itself recovers it (it used to come back
    at several times the width, with only a warning)."""
    tiny = Material.create(
        "mitsuba06:ward", {"variant": "ward", "alpha": 0.005, "specularReflectance": 0.1, "diffuseReflectance": 0}
    )
    result = fit(tiny, "mitsuba06:ward", fix={"variant": "ward"}, scene=Scene(resolution=64))
    assert result.warnings and "narrower than the probe resolves" in result.warnings[0]
    assert result.target.values["alpha"][0] == pytest.approx(0.005, rel=0.02)
    np.testing.assert_allclose(result.target.values["specularReflectance"], 0.1, rtol=0.02)


def test_a_mirror_is_never_black_and_never_scored_zero():
    """A glTF chrome (roughness 0) shows nothing under point lights; it is fitted where its lobe is
    resolved: the target is a mirror-like conductor of the same colour, not roughness 1 with error 0."""
    chrome = Material.create("gltf:metal-rough", {"baseColor": [0.95, 0.64, 0.54], "metallic": 1, "roughness": 0})
    r = fit(chrome, "mitsuba06:roughconductor", fix={"distribution": "ggx"}, scene=Scene(resolution=64))
    assert r.target.values["alpha"][0] < 0.01 and 0 < r.loss < 0.05
    assert any("mirror limit" in w for w in r.warnings)
    # its reflectance at normal incidence is the base colour: F0 of the fitted complex IOR (eta 1)
    k = r.target.values["k"]
    np.testing.assert_allclose(k**2 / (4 + k**2), [0.95, 0.64, 0.54], rtol=0.05)
    black = Material.create("mitsuba06:diffuse", {"reflectance": 0.0})
    with pytest.raises(MatremapError, match="renders black on the probe"):
        fit(black, "mitsuba06:ward")
    broad = fit(Material.create("mitsuba06:ward", {"alpha": 0.2}), "mitsuba06:pbr")
    assert broad.warnings == []


def test_a_smooth_dielectric_fitted_all_at_once_keeps_its_reflection():
    """A simple (joint) fit judged the probe's resolution on the full render, where a red plastic's diffuse covers
    the sphere: the mirror's unresolved highlight went unseen, and OpenPBR's specular was switched off (IOR 1,
    roughness 1) at a loss of 0.0000 (the opaque kind of Khronos TransmissionTest's red glass stripes). The specular
    part alone decides, as in staged fits."""
    red = Material.create("gltf:metal-rough", {"baseColor": [0.9, 0.17, 0.09], "metallic": 0, "roughness": 0})
    r = fit(red, "mtlx:open_pbr_surface", strategy="simple", scene=Scene(resolution=64))
    assert any("narrower than the probe resolves" in w for w in r.warnings)
    assert r.target.values["specular_ior"][0] == pytest.approx(1.5, abs=0.05)
    assert r.target.values["specular_roughness"][0] < 0.05
    assert r.loss > 0.001  # the reflection is in what the fit matched


def test_a_principled_dielectric_keeps_its_specular_lobe_in_a_two_stage_fit():
    """Mitsuba 3's principled has no override that draws its specular part alone: two-stage fits took that
    part for black and switched the target's specular off (ior at its minimum), the loss (0.042) hiding it
    behind the diffuse. Its specular goal is now full - diffuse: the fit keeps a dielectric F0 near the
    source's 0.04 and reaches the joint fit's loss."""
    source = Material.create(
        "mitsuba3:principled", {"base_color": [0.8, 0.6, 0.3], "roughness": 0.4, "metallic": 0.0, "specular": 0.5}
    )
    two = fit(source, "usd:preview_surface")
    simple = fit(source, "usd:preview_surface", strategy="simple")
    assert not any("black" in s.message for s in two.stages)
    assert 0.025 < f0_from_ior(float(two.target.values["ior"][0])) < 0.06
    assert two.loss < 1.1 * simple.loss and two.loss < 0.02


def test_a_principled_metal_is_fitted_as_a_metal_in_two_stages():
    """Held at metallic 1, Mitsuba 3's principled has no diffuse part and its whole render is the specular
    part; its specialisation did not say so, and every fit of a sweep from it ended at loss 1."""
    source = Material.create("mitsuba3:principled", {"base_color": [0.8, 0.6, 0.3], "roughness": 0.4, "metallic": 1.0})
    r = fit(source, "usd:preview_surface", fix={"metallic": 1.0})
    assert r.loss < 0.01
    np.testing.assert_allclose(r.target.values["diffuseColor"], [0.8, 0.6, 0.3], atol=0.05)


@pytest.mark.parametrize(
    "target, fix, ior",
    [
        ("mtlx:open_pbr_surface", {"base_metalness": 0.0}, "specular_ior"),
        ("cycles:principled", {"Metallic": 0.0}, "IOR"),
        ("usd:preview_surface", {"metallic": 0.0}, "ior"),
        ("gltf:metal-rough", {"metallic": 0.0}, "ior"),
    ],
)
def test_a_lambertian_switches_the_targets_specular_off_before_its_diffuse_is_fitted(target, fix, ior):
    """A source without a specular part: the target's specular part is switched off first, its IOR at 1 (no
    reflection), and the diffuse fitted as the target draws it without it. Before, by its weights alone and after
    the diffuse: OpenPBR kept its 1.5-IOR layer over a base fitted under it (relative error 0.24; Cycles 0.081,
    UsdPreviewSurface 0.091, glTF 0.033)."""
    src = Material.create("mitsuba3:diffuse", {"reflectance": [0.6, 0.3, 0.2]})
    r = fit(src, target, fix=fix)
    assert r.loss < 1e-3
    assert float(r.target.values[ior][0]) == pytest.approx(1.0)


def test_a_two_stage_fit_whose_parts_are_coupled_is_refined_jointly():
    """roughplastic's diffuse darkens as alpha grows (its tabulated rough transmittance), so the diffuse fitted at
    the starting alpha is too dark at the alpha the specular stage lands on: UsdPreviewSurface at roughness 1 came
    out 0.17 off on the embedded Mitsuba 0.6 model (0.62 on real Mitsuba 3's) although each stage matched."""
    source = Material.create("usd:preview_surface", {"diffuseColor": 0.5, "roughness": 1.0})
    result = fit(source, "mitsuba06:roughplastic", fix={"distribution": "ggx"}, strategy="two-stage")
    assert [s.name for s in result.stages] == ["diffuse", "specular", "joint (coupled parts)"]
    assert result.loss < 0.02
    # parts that do not depend on each other keep their two stages
    plain = fit(source.with_params({"roughness": 0.4}), "mitsuba06:roughplastic", fix={"distribution": "ggx"})
    assert [s.name for s in plain.stages] == ["diffuse", "specular"] and plain.loss < COUPLED
    # a fit as far off as its stage is a target that cannot draw the source (a copper as Ward: Ward's clamp): left
    copper = Material.create(
        "mitsuba06:roughconductor",
        {"distribution": "ggx", "alpha": 0.25, "eta": [0.2, 0.92, 1.1], "k": [3.9, 2.45, 2.14], "extEta": 1.0},
    )
    poor = fit(copper, "mitsuba06:ward", scene=Scene.probe([0.0], resolution=64), fix={"variant": "ward"})
    assert [s.name for s in poor.stages] == ["diffuse", "specular"] and poor.loss > COUPLED
