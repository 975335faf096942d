"""The embedded renderer's evaluators of the cycles dialect: f * cos(theta_i) of each model of
:mod:`matremap.dialects.cycles` (its model table, the formulas and their sources are there), as numpy
functions of [N, C, L, P] arrays, zero where either cosine is <= 0 (the renderer masks that).
"""

from __future__ import annotations

import functools
import hashlib
import json
from pathlib import Path

import numpy as np

from matremap.core.diskcache import cache_dir, load_tables, save_tables
from matremap.dialects.cycles import DIFFUSE, GLOSSY
from matremap.renderers.embedded import microfacet as mf
from matremap.renderers.embedded import quadrature

INV_PI = 1.0 / np.pi


def glossy(p, opt, g):
    alpha = mf.drawn_alpha(p["Roughness"] ** 2, g)
    distribution = opt["distribution"]
    if distribution == "ashikhmin_shirley":
        lobe = _ashikhmin_shirley(alpha, g)
    else:
        if distribution in ("ggx", "multi_ggx"):
            d = mf.d_ggx(g.cos_h, g.tan2_h, alpha)
            lam = mf.lambda_ggx
        else:
            d = mf.d_beckmann(g.cos_h, g.tan2_h, alpha)
            lam = mf.lambda_beckmann
        gg = mf.g_height_correlated(lam(g.tan_i, alpha), lam(g.tan_o, alpha))
        lobe = np.where(alpha * alpha <= 2e-10, 0.0, d * gg / (4.0 * g.cos_o))
        if distribution == "multi_ggx":
            lobe = lobe * multiscatter_scale(p["Color"], p["Roughness"], g.cos_o)
    return p["Color"] * lobe + p["Diffuse Color"] * g.lambert


ALBEDO_NODES = 32

_ALBEDO_FORMAT = 1

_ALBEDO_QUAD = (64, 64, 48)


def ggx_directional_albedo(mu, rough, quad: tuple[int, int] | None = None) -> np.ndarray:
    """E(mu, r): the fraction of light the white single-scatter GGX lobe (height-correlated Smith G,
    alpha = r^2) reflects towards a viewer at cos theta = mu, integrated numerically.

    Written over microfacet normals m, E = 1/(2 pi) integral (o.m) G2(i, o) / (cos theta_m mu) du dphi
    with i the mirror of o about m and u = tan^2 / (alpha^2 + tan^2) of theta_m (then
    D cos theta_m dm = du dphi / 2 pi). Reflection leaves the surface (i.n > 0) for all azimuths
    while tan theta_m < tan(theta_o / 2), for none beyond cot(theta_o / 2), and in between for
    |phi| < arccos(mu (t^2 - 1) / (2 sin theta_o t)), t = tan theta_m; the u integral is split at those
    two points and the azimuth integral runs over the admissible range, so the integrand is smooth
    on each panel (error < 2e-4 at mu = 1e-4, < 1e-5 for mu >= 0.05). ``mu`` and ``rough`` broadcast.
    """
    n_u, n_phi = quad or _ALBEDO_QUAD[:2]
    mu, rough = np.broadcast_arrays(np.asarray(mu, dtype=float), np.asarray(rough, dtype=float))
    shape = mu.shape
    mu = np.clip(mu.reshape(-1, 1, 1), 1e-7, 1.0 - 1e-9)
    a2 = (np.clip(rough.reshape(-1, 1, 1), 0.0, 1.0) ** 2) ** 2  # alpha^2
    a2 = np.maximum(a2, 1e-30)
    sin_o = np.sqrt(1.0 - mu * mu)
    xs, ws = quadrature.smoothstep(n_u)
    ends = []
    for t in ((1.0 - sin_o) / mu, (1.0 + sin_o) / mu):  # tan(theta_o / 2), cot(theta_o / 2)
        ends.append(t * t / (a2 + t * t))
    u1, u2 = ends
    u = np.concatenate([u1 * xs[:, None], u1 + (u2 - u1) * xs[:, None]], axis=-2)  # [M, 2 n_u, 1]
    wu = np.concatenate([u1 * ws[:, None], (u2 - u1) * ws[:, None]], axis=-2)
    tan2 = a2 * u / np.maximum(1.0 - u, 1e-300)
    t = np.sqrt(tan2)
    cos_m = 1.0 / np.sqrt(1.0 + tan2)
    sin_m = t * cos_m
    with np.errstate(divide="ignore", invalid="ignore"):
        cos_phi_max = np.where(t > 0.0, mu * (tan2 - 1.0) / (2.0 * sin_o * t), -1.0)
    phi_max = np.arccos(np.clip(cos_phi_max, -1.0, 1.0))
    px, pw = quadrature.smoothstep(n_phi)
    phi = phi_max * px
    o_m = sin_o * sin_m * np.cos(phi) + mu * cos_m
    cos_i = 2.0 * o_m * cos_m - mu
    ok = (o_m > 0.0) & (cos_i > 0.0)
    ci = np.where(ok, cos_i, 1.0)

    def lam(c):
        return 0.5 * (np.sqrt(1.0 + a2 * np.maximum(1.0 - c * c, 0.0) / (c * c)) - 1.0)

    g2 = 1.0 / (1.0 + lam(ci) + lam(mu))
    f = np.where(ok, o_m / (cos_m * mu) * g2, 0.0)
    e = np.sum(f * pw * phi_max * wu, axis=(-2, -1)) / np.pi
    return np.clip(e, 0.0, 1.0).reshape(shape)


def _albedo_spec() -> str:
    return json.dumps({"format": _ALBEDO_FORMAT, "nodes": ALBEDO_NODES, "quad": _ALBEDO_QUAD}, sort_keys=True)


def _albedo_cache_path() -> Path:
    digest = hashlib.sha256(_albedo_spec().encode()).hexdigest()[:12]
    return cache_dir() / f"cycles_ggx_albedo_{digest}.npz"


def _build_albedo_tables() -> tuple[np.ndarray, np.ndarray]:
    """E on the (mu, r) nodes [32, 32] and E_avg on the r nodes [32], as cycles_precompute.cpp
    defines them (node k of n at k / (n - 1), clamped below at 1e-4; r at the clamp is a mirror)."""
    n = ALBEDO_NODES
    nodes = np.maximum(np.arange(n) / (n - 1), 1e-4)
    e = np.stack([ggx_directional_albedo(nodes, r) for r in nodes], axis=1)  # [mu, r]
    # E_avg = integral of 2 mu E(mu) over [0, 1]: three panels, denser where E varies fastest
    x, w = quadrature.unit(_ALBEDO_QUAD[2])
    edges = (0.0, 0.05, 0.3, 1.0)
    mus = np.concatenate([a + (b - a) * x for a, b in zip(edges[:-1], edges[1:], strict=False)])
    wts = np.concatenate([(b - a) * w for a, b in zip(edges[:-1], edges[1:], strict=False)])
    e_avg = np.array([np.sum(2.0 * mus * ggx_directional_albedo(mus, r) * wts) for r in nodes])
    mirror = nodes**4 <= 2e-10  # alpha^2 at or below Cycles' roughness threshold: a mirror, E = 1
    e[:, mirror] = 1.0
    e_avg[mirror] = 1.0
    return np.clip(e, 0.0, 1.0), np.clip(e_avg, 0.0, 1.0)


def _load_albedo_tables(path: Path) -> tuple[np.ndarray, np.ndarray] | None:
    n = ALBEDO_NODES
    data = load_tables(path, _albedo_spec(), {"E": (n, n), "E_avg": (n,)})
    return None if data is None else (data["E"], data["E_avg"])


def _save_albedo_tables(path: Path, e: np.ndarray, e_avg: np.ndarray) -> None:
    """Write the tables to the cache (tables of other versions are removed)."""
    save_tables(path, "cycles_ggx_albedo_*.npz", spec=np.array(_albedo_spec()), E=e, E_avg=e_avg)


@functools.cache
def albedo_tables() -> tuple[np.ndarray, np.ndarray]:
    """(E [mu node, r node], E_avg [r node]) for Multiscatter GGX, from the cache or built."""
    path = _albedo_cache_path()
    tables = _load_albedo_tables(path)
    if tables is None:
        tables = _build_albedo_tables()
        _save_albedo_tables(path, *tables)
    for t in tables:
        t.flags.writeable = False
    return tables


def _lerp_index(x: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cycles' table coordinate: x clamped to [0, 1] times n - 1; the node below, the node above
    (both at most n - 1) and the fraction between them."""
    x = np.clip(np.asarray(x, dtype=float), 0.0, 1.0) * (n - 1)
    i = np.minimum(np.floor(x).astype(np.intp), n - 1)
    return i, np.minimum(i + 1, n - 1), x - i


def ggx_albedo(rough, mu) -> np.ndarray:
    """E(mu, r) read from the table as Cycles does: linear in r within each mu row, then in mu."""
    e, _ = albedo_tables()
    n = ALBEDO_NODES
    rough, mu = np.broadcast_arrays(np.asarray(rough, dtype=float), np.asarray(mu, dtype=float))
    r0, r1, tr = _lerp_index(rough, n)
    m0, m1, tm = _lerp_index(mu, n)

    def row(m):
        return (1.0 - tr) * e[m, r0] + tr * e[m, r1]

    return (1.0 - tm) * row(m0) + tm * row(m1)


def ggx_average_albedo(rough) -> np.ndarray:
    """E_avg(r) read from its table, linearly in r."""
    _, e_avg = albedo_tables()
    r0, r1, t = _lerp_index(rough, ALBEDO_NODES)
    return (1.0 - t) * e_avg[r0] + t * e_avg[r1]


def multiscatter_scale(color, roughness, cos_view) -> np.ndarray:
    """The factor Cycles' Multiscatter GGX puts on the single-scatter lobe (Color not included):
    1 + F_ms (1 - E) / E with F_ms = c E_avg / (1 - c (1 - E_avg)), c = max(Color, 0)."""
    r = np.abs(np.asarray(roughness, dtype=float))  # sqrt(alpha) with alpha = Roughness^2
    e = ggx_albedo(r, cos_view)
    e_avg = ggx_average_albedo(r)
    c = np.maximum(np.asarray(color, dtype=float), 0.0)
    f_ms = c * e_avg / (1.0 - c * (1.0 - e_avg))
    return 1.0 + f_ms * (1.0 - e) / e


def _ashikhmin_shirley(alpha: np.ndarray, g) -> np.ndarray:
    a = np.clip(alpha, 1e-4, 1.0)
    n = 2.0 / (a * a) - 2.0
    cos_i = np.maximum(g.cos_i, 1e-6)
    cos_o = np.maximum(g.cos_o, 1e-6)
    cos_h = np.maximum(g.cos_h, 1e-6)
    h_dot = np.maximum(g.i_dot_h, 1e-6)
    lobe = cos_i * (n + 1.0) / (8.0 * np.pi) * np.power(cos_h, n) / np.maximum(1e-6, h_dot * np.maximum(cos_i, cos_o))
    return np.where(alpha <= 1e-4, 0.0, lobe)


def diffuse(p, opt, g):
    return p["Color"] * g.lambert


#: model id -> evaluator
EVALUATORS = {GLOSSY.id: glossy, DIFFUSE.id: diffuse}
