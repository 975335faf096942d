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


@dataclass
class ChannelSolution:
    """The affine optimum of a problem whose channels are independent (:func:`solve_channels`)."""

    #: [L, channels] the optimal value of each affine parameter in each image channel
    theta: np.ndarray
    #: [L, channels] whether the value is off its bounds (its column is projected out of the Jacobian)
    free: np.ndarray
    #: [L, P, channels] the basis images ([L, P, 1]: the same in every channel)
    basis: np.ndarray


def box_lsq(g: np.ndarray, h: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """argmin 0.5 t^T g t - h^T t with lower <= t <= upper, for a small positive semi-definite ``g`` (K <= 4):
    the unconstrained minimum when it is inside the box, else every split of the unknowns into free / at the
    lower bound / at the upper bound is tried and the feasible stationary points compared (3^K small
    solves; exact, no iteration)."""
    k = len(h)
    if k == 1:
        return np.clip(h / g[0, 0] if g[0, 0] > 0 else lower, lower, upper)
    try:
        t = np.linalg.solve(g, h)
        if np.all(t >= lower) and np.all(t <= upper):
            return t
    except np.linalg.LinAlgError:
        pass
    if k == 2:  # the unconstrained minimum is outside: one unknown sits on a bound, the other is clipped
        return _box_lsq_2(g, h, lower, upper)
    best, best_value = np.clip(np.zeros(k), lower, upper), np.inf
    for state in np.ndindex(*([3] * k)):
        s = np.array(state, dtype=int)
        t = np.where(s == 1, lower, upper).astype(float)
        free = s == 0
        if np.any(free):
            rhs = h[free] - g[np.ix_(free, ~free)] @ t[~free]
            gf = g[np.ix_(free, free)]
            t[free] = np.linalg.lstsq(gf, rhs, rcond=None)[0]
            if np.any(t[free] < lower[free] - 1e-12) or np.any(t[free] > upper[free] + 1e-12):
                continue
        value = 0.5 * t @ g @ t - h @ t
        if value < best_value:
            best, best_value = np.clip(t, lower, upper), value
    return best


def _box_lsq_2(g: np.ndarray, h: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """:func:`box_lsq` for two unknowns whose unconstrained minimum is outside the box: the minimum has an
    unknown on a bound, and given it the other's minimum is its 1-D minimum clipped (a convex quadratic)."""
    best, best_value = np.clip(np.zeros(2), lower, upper), np.inf
    for i in (0, 1):
        j = 1 - i
        for bound in (lower[i], upper[i]):
            t = np.empty(2)
            t[i] = bound
            t[j] = (h[j] - g[j, i] * bound) / g[j, j] if g[j, j] > 0 else lower[j]
            t[j] = min(max(t[j], lower[j]), upper[j])
            value = 0.5 * t @ g @ t - h @ t
            if value < best_value:
                best, best_value = t, value
    return best


def solve_channels(basis: np.ndarray, b: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> ChannelSolution:
    """argmin over theta of sum_c ||sum_j theta[j, c] basis[j, :, c] - b[:, c]||^2 in the box, channel by
    channel (a model whose image channel c depends on channel c of its parameters only): per channel an
    L x L Gram matrix (:func:`box_lsq`), no decomposition of the tall design. ``basis`` [L, P, 1] is the
    same in every channel of ``b`` [P, channels]."""
    n_aff, ch = basis.shape[0], b.shape[1]
    theta = np.zeros((n_aff, ch))
    if basis.shape[2] == 1:
        m = basis[..., 0]
        g, h = m @ m.T, m @ b  # [L, L], [L, channels]
        try:
            theta = np.linalg.solve(g, h)
            inside = np.all((theta >= lower[:, None]) & (theta <= upper[:, None]), axis=0)
        except np.linalg.LinAlgError:
            inside = np.zeros(ch, dtype=bool)
        for k in np.flatnonzero(~inside):
            theta[:, k] = box_lsq(g, h[:, k], lower, upper)
    else:
        for c in range(ch):
            m = basis[..., c]
            theta[:, c] = box_lsq(m @ m.T, m @ b[:, c], lower, upper)
    free = (theta > lower[:, None] + 1e-9) & (theta < upper[:, None] - 1e-9)
    return ChannelSolution(theta, free, basis)


def channel_difference(image: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """``image - offset`` for an image [P, channels] and an offset [P, channels] or [P, 1], column by column (the
    same differences; numpy broadcasts [P, 1] against [P, 3] three elements at a time, several times slower)."""
    out = np.empty(image.shape)
    for c in range(image.shape[1]):
        np.subtract(image[:, c], offset[:, min(c, offset.shape[1] - 1)], out=out[:, c])
    return out


def affine_residual(
    offset: np.ndarray, theta: np.ndarray, basis: np.ndarray, goal: np.ndarray, scale: float
) -> np.ndarray:
    """``((offset + combine_channels(theta, basis)) - goal) * scale`` [P, channels], column by column: the same
    operations in the same order (so the same numbers), without broadcasting [P, 1] against [P, 3]; one grey basis
    image is scaled per channel in place of a [P, 1] x [1, 3] matrix product (one product per element either way)."""
    single = basis.shape[0] == 1 and basis.shape[2] == 1
    combined = None if single else combine_channels(theta, basis)
    out = np.empty(goal.shape)
    for c in range(goal.shape[1]):
        col = out[:, c]
        if combined is None:
            np.multiply(basis[0, :, 0], theta[0, c], out=col)
        else:
            col[...] = combined[:, c]
        col += offset[:, min(c, offset.shape[1] - 1)]
        col -= goal[:, c]
        col *= scale
    return out


def combine_channels(theta: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """sum_j theta[j, c] basis[j, :, c] -> [P, channels] (``basis`` [L, P, 1] or [L, P, channels])."""
    if basis.shape[2] == 1:
        return basis[..., 0].T @ theta
    return np.einsum("jc,jpc->pc", theta, basis)


def project_channels(jac: np.ndarray, solution: ChannelSolution) -> np.ndarray:
    """Kaufman's reduced Jacobian for :func:`solve_channels`: the rows of channel c ([P * channels, n], pixel
    major) with their component in the span of that channel's free basis images removed."""
    basis, free = solution.basis, solution.free
    ch = free.shape[1]
    n = jac.shape[1]
    out = np.array(jac, order="C").reshape(-1, ch, n)  # [P, channels, n]
    if basis.shape[2] == 1 and all(np.array_equal(free[:, 0], free[:, c]) for c in range(ch)):
        f = free[:, 0]
        if np.any(f):
            bf = basis[f, :, 0]  # [F, P]
            flat = out.reshape(out.shape[0], ch * n)
            coef = np.linalg.solve(bf @ bf.T, bf @ flat)
            if len(bf) == 1:  # one product per element, as the [P, 1] x [1, k] matrix product, column by column
                for k in range(flat.shape[1]):
                    flat[:, k] -= bf[0] * coef[0, k]
            else:
                flat -= bf.T @ coef
        return out.reshape(-1, n)
    for c in range(ch):
        f = free[:, c]
        if not np.any(f):
            continue
        bf = basis[f, :, c if basis.shape[2] > 1 else 0]  # [F, P]
        rows = out[:, c, :]
        coef = np.linalg.lstsq(bf @ bf.T, bf @ rows, rcond=None)[0]
        out[:, c, :] = rows - bf.T @ coef
    return out.reshape(-1, n)


def project_out(jac: np.ndarray, free_basis: np.ndarray) -> np.ndarray:
    """Kaufman's reduced Jacobian: ``jac`` with its component in the span of ``free_basis`` removed."""
    if free_basis.shape[1] == 0:
        return jac
    return jac - free_basis @ (free_basis.T @ jac)
