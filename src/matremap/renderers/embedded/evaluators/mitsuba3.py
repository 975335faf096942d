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

``roughplastic`` and ``principled`` are not emulated: Mitsuba 3's roughplastic diffuse layer differs from
Mitsuba 0.6's (2-59 % relative RMSE, see :mod:`matremap.dialects.equivalence`); both are drawn by Mitsuba 3.
"""

from __future__ import annotations

import numpy as np

from matremap.core.optics import fresnel_conductor
from matremap.dialects.mitsuba3 import DIFFUSE, ROUGHCONDUCTOR, ROUGHCONDUCTOR_ANISOTROPIC
from matremap.dialects.mitsuba3_conductors import CONDUCTOR_RGB
from matremap.errors import MatremapError
from matremap.renderers.embedded import microfacet as mf


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


#: model id -> evaluator
EVALUATORS = {
    DIFFUSE.id: diffuse,
    ROUGHCONDUCTOR.id: roughconductor,
    ROUGHCONDUCTOR_ANISOTROPIC.id: roughconductor_anisotropic,
}
