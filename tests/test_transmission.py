"""The transmission probe (renderers/embedded/transmission.py) and the transmission parameters of gltf:pbr
(KHR_materials_transmission / _volume) and mtlx:open_pbr_surface: Snell's law and the Fresnel split checked
against plain vector maths written here, energy (a non-absorbing sphere in a white world transmits 1 - F of the
entry), Beer-Lambert, thin walls, roughness blurring, and the reflection-only evaluators."""

from __future__ import annotations

import math

import numpy as np
import pytest

from matremap.core.envmap import constant
from matremap.core.material import Material
from matremap.core.optics import fresnel_dielectric
from matremap.core.scene import Scene
from matremap.renderers import get_renderer
from matremap.renderers.embedded import transmission as tr
from matremap.renderers.textured import surface_pixels

RES = 48
WHITE_WORLD = tr.TransmissionScene(resolution=RES, plane_half_size=0.0, env=constant(1.0), bounces=40)


def glass(**kw) -> Material:
    values = {"transmission_weight": 1.0, "specular_ior": 1.5, "specular_roughness": 0.0, **kw}
    return Material.create("mtlx:open_pbr_surface", values)


def gltf_glass(**kw) -> Material:
    values = {"transmission": 1.0, "metallic": 0.0, "roughness": 0.0, "baseColor": 1.0, "thickness": 1.0, **kw}
    return Material.create("gltf:pbr", values)


def test_a_clear_sphere_in_a_white_world_transmits_all_but_the_entry_reflection():
    """Inside a sphere every internal reflection meets the surface at the entry angle, so with the bounces summed
    a non-absorbing smooth dielectric sends 1 - F(theta_entry) of a white world to the camera."""
    through, mask = tr.transmitted(glass(), WHITE_WORLD)
    surf = surface_pixels("sphere", RES)
    cos_entry = np.sum(surf.normal * surf.view, axis=1)
    want = 1.0 - fresnel_dielectric(cos_entry, 1.5)
    got = through.reshape(-1, 3)[surf.pixels]
    np.testing.assert_allclose(got, np.repeat(want[:, None], 3, axis=1), atol=1e-9)
    assert mask.sum() == len(surf.pixels)


def snell_exit(p: np.ndarray, d: np.ndarray, eta: float) -> tuple[np.ndarray, np.ndarray]:
    """Written out again: refract d at p (sphere of radius 2), cross, refract out; returns exit point and
    direction."""
    n = p / np.linalg.norm(p)
    c = -float(d @ n)
    k = 1.0 - (1.0 - c * c) / eta**2
    t = d / eta + (c / eta - math.sqrt(k)) * n
    t /= np.linalg.norm(t)
    q = p - 2.0 * float(p @ t) * t
    nq = -q / np.linalg.norm(q)  # faces the ray inside
    c2 = -float(t @ nq)
    k2 = 1.0 - (1.0 - c2 * c2) * eta**2
    out = t * eta + (c2 * eta - math.sqrt(k2)) * nq
    return q, out / np.linalg.norm(out)


def test_the_first_exit_follows_snells_law_through_the_sphere():
    """One bounce, a background whose radiance encodes the exit ray: each pixel sees the plane where Snell's
    law (written out above) sends its ray, weighted by (1 - F) at both interfaces."""
    scene = tr.TransmissionScene(resolution=RES, bounces=1, tile=1e-3, plane_half_size=0.0, env=constant(1.0))
    surf = surface_pixels("sphere", RES)
    seen = {}

    def probe_background(origins, directions, scene_, env):
        seen["o"], seen["d"] = origins.copy(), directions.copy()
        return np.ones((len(origins), 3))

    saved = tr.background
    tr.background = probe_background
    try:
        through, _ = tr.transmitted(glass(), scene)
    finally:
        tr.background = saved
    for i in (0, len(surf.pixels) // 3, len(surf.pixels) // 2, len(surf.pixels) - 1):
        p = surf.normal[i] * 2.0
        q, out = snell_exit(p, -surf.view[i], 1.5)
        np.testing.assert_allclose(seen["o"][i], q, atol=1e-9)
        np.testing.assert_allclose(seen["d"][i], out, atol=1e-9)
        c1 = float(surf.normal[i] @ surf.view[i])
        f1 = fresnel_dielectric(c1, 1.5)
        np.testing.assert_allclose(through.reshape(-1, 3)[surf.pixels[i]], (1 - f1) * (1 - f1), rtol=1e-9)


def test_beer_lambert_along_the_diameter():
    """The centre pixel's ray crosses 2 radii: transmission_color^(4 / transmission_depth) against the clear
    sphere, in OpenPBR and in glTF's KHR_materials_volume alike."""
    scene = tr.TransmissionScene(resolution=RES + 1, plane_half_size=0.0, env=constant(1.0), bounces=1)
    colour, depth = np.array([0.8, 0.5, 0.1]), 3.0
    clear, _ = tr.transmitted(glass(), scene)
    honey, _ = tr.transmitted(glass(transmission_color=colour.tolist(), transmission_depth=depth), scene)
    g_honey, _ = tr.transmitted(gltf_glass(attenuationColor=colour.tolist(), attenuationDistance=depth), scene)
    c = RES // 2
    np.testing.assert_allclose(honey[c, c] / clear[c, c], colour ** (4.0 / depth), rtol=1e-3)
    np.testing.assert_allclose(g_honey[c, c] / clear[c, c], colour ** (4.0 / depth), rtol=2e-2)  # Schlick F


def test_a_thin_wall_does_not_bend_and_tints_each_wall():
    """glTF thickness 0 (and OpenPBR geometry_thin_walled): rays go straight through whatever the IOR (glTF at
    IOR 1.5); a smooth wall without reflection (glTF: specular 0; OpenPBR: IOR 1) lets everything through,
    tinted once per wall."""
    scene = tr.TransmissionScene(resolution=RES)
    env = tr.resolve(scene.env)
    tint = [0.9, 0.6, 0.3]
    m = Material.create(
        "gltf:pbr", {"transmission": 1.0, "metallic": 0.0, "roughness": 0.0, "specular": 0.0, "baseColor": tint}
    )
    through, mask = tr.transmitted(m, scene)
    rays = Scene(resolution=RES).camera_rays().reshape(-1, 3)
    straight = tr.background(np.broadcast_to([0.0, 0.0, 8.0], rays.shape).astype(float), rays, scene, env)
    want = straight.reshape(RES, RES, 3) * np.square(tint)
    np.testing.assert_allclose(through[mask], want[mask], atol=1e-9)
    thin = glass(geometry_thin_walled=1.0, specular_ior=1.0 + 1e-9, transmission_color=tint)
    through_o, _ = tr.transmitted(thin, scene)
    np.testing.assert_allclose(through_o[mask], want[mask], rtol=1e-6, atol=1e-9)


def test_roughness_blurs_the_background_seen_through():
    """The tiles' contrast through the sphere falls as the transmission lobe widens."""
    scene = tr.TransmissionScene(resolution=RES, samples=32)
    mask = surface_pixels("sphere", RES).mask()
    spread = [float(np.std(tr.transmitted(glass(specular_roughness=r), scene)[0][mask])) for r in (0.0, 0.2, 0.5)]
    assert spread[0] > spread[1] > spread[2]


def test_vndf_samples_are_visible_normals():
    """Heitz 2018's sampler: normals lie in the upper hemisphere, face the viewer, and for alpha 1 from the
    zenith are cosine-distributed about it (mean cos theta 2/3)."""
    u = tr._points(4096, 3)
    wi = np.tile([[0.3, 0.0, math.sqrt(1 - 0.09)]], (len(u), 1))
    m = tr.sample_vndf(wi, 0.4, u)
    assert np.all(m[:, 2] >= 0) and np.all(np.sum(m * wi, 1) > 0)
    np.testing.assert_allclose(np.linalg.norm(m, axis=1), 1.0, atol=1e-12)
    up = tr.sample_vndf(np.tile([[0.0, 0.0, 1.0]], (len(u), 1)), 1.0, u)
    assert float(np.mean(up[:, 2])) == pytest.approx(2.0 / 3.0, abs=5e-3)


def test_opaque_materials_transmit_nothing_and_others_are_refused():
    through, _ = tr.transmitted(Material.create("mtlx:open_pbr_surface", {"base_color": 0.5}), WHITE_WORLD)
    assert not np.any(through)
    with pytest.raises(Exception, match="transmission probe draws"):
        tr.interface_of(Material.create("mitsuba06:diffuse"))


@pytest.mark.parametrize(
    ("model", "values", "weight"),
    [
        ("gltf:pbr", {"baseColor": [0.6, 0.4, 0.2], "metallic": 0.0, "roughness": 0.5}, "transmission"),
        ("mtlx:open_pbr_surface", {"base_color": [0.6, 0.4, 0.2], "specular_roughness": 0.5}, "transmission_weight"),
        ("mtlx:standard_surface", {"base_color": [0.6, 0.4, 0.2], "specular_roughness": 0.5}, "transmission"),
        ("mitsuba3:principled", {"base_color": [0.6, 0.4, 0.2], "roughness": 0.5}, "spec_trans"),
    ],
)
def test_in_reflection_transmission_takes_the_diffuse_away(model, values, weight):
    """On the opaque probe a fully transmissive base keeps its specular reflection and loses its diffuse: the
    image equals the material with a black base colour; off, it is the model as before, bit for bit."""
    scene = Scene.probe([0.0, 45.0], resolution=40)
    r = get_renderer("embedded")
    black = "baseColor" if model == "gltf:pbr" else "base_color"
    plain, off, full, no_diffuse = r.render(
        [
            Material.create(model, values),
            Material.create(model, {**values, weight: 0.0}),
            Material.create(model, {**values, weight: 1.0}),
            Material.create(model, {**values, black: 0.0}),
        ],
        scene,
    )
    assert np.array_equal(plain, off)
    np.testing.assert_allclose(full, no_diffuse, rtol=1e-6, atol=1e-9)
    assert full.sum() < 0.5 * plain.sum()


def test_the_probe_image_shows_the_sphere_and_the_background():
    img = tr.render(
        glass(transmission_color=[0.9, 0.5, 0.1], transmission_depth=2.0), tr.TransmissionScene(resolution=32)
    )
    mask = surface_pixels("sphere", 32).mask()
    assert img.shape == (32, 32, 3) and img.dtype == np.float32 and np.isfinite(img).all()
    inside, outside = img[mask].mean(axis=0), img[~mask].mean(axis=0)
    assert inside[0] > inside[2] * 2 and outside[2] > 0.5 * outside[0]  # honey-tinted sphere, untinted tiles


@pytest.mark.parametrize(
    "values",
    [
        {"transmission_color": [0.83, 0.57, 0.04]},
        {"transmission_color": [0.8, 0.3, 0.2], "transmission_depth": 1.5},
        {"geometry_thin_walled": 1.0, "transmission_color": [0.5, 0.9, 0.6]},
    ],
)
def test_gltf_equivalent_transmits_as_the_openpbr_source(values):
    """OpenPBR transmission read into glTF's extensions: the same picture in the probe up to the Fresnel forms
    (glTF's Schlick against the exact dielectric Fresnel, F 0.09 against 0.11 at 60 degrees: measured 3.6 %,
    2.6 % and 3.8 % relative RMSE)."""
    scene = tr.TransmissionScene(resolution=RES, bounces=3)
    source = glass(specular_ior=1.45, **values)
    target = Material.create("gltf:pbr", tr.gltf_equivalent(tr.interface_of(source)))
    a, mask = tr.transmitted(source, scene)
    b, _ = tr.transmitted(target, scene)
    rel = np.linalg.norm(a[mask] - b[mask]) / np.linalg.norm(a[mask])
    assert rel < 0.05, rel


def test_standard_surface_transmission_reads_its_spec():
    """Standard Surface 1.0.1 "Specular transmission": transmission (1 - metalness) through the specular lobe's
    GGX and IOR; transmission_color a tint at depth 0, else Beer-Lambert over transmission_depth; thin_walled no
    bending (in and straight out through specular_IOR's microsurface, as MaterialX's graph refracts), a crossing
    losing the specular layer's reflection, and no interior."""

    def iface(**kw):
        values = {"transmission": 1.0, "specular_IOR": 1.6, "specular_roughness": 0.3, **kw}
        return tr.interface_of(Material.create("mtlx:standard_surface", values))

    solid = iface(transmission_color=[0.9, 0.5, 0.2], metalness=0.25)
    assert solid.eta == 1.6 and solid.alpha == pytest.approx(0.09) and not solid.thin_walled
    np.testing.assert_allclose(solid.weight, 0.75)
    np.testing.assert_allclose(solid.tint, [0.9, 0.5, 0.2])
    assert not solid.sigma.any()
    cos = np.array([1.0, 0.5, 0.1])
    np.testing.assert_allclose(solid.fresnel(cos), fresnel_dielectric(cos, 1.6))
    deep = iface(transmission_color=[0.9, 0.5, 0.2], transmission_depth=2.0)
    np.testing.assert_allclose(deep.tint, 1.0)
    np.testing.assert_allclose(np.exp(-deep.sigma * 2.0), [0.9, 0.5, 0.2])
    thin = iface(thin_walled=1.0, transmission_color=[0.5, 0.9, 0.6], specular=0.5)
    assert thin.thin_walled and thin.eta == 1.6
    np.testing.assert_allclose(thin.fresnel(cos), 0.5 * fresnel_dielectric(cos, 1.6))
    np.testing.assert_allclose(thin.tint, [0.5, 0.9, 0.6])
    # without a specular layer a thin wall loses nothing at its crossings: the white world comes through whole
    through, mask = tr.transmitted(
        Material.create(
            "mtlx:standard_surface",
            {"transmission": 1.0, "thin_walled": 1.0, "specular": 0.0, "specular_roughness": 0.0},
        ),
        WHITE_WORLD,
    )
    np.testing.assert_allclose(through[mask], 1.0, atol=1e-9)


def test_a_rough_thin_walled_standard_surface_blurs_as_openpbr_does():
    """A thin wall does not bend, but a rough one blurs what lies behind it: Standard Surface's thin wall drawn with
    the surrounding medium's IOR (eta 1) blurred nothing, and a rough glTF thin glass fitted onto it 0.43 off."""
    scene = tr.TransmissionScene(resolution=RES, samples=32)
    walls = {"specular_roughness": 0.5, "specular_IOR": 1.5}
    ss = Material.create("mtlx:standard_surface", {"transmission": 1.0, "thin_walled": 1.0, **walls})
    smooth = Material.create("mtlx:standard_surface", {"transmission": 1.0, "thin_walled": 1.0, "specular_IOR": 1.5})
    pbr = glass(geometry_thin_walled=1.0, specular_roughness=0.5, specular_ior=1.5)
    a, mask = tr.transmitted(ss, scene)
    b, _ = tr.transmitted(pbr, scene)
    c, _ = tr.transmitted(smooth, scene)
    assert np.linalg.norm(a[mask] - b[mask]) < 0.05 * np.linalg.norm(b[mask])
    assert np.linalg.norm(a[mask] - c[mask]) > 0.2 * np.linalg.norm(c[mask])  # blurred: not the smooth wall's


def test_a_smooth_glass_reflects_the_map_in_the_probe_image():
    """What a smooth glass reflects is in the transmission view (its mirror direction sampled): drawn by the lights
    alone it was missing, the sphere showing only what the glass lets through."""
    scene = tr.TransmissionScene(resolution=RES)
    smooth = glass()
    through, mask = tr.transmitted(smooth, scene)
    image = tr.render(smooth, scene)
    reflected = image[mask] - through[mask].astype(np.float32)
    assert reflected.min() > -1e-5 and reflected.mean() > 0.05 * through[mask].mean()
    # brightest at the rim, where the Fresnel factor rises
    radius = np.hypot(*np.meshgrid(np.arange(RES) - (RES - 1) / 2, np.arange(RES) - (RES - 1) / 2))[mask]
    rim, centre = radius > 0.8 * radius.max(), radius < 0.4 * radius.max()
    assert reflected[rim].mean() > 2.0 * reflected[centre].mean()
