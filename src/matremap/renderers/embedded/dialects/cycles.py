"""Blender Cycles (Blender >= 2.80) BSDF nodes, emulated: Glossy BSDF (+ a Diffuse BSDF added).

Source: Cycles ``intern/cycles/kernel/closure/bsdf_microfacet.h`` and
``bsdf_ashikhmin_shirley.h``; ``kernel/svm/closure.h`` for alpha = Roughness^2.

cycles:glossy -- Blender's Glossy BSDF node plus a Diffuse BSDF node joined by an Add Shader:

==============  ===============================================================================
parameter       meaning (node socket names)
==============  ===============================================================================
distribution    ggx*, beckmann, ashikhmin_shirley (Multiscatter GGX is not emulated)
Color           RGB in [0, 1], default 0.8; no Fresnel: the lobe is multiplied by it
Roughness       scalar in [0, 1], default 0.5; alpha = Roughness^2
Diffuse Color   RGB in [0, 1], default 0 (no diffuse node); Lambertian Color/pi
==============  ===============================================================================

* GGX / Beckmann: f = Color D G / (4 cos_i cos_o) with the height-correlated Smith
  G = 1/(1 + Lambda(i) + Lambda(o)) used since Blender 3.5; zero when alpha^2 <= 2e-10.
* Ashikhmin-Shirley: alpha clamped to [1e-4, 1] (zero at or below 1e-4), n = 2/alpha^2 - 2,
  f cos_i = cos_i (n+1)/(8 pi) (n.h)^n / max(1e-6, (h.o) max(cos_i, cos_o)), cosines floored at 1e-6.

cycles:diffuse -- the Diffuse BSDF node with Roughness 0 (Lambert): Color/pi.
"""

from __future__ import annotations

import numpy as np

from ....models import ModelSpec, OptionSpec, ParamSpec, register_white_reference
from .. import microfacet as mf
from . import dialect

INV_PI = 1.0 / np.pi

GLOSSY = ModelSpec(
    id="cycles:glossy",
    summary="Glossy BSDF (+ Diffuse BSDF), alpha = Roughness^2",
    params=(
        ParamSpec("Color", "specular", (0.8,) * 3, (0.0, 1.0), channels=3),
        ParamSpec("Roughness", "roughness", 0.5, (0.0, 1.0), doc="alpha = Roughness^2"),
        ParamSpec("Diffuse Color", "diffuse", (0.0,) * 3, (0.0, 1.0), channels=3),
    ),
    options=(OptionSpec("distribution", ("ggx", "beckmann", "ashikhmin_shirley"), "ggx"),),
    diffuse_only={"Color": 0.0},
    specular_only={"Diffuse Color": 0.0},
    reflectance=("param", "Color"),
)


@dialect(GLOSSY)
def glossy(p, opt, g):
    alpha = p["Roughness"] ** 2
    distribution = opt["distribution"]
    if distribution == "ashikhmin_shirley":
        lobe = _ashikhmin_shirley(alpha, g)
    else:
        if distribution == "ggx":
            d = mf.d_ggx(g.cos_h, g.tan2_h, alpha)
            lam = mf.lambda_ggx
        else:
            d = mf.d_beckmann(g.cos_h, g.tan2_h, alpha)
            lam = mf.lambda_beckmann
        gg = mf.g_height_correlated(lam(g.tan_i, alpha), lam(g.tan_o, alpha))
        lobe = np.where(alpha * alpha <= 2e-10, 0.0, d * gg / (4.0 * g.cos_o))
    return p["Color"] * lobe + p["Diffuse Color"] * g.lambert


def _ashikhmin_shirley(alpha: np.ndarray, g) -> np.ndarray:
    a = np.clip(alpha, 1e-4, 1.0)
    n = 2.0 / (a * a) - 2.0
    cos_i = np.maximum(g.cos_i, 1e-6)
    cos_o = np.maximum(g.cos_o, 1e-6)
    cos_h = np.maximum(g.cos_h, 1e-6)
    h_dot = np.maximum(g.i_dot_h, 1e-6)
    lobe = cos_i * (n + 1.0) / (8.0 * np.pi) * np.power(cos_h, n) / np.maximum(1e-6, h_dot * np.maximum(cos_i, cos_o))
    return np.where(alpha <= 1e-4, 0.0, lobe)


DIFFUSE = ModelSpec(
    id="cycles:diffuse",
    summary="Diffuse BSDF (Lambert)",
    params=(ParamSpec("Color", "diffuse", (0.8,) * 3, (0.0, 1.0), channels=3),),
    diffuse_only={},
    specular_only=None,
)


@dialect(DIFFUSE)
def diffuse(p, opt, g):
    return p["Color"] * g.lambert


register_white_reference("cycles", "cycles:diffuse", {"Color": 1.0})
