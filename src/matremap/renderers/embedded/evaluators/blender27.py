"""The embedded renderer's evaluators of the blender27 dialect: f * cos(theta_i) of each model of
:mod:`matremap.dialects.blender27` (its model table, the formulas and their sources are there), as numpy
functions of [N, C, L, P] arrays, zero where either cosine is <= 0 (the renderer masks that).
"""

from __future__ import annotations

import numpy as np

from matremap.dialects.blender27 import WARD


def ward(p, opt, g):
    alpha = np.maximum(p["specular_slope"], 0.001)
    a2 = alpha * alpha
    s = g.cos_i * np.exp(-g.tan2_h / a2) / (4.0 * np.pi * a2 * np.sqrt(g.cos_o * g.cos_i))
    spec = (p["specular_intensity"] * p["specular_color"]) * s
    return spec + (p["diffuse_intensity"] * p["diffuse_color"]) * g.cos_i


#: model id -> evaluator
EVALUATORS = {WARD.id: ward}
