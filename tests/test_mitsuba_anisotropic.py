"""Mitsuba 3's anisotropic roughconductor (alpha_u != alpha_v): read from scenes as
``mitsuba3:roughconductor-anisotropic``, drawn by the embedded renderer in the tangent frame of Mitsuba's
sphere (checked against the real Mitsuba 3 on the probe and under an environment, skipped without it),
written back, and remapped onto isotropic targets under a probe that sees both roughnesses."""

from __future__ import annotations

import importlib.util
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from matremap.core.material import Material
from matremap.core.scene import Scene
from matremap.errors import MatremapError
from matremap.formats import read_asset
from matremap.formats.mitsuba_xml import write
from matremap.remap import ANISOTROPIC_PROBE_LIGHTS, RemapJob, anisotropic_probe
from matremap.renderers.embedded.probe import EmbeddedRenderer
from matremap.uniform import fit

MODEL = "mitsuba3:roughconductor-anisotropic"
needs_mitsuba = pytest.mark.skipif(
    importlib.util.find_spec("mitsuba") is None, reason="Mitsuba 3 not installed: pip install 'matremap[mitsuba]'"
)
CASES = [
    (dist, au, av, mat)
    for dist in ("beckmann", "ggx")
    for au, av in ((0.05, 0.3), (0.3, 0.05), (0.5, 0.1), (0.02, 0.4))
    for mat in ("custom", "Au")
]


def aniso(dist: str, au: float, av: float, mat: str) -> Material:
    p = {"distribution": dist, "alpha_u": au, "alpha_v": av, "material": mat}
    if mat == "custom":
        p.update(eta=[0.2, 0.9, 1.1], k=[3.9, 2.4, 2.1])
    return Material.create(MODEL, p)


def rel(a: np.ndarray, b: np.ndarray, mask: np.ndarray) -> float:
    return float(np.linalg.norm(a[mask] - b[mask]) / np.linalg.norm(b[mask]))


@needs_mitsuba
def test_embedded_anisotropic_conductor_matches_mitsuba_on_the_probe():
    """16 cases, two lights: measured 0.9e-6 to 4.4e-6 relative RMSE (Mitsuba 3.9.1, scalar_rgb)."""
    from matremap.renderers.mitsuba3.probe import Mitsuba3Renderer

    scene = Scene.probe([0.0, 30.0], resolution=48)
    mask = scene.mask()
    ours, theirs = EmbeddedRenderer(), Mitsuba3Renderer()
    for case in CASES:
        m = aniso(*case)
        e, r = ours.render([m], scene)[0], theirs.render([m], scene)[0]
        assert rel(e, r, mask) < 1e-5, case
        # the two roughnesses are not interchangeable: the frame is Mitsuba's, not any frame
        swapped = m.with_params({"alpha_u": case[2], "alpha_v": case[1]})
        assert rel(ours.render([swapped], scene)[0], r, mask) > 0.05, case


@needs_mitsuba
def test_embedded_anisotropic_conductor_matches_mitsuba_under_an_environment():
    """Measured 1.4-1.8 % mean relative error at 256 spp (the isotropic diffuse baseline is 0.7-0.8 %);
    with the roughnesses swapped 70-73 %."""
    from scipy.ndimage import binary_erosion

    from matremap.core.envmap import builtin
    from matremap.renderers.embedded.environment import render_svbrdf
    from matremap.renderers.mitsuba3.environment import render_svbrdf_mitsuba3
    from matremap.renderers.textured import object_mask

    env, res = builtin(), 48
    inner = binary_erosion(object_mask("sphere", res), iterations=2)
    options = {"material": "Au", "distribution": "ggx"}

    def err(a: np.ndarray, b: np.ndarray) -> float:
        return float(np.abs(a[inner] - b[inner]).mean() / np.abs(b[inner]).mean())

    params = {"alpha_u": 0.08, "alpha_v": 0.4}
    ref = render_svbrdf(MODEL, params, options, env, 30.0, resolution=res, lights=2048)
    img = render_svbrdf_mitsuba3(MODEL, params, options, env, 30.0, resolution=res, spp=128)
    swapped = render_svbrdf(MODEL, {"alpha_u": 0.4, "alpha_v": 0.08}, options, env, 30.0, resolution=res, lights=2048)
    assert err(ref, img) < 0.03 and err(swapped, img) > 0.3


def test_read_written_and_refused(tmp_path):
    p = tmp_path / "s.xml"
    p.write_text(
        '<scene version="3.0.0"><bsdf type="roughconductor" id="brushed"><string name="material" value="Al"/>'
        '<float name="alpha_u" value="0.05"/><float name="alpha_v" value="0.3"/></bsdf>'
        '<bsdf type="roughconductor" id="maps"><texture type="bitmap" name="alpha_u">'
        '<string name="filename" value="a.png"/></texture><float name="alpha_v" value="0.3"/></bsdf></scene>'
    )
    a = read_asset(p, "brushed")
    assert a.model == MODEL and a.constants == {"alpha_u": 0.05, "alpha_v": 0.3, "material": "Al"}
    with pytest.raises(MatremapError, match="anisotropic roughness given by textures"):
        read_asset(p, "maps")
    out = write(tmp_path / "o.xml", a.material())
    bsdf = ET.parse(out).getroot().find("bsdf")
    assert bsdf.get("type") == "roughconductor" and {f.get("name") for f in bsdf.findall("float")} == {
        "alpha_u",
        "alpha_v",
    }
    assert read_asset(out).material() == a.material()
    if importlib.util.find_spec("mitsuba") is not None:
        import mitsuba as mi

        mi.set_variant("scalar_rgb")
        params = mi.traverse(mi.load_file(str(out)))
        assert params["material.alpha_u.value"] == pytest.approx(0.05)
        assert params["material.alpha_v.value"] == pytest.approx(0.3)


def test_the_headlight_cannot_see_anisotropy_so_remaps_add_an_oblique_light():
    """Under the headlight the half vector has no component along the sphere's tangent: alpha_u only scales
    the image (D's 1/(pi au av)), and an isotropic fit trades it for a darker F0 at ~0 error. With a light 45
    degrees off the view axis the same fit leaves a measurable error, for the quality gate to judge."""
    source = aniso("ggx", 0.4, 0.2, "Au")
    blind = fit(source, "mitsuba3:roughconductor", fix={"distribution": "ggx"}, scene=Scene())
    seeing = fit(source, "mitsuba3:roughconductor", fix={"distribution": "ggx"}, scene=Scene.probe([0.0, 45.0]))
    assert blind.loss < 1e-3 < 0.1 < seeing.loss
    iso = aniso("ggx", 0.3, 0.3, "Au")
    assert fit(iso, "mitsuba3:roughconductor", fix={"distribution": "ggx"}, scene=Scene.probe([0.0, 45.0])).loss < 0.01
    notes: list[str] = []
    job = anisotropic_probe(RemapJob("gltf:metal-rough"), MODEL, notes.append)
    assert job.scene is not None and tuple(li.theta for li in job.scene.lights) == ANISOTROPIC_PROBE_LIGHTS
    assert anisotropic_probe(RemapJob("gltf:metal-rough"), "mitsuba3:roughconductor", notes.append).scene is None
    assert len(notes) == 1 and "anisotropic" in notes[0]


WHITE_METAL = {"baseColor": 1.0, "metallic": 1.0, "roughness": 0.4}


def conductor_f0(m: Material) -> float:
    """F0 of a conductor with eta + i k at normal incidence (grey)."""
    eta, k = float(np.mean(m.values["eta"])), float(np.mean(m.values["k"]))
    return ((eta - 1.0) ** 2 + k * k) / ((eta + 1.0) ** 2 + k * k)


def test_an_isotropic_source_stays_isotropic():
    """A white glTF metal onto the anisotropic conductor keeps alpha_v = alpha_u and F0 = 1. Untied under the
    headlight, alpha_u only scales the image: the fit took alpha_u 0.031, alpha_v 0.16 and F0 0.19 at 7e-4
    error. Freed by the user or fitted from an anisotropic source, the pair is fitted apart; a fixed alpha_u
    holds alpha_v at its value."""
    source = Material.create("gltf:metal-rough", WHITE_METAL)
    ggx = {"distribution": "ggx"}
    for scene in (None, Scene.probe(ANISOTROPIC_PROBE_LIGHTS)):
        r = fit(source, MODEL, fix=ggx, scene=scene)
        v = r.target.values
        assert v["alpha_u"] == pytest.approx(v["alpha_v"], abs=0.0) and 0.14 < float(v["alpha_u"][0]) < 0.18
        assert conductor_f0(r.target) > 0.99 and r.loss < 0.01
    held = fit(source, MODEL, fix={**ggx, "alpha_u": 0.25})
    assert float(held.target.values["alpha_v"][0]) == 0.25
    freed = fit(source, MODEL, fix=ggx, free=["alpha_v"], scene=Scene.probe(ANISOTROPIC_PROBE_LIGHTS))
    assert freed.target.values["alpha_u"][0] != freed.target.values["alpha_v"][0] and freed.loss < 0.01
    apart = fit(aniso("ggx", 0.3, 0.1, "Au"), MODEL, fix=ggx, scene=Scene.probe(ANISOTROPIC_PROBE_LIGHTS))
    assert apart.target.values["alpha_u"][0] == pytest.approx(0.3, rel=0.05)
    assert apart.target.values["alpha_v"][0] == pytest.approx(0.1, rel=0.05)


@needs_mitsuba
def test_embedded_anisotropic_conductor_matches_mitsuba_at_several_eta_and_k():
    """Mitsuba 3's conductor Fresnel of eta + i k under the anisotropic lobe, lights on both sides and grazing:
    measured 8e-6 worst relative RMSE (Mitsuba 3.9.1, scalar_rgb)."""
    from matremap.renderers.mitsuba3.probe import Mitsuba3Renderer

    materials = [
        Material.create(MODEL, {"distribution": dist, "alpha_u": au, "alpha_v": av, "eta": eta, "k": k})
        for dist in ("beckmann", "ggx")
        for au, av in ((0.05, 0.3), (0.6, 0.15), (0.16, 0.16), (0.9, 0.02))
        for eta, k in ((1.0, 1.09), (1.5, 0.2), ([0.2, 0.9, 1.1], [3.9, 2.4, 2.1]), (3.0, 5.0))
    ]
    for lights in ([0.0, 45.0], [-30.0, 60.0], [75.0]):
        scene = Scene.probe(lights, resolution=48)
        mask = scene.mask()
        ours, theirs = EmbeddedRenderer().render(materials, scene), Mitsuba3Renderer().render(materials, scene)
        for m, e, r in zip(materials, ours, theirs, strict=True):
            assert rel(e, r, mask) < 2e-5, (lights, m.to_dict()["params"])


@needs_mitsuba
def test_a_white_metal_remapped_onto_the_anisotropic_conductor_renders_like_it_in_mitsuba(tmp_path):
    """The remapped conductor drawn by the real Mitsuba 3 under lights that see both roughnesses looks like the
    source (measured 5e-4 relative RMSE); the untied fit rendered 38 % darker there (0.29 mean for the source's
    0.46) while the gate, on the headlight, passed it at 7e-4."""
    from matremap.remap import remap_file
    from matremap.renderers.mitsuba3.probe import Mitsuba3Renderer

    gltf = tmp_path / "white.gltf"
    gltf.write_text(
        '{"asset": {"version": "2.0"}, "materials": [{"name": "white", "pbrMetallicRoughness": '
        '{"baseColorFactor": [1, 1, 1, 1], "metallicFactor": 1, "roughnessFactor": 0.4}}]}'
    )
    result = remap_file(gltf, MODEL, tmp_path / "out", fix={"distribution": "ggx"}, log=lambda _: None)
    assert result.verdict.passed
    fitted = result.material
    assert fitted.model == MODEL and fitted.values["alpha_u"][0] == fitted.values["alpha_v"][0]
    target = read_asset(result.file).material()  # as the written scene gives it (alpha_u = alpha_v: its alpha)
    source = Material.create("gltf:metal-rough", WHITE_METAL)
    for lights in (ANISOTROPIC_PROBE_LIGHTS, (-30.0, 60.0)):
        scene = Scene.probe(lights, resolution=64)
        mask = scene.mask()
        seen = Mitsuba3Renderer().render([target], scene)[0]
        assert rel(seen, EmbeddedRenderer().render([source], scene)[0], mask) < 0.01, lights


def test_maps_of_an_isotropic_source_convert_to_an_isotropic_pair(tmp_path):
    """A sweep of an isotropic source onto the anisotropic conductor fits alpha_v = alpha_u at every point, and the
    converted maps give alpha_v the alpha_u map: a transform's one roughness drives both. The brass glTF example
    onto it: alpha_u a map and alpha_v one constant before (mean 1 - SSIM 0.080), both the map now (0.009)."""
    from matremap.regress.transform import learn_transform
    from matremap.svbrdf.convert import convert
    from matremap.svbrdf.textures import ImageInfo, load_map_set, read_image, write_image_like
    from matremap.sweep.executors import InlineExecutor
    from matremap.sweep.grid import parse_grid
    from matremap.sweep.run import SweepConfig, run_sweep

    source = Material.create("mitsuba06:ward", {"variant": "ward", "diffuseReflectance": 0.0})
    config = SweepConfig(source=source, target=MODEL, fix={"distribution": "ggx"}, scene=Scene(resolution=48))
    db = tmp_path / "w.sqlite"
    grid = parse_grid("alpha=0.05:0.5:3,specularReflectance=0.05:0.2:2", source.spec)
    run_sweep(config, grid, str(db), InlineExecutor())
    maps = tmp_path / "maps"
    maps.mkdir()
    alpha = np.linspace(0.06, 0.45, 8 * 8, dtype=np.float32).reshape(8, 8)
    write_image_like(maps / "a.exr", alpha, ImageInfo("exr", "float32", 1, 0, 0, "linear"))
    (maps / "material.json").write_text(
        '{"model": "mitsuba06:ward", "maps": {"alpha": "a.exr"}, '
        '"params": {"variant": "ward", "diffuseReflectance": 0, "specularReflectance": 0.1}}'
    )
    transform = learn_transform(db)
    values, _ = transform.apply({"alpha": np.array([0.08, 0.3, 0.45])})
    assert np.array_equal(values["alpha_u"], values["alpha_v"]) and np.ptp(values["alpha_u"]) > 0.2
    convert(load_map_set(maps), transform, tmp_path / "out", workers=1)
    out = load_map_set(tmp_path / "out")
    assert out.maps["alpha_v"] == out.maps["alpha_u"] and "alpha_v" not in out.constants
    assert np.ptp(read_image(out.maps["alpha_u"])[0]) > 0.2
