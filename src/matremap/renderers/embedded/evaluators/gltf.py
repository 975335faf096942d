"""The embedded renderer's evaluators of the gltf dialect: f * cos(theta_i) of each model of
:mod:`matremap.dialects.gltf` (its model table, the formulas and their sources are there), as numpy
functions of [N, C, L, P] arrays, zero where either cosine is <= 0 (the renderer masks that).

``gltf:pbr`` is ``gltf:metal-rough`` (the same function) with the KHR_materials_sheen layer over it and the
KHR_materials_clearcoat layer over both; a layer at its default (sheenColor 0, clearcoat 0) multiplies by
exactly 1 and adds exactly 0, so the model is then gltf:metal-rough bit for bit.
"""

from __future__ import annotations

import numpy as np

from matremap.core.optics import dielectric_f0
from matremap.dialects.gltf import METAL_ROUGH, PBR
from matremap.renderers.embedded import layering as ly
from matremap.renderers.embedded import microfacet as mf

#: F0 of the clear coat: ior 1.5 (KHR_materials_clearcoat, "Clearcoat")
CLEARCOAT_F0 = 0.04


def specular_dv(roughness, opt, g) -> np.ndarray:
    """D V cos(theta_light) of glTF's specular_brdf (Appendix B): GGX, alpha = roughness^2, Smith visibility
    height-correlated or separable (option ``visibility``); zero for a mirror under point lights, a lobe of
    ``g.mirror_alpha`` where the renderer samples the mirror direction
    (:func:`~matremap.renderers.embedded.microfacet.drawn_alpha`)."""
    alpha = mf.drawn_alpha(roughness**2, g)
    a = np.maximum(alpha, 1e-7)
    d = mf.d_ggx(g.cos_h, g.tan2_h, a)
    if opt["visibility"] == "separable":
        gg = mf.g1_ggx(g.tan_i, a) * mf.g1_ggx(g.tan_o, a)
    else:
        gg = mf.g_height_correlated(mf.lambda_ggx(g.tan_i, a), mf.lambda_ggx(g.tan_o, a))
    return np.where(alpha * alpha <= 1e-14, 0.0, d * gg / (4.0 * np.maximum(g.cos_o, 1e-12)))  # D V cos(L)


def metal_rough(p, opt, g):
    lobe = specular_dv(p["roughness"], opt, g)
    w = g.schlick_weight
    base, metallic = p["baseColor"], p["metallic"]
    f0 = dielectric_f0(p["ior"], 1.0, p["specularColor"])
    fr = f0 + (1.0 - f0) * w
    weight = p["specular"]
    dielectric = (1.0 - weight * np.max(fr, axis=1, keepdims=True)) * base * g.lambert + (weight * fr) * lobe
    metal = (base + (1.0 - base) * w) * lobe
    return (1.0 - metallic) * dielectric + metallic * metal


def sheen_layer(p, g, material) -> np.ndarray:
    """KHR_materials_sheen: f_sheen + material min(1 - max(sheenColor) E(N.V), 1 - max(sheenColor) E(N.L))."""
    colour = np.asarray(p["sheenColor"], dtype=float)
    rough = p["sheenRoughness"]
    strength = np.max(colour, axis=1, keepdims=True)
    scaling = np.minimum(
        1.0 - strength * ly.gltf_sheen_albedo(g.cos_o, rough), 1.0 - strength * ly.gltf_sheen_albedo(g.cos_i, rough)
    )
    return colour * ly.gltf_sheen(rough, g) + material * scaling


def clearcoat_layer(p, opt, g, material) -> np.ndarray:
    """KHR_materials_clearcoat: material (1 - clearcoat Fc) + clearcoat Fc D V, Fc Schlick's of N.V, F0 0.04."""
    m = 1.0 - np.clip(g.cos_o, 0.0, 1.0)
    m2 = m * m
    fresnel = CLEARCOAT_F0 + (1.0 - CLEARCOAT_F0) * (m2 * m2 * m)
    weight = p["clearcoat"] * fresnel
    return material * (1.0 - weight) + weight * specular_dv(p["clearcoatRoughness"], opt, g)


def transmitted_diffuse(p, g) -> np.ndarray:
    """The diffuse reflection KHR_materials_transmission takes away: (1 - metallic) transmission (1 - specular
    max F) baseColor/pi cos (the specular BTDF that replaces it reflects nothing)."""
    f0 = dielectric_f0(p["ior"], 1.0, p["specularColor"])
    fr = f0 + (1.0 - f0) * g.schlick_weight
    weight = 1.0 - p["specular"] * np.max(fr, axis=1, keepdims=True)
    return (1.0 - p["metallic"]) * p["transmission"] * weight * p["baseColor"] * g.lambert


def pbr(p, opt, g):
    """gltf:pbr: the metallic-roughness material less what it transmits, the sheen over it, the clear coat over
    both."""
    material = metal_rough(p, opt, g)
    if np.any(np.asarray(p["transmission"]) > 0.0):
        material = material - transmitted_diffuse(p, g)
    return clearcoat_layer(p, opt, g, sheen_layer(p, g, material))


#: model id -> evaluator
EVALUATORS = {METAL_ROUGH.id: metal_rough, PBR.id: pbr}
