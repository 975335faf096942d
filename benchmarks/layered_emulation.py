"""The layered models: fits between them and the existing models, and the embedded ``mitsuba3:principled``
against real Mitsuba 3.

    .venv/bin/python benchmarks/layered_emulation.py fits [--size 128]
    .venv/bin/python benchmarks/layered_emulation.py mitsuba [--resolution 64] [--rows]
    .venv/bin/python benchmarks/layered_emulation.py glass [--resolution 48] [--rows]

``fits``: ``matremap.fit`` (two-stage, the probe of ``matremap fit``) from OpenPBR and Standard Surface
materials (a plastic, a copper, a coated copper, a sheen) onto gltf:metal-rough, cycles:principled,
mitsuba3:roughconductor / roughplastic and the other MaterialX model, and from plain glTF and Cycles
materials and a clear-coated Mitsuba 3 principled onto the MaterialX ones; prints the relative RMSE of each
fit, its time and the layer the target absorbed (the fit's note). Targets drawn by the embedded renderer
need nothing; mitsuba3:roughplastic needs Mitsuba 3 (skipped without it).

``mitsuba``: the embedded ``mitsuba3:principled`` and Mitsuba 3 draw the probe sphere (lights at 0 and 45
degrees) for a grid of parameters, in one batch each; the table gives the relative RMSE over sphere pixels
per lobe group (median and worst case). The transmission group (spec_trans 0.5 / 1, specular 0 / 0.2 / 0.5 / 1,
i.e. eta 1.0006 (specular 0 read as 1e-3) / 1.28 / 1.5 / 1.8) compares the reflection: the ``direct`` integrator
lights the first hit only, and a light below a pixel's horizon is behind the sphere itself (shadowed), so no
transmitted light reaches the camera (the background stays 0).

``glass``: the same for Mitsuba 3's glasses: roughdielectric on alpha 0.05 / 0.1 / 0.3 / 0.7 x IOR 1.33 / 1.5 /
2.0 x Beckmann / GGX, water in a medium of IOR 1.6789 (eta 0.79), a coloured specular_reflectance; dielectric and
thindielectric (a delta lobe: both renderers draw 0).
"""

from __future__ import annotations

import argparse
import itertools
import sys
import time

import numpy as np

from matremap.core.material import Material
from matremap.core.scene import Scene

COPPER = [0.95, 0.64, 0.54]
SOURCES = {
    "openpbr plastic": ("mtlx:open_pbr_surface", {"base_color": [0.8, 0.3, 0.1], "specular_roughness": 0.4}),
    "openpbr copper": (
        "mtlx:open_pbr_surface",
        {"base_metalness": 1.0, "base_color": COPPER, "specular_roughness": 0.35},
    ),
    "openpbr coated copper": (
        "mtlx:open_pbr_surface",
        {
            "base_metalness": 1.0,
            "base_color": COPPER,
            "specular_roughness": 0.35,
            "coat_weight": 1.0,
            "coat_color": [0.9, 0.6, 0.3],
            "coat_roughness": 0.25,
        },
    ),
    "openpbr fuzz (velvet)": (
        "mtlx:open_pbr_surface",
        {
            "base_color": [0.5, 0.05, 0.1],
            "specular_roughness": 0.6,
            "fuzz_weight": 1.0,
            "fuzz_color": [1.0, 0.5, 0.6],
            "fuzz_roughness": 0.5,
        },
    ),
    "stdsurf coated copper": (
        "mtlx:standard_surface",
        {
            "metalness": 1.0,
            "base_color": COPPER,
            "specular_roughness": 0.35,
            "coat": 1.0,
            "coat_color": [0.9, 0.6, 0.3],
            "coat_roughness": 0.25,
        },
    ),
    "stdsurf sheen": (
        "mtlx:standard_surface",
        {"base_color": [0.5, 0.05, 0.1], "specular_roughness": 0.6, "sheen": 1.0, "sheen_color": [1.0, 0.5, 0.6]},
    ),
    "gltf plastic": ("gltf:metal-rough", {"baseColor": [0.8, 0.3, 0.1], "metallic": 0.0, "roughness": 0.4}),
    "gltf copper": ("gltf:metal-rough", {"baseColor": COPPER, "metallic": 1.0, "roughness": 0.35}),
    "cycles plastic": ("cycles:principled", {"Base Color": [0.8, 0.3, 0.1], "Roughness": 0.4}),
    "mitsuba3 principled clearcoat": (
        "mitsuba3:principled",
        {"base_color": [0.8, 0.3, 0.1], "roughness": 0.4, "clearcoat": 1.0, "clearcoat_gloss": 0.5},
    ),
}
#: the parameter holding a target metallic, per model
METALLIC = {
    "gltf:metal-rough": "metallic",
    "cycles:principled": "Metallic",
    "mtlx:open_pbr_surface": "base_metalness",
    "mtlx:standard_surface": "metalness",
}
LAYERED_TARGETS = ("gltf:metal-rough", "cycles:principled", "mtlx:open_pbr_surface", "mtlx:standard_surface")


def is_metal(model: str, values: dict) -> bool:
    return float(values.get(METALLIC.get(model, ""), 0.0)) >= 0.5


def targets_for(model: str, values: dict) -> list[str]:
    """Every other model of the comparison that can take the source: conductors for metals, plastics for
    dielectrics."""
    metal = is_metal(model, values)
    extra = ["mitsuba3:roughconductor"] if metal else ["mitsuba3:roughplastic"]
    if model.startswith("mtlx:"):
        return [t for t in LAYERED_TARGETS if t != model] + extra
    return ["mtlx:open_pbr_surface", "mtlx:standard_surface"]


def fix_for(target: str, metal: bool) -> dict:
    fix: dict = {"distribution": "ggx"} if target.startswith("mitsuba3:rough") else {}
    if target in METALLIC:
        fix[METALLIC[target]] = 1.0 if metal else 0.0
    return fix


def run_fits(size: int) -> int:
    from matremap.errors import MatremapError
    from matremap.uniform import fit

    scene = Scene.probe([0.0, 45.0], resolution=size)
    print(f"two-stage fits on the probe ({size}^2, lights at 0 and 45 degrees); loss = relative RMSE")
    print("| source | target | loss | seconds | note |")
    print("|---|---|---|---|---|")
    for name, (model, values) in SOURCES.items():
        source = Material.create(model, values)
        metal = is_metal(model, values)
        for target in targets_for(model, values):
            try:
                t0 = time.perf_counter()
                r = fit(source, target, scene=scene, fix=fix_for(target, metal))
                seconds = time.perf_counter() - t0
            except MatremapError as e:
                print(f"| {name} | {target} | - | - | skipped: {e} |")
                continue
            notes = "; ".join(w.split(": ", 1)[-1] for w in r.warnings if "absorbed" in w)
            print(f"| {name} | {target} | {r.loss:.4f} | {seconds:.1f} | {notes} |")
    return 0


# -- mitsuba3:principled against Mitsuba 3 -------------------------------------------------------------

BASE = [0.8, 0.4, 0.2]


def principled_grid() -> list[tuple[str, dict]]:
    """(lobe group, parameters) of every case."""
    cases: list[tuple[str, dict]] = []
    for r in (0.1, 0.3, 0.6, 1.0):
        cases.append(("diffuse", {"base_color": BASE, "roughness": r, "specular": 0.0}))
        for s, tint in itertools.product((0.2, 0.5, 1.0), (0.0, 1.0)):
            cases.append(("dielectric", {"base_color": BASE, "roughness": r, "specular": s, "spec_tint": tint}))
        for m in (0.5, 1.0):
            cases.append(("metal", {"base_color": BASE, "roughness": r, "metallic": m}))
        for sheen, tint in itertools.product((0.5, 1.0), (0.0, 1.0)):
            cases.append(("sheen", {"base_color": BASE, "roughness": r, "sheen": sheen, "sheen_tint": tint}))
        for cc, gloss in itertools.product((0.5, 1.0), (0.0, 0.5, 1.0)):
            cases.append(("clearcoat", {"base_color": BASE, "roughness": r, "clearcoat": cc, "clearcoat_gloss": gloss}))
        for st, s in itertools.product((0.5, 1.0), (0.0, 0.2, 0.5, 1.0)):
            cases.append(("transmission", {"base_color": BASE, "roughness": r, "specular": s, "spec_trans": st}))
        cases.append(
            (
                "all",
                {
                    "base_color": BASE,
                    "roughness": r,
                    "metallic": 0.3,
                    "specular": 0.7,
                    "spec_tint": 0.5,
                    "sheen": 0.6,
                    "sheen_tint": 0.4,
                    "clearcoat": 0.8,
                    "clearcoat_gloss": 0.6,
                },
            )
        )
    return cases


def relative_rmse(a: np.ndarray, b: np.ndarray, mask: np.ndarray) -> np.ndarray:
    d = (a - b)[:, mask].reshape(len(a), -1)
    return np.linalg.norm(d, axis=1) / np.linalg.norm(b[:, mask].reshape(len(b), -1), axis=1)


def run_mitsuba(resolution: int, rows: bool) -> int:
    from matremap.renderers.embedded import EmbeddedRenderer
    from matremap.renderers.mitsuba3.plugins import INSTALL_HINT, mitsuba_installed

    if not mitsuba_installed():
        print(INSTALL_HINT, file=sys.stderr)
        return 4
    from matremap.renderers.mitsuba3.probe import Mitsuba3Renderer

    scene = Scene.probe([0.0, 45.0], resolution=resolution)
    mask = scene.mask()
    cases = principled_grid()
    mats = [Material.create("mitsuba3:principled", v) for _, v in cases]
    t0 = time.perf_counter()
    emb = EmbeddedRenderer().render(mats, scene)
    t_emb = time.perf_counter() - t0
    t0 = time.perf_counter()
    real = Mitsuba3Renderer().render(mats, scene)
    t_real = time.perf_counter() - t0
    err = relative_rmse(emb, real, mask)
    if rows:
        for (group, v), e in zip(cases, err, strict=True):
            print(f"{group:10s} {e:.2e} {v}")
    print(f"{len(cases)} cases at {resolution}^2: embedded {t_emb:.2f} s, Mitsuba 3 {t_real:.1f} s")
    print("| lobe | cases | median rel. RMSE | worst |")
    print("|---|---|---|---|")
    for group in ("diffuse", "dielectric", "metal", "sheen", "clearcoat", "transmission", "all"):
        sel = np.array([g == group for g, _ in cases])
        print(f"| {group} | {sel.sum()} | {np.median(err[sel]):.1e} | {err[sel].max():.1e} |")
    worst = int(np.argmax(err))
    print(f"worst case overall: {err[worst]:.2e} ({cases[worst]})")
    return 0


def glass_grid() -> list[tuple[str, str, dict]]:
    """(label, model, values) of the glass cases."""
    cases = [
        (
            f"{d} alpha {a} IOR {ior}",
            "mitsuba3:roughdielectric",
            {"distribution": d, "alpha": a, "int_ior": ior, "ext_ior": 1.0},
        )
        for d, a, ior in itertools.product(("beckmann", "ggx"), (0.05, 0.1, 0.3, 0.7), (1.33, 1.5, 2.0))
    ]
    return cases + [
        (
            "ggx 0.3, water in 1.6789",
            "mitsuba3:roughdielectric",
            {"distribution": "ggx", "alpha": 0.3, "int_ior": 1.333, "ext_ior": 1.6789},
        ),
        ("beckmann 0.2, coloured", "mitsuba3:roughdielectric", {"alpha": 0.2, "specular_reflectance": [0.9, 0.5, 0.2]}),
        ("dielectric", "mitsuba3:dielectric", {}),
        ("thindielectric", "mitsuba3:thindielectric", {}),
    ]


def run_glass(resolution: int, rows: bool) -> int:
    """The embedded glasses' reflection against Mitsuba 3 on the probe (relative RMSE; 0 where both are black)."""
    from matremap.renderers.embedded import EmbeddedRenderer
    from matremap.renderers.mitsuba3.plugins import INSTALL_HINT, mitsuba_installed

    if not mitsuba_installed():
        print(INSTALL_HINT, file=sys.stderr)
        return 4
    from matremap.renderers.mitsuba3.probe import Mitsuba3Renderer

    scene = Scene.probe([0.0, 45.0], resolution=resolution)
    mask = scene.mask()
    cases = glass_grid()
    mats = [Material.create(model, v) for _, model, v in cases]
    emb, real = EmbeddedRenderer().render(mats, scene), Mitsuba3Renderer().render(mats, scene)
    err = []
    for a, b in zip(emb, real, strict=True):
        norm = float(np.linalg.norm(b[mask]))
        err.append(float(np.linalg.norm(a[mask] - b[mask]) / norm) if norm > 0 else float(np.abs(a[mask]).max()))
    if rows:
        for (label, _, _), e in zip(cases, err, strict=True):
            print(f"{label:32s} {e:.2e}")
    grid = np.array(err[:24])
    print(
        f"roughdielectric grid, {len(grid)} cases at {resolution}^2: "
        f"median {np.median(grid):.1e}, worst {grid.max():.1e}"
    )
    for (label, _, _), e in list(zip(cases, err, strict=True))[24:]:
        print(f"{label}: {e:.1e}")
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="what", required=True)
    f = sub.add_parser("fits")
    f.add_argument("--size", type=int, default=128)
    m = sub.add_parser("mitsuba")
    m.add_argument("--resolution", type=int, default=64)
    m.add_argument("--rows", action="store_true")
    g = sub.add_parser("glass")
    g.add_argument("--resolution", type=int, default=48)
    g.add_argument("--rows", action="store_true")
    args = ap.parse_args(argv)
    if args.what == "fits":
        return run_fits(args.size)
    if args.what == "glass":
        return run_glass(args.resolution, args.rows)
    return run_mitsuba(args.resolution, args.rows)


if __name__ == "__main__":
    sys.exit(main())
