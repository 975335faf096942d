"""glTF 2.0 metallic-roughness material, emulated as its specification defines it.

Source: the glTF 2.0 specification, Appendix B "BRDF Implementation" (Khronos, 2021), and the
extensions KHR_materials_ior and KHR_materials_specular. In the spec's notation (V view, L light,
H half vector, all dot products clamped to [0, 1]):

* alpha = roughness^2;
* D = alpha^2 / (pi ((N.H)^2 (alpha^2 - 1) + 1)^2)  (Trowbridge-Reitz / GGX);
* the visibility term V = G / (4 |N.L| |N.V|) with Smith's GGX masking-shadowing, by default in
  its height-correlated form, G = 1 / (1 + Lambda(L) + Lambda(V)) (what the Khronos sample viewer
  and most engines evaluate; option ``visibility=separable`` gives the product G1(L) G1(V) the
  appendix writes out);
* Schlick's Fresnel F(f0, f90) = f0 + (f90 - f0) (1 - |V.H|)^5;
* metal_brdf = F(baseColor, 1) D V;
* dielectric_brdf = (1 - specular max_c(fr)) baseColor / pi + specular fr D V, where
  fr = F(min(((ior - 1)/(ior + 1))^2 specularColor, 1), 1) per channel: KHR_materials_ior and
  the ratified KHR_materials_specular (its ``fresnel_mix``: the diffuse base is weighted by one
  number, the largest channel of fr). Without the extensions ior = 1.5 gives f0 = 0.04 and
  specular = specularColor = 1, the core spec's mix(diffuse, specular, F(0.04, 1));
* material = mix(dielectric_brdf, metal_brdf, metallic).

The parameter names are the glTF JSON property names without ``Factor``.
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
