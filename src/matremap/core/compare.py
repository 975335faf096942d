"""Pictures of results: a source | target | difference strip for a uniform fit.

Images are linear; the strip is meant for a PNG (sRGB-encoded on writing) or an EXR. The
difference panel shows |target - source| scaled so that 10 % of the source's peak is white.
"""

from __future__ import annotations

import numpy as np

from matremap.core.fit import FitResult
from matremap.renderers import get_renderer


def comparison_strip(result: FitResult, gap: int = 4) -> np.ndarray:
    """[H, 3W + 2 gap, 3] linear image: source (irradiance-matched), target, scaled difference."""
    scene = result.scene
    src = get_renderer(result.source_renderer).render([result.source], scene)[0] * result.irradiance_scale
    tgt = get_renderer(result.target_renderer).render([result.target], scene)[0]
    peak = float(np.percentile(src[scene.mask()], 99.5)) or 1.0
    diff = np.abs(tgt - src) / (0.1 * peak) * peak  # 10 % of the peak reads as the peak
    h = scene.resolution
    spacer = np.full((h, gap, 3), 0.02 * peak, dtype=np.float32)
    strip = np.concatenate([src, spacer, tgt, spacer, diff.astype(np.float32)], axis=1)
    return strip / peak  # exposure: the source's 99.5th percentile at 1
