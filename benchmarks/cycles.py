"""Real Blender Cycles backend: cross-check against the embedded emulation, seconds per render and per fit.

Run with the main venv: ``.venv/bin/python benchmarks/cycles.py`` (needs the bpy venv, see docs/cycles.md).
"""

from __future__ import annotations

import time

import numpy as np

from matremap.core.material import Material
from matremap.core.scene import Scene
from matremap.renderers import get_renderer
from matremap.renderers.cycles.probe import CyclesRenderer
from matremap.uniform import fit


def rel(a, b, mask):
    return float(np.linalg.norm(a[mask] - b[mask]) / np.linalg.norm(b[mask]))


def blend_timing(cycles: CyclesRenderer) -> None:
    """Write a uniform Principled material as a .blend, reopen it and render its sphere in the probe."""
    import tempfile
    from pathlib import Path

    from matremap.formats import blend

    m = Material.create("cycles:principled", {"Base Color": [0.8, 0.3, 0.1], "Roughness": 0.4})
    scene = Scene.probe([0.0, 45.0], resolution=64)
    with tempfile.TemporaryDirectory() as d:
        out = Path(d) / "m.blend"
        t0 = time.perf_counter()
        blend.write(out, m, renderer=cycles)
        t1 = time.perf_counter()
        img = cycles._request({"op": "render_blend", "path": str(out), "scene": cycles.scene_dict(scene)})[0]
        t2 = time.perf_counter()
        err = rel(img, cycles.render([m], scene)[0], scene.mask())
        print(
            f".blend write {t1 - t0:.2f} s ({out.stat().st_size / 1e3:.0f} kB), reopen + render its sphere "
            f"{t2 - t1:.2f} s; vs the backend's true sphere {err:.1e} relative RMSE"
        )


def main() -> None:
    cycles = CyclesRenderer()
    embedded = get_renderer("embedded")
    t0 = time.perf_counter()
    cycles.start()
    print(f"worker start (import bpy): {time.perf_counter() - t0:.2f} s, Blender {cycles.blender_version}")
    for res in (64, 128):
        scene = Scene.probe([0.0, 45.0], resolution=res)
        mask = scene.mask()
        for dist in ("ggx", "beckmann", "ashikhmin_shirley", "multi_ggx"):
            mats = [
                Material.create("cycles:glossy", {"distribution": dist, "Roughness": r, "Diffuse Color": 0.1})
                for r in (0.1, 0.3, 0.5, 0.9)
            ]
            real, ref = cycles.render(mats, scene), embedded.render(mats, scene)
            errs = [rel(a, b, mask) for a, b in zip(real, ref, strict=True)]
            print(
                f"{res}^2 glossy {dist:18s} relative RMSE per roughness 0.1/0.3/0.5/0.9: "
                + " ".join(f"{e:.1e}" for e in errs)
            )
            if dist == "multi_ggx":  # how far single scattering is from it: what the compensation adds
                single = embedded.render(
                    [Material.create("cycles:glossy", {**m.values, "distribution": "ggx"}) for m in mats], scene
                )
                print(
                    f"{res}^2 glossy multi_ggx vs single-scatter ggx: "
                    + " ".join(f"{rel(a, b, mask):.1e}" for a, b in zip(real, single, strict=True))
                )
        d = Material.create("cycles:diffuse", {"Color": [0.2, 0.5, 1.0]})
        err = rel(cycles.render([d], scene)[0], embedded.render([d], scene)[0], mask)
        print(f"{res}^2 diffuse relative RMSE {err:.1e}")
        mats = [Material.create("cycles:principled", {"Roughness": 0.1 + 0.05 * i}) for i in range(16)]
        cycles.render(mats[:1], scene)
        t0 = time.perf_counter()
        cycles.render(mats, scene)
        dt = (time.perf_counter() - t0) / (len(mats) * len(scene.lights))
        print(f"{res}^2 seconds per Cycles image (one material, one light): {dt * 1000:.1f} ms")
    blend_timing(cycles)
    scene = Scene.probe([0.0], resolution=64)
    source = Material.create(
        "mitsuba06:ward",
        {"variant": "ward", "alpha": 0.2, "specularReflectance": 0.08, "diffuseReflectance": [0.5, 0.3, 0.2]},
    )
    t0 = time.perf_counter()
    r = fit(source, "cycles:principled", scene=scene, target_renderer=cycles)
    print(
        f"fit mitsuba06:ward -> cycles:principled 64^2: loss {r.loss:.4f}, {r.renders} renders, "
        f"{time.perf_counter() - t0:.2f} s; {r.target}"
    )
    cycles.close()


if __name__ == "__main__":
    main()
