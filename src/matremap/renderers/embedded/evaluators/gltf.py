"""The embedded renderer's evaluators of the gltf dialect: f * cos(theta_i) of each model of
:mod:`matremap.dialects.gltf` (its model table, the formulas and their sources are there), as numpy
functions of [N, C, L, P] arrays, zero where either cosine is <= 0 (the renderer masks that).
"""

from __future__ import annotations

import numpy as np

from matremap.core.optics import dielectric_f0
from matremap.dialects.gltf import METAL_ROUGH
from matremap.renderers.embedded import microfacet as mf


def metal_rough(p, opt, g):
    alpha = p["roughness"] ** 2
    a = np.maximum(alpha, 1e-7)
    d = mf.d_ggx(g.cos_h, g.tan2_h, a)
    if opt["visibility"] == "separable":
        gg = mf.g1_ggx(g.tan_i, a) * mf.g1_ggx(g.tan_o, a)
    else:
        gg = mf.g_height_correlated(mf.lambda_ggx(g.tan_i, a), mf.lambda_ggx(g.tan_o, a))
    lobe = np.where(alpha * alpha <= 1e-14, 0.0, d * gg / (4.0 * np.maximum(g.cos_o, 1e-12)))  # D V cos(L)
    w = g.schlick_weight
    base, metallic = p["baseColor"], p["metallic"]
    f0 = dielectric_f0(p["ior"], 1.0, p["specularColor"])
    fr = f0 + (1.0 - f0) * w
    weight = p["specular"]
    dielectric = (1.0 - weight * np.max(fr, axis=1, keepdims=True)) * base * g.lambert + (weight * fr) * lobe
    metal = (base + (1.0 - base) * w) * lobe
    return (1.0 - metallic) * dielectric + metallic * metal


#: model id -> evaluator
EVALUATORS = {METAL_ROUGH.id: metal_rough}
