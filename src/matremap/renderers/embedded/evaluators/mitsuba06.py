"""The embedded renderer's evaluators of the mitsuba06 dialect: f * cos(theta_i) of each model of
:mod:`matremap.dialects.mitsuba06` (its model table, the formulas and their sources are there), as numpy
functions of [N, C, L, P] arrays, zero where either cosine is <= 0 (the renderer masks that).
"""

from __future__ import annotations

import numpy as np

from matremap.core.inplace import into
from matremap.core.optics import fresnel_conductor, fresnel_dielectric
from matremap.dialects.mitsuba06 import DIFFUSE, PBR, PHONG, ROUGHCONDUCTOR, ROUGHPLASTIC, WARD
from matremap.renderers.embedded import microfacet as mf

INV_PI = 1.0 / np.pi


def energy_clamp(rho_s: np.ndarray, rho_d: np.ndarray) -> np.ndarray:
    """Mitsuba 0.6 ``BSDF::ensureEnergyConservation`` (``src/librender/bsdf.cpp``): when the largest
    per-channel sum rho_s + rho_d exceeds 1, both are scaled by 0.99 / (that sum).
    Returns the scale factor, broadcastable to the inputs."""
    total = np.max(rho_s + rho_d, axis=1, keepdims=True)  # parameters are [N, C, 1, 1]
    return np.where(total > 1.0, 0.99 / np.maximum(total, 1e-300), 1.0)


def _microfacet(distribution: str, alpha: np.ndarray, g) -> np.ndarray:
    """D G / (4 cos_o): the microfacet lobe times cos_i, without Fresnel."""
    d = mf.d_mitsuba06(distribution, g, alpha)
    gg = mf.g_mitsuba06(distribution, g.tan_i, g.tan_o, alpha)
    return into(np.divide, into(np.multiply, d, gg), 4.0 * g.cos_o)


def diffuse(p, opt, g):
    return p["reflectance"] * g.lambert


def ward(p, opt, g):
    alpha = p["alpha"]
    a2 = alpha * alpha
    variant = opt["variant"]
    if variant == "ward":
        factor = 1.0 / (4.0 * np.pi * a2 * np.sqrt(g.cos_i * g.cos_o))
    elif variant == "ward-duer":
        factor = 1.0 / (4.0 * np.pi * a2 * g.cos_i * g.cos_o)
    else:  # balanced
        hz2 = g.h_z * g.h_z
        factor = g.h_len2 / (np.pi * a2 * hz2 * hz2)
    lobe = factor * np.exp(-g.tan2_h / a2)
    lobe = np.where(lobe > 1e-10, lobe, 0.0)
    rho_s, rho_d = p["specularReflectance"], p["diffuseReflectance"]
    scale = energy_clamp(rho_s, rho_d)
    return (scale * rho_s) * (lobe * g.cos_i) + (scale * rho_d) * g.lambert


def phong(p, opt, g):
    e = p["exponent"]
    lobe = (e + 2.0) * (0.5 * INV_PI) * np.power(np.maximum(g.cos_reflect, 0.0), e)
    rho_s, rho_d = p["specularReflectance"], p["diffuseReflectance"]
    scale = energy_clamp(rho_s, rho_d)
    return (scale * rho_s) * (lobe * g.cos_i) + (scale * rho_d) * g.lambert


def roughconductor(p, opt, g):
    ext = p["extEta"]
    f = fresnel_conductor(g.i_dot_h, p["eta"] / ext, p["k"] / ext)
    return p["specularReflectance"] * f * _microfacet(opt["distribution"], p["alpha"], g)


def roughplastic(p, opt, g):
    from matremap.renderers.embedded.rough_transmittance import diffuse_fresnel_reflectance, transmittance

    distribution, alpha = opt["distribution"], np.maximum(p["alpha"], mf.ALPHA_MIN)
    eta = p["intIOR"] / p["extIOR"]
    ks, rho_d = p["specularReflectance"], p["diffuseReflectance"]
    # (ks F) lobe: a ks of 1 changes no number, and a ks of 0 (the diffuse part) makes +0 of the finite F lobe
    spec = None
    if np.any(ks):
        fresnel = fresnel_dielectric(g.i_dot_h, eta)
        spec = into(np.multiply, fresnel if np.all(ks == 1.0) else ks * fresnel, _microfacet(distribution, alpha, g))
    if not np.any(rho_d > 0):
        return spec if spec is not None else ks * g.lambert
    fdr = diffuse_fresnel_reflectance(distribution, alpha, 1.0 / eta)
    rho = rho_d / (1.0 - rho_d * fdr) if opt["nonlinear"] == "true" else rho_d / (1.0 - fdr)
    t12 = transmittance(distribution, g.cos_i, alpha, eta)
    t21 = transmittance(distribution, g.cos_o, alpha, eta)
    diffuse = rho * into(np.divide, into(np.multiply, g.lambert * t12, t21), eta * eta)
    return diffuse if spec is None else into(np.add, spec, diffuse)


def pbr(p, opt, g):
    f0 = p["F0"]
    fresnel = into(np.add, (1.0 - f0) * g.schlick_weight, f0)  # Schlick: F0 + (1 - F0)(1 - i.h)^5
    lobe = _microfacet(opt["distribution"], p["alpha"], g)
    # (ks F) lobe + rho_d cos/pi; a factor ks of 1 and a term of rho_d 0 change no number: skipped
    ks, rho_d = p["specularReflectance"], p["diffuseReflectance"]
    spec = into(np.multiply, fresnel if np.all(ks == 1.0) else ks * fresnel, lobe)
    return spec if not np.any(rho_d) else spec + rho_d * g.lambert


#: model id -> evaluator
EVALUATORS = {
    DIFFUSE.id: diffuse,
    WARD.id: ward,
    PHONG.id: phong,
    ROUGHCONDUCTOR.id: roughconductor,
    ROUGHPLASTIC.id: roughplastic,
    PBR.id: pbr,
}
