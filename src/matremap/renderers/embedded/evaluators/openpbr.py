"""The embedded renderer's evaluator of ``mtlx:open_pbr_surface``: OpenPBR Surface v1.1 (opaque part) as
f * cos(theta_light) on [N, C, L, P] arrays.

Source: the OpenPBR Surface specification v1.1 (text of v1.1.1, AcademySoftwareFoundation/OpenPBR
``index.html``); section names in quotes. The layering follows "Model > Reduction to a mixture of lobes"
(non-thin-walled mode, albedo scaling):

  f_surface      = F f_fuzz + lerp(1, 1 - E_fuzz, F) f_coated            ("Fuzz", eq. fuzz-layering-approx)
  f_coated       = C f_coat + lerp(1, T_coat (1 - E_coat), C) Delta_C f_base  ("Coat"; "Darkening")
  f_base         = lerp(f_dielectric, f_conductor, M)                       ("Base substrate")
  f_dielectric   = f_specular + (1 - E_specular) f_diffuse                  ("Glossy-diffuse")

* f_specular ("Dielectric base"): GGX (alpha = r^2, "Microfacet model") times the real dielectric Fresnel
  of the IOR ratio eta'_s times specular_color. eta_s = lerp(specular_ior, eta_bc, C) with
  eta_bc = specular_ior/coat_ior, inverted when below 1 ("Coat", eq. specular_ior_ratio, and "Total
  internal reflection", eq. specular_ior_ratio_with_tir_fix); eta'_s from eq. modulated_ior with
  xi_s = specular_weight. E_specular is its directional albedo (tinted: RGB).
* f_diffuse ("Glossy-diffuse"): base_weight times EON with rho = base_color, sigma = base_diffuse_roughness,
  times 1 - transmission_weight ("Translucent base": its BTDF reflects nothing; the coat darkening's base albedo
  loses the same share of the diffuse). What it transmits is drawn by ``..transmission``.
* f_conductor ("Metal"): GGX times specular_weight F82-tint(F0 = base_weight base_color, tint =
  specular_color), capped at 1 (specular_weight may exceed 1 for the dielectric only).
* Roughening ("Coat > Roughening"): the base lobes use lerp(r, min(1, r^4 + 2 r_coat^4)^(1/4), C).
* f_coat: GGX (coat_roughness) times the dielectric Fresnel of coat_ior; E_coat its albedo.
* T_coat ("Coat > View-dependent absorption"): coat_color^((1/mu_i^t + 1/mu_o^t)/2), the cosines refracted
  into the coat; coat_color at normal incidence.
* Delta_C ("Coat > Darkening"): lerp(1, (1 - K)/(1 - E_b K), C coat_darkening) with K = lerp(K_s, K_r, r_b),
  K_r = 1 - (1 - E_F(coat_ior))/coat_ior^2 (E_F the hemispherical Fresnel average, integrated here),
  K_s = F(mu_o, coat_ior), r_b = lerp(lerp(1, r, clamp(xi_s F_s)), r, M) and E_b the base's
  normal-incidence albedo lerp(E_spec + (1 - E_spec) base_weight base_color, specular_weight F0, M).
* f_fuzz ("Fuzz"): fuzz_color times Zeltner et al.'s LTC sheen (the fitted form the spec recommends),
  E_fuzz its albedo R(mu_o, fuzz_roughness) (grey: the fuzz does not tint the layers below).
* Multiple scattering ("Microfacet model"): with option ``multiscatter=turquin`` each GGX lobe and its
  albedo carry Turquin's factor 1 + F0 (1 - E)/E (F0 of the lobe's Fresnel at normal incidence).

The spec leaves these to the implementation; the choices here are those of its reference MaterialX graph
except: the directional albedos are integrated numerically (:mod:`..layering`) rather than fitted, the coat
absorption is view-dependent and the darkening follows the section's general K (the graph uses K_r with F0).
"""

from __future__ import annotations

import numpy as np

from matremap.core.optics import f0_from_ior, fresnel_dielectric
from matremap.dialects.mtlx import OPEN_PBR_SURFACE
from matremap.renderers.embedded import layering as ly


def coat_roughened(rough, coat_rough, coat) -> np.ndarray:
    """ "Coat > Roughening": lerp(r, min(1, r^4 + 2 r_coat^4)^(1/4), coat_weight)."""
    return (1.0 - coat) * rough + coat * np.minimum(1.0, rough**4 + 2.0 * coat_rough**4) ** 0.25


def specular_ior_ratio(specular_ior, coat_ior, coat) -> np.ndarray:
    """eta_s = lerp(n_b, eta_bc, C) with eta_bc = n_b/n_c, or n_c/n_b where that is below 1 (TIR fix)."""
    ratio = specular_ior / coat_ior
    fixed = np.where(ratio >= 1.0, ratio, 1.0 / ratio)
    return (1.0 - coat) * specular_ior + coat * fixed


def dielectric_base(p, g, rough, eta, multi: bool) -> tuple[np.ndarray, np.ndarray]:
    """f_dielectric = f_specular + (1 - E_specular) f_diffuse, and E_specular at normal incidence (for
    the coat darkening)."""
    f0 = f0_from_ior(eta)
    tint = p["specular_color"]
    lobe = ly.ggx_lobe(rough, g)
    gain = ly.multiscatter_gain(f0, g.cos_o, rough) if multi else 1.0
    specular = tint * fresnel_dielectric(g.i_dot_h, eta) * lobe * gain
    e_specular = tint * ly.dielectric_albedo(g.cos_o, rough, f0) * gain
    gain_n = ly.multiscatter_gain(f0, 1.0, rough) if multi else 1.0
    e_normal = tint * ly.dielectric_albedo(1.0, rough, f0) * gain_n
    diffuse = p["base_weight"] * ly.eon_diffuse(p["base_color"], p["base_diffuse_roughness"], g)
    if np.any(np.asarray(p["transmission_weight"]) > 0.0):  # "Translucent base": its BTDF reflects nothing
        diffuse = (1.0 - np.clip(p["transmission_weight"], 0.0, 1.0)) * diffuse
    return specular + (1.0 - e_specular) * diffuse, e_normal


def conductor(p, g, rough, multi: bool) -> np.ndarray:
    """f_conductor: GGX times min(specular_weight F82-tint, 1)."""
    f0 = p["base_weight"] * p["base_color"]
    fresnel = np.minimum(p["specular_weight"] * ly.f82_tint(g.i_dot_h, f0, p["specular_color"]), 1.0)
    gain = ly.multiscatter_gain(np.minimum(p["specular_weight"] * f0, 1.0), g.cos_o, rough) if multi else 1.0
    return fresnel * ly.ggx_lobe(rough, g) * gain


def darkening(p, g, eta_s, e_specular_normal) -> np.ndarray:
    """Delta_C modulated: lerp(1, (1 - K)/(1 - E_b K), coat_weight coat_darkening) ("Coat > Darkening")."""
    n_c = p["coat_ior"]
    metal = np.clip(p["base_metalness"], 0.0, 1.0)
    rough = p["specular_roughness"]
    k_r = 1.0 - (1.0 - ly.average_fresnel(n_c)) / (n_c * n_c)
    k_s = fresnel_dielectric(g.cos_o, n_c)
    r_d = rough + (1.0 - rough) * (1.0 - np.clip(p["specular_weight"] * f0_from_ior(eta_s), 0.0, 1.0))
    r_b = (1.0 - metal) * r_d + metal * rough
    k = (1.0 - r_b) * k_s + r_b * k_r
    albedo = p["base_weight"] * p["base_color"]
    diffuse_albedo = albedo
    if np.any(np.asarray(p["transmission_weight"]) > 0.0):
        diffuse_albedo = (1.0 - np.clip(p["transmission_weight"], 0.0, 1.0)) * albedo
    e_dielectric = e_specular_normal + (1.0 - e_specular_normal) * diffuse_albedo
    e_base = (1.0 - metal) * e_dielectric + metal * np.minimum(p["specular_weight"] * albedo, 1.0)
    delta = (1.0 - k) / (1.0 - e_base * k)
    amount = np.clip(p["coat_weight"], 0.0, 1.0) * p["coat_darkening"]
    return (1.0 - amount) + amount * delta


def coat_layer(p, g, base, multi: bool) -> np.ndarray:
    """C f_coat + lerp(1, T_coat (1 - E_coat), C) base (base already darkened)."""
    coat = np.clip(p["coat_weight"], 0.0, 1.0)
    n_c = p["coat_ior"]
    rough = p["coat_roughness"]
    f0 = f0_from_ior(n_c)
    gain = ly.multiscatter_gain(f0, g.cos_o, rough) if multi else 1.0
    f_coat = fresnel_dielectric(g.i_dot_h, n_c) * ly.ggx_lobe(rough, g) * gain
    e_coat = ly.dielectric_albedo(g.cos_o, rough, f0) * gain
    path = 0.5 * (1.0 / ly.refracted_cos(g.cos_i, n_c) + 1.0 / ly.refracted_cos(g.cos_o, n_c))
    transmittance = np.asarray(p["coat_color"], dtype=float) ** path
    return coat * f_coat + ((1.0 - coat) + coat * transmittance * (1.0 - e_coat)) * base


def open_pbr_surface(p, opt, g):
    """f * cos(theta_light) of OpenPBR Surface (see the module docstring for each step)."""
    multi = opt["multiscatter"] == "turquin"
    coat = np.clip(p["coat_weight"], 0.0, 1.0)
    metal = np.clip(p["base_metalness"], 0.0, 1.0)
    rough = coat_roughened(p["specular_roughness"], p["coat_roughness"], coat)
    eta_s = specular_ior_ratio(p["specular_ior"], p["coat_ior"], coat)
    eta = ly.modulated_ior(eta_s, p["specular_weight"])
    dielectric, e_normal = dielectric_base(p, g, rough, eta, multi)
    base = (1.0 - metal) * dielectric + metal * conductor(p, g, rough, multi)
    coated = coat_layer(p, g, darkening(p, g, eta_s, e_normal) * base, multi)
    fuzz = np.clip(p["fuzz_weight"], 0.0, 1.0)
    rough_f = p["fuzz_roughness"]
    return (
        fuzz * p["fuzz_color"] * ly.zeltner_sheen(rough_f, g)
        + (1.0 - fuzz * ly.zeltner_albedo(g.cos_o, rough_f)) * coated
    )


#: model id -> evaluator
EVALUATORS = {OPEN_PBR_SURFACE.id: open_pbr_surface}
