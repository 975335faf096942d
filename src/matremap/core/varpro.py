"""The linear half of a separable least-squares fit (variable projection).

A probe image that is affine in some parameters, image = C + sum_j theta_j B_j (C and B_j depending on
the other, nonlinear parameters only), is fitted by solving theta in closed form for each trial of the
nonlinear ones and descending on the nonlinear ones alone (Golub & Pereyra, "The differentiation of
pseudo-inverses and nonlinear least squares problems whose variables separate", SIAM J. Numer. Anal.
10(2), 1973). The descent uses Kaufman's approximation of the reduced Jacobian, the partial derivative
at fixed theta projected off the span of the B_j (Kaufman, "A variable projection method for solving
separable nonlinear least squares problems", BIT 15, 1975): one render per nonlinear variable, as a plain
fit needs.

Here theta lives in a box (the parameters' bounds) and, for models that rescale their reflectances when
they sum above a limit (Mitsuba 0.6's energy conservation), under a per-channel sum limit.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Unknown:
    """One unknown of theta: parameter ``param`` (index into the linear parameters), image channel
    ``channel`` (None: a scalar parameter that scales every channel)."""

    param: int
    channel: int | None


def unknowns(channels: Sequence[int], image_channels: int) -> list[Unknown]:
    """The unknowns of parameters with these channel counts, for images of ``image_channels`` channels
    (1 in grey mode: one unknown per parameter)."""
    out = []
    for j, c in enumerate(channels):
        if c == 3 and image_channels == 3:
            out += [Unknown(j, k) for k in range(3)]
        else:
            out.append(Unknown(j, None))
    return out


def design(basis: np.ndarray, layout: Sequence[Unknown]) -> np.ndarray:
    """The design matrix [P * channels, K] of basis images ``basis`` [L, P, channels]."""
    _, pixels, ch = basis.shape
    a = np.zeros((pixels * ch, len(layout)))
    for k, u in enumerate(layout):
        if u.channel is None:
            a[:, k] = basis[u.param].ravel()
        else:
            a[u.channel :: ch, k] = basis[u.param][:, u.channel]
    return a


def sum_rows(layout: Sequence[Unknown], image_channels: int) -> np.ndarray:
    """The per-channel sums of theta as rows of a matrix G (G theta = the sums, one per channel)."""
    g = np.zeros((image_channels, len(layout)))
    for k, u in enumerate(layout):
        if u.channel is None:
            g[:, k] = 1.0
        else:
            g[u.channel, k] = 1.0
    return g


@dataclass
class AffineSolution:
    theta: np.ndarray
    #: orthonormal basis of the columns whose unknown is free (off its bounds and the sum limit)
    free_basis: np.ndarray


def solve(
    a: np.ndarray,
    b: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    sums: np.ndarray | None = None,
    limit: float | None = None,
) -> AffineSolution:
    """argmin ||a theta - b|| with lower <= theta <= upper (and sums @ theta <= limit when given)."""
    from scipy.optimize import lsq_linear

    q, r = np.linalg.qr(a)  # ||a t - b||^2 = ||r t - q^T b||^2 + const: the rest works on K x K
    qb = q.T @ b
    theta = lsq_linear(r, qb, bounds=(lower, upper), method="bvls").x if a.shape[1] else np.zeros(0)
    limited = False
    if sums is not None and limit is not None and np.any(sums @ theta > limit):
        theta, limited = _limited(r, qb, lower, upper, sums, limit, theta), True
    free = (theta > lower + 1e-9) & (theta < upper - 1e-9)
    basis = np.zeros((a.shape[0], 0)) if limited or not np.any(free) else np.linalg.qr(a[:, free])[0]
    return AffineSolution(theta, basis)


def _limited(
    r: np.ndarray,
    qb: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    sums: np.ndarray,
    limit: float,
    start: np.ndarray,
) -> np.ndarray:
    """The box- and sum-constrained minimum (a K-variable quadratic programme, SLSQP)."""
    from scipy.optimize import minimize

    h, g = r.T @ r, r.T @ qb
    x0 = start * min(1.0, limit / max(float(np.max(sums @ start)), 1e-300))
    res = minimize(
        lambda t: float(t @ h @ t - 2.0 * g @ t),
        np.clip(x0, lower, upper),
        jac=lambda t: 2.0 * (h @ t - g),
        bounds=list(zip(lower, upper, strict=True)),
        constraints=[{"type": "ineq", "fun": lambda t: limit - sums @ t, "jac": lambda t: -sums}],
        method="SLSQP",
        options={"ftol": 1e-12, "maxiter": 100},
    )
    return np.clip(res.x, lower, upper)


def project_out(jac: np.ndarray, free_basis: np.ndarray) -> np.ndarray:
    """Kaufman's reduced Jacobian: ``jac`` with its component in the span of ``free_basis`` removed."""
    if free_basis.shape[1] == 0:
        return jac
    return jac - free_basis @ (free_basis.T @ jac)
