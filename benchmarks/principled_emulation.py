"""The embedded ``cycles:principled`` against real Blender 5.0 Cycles on a grid of parameters.

    .venv/bin/python benchmarks/principled_emulation.py [--resolution 64] [--rows]

Both renderers draw the probe sphere (``Scene.probe([0, 45])``: a headlight and a light 45 degrees
off, in one image) for every case of the grid, in one batch each; the table gives the relative RMSE
over sphere pixels, ||embedded - cycles|| / ||cycles||, per lobe and distribution (median and worst
case of the group), and, for the full material, the same with an ablated emulation whose diffuse
base is weighted by 1 - F0 (the specular albedo table of Cycles left out), to show that the
measurement sees the layering. ``--rows`` prints every case.

Groups (each for distribution multi_ggx and ggx):

* diffuse: Metallic 0, Specular IOR Level 0 (no specular lobe), coloured Base Color, Roughness and
  IOR over the grid (they should not matter);
* dielectric: Base Color 0, Metallic 0, Roughness 0.05..1, IOR 1.1 / 1.5 / 2.5, Specular IOR Level
  0.5 / 1, Specular Tint white / coloured;
* metal: Metallic 1, coloured Base Color, Roughness 0.05..1, Specular Tint white / coloured;
* full: coloured Base Color, Metallic 0 / 0.5, Roughness 0.05..1, IOR 1.1 / 1.5 / 2.5, Specular IOR
  Level 0 / 0.5 / 1, Specular Tint white / coloured;
* coat: a coloured dielectric (Roughness 0.4) or metal (Metallic 1, Roughness 0.3) under Coat Weight
  0.5 / 1, Coat Roughness 0.03..1, Coat IOR 1.3 / 1.5 / 2.0, Coat Tint white / amber;
* sheen: the same bases under Sheen Weight 0.5 / 1, Sheen Roughness 0.05..1, Sheen Tint white / pink, and a
  sheen alone (black base, no specular);
* coat+sheen: both layers over the dielectric and the metal;
* transmission: Transmission Weight 0.5 / 1, Roughness 0.05..1, IOR 1.1 / 1.5 / 2.5; a full glass with a coloured
  Specular Tint; and 0.7 of it with Metallic 0.3, Specular IOR Level 0.8, a coat and a sheen. What is compared is
  the reflection: Cycles renders direct light only (``max_bounces = 0``), the background is black, and the
  worker's occluder (``renderers/cycles/worker.py``: Cycles skips a shadow ray's own primitive, the whole point
  cloud sphere) keeps a light below a pixel's horizon from reaching the glass through the sphere, except within
  0.08 degrees of the horizon, where a pixel of the 45-degree light's terminator can still catch it.

Needs the bpy venv (``python3.11 -m venv .venv-bpy && .venv-bpy/bin/pip install bpy==5.0.1``).
"""

from __future__ import annotations

import argparse
import itertools
import sys
import time
from contextlib import contextmanager

import numpy as np

from matremap.core.material import Material
from matremap.core.scene import Scene
from matremap.renderers.embedded import EmbeddedRenderer
from matremap.renderers.embedded.evaluators import principled

ROUGHNESS = (0.05, 0.2, 0.4, 0.7, 1.0)
IORS = (1.1, 1.5, 2.5)
TINTS = ((1.0, 1.0, 1.0), (1.0, 0.6, 0.3))
BASE = (0.8, 0.4, 0.2)
DISTRIBUTIONS = ("multi_ggx", "ggx")


def grid() -> list[tuple[str, str, dict]]:
    """(group, distribution, parameter values) of every case."""
    cases: list[tuple[str, str, dict]] = []
    for dist in DISTRIBUTIONS:
        for r, ior in itertools.product(ROUGHNESS, IORS):
            cases.append(("diffuse", dist, {"Base Color": BASE, "Roughness": r, "IOR": ior, "Specular IOR Level": 0.0}))
        for r, ior, level, tint in itertools.product(ROUGHNESS, IORS, (0.5, 1.0), TINTS):
            values = {"Base Color": 0.0, "Roughness": r, "IOR": ior, "Specular IOR Level": level, "Specular Tint": tint}
            cases.append(("dielectric", dist, values))
        for r, tint in itertools.product(ROUGHNESS, TINTS):
            cases.append(("metal", dist, {"Base Color": BASE, "Metallic": 1.0, "Roughness": r, "Specular Tint": tint}))
        for m, r, ior, level, tint in itertools.product((0.0, 0.5), ROUGHNESS, IORS, (0.0, 0.5, 1.0), TINTS):
            values = {
                "Base Color": BASE,
                "Metallic": m,
                "Roughness": r,
                "IOR": ior,
                "Specular IOR Level": level,
                "Specular Tint": tint,
            }
            cases.append(("full", dist, values))
        cases += layered_cases(dist)
        cases += transmission_cases(dist)
    return cases


def transmission_cases(dist: str) -> list[tuple[str, str, dict]]:
    """The transmission group of one distribution (see the module docstring)."""
    cases: list[tuple[str, str, dict]] = []
    for t, r, ior in itertools.product((0.5, 1.0), ROUGHNESS, IORS):
        cases.append(("transmission", dist, {"Base Color": BASE, "Roughness": r, "IOR": ior, "Transmission Weight": t}))
    for r in ROUGHNESS:
        tinted = {"Base Color": BASE, "Roughness": r, "Transmission Weight": 1.0, "Specular Tint": TINTS[1]}
        cases.append(("transmission", dist, tinted))
        mixed = {"Base Color": BASE, "Roughness": r, "Transmission Weight": 0.7, "Metallic": 0.3}
        mixed.update({"Specular IOR Level": 0.8, "Coat Weight": 0.5, "Sheen Weight": 0.3})
        cases.append(("transmission", dist, mixed))
    return cases


LAYER_BASES = (
    {"Base Color": BASE, "Roughness": 0.4},
    {"Base Color": BASE, "Metallic": 1.0, "Roughness": 0.3},
)
LAYER_ROUGHNESS = (0.03, 0.05, 0.2, 0.5, 1.0)
GROUPS = ("diffuse", "dielectric", "metal", "full", "coat", "sheen", "coat+sheen", "transmission")


def layered_cases(dist: str) -> list[tuple[str, str, dict]]:
    """The coat, sheen and coat+sheen groups of one distribution (see the module docstring)."""
    cases: list[tuple[str, str, dict]] = []
    for base in LAYER_BASES:
        for w, r, ior, tint in itertools.product((0.5, 1.0), LAYER_ROUGHNESS, (1.3, 1.5, 2.0), TINTS):
            coat = {"Coat Weight": w, "Coat Roughness": r, "Coat IOR": ior, "Coat Tint": tint}
            cases.append(("coat", dist, {**base, **coat}))
        for w, r, tint in itertools.product((0.5, 1.0), LAYER_ROUGHNESS, ((1.0, 1.0, 1.0), (1.0, 0.5, 0.6))):
            cases.append(("sheen", dist, {**base, "Sheen Weight": w, "Sheen Roughness": r, "Sheen Tint": tint}))
        for r in (0.05, 0.3, 0.8):
            both = {"Coat Weight": 1.0, "Coat Roughness": r, "Coat Tint": TINTS[1], "Sheen Weight": 0.7}
            cases.append(("coat+sheen", dist, {**base, **both, "Sheen Roughness": r, "Sheen Tint": (1.0, 0.5, 0.6)}))
    for r in LAYER_ROUGHNESS:
        alone = {"Base Color": 0.0, "Specular IOR Level": 0.0, "Sheen Weight": 1.0, "Sheen Roughness": r}
        cases.append(("sheen", dist, alone))
    return cases


@contextmanager
def diffuse_under_one_minus_f0():
    """The ablation: the specular albedo estimate's s set to 0, so the diffuse takes 1 - F0 tint."""
    saved = principled.specular_albedo_s
    principled.specular_albedo_s = lambda rough, mu, eta: np.zeros(np.broadcast(rough, mu, eta).shape)
    try:
        yield
    finally:
        principled.specular_albedo_s = saved


def below_horizon_band(scene: Scene, width: float = 2e-3) -> np.ndarray:
    """Sphere pixels [res, res] some light reaches at -width < n.l <= 0: just below the pixel's horizon, where
    Cycles' shadow ray can still graze past the worker's occluder."""
    res = scene.resolution
    d = scene.camera_rays().reshape(-1, 3)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    cam = np.array([0.0, 0.0, scene.camera_distance])
    b = d @ cam
    disc = b * b - (cam @ cam - scene.sphere_radius**2)
    p = cam + (-b - np.sqrt(np.maximum(disc, 0.0)))[:, None] * d
    n = p / scene.sphere_radius
    band = np.zeros(len(d), dtype=bool)
    for light in scene.lights:
        to_light = scene.light_position(light) - p
        cos = np.sum(n * to_light, axis=1) / np.linalg.norm(to_light, axis=1)
        band |= (cos <= 0.0) & (cos > -width)
    return (band & (disc > 0.0)).reshape(res, res) & scene.mask()


def relative_rmse(a: np.ndarray, b: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Per image of a batch: ||a - b|| / ||b|| over the masked pixels."""
    d = (a - b)[:, mask]
    return np.linalg.norm(d.reshape(len(a), -1), axis=1) / np.linalg.norm(b[:, mask].reshape(len(b), -1), axis=1)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--resolution", type=int, default=64)
    ap.add_argument("--rows", action="store_true", help="print every case")
    args = ap.parse_args(argv)

    from matremap.renderers.cycles.client import INSTALL_HINT, bpy_available
    from matremap.renderers.cycles.probe import CyclesRenderer

    if not bpy_available():
        print(INSTALL_HINT, file=sys.stderr)
        return 4
    scene = Scene.probe([0.0, 45.0], resolution=args.resolution)
    mask = scene.mask()
    cases = grid()
    mats = [Material.create("cycles:principled", {**values, "distribution": d}) for _, d, values in cases]
    t0 = time.perf_counter()
    embedded = EmbeddedRenderer().render(mats, scene)
    t_emb = time.perf_counter() - t0
    with diffuse_under_one_minus_f0():
        ablated = EmbeddedRenderer().render(mats, scene)
    cycles = CyclesRenderer(timeout=1800.0)
    try:
        t0 = time.perf_counter()
        real = cycles.render(mats, scene)
        t_real = time.perf_counter() - t0
    finally:
        cycles.close()
    err = relative_rmse(embedded, real, mask)
    err_ablated = relative_rmse(ablated, real, mask)
    band = below_horizon_band(scene)
    err_off_band = relative_rmse(embedded, real, mask & ~band)
    if args.rows:
        for (group, dist, values), e in zip(cases, err, strict=True):
            print(f"{group:10s} {dist:9s} {e:.2e} {values}")
    timing = f"embedded {t_emb:.2f} s, Cycles {t_real:.1f} s"
    print(f"{len(cases)} cases at {args.resolution}^2, lights at 0 and 45 degrees: {timing}")
    print(f"({band.sum()} sphere pixels lie just below a light's horizon: -2e-3 < n.l <= 0)")
    print(
        "| lobe | distribution | cases | median rel. RMSE | worst | worst off those pixels | "
        "worst, diffuse under 1 - F0 |"
    )
    print("|---|---|---|---|---|---|---|")
    for group in GROUPS:
        for dist in DISTRIBUTIONS:
            sel = np.array([g == group and d == dist for g, d, _ in cases])
            worst = int(np.argmax(np.where(sel, err, -1.0)))
            print(
                f"| {group} | {dist} | {sel.sum()} | {np.median(err[sel]):.1e} | {err[worst]:.1e} | "
                f"{err_off_band[sel].max():.1e} | {err_ablated[sel].max():.1e} |"
            )
    print(f"worst case overall: {err.max():.2e} ({cases[int(np.argmax(err))]})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
