"""Transmittance through a rough dielectric interface, as Mitsuba 0.6 tabulates it.

Mitsuba 0.6's ``roughplastic`` (and ``roughcoating``) weight their diffuse term with T(mu_i) T(mu_o)
and renormalise it with the internal diffuse reflectance Fdr. Mitsuba reads both from precomputed
tables (``data/microfacet/{beckmann,ggx,phong}.dat``, written by ``src/utils/rdielprec.cpp`` and read
by ``src/bsdfs/rtrans.h``); this module computes the same quantities by numerical integration and
caches the result.

What is tabulated (rdielprec integrates the ``sample()`` weight of the ``roughdielectric`` plugin
restricted to transmission, in importance mode): for an incident direction i with cos(theta_i) = mu
on the side of the interface where the relative IOR (far side / near side) is eta,

    T(mu, alpha, eta) = integral over microfacet normals m with i.m > 0 of
        D(m) G1(i) G1(o) (i.m) (1 - F(i.m, eta)) / mu  dm,

where o = refract(i, m) (zero under total internal reflection and where o does not cross the
macro-surface), D and the separable Smith G1 are those of ``microfacet.h`` (Walter et al. 2007: Beckmann
with its rational G1, exact GGX G1, Phong with e = 2/alpha^2 - 2 and the Beckmann G1), and F is the
dielectric Fresnel reflectance. This is the integral of the rough BTDF times |cos(theta_o)|, so the
energy lost to shadowing-masking is *not* counted as transmitted: T <= 1 - (rough reflectance) and
T < 1 even at eta = 1. ``diffuse_fresnel_reflectance`` returns 1 - integral T(mu) 2 mu dmu
(``RoughTransmittance::evalDiffuse`` is that integral); roughplastic uses
Fdr = 1 - evalDiffuse(alpha) of the *internal* side, i.e. eta -> 1/eta.

Numerics. The integral over m uses the D-importance variable in theta_m (split where the allowed
azimuth range starts to shrink, with a cosine substitution on the second panel) and an endpoint
substitution in phi_m; eta > 1 and eta < 1 are tabulated separately for eta' = max(eta, 1/eta) in
[1, 4] and alpha in [1e-4, 4] (phong: [1e-4, 1]). Axes: alpha = 1e-4 + (alpha_max - 1e-4) x^4,
eta' = 1 + 3 x^4 (as Mitsuba), mu = sin^2(pi x / 2) for eta >= 1 and, for eta < 1, an asinh
coordinate centred on the critical angle mu_c = sqrt(1 - eta^2) with a width growing with alpha
(the total-internal-reflection edge is sharp for small alpha). Values are interpolated with
tensor-product Catmull-Rom splines (as Mitsuba) and clamped to [0, 1] (as Mitsuba); Fdr is
tabulated on the (alpha, eta') nodes by integrating the mu-spline. See ``GRID_INFO`` for the grid
sizes and the measured accuracy.

Inputs outside the tables are clamped: alpha to [1e-4, alpha_max] (Mitsuba clamps alpha >= 1e-4 and
refuses alpha above its table: 4 for beckmann/ggx, 0.5 for phong), eta' to [1, 4] (Mitsuba refuses
eta' outside [1.0001, 4]), mu to [1e-6, 1]. A negative cosine means light from the other side:
T(-mu, alpha, eta) = T(mu, alpha, 1/eta), as in ``RoughTransmittance::eval``.

Tables are built once per distribution (a couple of seconds) and cached in memory and on disk
(``$MATREMAP_CACHE_DIR`` or ``~/.cache/matremap``; skipped silently when not writable).
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import tempfile
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...optics import fresnel_dielectric
from .microfacet import ALPHA_MIN, g1_beckmann_rational, g1_ggx, phong_exponent

__all__ = [
    "ALPHA_MAX",
    "ETA_MAX",
    "GRID_INFO",
    "diffuse_fresnel_reflectance",
    "transmittance",
    "transmittance_direct",
]

#: largest tabulated roughness per distribution (larger values are clamped)
ALPHA_MAX = {"beckmann": 4.0, "ggx": 4.0, "phong": 1.0}
#: largest tabulated eta' = max(eta, 1/eta)
ETA_MAX = 4.0
MU_MIN = 1e-6

_FORMAT = 1
# grid: nodes along mu, alpha, eta' (both sides use the same sizes)
_N_MU, _N_ALPHA, _N_ETA = 48, 32, 20
# quadrature: Gauss-Legendre nodes in theta_m (panel 1, panel 2) and in phi_m, per side
_QUAD = {"ext": (8, 12, 8), "int": (8, 24, 8)}
# width of the asinh mu-coordinate of the internal side: w = _W_SLOPE * alpha + _W0
_W_SLOPE, _W0 = 1.0, 1e-3

GRID_INFO = {
    "mu_nodes": _N_MU,
    "alpha_nodes": _N_ALPHA,
    "eta_nodes_per_side": _N_ETA,
    "quadrature_nodes": {k: (v[0] + v[1]) * v[2] for k, v in _QUAD.items()},
}


def _canonical(distribution: str) -> str:
    d = str(distribution).lower()
    if d == "as":
        d = "phong"
    if d not in ALPHA_MAX:
        raise ValueError(f"unknown microfacet distribution {distribution!r}; expected beckmann, ggx or phong")
    return d


# ---------------------------------------------------------------------------------------------
# direct numerical integration


def _gauss01(n: int) -> tuple[np.ndarray, np.ndarray]:
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (x + 1.0), 0.5 * w


def _v_of_cos(distribution: str, cos_m: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Importance variable v in [0, 1] of a microfacet polar angle (v = 1 at the normal, 0 at
    grazing): v^2 = 1 - P(theta < theta_m) for beckmann/ggx and v^2 = P(theta > theta_m) ... for phong,
    where P is the distribution of theta under D(m) cos(theta_m)."""
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
    """T for points given as arrays of shape [P, 1, 1]."""
    t1, w1, t2, w2, wphi, wwphi = nodes
    sin_i = np.sqrt(np.maximum(1.0 - mu * mu, 0.0))
    c_min = np.sqrt(np.maximum(1.0 - eta * eta, 0.0))  # below it: total internal reflection
    # microfacets with i.m > c_min form a cap of angular radius theta_cap around i; its azimuth
    # range around the macro normal is full for theta_m < theta_a and empty beyond theta_b
    theta_i = np.arccos(np.clip(mu, -1.0, 1.0))
    theta_cap = np.arccos(c_min)
    theta_a = np.clip(theta_cap - theta_i, 0.0, 0.5 * np.pi)
    theta_b = np.clip(theta_cap + theta_i, 0.0, 0.5 * np.pi)
    va = _v_of_cos(distribution, np.cos(theta_a), alpha)
    vb = _v_of_cos(distribution, np.cos(theta_b), alpha)
    # panel 1: v in [va, 1] (plain), panel 2: v in [vb, va] with a cosine substitution that smooths
    # the square-root behaviour of the azimuth range at both ends
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
    phi1 = np.arccos(np.clip(ratio, -1.0, 1.0))  # allowed azimuths: |phi| < phi1
    c = den * np.cos(phi1 * (1.0 - wphi * wphi)) + mc  # phi = phi1 (1 - w^2)
    fresnel = fresnel_dielectric(c, eta)
    inv_eta = 1.0 / eta
    cos_t = np.sqrt(np.maximum(1.0 - (1.0 - c * c) * (inv_eta * inv_eta), 0.0))
    oz = cos_m * (c * inv_eta - cos_t) - mu * inv_eta  # z of o = refract(i, m)
    oz2 = oz * oz
    tan2_o = np.maximum(1.0 - oz2, 0.0) / oz2
    tan2_i = (1.0 - mu * mu) / (mu * mu)
    g1 = g1_ggx if distribution == "ggx" else g1_beckmann_rational
    f = np.where((oz < 0) & (c > 0), g1(tan2_o, alpha) * c * (1.0 - fresnel), 0.0)
    inner = f @ wwphi  # [P, n_theta]
    # D cos dm = du dphi / (2 pi), u = 1 - v^2 (or v^2), du = 2 v dv; phi in [-phi1, phi1]
    jac = (2.0 * v[..., 0] * wv[..., 0]) * (2.0 * phi1[..., 0]) / (mu[..., 0] * cos_m[..., 0])
    return g1(tan2_i[..., 0, 0], alpha[..., 0, 0]) * (inner * jac).sum(-1) / np.pi


def _integrate(distribution, mu, alpha, eta, quad, workers=None, chunk_elems=1 << 15):
    mu, alpha, eta = (np.ravel(a).astype(float) for a in np.broadcast_arrays(mu, alpha, eta))
    alpha = np.maximum(alpha, ALPHA_MIN)
    n1, n2, nphi = quad
    t1, w1 = _gauss01(n1)
    t2, w2 = _gauss01(n2)
    wphi, wwphi = _gauss01(nphi)
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
    distribution: str,
    cos_theta: np.ndarray,
    alpha: np.ndarray,
    eta: np.ndarray,
    quad: tuple[int, int, int] = (16, 48, 16),
) -> np.ndarray:
    """T by direct numerical integration (no table, no clamping to [0, 1]); slow, for checks.
    ``quad`` = Gauss-Legendre nodes in the two theta_m panels and in phi_m."""
    d = _canonical(distribution)
    mu, alpha, eta = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (cos_theta, alpha, eta)))
    flip = mu < 0
    eta = np.where(flip, 1.0 / eta, eta)
    mu = np.clip(np.abs(mu), MU_MIN, 1.0)
    return _integrate(d, mu, alpha, eta, quad).reshape(mu.shape)


# ---------------------------------------------------------------------------------------------
# grids


def _alpha_of_x(d, x):
    return ALPHA_MIN + (ALPHA_MAX[d] - ALPHA_MIN) * x**4


def _x_of_alpha(d, alpha):
    return ((alpha - ALPHA_MIN) / (ALPHA_MAX[d] - ALPHA_MIN)) ** 0.25


def _etap_of_x(x):
    return 1.0 + (ETA_MAX - 1.0) * x**4


def _x_of_etap(etap):
    return ((etap - 1.0) / (ETA_MAX - 1.0)) ** 0.25


def _mu_of_index_ext(k):
    return np.maximum(np.sin(0.5 * np.pi * k / (_N_MU - 1)) ** 2, MU_MIN)


def _index_of_mu_ext(mu):
    return np.arcsin(np.sqrt(mu)) * (2.0 / np.pi) * (_N_MU - 1)


def _asinh_frame(alpha, etap):
    mu_c = np.sqrt(1.0 - 1.0 / (etap * etap))
    w = _W_SLOPE * alpha + _W0
    return mu_c, w, np.arcsinh(-mu_c / w), np.arcsinh((1.0 - mu_c) / w)


def _mu_of_index_int(k, alpha, etap):
    mu_c, w, y0, y1 = _asinh_frame(alpha, etap)
    return np.clip(mu_c + w * np.sinh(y0 + (y1 - y0) * k / (_N_MU - 1)), MU_MIN, 1.0)


def _index_of_mu_int(mu, alpha, etap):
    mu_c, w, y0, y1 = _asinh_frame(alpha, etap)
    return (np.arcsinh((mu - mu_c) / w) - y0) / (y1 - y0) * (_N_MU - 1)


# ---------------------------------------------------------------------------------------------
# Catmull-Rom interpolation on padded tables (one ghost node per side and axis)


def _pad(table: np.ndarray, modes) -> np.ndarray:
    """Add one ghost node at both ends of every axis: 'mirror' (f(-1) = f(1), for a function even
    in the grid coordinate there) or 'linear' (linear extrapolation)."""
    for axis, (lo_mode, hi_mode) in enumerate(modes):
        a = np.moveaxis(table, axis, 0)
        lo = a[1] if lo_mode == "mirror" else 2.0 * a[0] - a[1]
        hi = a[-2] if hi_mode == "mirror" else 2.0 * a[-1] - a[-2]
        table = np.moveaxis(np.concatenate([lo[None], a, hi[None]], axis=0), 0, axis)
    return np.ascontiguousarray(table)


def _cr(x: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Catmull-Rom taps for index coordinates x in [0, n-1]: the first tap's index in the padded
    axis and the 4 weights."""
    x = np.clip(x, 0.0, n - 1.0)
    i = np.minimum(x.astype(np.intp), n - 2)
    t = x - i
    t2 = t * t
    t3 = t2 * t
    w = np.stack(
        [0.5 * (-t3 + 2 * t2 - t), 0.5 * (3 * t3 - 5 * t2 + 2), 0.5 * (-3 * t3 + 4 * t2 + t), 0.5 * (t3 - t2)],
        axis=-1,
    )
    return i, w


_MU_PAD = {"ext": ("mirror", "mirror"), "int": ("linear", "linear")}
_PAD_AE = (("mirror", "linear"), ("mirror", "linear"))  # alpha, eta'


@dataclass(frozen=True)
class _Side:
    table: np.ndarray  # padded T [alpha, eta', mu] (mu last, contiguous)
    fdr: np.ndarray  # padded Fdr [alpha, eta']


@dataclass(frozen=True)
class _Tables:
    distribution: str
    ext: _Side
    int: _Side


def _mu_index(side, mu, alpha, etap):
    return _index_of_mu_ext(mu) if side == "ext" else _index_of_mu_int(mu, alpha, etap)


def _curves(side: _Side, ia, wa, ie, we) -> np.ndarray:
    """Spline-interpolate the table in (alpha, eta') -> one padded mu-curve per point [K, N_mu + 2]."""
    t = side.table
    off = np.arange(4)
    rows = t[(ia[:, None, None] + off[None, :, None]), (ie[:, None, None] + off[None, None, :])]  # K,4,4,M
    return np.einsum("kab,kabm->km", wa[:, :, None] * we[:, None, :], rows)


def _eval_side(d: str, side_name: str, side: _Side, mu, alpha, etap, pair=None):
    """T on one side. mu: [N]; alpha, etap: [K] per (alpha, eta') pair and ``pair`` [N] the pair of
    each point (or None when K == N, one pair per point)."""
    ia, wa = _cr(_x_of_alpha(d, alpha) * (_N_ALPHA - 1), _N_ALPHA)
    ie, we = _cr(_x_of_etap(etap) * (_N_ETA - 1), _N_ETA)
    a_pt, e_pt = (alpha, etap) if pair is None else (alpha[pair], etap[pair])
    im, wm = _cr(_mu_index(side_name, mu, a_pt, e_pt), _N_MU)
    off = np.arange(4)
    if pair is not None:  # few (alpha, eta') pairs: reduce to mu-curves first
        curves = _curves(side, ia, wa, ie, we)
        return np.einsum("na,na->n", curves[pair[:, None], im[:, None] + off], wm)
    t = side.table
    out = np.empty(mu.shape)
    step = 8192
    for s in range(0, mu.size, step):
        sl = slice(s, s + step)
        vals = t[
            ia[sl, :, None, None] + off[:, None, None],
            ie[sl, None, :, None] + off[None, :, None],
            im[sl, None, None, :] + off[None, None, :],
        ]  # n,4,4,4
        vals = np.einsum("nabc,nc->nab", vals, wm[sl])
        vals = np.einsum("nab,nb->na", vals, we[sl])
        out[sl] = np.einsum("na,na->n", vals, wa[sl])
    return out


# ---------------------------------------------------------------------------------------------
# building, caching


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
            "w": [_W_SLOPE, _W0],
        },
        sort_keys=True,
    )


def _cache_dir() -> Path:
    env = os.environ.get("MATREMAP_CACHE_DIR")
    return Path(env) if env else Path.home() / ".cache" / "matremap"


def _cache_path(d: str) -> Path:
    digest = hashlib.sha256(_spec(d).encode()).hexdigest()[:12]
    return _cache_dir() / f"rough_transmittance_{d}_{digest}.npz"


def _fdr_table(d: str, side_name: str, t_pad: np.ndarray) -> np.ndarray:
    """1 - integral T(mu) 2 mu dmu on every (alpha, eta') node, integrating the mu-spline with
    4 Gauss points per grid cell in the index coordinate."""
    a_nodes = _alpha_of_x(d, np.linspace(0.0, 1.0, _N_ALPHA))
    e_nodes = _etap_of_x(np.linspace(0.0, 1.0, _N_ETA))
    g, gw = _gauss01(4)
    k = (np.arange(_N_MU - 1)[:, None] + g[None, :]).ravel()  # index coordinates
    kw = np.tile(gw, _N_MU - 1)
    im, wm = _cr(k, _N_MU)
    off = np.arange(4)
    vals = np.einsum("aekt,kt->aek", t_pad[1:-1, 1:-1][:, :, im[:, None] + off], wm)  # spline values
    a, e = a_nodes[:, None, None], e_nodes[None, :, None]
    if side_name == "ext":
        c = 0.5 * np.pi / (_N_MU - 1)
        mu = np.broadcast_to(_mu_of_index_ext(k), vals.shape)
        dmu = np.broadcast_to(c * np.sin(2.0 * c * k), vals.shape)
    else:
        mu = _mu_of_index_int(k, a, e)
        mu_c, w, y0, y1 = _asinh_frame(a, e)
        y = y0 + (y1 - y0) * k / (_N_MU - 1)
        dmu = w * np.cosh(y) * (y1 - y0) / (_N_MU - 1)
        dmu = np.where((mu > MU_MIN) & (mu < 1.0), dmu, 0.0)
    trans = np.clip(vals, 0.0, 1.0)
    return 1.0 - np.sum(trans * 2.0 * mu * dmu * kw, axis=-1)


def _build(d: str) -> dict[str, np.ndarray]:
    kmu = np.arange(_N_MU, dtype=float)
    a_nodes = _alpha_of_x(d, np.linspace(0.0, 1.0, _N_ALPHA))
    e_nodes = _etap_of_x(np.linspace(0.0, 1.0, _N_ETA))
    A, E, K = np.meshgrid(a_nodes, e_nodes, kmu, indexing="ij")  # [alpha, eta', mu]
    out = {}
    for side_name in ("ext", "int"):
        if side_name == "ext":
            mu, eta = _mu_of_index_ext(K), E
        else:
            mu, eta = _mu_of_index_int(K, A, E), 1.0 / E
        t = _integrate(d, mu, A, eta, _QUAD[side_name]).reshape(A.shape)
        t_pad = _pad(t, _PAD_AE + (_MU_PAD[side_name],))
        out[f"T_{side_name}"] = t
        out[f"Fdr_{side_name}"] = _fdr_table(d, side_name, t_pad)
    return out


def _load(path: Path, d: str) -> dict[str, np.ndarray] | None:
    try:
        with np.load(path, allow_pickle=False) as z:
            if str(z["spec"]) != _spec(d):
                return None
            data = {k: np.array(z[k]) for k in ("T_ext", "T_int", "Fdr_ext", "Fdr_int")}
    except (OSError, KeyError, ValueError, EOFError):
        return None
    shape = (_N_ALPHA, _N_ETA, _N_MU)
    ok = all(data[f"T_{s}"].shape == shape and data[f"Fdr_{s}"].shape == shape[:2] for s in ("ext", "int"))
    return data if ok and all(np.isfinite(v).all() for v in data.values()) else None


def _save(path: Path, d: str, data: dict[str, np.ndarray]) -> None:
    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.stem + ".", suffix=".tmp")
        with os.fdopen(fd, "wb") as f:
            np.savez(f, spec=np.array(_spec(d)), **data)
        os.replace(tmp, path)
        tmp = None
    except OSError:
        pass  # no (writable) cache directory: keep the tables in memory only
    finally:
        if tmp is not None:
            try:
                os.unlink(tmp)
            except OSError:
                pass


@functools.lru_cache(maxsize=None)
def _tables(d: str) -> _Tables:
    path = _cache_path(d)
    data = _load(path, d)
    if data is None:
        data = _build(d)
        _save(path, d, data)
    sides = {}
    for s in ("ext", "int"):
        sides[s] = _Side(
            table=_pad(data[f"T_{s}"], _PAD_AE + (_MU_PAD[s],)),
            fdr=_pad(data[f"Fdr_{s}"], _PAD_AE),
        )
    return _Tables(d, sides["ext"], sides["int"])


# ---------------------------------------------------------------------------------------------
# public API


def transmittance(distribution: str, cos_theta, alpha, eta) -> np.ndarray:
    """Rough dielectric transmittance T(mu, alpha, eta) (see the module docstring), broadcasting
    ``cos_theta``, ``alpha`` and ``eta`` (relative IOR beyond / before the interface, < 1 on the
    inside). Values are in [0, 1]."""
    d = _canonical(distribution)
    tabs = _tables(d)
    mu = np.asarray(cos_theta, dtype=float)
    alpha = np.asarray(alpha, dtype=float)
    eta = np.asarray(eta, dtype=float)
    shape = np.broadcast_shapes(mu.shape, alpha.shape, eta.shape)
    n = int(np.prod(shape))
    if n == 0:
        return np.zeros(shape)
    bad = ~(np.isfinite(mu) & np.isfinite(alpha) & np.isfinite(eta) & (eta > 0))
    if bad.any():  # NaN (or eta <= 0) in, NaN out; compute the rest with placeholders
        mu, alpha, eta = np.where(bad, 1.0, mu), np.where(bad, 0.1, alpha), np.where(bad, 1.5, eta)
    alpha = np.clip(alpha, ALPHA_MIN, ALPHA_MAX[d])
    if np.any(mu < 0):  # light from the other side
        eta = np.where(mu < 0, 1.0 / eta, eta)
        mu = np.abs(mu)
    mu_flat = np.broadcast_to(np.clip(mu, MU_MIN, 1.0), shape).ravel()
    # (alpha, eta) pairs: few of them (one per material, typically) -> reduce to mu-curves first
    a_pairs, e_pairs = (np.ravel(x) for x in np.broadcast_arrays(alpha, eta))
    k = a_pairs.size
    if k * (_N_MU + 2) < n:
        pair = np.broadcast_to(np.arange(k).reshape(np.broadcast_shapes(alpha.shape, eta.shape)), shape).ravel()
    else:
        a_pairs = np.broadcast_to(alpha, shape).ravel()
        e_pairs = np.broadcast_to(eta, shape).ravel()
        pair = None
    out = np.empty(n)
    inside = e_pairs < 1.0
    etap = np.clip(np.where(inside, 1.0 / e_pairs, e_pairs), 1.0, ETA_MAX)
    for side_name, sel in (("ext", ~inside), ("int", inside)):
        if not sel.any():
            continue
        side = tabs.ext if side_name == "ext" else tabs.int
        if pair is None:
            out[sel] = _eval_side(d, side_name, side, mu_flat[sel], a_pairs[sel], etap[sel])
        else:
            pts = sel[pair]
            remap = np.cumsum(sel) - 1
            out[pts] = _eval_side(
                d, side_name, side, mu_flat[pts], a_pairs[sel], etap[sel], pair=remap[pair[pts]]
            )
    out = np.clip(out, 0.0, 1.0).reshape(shape)
    if bad.any():
        out[np.broadcast_to(bad, shape)] = np.nan
    return out


def diffuse_fresnel_reflectance(distribution: str, alpha, eta) -> np.ndarray:
    """Fdr = 1 - integral over mu of T(mu, alpha, eta) 2 mu dmu: the fraction of cosine-weighted
    (diffuse) light arriving at the interface from the side where the relative IOR is ``eta`` that
    is *not* transmitted. roughplastic uses the internal side: pass 1/eta = extIOR/intIOR."""
    d = _canonical(distribution)
    tabs = _tables(d)
    alpha = np.asarray(alpha, dtype=float)
    eta = np.asarray(eta, dtype=float)
    shape = np.broadcast_shapes(alpha.shape, eta.shape)
    bad = np.broadcast_to(~(np.isfinite(alpha) & np.isfinite(eta) & (eta > 0)), shape).ravel()
    a = np.broadcast_to(np.clip(alpha, ALPHA_MIN, ALPHA_MAX[d]), shape).ravel()
    e = np.broadcast_to(eta, shape).ravel()
    if bad.any():
        a, e = np.where(bad, 0.1, a), np.where(bad, 1.5, e)
    inside = e < 1.0
    etap = np.clip(np.where(inside, 1.0 / e, e), 1.0, ETA_MAX)
    ia, wa = _cr(_x_of_alpha(d, a) * (_N_ALPHA - 1), _N_ALPHA)
    ie, we = _cr(_x_of_etap(etap) * (_N_ETA - 1), _N_ETA)
    off = np.arange(4)
    out = np.empty(a.size)
    for side, sel in ((tabs.ext, ~inside), (tabs.int, inside)):
        if sel.any():
            vals = side.fdr[ia[sel, :, None] + off[:, None], ie[sel, None, :] + off[None, :]]
            out[sel] = np.einsum("nab,na,nb->n", vals, wa[sel], we[sel])
    out = np.clip(out, 0.0, 1.0)
    out[bad] = np.nan
    return out.reshape(shape)
