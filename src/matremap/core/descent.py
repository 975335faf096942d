"""Bounded nonlinear least squares in ask/tell form: Levenberg-Marquardt inside a box.

minimise 0.5 ||r(x)||^2 subject to lower <= x <= upper, where r and its Jacobian come from renders, so
they are generators (:mod:`matremap.core.lockstep`): ``residual(x)`` and ``jacobian(x)`` yield render
requests and return arrays. The descent is itself a generator and returns a :class:`Descent`.

The method is Levenberg-Marquardt (Moré, "The Levenberg-Marquardt algorithm: implementation and
theory", Numerical Analysis, LNM 630, 1978) on the normal equations, with

* Marquardt's scaling by the Jacobian's column norms, kept at their running maximum (MINPACK's ``mode 1``,
  the ``x_scale="jac"`` of SciPy's ``least_squares``), so that a parameter's step follows its scale;
* Marquardt's damping update with a gain ratio rho (actual / predicted reduction): lambda / 10 after a
  step with rho > 3/4, times 2 for rho < 1/4, times 10 after a step that does not reduce the cost;
* a step limit per variable (``limit(x)``, e.g. a fraction of the parameter's value): a longer step is
  shortened along its direction, so the first Gauss-Newton step of a curved problem cannot leap across
  the box (a trust region of box shape, doubled after a shortened step that went well, halved after a
  rejected one); a step that would be shortened below :data:`CLIP_BELOW` of itself is instead clipped per
  component: a huge step along a flat direction (a coat colour under a coat of weight 0) would otherwise
  leave every other variable where it was;
* bounds by projection: a variable on its bound whose gradient points outwards is held for the step, and a
  step is clipped into the box (the model's predicted reduction is taken for the clipped step);
* MINPACK's stopping rules: the relative reduction of the cost below ``tol`` (``ftol``), a step below
  ``tol`` relative to x (``xtol``), or every scaled gradient component below ``tol`` times ||r|| (``gtol``,
  the cosine of the angle between the residual and each Jacobian column).

The problems here have 1-7 unknowns and tens of thousands of residuals: the normal equations cost one
pass over the Jacobian, the solves are on n x n matrices. Compared with SciPy's ``least_squares(method="trf")``
(which this replaces) it reaches the same minima (same tolerance 1e-4, see ``tests/test_lockstep.py``)
without an SVD of the Jacobian per iteration, and it can be suspended between renders.
"""

from __future__ import annotations

from collections.abc import Callable, Generator
from dataclasses import dataclass
from typing import Any

import numpy as np

#: a step the box would shorten below this fraction of itself is clipped per component instead (see
#: :func:`descend`): measured on a coloured cycles:glossy -> mitsuba06:pbr simple fit (41 renders, as with
#: scaling alone; clipping always: 139.5) and OpenPBR coated copper onto Standard Surface with the coat freed
#: (0.0117, coat 1.00; scaling alone stalls at 0.52; clipping always 0.019, coat 0.81; SciPy's TRF 0.0114)
CLIP_BELOW = 0.1

Ask = Generator[Any, Any, np.ndarray]


@dataclass
class Descent:
    """The end of a descent: the solution, 0.5 ||r||^2 there, residual evaluations made and why it stopped."""

    x: np.ndarray
    cost: float
    evaluations: int
    message: str


def descend(
    residual: Callable[[np.ndarray], Ask],
    jacobian: Callable[[np.ndarray], Ask],
    x0: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    tol: float = 1e-4,
    max_evaluations: int = 50,
    exact: float = 1e-6,
    limit: Callable[[np.ndarray], np.ndarray] | None = None,
) -> Generator[Any, Any, Descent]:
    """Long: the Levenberg-Marquardt loop with its stopping rules reads best in one piece.

    Minimise 0.5 ||residual(x)||^2 in the box from ``x0`` (see the module docstring). ``jacobian(x)`` is only
    asked at points whose residual was just evaluated. A residual norm below ``exact`` stops at once."""
    x = np.clip(np.asarray(x0, dtype=float), lower, upper)
    r = yield from residual(x)
    cost = 0.5 * float(r @ r)
    evaluations = 1
    if np.sqrt(2.0 * cost) < exact:
        return Descent(x, cost, evaluations, "the start matches exactly")
    scale = np.zeros_like(x)
    lam, radius = 1e-3, 1.0
    while True:
        jac = yield from jacobian(x)
        g = jac.T @ r
        h = jac.T @ jac
        scale = np.maximum(scale, np.sqrt(np.diag(h)))
        d = np.where(scale > 0, scale, 1.0)
        held = ((x <= lower) & (g > 0)) | ((x >= upper) & (g < 0))
        free = ~held
        if not np.any(free) or np.max(np.abs(g[free]) / d[free]) <= tol * np.sqrt(2.0 * cost):
            return Descent(x, cost, evaluations, "gtol: the gradient vanishes (in the box)")
        while True:
            step = np.zeros_like(x)
            hf = h[np.ix_(free, free)] + lam * np.diag(d[free] ** 2)
            try:
                step[free] = np.linalg.solve(hf, -g[free])
            except np.linalg.LinAlgError:
                step[free] = -g[free] / (lam * d[free] ** 2)
            shortened = 1.0
            if limit is not None:
                # the box: a step past it is scaled back as a whole (it keeps the LM direction), unless that would
                # shrink it below CLIP_BELOW of itself -- a Gauss-Newton step along a flat direction (a coat colour
                # under a coat of weight 0) is huge, and scaling by it left every other variable still (stalled at
                # 0.49 where SciPy's TRF reached 0.011) -- then each component is clipped to its own limit.
                # Clipping every long step bent the direction of ordinary ones: a coloured glossy -> pbr simple
                # fit took 139.5 renders instead of 41
                bound = radius * limit(x)
                shortened = min(1.0, float(np.min(bound / np.maximum(np.abs(step), 1e-300))))
                step = np.clip(step, -bound, bound) if shortened < CLIP_BELOW else step * shortened
            x_new = np.clip(x + step, lower, upper)
            step = x_new - x
            small_step = np.linalg.norm(step) <= tol * (tol + np.linalg.norm(x))
            predicted = -(g @ step + 0.5 * step @ h @ step)
            if not np.any(step) or (small_step and predicted <= 0):
                return Descent(x, cost, evaluations, "xtol: the step vanishes")
            r_new = yield from residual(x_new)
            evaluations += 1
            cost_new = 0.5 * float(r_new @ r_new)
            actual = cost - cost_new
            rho = actual / predicted if predicted > 0 else -1.0
            if actual > 0 and rho > 1e-4:
                x, r, cost_old, cost = x_new, r_new, cost, cost_new
                lam = max(lam / 10.0, 1e-12) if rho > 0.75 else lam * 2.0 if rho < 0.25 else lam
                radius = radius * 2.0 if (rho > 0.75 and shortened < 1.0) else radius
                if np.sqrt(2.0 * cost) < exact:
                    return Descent(x, cost, evaluations, "the images match exactly")
                if actual <= tol * cost_old:
                    return Descent(x, cost, evaluations, "ftol: the cost no longer decreases")
                if small_step:
                    return Descent(x, cost, evaluations, "xtol: the step vanishes")
                break
            if small_step:
                return Descent(x, cost, evaluations, "xtol: the step vanishes")
            lam *= 10.0
            radius *= 0.5
            if evaluations >= max_evaluations:
                return Descent(x, cost, evaluations, "the evaluation limit is reached")
        if evaluations >= max_evaluations:
            return Descent(x, cost, evaluations, "the evaluation limit is reached")


__all__ = ["Descent", "descend"]
