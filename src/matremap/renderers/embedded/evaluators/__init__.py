"""The embedded renderer's evaluators, one module per emulated renderer family.

Each module evaluates the models of the dialect of the same name (:mod:`matremap.dialects`; the model
tables and the formulas' sources are there) and lists them in ``EVALUATORS``: model id -> a numpy
function ``f(params, options, geometry)`` returning f * cos(theta_light) for a batch, with params
[N, C, 1, 1] (C = 1 or 3 channels) and geometry arrays [L, P] (lights, pixels).
"""

from __future__ import annotations

from matremap.renderers.embedded.evaluators import (
    blender27,
    cycles,
    gltf,
    mitsuba06,
    mitsuba3,
    openpbr,
    principled,
    standard_surface,
    usd,
)
from matremap.renderers.embedded.geometry import Evaluator

#: every model the embedded renderer draws: model id -> evaluator
EVALUATORS: dict[str, Evaluator] = {
    **mitsuba06.EVALUATORS,
    **mitsuba3.EVALUATORS,
    **blender27.EVALUATORS,
    **cycles.EVALUATORS,
    **principled.EVALUATORS,
    **gltf.EVALUATORS,
    **usd.EVALUATORS,
    **openpbr.EVALUATORS,
    **standard_surface.EVALUATORS,
}

#: the models whose evaluator reads the shading frame (``LocalGeometry.frame``): the others are spared computing it
FRAMED = mitsuba3.FRAMED

__all__ = ["EVALUATORS", "FRAMED", "Evaluator"]
