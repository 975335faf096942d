"""Fresnel reflectance and the F0 <-> index-of-refraction change of variable.

Pure numpy functions of arrays of cosines, named after the math (in the spirit of PBRT's
``FrDielectric`` / ``FrComplex``). Formulas: Mitsuba 0.6 ``src/libcore/util.cpp``
(``fresnelConductorExact``, ``fresnelDielectricExt``), Schlick 1994, and eq. (1) of Sztrajman et
al. 2019 for F0 of a complex IOR.
"""

from __future__ import annotations

import numpy as np

from matremap.core.inplace import into

ArrayLike = np.ndarray | float


def fresnel_conductor(cos_theta: ArrayLike, eta: ArrayLike, k: ArrayLike) -> np.ndarray:
    """Unpolarised Fresnel reflectance of a conductor with complex IOR eta + i k (exact).

    t = eta^2 - k^2 - sin^2, A = sqrt(t^2 + 4 eta^2 k^2), a = sqrt((A + t)/2);
    Rs = (A + cos^2 - 2 a cos)/(A + cos^2 + 2 a cos);
    Rp = Rs (A cos^2 + sin^4 - 2 a cos sin^2)/(A cos^2 + sin^4 + 2 a cos sin^2); F = (Rs + Rp)/2.
    """
    c = np.asarray(cos_theta, dtype=float)
    c2 = c * c
    s2 = 1.0 - c2
    eta = np.asarray(eta, dtype=float)
    k = np.asarray(k, dtype=float)
    t = eta * eta - k * k - s2
    a2b2 = np.sqrt(t * t + 4.0 * eta * eta * k * k)
    a = np.sqrt(np.maximum(0.5 * (a2b2 + t), 0.0))
    term1 = a2b2 + c2
    term2 = 2.0 * a * c
    rs = (term1 - term2) / (term1 + term2)
    term3 = a2b2 * c2 + s2 * s2
    term4 = term2 * s2
    rp = rs * (term3 - term4) / (term3 + term4)
    return 0.5 * (rp + rs)


def fresnel_dielectric(cos_theta_i: ArrayLike, eta: ArrayLike) -> np.ndarray:
    """Unpolarised Fresnel reflectance at a dielectric interface with relative IOR eta
    (interior/exterior), for light arriving from the side the normal points to when
    cos_theta_i > 0 and from inside when it is negative. Total internal reflection gives 1.
    """
    ci = np.asarray(cos_theta_i, dtype=float)
    eta = np.asarray(eta, dtype=float)
    if np.all(ci > 0):  # light from outside everywhere (a BRDF's i.h): the same numbers without the selection
        eta_eff = eta
    else:
        eta_eff = np.where(ci > 0, eta, 1.0 / eta)
        ci = np.abs(ci)
    # written into its own temporaries (into): the same operations in the same order
    c2 = ci * ci
    cos2_t = np.subtract(1.0, c2, out=c2) if isinstance(c2, np.ndarray) else 1.0 - c2
    sin2_t = into(np.divide, cos2_t, eta_eff * eta_eff)  # (1 - ci^2) / eta^2
    tir = sin2_t >= 1.0
    ct = np.sqrt(np.maximum(1.0 - sin2_t, 0.0))
    et = eta_eff * ct
    rs = into(np.divide, ci - et, into(np.add, et, ci))
    eci = eta_eff * ci
    rp = into(np.divide, eci - ct, into(np.add, eci, ct))
    f = into(np.multiply, into(np.add, into(np.multiply, rs, rs), into(np.multiply, rp, rp)), 0.5)
    return np.where(tir, 1.0, f)


def fresnel_schlick(cos_theta: ArrayLike, f0: ArrayLike) -> np.ndarray:
    """Schlick's approximation F = F0 + (1 - F0)(1 - cos)^5."""
    c = np.clip(np.asarray(cos_theta, dtype=float), 0.0, 1.0)
    f0 = np.asarray(f0, dtype=float)
    m = 1.0 - c
    m2 = m * m
    return f0 + (1.0 - f0) * (m2 * m2 * m)


def f0_from_ior(eta: ArrayLike, k: ArrayLike = 0.0) -> np.ndarray:
    """Normal-incidence reflectance of a complex IOR c = eta + i k (paper eq. 1):
    F0 = (c - 1)(c* - 1) / ((c + 1)(c* + 1)) = ((eta - 1)^2 + k^2) / ((eta + 1)^2 + k^2)."""
    eta = np.asarray(eta, dtype=float)
    k = np.asarray(k, dtype=float)
    return ((eta - 1.0) ** 2 + k * k) / ((eta + 1.0) ** 2 + k * k)


def ior_from_f0(f0: ArrayLike) -> np.ndarray:
    """The real IOR (k = 0, eta >= 1) whose normal-incidence reflectance is F0:
    eta = (1 + sqrt F0) / (1 - sqrt F0)."""
    s = np.sqrt(np.clip(np.asarray(f0, dtype=float), 0.0, 1.0 - 1e-12))
    return (1.0 + s) / (1.0 - s)


def dielectric_f0(ior: ArrayLike, specular: ArrayLike = 1.0, specular_color: ArrayLike = 1.0) -> np.ndarray:
    """F0 of a glTF dielectric (KHR_materials_ior and KHR_materials_specular):
    min(((ior - 1) / (ior + 1))^2 specularColor, 1) specular."""
    r = (np.asarray(ior, dtype=float) - 1.0) / (np.asarray(ior, dtype=float) + 1.0)
    return np.minimum(r * r * np.asarray(specular_color), 1.0) * np.asarray(specular)
