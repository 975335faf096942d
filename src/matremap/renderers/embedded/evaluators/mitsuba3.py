"""The embedded renderer's evaluators of the mitsuba3 dialect: Mitsuba 3's ``diffuse`` and
``roughconductor`` (:mod:`matremap.dialects.mitsuba3`), as numpy functions of [N, C, L, P] arrays.

Source: Mitsuba 3.9 ``src/bsdfs/diffuse.cpp`` (reflectance / pi) and ``src/bsdfs/roughconductor.cpp``:
specular_reflectance F_conductor(i.h; eta + i k) D G / (4 cos_i cos_o), with Smith's separable G of the
same rational Beckmann G1 as Mitsuba 0.6 (``include/mitsuba/render/microfacet.h``) and no exterior IOR:
Mitsuba 0.6's formula at extEta = 1, which is what this module evaluates. A named ``material`` takes
the RGB eta and k Mitsuba's rgb variants convert its spectral data to
(:mod:`matremap.dialects.mitsuba3_conductors`); ``none`` is Mitsuba's perfect mirror (Fresnel 1).
The anisotropic roughconductor (``alpha_u`` != ``alpha_v``) evaluates D and G in the shading frame
(``g.frame``: the probe sphere's is Mitsuba's ``sphere`` frame, s along dp/du). Checked against the real
Mitsuba 3 in tests/test_mitsuba3_emulation.py and tests/test_mitsuba_anisotropic.py.

``principled``: Mitsuba 3.9 ``src/bsdfs/principled.cpp`` (``Principled::eval``) and ``principledhelpers.h``,
the reflection of the front side, in Mitsuba's own terms (its ``wi`` is the viewer, ``wo`` the light):

* specular: F D G / (4 cos_view) with GGX D and the separable Smith G of alpha = max(0.001, roughness^2),
  F = (1 - metallic)(1 - spec_tint) F_dielectric(o.h, eta) + metallic Schlick(base_color)
  + (1 - metallic) spec_tint Schlick(c_tint ((eta - 1)/(eta + 1))^2), eta = 2/(1 - sqrt(0.08 specular)) - 1,
  c_tint = base_color / luminance (Rec. 709 weights) or 1; the whole lobe (metal included) is off where
  F_dielectric is 0, i.e. at specular 0 (a Mitsuba quirk: a metal then has no reflection at all);
* clearcoat: 0.25 clearcoat Schlick(0.04) D_GTR1 G cos_light with GTR1 alpha = lerp(0.1, 0.001,
  clearcoat_gloss) and G the product of GGX G1 at alpha 0.25. Unlike Burley's clearcoat, Mitsuba's has no
  1 / (4 cos_view cos_light) (its G1 is the plain Smith term); followed here;
* diffuse: (1 - metallic) base_color / pi ((1 - F_v/2)(1 - F_l/2) + R_r (F_l + F_v + F_l F_v (R_r - 1)))
  cos_light, F_x = (1 - cos_x)^5, R_r = 2 roughness (h.l)^2;
* sheen: sheen (1 - metallic) (1 - h.l)^5 lerp(1, c_tint, sheen_tint) cos_light (no 1/pi, as Burley's).

* spec_trans (transmission, ``bsdf = (1 - metallic) spec_trans``): ``Principled::eval`` weighs only the diffuse
  (with its retro-reflection) by ``brdf = (1 - metallic)(1 - spec_trans)``; the specular reflection, its Fresnel
  (front side), the sheen and the clearcoat are unchanged. Its transmission lobe (``sqrt(base_color) bsdf``
  times the rough dielectric BTDF) is not reflection and is drawn by the transmission probe
  (``..transmission.mitsuba3_principled_interface``). With spec_trans > 0 a specular of 0 is read as 1e-3
  (the constructor's and ``parameters_changed``'s "eta = 1 is not plausible for transmission"), so a faint
  dielectric lobe remains.

Not emulated: anisotropic > 0 and flatness > 0 (refused with one line; Mitsuba 3 draws
them with ``--target-renderer mitsuba3``). Checked against the real Mitsuba 3 in
tests/test_mitsuba3_principled_emulation.py.

The glasses, their reflection only (what they let through is the transmission probe's): ``dielectric`` and
``thindielectric`` (``dielectric.cpp``, ``thindielectric.cpp``) reflect a delta lobe, which no point light reaches:
zero, as every mirror of the embedded renderer. ``roughdielectric`` (``roughdielectric.cpp``, ``eval``, the
reflection branch): specular_reflectance F(i.h, int_ior/ext_ior) D G / (4 cos_view) -- Mitsuba's exact dielectric
Fresnel (``fresnel.h``; an eta below 1 reflects totally past its critical angle), its Beckmann or GGX D and the
separable Smith G (``MicrofacetDistribution::G``, the same G1 as roughconductor's; ``sample_visible`` changes
sampling only). Checked against the real Mitsuba 3 in tests/test_mitsuba3_glass.py.

``roughplastic`` is not emulated: Mitsuba 3's roughplastic
diffuse layer differs from Mitsuba 0.6's (2-59 % relative RMSE, see :mod:`matremap.dialects.equivalence`).
"""

from __future__ import annotations

import numpy as np

from matremap.core.optics import fresnel_conductor, fresnel_dielectric
from matremap.dialects.mitsuba3 import (
    DIELECTRIC,
    DIFFUSE,
    PRINCIPLED,
    ROUGHCONDUCTOR,
    ROUGHCONDUCTOR_ANISOTROPIC,
    ROUGHDIELECTRIC,
    THINDIELECTRIC,
)
from matremap.dialects.mitsuba3_conductors import CONDUCTOR_RGB
from matremap.errors import MatremapError
from matremap.renderers.embedded import microfacet as mf

#: Mitsuba's ``luminance`` of linear sRGB (Rec. 709)
LUMINANCE = np.array([0.212671, 0.715160, 0.072169])


def diffuse(p, opt, g):
    return p["reflectance"] * g.lambert


def conductor_fresnel(p, opt, g):
    """Mitsuba 3's conductor Fresnel at i.h: 1 for ``none``, else of eta + i k (custom or named)."""
    material = opt.get("material", "custom")
    if material == "none":
        return np.ones_like(g.i_dot_h)
    if material == "custom":
        eta, k = p["eta"], p["k"]
    else:
        e, kk = CONDUCTOR_RGB[material]
        eta, k = np.asarray(e)[None, :, None, None], np.asarray(kk)[None, :, None, None]
    return fresnel_conductor(g.i_dot_h, eta, k)


def roughconductor(p, opt, g):
    f = conductor_fresnel(p, opt, g)
    distribution, alpha = opt["distribution"], p["alpha"]
    d = mf.d_mitsuba06(distribution, g, alpha)
    gg = mf.g_mitsuba06(distribution, g.tan_i, g.tan_o, alpha)
    return p["specular_reflectance"] * f * (d * gg / (4.0 * g.cos_o))


def schlick_weight(cos) -> np.ndarray:
    """Mitsuba's ``schlick_weight``: clip(1 - cos, 0, 1)^5."""
    m = np.clip(1.0 - cos, 0.0, 1.0)
    return m * m * m * m * m


def principled_eta(specular, spec_trans) -> np.ndarray:
    """Mitsuba 3's principled IOR: eta = 2/(1 - sqrt(0.08 specular)) - 1, with a specular of 0 read as 1e-3
    where spec_trans > 0 (principled.cpp: "zero specular is not plausible for transmission")."""
    specular = np.where((np.asarray(spec_trans) > 0.0) & (np.asarray(specular) == 0.0), 1e-3, specular)
    return 2.0 / (1.0 - np.sqrt(0.08 * specular)) - 1.0


def principled(p, opt, g):
    """f * cos(theta_light) of Mitsuba 3's ``principled`` (see the module docstring)."""
    for name in ("anisotropic", "flatness"):
        if np.any(p[name] > 0.0):
            raise MatremapError(
                f"mitsuba3:principled with {name} > 0 is not emulated by the embedded renderer; "
                "draw it with Mitsuba 3 (--target-renderer mitsuba3 / --source-renderer mitsuba3)"
            )
    base, rough, metallic = p["base_color"], p["roughness"], p["metallic"]
    eta = principled_eta(p["specular"], p["spec_trans"])
    weights = LUMINANCE.reshape((1, 3) + (1,) * (base.ndim - 2))
    lum = np.sum(base * weights, axis=1, keepdims=True) if base.shape[1] == 3 else base
    c_tint = np.where(lum > 0.0, base / np.where(lum > 0.0, lum, 1.0), 1.0)
    alpha = np.maximum(0.001, rough * rough)
    d = mf.d_mitsuba06("ggx", g, alpha)
    gg = mf.g_mitsuba06("ggx", g.tan_i, g.tan_o, alpha)
    w_h = schlick_weight(g.i_dot_h)
    f_d = fresnel_dielectric(g.i_dot_h, eta)
    spec_tint = p["spec_tint"]
    r0 = c_tint * ((eta - 1.0) / (eta + 1.0)) ** 2
    fresnel = (
        (1.0 - metallic) * (1.0 - spec_tint) * f_d
        + metallic * (base + (1.0 - base) * w_h)
        + (1.0 - metallic) * spec_tint * (r0 + (1.0 - r0) * w_h)
    )
    specular = np.where(f_d > 0.0, fresnel * d * gg / (4.0 * g.cos_o), 0.0)
    # clearcoat: GTR1, Schlick 0.04, G1 at alpha 0.25, no 1/(4 cos cos)
    a2 = (0.1 + p["clearcoat_gloss"] * (0.001 - 0.1)) ** 2
    d_cc = (a2 - 1.0) / (np.pi * np.log(a2) * (1.0 + (a2 - 1.0) * g.cos_h**2))
    d_cc = np.where(d_cc * g.cos_h > 1e-20, d_cc, 0.0)
    a_cc = np.full(1, 0.25)
    g_cc = mf.g1_ggx(g.tan_i, a_cc) * mf.g1_ggx(g.tan_o, a_cc)
    clearcoat = 0.25 * p["clearcoat"] * (0.04 + 0.96 * w_h) * d_cc * g_cc * g.cos_i
    # diffuse with retro-reflection, and sheen
    f_l, f_v = schlick_weight(g.cos_i), schlick_weight(g.cos_o)
    rr = 2.0 * rough * g.i_dot_h**2
    lobe = (1.0 - 0.5 * f_v) * (1.0 - 0.5 * f_l) + rr * (f_l + f_v + f_l * f_v * (rr - 1.0))
    diffuse = (1.0 - metallic) * (1.0 - p["spec_trans"]) * base * g.lambert * lobe
    c_sheen = 1.0 + p["sheen_tint"] * (c_tint - 1.0)
    sheen = p["sheen"] * (1.0 - metallic) * w_h * c_sheen * g.cos_i
    return specular + clearcoat + diffuse + sheen


def roughconductor_anisotropic(p, opt, g):
    """Mitsuba 3's roughconductor with alpha_u != alpha_v: D and Smith G of the half vector and the
    directions in the shading frame (microfacet.h), which the scene must give (``g.frame``)."""
    if g.frame is None:
        raise MatremapError(
            "mitsuba3:roughconductor-anisotropic needs the surface's tangent frame, which this scene does not give"
        )
    i_s, i_t, o_s, o_t = g.frame
    inv = 1.0 / np.sqrt(g.h_len2)
    au, av, distribution = p["alpha_u"], p["alpha_v"], opt["distribution"]
    d = mf.d_anisotropic(distribution, (i_s + o_s) * inv, (i_t + o_t) * inv, g.cos_h, au, av)
    gg = mf.g1_anisotropic(distribution, i_s, i_t, g.cos_i, au, av) * mf.g1_anisotropic(
        distribution, o_s, o_t, g.cos_o, au, av
    )
    return p["specular_reflectance"] * conductor_fresnel(p, opt, g) * (d * gg / (4.0 * g.cos_o))


def delta_glass(p, opt, g, thin: bool = False):
    """``dielectric`` / ``thindielectric``: a delta reflection, zero under point lights; where the renderer
    samples the mirror direction (``g.mirror_alpha``), drawn as GGX of that alpha with the exact Fresnel R of
    eta = int_ior / ext_ior, the thin slab's R' = 2R / (1 + R) (its internal reflections summed)."""
    if not g.mirror_alpha > 0.0:
        return 0.0 * p["specular_reflectance"] * g.cos_o
    alpha = mf.drawn_alpha(0.0, g)
    r = fresnel_dielectric(g.i_dot_h, p["int_ior"] / p["ext_ior"])
    if thin:
        r = 2.0 * r / (1.0 + r)
    lobe = mf.d_ggx(g.cos_h, g.tan2_h, alpha) * mf.g_mitsuba06("ggx", g.tan_i, g.tan_o, alpha) / (4.0 * g.cos_o)
    return p["specular_reflectance"] * r * lobe


def delta_thin_glass(p, opt, g):
    """``thindielectric``'s reflection (:func:`delta_glass`)."""
    return delta_glass(p, opt, g, thin=True)


def roughdielectric(p, opt, g):
    """Mitsuba 3's ``roughdielectric`` reflection (see the module docstring)."""
    eta = p["int_ior"] / p["ext_ior"]
    distribution, alpha = opt["distribution"], p["alpha"]
    d = mf.d_mitsuba06(distribution, g, alpha)
    gg = mf.g_mitsuba06(distribution, g.tan_i, g.tan_o, alpha)
    return p["specular_reflectance"] * fresnel_dielectric(g.i_dot_h, eta) * (d * gg / (4.0 * g.cos_o))


#: the models whose evaluator reads the shading frame (``g.frame``)
FRAMED = frozenset({ROUGHCONDUCTOR_ANISOTROPIC.id})

#: model id -> evaluator
EVALUATORS = {
    DIELECTRIC.id: delta_glass,
    ROUGHDIELECTRIC.id: roughdielectric,
    THINDIELECTRIC.id: delta_thin_glass,
    DIFFUSE.id: diffuse,
    ROUGHCONDUCTOR.id: roughconductor,
    ROUGHCONDUCTOR_ANISOTROPIC.id: roughconductor_anisotropic,
    PRINCIPLED.id: principled,
}
