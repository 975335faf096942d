"""Transmittance through a rough dielectric interface, as Mitsuba 0.6 tabulates it.

Mitsuba 0.6's ``roughplastic`` weights its diffuse term with T12(cos_i) T21(cos_o) and renormalises
it with the internal diffuse reflectance Fdr. It reads both from precomputed tables
(``data/microfacet/{beckmann,ggx,phong}.dat``, written by ``src/utils/rdielprec.cpp``, read by
``src/bsdfs/rtrans.h``); this module computes the same quantities by numerical integration and
caches them.

**What is tabulated.** rdielprec integrates, over the 2D sample space, the ``sample()`` weight of the
``roughdielectric`` plugin restricted to transmission (importance mode, so without the 1/eta^2
radiance scaling). That is the integral of the rough BTDF of Walter et al. 2007 times |cos theta_o|:
for light arriving at cos(theta_i) = mu from the side where the relative IOR (far side over near
side) is eta,

    T(mu, alpha, eta) = integral over microfacet normals m with i.m > 0 of
        D(m) G1(i) G1(o) (i.m) (1 - F(i.m, eta)) / mu  dm,

with o = refract(i, m) (no contribution under total internal reflection or where o does not
cross the macro-surface). D and the separable Smith G = G1(i) G1(o) are those of Mitsuba 0.6's
``microfacet.h`` (:mod:`.microfacet`: Beckmann with Walter's rational G1; GGX with its exact G1;
Phong with exponent 2/alpha^2 - 2 and the Beckmann G1); F is the dielectric Fresnel reflectance.
Energy lost to shadowing-masking therefore does *not* count as transmitted (T < 1 even at eta = 1).
``RoughTransmittance::evalDiffuse`` is the cosine-weighted average integral T(mu) 2 mu dmu, and
roughplastic uses ``Fdr = 1 - evalDiffuse`` of the *internal* side (relative IOR 1/eta):
:func:`diffuse_fresnel_reflectance` returns that 1 - integral for the eta it is given.

**Numerics.** The integral over m uses the importance variable of D cos(theta_m) in theta_m, split
where the admissible azimuth range (i.m > 0, or above the critical cosine) starts to shrink, with a
cosine substitution on the second panel and an endpoint substitution in phi_m ((8 + 12) x 8 Gauss
nodes outside, (8 + 40) x 8 inside; quadrature error < 2e-4 outside, < 5e-4 inside). Tables, per
distribution and per side (eta >= 1 and eta < 1, indexed by eta' = max(eta, 1/eta)), have
48 (mu) x 44 (alpha) x 26 (eta') nodes: eta' = 1 + 3 x^4 on [1, 4] (Mitsuba's warp); alpha on
[1e-4, alpha_max], uniform in an equal blend of log(alpha) and alpha; mu uniform in a blend of
asinh((mu - mu_c) / (alpha + w0)) and asin(sqrt(mu)), where mu_c = 0 outside and is the critical
cosine sqrt(1 - eta^2) inside, so that the grazing and total-internal-reflection edges, whose width
scales with alpha, are resolved. Values are interpolated with tensor-product Catmull-Rom splines
(as Mitsuba) and clamped to [0, 1] (as Mitsuba); Fdr is tabulated on the (alpha, eta') nodes by
integrating the mu-spline. Measured against direct integration (quadrature error < 5e-5) at 4000
random points per distribution and side (mu^(2/3), log(alpha) and sqrt(eta' - 1) uniform), for
eta' in [1.05, 4]: outside, max |error| 1.2e-3 (8.7e-4 for eta' >= 1.2), 99th percentile 2.6e-4;
inside, max 1.4e-3 away from the critical angle (|mu - mu_c| > 0.05) and up to 5e-3 next to it for
alpha ~ 0.005-0.1, 99th percentile 4.6e-4; Fdr max 1.9e-4. For eta' < 1.05 (nearly index-matched
interfaces) the corner mu, alpha -> 0 is not resolved (errors up to ~0.04 at grazing incidence).
Against Mitsuba's own tables (at their nodes, eta' >= 1.05): outside rms 2e-4; inside Mitsuba's
adaptive cubature returned exact zeros where transmission is confined to a small part of the
sample space, and its internal Fdr is up to 0.024 too high at eta' ~ 3.8 and small alpha; for
eta' ~ 1.5 and alpha >= 0.03 the internal Fdr agree within 1.5e-3.

**Domain.** Inputs outside the tables are clamped: alpha to [1e-4, alpha_max] with alpha_max = 4
(beckmann, ggx) or 1 (phong; e = 0 there). Mitsuba 0.6 also clamps alpha >= 1e-4, but *refuses*
alpha above its tables (4 for beckmann and ggx, 0.5 for phong) and eta' outside [1.0001, 4]; here
eta' is clamped to [1, 4]. mu is clamped to [1e-6, 1]; a negative cosine means light from the
other side: T(-mu, alpha, eta) = T(mu, alpha, 1/eta), as in ``RoughTransmittance::eval``.

Tables take about 2-3 s per distribution to build (two threads) and are cached in memory and on
disk, in matremap's private cache folder (``$MATREMAP_CACHE``, default ``~/.cache/matremap``;
skipped silently if not writable or not private).
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from matremap.core.diskcache import cache_dir, load_tables, save_tables
from matremap.core.optics import fresnel_dielectric
from matremap.renderers.embedded import quadrature
from matremap.renderers.embedded.microfacet import ALPHA_MIN, g1_beckmann_rational, g1_ggx, phong_exponent

__all__ = [
    "ALPHA_MAX",
    "ETA_MAX",
    "MU_MIN",
    "diffuse_fresnel_reflectance",
    "transmittance",
    "transmittance_direct",
]

#: largest tabulated roughness per distribution (larger values are clamped)
ALPHA_MAX = {"beckmann": 4.0, "ggx": 4.0, "phong": 1.0}
#: largest tabulated eta' = max(eta, 1/eta) (larger values are clamped)
ETA_MAX = 4.0
#: smallest cosine (smaller ones are clamped)
MU_MIN = 1e-6

_FORMAT = 2
# nodes along mu, alpha, eta' (the same on both sides)
_N_MU, _N_ALPHA, _N_ETA = 48, 44, 26
# Gauss-Legendre nodes: theta_m panel 1, theta_m panel 2, phi_m (per side)
_QUAD = {"ext": (8, 12, 8), "int": (8, 40, 8)}
# alpha coordinate: weight of log(alpha) (the rest is linear in alpha)
_ALPHA_LOG_WEIGHT = 0.5
# mu coordinate per side: (weight of the asinh part, w = slope * alpha + w0)
_MU_MAP = {"ext": (0.5, 1.0, 1e-4), "int": (0.7, 1.0, 2e-4)}
_SIDES = ("ext", "int")


def _canonical(distribution: str) -> str:
    d = str(distribution).lower()
    if d == "as":
        d = "phong"
    if d not in ALPHA_MAX:
        raise ValueError(f"unknown microfacet distribution {distribution!r}; expected beckmann, ggx or phong")
    return d


# ---------------------------------------------------------------------------------------------
# direct numerical integration


def _v_of_cos(distribution: str, cos_m: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Importance variable of a microfacet polar angle, v = 1 at the normal and 0 at grazing,
    with D cos(theta_m) dm = |d(v^2)| dphi / (2 pi): v^2 = exp(-tan^2 / alpha^2) (beckmann),
    alpha^2 / (alpha^2 + tan^2) (ggx), cos^(e + 2) (phong)."""
    cos_m = np.clip(cos_m, 0.0, 1.0)
    tan2 = (1.0 - cos_m * cos_m) / (cos_m * cos_m)
    if distribution == "beckmann":
        return np.where(cos_m > 0, np.exp(-tan2 / (2.0 * alpha * alpha)), 0.0)
    if distribution == "ggx":
        return np.where(cos_m > 0, alpha / np.sqrt(alpha * alpha + tan2), 0.0)
    return cos_m ** (0.5 * (phong_exponent(alpha) + 2.0))


def _cos_of_v(distribution: str, v: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    if distribution == "beckmann":
        tan2 = -2.0 * alpha * alpha * np.log(v)
    elif distribution == "ggx":
        tan2 = alpha * alpha * (1.0 - v * v) / (v * v)
    else:
        return v ** (2.0 / (phong_exponent(alpha) + 2.0))
    return 1.0 / np.sqrt(1.0 + tan2)


def _integrate_chunk(distribution, mu, alpha, eta, nodes):
    """T at points given as arrays of shape [P, 1, 1]."""
    t1, w1, t2, w2, wphi, wwphi = nodes
    sin_i = np.sqrt(np.maximum(1.0 - mu * mu, 0.0))
    c_min = np.sqrt(np.maximum(1.0 - eta * eta, 0.0))  # i.m below it: total internal reflection
    # admissible microfacets (i.m > c_min) form a cap of angular radius theta_cap around i; their
    # azimuths around the macro normal cover the full circle for theta_m < theta_a, none beyond theta_b
    theta_i = np.arccos(np.clip(mu, -1.0, 1.0))
    theta_cap = np.arccos(c_min)
    theta_a = np.clip(theta_cap - theta_i, 0.0, 0.5 * np.pi)
    theta_b = np.clip(theta_cap + theta_i, 0.0, 0.5 * np.pi)
    va = _v_of_cos(distribution, np.cos(theta_a), alpha)
    vb = _v_of_cos(distribution, np.cos(theta_b), alpha)
    # panel 1: v in [va, 1]; panel 2: v in [vb, va] with a cosine substitution that smooths the
    # square-root behaviour of the azimuth range at both of its ends
    s2 = 0.5 * (1.0 - np.cos(np.pi * t2))
    j2 = 0.5 * np.pi * np.sin(np.pi * t2)
    v = np.concatenate([va + (1.0 - va) * t1, vb + (va - vb) * s2], axis=-2)
    wv = np.concatenate([(1.0 - va) * w1, (va - vb) * (w2 * j2)], axis=-2)
    v = np.maximum(v, 1e-300)
    cos_m = np.maximum(_cos_of_v(distribution, v, alpha), 1e-300)
    sin_m = np.sqrt(np.maximum(1.0 - cos_m * cos_m, 0.0))
    den = sin_i * sin_m
    mc = mu * cos_m
    safe = den > 0
    ratio = np.where(safe, (c_min - mc) / np.where(safe, den, 1.0), np.where(mc > c_min, -1.0, 1.0))
    phi1 = np.arccos(np.clip(ratio, -1.0, 1.0))  # admissible azimuths: |phi| < phi1
    c = den * np.cos(phi1 * (1.0 - wphi * wphi)) + mc  # i.m at phi = phi1 (1 - w^2)
    fresnel = fresnel_dielectric(c, eta)
    inv_eta = 1.0 / eta
    cos_t = np.sqrt(np.maximum(1.0 - (1.0 - c * c) * (inv_eta * inv_eta), 0.0))
    oz = cos_m * (c * inv_eta - cos_t) - mu * inv_eta  # z of o = refract(i, m)
    tan_o = np.sqrt(np.maximum(1.0 - oz * oz, 0.0)) / np.abs(oz)
    tan_i = sin_i / mu
    g1 = g1_ggx if distribution == "ggx" else g1_beckmann_rational
    f = np.where((oz < 0) & (c > 0), g1(tan_o, alpha) * c * (1.0 - fresnel), 0.0)
    inner = f @ wwphi  # [P, n_theta]
    # D cos dm = d(v^2) dphi / (2 pi); phi in [-phi1, phi1]
    jac = (2.0 * v[..., 0] * wv[..., 0]) * (2.0 * phi1[..., 0]) / (mu[..., 0] * cos_m[..., 0])
    return g1(tan_i[..., 0, 0], alpha[..., 0, 0]) * (inner * jac).sum(-1) / np.pi


def _integrate(distribution, mu, alpha, eta, quad, workers=None, chunk_elems=1 << 17) -> np.ndarray:
    """T at points (flattened broadcast of the inputs), chunked, on up to 4 threads."""
    mu, alpha, eta = (np.ravel(a).astype(float) for a in np.broadcast_arrays(mu, alpha, eta))
    alpha = np.maximum(alpha, ALPHA_MIN)
    n1, n2, nphi = quad
    t1, w1 = quadrature.unit(n1)
    t2, w2 = quadrature.unit(n2)
    wphi, wwphi = quadrature.unit(nphi)
    nodes = (t1[:, None], w1[:, None], t2[:, None], w2[:, None], wphi, wphi * wwphi)
    step = max(1, chunk_elems // ((n1 + n2) * nphi))
    out = np.empty(mu.size)

    def run(start):
        sl = slice(start, start + step)
        with np.errstate(all="ignore"):
            out[sl] = _integrate_chunk(
                distribution, mu[sl, None, None], alpha[sl, None, None], eta[sl, None, None], nodes
            )

    starts = range(0, mu.size, step)
    workers = workers or min(4, os.cpu_count() or 1)
    if workers > 1 and len(starts) > 1:
        with ThreadPoolExecutor(workers) as pool:
            list(pool.map(run, starts))
    else:
        for s in starts:
            run(s)
    return out


def transmittance_direct(
    distribution: str, cos_theta, alpha, eta, quad: tuple[int, int, int] = (24, 96, 24)
) -> np.ndarray:
    """T by direct numerical integration (no table; not clamped to [0, 1]); slow, for checks.
    ``quad``: Gauss-Legendre nodes in the two theta_m panels and in phi_m."""
    d = _canonical(distribution)
    mu, alpha, eta = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (cos_theta, alpha, eta)))
    eta = np.where(mu < 0, 1.0 / eta, eta)
    mu = np.clip(np.abs(mu), MU_MIN, 1.0)
    return _integrate(d, mu, alpha, eta, quad).reshape(mu.shape)


# ---------------------------------------------------------------------------------------------
# grids: every axis is uniform in a coordinate x in [0, 1] given in closed form as a function of
# the physical variable (what evaluation needs); the nodes are found by bisection.


def _x_of_alpha(d, alpha):
    lo, hi = ALPHA_MIN, ALPHA_MAX[d]
    lam = _ALPHA_LOG_WEIGHT
    return lam * np.log(alpha / lo) / np.log(hi / lo) + (1.0 - lam) * (alpha - lo) / (hi - lo)


def _x_of_etap(etap):
    return ((etap - 1.0) / (ETA_MAX - 1.0)) ** 0.25


def _mu_map(inside, alpha, etap):
    """Per-(alpha, eta') parameters of the mu coordinate
    x = c1 (asinh((mu - mu_c) / w) - y0) + c2 asin(sqrt(mu)), x in [0, 1]."""
    lam = np.where(inside, _MU_MAP["int"][0], _MU_MAP["ext"][0])
    w = np.where(inside, _MU_MAP["int"][1], _MU_MAP["ext"][1]) * alpha + np.where(
        inside, _MU_MAP["int"][2], _MU_MAP["ext"][2]
    )
    mu_c = np.where(inside, np.sqrt(1.0 - 1.0 / (etap * etap)), 0.0)
    y0 = np.arcsinh(-mu_c / w)
    y1 = np.arcsinh((1.0 - mu_c) / w)
    return mu_c, w, y0, lam / (y1 - y0), (1.0 - lam) * (2.0 / np.pi)


def _x_of_mu(inside, mu, alpha, etap, asin_sqrt_mu=None):
    """The mu coordinate of the tables (``asin_sqrt_mu``: asin(sqrt(clip(mu, 0, 1))) when known)."""
    mu_c, w, y0, c1, c2 = _mu_map(inside, alpha, etap)
    if asin_sqrt_mu is None:
        asin_sqrt_mu = np.arcsin(np.sqrt(np.clip(mu, 0.0, 1.0)))
    return c1 * (np.arcsinh((mu - mu_c) / w) - y0) + c2 * asin_sqrt_mu


def _invert(f, x, lo, hi, iters=64):
    """Solve f(t) = x for an increasing f on [lo, hi] by bisection (vectorised)."""
    x, lo, hi = np.broadcast_arrays(np.asarray(x, float), np.asarray(lo, float), np.asarray(hi, float))
    lo, hi = lo.copy(), hi.copy()
    for _ in range(iters):
        mid = 0.5 * (lo + hi)
        below = f(mid) < x
        lo = np.where(below, mid, lo)
        hi = np.where(below, hi, mid)
    return 0.5 * (lo + hi)


def _alpha_nodes(d):
    a = _invert(lambda t: _x_of_alpha(d, t), np.linspace(0.0, 1.0, _N_ALPHA), ALPHA_MIN, ALPHA_MAX[d])
    a[0], a[-1] = ALPHA_MIN, ALPHA_MAX[d]
    return a


def _etap_nodes():
    return 1.0 + (ETA_MAX - 1.0) * np.linspace(0.0, 1.0, _N_ETA) ** 4


def _mu_of_x(inside, x, alpha, etap):
    return _invert(lambda t: _x_of_mu(inside, t, alpha, etap), x, 0.0, 1.0)


# ---------------------------------------------------------------------------------------------
# Catmull-Rom splines on tables padded with one ghost node per end and axis


def _pad(table: np.ndarray, modes) -> np.ndarray:
    """Ghost nodes: 'mirror' (f(-1) = f(1): the function is even in the grid coordinate there) or
    'linear' (linear extrapolation)."""
    for axis, (lo_mode, hi_mode) in enumerate(modes):
        a = np.moveaxis(table, axis, 0)
        lo = a[1] if lo_mode == "mirror" else 2.0 * a[0] - a[1]
        hi = a[-2] if hi_mode == "mirror" else 2.0 * a[-1] - a[-2]
        table = np.moveaxis(np.concatenate([lo[None], a, hi[None]], axis=0), 0, axis)
    return np.ascontiguousarray(table)


# alpha (log-like near 1e-4), eta' (x^4 warp: even in x at eta' = 1), mu
_PAD = (("linear", "linear"), ("mirror", "linear"), ("linear", "linear"))


def _cell(x: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Cell of index coordinates x (clamped to [0, n-1]): its first tap in the padded axis
    (= the node left of x) and the fraction t in [0, 1]."""
    x = np.clip(x, 0.0, n - 1.0)
    i = np.minimum(x.astype(np.intp), n - 2)
    return i, x - i


def _cr_weights(t: np.ndarray) -> np.ndarray:
    t2 = t * t
    t3 = t2 * t
    return np.stack(
        [0.5 * (-t3 + 2 * t2 - t), 0.5 * (3 * t3 - 5 * t2 + 2), 0.5 * (-3 * t3 + 4 * t2 + t), 0.5 * (t3 - t2)],
        axis=-1,
    )


@dataclass(frozen=True)
class _Tables:
    distribution: str
    trans: dict  # side -> padded T [alpha, eta', mu]
    fdr: dict  # side -> padded Fdr [alpha, eta']


def _ae_taps(d, alpha, etap):
    ia, ta = _cell(_x_of_alpha(d, alpha) * (_N_ALPHA - 1), _N_ALPHA)
    ie, te = _cell(_x_of_etap(etap) * (_N_ETA - 1), _N_ETA)
    return ia, _cr_weights(ta), ie, _cr_weights(te)


def _eval_pairs(d, tabs, mu, alpha, etap, inside, shape, asin_sqrt_mu=None):
    """Few (alpha, eta') pairs (arrays of one shape, broadcasting with mu to ``shape``): reduce the
    tables to one mu-curve per pair, then interpolate along mu."""
    a_k, e_k, in_k = (np.ravel(v) for v in np.broadcast_arrays(alpha, etap, inside))
    ia, wa, ie, we = _ae_taps(d, a_k, e_k)
    m2 = _N_MU + 2
    curves = np.empty((a_k.size, m2))
    off = np.arange(4)
    for side in _SIDES:
        sel = in_k if side == "int" else ~in_k
        if sel.any():
            rows = tabs.trans[side][ia[sel][:, None, None] + off[:, None], ie[sel][:, None, None] + off[None, :]]
            curves[sel] = np.einsum("kab,kabm->km", wa[sel][:, :, None] * we[sel][:, None, :], rows)
    # cubic coefficients of every cell of every curve: [K, N_mu - 1, 4]
    p0, p1, p2, p3 = curves[:, :-3], curves[:, 1:-2], curves[:, 2:-1], curves[:, 3:]
    coef = np.stack(
        [p1, 0.5 * (p2 - p0), p0 - 2.5 * p1 + 2.0 * p2 - 0.5 * p3, 1.5 * (p1 - p2) + 0.5 * (p3 - p0)], axis=-1
    ).ravel()
    i, t = _cell(_x_of_mu(inside, mu, alpha, etap, asin_sqrt_mu) * (_N_MU - 1), _N_MU)
    pair_shape = np.broadcast_shapes(np.shape(alpha), np.shape(etap), np.shape(inside))
    base = np.broadcast_to((np.arange(a_k.size).reshape(pair_shape) * (_N_MU - 1) + i) * 4, shape).ravel()
    t = np.broadcast_to(t, shape).ravel()
    c0, c1, c2, c3 = (np.take(coef, base + j) for j in range(4))
    return c0 + t * (c1 + t * (c2 + t * c3))


def _eval_points(d, tabs, mu, alpha, etap, inside):
    """One (alpha, eta') per point (flat arrays): tricubic Catmull-Rom, 64 taps."""
    out = np.empty(mu.size)
    ia, wa, ie, we = _ae_taps(d, alpha, etap)
    i, t = _cell(_x_of_mu(inside, mu, alpha, etap) * (_N_MU - 1), _N_MU)
    wm = _cr_weights(t)
    for side in _SIDES:
        sel = np.flatnonzero(inside if side == "int" else ~inside)
        table = tabs.trans[side]
        s0, s1, _ = (s // table.itemsize for s in table.strides)
        off = (np.arange(4)[:, None, None] * s0 + np.arange(4)[None, :, None] * s1 + np.arange(4)).ravel()
        flat = table.ravel()
        for c in range(0, sel.size, 8192):
            k = sel[c : c + 8192]
            vals = np.take(flat, (ia[k] * s0 + ie[k] * s1 + i[k])[:, None] + off).reshape(-1, 4, 4, 4)
            out[k] = np.einsum("nabc,na,nb,nc->n", vals, wa[k], we[k], wm[k], optimize=True)
    return out


# ---------------------------------------------------------------------------------------------
# building and caching


def _spec(d: str) -> str:
    return json.dumps(
        {
            "format": _FORMAT,
            "distribution": d,
            "alpha": [ALPHA_MIN, ALPHA_MAX[d]],
            "eta_max": ETA_MAX,
            "mu_min": MU_MIN,
            "n": [_N_MU, _N_ALPHA, _N_ETA],
            "quad": _QUAD,
            "maps": [_ALPHA_LOG_WEIGHT, _MU_MAP],
        },
        sort_keys=True,
    )


def _cache_path(d: str) -> Path:
    digest = hashlib.sha256(_spec(d).encode()).hexdigest()[:12]
    return cache_dir() / f"rough_transmittance_{d}_{digest}.npz"


def _fdr_table(d: str, side: str, t_pad: np.ndarray) -> np.ndarray:
    """1 - integral T(mu) 2 mu dmu on every (alpha, eta') node: the mu-spline integrated with 4
    Gauss points per cell of the mu coordinate."""
    inside = side == "int"
    a = _alpha_nodes(d)[:, None, None]
    e = _etap_nodes()[None, :, None]
    g, gw = quadrature.unit(4)
    k = (np.arange(_N_MU - 1)[:, None] + g[None, :]).ravel()  # index coordinates
    i, t = _cell(k, _N_MU)
    vals = np.einsum("aekt,kt->aek", t_pad[1:-1, 1:-1][:, :, i[:, None] + np.arange(4)], _cr_weights(t))
    mu = _mu_of_x(inside, k / (_N_MU - 1), a, e)
    h = 1e-7  # d mu / d index from the closed-form forward map
    lo, hi = np.maximum(mu - h, 0.0), np.minimum(mu + h, 1.0)
    dmu = (hi - lo) / ((_x_of_mu(inside, hi, a, e) - _x_of_mu(inside, lo, a, e)) * (_N_MU - 1))
    return 1.0 - np.sum(np.clip(vals, 0.0, 1.0) * 2.0 * mu * dmu * np.tile(gw, _N_MU - 1), axis=-1)


def _build(d: str) -> dict[str, np.ndarray]:
    a = _alpha_nodes(d)[:, None, None]
    e = _etap_nodes()[None, :, None]
    x = np.linspace(0.0, 1.0, _N_MU)
    out = {}
    for side in _SIDES:
        inside = side == "int"
        mu = np.maximum(_mu_of_x(inside, x, a, e), MU_MIN)  # [alpha, eta', mu]
        t = _integrate(d, mu, a, 1.0 / e if inside else e, _QUAD[side]).reshape(mu.shape)
        out[f"T_{side}"] = t
        out[f"Fdr_{side}"] = _fdr_table(d, side, _pad(t, _PAD))
    return out


def _load(path: Path, d: str) -> dict[str, np.ndarray] | None:
    shape = (_N_ALPHA, _N_ETA, _N_MU)
    shapes = {**{f"T_{s}": shape for s in _SIDES}, **{f"Fdr_{s}": shape[:2] for s in _SIDES}}
    return load_tables(path, _spec(d), shapes)


def _save(path: Path, d: str, data: dict[str, np.ndarray]) -> None:
    """Write the tables to the cache, dropping tables of other grid versions."""
    save_tables(path, f"rough_transmittance_{d}_*.npz", spec=np.array(_spec(d)), **data)


@functools.cache  # = lru_cache(maxsize=None)
def _tables(d: str) -> _Tables:
    path = _cache_path(d)
    data = _load(path, d)
    if data is None:
        data = _build(d)
        _save(path, d, data)
    return _Tables(
        d,
        trans={s: _pad(data[f"T_{s}"], _PAD) for s in _SIDES},
        fdr={s: _pad(data[f"Fdr_{s}"], _PAD[:2]) for s in _SIDES},
    )


# ---------------------------------------------------------------------------------------------
# public API


def transmittance(distribution: str, cos_theta, alpha, eta) -> np.ndarray:
    """Rough dielectric transmittance T(mu, alpha, eta) in [0, 1] (see the module docstring) for a
    distribution in {beckmann, ggx, phong} ('as' = phong). Broadcasts ``cos_theta`` (mu),
    ``alpha`` and ``eta`` (relative IOR beyond / before the interface; < 1 from the inside).
    NaN inputs (or eta <= 0) give NaN."""
    d = _canonical(distribution)
    tabs = _tables(d)
    terms = _mu_terms(cos_theta)
    mu = np.asarray(cos_theta, dtype=float)
    alpha = np.asarray(alpha, dtype=float)
    eta = np.asarray(eta, dtype=float)
    shape = np.broadcast_shapes(mu.shape, alpha.shape, eta.shape)
    n = int(np.prod(shape))
    if n == 0:
        return np.zeros(shape)
    if terms is not None:  # a probe's cosines, all in [0, 1]: their terms are known
        with np.errstate(invalid="ignore"):
            usable = bool(np.all(np.isfinite(alpha) & np.isfinite(eta) & (eta > 0)))
        pair_shape = np.broadcast_shapes(alpha.shape, eta.shape)
        if usable and 16 * int(np.prod(pair_shape)) <= n:
            alpha = np.clip(alpha, ALPHA_MIN, ALPHA_MAX[d])
            inside = eta < 1.0
            etap = np.clip(np.where(inside, 1.0 / eta, eta), 1.0, ETA_MAX)
            out = _eval_pairs(d, tabs, terms[0], alpha, etap, inside, shape, terms[1])
            return np.clip(out, 0.0, 1.0).reshape(shape)
    with np.errstate(invalid="ignore"):
        bad = ~(np.isfinite(mu) & np.isfinite(alpha) & np.isfinite(eta) & (eta > 0))
    if bad.any():  # placeholders; NaN is put back at the end
        mu, alpha, eta = np.where(bad, 1.0, mu), np.where(bad, 0.1, alpha), np.where(bad, 1.5, eta)
    if np.any(mu < 0):  # light from the other side
        eta = np.where(mu < 0, 1.0 / eta, eta)
        mu = np.abs(mu)
    mu = np.clip(mu, MU_MIN, 1.0)
    alpha = np.clip(alpha, ALPHA_MIN, ALPHA_MAX[d])
    inside = eta < 1.0
    etap = np.clip(np.where(inside, 1.0 / eta, eta), 1.0, ETA_MAX)
    pair_shape = np.broadcast_shapes(alpha.shape, etap.shape)
    if 16 * int(np.prod(pair_shape)) <= n:  # few (alpha, eta) pairs, e.g. one per material
        out = _eval_pairs(d, tabs, mu, alpha, etap, inside, shape)
    else:
        mu, alpha, etap, inside = (np.broadcast_to(v, shape).ravel() for v in (mu, alpha, etap, inside))
        out = _eval_points(d, tabs, mu, alpha, etap, inside)
    out = np.clip(out, 0.0, 1.0).reshape(shape)
    if bad.any():
        out[np.broadcast_to(bad, shape)] = np.nan
    return out


#: mu-only terms of read-only cosine arrays (a probe's geometry, evaluated again at every render): id -> (the
#: array, kept so that its id stays its own; clip(mu, MU_MIN, 1); asin(sqrt(that))), the most recent last
_MU_TERMS: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
MU_TERMS_SIZE = 8


def _mu_terms(cos_theta) -> tuple[np.ndarray, np.ndarray] | None:
    """(clip(mu, MU_MIN, 1), asin(sqrt(that))) of a read-only float64 array of cosines in [0, 1] (finite), kept
    for the next call with the same array; None for any other input (computed as before by the caller). Read-only
    arrays (and views of read-only arrays) cannot change under the cache: the probe's geometry is made so."""
    if not isinstance(cos_theta, np.ndarray) or cos_theta.dtype != np.float64 or not _read_only(cos_theta):
        return None
    hit = _MU_TERMS.pop(id(cos_theta), None)
    if hit is None or hit[0] is not cos_theta:
        with np.errstate(invalid="ignore"):
            if not bool(np.all((cos_theta >= 0.0) & (cos_theta <= 1.0))):  # NaN, the far side: the general path
                return None
        mu = np.clip(cos_theta, MU_MIN, 1.0)
        hit = (cos_theta, mu, np.arcsin(np.sqrt(np.clip(mu, 0.0, 1.0))))
    _MU_TERMS[id(cos_theta)] = hit
    while len(_MU_TERMS) > MU_TERMS_SIZE:
        del _MU_TERMS[next(iter(_MU_TERMS))]
    return hit[1], hit[2]


def _read_only(a: np.ndarray) -> bool:
    """Whether neither ``a`` nor any array it views can be written through."""
    view: object = a
    while isinstance(view, np.ndarray):
        if view.flags.writeable:
            return False
        view = view.base
    return True


def diffuse_fresnel_reflectance(distribution: str, alpha, eta) -> np.ndarray:
    """Fdr = 1 - integral T(mu, alpha, eta) 2 mu dmu: the part of diffuse (cosine-weighted) light
    arriving at the interface from the side where the relative IOR is ``eta`` that is not
    transmitted. roughplastic needs the internal side: pass 1/eta = extIOR/intIOR."""
    d = _canonical(distribution)
    tabs = _tables(d)
    alpha = np.asarray(alpha, dtype=float)
    eta = np.asarray(eta, dtype=float)
    shape = np.broadcast_shapes(alpha.shape, eta.shape)
    with np.errstate(invalid="ignore"):
        bad = np.broadcast_to(~(np.isfinite(alpha) & np.isfinite(eta) & (eta > 0)), shape).ravel()
    a = np.broadcast_to(alpha, shape).ravel()
    e = np.broadcast_to(eta, shape).ravel()
    if bad.any():
        a, e = np.where(bad, 0.1, a), np.where(bad, 1.5, e)
    a = np.clip(a, ALPHA_MIN, ALPHA_MAX[d])
    inside = e < 1.0
    etap = np.clip(np.where(inside, 1.0 / e, e), 1.0, ETA_MAX)
    ia, wa, ie, we = _ae_taps(d, a, etap)
    off = np.arange(4)
    out = np.empty(a.size)
    for side in _SIDES:
        sel = inside if side == "int" else ~inside
        if sel.any():
            vals = tabs.fdr[side][ia[sel][:, None, None] + off[:, None], ie[sel][:, None, None] + off[None, :]]
            out[sel] = np.einsum("nab,na,nb->n", vals, wa[sel], we[sel])
    out = np.clip(out, 0.0, 1.0)
    out[bad] = np.nan
    return out.reshape(shape)
