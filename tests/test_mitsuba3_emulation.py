"""The embedded emulation of Mitsuba 3's diffuse and roughconductor (named conductors included) against the
real Mitsuba 3: fits onto them need no Mitsuba, and the real renderer agrees (skips without Mitsuba)."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest

from matremap.core.material import Material
from matremap.core.scene import Scene
from matremap.dialects.mitsuba3 import CONDUCTORS
from matremap.dialects.mitsuba3_conductors import CONDUCTOR_RGB
from matremap.renderers import get_renderer, renderer_for
from matremap.uniform import fit

HAS_MITSUBA = importlib.util.find_spec("mitsuba") is not None


def relative_rmse(a: np.ndarray, b: np.ndarray, mask: np.ndarray) -> float:
    return float(np.linalg.norm(a[mask] - b[mask]) / np.linalg.norm(b[mask]))


def test_the_embedded_renderer_draws_them_and_knows_every_named_conductor():
    assert renderer_for("mitsuba3:diffuse") == "embedded" and renderer_for("mitsuba3:roughconductor") == "embedded"
    assert renderer_for("mitsuba3:roughplastic") == "mitsuba3"  # Mitsuba 3's own plastic is not emulated
    assert set(CONDUCTOR_RGB) == set(CONDUCTORS) - {"none"}
    scene = Scene.probe([0.0], resolution=32)
    gold, mirror = get_renderer("embedded").render(
        [
            Material.create("mitsuba3:roughconductor", {"material": "Au", "alpha": 0.3}),
            Material.create("mitsuba3:roughconductor", {"material": "none", "alpha": 0.3}),
        ],
        scene,
    )
    m = scene.mask()
    assert gold[m][:, 0].mean() > 1.5 * gold[m][:, 2].mean()  # gold is yellow
    assert np.all(mirror[m] >= gold[m] - 1e-6)  # a perfect mirror reflects at least as much


def test_a_fit_onto_mitsuba3_conductor_needs_no_mitsuba():
    source = Material.create("mitsuba06:roughconductor", {"alpha": 0.2, "eta": [0.2, 0.9, 1.1], "k": [3.9, 2.4, 2.1]})
    r = fit(source, "mitsuba3:roughconductor", fix={"distribution": "beckmann"}, free=["eta"])
    assert r.target_renderer == "embedded" and r.loss < 0.01


@pytest.mark.skipif(not HAS_MITSUBA, reason="Mitsuba 3 not installed: pip install 'matremap[mitsuba]'")
def test_the_emulation_matches_the_real_mitsuba_3():
    from matremap.renderers.mitsuba3.probe import Mitsuba3Renderer

    real, embedded = Mitsuba3Renderer(), get_renderer("embedded")
    scene = Scene.probe([0.0, 45.0], resolution=64)
    materials = [Material.create("mitsuba3:diffuse", {"reflectance": [0.7, 0.4, 0.2]})]
    for distribution in ("beckmann", "ggx"):
        for alpha in (0.05, 0.3, 0.8):
            materials.append(
                Material.create(
                    "mitsuba3:roughconductor",
                    {"distribution": distribution, "alpha": alpha, "eta": [0.2, 0.9, 1.1], "k": [3.9, 2.4, 2.1]},
                )
            )
    for name in ("Au", "Cu", "Al", "Cr", "none"):
        materials.append(Material.create("mitsuba3:roughconductor", {"material": name, "alpha": 0.2}))
    ours, theirs = embedded.render(materials, scene), real.render(materials, scene)
    for m, a, b in zip(materials, ours, theirs, strict=True):
        assert relative_rmse(a, b, scene.mask()) < 2e-3, m.to_dict()
