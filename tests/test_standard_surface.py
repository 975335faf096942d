"""``mtlx:standard_surface`` on the embedded renderer: an independent scalar reading of the Standard Surface
1.0.1 closure formulas, the sheen albedo table, energy (white furnace) and the limits where it is a simpler
model."""

from __future__ import annotations

import cmath
import math

import numpy as np
import pytest

from matremap.core.material import Material
from matremap.core.scene import Scene
from matremap.renderers.embedded import EmbeddedRenderer
from matremap.renderers.embedded import layering as ly
from matremap.renderers.embedded.evaluators import EVALUATORS
from matremap.renderers.embedded.geometry import direction, from_directions
from matremap.renderers.registry import renderer_for

MODEL = "mtlx:standard_surface"
SCENE = Scene.probe([0.0, 45.0], resolution=40)


def evaluate(values: dict, wi: np.ndarray, wo: np.ndarray, options: dict | None = None) -> np.ndarray:
    """f cos(theta_i) per channel [3, P] of one material at direction pairs [P, 3]."""
    m = Material.create(MODEL, values)
    p = {k: np.asarray(v, dtype=float).reshape(1, -1, 1) for k, v in m.values.items()}
    f = EVALUATORS[MODEL](p, {**m.options, **(options or {})}, from_directions(wi, wo))
    return np.broadcast_to(f, (1, 3, len(wi)))[0]


def fresnel_complex(c: float, n: complex) -> float:
    """Unpolarised Fresnel reflectance of an interface to the complex IOR n (Born and Wolf), by complex
    arithmetic: r_s = (c - t)/(c + t), r_p = (n^2 c - t)/(n^2 c + t), t = sqrt(n^2 - sin^2)."""
    t = cmath.sqrt(n * n - (1.0 - c * c))
    rs = (c - t) / (c + t)
    rp = (n * n * c - t) / (n * n * c + t)
    return 0.5 * (abs(rs) ** 2 + abs(rp) ** 2)


def ggx_fcos(wi, wo, r: float) -> float:
    a2 = r**4
    h = (wi + wo) / np.linalg.norm(wi + wo)
    d = a2 / (math.pi * (h[2] ** 2 * (a2 - 1.0) + 1.0) ** 2)

    def lam(mu):
        return 0.5 * (-1.0 + math.sqrt(1.0 + a2 * (1.0 - mu * mu) / (mu * mu)))

    return d / (1.0 + lam(wi[2]) + lam(wo[2])) / (4.0 * wo[2])


def oren_nayar(rho: float, sigma: float, wi, wo) -> float:
    """Oren and Nayar 1994 eq. 30 with angles: rho/pi (A + B max(0, cos dphi) sin(alpha) tan(beta)) mu_i."""
    ti, to = math.acos(wi[2]), math.acos(wo[2])
    cos_dphi = 0.0
    if math.sin(ti) > 1e-9 and math.sin(to) > 1e-9:
        cos_dphi = (wi[0] * wo[0] + wi[1] * wo[1]) / (math.sin(ti) * math.sin(to))
    s2 = sigma * sigma
    a = 1 - 0.5 * s2 / (s2 + 0.33)
    b = 0.45 * s2 / (s2 + 0.09)
    alpha, beta = max(ti, to), min(ti, to)
    return rho / math.pi * (a + b * max(0.0, cos_dphi) * math.sin(alpha) * math.tan(beta)) * wi[2]


def charlie(r: float, wi, wo) -> float:
    h = (wi + wo) / np.linalg.norm(wi + wo)
    inv = 1 / max(r, 0.005)
    sin_h = math.sqrt(max(0.0, 1 - h[2] ** 2))
    d = (2 + inv) * sin_h**inv / (2 * math.pi)
    return d / (4 * (wi[2] + wo[2] - wi[2] * wo[2])) * wi[2]


def gulbrandsen(r: float, g: float) -> complex:
    r = min(max(r, 0.0), 0.99)
    n = g * (1 - r) / (1 + r) + (1 - g) * (1 + math.sqrt(r)) / (1 - math.sqrt(r))
    k = math.sqrt(max(((n + 1) ** 2 * r - (n - 1) ** 2) / (1 - r), 0.0))
    return complex(n, k)


def standard_surface_scalar(v: dict, wi, wo, c: int, multi: bool) -> float:
    """f mu_i of Standard Surface 1.0.1 for one channel from the spec's closure formulas; only the
    directional albedos (tables) come from matremap."""
    col = {k: (val[c] if isinstance(val, list | tuple | np.ndarray) else val) for k, val in v.items()}
    mo = wo[2]
    h = (wi + wo) / np.linalg.norm(wi + wo)
    ih = float(wi @ h)

    def gain(f0, rr):
        e = float(ly.white_albedo(mo, rr))
        return 1 + f0 * (1 - e) / e if multi else 1.0

    base_mix = col["base"] * oren_nayar(col["base_color"], col["diffuse_roughness"], wi, wo)
    sh, rs = col["sheen"], col["sheen_roughness"]
    sheen_layer = sh * col["sheen_color"] * charlie(rs, wi, wo) + (1 - sh * float(ly.sheen_albedo(mo, rs))) * base_mix
    r, ior = col["specular_roughness"], col["specular_IOR"]
    f0 = ((ior - 1) / (ior + 1)) ** 2
    w = col["specular"] * col["specular_color"]
    spec = fresnel_complex(ih, complex(ior, 0)) * ggx_fcos(wi, wo, r) * gain(f0, r)
    e_spec = float(ly.dielectric_albedo(mo, r, f0)) * gain(f0, r)
    transmission_sheen_mix = (1 - col["transmission"]) * sheen_layer  # specular_btdf reflects nothing
    spec_layer = w * spec + (1 - w * e_spec) * transmission_sheen_mix
    refl = col["base"] * col["base_color"]
    eta = gulbrandsen(refl, col["specular"] * col["specular_color"])
    metal = fresnel_complex(ih, eta) * ggx_fcos(wi, wo, r) * gain(min(max(refl, 0), 0.99), r)
    m = col["metalness"]
    mixture = m * metal + (1 - m) * spec_layer
    cr, cior, cw = col["coat_roughness"], col["coat_IOR"], col["coat"]
    f0c = ((cior - 1) / (cior + 1)) ** 2
    coat = fresnel_complex(ih, complex(cior, 0)) * ggx_fcos(wi, wo, cr) * gain(f0c, cr)
    e_coat = float(ly.dielectric_albedo(mo, cr, f0c)) * gain(f0c, cr)
    return cw * coat + (1 - cw + cw * col["coat_color"] * (1 - e_coat)) * mixture


CASES = [
    {"base_color": [0.8, 0.4, 0.2], "specular_roughness": 0.4},
    {"base_color": [0.6, 0.5, 0.3], "diffuse_roughness": 0.7, "specular_IOR": 2.1, "specular": 0.5},
    {"base_color": [0.95, 0.64, 0.54], "metalness": 1.0, "specular_color": [0.9, 0.8, 0.7], "specular_roughness": 0.3},
    {
        "base_color": [0.95, 0.64, 0.54],
        "metalness": 1.0,
        "specular_roughness": 0.35,
        "coat": 1.0,
        "coat_color": [0.9, 0.6, 0.3],
        "coat_roughness": 0.2,
        "coat_IOR": 1.6,
    },
    {
        "base_color": [0.3, 0.5, 0.7],
        "metalness": 0.3,
        "specular_color": [1.0, 0.6, 0.4],
        "specular_roughness": 0.6,
        "coat": 0.5,
        "coat_roughness": 0.4,
        "sheen": 0.8,
        "sheen_color": [0.9, 0.2, 0.5],
        "sheen_roughness": 0.4,
        "diffuse_roughness": 0.3,
    },
    {
        "base_color": [0.3, 0.5, 0.7],
        "metalness": 0.2,
        "specular_roughness": 0.3,
        "sheen": 0.6,
        "transmission": 0.7,
        "transmission_color": [0.9, 0.5, 0.2],
        "transmission_depth": 1.0,
        "coat": 0.5,
    },
]
PAIRS = [
    ((20.0, 0.0), (35.0, 180.0)),
    ((60.0, 30.0), (10.0, 200.0)),
    ((75.0, 90.0), (70.0, 260.0)),
    ((50.0, 10.0), (45.0, 20.0)),
]


@pytest.mark.parametrize("multi", [True, False])
@pytest.mark.parametrize("case", range(len(CASES)))
def test_matches_an_independent_scalar_reading_of_the_spec(case, multi):
    """Every closure and weight, at four direction pairs, per channel, within 1e-9 (the conductor Fresnel
    by complex arithmetic, Oren-Nayar with angles)."""
    values = Material.create(MODEL, CASES[case]).to_dict()["params"]
    wi = np.array([direction(*p[0]) for p in PAIRS])
    wo = np.array([direction(*p[1]) for p in PAIRS])
    got = evaluate(CASES[case], wi, wo, {"multiscatter": "turquin" if multi else "none"})
    for j in range(len(PAIRS)):
        for c in range(3):
            expected = standard_surface_scalar(values, wi[j], wo[j], c, multi)
            assert got[c, j] == pytest.approx(expected, rel=1e-9, abs=1e-12), (case, j, c)


def hemisphere(fcos, mu: float, n_t: int = 400, n_p: int = 300) -> np.ndarray:
    x, w = np.polynomial.legendre.leggauss(n_t)
    ct, wt = 0.5 * (x + 1.0), 0.5 * w
    phi = (np.arange(n_p) + 0.5) * 2.0 * np.pi / n_p
    st = np.sqrt(1.0 - ct * ct)
    wi = np.stack(np.broadcast_arrays(st[:, None] * np.cos(phi), st[:, None] * np.sin(phi), ct[:, None]), -1)
    wi = wi.reshape(-1, 3)
    wo = np.broadcast_to([math.sqrt(1 - mu * mu), 0.0, mu], wi.shape)
    f = np.asarray(fcos(wi, wo))
    f = f.reshape(*f.shape[:-1], n_t, n_p)
    return np.sum(f * wt[:, None], axis=(-2, -1)) * 2.0 * np.pi / n_p


def test_sheen_albedo_table_matches_direct_integration():
    """The Charlie sheen's albedo table off its nodes, against quadrature over light directions."""
    for mu, r in ((0.3, 0.35), (0.7, 0.6), (0.5, 0.9)):
        e = hemisphere(lambda wi, wo, r=r: ly.charlie_sheen(r, from_directions(wi, wo)), mu, 800, 600)
        assert float(ly.sheen_albedo(mu, r)) == pytest.approx(float(e), abs=2e-3)


COMBOS = {
    "diffuse": {"specular": 0.0},
    "rough diffuse": {"specular": 0.0, "diffuse_roughness": 1.0},
    "specular over diffuse": {},
    "metal": {"metalness": 1.0},
    "coat over metal": {"metalness": 1.0, "coat": 1.0, "coat_roughness": 0.4},
    "coat over diffuse": {"coat": 1.0, "coat_roughness": 0.4, "coat_IOR": 2.0},
    "sheen over diffuse": {"sheen": 1.0, "sheen_roughness": 0.5},
    "everything": {"sheen": 0.6, "coat": 0.7, "coat_roughness": 0.5, "metalness": 0.3},
}


@pytest.mark.parametrize("combo", list(COMBOS))
def test_white_furnace_every_closure_combination_reflects_at_most_all_light(combo):
    """White base and tints, specular roughness 0.4: at most 1 (+3e-3 for the tables) at every view.
    Oren-Nayar's qualitative model loses light when rough (the spec's closure, without compensation)."""
    values = {"base_color": 1.0, "specular_roughness": 0.4, **COMBOS[combo]}
    for mu in (0.15, 0.5, 1.0):
        e = float(hemisphere(lambda wi, wo: evaluate(values, wi, wo)[0], mu))
        assert e <= 1.003, (combo, mu, e)
        if combo in ("diffuse", "specular over diffuse", "metal", "sheen over diffuse"):
            assert e >= 0.985, (combo, mu, e)
        if combo == "rough diffuse":
            assert e < 0.97


def render(values: dict) -> np.ndarray:
    return EmbeddedRenderer().render([Material.create(MODEL, values)], SCENE)[0]


def test_without_coat_or_sheen_the_layers_vanish_exactly():
    base = {"base_color": [0.7, 0.4, 0.2], "specular_roughness": 0.35, "metalness": 0.3, "specular_IOR": 1.7}
    plain = render(base)
    np.testing.assert_array_equal(
        render({**base, "coat_color": [0.1, 0.5, 0.9], "coat_roughness": 0.7, "coat_IOR": 2.9}), plain
    )
    np.testing.assert_array_equal(render({**base, "sheen_color": [0.2, 0.3, 0.4], "sheen_roughness": 0.1}), plain)
    assert np.abs(render({**base, "sheen": 1.0}) - plain).max() > 0.005


def test_metal_reflects_base_color_head_on_and_the_edge_tint_at_grazing():
    """Gulbrandsen's mapping: F(1) = base base_color; a white edge tint keeps the edge near white, a dark
    one darkens it (the F82-like dip of real metals)."""
    r = np.array([0.95, 0.64, 0.54])
    n, k = ly.artistic_conductor(r, 1.0)
    from matremap.core.optics import fresnel_conductor

    np.testing.assert_allclose(fresnel_conductor(1.0, n, k), r, rtol=1e-9)
    n2, k2 = ly.artistic_conductor(r, np.array([0.2, 0.2, 0.2]))
    np.testing.assert_allclose(fresnel_conductor(1.0, n2, k2), r, rtol=1e-9)
    assert np.all(fresnel_conductor(0.15, n2, k2) < fresnel_conductor(0.15, n, k) - 0.02)


def test_no_specular_smooth_diffuse_is_lambert():
    a = render({"base_color": [0.8, 0.5, 0.1], "specular": 0.0, "base": 0.9})
    b = EmbeddedRenderer().render([Material.create("cycles:diffuse", {"Color": [0.72, 0.45, 0.09]})], SCENE)[0]
    np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-9)


def test_channels_are_separable():
    rgb = {
        "base_color": [0.8, 0.3, 0.1],
        "specular_color": [1.0, 0.7, 0.4],
        "coat": 0.7,
        "coat_color": [0.9, 0.6, 0.2],
        "sheen": 0.4,
        "sheen_color": [0.3, 0.8, 0.5],
        "metalness": 0.4,
    }
    full = render(rgb)
    for c in range(3):
        grey = {k: (v[c] if isinstance(v, list) else v) for k, v in rgb.items()}
        np.testing.assert_allclose(render(grey)[..., c], full[..., c], rtol=1e-6, atol=1e-9)


def test_drawn_by_the_embedded_renderer():
    assert renderer_for(MODEL) == "embedded"
    img = render({"base_color": [0.8, 0.3, 0.1], "coat": 1.0, "sheen": 0.5})
    assert np.isfinite(img).all() and img[SCENE.mask()].min() >= 0 and img[SCENE.mask()].mean() > 0


def test_a_sheen_fitted_onto_a_plain_dielectric_is_absorbed_by_the_diffuse():
    """Standard Surface velvet onto glTF (no sheen): the diffuse part carries the sheen (measured 0.265 at
    128^2: a sheen's grazing glow has no diffuse counterpart), and the note names the layer."""
    from matremap.uniform import fit

    values = {"base_color": [0.5, 0.05, 0.1], "specular_roughness": 0.6, "sheen": 1.0, "sheen_color": [1, 0.5, 0.6]}
    scene = Scene.probe([0.0, 45.0], resolution=64)
    r = fit(Material.create(MODEL, values), "gltf:metal-rough", scene=scene, fix={"metallic": 0.0})
    assert r.loss < 0.35
    assert np.all(np.asarray(r.target.values["baseColor"]) > np.array([0.5, 0.05, 0.1]))  # lightened by the sheen
    notes = [w for w in r.warnings if "absorbed" in w]
    assert len(notes) == 1 and "sheen layer (sheen 1)" in notes[0]
