"""Microfacet distributions D and Smith shadowing-masking G, as functions of cosines and alpha.

Mitsuba 0.6 conventions (``include/mitsuba/render/microfacet.h``): alpha clamped to >= 1e-4,
Beckmann and GGX as usual, Phong / Ashikhmin-Shirley through the exponent e = 2/alpha^2 - 2, and a
separable Smith G = G1(i) G1(o) with Walter et al.'s rational approximation of the Beckmann G1
(also used for Phong). Cycles conventions (``kernel/closure/bsdf_microfacet.h``): height-correlated
Smith G = 1 / (1 + Lambda(i) + Lambda(o)).

All functions broadcast: ``cos_h`` / ``tan2`` are arrays of cosines or tan^2 of polar angles,
``alpha`` an array of roughness values.
"""

from __future__ import annotations

import numpy as np

ALPHA_MIN = 1e-4
DISTRIBUTIONS = ("beckmann", "ggx", "phong", "as")


def phong_exponent(alpha: np.ndarray) -> np.ndarray:
    """Blinn-Phong exponent equivalent to a Beckmann alpha: e = max(2/alpha^2 - 2, 0)."""
    return np.maximum(2.0 / (alpha * alpha) - 2.0, 0.0)


def d_beckmann(cos_h: np.ndarray, tan2_h: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """D = exp(-tan^2 / alpha^2) / (pi alpha^2 cos^4)."""
    a2 = alpha * alpha
    c2 = cos_h * cos_h
    return np.exp(-tan2_h / a2) / (np.pi * a2 * c2 * c2)


def d_ggx(cos_h: np.ndarray, tan2_h: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """D = 1 / (pi alpha^2 cos^4 (1 + tan^2 / alpha^2)^2)  (Trowbridge-Reitz)."""
    a2 = alpha * alpha
    c2 = cos_h * cos_h
    r = 1.0 + tan2_h / a2
    return 1.0 / (np.pi * a2 * c2 * c2 * r * r)


def d_phong(cos_h: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Normalised Blinn-Phong D = (e + 2)/(2 pi) cos^e with e = 2/alpha^2 - 2 (isotropic
    Ashikhmin-Shirley, Mitsuba 0.6 'phong' and 'as')."""
    e = phong_exponent(alpha)
    return (e + 2.0) / (2.0 * np.pi) * np.power(np.maximum(cos_h, 0.0), e)


def d_mitsuba06(distribution: str, cos_h: np.ndarray, tan2_h: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Mitsuba 0.6 ``MicrofacetDistribution::eval`` for an isotropic alpha (clamped >= 1e-4);
    values with D cos < 1e-20 are flushed to zero as Mitsuba does."""
    alpha = np.maximum(alpha, ALPHA_MIN)
    if distribution == "beckmann":
        d = d_beckmann(cos_h, tan2_h, alpha)
    elif distribution == "ggx":
        d = d_ggx(cos_h, tan2_h, alpha)
    elif distribution in ("phong", "as"):
        d = d_phong(cos_h, alpha)
    else:
        raise ValueError(f"unknown distribution {distribution!r}")
    return np.where(d * cos_h < 1e-20, 0.0, d)


def g1_beckmann_rational(tan2_v: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Smith G1 for Beckmann, Walter et al. 2007 rational fit: a = 1/(alpha tan);
    G1 = 1 for a >= 1.6, else (3.535 a + 2.181 a^2) / (1 + 2.276 a + 2.577 a^2)."""
    with np.errstate(divide="ignore", invalid="ignore"):  # a = inf at normal incidence: G1 = 1
        a = 1.0 / (alpha * np.sqrt(tan2_v))
        g = (3.535 * a + 2.181 * a * a) / (1.0 + 2.276 * a + 2.577 * a * a)
    return np.where(a >= 1.6, 1.0, g)


def g1_ggx(tan2_v: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Smith G1 for GGX: 2 / (1 + sqrt(1 + alpha^2 tan^2))."""
    return 2.0 / (1.0 + np.sqrt(1.0 + alpha * alpha * tan2_v))


def g_mitsuba06(distribution: str, tan2_i: np.ndarray, tan2_o: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Separable Smith G = G1(i) G1(o) as in Mitsuba 0.6 (Beckmann's G1 also for Phong/AS)."""
    alpha = np.maximum(alpha, ALPHA_MIN)
    g1 = g1_ggx if distribution == "ggx" else g1_beckmann_rational
    return g1(tan2_i, alpha) * g1(tan2_o, alpha)


def lambda_ggx(tan2_v: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Smith Lambda for GGX: (sqrt(1 + alpha^2 tan^2) - 1) / 2."""
    return 0.5 * (np.sqrt(1.0 + alpha * alpha * tan2_v) - 1.0)


def lambda_beckmann(tan2_v: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Smith Lambda for Beckmann, rational fit used by Cycles: a = 1/(alpha tan);
    ((0.396 a - 1.259) a + 1) / ((2.181 a + 3.535) a) for a < 1.6, else 0."""
    with np.errstate(divide="ignore", invalid="ignore"):
        a = 1.0 / (alpha * np.sqrt(tan2_v))
        lam = ((0.396 * a - 1.259) * a + 1.0) / ((2.181 * a + 3.535) * a)
    return np.where(a < 1.6, lam, 0.0)


def g_height_correlated(lam_i: np.ndarray, lam_o: np.ndarray) -> np.ndarray:
    """Height-correlated Smith G = 1 / (1 + Lambda(i) + Lambda(o))."""
    return 1.0 / (1.0 + lam_i + lam_o)
