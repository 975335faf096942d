"""The probe scene: a sphere lit by point lights, seen by a pinhole camera (paper §4).

Plain data that every renderer backend builds the same way:

* sphere of radius ``sphere_radius`` (2) at the origin;
* perspective camera at (0, 0, ``camera_distance``) looking down -z, +y up, square image of
  ``resolution`` pixels, field of view ``fov`` degrees (default: frames the sphere with a 5 % margin);
* point lights at ``light_distance`` (default: the camera distance) from the origin, each at an
  angle ``theta`` (degrees) from the view axis towards +x; theta = 0 is a headlight at the camera.
  A light's radiant intensity defaults to pi (d - r)^2 W/sr, so that a white Lambertian surface
  facing a headlight at the sphere's nearest point has radiance 1.

Images are linear HDR RGB float32 ``[H, W, 3]``; :meth:`Scene.mask` marks sphere pixels.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from matremap.errors import MatremapError


@dataclass(frozen=True)
class PointLight:
    """An isotropic point light ``theta`` degrees from the view axis (towards +x)."""

    theta: float = 0.0
    intensity: float | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"theta": self.theta, "intensity": self.intensity}


@dataclass(frozen=True)
class Scene:
    resolution: int = 128
    lights: tuple[PointLight, ...] = (PointLight(),)
    camera_distance: float = 8.0
    sphere_radius: float = 2.0
    light_distance: float | None = None
    fov: float | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.resolution, int) or not 8 <= self.resolution <= 8192:
            raise MatremapError(f"scene resolution must be an integer in [8, 8192], got {self.resolution!r}")
        if not self.lights:
            raise MatremapError("the scene needs at least one light")
        for light in self.lights:
            if not math.isfinite(light.theta) or not -90.0 < light.theta < 90.0:
                raise MatremapError(
                    f"light angle {light.theta!r} must be a finite angle in (-90, 90) degrees from the view axis"
                )
            if light.intensity is not None and not (math.isfinite(light.intensity) and light.intensity > 0):
                raise MatremapError(f"light intensity must be positive, got {light.intensity!r}")
        if not self.camera_distance > self.sphere_radius > 0:
            raise MatremapError("the camera must be outside the sphere (camera_distance > sphere_radius > 0)")
        if self.light_distance is not None and not self.light_distance > self.sphere_radius:
            raise MatremapError("lights must be outside the sphere (light_distance > sphere_radius)")

    # -- construction ------------------------------------------------------------------------
    @classmethod
    def probe(cls, lights: Iterable[float] = (0.0,), resolution: int = 128) -> Scene:
        """The paper's probe scene with lights at the given angles (degrees) from the view axis."""
        return cls(resolution=resolution, lights=tuple(PointLight(float(t)) for t in lights))

    def to_dict(self) -> dict[str, Any]:
        return {
            "resolution": self.resolution,
            "lights": [light.to_dict() for light in self.lights],
            "camera_distance": self.camera_distance,
            "sphere_radius": self.sphere_radius,
            "light_distance": self.effective_light_distance,
            "fov": self.effective_fov,
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Scene:
        lights = tuple(PointLight(**light) for light in d.get("lights", [{"theta": 0.0}]))
        kw = {k: d[k] for k in ("resolution", "camera_distance", "sphere_radius", "light_distance", "fov") if k in d}
        return cls(lights=lights, **kw)

    # -- derived quantities --------------------------------------------------------------------
    @property
    def effective_light_distance(self) -> float:
        return self.light_distance if self.light_distance is not None else self.camera_distance

    @property
    def effective_fov(self) -> float:
        """Full field of view in degrees."""
        if self.fov is not None:
            return self.fov
        half = math.asin(self.sphere_radius / self.camera_distance)
        return math.degrees(2.0 * math.atan(1.05 * math.tan(half)))

    def light_position(self, light: PointLight) -> np.ndarray:
        t = math.radians(light.theta)
        d = self.effective_light_distance
        return np.array([d * math.sin(t), 0.0, d * math.cos(t)])

    def light_intensity(self, light: PointLight) -> float:
        """Radiant intensity (W/sr) of a light."""
        if light.intensity is not None:
            return light.intensity
        return math.pi * (self.effective_light_distance - self.sphere_radius) ** 2

    def camera_rays(self) -> np.ndarray:
        """Unit directions [H, W, 3] of the rays through the pixel centres."""
        n = self.resolution
        t = math.tan(math.radians(self.effective_fov) / 2.0)
        c = (np.arange(n) + 0.5) / n * 2.0 - 1.0
        x = c[None, :] * t
        y = -c[:, None] * t
        d = np.stack(np.broadcast_arrays(x, y, -np.ones_like(x * y)), axis=-1)
        return d / np.linalg.norm(d, axis=-1, keepdims=True)

    def mask(self) -> np.ndarray:
        """Boolean [H, W]: True on pixels whose centre ray hits the sphere."""
        return _sphere_hits(self)[0]

    def pixel_indices(self) -> np.ndarray:
        """Flat indices (row-major, into H*W) of the sphere pixels; faster than the boolean mask."""
        return _sphere_hits(self)[1]

    def sphere_points(self) -> np.ndarray:
        """World positions [P, 3] of the sphere points seen through the masked pixels (row-major)."""
        return _sphere_hits(self)[2]


@lru_cache(maxsize=32)
def _sphere_hits(scene: Scene) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mask, flat pixel indices and hit points of the camera rays on the sphere (read-only)."""
    d = scene.camera_rays()
    o = np.array([0.0, 0.0, scene.camera_distance])
    b = d @ o
    disc = b * b - (o @ o - scene.sphere_radius**2)
    mask = disc > 0.0
    t = -b - np.sqrt(np.where(mask, disc, 0.0))
    points = (o + t[..., None] * d)[mask]
    out = (mask, np.flatnonzero(mask), points)
    for a in out:
        a.flags.writeable = False
    return out


def parse_lights(values: Iterable[str | float] | None) -> tuple[float, ...]:
    """Light angles from CLI strings, checked."""
    if not values:
        return (0.0,)
    out = []
    for v in values:
        try:
            out.append(float(v))
        except (TypeError, ValueError):
            raise MatremapError(f"--light takes an angle in degrees from the view axis, got {v!r}") from None
    return tuple(out)
