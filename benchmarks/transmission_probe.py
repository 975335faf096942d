"""The embedded transmission probe against Mitsuba 3 path-tracing the same scene (issue 16).

    .venv/bin/python benchmarks/transmission_probe.py [--res 48] [--spp 512] [--grey] [--mitsuba-glass]

Each case is an OpenPBR glass (exact dielectric Fresnel, as Mitsuba's ``dielectric`` / ``roughdielectric``) in the
transmission probe with a black environment, so that the image on the sphere is only what it lets through from the
tiled plane behind (renderers/mitsuba3/transmission_reference.py builds Mitsuba's scene). Columns: per channel, the
embedded mean over the sphere's inner pixels (off the silhouette) relative to Mitsuba's; the relative RMSE of the
two images blurred by a 1.5-pixel Gaussian (the embedded probe shoots one ray through each pixel centre, Mitsuba
integrates over the pixel: tile edges differ pixel by pixel, not on average); the embedded probe at the fits' 8
paths per pixel and at 64; seconds. The first row checks the plane alone (no sphere) pixel by pixel. ``--grey``
makes every tile grey (1 and 0.35): the mean then measures energy alone, without the colour that a different
spread of the rough lobe takes from the neighbouring tiles. ``--mitsuba-glass``: Mitsuba 3's own glasses
(``mitsuba3:dielectric``, ``roughdielectric`` with both distributions, ``thindielectric``) instead, Mitsuba drawing
each with its own plugin (tint, eta below 1, Beckmann, the thin slab), the embedded probe with 1 or 64 paths.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np
from scipy.ndimage import gaussian_filter

from matremap.core.envmap import constant
from matremap.core.material import Material
from matremap.core.scene import Scene
from matremap.renderers.embedded import transmission as tr
from matremap.renderers.mitsuba3.transmission_reference import render_reference

CASES = [
    ("smooth, IOR 1.5", {"specular_ior": 1.5, "specular_roughness": 0.0}),
    ("smooth, IOR 1.33", {"specular_ior": 1.33, "specular_roughness": 0.0}),
    ("smooth, IOR 2.4", {"specular_ior": 2.4, "specular_roughness": 0.0}),
    ("rough 0.1 (alpha 0.01)", {"specular_ior": 1.5, "specular_roughness": 0.1}),
    ("rough 0.3 (alpha 0.09)", {"specular_ior": 1.5, "specular_roughness": 0.3}),
    ("rough 0.5 (alpha 0.25)", {"specular_ior": 1.5, "specular_roughness": 0.5}),
    (
        "volume (0.8, 0.5, 0.2) at 2",
        {
            "specular_ior": 1.5,
            "specular_roughness": 0.0,
            "transmission_color": [0.8, 0.5, 0.2],
            "transmission_depth": 2,
        },
    ),
]


def inner(res: int) -> np.ndarray:
    """The sphere's pixels whose centre is within 80 % of its radius on the image (off the silhouette)."""
    mask = Scene(resolution=res).mask()
    yy, xx = np.mgrid[0:res, 0:res]
    r = np.hypot(xx - res / 2 + 0.5, yy - res / 2 + 0.5) / (res / 2 / 1.05)
    return mask & (r < 0.8)


def compare(ours: np.ndarray, ref: np.ndarray, res: int) -> tuple[np.ndarray, float]:
    """Mean ratio per channel over the inner pixels and the relative RMSE of the blurred images there."""
    sel, mask = inner(res), Scene(resolution=res).mask()

    def blur(x: np.ndarray) -> np.ndarray:
        return np.stack([gaussian_filter(np.where(mask, x[..., c], 0.0), 1.5) for c in range(3)], axis=-1)[sel]

    a, b = blur(ours), blur(ref)
    return ours[sel].mean(0) / ref[sel].mean(0) - 1.0, float(np.linalg.norm(a - b) / np.linalg.norm(b))


GLASSES = [
    ("dielectric bk7", "mitsuba3:dielectric", {}),
    ("dielectric tinted (0.9, 0.6, 0.3)", "mitsuba3:dielectric", {"specular_transmittance": [0.9, 0.6, 0.3]}),
    ("dielectric IOR 2.0", "mitsuba3:dielectric", {"int_ior": 2.0, "ext_ior": 1.0}),
    ("dielectric water in 1.6789 (eta 0.79)", "mitsuba3:dielectric", {"int_ior": 1.333, "ext_ior": 1.6789}),
    *(
        (
            f"roughdielectric {d} {a}",
            "mitsuba3:roughdielectric",
            {"distribution": d, "alpha": a, "int_ior": 1.5, "ext_ior": 1.0},
        )
        for d in ("ggx", "beckmann")
        for a in (0.05, 0.1, 0.3, 0.5)
    ),
    ("thindielectric bk7", "mitsuba3:thindielectric", {}),
    (
        "thindielectric IOR 2, tinted",
        "mitsuba3:thindielectric",
        {"int_ior": 2.0, "ext_ior": 1.0, "specular_transmittance": [0.9, 0.6, 0.3]},
    ),
    (
        "thindielectric IOR 2, no reflection",
        "mitsuba3:thindielectric",
        {"int_ior": 2.0, "ext_ior": 1.0, "specular_reflectance": 0.0},
    ),
]


def run_glasses(res: int, spp: int) -> int:
    """Mitsuba 3's glasses through the probe against Mitsuba drawing them with their own plugins."""
    from matremap.renderers.mitsuba3.plugins import bsdf_dict

    black = constant(0.0)
    print("| case | mean (R, G, B) | blurred RMSE | Mitsuba s |")
    print("|---|---|---|---|")
    for label, model, values in GLASSES:
        m = Material.create(model, values)
        samples = 1 if tr.interface_of(m).alpha < tr.SMOOTH_ALPHA else 64
        t = time.perf_counter()
        ref = render_reference(1.0, 0.0, resolution=res, spp=spp, bsdf=bsdf_dict(model, dict(m.options), m)[0])
        seconds = time.perf_counter() - t
        ours, _ = tr.transmitted(m, tr.TransmissionScene(resolution=res, env=black, bounces=12, samples=samples))
        mean, rmse = compare(ours, ref, res)
        print(f"| {label} | {', '.join(f'{x:+.3f}' for x in mean)} | {rmse:.4f} | {seconds:.1f} |", flush=True)
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, default=48)
    ap.add_argument("--spp", type=int, default=512)
    ap.add_argument("--grey", action="store_true", help="grey tiles (energy alone)")
    ap.add_argument("--mitsuba-glass", action="store_true", help="Mitsuba 3's glass models")
    args = ap.parse_args(argv)
    if args.grey:
        tr.PALETTE[:] = 1.0  # read by both the embedded background and the reference's bitmap
    if args.mitsuba_glass:
        return run_glasses(args.res, args.spp)
    res = args.res
    black = constant(0.0)
    scene = Scene(resolution=res)
    rays = scene.camera_rays().reshape(-1, 3)
    plane = tr.background(
        np.broadcast_to([0.0, 0.0, 8.0], rays.shape).astype(float), rays, tr.TransmissionScene(), black
    )
    alone = render_reference(1.0, 0.0, resolution=res, spp=16)
    off = ~scene.mask()
    gap = np.abs(alone[off] - plane.reshape(res, res, 3)[off]).max(axis=-1)
    print(
        f"plane alone, off the sphere: median |difference| {np.median(gap):.1e}; {np.mean(gap > 1e-3):.1%} of the "
        "pixels differ by more than 1e-3 (tile edges: Mitsuba averages a pixel, the probe takes its centre)"
    )
    print("\n| case | mean, 8 paths (R, G, B) | blurred RMSE, 8 | mean, 64 paths | blurred RMSE, 64 | Mitsuba s |")
    print("|---|---|---|---|---|---|")
    for label, values in CASES:
        m = Material.create("mtlx:open_pbr_surface", {"transmission_weight": 1.0, **values})
        iface = tr.interface_of(m)
        t = time.perf_counter()
        ref = render_reference(iface.eta, iface.alpha, iface.sigma, resolution=res, spp=args.spp)
        seconds = time.perf_counter() - t
        cells = []
        for samples in (8, 64):
            ours, _ = tr.transmitted(m, tr.TransmissionScene(resolution=res, env=black, bounces=12, samples=samples))
            mean, rmse = compare(ours, ref, res)
            cells += [", ".join(f"{x:+.3f}" for x in mean), f"{rmse:.4f}"]
        print(f"| {label} | {' | '.join(cells)} | {seconds:.1f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
