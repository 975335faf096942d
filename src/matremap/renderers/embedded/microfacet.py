"""Microfacet distributions D and Smith shadowing-masking G, as functions of cosines and alpha.

Mitsuba 0.6 conventions (``include/mitsuba/render/microfacet.h``): alpha clamped to >= 1e-4,
Beckmann and GGX as usual, Phong / Ashikhmin-Shirley through the exponent e = 2/alpha^2 - 2, and a
separable Smith G = G1(i) G1(o) with Walter et al.'s rational approximation of the Beckmann G1
(also used for Phong). Cycles conventions (``kernel/closure/bsdf_microfacet.h``): height-correlated
Smith G = 1 / (1 + Lambda(i) + Lambda(o)).

All functions broadcast: ``cos_h``, ``tan2_h`` / ``tan_v`` are arrays of cosines, tan^2 of the
half-vector angle and tangents of polar angles, ``alpha`` an array of roughness values. The hot ones work in
place on their own temporaries (:func:`~matremap.core.inplace.into`: the same numbers, fewer allocations).
"""

from __future__ import annotations

import numpy as np

from matremap.core.inplace import into

ALPHA_MIN = 1e-4


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
    r = into(np.add, tan2_h / a2, 1.0)  # 1 + tan^2 / alpha^2
    den = into(np.multiply, into(np.multiply, np.pi * a2 * c2, c2), r)
    den = into(np.multiply, den, r)
    return np.divide(1.0, den, out=den) if isinstance(den, np.ndarray) and den.ndim > 0 else 1.0 / den


def d_phong(cos_h: np.ndarray, alpha: np.ndarray, log_cos_h: np.ndarray | None = None) -> np.ndarray:
    """Normalised Blinn-Phong D = (e + 2)/(2 pi) cos^e with e = 2/alpha^2 - 2 (isotropic
    Ashikhmin-Shirley, Mitsuba 0.6 'phong' and 'as'). ``log_cos_h`` may be passed precomputed."""
    e = phong_exponent(alpha)
    if log_cos_h is None:
        with np.errstate(divide="ignore"):
            log_cos_h = np.log(np.maximum(cos_h, 0.0))
    return (e + 2.0) / (2.0 * np.pi) * np.exp(e * log_cos_h)


def d_mitsuba06(distribution: str, g, alpha: np.ndarray) -> np.ndarray:
    """Mitsuba 0.6 ``MicrofacetDistribution::eval`` for an isotropic alpha (clamped >= 1e-4) on a
    :class:`~.geometry.LocalGeometry`; values with D cos < 1e-20 are flushed to zero as Mitsuba does."""
    alpha = np.maximum(alpha, ALPHA_MIN)
    if distribution == "beckmann":
        d = d_beckmann(g.cos_h, g.tan2_h, alpha)
    elif distribution == "ggx":
        d = d_ggx(g.cos_h, g.tan2_h, alpha)
    elif distribution in ("phong", "as"):
        d = d_phong(g.cos_h, alpha, g.log_cos_h)
    else:
        raise ValueError(f"unknown distribution {distribution!r}")
    return _flush(d, d * g.cos_h < 1e-20, 0.0)


def _flush(a, where, value: float) -> np.ndarray:
    """``np.where(where, value, a)``, written into ``a`` when it is an array of the result's shape."""
    if isinstance(a, np.ndarray) and a.ndim > 0 and a.shape == np.shape(where):
        np.copyto(a, value, where=where)
        return a
    return np.where(where, value, a)


def g1_beckmann_rational(tan_v: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Smith G1 for Beckmann, Walter et al. 2007 rational fit: a = 1/(alpha tan);
    G1 = 1 for a >= 1.6, else (3.535 a + 2.181 a^2) / (1 + 2.276 a + 2.577 a^2),
    evaluated as (3.535 b + 2.181) / (b^2 + 2.276 b + 2.577) with b = 1/a = alpha tan."""
    b = alpha * tan_v
    num = into(np.add, 3.535 * b, 2.181)
    den = into(np.add, into(np.multiply, b + 2.276, b), 2.577)
    return _flush(into(np.divide, num, den), b <= 0.625, 1.0)


def g1_ggx(tan_v: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Smith G1 for GGX: 2 / (1 + sqrt(1 + alpha^2 tan^2))."""
    b = alpha * tan_v
    root = into(np.add, b * b, 1.0)  # 1 + b^2
    root = np.sqrt(root, out=root) if isinstance(root, np.ndarray) and root.ndim > 0 else np.sqrt(root)
    root = into(np.add, root, 1.0)
    return np.divide(2.0, root, out=root) if isinstance(root, np.ndarray) and root.ndim > 0 else 2.0 / root


def g_mitsuba06(distribution: str, tan_i: np.ndarray, tan_o: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Separable Smith G = G1(i) G1(o) as in Mitsuba 0.6 (Beckmann's G1 also for Phong/AS);
    ``tan_i``, ``tan_o`` are the tangents of the polar angles."""
    alpha = np.maximum(alpha, ALPHA_MIN)
    g1 = g1_ggx if distribution == "ggx" else g1_beckmann_rational
    return into(np.multiply, g1(tan_i, alpha), g1(tan_o, alpha))


def lambda_ggx(tan_v: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Smith Lambda for GGX: (sqrt(1 + alpha^2 tan^2) - 1) / 2."""
    b = alpha * tan_v
    return 0.5 * (np.sqrt(1.0 + b * b) - 1.0)


def lambda_beckmann(tan_v: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Smith Lambda for Beckmann, rational fit used by Cycles: a = 1/(alpha tan);
    ((0.396 a - 1.259) a + 1) / ((2.181 a + 3.535) a), evaluated as
    (0.396 - 1.259 b + b^2) / (2.181 + 3.535 b) with b = 1/a = alpha tan; zero where
    alpha^2 tan^2 < 0.39 (Cycles' ``bsdf_lambda_from_sqr_alpha_tan_n`` cut, a hair below a = 1.6)."""
    b = alpha * tan_v
    lam = (0.396 + b * (b - 1.259)) / (2.181 + 3.535 * b)
    return np.where(b * b < 0.39, 0.0, lam)


def g_height_correlated(lam_i: np.ndarray, lam_o: np.ndarray) -> np.ndarray:
    """Height-correlated Smith G = 1 / (1 + Lambda(i) + Lambda(o))."""
    return 1.0 / (1.0 + lam_i + lam_o)


def d_anisotropic(
    distribution: str, hx: np.ndarray, hy: np.ndarray, hz: np.ndarray, alpha_u: np.ndarray, alpha_v: np.ndarray
) -> np.ndarray:
    """Mitsuba 3 ``MicrofacetDistribution::eval`` (``include/mitsuba/render/microfacet.h``) of the unit
    half vector (hx, hy, hz) in the shading frame: Beckmann exp(-(hx^2/au^2 + hy^2/av^2)/hz^2) /
    (pi au av hz^4), GGX 1 / (pi au av (hx^2/au^2 + hy^2/av^2 + hz^2)^2); alphas clamped to >= 1e-4,
    values with D hz < 1e-20 flushed to zero."""
    au, av = np.maximum(alpha_u, ALPHA_MIN), np.maximum(alpha_v, ALPHA_MIN)
    sx, sy, hz2 = (hx / au) ** 2, (hy / av) ** 2, hz * hz
    if distribution == "beckmann":
        d = np.exp(-(sx + sy) / hz2) / (np.pi * au * av * hz2 * hz2)
    elif distribution == "ggx":
        d = 1.0 / (np.pi * au * av * (sx + sy + hz2) ** 2)
    else:
        raise ValueError(f"unknown distribution {distribution!r}")
    return np.where(d * hz < 1e-20, 0.0, d)


def g1_anisotropic(
    distribution: str, vx: np.ndarray, vy: np.ndarray, vz: np.ndarray, alpha_u: np.ndarray, alpha_v: np.ndarray
) -> np.ndarray:
    """Mitsuba 3 ``smith_g1`` for direction (vx, vy, vz): the isotropic G1 at alpha tan = sqrt((au vx)^2 +
    (av vy)^2) / vz (rational Beckmann or GGX, as :func:`g1_beckmann_rational` / :func:`g1_ggx`)."""
    au, av = np.maximum(alpha_u, ALPHA_MIN), np.maximum(alpha_v, ALPHA_MIN)
    b = np.sqrt((au * vx) ** 2 + (av * vy) ** 2) / vz
    g1 = g1_ggx if distribution == "ggx" else g1_beckmann_rational
    return g1(b, np.ones_like(b))


def drawn_alpha(alpha, g) -> np.ndarray:
    """``alpha`` as a lobe is drawn on the geometry ``g``: floored at ``g.mirror_alpha`` where the renderer
    samples the mirror direction (a mirror then shows what it reflects, as a lobe of alpha 1e-4, as narrow as
    Mitsuba's; see :mod:`~matremap.renderers.embedded.mirror_samples`); as given elsewhere, where the evaluators
    draw a mirror as zero (no point light reaches its delta lobe)."""
    a = np.asarray(alpha, dtype=float)
    return np.maximum(a, g.mirror_alpha) if g.mirror_alpha > 0.0 else a
