"""The descent's step limit (core/descent.py CLIP_BELOW): a step past its box is scaled back along its direction,
and clipped per component only when a flat direction would shrink it to nothing.

Clipping every long step (5382c5e) bent ordinary Levenberg-Marquardt steps: coloured cycles:glossy -> pbr fits
with the simple strategy took 139.5 renders (median of 20) instead of 41, at a slightly worse loss; scaling alone
stalls OpenPBR coated copper onto Standard Surface with the coat freed at 0.52 (the coat colour's huge step).
"""

from __future__ import annotations

import statistics

import numpy as np

from matremap.core.material import Material
from matremap.core.scene import Scene
from matremap.uniform import fit


def test_coloured_simple_fits_take_their_lm_steps_not_bent_ones():
    rng = np.random.default_rng(0)
    sources = [
        Material.create(
            "cycles:glossy",
            {
                "Roughness": rng.uniform(0.2, 0.9),
                "Color": rng.uniform(0.1, 0.9, 3).tolist(),
                "Diffuse Color": rng.uniform(0.0, 0.5, 3).tolist(),
            },
        )
        for _ in range(6)
    ]
    scene = Scene(resolution=64)
    results = [fit(s, "mitsuba06:pbr", "simple", scene, fix={"distribution": "ggx"}) for s in sources]
    assert statistics.median(r.renders for r in results) <= 60, [r.renders for r in results]  # 139.5 when bent
    assert max(r.loss for r in results) < 0.02


def test_a_flat_coat_colour_does_not_freeze_the_other_unknowns():
    source = Material.create(
        "mtlx:open_pbr_surface",
        {
            "base_metalness": 1.0,
            "base_color": [0.95, 0.64, 0.54],
            "specular_roughness": 0.35,
            "coat_weight": 1.0,
            "coat_color": [0.9, 0.6, 0.3],
            "coat_roughness": 0.25,
        },
    )
    r = fit(
        source,
        "mtlx:standard_surface",
        "simple",
        Scene.probe([0.0, 45.0], resolution=64),
        fix={"metalness": 1.0},
        free=["coat", "coat_color", "coat_roughness"],
    )
    assert r.loss < 0.03 and r.target.values["coat"][0] > 0.7, (r.loss, r.target.values["coat"])  # stalled: 0.52
