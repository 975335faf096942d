"""Renderer dialects emulated by the embedded renderer, one module per renderer family.

Each module declares its models as :class:`~matremap.core.models.ModelSpec` data and, with
:func:`dialect`, the numpy function that evaluates f * cos(theta_light) for a batch. Importing
this package registers them all.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

import numpy as np

from matremap.core.models import ModelSpec, register
from matremap.renderers.embedded.geometry import LocalGeometry

#: f(params, options, geometry) -> f * cos(theta_i); params are [N, C, 1, 1] (C = 1 or 3 channels),
#: geometry arrays [L, P] (lights, pixels), the result broadcasts to [N, C, L, P]
Evaluator = Callable[[Mapping[str, np.ndarray], Mapping[str, str], LocalGeometry], np.ndarray]

EVALUATORS: dict[str, Evaluator] = {}


def dialect(spec: ModelSpec) -> Callable[[Evaluator], Evaluator]:
    """Register ``spec`` and the function that evaluates it in the embedded renderer."""

    def wrap(fn: Evaluator) -> Evaluator:
        register(spec)
        EVALUATORS[spec.id] = fn
        return fn

    return wrap


def energy_clamp(rho_s: np.ndarray, rho_d: np.ndarray) -> np.ndarray:
    """Mitsuba 0.6 ``BSDF::ensureEnergyConservation`` (``src/librender/bsdf.cpp``): when the largest
    per-channel sum rho_s + rho_d exceeds 1, both are scaled by 0.99 / (that sum).
    Returns the scale factor, broadcastable to the inputs."""
    total = np.max(rho_s + rho_d, axis=1, keepdims=True)  # parameters are [N, C, 1, 1]
    return np.where(total > 1.0, 0.99 / np.maximum(total, 1e-300), 1.0)


from matremap.renderers.embedded.evaluators import blender27, cycles, gltf, mitsuba06  # noqa: E402,F401  (registration)
