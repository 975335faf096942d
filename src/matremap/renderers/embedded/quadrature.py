"""Gauss-Legendre quadrature on [0, 1], computed once per rule size.

NumPy's ``leggauss`` solves for the nodes of an n-point rule (the eigenvalues of its Jacobi matrix, Golub and Welsch
1969) at every call: about 1 ms at n = 64, and the embedded renderer's layered evaluators asked for the same rules
at every render (13 % of a glass fit onto OpenPBR went there). The rules here are cached and read-only.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np


@lru_cache(maxsize=64)
def unit(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Nodes and weights of the n-point Gauss-Legendre rule on [0, 1]."""
    x, w = np.polynomial.legendre.leggauss(n)
    return _frozen(0.5 * (x + 1.0)), _frozen(0.5 * w)


@lru_cache(maxsize=64)
def smoothstep(n: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`unit` pushed through x -> 3x^2 - 2x^3, whose zero slope at both ends absorbs the square-root
    behaviour of an integrand at its panel's ends."""
    x, w = unit(n)
    return _frozen(x * x * (3.0 - 2.0 * x)), _frozen(6.0 * x * (1.0 - x) * w)


def _frozen(a: np.ndarray) -> np.ndarray:
    a.flags.writeable = False
    return a
