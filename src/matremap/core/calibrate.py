"""Irradiance matching between renderers (paper §4).

Renderers disagree on what a light of given settings delivers (Blender Internal's Lambert has no
1/pi, Blender lights are given in watts, Mitsuba's in W/sr). Before remapping across renderers the
source images are multiplied by one global scale: the least-squares ratio of the renders of a white
Lambertian reference material in each renderer (each family names its reference, see
:func:`matremap.core.models.white_reference`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from matremap.core.models import Material, white_reference
from matremap.core.scene import Scene
from matremap.errors import MatremapError
from matremap.renderers.base import Renderer


def renderer_key(renderer: Renderer, material: Material) -> tuple[str, str]:
    """What identifies 'a renderer' for irradiance: the backend and the model family it emulates."""
    return (renderer.name, material.spec.family)


def irradiance_scale(
    source: Material,
    source_renderer: Renderer,
    target_model: str,
    target_renderer: Renderer,
    scene: Scene,
    render: Callable[[Renderer, list[Material]], np.ndarray] | None = None,
) -> float:
    """Factor s such that s * (source render) is in the target renderer's irradiance units.

    1.0 when source and target are the same renderer and family. ``render`` lets the caller count
    renders; it defaults to the renderer's own ``render``.
    """
    target_family = target_model.split(":", 1)[0]
    if renderer_key(source_renderer, source) == (target_renderer.name, target_family):
        return 1.0
    render = render or (lambda r, ms: r.render(ms, scene))
    mask = scene.mask()
    src = render(source_renderer, [white_reference(source.spec.family)])[0][mask].astype(float)
    tgt = render(target_renderer, [white_reference(target_family)])[0][mask].astype(float)
    denom = float(np.sum(src * src))
    if not denom > 0:
        raise MatremapError(
            f"irradiance matching failed: the white reference of {source.spec.family} renders black in "
            f"{source_renderer.name}; check that the scene's lights reach the sphere"
        )
    return float(np.sum(src * tgt) / denom)
