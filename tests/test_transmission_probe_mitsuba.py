"""The embedded transmission probe against Mitsuba 3 path-tracing the same scene (renderers/mitsuba3/
transmission_reference.py): the tiled plane pixel for pixel, and what smooth, absorbing and rough glass spheres let
through. Grey tiles, so that the mean measures energy (benchmarks/transmission_probe.py has the coloured table).
Measured (48^2, 512 spp): smooth IOR 1.5 mean +0.000, blurred relative RMSE 0.008; a Beer-Lambert volume +0.004,
0.024; GGX alpha 0.09 at 64 paths -0.013, 0.035. Skipped without Mitsuba 3."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mitsuba")
pytest.importorskip("scipy")

from matremap.core.envmap import constant  # noqa: E402
from matremap.core.material import Material  # noqa: E402
from matremap.core.scene import Scene  # noqa: E402
from matremap.renderers.embedded import transmission as tr  # noqa: E402
from matremap.renderers.mitsuba3.transmission_reference import render_reference  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from transmission_probe import compare  # noqa: E402

RES = 48
BLACK = constant(0.0)


@pytest.fixture(autouse=True)
def grey_tiles(monkeypatch):
    monkeypatch.setattr(tr, "PALETTE", np.ones_like(tr.PALETTE))


def glass(**kw) -> Material:
    return Material.create("mtlx:open_pbr_surface", {"transmission_weight": 1.0, "specular_ior": 1.5, **kw})


def ours(m: Material, samples: int = 8) -> np.ndarray:
    return tr.transmitted(m, tr.TransmissionScene(resolution=RES, env=BLACK, bounces=12, samples=samples))[0]


def reference(m: Material) -> np.ndarray:
    iface = tr.interface_of(m)
    return render_reference(iface.eta, iface.alpha, iface.sigma, resolution=RES, spp=256)


def test_the_plane_is_where_mitsuba_draws_it():
    scene = Scene(resolution=RES)
    rays = scene.camera_rays().reshape(-1, 3)
    origins = np.broadcast_to([0.0, 0.0, scene.camera_distance], rays.shape).astype(float)
    plane = tr.background(origins, rays, tr.TransmissionScene(), BLACK).reshape(RES, RES, 3)
    alone = render_reference(1.0, 0.0, resolution=RES, spp=16)
    off = ~scene.mask()
    assert np.median(np.abs(alone[off] - plane[off])) < 1e-5  # equal but where a tile edge crosses a pixel


@pytest.mark.parametrize(
    "values, samples, mean_tol, rmse_tol",
    [
        ({"specular_roughness": 0.0}, 1, 0.005, 0.02),
        ({"specular_roughness": 0.0, "transmission_color": [0.8, 0.5, 0.2], "transmission_depth": 2.0}, 1, 0.01, 0.05),
        ({"specular_roughness": 0.3}, 64, 0.03, 0.07),
    ],
    ids=["smooth", "volume", "rough"],
)
def test_what_a_glass_sphere_lets_through_is_what_mitsuba_traces(values, samples, mean_tol, rmse_tol):
    m = glass(**values)
    mean, rmse = compare(ours(m, samples), reference(m), RES)
    assert np.all(np.abs(mean) < mean_tol), mean
    assert rmse < rmse_tol, rmse
