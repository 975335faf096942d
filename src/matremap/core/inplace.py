"""Elementwise arithmetic written into a temporary the caller owns: the same operations in the same order (so the
same numbers) with fewer allocations, for the embedded renderer's evaluators, whose arrays are a probe's pixels
(a fit on the embedded renderer spends a third of its time in them)."""

from __future__ import annotations

from typing import Any

import numpy as np


def into(ufunc: np.ufunc, a: Any, b: Any) -> Any:
    """``ufunc(a, b)``, written into ``a`` when ``a`` is a float64 array that a caller made for the purpose and that
    already has the result's shape (so overwriting it changes nothing else), else a new array."""
    if type(a) is np.ndarray and a.ndim and a.dtype == np.float64:
        if not isinstance(b, np.ndarray) or (b.dtype == np.float64 and b.ndim <= a.ndim and b.size <= a.size):
            try:
                return ufunc(a, b, out=a)
            except ValueError:  # b broadcasts ``a`` to a larger shape
                pass
    return ufunc(a, b)


__all__ = ["into"]
