"""``gltf:pbr``: glTF metallic-roughness with the KHR_materials_sheen and KHR_materials_clearcoat layers.

The reference below is scalar ``math`` code written from the ratified extension texts (KHR_materials_clearcoat
"Clearcoat" and "Implementation": fresnel_coat with F0 0.04 and Schlick's Fresnel of N.V; KHR_materials_sheen
"Implementation Notes": Charlie D with alpha = sheenRoughness^2, the Estevez-Kulla visibility with its fitted
Lambda, albedo scaling by min(1 - max(sheenColor) E(N.V), 1 - max(sheenColor) E(N.L))) over the base
material of tests/test_gltf_dialect.py's reference (glTF 2.0 Appendix B). E, the sheen lobe's directional
albedo, is the one input taken from matremap (its table); the table itself is checked against a direct
quadrature of the reference lobe. None of matremap's microfacet or layering helpers is used otherwise.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_gltf_dialect import PAIRS, reference

from matremap.core.material import Material
from matremap.core.scene import PointLight, Scene
from matremap.dialects import get_model
from matremap.dialects.mtlx import LAYERS
from matremap.renderers import get_renderer
from matremap.renderers.embedded import layering as ly
from matremap.renderers.embedded.evaluators import EVALUATORS
from matremap.renderers.embedded.geometry import from_directions

MODEL = "gltf:pbr"


def dot(a, b) -> float:
    return sum(x * y for x, y in zip(a, b, strict=True))


def charlie_l(x: float, r: float) -> float:
    t = (1.0 - r) ** 2
    a = 21.5473 + (25.3245 - 21.5473) * t
    b = 3.82987 + (3.32435 - 3.82987) * t
    c = 0.19823 + (0.16801 - 0.19823) * t
    d = -1.97760 + (-1.27393 + 1.97760) * t
    e = -4.32054 + (-4.85967 + 4.32054) * t
    return a / (1.0 + b * x**c) + d * x + e


def lambda_sheen(cos_theta: float, r: float) -> float:
    if abs(cos_theta) < 0.5:
        return math.exp(charlie_l(cos_theta, r))
    return math.exp(2.0 * charlie_l(0.5, r) - charlie_l(1.0 - cos_theta, r))


def sheen_fcos(rough: float, L, V) -> float:
    """D_Charlie V_Charlie N.L of a white sheen (KHR_materials_sheen, Implementation Notes)."""
    N = (0.0, 0.0, 1.0)
    H = [a + b for a, b in zip(L, V, strict=True)]
    n = math.sqrt(dot(H, H))
    NdotH = dot(N, H) / n
    NdotL, NdotV = dot(N, L), dot(N, V)
    r = max(rough, 1e-6) ** 2
    inv_r = 1.0 / r
    d = (2.0 + inv_r) * (1.0 - NdotH * NdotH) ** (0.5 * inv_r) / (2.0 * math.pi)
    vis = 1.0 / ((1.0 + lambda_sheen(NdotV, r) + lambda_sheen(NdotL, r)) * (4.0 * NdotV * NdotL))
    return d * vis * NdotL


def specular_fcos(rough: float, L, V) -> float:
    """glTF's specular_brdf D V (height-correlated) times N.L, alpha = rough^2."""
    N = (0.0, 0.0, 1.0)
    H = [a + b for a, b in zip(L, V, strict=True)]
    n = math.sqrt(dot(H, H))
    NdotH, NdotL, NdotV = dot(N, H) / n, dot(N, L), dot(N, V)
    a2 = rough**4
    if a2 <= 1e-14:  # a mirror: nothing under point lights
        return 0.0
    D = a2 / (math.pi * (NdotH * NdotH * (a2 - 1.0) + 1.0) ** 2)
    vis = 0.5 / (
        NdotL * math.sqrt(NdotV * NdotV * (1.0 - a2) + a2) + NdotV * math.sqrt(NdotL * NdotL * (1.0 - a2) + a2)
    )
    return D * vis * NdotL


def pbr_reference(params: dict, L, V) -> list[float]:
    """f cos(theta_L) per channel: the core material, the sheen over it, the clear coat over both."""
    base = reference(params, L, V, "height-correlated")
    sheen_colour = params["sheenColor"]
    rs = params["sheenRoughness"]
    strength = max(sheen_colour)
    e_v = float(ly.gltf_sheen_albedo(V[2], rs))
    e_l = float(ly.gltf_sheen_albedo(L[2], rs))
    scaling = min(1.0 - strength * e_v, 1.0 - strength * e_l)
    s = sheen_fcos(rs, L, V)
    sheened = [sheen_colour[c] * s + base[c] * scaling for c in range(3)]
    fc = 0.04 + (1.0 - 0.04) * (1.0 - V[2]) ** 5
    cc = params["clearcoat"]
    coat = specular_fcos(params["clearcoatRoughness"], L, V)
    return [sheened[c] * (1.0 - cc * fc) + cc * fc * coat for c in range(3)]


def evaluate(values: dict, wi, wo, model: str = MODEL) -> np.ndarray:
    """f cos(theta_i) per channel [3, P] of one material at direction pairs [P, 3]."""
    m = Material.create(model, values)
    p = {k: np.asarray(v, dtype=float).reshape(1, -1, 1) for k, v in m.values.items()}
    g = from_directions(np.atleast_2d(wi), np.atleast_2d(wo))
    return np.broadcast_to(EVALUATORS[model](p, dict(m.options), g), (1, 3, g.cos_i.shape[-1]))[0]


CASES = {
    "clearcoat over a dielectric": {
        "baseColor": [0.5, 0.2, 0.1],
        "metallic": 0.0,
        "roughness": 0.5,
        "clearcoat": 1.0,
        "clearcoatRoughness": 0.2,
    },
    "half clearcoat over a metal": {
        "baseColor": [0.95, 0.64, 0.54],
        "metallic": 1.0,
        "roughness": 0.35,
        "clearcoat": 0.5,
        "clearcoatRoughness": 0.6,
    },
    "velvet": {
        "baseColor": [0.5, 0.05, 0.1],
        "metallic": 0.0,
        "roughness": 0.6,
        "sheenColor": [1.0, 0.5, 0.6],
        "sheenRoughness": 0.5,
    },
    "smooth sheen": {
        "baseColor": [0.2, 0.3, 0.4],
        "metallic": 0.0,
        "sheenColor": [0.3, 0.9, 0.2],
        "sheenRoughness": 0.15,
    },
    "everything": {
        "baseColor": [0.8, 0.7, 0.2],
        "metallic": 0.4,
        "roughness": 0.7,
        "ior": 1.9,
        "specular": 0.6,
        "specularColor": [1.6, 1.0, 0.3],
        "sheenColor": [0.6, 0.6, 0.9],
        "sheenRoughness": 0.8,
        "clearcoat": 0.7,
        "clearcoatRoughness": 0.05,
    },
}


def _full(m: Material) -> dict:
    return {k: (list(v) if len(v) == 3 else float(v[0])) for k, v in m.values.items()}


@pytest.mark.parametrize("pair", list(PAIRS))
@pytest.mark.parametrize("case", list(CASES))
def test_layers_match_the_extension_formulas(case, pair):
    m = Material.create(MODEL, CASES[case])
    L, V = PAIRS[pair]
    np.testing.assert_allclose(evaluate(CASES[case], L, V)[:, 0], pbr_reference(_full(m), L, V), rtol=1e-9, atol=1e-15)


def test_defaults_are_off_and_the_model_is_then_metal_rough_bit_for_bit():
    """Every gltf:metal-rough parameter and option is gltf:pbr's, with the same defaults; the layers default to
    the extensions' defaults (off); renders of random materials are identical to the last bit."""
    mr, pbr = get_model("gltf:metal-rough"), get_model(MODEL)
    assert pbr.params[: len(mr.params)] == mr.params and pbr.options == mr.options
    assert {p.name: p.default for p in pbr.params[len(mr.params) :]} == {
        "sheenColor": (0.0, 0.0, 0.0),
        "sheenRoughness": 0.0,
        "clearcoat": 0.0,
        "clearcoatRoughness": 0.0,
        "transmission": 0.0,
        "thickness": 0.0,
        "attenuationDistance": 0.0,
        "attenuationColor": (1.0, 1.0, 1.0),
    }
    assert not any(p.fit for p in pbr.params[len(mr.params) :])  # held off unless freed
    rng = np.random.default_rng(7)
    values = [
        {
            "baseColor": rng.uniform(0, 1, 3).tolist(),
            "metallic": float(rng.choice([0.0, 1.0, rng.uniform()])),
            "roughness": float(rng.uniform()),
            "ior": float(rng.uniform(1, 3)),
            "specular": float(rng.uniform()),
            "specularColor": rng.uniform(0, 2, 3).tolist(),
            "visibility": ("height-correlated", "separable")[k % 2],
        }
        for k in range(12)
    ]
    scene = Scene(resolution=48, lights=(PointLight(0.0), PointLight(55.0)))
    r = get_renderer("embedded")
    a = r.render([Material.create("gltf:metal-rough", v) for v in values], scene)
    b = r.render([Material.create(MODEL, v) for v in values], scene)
    assert a.max() > 0.1 and np.array_equal(a, b)


# -- the sheen albedo table and energy --------------------------------------------------------------------


def hemisphere(fcos, mu: float, n_t: int = 600, n_p: int = 400) -> np.ndarray:
    """Integral over light directions of fcos(wi, wo) [..., P] for a viewer at cos mu: Gauss-Legendre in cos,
    split at 1/2 (the sheen's knee), times the midpoint rule in phi."""
    x, w = np.polynomial.legendre.leggauss(n_t // 2)
    ct = np.concatenate([0.25 * (x + 1.0), 0.5 + 0.25 * (x + 1.0)])
    wt = np.concatenate([0.25 * w, 0.25 * w])
    phi = (np.arange(n_p) + 0.5) * 2.0 * np.pi / n_p
    st = np.sqrt(1.0 - ct * ct)
    wi = np.stack(np.broadcast_arrays(st[:, None] * np.cos(phi), st[:, None] * np.sin(phi), ct[:, None]), -1)
    wi = wi.reshape(-1, 3)
    wo = np.broadcast_to([math.sqrt(1 - mu * mu), 0.0, mu], wi.shape)
    f = np.asarray(fcos(wi, wo))
    f = f.reshape(*f.shape[:-1], n_t, n_p)
    return np.sum(f * wt[:, None], axis=(-2, -1)) * 2.0 * np.pi / n_p


def reference_sheen_vectorised(rough: float, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """:func:`sheen_fcos` on arrays of direction pairs (the same arithmetic)."""
    h = wi + wo
    nh = h[:, 2] / np.linalg.norm(h, axis=1)
    r = max(rough, 1e-6) ** 2
    d = (2.0 + 1.0 / r) * (1.0 - nh * nh) ** (0.5 / r) / (2.0 * math.pi)
    lam = np.vectorize(lambda c: lambda_sheen(c, r))
    return d / ((1.0 + lam(wo[:, 2]) + lam(wi[:, 2])) * 4.0 * wo[:, 2])


@pytest.mark.parametrize(("mu", "rough"), [(0.9, 0.3), (0.5, 0.55), (0.2, 0.8), (0.7, 1.0), (0.12, 0.25)])
def test_sheen_albedo_table_matches_a_direct_quadrature_of_the_reference_lobe(mu, rough):
    """E(mu, r) read from the table (bilinear between nodes) within 1e-3 of integrating the reference lobe
    (measured: median 3e-5, at most 2.8e-4 for sheenRoughness >= 0.2 over 400 random points; 4.7e-3 below,
    where the albedo at grazing views changes fastest)."""
    direct = float(hemisphere(lambda wi, wo: reference_sheen_vectorised(rough, wi, wo), mu, 800, 200))
    assert float(ly.gltf_sheen_albedo(mu, rough)) == pytest.approx(direct, abs=1e-3)
    assert 0.0 < direct < 1.0


def directional_albedo(values: dict, mu: float) -> np.ndarray:
    return hemisphere(lambda wi, wo: evaluate(values, wi, wo), mu, 400, 240)


@pytest.mark.parametrize("rough", [0.3, 0.6, 1.0])
def test_a_white_sheen_over_black_reflects_the_tabulated_albedo_and_over_white_at_most_all_light(rough):
    """sheenColor 1 over a black base reflects E(mu) (what the albedo scaling removes from the base), and
    over a white Lambertian (no specular) the total stays at most 1: E(mu) + (1 - E(mu)) x at most 1."""
    for mu in (0.25, 0.6, 0.95):
        black = {"baseColor": 0.0, "metallic": 0.0, "specular": 0.0, "sheenColor": 1.0, "sheenRoughness": rough}
        e = float(directional_albedo(black, mu)[0])
        assert e == pytest.approx(float(ly.gltf_sheen_albedo(mu, rough)), abs=1e-3)
        white = {**black, "baseColor": 1.0}
        total = float(directional_albedo(white, mu)[0])
        assert e < total <= 1.0 + 1e-3, (mu, total)


@pytest.mark.parametrize("combo", ["coat over white metal", "coat over white diffuse", "all layers"])
def test_clearcoat_weighs_the_base_by_one_minus_its_fresnel(combo):
    """The clear coat reflects clearcoat Fc(mu) E_ggx(mu) and leaves (1 - clearcoat Fc(mu)) of the base's albedo
    (Fc of N.V: exact in the integral), so it adds no energy: a white coated metal reflects at most all light,
    and over glTF's own white dielectric, whose albedo exceeds 1 at grazing views (the core spec's fresnel_mix
    weighs the diffuse by 1 - F(V.H), not by the specular albedo: measured 1.18 at mu 0.1, roughness 0.4),
    the coat brings it down towards its lobe's albedo."""
    base = {
        "coat over white metal": {"baseColor": 1.0, "metallic": 1.0, "roughness": 0.4},
        "coat over white diffuse": {"baseColor": 1.0, "metallic": 0.0, "roughness": 0.4},
        "all layers": {"baseColor": 1.0, "metallic": 0.5, "roughness": 0.3, "sheenColor": 1.0, "sheenRoughness": 0.5},
    }[combo]
    coat = {"clearcoat": 1.0, "clearcoatRoughness": 0.3}
    for mu in (0.2, 0.6, 1.0):
        fc = 0.04 + 0.96 * (1.0 - mu) ** 5
        e_base = float(directional_albedo(base, mu)[0])
        e_white_lobe = float(hemisphere(lambda wi, wo: ly.ggx_lobe(0.3, from_directions(wi, wo)), mu, 400, 240))
        coated = float(directional_albedo({**base, **coat}, mu)[0])
        assert coated == pytest.approx((1.0 - fc) * e_base + fc * e_white_lobe, rel=1e-9)
        assert coated <= max(e_base, 1.0 + 1e-3)
        if combo == "coat over white metal":
            assert e_base < coated <= 1.0


# -- fits across layering ---------------------------------------------------------------------------------

SCENE = Scene.probe([0.0, 45.0], resolution=64)
COATED_COPPER = {
    "base_metalness": 1.0,
    "base_color": [0.95, 0.64, 0.54],
    "specular_roughness": 0.35,
    "coat_weight": 1.0,
    "coat_color": [0.9, 0.6, 0.3],
    "coat_roughness": 0.25,
}
VELVET = {
    "base_color": [0.5, 0.05, 0.1],
    "specular_roughness": 0.6,
    "fuzz_weight": 1.0,
    "fuzz_color": [1.0, 0.5, 0.6],
    "fuzz_roughness": 0.5,
}


def test_layers_table_names_the_gltf_layers():
    assert LAYERS[MODEL] == {"coat": "clearcoat", "sheen": "sheenColor", "transmission": "transmission"}
    for weight in LAYERS[MODEL].values():
        assert weight in get_model(MODEL).param_names


def test_a_coat_is_found_again_when_freed_and_named_when_held():
    """OpenPBR coated copper onto gltf:pbr: with the coat held off the look is absorbed and the note says how to
    free it (measured 0.084 relative RMSE at 128^2, as onto gltf:metal-rough); freed, three-stage, the clear coat
    is found (measured 0.011 at 128^2, clearcoat 1.0, clearcoatRoughness 0.235; two-stage stops at 0.03 with
    main's descent, which limits a stage's evaluations)."""
    from matremap.uniform import fit

    source = Material.create("mtlx:open_pbr_surface", COATED_COPPER)
    held = fit(source, MODEL, scene=SCENE, fix={"metallic": 1.0})
    assert held.loss > 0.06
    assert any("gltf:pbr's clearcoat stayed 0 (free it with --free clearcoat" in w for w in held.warnings)
    free = ["clearcoat", "clearcoatRoughness"]
    freed = fit(source, MODEL, "three-stage", scene=SCENE, fix={"metallic": 1.0}, free=free)
    assert freed.loss < 0.3 * held.loss and freed.loss < 0.025
    assert float(freed.target.values["clearcoat"][0]) > 0.8
    assert 0.15 < float(freed.target.values["clearcoatRoughness"][0]) < 0.35
    assert not [w for w in freed.warnings if "absorbed" in w]


def test_a_fuzz_is_fitted_as_a_sheen_when_freed():
    """OpenPBR velvet onto gltf:pbr: absorbed 0.265 (128^2); freed, three-stage: 0.040 with a pink sheen."""
    from matremap.uniform import fit

    source = Material.create("mtlx:open_pbr_surface", VELVET)
    held = fit(source, MODEL, scene=SCENE, fix={"metallic": 0.0})
    assert held.loss > 0.2 and any("sheenColor stayed 0" in w for w in held.warnings)
    freed = fit(source, MODEL, "three-stage", scene=SCENE, fix={"metallic": 0.0}, free=["sheenColor", "sheenRoughness"])
    assert freed.loss < 0.25 * held.loss
    sheen = np.asarray(freed.target.values["sheenColor"])
    assert sheen[0] > sheen[2] > sheen[1] > 0.2  # the fuzz's pink [1, 0.5, 0.6]
    assert not [w for w in freed.warnings if "absorbed" in w]


def test_a_plain_source_leaves_the_layers_off():
    from matremap.uniform import fit

    source = Material.create("gltf:metal-rough", {"baseColor": [0.8, 0.3, 0.1], "metallic": 0.0, "roughness": 0.4})
    r = fit(source, MODEL, scene=SCENE, fix={"metallic": 0.0})
    assert r.loss < 1e-3 and not r.warnings
    assert float(r.target.values["clearcoat"][0]) == 0.0 and max(r.target.values["sheenColor"]) == 0.0
