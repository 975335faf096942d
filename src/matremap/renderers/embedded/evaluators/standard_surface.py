"""The embedded renderer's evaluator of ``mtlx:standard_surface``: Autodesk Standard Surface v1.0.1
(its reflection) as f * cos(theta_light) on [N, C, L, P] arrays.

Source: the Autodesk Standard Surface specification, version 1.0.1.1 (Autodesk/standard-surface
``index.html``), section "Closures", whose closure formulas are evaluated with reflectance(brdf) the
lobe's directional albedo at the view angle (the spec assumes such a function; here it is integrated
numerically, :mod:`..layering`):

* "Coating": coat_layer = coat coat_brdf + lerp(1, coat_color (1 - E_coat), coat) specular_mixture;
  coat_brdf GGX with alpha = coat_roughness^2 and the dielectric Fresnel of coat_IOR.
* "Metal": specular_mixture = metalness metal_brdf + (1 - metalness) specular_reflection_layer; metal_brdf
  GGX (alpha = specular_roughness^2) with the exact conductor Fresnel of the complex IOR Gulbrandsen's
  artist-friendly mapping gives for reflectivity base base_color and edge tint specular specular_color
  (the section cites [Gulbrandsen2014]; the spec's OSL reference does the same).
* "Specular reflection": specular specular_color specular_brdf + (1 - specular specular_color E_specular)
  sheen_layer, with specular_brdf GGX and the dielectric Fresnel of specular_IOR.
* "Specular transmission": transmission_sheen_mix = transmission transm_color specular_btdf
  + (1 - transmission) sheen_layer; the BTDF reflects nothing, so the reflection keeps (1 - transmission)
  sheen_layer (what it transmits: ``..transmission.standard_surface_interface``).
* "Sheen": sheen sheen_color sheen_brdf + (1 - sheen E_sheen) base_mix, sheen_brdf the Estevez-Kulla
  ("Charlie") distribution with sheen_roughness, under the visibility MaterialX 1.39 uses.
* "Diffuse reflection": base_mix = base base_color diffuse_brdf, Oren-Nayar with sigma = diffuse_roughness
  (the qualitative model, as MaterialX 1.39's ``oren_nayar_diffuse_bsdf``).

The spec is silent on multiple scattering; option ``multiscatter=turquin`` (default, as MaterialX's
implementation) puts Turquin's factor on each GGX lobe and its albedo. Not modelled (default 0 in the
spec): coat_affect_color, coat_affect_roughness, thin film, anisotropy.
"""

from __future__ import annotations

import numpy as np

from matremap.core.optics import f0_from_ior, fresnel_conductor, fresnel_dielectric
from matremap.dialects.mtlx import STANDARD_SURFACE
from matremap.renderers.embedded import layering as ly


def sheen_layer(p, g) -> np.ndarray:
    """sheen sheen_color sheen_brdf + (1 - sheen E_sheen) base base_color oren_nayar."""
    sheen = np.clip(p["sheen"], 0.0, 1.0)
    rough = p["sheen_roughness"]
    diffuse = ly.qon_diffuse(p["base"] * p["base_color"], p["diffuse_roughness"], g)
    return (
        sheen * p["sheen_color"] * ly.charlie_sheen(rough, g)
        + (1.0 - sheen * ly.sheen_albedo(g.cos_o, rough)) * diffuse
    )


def transmission_sheen_mix(p, g) -> np.ndarray:
    """The reflection of transmission transm_color specular_btdf + (1 - transmission) sheen_layer: the BTDF
    reflects nothing."""
    below = sheen_layer(p, g)
    if not np.any(np.asarray(p["transmission"]) > 0.0):
        return below
    return (1.0 - np.clip(p["transmission"], 0.0, 1.0)) * below


def specular_reflection_layer(p, g, below, multi: bool) -> np.ndarray:
    """specular specular_color specular_brdf + (1 - specular specular_color E_specular) below."""
    rough, ior = p["specular_roughness"], p["specular_IOR"]
    f0 = f0_from_ior(ior)
    gain = ly.multiscatter_gain(f0, g.cos_o, rough) if multi else 1.0
    brdf = fresnel_dielectric(g.i_dot_h, ior) * ly.ggx_lobe(rough, g) * gain
    weight = p["specular"] * p["specular_color"]
    return weight * brdf + (1.0 - weight * ly.dielectric_albedo(g.cos_o, rough, f0) * gain) * below


def metal_brdf(p, g, multi: bool) -> np.ndarray:
    """GGX with the exact conductor Fresnel of Gulbrandsen's (n, k)."""
    reflectivity = p["base"] * p["base_color"]
    n, k = ly.artistic_conductor(reflectivity, p["specular"] * p["specular_color"])
    rough = p["specular_roughness"]
    gain = ly.multiscatter_gain(np.clip(reflectivity, 0.0, 0.99), g.cos_o, rough) if multi else 1.0
    return fresnel_conductor(g.i_dot_h, n, k) * ly.ggx_lobe(rough, g) * gain


def standard_surface(p, opt, g):
    """f * cos(theta_light) of Standard Surface (see the module docstring for each closure)."""
    multi = opt["multiscatter"] == "turquin"
    metalness = np.clip(p["metalness"], 0.0, 1.0)
    dielectric = specular_reflection_layer(p, g, transmission_sheen_mix(p, g), multi)
    mixture = metalness * metal_brdf(p, g, multi) + (1.0 - metalness) * dielectric
    coat = np.clip(p["coat"], 0.0, 1.0)
    ior, rough = p["coat_IOR"], p["coat_roughness"]
    f0 = f0_from_ior(ior)
    gain = ly.multiscatter_gain(f0, g.cos_o, rough) if multi else 1.0
    coat_brdf = fresnel_dielectric(g.i_dot_h, ior) * ly.ggx_lobe(rough, g) * gain
    e_coat = ly.dielectric_albedo(g.cos_o, rough, f0) * gain
    return coat * coat_brdf + ((1.0 - coat) + coat * p["coat_color"] * (1.0 - e_coat)) * mixture


#: model id -> evaluator
EVALUATORS = {STANDARD_SURFACE.id: standard_surface}
