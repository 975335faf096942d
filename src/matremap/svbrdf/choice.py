"""Choosing between transforms fitted under different probes, for the light the result will be seen in.

The transform library holds transforms fitted under the paper's point-light probe and under an environment
probe (issue 18). Which one gives the remapped maps the closer look depends on the light they are seen in:
fitted under an environment, a Ward -> Ashikhmin-Shirley transform gives up highlight energy that the
point light would keep, to match what the environment's grazing lights show, which is right under that
environment and wrong under another (``benchmarks/ssim_floor.py``). So :func:`best_transform` measures each
candidate where the result will be judged: a few of the maps' own texels, as uniform materials, drawn with
the source and with each candidate's output under the evaluation's environment map -- at rotations and
light samples of their own (:data:`~matremap.core.scene.FIT_ROTATIONS`, seed
:data:`~matremap.core.scene.FIT_SEED`), not the evaluation's, so that the choice is not made on the views
that then judge it -- and keeps the one with the lowest mean 1 - SSIM (:mod:`matremap.core.objective`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from matremap.core.calibrate import irradiance_scale
from matremap.core.material import Material
from matremap.core.objective import make as make_objective
from matremap.core.scene import EnvironmentProbe, Scene
from matremap.regress.transform import Transform
from matremap.renderers.base import render_pixels
from matremap.renderers.registry import get_renderer, renderer_for

#: texels drawn to compare candidates (the median texel and this many others, at random)
TEXELS = 7
#: the side of the comparison's views
RESOLUTION = 64


@dataclass(frozen=True)
class Choice:
    """The index of the chosen candidate and each candidate's mean 1 - SSIM."""

    index: int
    scores: list[float]


def texel_materials(model: str, options: Mapping[str, Any], params: Mapping[str, Any], count: int = TEXELS) -> dict:
    """``count`` texels of the maps ``params`` (arrays [h, w] or [h, w, 3], or constants) as parameter arrays
    [count (+1), ...]: the per-parameter median first, then texels drawn at random (seed 0)."""
    from matremap.dialects import get_model

    spec = get_model(model)
    arrays = {k: np.asarray(v, dtype=float) for k, v in params.items() if k in spec.param_names}
    maps = {k: a for k, a in arrays.items() if a.ndim >= 2}
    n = min(int(np.prod(a.shape[:2])) for a in maps.values()) if maps else 1
    pick = np.random.default_rng(0).choice(n, size=min(count, n), replace=False)
    out = {}
    for k, a in arrays.items():
        if a.ndim >= 2:
            flat = a.reshape(-1, *a.shape[2:])[:n]
            out[k] = np.concatenate([np.median(flat, axis=0)[None], flat[pick]])
        else:
            out[k] = np.broadcast_to(a, (len(pick) + 1, *a.shape)).copy()
    return out


def best_transform(
    candidates: Sequence[Transform],
    model: str,
    options: Mapping[str, Any],
    params: Mapping[str, Any],
    envmap: str,
    target_renderer: str | None = None,
) -> Choice:
    """Score each candidate transform of the maps ``params`` (of ``model`` with ``options``) under ``envmap``
    (see the module docstring) and choose the best."""
    scene = Scene(resolution=RESOLUTION, lights=(), environment=EnvironmentProbe.of(envmap))
    texels = texel_materials(model, options, params)
    count = len(next(iter(texels.values())))
    sources = [Material.create(model, {**options, **{k: v[i] for k, v in texels.items()}}) for i in range(count)]
    src_r = get_renderer(renderer_for(model))
    goals = render_pixels(src_r, sources, scene).astype(np.float64)
    scores = []
    for t in candidates:
        values, _ = t.apply(texels)
        targets = [
            Material.create(t.target, {**t.target_options, **{k: np.asarray(v)[i] for k, v in values.items()}})
            for i in range(count)
        ]
        tgt_r = get_renderer(target_renderer or renderer_for(t.target))
        scale = irradiance_scale(sources[0], src_r, t.target, tgt_r, scene)
        images = render_pixels(tgt_r, targets, scene).astype(np.float64)
        per = [
            float(np.sum(make_objective("ssim", scale * g, scene).residuals(img[None]) ** 2))
            for g, img in zip(goals, images, strict=True)
        ]
        scores.append(float(np.mean(per)))
    return Choice(int(np.argmin(scores)), scores)


__all__ = ["Choice", "best_transform", "texel_materials"]
