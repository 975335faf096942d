"""Mitsuba 3's glasses (dielectric, roughdielectric, thindielectric) as matremap models: their reflection under the
probe's point lights against the real Mitsuba 3 (its ``direct`` integrator: nothing passes through the sphere), and
what they let through in the transmission probe against Mitsuba 3 path-tracing the same scene. Measured (64^2, two
lights): roughdielectric on alpha {0.05, 0.1, 0.3, 0.7} x IOR {1.33, 1.5, 2.0} x {beckmann, ggx} relative RMSE
median 4e-7, worst 1.2e-6 (float32 rounding); the smooth glasses reflect nothing a point light reaches, in both.
The real-renderer tests skip without Mitsuba 3."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest

from matremap.core.material import Material
from matremap.core.scene import Scene
from matremap.renderers import get_renderer, renderer_for

HAS_MITSUBA = importlib.util.find_spec("mitsuba") is not None
needs_mitsuba = pytest.mark.skipif(not HAS_MITSUBA, reason="Mitsuba 3 not installed: pip install 'matremap[mitsuba]'")

GRID = [
    (distribution, alpha, ior)
    for distribution in ("beckmann", "ggx")
    for alpha in (0.05, 0.1, 0.3, 0.7)
    for ior in (1.33, 1.5, 2.0)
]


def relative_rmse(a: np.ndarray, b: np.ndarray, mask: np.ndarray) -> float:
    return float(np.linalg.norm(a[mask] - b[mask]) / np.linalg.norm(b[mask]))


def test_the_embedded_renderer_draws_the_glasses_reflection():
    assert all(renderer_for(f"mitsuba3:{m}") == "embedded" for m in ("dielectric", "roughdielectric", "thindielectric"))
    scene = Scene.probe([0.0], resolution=32)
    low, high, smooth, thin = get_renderer("embedded").render(
        [
            Material.create("mitsuba3:roughdielectric", {"alpha": 0.2, "int_ior": 1.33}),
            Material.create("mitsuba3:roughdielectric", {"alpha": 0.2, "int_ior": 2.0}),
            Material.create("mitsuba3:dielectric", {}),
            Material.create("mitsuba3:thindielectric", {}),
        ],
        scene,
    )
    m = scene.mask()
    assert high[m].mean() > 2.0 * low[m].mean() > 0.0  # a denser glass reflects more
    assert not smooth.any() and not thin.any()  # a delta lobe: no point light reaches it


@needs_mitsuba
def test_roughdielectric_reflection_matches_the_real_mitsuba_3():
    from matremap.renderers.mitsuba3.probe import Mitsuba3Renderer

    scene = Scene.probe([0.0, 45.0], resolution=48)
    materials = [
        Material.create("mitsuba3:roughdielectric", {"distribution": d, "alpha": a, "int_ior": ior, "ext_ior": 1.0})
        for d, a, ior in GRID
    ]
    materials += [
        # eta < 1: water inside a denser medium (the corpus's glasses), total reflection past the critical angle
        Material.create(
            "mitsuba3:roughdielectric", {"distribution": "ggx", "alpha": 0.3, "int_ior": 1.333, "ext_ior": 1.6789}
        ),
        Material.create("mitsuba3:roughdielectric", {"alpha": 0.2, "specular_reflectance": [0.9, 0.5, 0.2]}),
    ]
    ours, theirs = get_renderer("embedded").render(materials, scene), Mitsuba3Renderer().render(materials, scene)
    errors = [relative_rmse(a, b, scene.mask()) for a, b in zip(ours, theirs, strict=True)]
    assert max(errors) < 1e-4, max(zip(errors, (m.to_dict() for m in materials), strict=True), key=lambda e: e[0])


@needs_mitsuba
def test_the_smooth_glasses_reflect_nothing_under_point_lights_in_mitsuba_either():
    from matremap.renderers.mitsuba3.probe import Mitsuba3Renderer

    scene = Scene.probe([0.0, 45.0], resolution=32)
    materials = [Material.create("mitsuba3:dielectric", {}), Material.create("mitsuba3:thindielectric", {})]
    assert not Mitsuba3Renderer().render(materials, scene).any()


# -- what they let through ----------------------------------------------------------------------------


def test_a_glass_is_read_as_mitsuba_applies_it():
    from matremap.core.optics import fresnel_dielectric
    from matremap.renderers.embedded import transmission as tr

    solid = tr.interface_of(Material.create("mitsuba3:dielectric", {"specular_transmittance": [0.9, 0.6, 0.3]}))
    assert np.allclose(solid.tint, [0.81, 0.36, 0.09]) and np.all(solid.weight == 1.0)  # once per crossing: in, out
    assert solid.eta == pytest.approx(1.5046 / 1.000277) and solid.alpha == 0.0 and not solid.thin_walled
    thin = tr.interface_of(Material.create("mitsuba3:thindielectric", {"int_ior": 2.0, "ext_ior": 1.0}))
    cos = np.linspace(0.05, 1.0, 20)
    r = fresnel_dielectric(cos, 2.0)
    # a wall (two of the probe's crossings) lets through 1 - R', R' = 2R / (1 + R): the slab's reflections summed
    assert np.allclose((1.0 - thin.fresnel(cos)) ** 2, 1.0 - 2.0 * r / (1.0 + r)) and thin.thin_walled
    ggx = tr.interface_of(Material.create("mitsuba3:roughdielectric", {"distribution": "ggx", "alpha": 0.3}))
    beckmann = tr.interface_of(Material.create("mitsuba3:roughdielectric", {"distribution": "beckmann", "alpha": 0.3}))
    assert ggx.alpha == 0.3 and beckmann.alpha == pytest.approx(0.3 * 0.517, abs=1e-3)


@pytest.mark.parametrize("model", ["mitsuba3:dielectric", "mitsuba3:roughdielectric", "mitsuba3:thindielectric"])
def test_a_transmission_read_across_onto_a_glass_transmits_as_it_did(model):
    from matremap.renderers.embedded import transmission as tr

    thin = model == "mitsuba3:thindielectric"
    source = Material.create(
        "mtlx:open_pbr_surface",
        {
            "transmission_weight": 1.0,
            "specular_ior": 1.45,
            "specular_roughness": 0.2,
            "transmission_color": [0.9, 0.7, 0.5],
            "geometry_thin_walled": 1.0 if thin else 0.0,
        },
    )
    iface = tr.interface_of(source)
    values, freed = tr.EQUIVALENTS[model](iface)
    back = tr.interface_of(Material.create(model, values))
    assert "specular_transmittance" in freed
    assert np.allclose(back.tint, iface.tint) and back.eta == pytest.approx(iface.eta)
    if model == "mitsuba3:roughdielectric":
        assert back.alpha == pytest.approx(iface.alpha) and "alpha" in freed


RES = 48


def _through(m: Material, samples: int) -> tuple[np.ndarray, np.ndarray]:
    """The embedded probe's and Mitsuba 3's transmission of ``m`` (grey tiles, black environment)."""
    import sys
    from pathlib import Path

    pytest.importorskip("scipy")
    from matremap.core.envmap import constant
    from matremap.renderers.embedded import transmission as tr
    from matremap.renderers.mitsuba3.plugins import bsdf_dict
    from matremap.renderers.mitsuba3.transmission_reference import render_reference

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from transmission_probe import compare

    scene = tr.TransmissionScene(resolution=RES, env=constant(0.0), bounces=12, samples=samples)
    ours = tr.transmitted(m, scene)[0]
    ref = render_reference(1.0, 0.0, resolution=RES, spp=256, bsdf=bsdf_dict(m.model, dict(m.options), m)[0])
    return compare(ours, ref, RES)


@needs_mitsuba
@pytest.mark.parametrize(
    "model, values, samples, mean_tol, rmse_tol",
    [
        ("mitsuba3:dielectric", {"specular_transmittance": [0.9, 0.6, 0.3]}, 1, 0.005, 0.02),
        ("mitsuba3:dielectric", {"int_ior": 1.333, "ext_ior": 1.6789}, 1, 0.015, 0.06),
        (
            "mitsuba3:roughdielectric",
            {"distribution": "ggx", "alpha": 0.1, "int_ior": 1.5, "ext_ior": 1.0},
            64,
            0.02,
            0.05,
        ),
        (
            "mitsuba3:roughdielectric",
            {"distribution": "beckmann", "alpha": 0.3, "int_ior": 1.5, "ext_ior": 1.0},
            64,
            0.03,
            0.06,
        ),
        (
            "mitsuba3:thindielectric",
            {"int_ior": 2.0, "ext_ior": 1.0, "specular_reflectance": [0.0, 0.0, 0.0]},
            1,
            0.005,
            0.05,
        ),
        ("mitsuba3:thindielectric", {}, 1, 0.035, 0.08),
    ],
    ids=["tinted", "eta-below-1", "rough-ggx", "rough-beckmann", "thin-no-interreflection", "thin-bk7"],
)
def test_what_a_glass_lets_through_is_what_mitsuba_traces(grey_tiles, model, values, samples, mean_tol, rmse_tol):
    mean, rmse = _through(Material.create(model, values), samples)
    assert np.all(np.abs(mean) < mean_tol), mean
    assert rmse < rmse_tol, rmse


@pytest.fixture
def grey_tiles(monkeypatch):
    from matremap.renderers.embedded import transmission as tr

    monkeypatch.setattr(tr, "PALETTE", np.ones_like(tr.PALETTE))


# -- end to end ---------------------------------------------------------------------------------------

BK7_ROUGH = """<scene version="3.0.0">
    <bsdf type="roughdielectric" id="glass">
        <string name="int_ior" value="bk7"/>
        <string name="ext_ior" value="air"/>
        <string name="distribution" value="ggx"/>
        <float name="alpha" value="0.1"/>
    </bsdf>
</scene>
"""


def test_a_mitsuba_glass_is_read_and_written_back_as_its_plugin(tmp_path):
    from matremap.formats import read_asset
    from matremap.formats.mitsuba_xml import write

    (tmp_path / "glass.xml").write_text(BK7_ROUGH)
    m = read_asset(tmp_path / "glass.xml", "glass").material()
    assert m.model == "mitsuba3:roughdielectric" and m.options["distribution"] == "ggx"
    assert float(m.values["int_ior"][0]) == 1.5046 and float(m.values["ext_ior"][0]) == 1.000277
    out = write(tmp_path / "out.xml", m)
    assert read_asset(out, read_asset(out).name).material() == m
    if HAS_MITSUBA:
        import mitsuba as mi

        mi.set_variant("scalar_rgb")
        assert "RoughDielectric" in str(mi.load_file(str(out)).shapes()[0].bsdf())


def test_a_rough_bk7_glass_remapped_onto_gltf_keeps_its_transmission(tmp_path, capsys):
    pygltflib = pytest.importorskip("pygltflib", reason="pip install pygltflib")
    from matremap.cli import main

    (tmp_path / "glass.xml").write_text(BK7_ROUGH)
    # metallic 0: remap holds a glTF target's metallic at 1 for a source without a diffuse part (a metal) unless told
    code = main(
        ["remap", str(tmp_path / "glass.xml"), "--to", "gltf:pbr", "--fix", "metallic=0", "-o", str(tmp_path / "out")]
    )
    said = capsys.readouterr()
    text = said.out + said.err
    assert code == 0, text
    fit_error = float(text.split("relative L2 error ")[1].split()[0])
    assert fit_error < 0.05  # measured 0.023
    out = next((tmp_path / "out").rglob("*.gltf"))
    g = pygltflib.GLTF2().load(str(out))
    ext = g.materials[0].extensions
    assert (
        "KHR_materials_transmission" in g.extensionsUsed
        and ext["KHR_materials_transmission"]["transmissionFactor"] > 0.95
    )
    assert ext["KHR_materials_ior"]["ior"] == pytest.approx(1.5, abs=0.02)
    assert g.materials[0].pbrMetallicRoughness.roughnessFactor == pytest.approx(0.316, abs=0.05)  # sqrt(alpha)


def test_a_glass_is_not_taken_for_a_metal(tmp_path, capsys):
    """A glass has no diffuse part; remap took such a source for a metal and held glTF's metallic at 1 (fit error
    0.73). A source that transmits is a dielectric (remap.glass_is_dielectric)."""
    from matremap.cli import main

    (tmp_path / "glass.xml").write_text(BK7_ROUGH)
    assert main(["remap", str(tmp_path / "glass.xml"), "--to", "gltf:pbr", "-o", str(tmp_path / "out")]) == 0
