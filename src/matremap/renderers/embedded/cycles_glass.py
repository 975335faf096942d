"""Cycles' albedo tables of its GGX glass closure, which its Multiscatter GGX energy compensation of the
Principled BSDF's transmission reads (Blender 5.0 ``intern/cycles``).

``kernel/closure/bsdf_microfacet.h`` ``microfacet_ggx_preserve_energy`` on a ``CLOSURE_BSDF_MICROFACET_GGX_GLASS_ID``
closure reads E(r, mu, z) from the 16 x 16 x 16 table ``ggx_glass_E`` (``lookup_table_read_3D``: linear in r, then
mu, then z) and E_avg(r, z) from the 16 x 16 table ``ggx_glass_Eavg`` (``lookup_table_read_2D``), with r =
sqrt(alpha) the roughness, mu the cosine of the view and z = sqrt((ior - 1)/(ior + 1)) (an IOR below 1 reads the
``_inv`` tables, not needed from the front face). ``app/cycles_precompute.cpp`` fills them, for r = i/15 (clamped to
[1e-4, 1]), mu = j/15 (clamped to [1e-4, 1]) and ior = ior_from_F0(clamp(k/15, 1e-4, 0.99)^4), with the Monte Carlo
mean of eval / pdf of ``bsdf_microfacet_sample`` on a white glass closure (real dielectric Fresnel), clamped to
[0, 1]; E_avg is the mean of 2 mu E over mu uniform in [0, 1]. With VNDF sampling and the choice of reflection
with probability F, that mean is

  E = mean over visible normals m of  F(o.m) (1 + L(o)) / (1 + L(o) + L(r)) [r above the surface]
                                    + (1 - F(o.m)) (1 + L(o)) / (1 + L(o) + L(t)) [t below it]

with r and t the view reflected and refracted about m and L Smith's GGX Lambda; from outside (ior >= 1) the
refracted direction is always below the surface. A closure Cycles treats as specular (alpha^2 at or below
``BSDF_ROUGHNESS_SQ_THRESH``, or an IOR within 1e-4 of 1, which float32 makes the k = 0 plane) returns eval / pdf
= 1. Here each node is integrated numerically (:func:`glass_albedo_exact`) in the parametrisation of
:func:`~matremap.renderers.embedded.evaluators.principled.visible_normal_mean`, split where the integrand jumps
(the reflection's horizon) or kinks (back-facing normals); the tables are cached like Cycles' other tables
(:mod:`matremap.core.diskcache`).
"""

from __future__ import annotations

import functools
import hashlib
import json
from pathlib import Path

import numpy as np

from matremap.core.diskcache import cache_dir, load_tables, save_tables
from matremap.core.optics import fresnel_dielectric, ior_from_f0
from matremap.renderers.embedded import quadrature

#: nodes per axis of ``ggx_glass_E`` (roughness, cos_view, z) and ``ggx_glass_Eavg`` (roughness, z)
GLASS_NODES = 16
#: Cycles' ``BSDF_ROUGHNESS_SQ_THRESH``: alpha^2 at or below is a specular closure
SPECULAR_ALPHA2 = 2e-10

_TABLE_FORMAT = 1
_QUAD = (40, 40)
_MU_NODES = 48


def _lambda(cos2, a2) -> np.ndarray:
    """Smith's GGX Lambda of a direction at cos^2 theta = ``cos2`` (either side of the surface)."""
    cos2 = np.maximum(cos2, 1e-300)
    return 0.5 * (np.sqrt(1.0 + a2 * np.maximum(1.0 / cos2 - 1.0, 0.0)) - 1.0)


def _panels(u_breaks: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Quadrature nodes and weights [N, k n, 1] in u over the panels between consecutive ``u_breaks``
    [N, ..., k + 1]."""
    xs, ws = quadrature.smoothstep(n)
    u_breaks = u_breaks.reshape(len(u_breaks), -1)
    lo, hi = u_breaks[:, :-1, None], u_breaks[:, 1:, None]
    u = lo + (hi - lo) * xs
    w = (hi - lo) * ws
    return u.reshape(len(u), -1, 1), w.reshape(len(w), -1, 1)


def glass_albedo_exact(mu, rough, eta, quad: tuple[int, int] | None = None) -> np.ndarray:
    """Long: the two integrals (refraction over every facing normal, reflection where it stays above the
    surface) share one parametrisation and are read best together.

    E of the white GGX glass closure (see the module docstring) for a viewer at cos theta = ``mu``, alpha =
    ``rough``^2 and relative IOR ``eta`` >= 1, by quadrature; arguments broadcast (1-d result). With u =
    tan^2 theta_m / (alpha^2 + tan^2 theta_m), uniform under D cos theta_m, the mean over visible normals is
    1/pi integral over u in [0, 1), phi in [0, pi] of G1(o) max(o.m, 0) / (mu cos theta_m) w(m)."""
    n_u, n_phi = quad or _QUAD
    mu, rough, eta = np.broadcast_arrays(*(np.asarray(x, dtype=float) for x in (mu, rough, eta)))
    shape = mu.shape
    mu = np.clip(mu.reshape(-1, 1, 1), 1e-7, 1.0 - 1e-9)
    eta = np.maximum(eta.reshape(-1, 1, 1), 1.0)
    a2 = np.maximum(np.clip(rough.reshape(-1, 1, 1), 0.0, 1.0) ** 4, 1e-30)
    sin_o = np.sqrt(1.0 - mu * mu)
    lam_o = _lambda(mu * mu, a2)
    g1_o = 1.0 / (1.0 + lam_o)
    px, pw = quadrature.smoothstep(n_phi)

    def u_of(t):
        return t * t / (a2 + t * t)

    def integrate(u_breaks, phi_edge, weight):
        u, wu = _panels(u_breaks, n_u)
        tan2 = a2 * u / np.maximum(1.0 - u, 1e-300)
        t = np.sqrt(tan2)
        cos_m = 1.0 / np.sqrt(1.0 + tan2)
        sin_m = t * cos_m
        with np.errstate(divide="ignore", invalid="ignore"):
            phi_max = np.arccos(np.clip(np.where(t > 0.0, phi_edge(t), -1.0), -1.0, 1.0))
        cos_phi = np.cos(phi_max * px)
        o_m = sin_o * sin_m * cos_phi + mu * cos_m
        ok = o_m > 0.0
        c = np.where(ok, o_m, 1.0)
        f = np.where(ok, g1_o * c / (mu * cos_m) * weight(c, cos_m), 0.0)
        return np.sum(f * pw * phi_max * wu, axis=(-2, -1)) / np.pi

    def reflected(c, cos_m):
        r_z = 2.0 * c * cos_m - mu
        ratio = (1.0 + lam_o) / (1.0 + lam_o + _lambda(r_z * r_z, a2))
        return np.where(r_z > 0.0, fresnel_dielectric(c, eta) * ratio, 0.0)

    def refracted(c, cos_m):
        cos_t = np.sqrt(np.maximum(1.0 - (1.0 - c * c) / (eta * eta), 0.0))
        t_z = -mu / eta + (c / eta - cos_t) * cos_m
        ratio = (1.0 + lam_o) / (1.0 + lam_o + _lambda(t_z * t_z, a2))
        return (1.0 - fresnel_dielectric(c, eta)) * ratio

    # refraction: every facing normal; beyond tan theta_m = mu / sin_o the back-facing azimuths drop out
    t_back = mu / np.maximum(sin_o, 1e-300)
    u_back = u_of(t_back)
    through = integrate(
        np.concatenate([0.0 * u_back, u_back, 1.0 + 0.0 * u_back], axis=-1),
        lambda t: -mu / (sin_o * t),
        refracted,
    )
    # reflection: all azimuths while tan theta_m < (1 - sin_o)/mu, none beyond (1 + sin_o)/mu
    u1, u2 = u_of((1.0 - sin_o) / mu), u_of((1.0 + sin_o) / mu)
    back = integrate(
        np.concatenate([0.0 * u1, u1, u2], axis=-1),
        lambda t: mu * (t * t - 1.0) / (2.0 * sin_o * t),
        reflected,
    )
    e = through + back
    specular = ((a2 <= SPECULAR_ALPHA2) | (np.abs(eta - 1.0) < 1e-4)).reshape(-1)
    return np.where(specular, 1.0, e).reshape(shape)


def _nodes() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cycles' table nodes: roughness, cos_view and the IOR of each z node."""
    n = GLASS_NODES
    x = np.arange(n) / (n - 1)
    ior = ior_from_f0(np.clip(x, 1e-4, 0.99) ** 4)
    ior = np.where(np.float32(ior) == np.float32(1.0), 1.0, ior)  # Cycles works in float32
    return np.clip(x, 1e-4, 1.0), np.clip(x, 1e-4, 1.0), ior


def _build() -> tuple[np.ndarray, np.ndarray]:
    """The tables E [z, mu, r] and E_avg [z, r]."""
    rough, mus, iors = _nodes()
    n = GLASS_NODES
    xs, ws = quadrature.smoothstep(_MU_NODES)
    e = np.zeros((n, n, n))
    e_avg = np.zeros((n, n))
    for k, ior in enumerate(iors):
        mu_grid, r_grid = np.meshgrid(mus, rough, indexing="ij")
        e[k] = glass_albedo_exact(mu_grid, r_grid, ior)
        m_grid, r2 = np.meshgrid(xs, rough, indexing="ij")
        e_mu = glass_albedo_exact(m_grid, r2, ior)
        e_avg[k] = np.sum(2.0 * xs[:, None] * e_mu * ws[:, None], axis=0)
    return np.clip(e, 0.0, 1.0), np.clip(e_avg, 0.0, 1.0)


def _spec() -> str:
    return json.dumps({"format": _TABLE_FORMAT, "nodes": GLASS_NODES, "quad": _QUAD, "mu": _MU_NODES}, sort_keys=True)


def _path() -> Path:
    return cache_dir() / f"cycles_ggx_glass_E_{hashlib.sha256(_spec().encode()).hexdigest()[:12]}.npz"


@functools.cache
def glass_tables() -> tuple[np.ndarray, np.ndarray]:
    """(``ggx_glass_E`` [z, mu, r], ``ggx_glass_Eavg`` [z, r]) on Cycles' nodes, from the cache or built (a few
    seconds)."""
    n = GLASS_NODES
    data = load_tables(_path(), _spec(), {"e": (n, n, n), "e_avg": (n, n)})
    if data is None:
        e, e_avg = _build()
        save_tables(_path(), "cycles_ggx_glass_E_*.npz", spec=np.array(_spec()), e=e, e_avg=e_avg)
    else:
        e, e_avg = data["e"], data["e_avg"]
    e.flags.writeable = False
    e_avg.flags.writeable = False
    return e, e_avg


def _lerp(x, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``lookup_table_read``'s coordinate: clamp(x, 0, 1) (n - 1); node below, node above, fraction."""
    x = np.clip(np.asarray(x, dtype=float), 0.0, 1.0) * (n - 1)
    i = np.minimum(np.floor(x).astype(np.intp), n - 1)
    return i, np.minimum(i + 1, n - 1), x - i


def _z(eta) -> np.ndarray:
    eta = np.asarray(eta, dtype=float)
    return np.sqrt(np.abs((eta - 1.0) / (eta + 1.0)))


def glass_albedo(rough, mu, eta) -> np.ndarray:
    """E read as ``lookup_table_read_3D(rough, mu, z)`` does (linear in roughness, then mu, then z)."""
    e, _ = glass_tables()
    n = GLASS_NODES
    r0, r1, tr = _lerp(rough, n)
    m0, m1, tm = _lerp(mu, n)
    z0, z1, tz = _lerp(_z(eta), n)

    def plane(k):
        def row(m):
            return (1.0 - tr) * e[k, m, r0] + tr * e[k, m, r1]

        return (1.0 - tm) * row(m0) + tm * row(m1)

    return (1.0 - tz) * plane(z0) + tz * plane(z1)


def glass_average_albedo(rough, eta) -> np.ndarray:
    """E_avg read as ``lookup_table_read_2D(rough, z)`` does (linear in roughness, then z)."""
    _, e_avg = glass_tables()
    n = GLASS_NODES
    r0, r1, tr = _lerp(rough, n)
    z0, z1, tz = _lerp(_z(eta), n)

    def row(k):
        return (1.0 - tr) * e_avg[k, r0] + tr * e_avg[k, r1]

    return (1.0 - tz) * row(z0) + tz * row(z1)


def glass_multiscatter_scale(fss, rough, mu, eta) -> np.ndarray:
    """What ``microfacet_ggx_preserve_energy`` puts on a glass closure: 1 + F_ms (1 - E)/E, F_ms = Fss E_avg /
    (1 - Fss (1 - E_avg)) (energy_scale times the darkening folded into its weight)."""
    e = glass_albedo(rough, mu, eta)
    e_avg = glass_average_albedo(rough, eta)
    fss = np.asarray(fss, dtype=float)
    f_ms = fss * e_avg / (1.0 - fss * (1.0 - e_avg))
    return 1.0 + f_ms * (1.0 - e) / e


__all__ = [
    "GLASS_NODES",
    "glass_albedo",
    "glass_albedo_exact",
    "glass_average_albedo",
    "glass_multiscatter_scale",
    "glass_tables",
]
