"""Irradiance matching between renderers (paper §4).

Renderers disagree on what a light of given settings delivers (Blender Internal's Lambert has no
1/pi, Blender lights are given in watts, Mitsuba's in W/sr). Before remapping across renderers the
source images are multiplied by one global scale: the least-squares ratio of the renders of a white
Lambertian reference material in each renderer family (each dialect names its reference, see
:func:`matremap.core.material.white_reference`).

One rule decides when no scaling is needed, for the probe and for environment renders alike: the
units belong to the renderer family, and the embedded renderer draws each family it emulates in that
family's units (its Cycles emulation is 5e-7 from real Cycles on the probe; its Mitsuba 0.6 diffuse
agrees with Mitsuba 3 to 1e-5), so two models of one family are never rescaled.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from matremap.core.material import Material, white_reference
from matremap.core.scene import Scene
from matremap.dialects import get_model
from matremap.errors import MatremapError
from matremap.renderers.base import Renderer, render_pixels


def same_units(source_model: str, target_model: str) -> bool:
    """Whether renders of the two models need no irradiance scaling: they share a renderer family."""
    return get_model(source_model).family == get_model(target_model).family


def irradiance_ratio(source_white: np.ndarray, target_white: np.ndarray, where: str) -> float:
    """Least-squares s with s * source_white ~ target_white (renders of the white references);
    ``where`` names the source for the error when its reference renders black."""
    src, tgt = np.asarray(source_white, dtype=float), np.asarray(target_white, dtype=float)
    denom = float(np.sum(src * src))
    if not denom > 0:
        raise MatremapError(
            f"irradiance matching failed: the white reference of {where} renders black; "
            "check that the lights reach the sphere"
        )
    return float(np.sum(src * tgt) / denom)


def irradiance_scale(
    source: Material,
    source_renderer: Renderer,
    target_model: str,
    target_renderer: Renderer,
    scene: Scene,
    render: Callable[[Renderer, list[Material]], np.ndarray] | None = None,
) -> float:
    """Factor s such that s * (source probe render) is in the target's irradiance units.

    1.0 when source and target share a renderer family (:func:`same_units`). ``render`` (the sphere pixels
    of a batch, as :func:`~matremap.renderers.base.render_pixels` draws them) lets the caller count renders.
    """
    if same_units(source.model, target_model):
        return 1.0
    render = render or (lambda r, ms: render_pixels(r, ms, scene))
    source_family, target_family = source.spec.family, get_model(target_model).family
    src = render(source_renderer, [white_reference(source_family)])[0]
    tgt = render(target_renderer, [white_reference(target_family)])[0]
    return irradiance_ratio(src, tgt, f"{source_family} in {source_renderer.name}")


__all__ = ["irradiance_ratio", "irradiance_scale", "same_units"]
