"""The embedded renderer's evaluators of the usd dialect: f * cos(theta_i) of each model of
:mod:`matremap.dialects.usd` (its model table, the formulas, their sources and the choices made where the
UsdPreviewSurface specification is silent are there), as numpy functions of [N, C, L, P] arrays, zero where
either cosine is <= 0 (the renderer masks that).
"""

from __future__ import annotations

import numpy as np

from matremap.core.optics import f0_from_ior
from matremap.dialects.usd import PREVIEW_SURFACE, metalness_f0_f90
from matremap.renderers.embedded import microfacet as mf

#: alpha^2 at or below which a lobe is a mirror no point light reaches (as in the gltf evaluator)
MIRROR_ALPHA2 = 1e-14


def smith_schlick_g1(cos_v: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Storm's masking term G1 = N.v / (N.v (1 - k) + k), k = alpha / 2."""
    return cos_v / (cos_v * (1.0 - k) + k)


def ggx_lobe(roughness: np.ndarray, g) -> np.ndarray:
    """D G / (4 N.L N.E) times N.L: GGX with alpha = roughness^2 and Storm's separable Smith-Schlick G; a mirror
    zero under point lights, a lobe of ``g.mirror_alpha`` where the renderer samples the mirror direction."""
    alpha = mf.drawn_alpha(roughness * roughness, g)
    a = np.maximum(alpha, 1e-7)
    d = mf.d_ggx(g.cos_h, g.tan2_h, a)
    k = 0.5 * a
    cos_i, cos_o = np.maximum(g.cos_i, 1e-12), np.maximum(g.cos_o, 1e-12)
    gg = smith_schlick_g1(cos_i, k) * smith_schlick_g1(cos_o, k)
    return np.where(alpha * alpha <= MIRROR_ALPHA2, 0.0, d * gg / (4.0 * cos_o))


def preview_surface(p, opt, g):
    w = g.schlick_weight
    diffuse_color = p["diffuseColor"]
    f0: np.ndarray
    f90: np.ndarray | float
    kd: np.ndarray | float
    if opt["useSpecularWorkflow"] == "1":
        f0, f90, kd = p["specularColor"], 1.0, 1.0
    else:
        f0, f90 = metalness_f0_f90(diffuse_color, p["metallic"], p["ior"])
        kd = 1.0 - p["metallic"]
    fresnel = f0 + (f90 - f0) * w
    out = kd * (1.0 - fresnel) * diffuse_color * g.lambert + fresnel * ggx_lobe(p["roughness"], g)
    coat = p["clearcoat"]
    if np.any(coat > 0):
        r2 = f0_from_ior(p["ior"])
        out = out + coat * (r2 + (1.0 - r2) * w) * ggx_lobe(p["clearcoatRoughness"], g)
    return out


#: model id -> evaluator
EVALUATORS = {PREVIEW_SURFACE.id: preview_surface}
