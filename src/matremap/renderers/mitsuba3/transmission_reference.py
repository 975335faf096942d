"""The transmission probe drawn by Mitsuba 3, as an independent reference for the embedded one.

:mod:`matremap.renderers.embedded.transmission` traces what a material lets through deterministically (fixed
paths, Snell's law, Fresnel, Beer-Lambert, internal reflections). This builds the same scene in Mitsuba 3 and
path-traces it: the probe's camera (:meth:`~matremap.core.scene.Scene.camera_rays`: pinhole at (0, 0, 8), the
probe's field of view), the sphere of radius 2 with a ``dielectric`` / ``roughdielectric`` (GGX, Mitsuba's
exact Fresnel) and, for an absorbing volume, a ``homogeneous`` interior medium of albedo 0; behind it the tiled
plane at z = -4 as a ``rectangle`` area emitter whose radiance is a nearest-filtered bitmap of the probe's tiles
(:func:`~matremap.renderers.embedded.transmission.background`), and nothing else (no environment: what reaches
the camera through the sphere is the transmitted light alone, with every internal reflection).

Used by ``benchmarks/transmission_probe.py`` and its test; it needs Mitsuba 3 (imported lazily).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from matremap.core.scene import Scene

#: texels per tile side in the plane's bitmap
TILE_TEXELS = 8


def tile_bitmap(plane_half_size: float, tile: float) -> np.ndarray:
    """The plane's tiles as an RGB image [n, n, 3] (row 0 at y = -half: Mitsuba's rectangle maps v along +y from
    the bitmap's first row), the colour of tile (i, j) as the embedded background draws it."""
    from matremap.renderers.embedded.transmission import PALETTE

    tiles = int(round(2.0 * plane_half_size / tile))
    index = np.arange(tiles * TILE_TEXELS) // TILE_TEXELS - tiles // 2
    i, j = np.meshgrid(index, index)  # i along x (columns), j along y (rows)
    colour = PALETTE[np.mod(i + 2 * j, len(PALETTE))]
    return (colour * np.where(np.mod(i + j, 2) == 0, 1.0, 0.35)[..., None]).astype(np.float32)


def glass_bsdf(eta: float, alpha: float) -> dict[str, Any]:
    """A smooth (alpha 0) or GGX-rough dielectric of relative IOR ``eta``."""
    if alpha <= 0.0:
        return {"type": "dielectric", "int_ior": float(eta), "ext_ior": 1.0}
    return {"type": "roughdielectric", "distribution": "ggx", "alpha": float(alpha), "int_ior": float(eta)}


def render_reference(
    eta: float,
    alpha: float,
    sigma: np.ndarray | None = None,
    resolution: int = 48,
    spp: int = 256,
    plane_z: float = -4.0,
    plane_half_size: float = 12.0,
    tile: float = 0.5,
    seed: int = 0,
    bsdf: dict[str, Any] | None = None,
) -> np.ndarray:
    """Linear radiance [res, res, 3] of the probe's sphere (relative IOR ``eta``, GGX ``alpha``, extinction
    ``sigma`` per scene unit inside) before the tiled plane, path-traced by Mitsuba 3 (``scalar_rgb``) with
    ``spp`` samples per pixel; ``eta`` 1 and no sphere is the plane alone. ``bsdf``: the sphere's Mitsuba BSDF
    dictionary instead of :func:`glass_bsdf` (a ``mitsuba3:*`` glass as it is, e.g. a tinted or thin one)."""
    import mitsuba as mi

    if not mi.variant():
        mi.set_variant("scalar_rgb")
    scene = Scene(resolution=resolution)
    look = mi.ScalarTransform4f().look_at(origin=[0, 0, scene.camera_distance], target=[0, 0, 0], up=[0, 1, 0])
    absorbs = sigma is not None and bool(np.any(np.asarray(sigma) > 0.0))
    d: dict[str, Any] = {
        "type": "scene",
        "integrator": {"type": "volpath" if absorbs else "path", "max_depth": 16},
        "sensor": {
            "type": "perspective",
            "fov": float(scene.effective_fov),
            "fov_axis": "x",
            "to_world": look,
            "sampler": {"type": "independent", "sample_count": int(spp), "seed": int(seed)},
            "film": {
                "type": "hdrfilm",
                "width": resolution,
                "height": resolution,
                "rfilter": {"type": "box"},
                "pixel_format": "rgb",
            },
        },
        "plane": {
            "type": "rectangle",
            "to_world": mi.ScalarTransform4f().translate([0, 0, plane_z])
            @ mi.ScalarTransform4f().scale([plane_half_size, plane_half_size, 1.0]),
            "emitter": {
                "type": "area",
                "radiance": {
                    "type": "bitmap",
                    "bitmap": mi.Bitmap(tile_bitmap(plane_half_size, tile)),
                    "filter_type": "nearest",
                    "raw": True,
                },
            },
            "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.0, 0.0, 0.0]}},
        },
    }
    if bsdf is not None or not math.isclose(eta, 1.0) or alpha > 0.0 or absorbs:
        sphere: dict[str, Any] = {
            "type": "sphere",
            "center": [0.0, 0.0, 0.0],
            "radius": scene.sphere_radius,
            "bsdf": bsdf if bsdf is not None else glass_bsdf(eta, alpha),
        }
        if absorbs:
            sphere["interior"] = {
                "type": "homogeneous",
                "sigma_t": {"type": "rgb", "value": [float(s) for s in np.asarray(sigma)]},
                "albedo": {"type": "rgb", "value": [0.0, 0.0, 0.0]},
            }
        d["sphere"] = sphere
    return np.asarray(mi.render(mi.load_dict(d)), dtype=np.float32)


__all__ = ["TILE_TEXELS", "glass_bsdf", "render_reference", "tile_bitmap"]
