"""Pieces shared by the embedded evaluators of the layered über-shaders (OpenPBR Surface, Autodesk
Standard Surface): microfacet lobes, Fresnel forms, diffuse and sheen lobes, and the directional albedos
that albedo-scaled layering weighs a lower layer with.

Everything is f * cos(theta_light) on [N, C, L, P] arrays (or scalars and 1-d arrays), in the notation
of :mod:`matremap.renderers.embedded.geometry` (i towards the light, o towards the viewer).

Sources (formulas, not code):

* GGX with the height-correlated Smith G2 (Heitz 2014, "Understanding the masking-shadowing function",
  eq. 99), alpha = roughness^2 (OpenPBR 1.1 "Microfacet model"; Standard Surface 1.0.1 parameter tables).
* Multiple-scattering compensation: Turquin 2019, "Practical multiple scattering compensation for
  microfacet models": f_ms = f_ss (1 + F0 (1 - E(mu_o)) / E(mu_o)) with E the white single-scatter
  albedo (OpenPBR 1.1 "Microfacet model" names it as an allowed scheme).
* F82-tint metal Fresnel: OpenPBR 1.1 "Metal" (Kutz et al. 2021 after Hoffman 2019); clamped to
  [0, 1] here, since for edge tints far below 1 the formula goes negative between mu = 1/7 and 1/2.
* Artist-friendly metal Fresnel: Gulbrandsen 2014, "Artist friendly metallic Fresnel", JCGT 3(4):
  reflectivity r and edge tint g give n = g n_min + (1 - g) n_max, n_min = (1 - r)/(1 + r),
  n_max = (1 + sqrt r)/(1 - sqrt r), k^2 = ((n + 1)^2 r - (n - 1)^2)/(1 - r), r clamped to 0.99
  (Standard Surface 1.0.1 "Metal"); then the exact conductor Fresnel.
* Energy-preserving Oren-Nayar (EON): Portsmouth, Kutz and Hill 2025, "EON: a practical energy-preserving
  rough diffuse BRDF", JCGT 14(1); OpenPBR 1.1 "Glossy-diffuse" and its footnote on s and t. The Fujii
  lobe rho/pi A (1 + sigma s/t) with A = 1/(1 + (1/2 - 2/(3 pi)) sigma), its exact directional albedo
  E_FON(mu) and average <E_FON> = A (1 + (2/3 - 28/(15 pi)) sigma), and the compensation
  rho_ms/pi (1 - E_FON(mu_i)) (1 - E_FON(mu_o)) / (1 - <E_FON>), rho_ms = rho^2 <E> / (1 - rho (1 - <E>)).
  (The spec's text writes rho_ms with one more 1/pi; with it a white EON would reflect 1/pi of what
  it lacks and fail the white furnace the same section promises; the EON paper's form passes it.)
* Qualitative Oren-Nayar: Oren and Nayar 1994, eq. 30: rho/pi (A + B max(0, cos(phi_i - phi_o))
  sin(alpha) tan(beta)), A = 1 - 0.5 s^2/(s^2 + 0.33), B = 0.45 s^2/(s^2 + 0.09), as MaterialX 1.39's
  ``oren_nayar_diffuse_bsdf`` evaluates it for Standard Surface (sigma = diffuse_roughness).
* Zeltner sheen: Zeltner, Burley and Chiang 2022, "Practical multiple-scattering sheen using linearly
  transformed cosines" (OpenPBR 1.1 "Fuzz"): mu_i f = E(mu_o, r) D_LTC(i), with the analytic fits of
  E and of the inverse LTC matrix [[a, 0, b], [0, a, 0], [0, 0, 1]] published with the paper
  (github.com/tizian/ltc-sheen, as MaterialX 1.39 uses them); roughness clamped to [0.01, 1].
* Charlie sheen: Estevez and Kulla 2017, "Production friendly microfacet sheen BRDF":
  D = (2 + 1/r) sin^(1/r)(theta_h) / (2 pi), r >= 0.005, with Neubelt and Pettineo's visibility
  1/(4 (mu_i + mu_o - mu_i mu_o)), the form MaterialX 1.39's ``sheen_bsdf`` evaluates for Standard
  Surface (its spec names only the distribution).
* glTF sheen (KHR_materials_sheen, ratified README, "Implementation Notes"): the same D with
  r = sheenRoughness^2 and Estevez and Kulla's own visibility 1/((1 + Lambda(mu_o) + Lambda(mu_i)) 4 mu_i mu_o),
  Lambda(mu) = exp(L(mu)) for mu < 1/2 and exp(2 L(1/2) - L(1 - mu)) above, L(x) = a/(1 + b x^c) + d x + e
  with a..e interpolated in (1 - r)^2 between the README's two sets of constants; its directional albedo
  (the E(mu) the extension's albedo scaling looks up) is integrated here into a table of its own.

Directional albedos E(mu_o) of the GGX lobes (white, and with the real dielectric Fresnel of every F0)
and of the Charlie sheen are integrated numerically on node grids here (uniform in sqrt(mu), in the
roughness and in F0^(1/4)), read bilinearly (trilinearly in F0) in those coordinates, and cached on disk
like the rough transmittance of ``roughplastic`` (:mod:`.rough_transmittance`). Built in about 15 s;
read back within 3e-3 of direct integration (median 2e-4) away from F0 > 0.5.
"""

from __future__ import annotations

import functools
import hashlib
import json
from collections.abc import Callable
from pathlib import Path

import numpy as np

from matremap.core.diskcache import cache_dir, load_tables, save_tables
from matremap.core.optics import f0_from_ior, fresnel_dielectric, ior_from_f0
from matremap.renderers.embedded import microfacet as mf
from matremap.renderers.embedded import quadrature

INV_PI = 1.0 / np.pi
#: below this alpha^2 a GGX lobe is a mirror: zero under point lights
MIRROR_ALPHA2 = 1e-14
#: Fujii's Oren-Nayar constants (OpenPBR 1.1 footnote; EON paper)
FON_C1 = 0.5 - 2.0 / (3.0 * np.pi)
FON_C2 = 2.0 / 3.0 - 28.0 / (15.0 * np.pi)

#: nodes of the albedo tables: cos_view, roughness, and F0 of the dielectric Fresnel
MU_NODES, ROUGH_NODES, F0_NODES = 32, 32, 24
_TABLE_FORMAT = 2
_QUAD = (48, 48)
_SHEEN_QUAD = (160, 96)


# -- microfacet lobes and Fresnel -----------------------------------------------------------------


def ggx_lobe(rough, g) -> np.ndarray:
    """The white single-scatter GGX lobe times cos(theta_light): D G2 / (4 cos_view), alpha = rough^2,
    height-correlated Smith G2; zero for a mirror (alpha^2 <= 1e-14) under point lights, a lobe of ``g.mirror_alpha``
    where the renderer samples the mirror direction (:func:`~matremap.renderers.embedded.microfacet.drawn_alpha`)."""
    alpha = mf.drawn_alpha(np.asarray(rough, dtype=float) ** 2, g)
    a = np.maximum(alpha, 1e-7)
    d = mf.d_ggx(g.cos_h, g.tan2_h, a)
    g2 = mf.g_height_correlated(mf.lambda_ggx(g.tan_i, a), mf.lambda_ggx(g.tan_o, a))
    return np.where(alpha * alpha <= MIRROR_ALPHA2, 0.0, d * g2 / (4.0 * np.maximum(g.cos_o, 1e-12)))


def f82_tint(cos_theta, f0, tint) -> np.ndarray:
    """F82-tint: Schlick(F0) - mu (1 - mu)^6 / (mu_bar (1 - mu_bar)^6) (Schlick(mu_bar) (1 - tint)),
    mu_bar = 1/7, clamped to [0, 1] (see the module docstring)."""
    mu = np.clip(np.asarray(cos_theta, dtype=float), 0.0, 1.0)
    f0 = np.asarray(f0, dtype=float)
    mb = 1.0 / 7.0
    schlick_bar = f0 + (1.0 - f0) * (1.0 - mb) ** 5
    m = 1.0 - mu
    schlick = f0 + (1.0 - f0) * m**5
    edge = mu * m**6 / (mb * (1.0 - mb) ** 6)
    return np.clip(schlick - edge * schlick_bar * (1.0 - np.asarray(tint, dtype=float)), 0.0, 1.0)


def artistic_conductor(reflectivity, edge) -> tuple[np.ndarray, np.ndarray]:
    """Gulbrandsen 2014: the complex IOR (n, k) whose Fresnel has normal reflectance ``reflectivity``
    (clamped to [0, 0.99]) and edge tint ``edge``."""
    r = np.clip(np.asarray(reflectivity, dtype=float), 0.0, 0.99)
    g = np.asarray(edge, dtype=float)
    sr = np.sqrt(r)
    n = g * (1.0 - r) / (1.0 + r) + (1.0 - g) * (1.0 + sr) / (1.0 - sr)
    k2 = ((n + 1.0) ** 2 * r - (n - 1.0) ** 2) / (1.0 - r)
    return n, np.sqrt(np.maximum(k2, 0.0))


def modulated_ior(eta, weight) -> np.ndarray:
    """OpenPBR 1.1 eq. modulated_ior: the IOR ratio whose F0 is ``weight`` times that of ``eta``
    (weight F0 clamped to [0, 0.99999], as the spec's clamp of specular_weight to 1/F0 requires)."""
    eta = np.asarray(eta, dtype=float)
    f0 = np.clip(np.asarray(weight, dtype=float) * f0_from_ior(eta), 0.0, 0.99999)
    eps = np.sign(eta - 1.0) * np.sqrt(f0)
    return (1.0 + eps) / (1.0 - eps)


def refracted_cos(mu, eta) -> np.ndarray:
    """The cosine of a direction at cos ``mu`` refracted into a medium of relative IOR ``eta`` >= 1."""
    mu = np.asarray(mu, dtype=float)
    return np.sqrt(np.maximum(1.0 - (1.0 - mu * mu) / np.asarray(eta, dtype=float) ** 2, 1e-12))


def average_fresnel(eta, n: int = 64) -> np.ndarray:
    """E_F(eta) = 2 integral of F(mu, eta) mu dmu over [0, 1] (OpenPBR 1.1 footnote avg_fresnel), by
    Gauss-Legendre quadrature; ``eta`` broadcasts."""
    mu, w = quadrature.unit(n)
    eta = np.asarray(eta, dtype=float)[..., None]
    return np.sum(2.0 * mu * w * fresnel_dielectric(mu, eta), axis=-1)


# -- diffuse lobes --------------------------------------------------------------------------------


def fon_albedo(mu, sigma) -> np.ndarray:
    """The exact directional albedo of Fujii's Oren-Nayar lobe with rho = 1 (EON paper)."""
    mu = np.clip(np.asarray(mu, dtype=float), 1e-7, 1.0)
    sigma = np.asarray(sigma, dtype=float)
    a = 1.0 / (1.0 + FON_C1 * sigma)
    si = np.sqrt(np.maximum(1.0 - mu * mu, 0.0))
    big_g = si * (np.arccos(mu) - si * mu) + (2.0 / 3.0) * ((si / mu) * (1.0 - si**3) - si)
    return a + sigma * a * big_g * INV_PI


def fon_average_albedo(sigma) -> np.ndarray:
    """<E_FON> = A (1 + (2/3 - 28/(15 pi)) sigma): the cosine-weighted mean of :func:`fon_albedo`."""
    sigma = np.asarray(sigma, dtype=float)
    return (1.0 + FON_C2 * sigma) / (1.0 + FON_C1 * sigma)


def eon_diffuse(rho, sigma, g) -> np.ndarray:
    """EON (Fujii's Oren-Nayar plus the reciprocal multiple-scattering term), times cos(theta_light)."""
    s = g.i_dot_o - g.cos_i * g.cos_o
    s_over_t = np.where(s > 0.0, s / np.maximum(g.cos_i, g.cos_o), s)
    a = 1.0 / (1.0 + FON_C1 * sigma)
    single = rho * INV_PI * a * (1.0 + sigma * s_over_t)
    e_avg = fon_average_albedo(sigma)
    rho_ms = rho * rho * e_avg / (1.0 - rho * (1.0 - e_avg))
    eps = 1e-7
    multi = (
        rho_ms
        * INV_PI
        * np.maximum(eps, 1.0 - fon_albedo(g.cos_i, sigma))
        * np.maximum(eps, 1.0 - fon_albedo(g.cos_o, sigma))
        / np.maximum(eps, 1.0 - e_avg)
    )
    return (single + multi) * g.cos_i


def qon_diffuse(rho, sigma, g) -> np.ndarray:
    """Oren and Nayar's qualitative model (sigma = the roughness as given), times cos(theta_light)."""
    s2 = sigma * sigma
    a = 1.0 - 0.5 * s2 / (s2 + 0.33)
    b = 0.45 * s2 / (s2 + 0.09)
    s = g.i_dot_o - g.cos_i * g.cos_o
    s_over_t = np.where(s > 0.0, s / np.maximum(g.cos_i, g.cos_o), 0.0)
    return rho * INV_PI * (a + b * s_over_t) * g.cos_i


# -- sheen lobes ----------------------------------------------------------------------------------


def zeltner_albedo(mu, rough) -> np.ndarray:
    """Zeltner et al.'s fit of the sheen layer's directional albedo R(mu, r) (r clamped to [0.01, 1]),
    clamped to [0, 1] (the fit dips to -2e-5 at smooth grazing views)."""
    x = np.asarray(mu, dtype=float)
    y = np.clip(np.asarray(rough, dtype=float), 0.01, 1.0)
    s = y * (0.0206607 + 1.58491 * y) / (0.0379424 + y * (1.32227 + y))
    m = y * (-0.193854 + y * (-1.14885 + y * (1.7932 - 0.95943 * y * y))) / (0.046391 + y)
    o = y * (0.000654023 + (-0.0207818 + 0.119681 * y) * y) / (1.26264 + y * (-1.92021 + y))
    return np.clip(np.exp(-0.5 * ((x - m) / s) ** 2) / (s * np.sqrt(2.0 * np.pi)) + o, 0.0, 1.0)


def zeltner_ltc(mu, rough) -> tuple[np.ndarray, np.ndarray]:
    """The fitted inverse-LTC coefficients (a, b) of Zeltner et al.'s sheen at (mu, r)."""
    x = np.clip(np.asarray(mu, dtype=float), 0.0, 1.0)
    y = np.clip(np.asarray(rough, dtype=float), 0.01, 1.0)
    a = (2.58126 * x + 0.813703 * y) * y / (1.0 + 0.310327 * x * x + 2.60994 * x * y)
    b = np.sqrt(1.0 - x) * (y - 1.0) * y**3 / (0.0000254053 + 1.71228 * x - 1.71506 * x * y + 1.34174 * y * y)
    return a, b


def zeltner_sheen(rough, g) -> np.ndarray:
    """The white Zeltner sheen times cos(theta_light): R(mu_o, r) D(i), D the linearly transformed cosine
    (:func:`ltc_cosine`) with the fitted (a, b) at (mu_o, r)."""
    a, b = zeltner_ltc(g.cos_o, rough)
    return zeltner_albedo(g.cos_o, rough) * ltc_cosine(a, b, g)


def ltc_cosine(a, b, g) -> np.ndarray:
    """The linearly transformed cosine of Zeltner et al.'s sheen, D(light), in the frame whose x axis is the
    viewer's azimuth: with w = (a x + b z, a y, z) the light direction under the inverse matrix
    [[a, 0, b], [0, a, 0], [0, 0, 1]], D = max(w_z, 0)/pi (a / |w|^2)^2 (it integrates to 1)."""
    sin_o = np.sqrt(np.maximum(1.0 - g.cos_o**2, 0.0))
    x = np.where(sin_o > 1e-9, (g.i_dot_o - g.cos_i * g.cos_o) / np.maximum(sin_o, 1e-9), 0.0)
    y2 = np.maximum(1.0 - g.cos_i**2 - x * x, 0.0)
    z = g.cos_i
    len2 = (a * x + b * z) ** 2 + a * a * y2 + z * z
    return np.maximum(z, 0.0) * INV_PI * (a / len2) ** 2


def charlie_sheen(rough, g) -> np.ndarray:
    """The white Charlie sheen (Neubelt-Pettineo visibility) times cos(theta_light)."""
    inv_r = 1.0 / np.maximum(np.asarray(rough, dtype=float), 0.005)
    sin2_h = g.tan2_h / (1.0 + g.tan2_h)
    d = (2.0 + inv_r) * sin2_h ** (0.5 * inv_r) / (2.0 * np.pi)
    return d / (4.0 * (g.cos_i + g.cos_o - g.cos_i * g.cos_o)) * g.cos_i


#: Estevez and Kulla's fitted constants of L(x) (KHR_materials_sheen README): (at r = 1, at r = 0) for a..e
_CHARLIE_L = (
    (21.5473, 25.3245),
    (3.82987, 3.32435),
    (0.19823, 0.16801),
    (-1.97760, -1.27393),
    (-4.32054, -4.85967),
)
#: the smallest sheen roughness (the Khronos sample viewer's clamp; the README leaves 0 open)
GLTF_SHEEN_MIN_ROUGHNESS = 1e-6


def charlie_lambda(mu, r) -> np.ndarray:
    """Estevez and Kulla's fitted Lambda of the Charlie sheen at cos ``mu`` for r = alpha (see the module doc)."""
    t = (1.0 - np.asarray(r, dtype=float)) ** 2
    a, b, c, d, e = ((1.0 - t) * lo + t * hi for lo, hi in _CHARLIE_L)

    def big_l(x):
        return a / (1.0 + b * np.power(x, c)) + d * x + e

    mu = np.abs(np.asarray(mu, dtype=float))
    low = np.minimum(mu, 0.5)  # each branch evaluated only where it holds, then chosen
    high = np.maximum(mu, 0.5)
    return np.where(mu < 0.5, np.exp(big_l(low)), np.exp(2.0 * big_l(0.5) - big_l(1.0 - high)))


def gltf_sheen(rough, g) -> np.ndarray:
    """The white glTF (KHR_materials_sheen) sheen times cos(theta_light): D_Charlie(r) / ((1 + Lambda(mu_o) +
    Lambda(mu_i)) 4 mu_o), r = max(rough, 1e-6)^2."""
    r = np.maximum(np.asarray(rough, dtype=float), GLTF_SHEEN_MIN_ROUGHNESS) ** 2
    inv_r = 1.0 / r
    sin2_h = g.tan2_h / (1.0 + g.tan2_h)
    d = (2.0 + inv_r) * sin2_h ** (0.5 * inv_r) / (2.0 * np.pi)
    lam = 1.0 + charlie_lambda(g.cos_o, r) + charlie_lambda(g.cos_i, r)
    return d / (lam * 4.0 * np.maximum(g.cos_o, 1e-12))


# -- numerical directional albedos ----------------------------------------------------------------


def ggx_weighted_albedo(
    mu, rough, weight: Callable[[np.ndarray], np.ndarray], quad: tuple[int, int] | None = None
) -> np.ndarray:
    """The directional albedo of the single-scatter GGX lobe (height-correlated G2, alpha = rough^2)
    with the Fresnel factor ``weight(o.m)`` for a viewer at cos theta = ``mu``; ``weight`` may add a
    trailing axis (one albedo per entry). ``mu`` and ``rough`` are 1-d of equal length.

    Over microfacet normals m: E = 1/(2 pi) integral w(o.m) (o.m) G2(i, o) / (cos theta_m mu) du dphi,
    u = tan^2 / (alpha^2 + tan^2) of theta_m, i the mirror of o about m. The u range is split where the
    reflection starts (tan(theta_o/2)) and stops (cot(theta_o/2)) to go below the horizon and phi runs
    over the azimuths where it stays above, so each panel is smooth."""
    n_u, n_phi = quad or _QUAD
    mu = np.clip(np.asarray(mu, dtype=float).reshape(-1, 1, 1), 1e-7, 1.0 - 1e-9)
    a2 = np.maximum(np.clip(np.asarray(rough, dtype=float).reshape(-1, 1, 1), 0.0, 1.0) ** 4, 1e-30)
    sin_o = np.sqrt(1.0 - mu * mu)
    t_all, t_none = (1.0 - sin_o) / mu, (1.0 + sin_o) / mu
    u1, u2 = t_all**2 / (a2 + t_all**2), t_none**2 / (a2 + t_none**2)
    xs, ws = quadrature.smoothstep(n_u)
    u = np.concatenate([u1 * xs[:, None], u1 + (u2 - u1) * xs[:, None]], axis=-2)
    wu = np.concatenate([u1 * ws[:, None], (u2 - u1) * ws[:, None]], axis=-2)
    tan2 = a2 * u / np.maximum(1.0 - u, 1e-300)
    t = np.sqrt(tan2)
    cos_m = 1.0 / np.sqrt(1.0 + tan2)
    with np.errstate(divide="ignore", invalid="ignore"):
        edge = np.where(t > 0.0, mu * (tan2 - 1.0) / (2.0 * sin_o * t), -1.0)
    phi_max = np.arccos(np.clip(edge, -1.0, 1.0))
    px, pw = quadrature.smoothstep(n_phi)
    o_m = sin_o * t * cos_m * np.cos(phi_max * px) + mu * cos_m
    cos_i = 2.0 * o_m * cos_m - mu
    ok = (o_m > 0.0) & (cos_i > 0.0)
    ci = np.where(ok, cos_i, 1.0)

    def lam(c):
        return 0.5 * (np.sqrt(1.0 + a2 * np.maximum(1.0 - c * c, 0.0) / (c * c)) - 1.0)

    f = np.where(ok, o_m / (cos_m * mu) / (1.0 + lam(ci) + lam(mu)), 0.0) * pw * phi_max * wu / np.pi
    wgt = np.asarray(weight(np.where(ok, o_m, 1.0)), dtype=float)
    if wgt.ndim == f.ndim + 1:
        return np.einsum("mup,mupk->mk", f, wgt)
    return np.sum(f * wgt, axis=(-2, -1))


def sheen_albedo_numeric(mu, rough, quad: tuple[int, int] | None = None, lobe=None) -> np.ndarray:
    """The directional albedo of :func:`charlie_sheen` (or of ``lobe(rough, g)``, f cos(theta_light) of an
    isotropic lobe) for a viewer at cos ``mu`` (1-d ``mu``, ``rough``), by Gauss-Legendre quadrature over
    the light's cosine (split at 0.5, where the lobe has its knee at grazing angles) and azimuth (the lobe
    is symmetric about the view plane)."""
    from matremap.renderers.embedded.geometry import LocalGeometry

    n_t, n_p = quad or _SHEEN_QUAD
    x, w = quadrature.unit(n_t // 2)
    ct = np.concatenate([0.5 * x, 0.5 + 0.5 * x])
    wt = np.concatenate([0.5 * w, 0.5 * w])
    xp, wp = quadrature.unit(n_p)
    phi, wphi = np.pi * xp, np.pi * wp
    mu = np.clip(np.asarray(mu, dtype=float).reshape(-1, 1, 1), 1e-4, 1.0)
    rough = np.asarray(rough, dtype=float).reshape(-1, 1, 1)
    st = np.sqrt(1.0 - ct * ct)[:, None]
    i_dot_o = st * np.sqrt(1.0 - mu * mu) * np.cos(phi)[None, :] + ct[:, None] * mu
    g = LocalGeometry(np.broadcast_to(ct[:, None], i_dot_o.shape), np.broadcast_to(mu, i_dot_o.shape), i_dot_o)
    fcos = (lobe or charlie_sheen)(rough, g)
    return 2.0 * np.sum(fcos * wt[:, None] * wphi[None, :], axis=(-2, -1))


def _table_spec() -> str:
    spec = {
        "format": _TABLE_FORMAT,
        "nodes": [MU_NODES, ROUGH_NODES, F0_NODES],
        "quad": list(_QUAD),
        "sheen_quad": list(_SHEEN_QUAD),
    }
    return json.dumps(spec, sort_keys=True)


def _table_path() -> Path:
    digest = hashlib.sha256(_table_spec().encode()).hexdigest()[:12]
    return cache_dir() / f"layering_albedo_{digest}.npz"


def mu_nodes(n: int = MU_NODES) -> np.ndarray:
    """The cos_view nodes: uniform in sqrt(mu) (finer towards grazing, where albedos change fastest)."""
    return np.maximum((np.arange(n) / (n - 1)) ** 2, 1e-4)


def rough_nodes(n: int = ROUGH_NODES) -> np.ndarray:
    """The roughness nodes: uniform in [0, 1]."""
    return np.arange(n) / (n - 1)


def f0_nodes() -> np.ndarray:
    """The F0 nodes: uniform in F0^(1/4) (a dielectric's grazing Fresnel rises steeply as F0 leaves 0)."""
    return (np.arange(F0_NODES) / (F0_NODES - 1)) ** 4


def _build_tables() -> dict[str, np.ndarray]:
    """E_white [mu, r], E_dielectric [f0, mu, r] and E_sheen [mu, r] on the nodes (see the module doc)."""
    mus, roughs, f0s = mu_nodes(), rough_nodes(), f0_nodes()
    etas = ior_from_f0(np.minimum(f0s, 0.99999))
    white = np.zeros((MU_NODES, ROUGH_NODES))
    diel = np.zeros((F0_NODES, MU_NODES, ROUGH_NODES))
    sheen = np.zeros((MU_NODES, ROUGH_NODES))

    def fresnel(c):
        return np.where(f0s >= 1.0, 1.0, fresnel_dielectric(c[..., None], etas))

    for k, r in enumerate(roughs):
        if r == 0.0:  # a mirror reflects the Fresnel factor of the view angle
            white[:, k] = 1.0
            diel[:, :, k] = fresnel(mus).T
        else:
            rr = np.full_like(mus, r)
            white[:, k] = ggx_weighted_albedo(mus, rr, np.ones_like)
            diel[:, :, k] = ggx_weighted_albedo(mus, rr, fresnel).T
        sheen[:, k] = sheen_albedo_numeric(mus, np.full_like(mus, r))
    return {"white": np.clip(white, 0, 1), "dielectric": np.clip(diel, 0, 1), "sheen": np.clip(sheen, 0, 1)}


@functools.cache
def albedo_tables() -> dict[str, np.ndarray]:
    """The albedo tables, from the cache or built (about half a minute)."""
    path = _table_path()
    shapes = {
        "white": (MU_NODES, ROUGH_NODES),
        "dielectric": (F0_NODES, MU_NODES, ROUGH_NODES),
        "sheen": (MU_NODES, ROUGH_NODES),
    }
    tables = load_tables(path, _table_spec(), shapes)
    if tables is None:
        tables = _build_tables()
        save_tables(path, "layering_albedo_*.npz", spec=np.array(_table_spec()), **tables)
    for t in tables.values():
        t.flags.writeable = False
    return tables


def _lerp(x, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    x = np.clip(np.asarray(x, dtype=float), 0.0, 1.0) * (n - 1)
    i = np.minimum(np.floor(x).astype(np.intp), n - 2)
    return i, i + 1, x - i


def _one_value(a: np.ndarray) -> float | None:
    """The value every element of ``a`` holds, or None when they differ (or there are none)."""
    return float(a.flat[0]) if a.size and float(np.min(a)) == float(np.max(a)) else None


def _shaped(out: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """``out`` broadcast (as a copy) to ``shape`` where it is not that shape already."""
    return out if np.shape(out) == shape else np.array(np.broadcast_to(out, shape))


def _bilinear(table: np.ndarray, mu, rough, plane=()) -> np.ndarray:
    """``table[*plane, mu, r]`` read bilinearly in (sqrt(mu), r) (nodes as :func:`mu_nodes` and
    :func:`rough_nodes` make them, as many as the table has); ``plane`` indexes leading axes."""
    n_mu, n_rough = table.shape[-2:]
    r = np.asarray(rough, dtype=float)
    one = _one_value(r)
    if all(np.ndim(p) == 0 for p in plane) and one is not None:
        # one roughness (a uniform material): the table's column at it, then linear along mu -- the same
        # bilinear value with two gathers per pixel from a short column instead of four from the table
        r0, r1, tr = _lerp(one, n_rough)
        column = (1 - tr) * table[(*plane, slice(None), r0)] + tr * table[(*plane, slice(None), r1)]
        m0, m1, tm = _lerp(np.sqrt(np.clip(mu, 0.0, 1.0)), n_mu)
        out = column[m0]
        out *= 1 - tm
        out += tm * column[m1]
        return _shaped(out, np.broadcast_shapes(np.shape(mu), r.shape))
    m0, m1, tm = _lerp(np.sqrt(np.clip(mu, 0.0, 1.0)), n_mu)
    r0, r1, tr = _lerp(rough, n_rough)
    row0 = (1 - tr) * table[(*plane, m0, r0)] + tr * table[(*plane, m0, r1)]
    row1 = (1 - tr) * table[(*plane, m1, r0)] + tr * table[(*plane, m1, r1)]
    return (1 - tm) * row0 + tm * row1


def white_albedo(mu, rough) -> np.ndarray:
    """E(mu, r) of the white single-scatter GGX lobe, read bilinearly from the table."""
    return _bilinear(albedo_tables()["white"], mu, rough)


def dielectric_albedo(mu, rough, f0) -> np.ndarray:
    """E(mu, r) of the single-scatter GGX lobe with the real dielectric Fresnel of normal reflectance
    ``f0`` (eta = (1 + sqrt F0)/(1 - sqrt F0)), read trilinearly from the table."""
    table = albedo_tables()["dielectric"]
    f = np.asarray(f0, dtype=float)
    one = _one_value(f)  # one F0 (a uniform material): scalar planes, so that _bilinear reads one column
    k0, k1, tk = _lerp(np.sqrt(np.sqrt(np.clip(f if one is None else one, 0.0, 1.0))), F0_NODES)
    out = (1 - tk) * _bilinear(table, mu, rough, (k0,)) + tk * _bilinear(table, mu, rough, (k1,))
    return _shaped(out, np.broadcast_shapes(np.shape(out), f.shape))


def sheen_albedo(mu, rough) -> np.ndarray:
    """E(mu, r) of the white Charlie sheen, read bilinearly from the table."""
    return _bilinear(albedo_tables()["sheen"], mu, rough)


_GLTF_SHEEN_FORMAT = 1
_GLTF_SHEEN_QUAD = (160, 96)
#: nodes of the glTF sheen table (cos_view, sheenRoughness): finer in roughness than the others, as the
#: lobe's albedo at grazing views changes fast below sheenRoughness 0.2
GLTF_SHEEN_NODES = (48, 96)


def _gltf_sheen_spec() -> str:
    spec = {"format": _GLTF_SHEEN_FORMAT, "nodes": list(GLTF_SHEEN_NODES), "quad": list(_GLTF_SHEEN_QUAD)}
    return json.dumps(spec, sort_keys=True)


@functools.cache
def gltf_sheen_table() -> np.ndarray:
    """E[mu node, roughness node] of the white glTF sheen (:func:`gltf_sheen`), from the cache or integrated
    (a few seconds); a table file of its own, so the other tables' cache stays valid."""
    spec = _gltf_sheen_spec()
    path = cache_dir() / f"gltf_sheen_albedo_{hashlib.sha256(spec.encode()).hexdigest()[:12]}.npz"
    data = load_tables(path, spec, {"sheen": GLTF_SHEEN_NODES})
    if data is None:
        mus = mu_nodes(GLTF_SHEEN_NODES[0])
        table = np.stack(
            [
                sheen_albedo_numeric(mus, np.full_like(mus, r), _GLTF_SHEEN_QUAD, gltf_sheen)
                for r in rough_nodes(GLTF_SHEEN_NODES[1])
            ],
            axis=1,
        )
        data = {"sheen": np.clip(table, 0.0, 1.0)}
        save_tables(path, "gltf_sheen_albedo_*.npz", spec=np.array(spec), **data)
    table = data["sheen"]
    table.flags.writeable = False
    return table


def gltf_sheen_albedo(mu, rough) -> np.ndarray:
    """E(mu, sheenRoughness) of the white glTF sheen, read bilinearly (in sqrt(mu), sheenRoughness)."""
    return _bilinear(gltf_sheen_table(), mu, rough)


def multiscatter_gain(f0, mu, rough) -> np.ndarray:
    """Turquin's factor 1 + F0 (1 - E) / E on a GGX lobe (E the white albedo at the view angle)."""
    e = np.maximum(white_albedo(mu, rough), 1e-6)
    return 1.0 + np.asarray(f0, dtype=float) * (1.0 - e) / e


__all__ = [
    "INV_PI",
    "albedo_tables",
    "artistic_conductor",
    "average_fresnel",
    "charlie_lambda",
    "charlie_sheen",
    "dielectric_albedo",
    "eon_diffuse",
    "f82_tint",
    "fon_albedo",
    "fon_average_albedo",
    "ggx_lobe",
    "gltf_sheen",
    "gltf_sheen_albedo",
    "gltf_sheen_table",
    "ltc_cosine",
    "ggx_weighted_albedo",
    "modulated_ior",
    "multiscatter_gain",
    "qon_diffuse",
    "refracted_cos",
    "sheen_albedo",
    "sheen_albedo_numeric",
    "white_albedo",
    "zeltner_albedo",
    "zeltner_ltc",
    "zeltner_sheen",
]
