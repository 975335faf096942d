"""The probe scene: a sphere lit by point lights or an environment, seen by a pinhole camera (paper §4).

Plain data that every renderer backend builds the same way:

* sphere of radius ``sphere_radius`` (2) at the origin;
* perspective camera at (0, 0, ``camera_distance``) looking down -z, +y up, square image of
  ``resolution`` pixels, field of view ``fov`` degrees (default: frames the sphere with a 5 % margin);
* point lights at ``light_distance`` (default: the camera distance) from the origin, each at an
  angle ``theta`` (degrees) from the view axis towards +x; theta = 0 is a headlight at the camera.
  A light's radiant intensity defaults to pi (d - r)^2 W/sr, so that a white Lambertian surface
  facing a headlight at the sphere's nearest point has radiance 1.

Images are linear HDR RGB float32 ``[H, W, 3]``; :meth:`Scene.mask` marks sphere pixels.

**Environment probes** (issue 18). The paper fits under a point light and judges under an environment map;
a scene may instead (or as well) light the sphere by an :class:`EnvironmentProbe`: an environment map turned
to a few rotations about +y, each drawn as its own *view* of the sphere, lit by the map's importance-sampled
directional lights (:func:`~matremap.core.envmap.directional_lights`). A scene with point lights and an
environment is the *mixed* probe: the point-light view, then the environment views. A scene of several views
is drawn view by view (:meth:`Scene.views`, each a scene of one view); its pixels are the views' sphere
pixels one view after the other, and its image is the views side by side (``[H, V W, 3]``). Each view is
weighted by :meth:`Scene.view_weights` -- the inverse of the mean radiance a white Lambertian sphere has in
it -- so that a bright environment does not drown a point-light view in the least squares (the weights
multiply source and target renders alike, so a fit's optimum in one view is unchanged by them).

**The transmission view** (issue 16). A point-light or environment view draws a material's reflection only; a
scene may add a :class:`TransmissionProbe`, one more view in which the sphere stands in front of a tiled
background under an environment, so that what a transmissive material lets through -- refracted, tinted,
blurred -- is in the image (:mod:`matremap.renderers.embedded.transmission` draws it, on the same camera).
"""

from __future__ import annotations

import hashlib
import math
import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace
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


#: the rotations (degrees about +y) an environment probe fits under by default: none of them is among the
#: evaluation's default rotations (0:360:6, i.e. 0, 60, ..., 300), so a fit is never judged where it was made
FIT_ROTATIONS = (30.0, 150.0, 270.0)
#: the directional lights an environment probe samples per rotation, and its sampling seed (the evaluation's
#: is 0: its light set is another draw of the same map)
FIT_LIGHTS = 64
FIT_SEED = 1


@dataclass(frozen=True)
class EnvironmentProbe:
    """An environment map lighting the probe sphere at each of ``rotations`` (degrees about +y), sampled
    into ``lights`` directional lights with ``seed``. ``env`` is ``'builtin'``, ``'constant'`` or an
    .exr/.hdr path; ``digest`` is the file's SHA-256 (:meth:`of` fills it), so that a sweep's key changes
    when the map's content does."""

    env: str = "builtin"
    rotations: tuple[float, ...] = FIT_ROTATIONS
    lights: int = FIT_LIGHTS
    seed: int = FIT_SEED
    digest: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "rotations", tuple(float(r) for r in self.rotations))
        if not self.rotations or not all(math.isfinite(r) for r in self.rotations):
            raise MatremapError("an environment probe needs at least one finite rotation (degrees)")
        if not isinstance(self.lights, int) or not 1 <= self.lights <= 4096:
            raise MatremapError(f"an environment probe takes 1 to 4096 lights per rotation, got {self.lights!r}")

    @classmethod
    def of(cls, env: str | os.PathLike, **kw: Any) -> EnvironmentProbe:
        """The probe of the map ``env`` ('builtin', 'constant' or a file, checked and digested now)."""
        name = str(env)
        digest = ""
        if name not in ("builtin", "constant"):
            from matremap.core.envmap import load

            load(name)  # one clear error now for a missing or unreadable map
            with open(name, "rb") as f:
                digest = hashlib.sha256(f.read()).hexdigest()
            name = os.path.abspath(name)
        return cls(env=name, digest=digest, **kw)

    def label(self) -> str:
        env = self.env if self.env in ("builtin", "constant") else os.path.basename(self.env)
        turns = ", ".join(f"{r:g}" for r in self.rotations)
        return f"{env} at {turns} deg, {self.lights} lights"

    def to_dict(self) -> dict[str, Any]:
        return {
            "env": self.env,
            "rotations": list(self.rotations),
            "lights": self.lights,
            "seed": self.seed,
            "digest": self.digest,
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> EnvironmentProbe:
        return cls(
            env=str(d.get("env", "builtin")),
            rotations=tuple(d.get("rotations", FIT_ROTATIONS)),
            lights=int(d.get("lights", FIT_LIGHTS)),
            seed=int(d.get("seed", FIT_SEED)),
            digest=str(d.get("digest", "")),
        )

    def directional(self, rotation: float) -> tuple[np.ndarray, np.ndarray]:
        """Unit directions towards the lights [L, 3] and their RGB intensities [L, 3] at ``rotation``."""
        return _directional(self.env, self.lights, float(rotation), self.seed)


@lru_cache(maxsize=64)
def _directional(env: str, lights: int, rotation: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    from matremap.core.envmap import directional_lights, resolve

    d, i = directional_lights(resolve(env), lights, rotation, seed)
    d.flags.writeable = False
    i.flags.writeable = False
    return d, i


@dataclass(frozen=True)
class TransmissionProbe:
    """The transmission view: the sphere in front of the tiled background under the map ``env`` ('builtin',
    'constant' or an .exr/.hdr, digested like :class:`EnvironmentProbe`), its reflection drawn by ``lights``
    directional lights of the map, a rough interface traced along ``samples`` fixed paths per pixel, ``bounces``
    internal reflections followed (:class:`~matremap.renderers.embedded.transmission.TransmissionScene`)."""

    env: str = "builtin"
    lights: int = FIT_LIGHTS
    samples: int = 8
    bounces: int = 4
    digest: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.lights, int) or not 1 <= self.lights <= 4096:
            raise MatremapError(f"the transmission probe takes 1 to 4096 lights, got {self.lights!r}")
        if not isinstance(self.samples, int) or not 1 <= self.samples <= 1024:
            raise MatremapError(f"the transmission probe takes 1 to 1024 paths per pixel, got {self.samples!r}")
        if not isinstance(self.bounces, int) or not 1 <= self.bounces <= 64:
            raise MatremapError(f"the transmission probe follows 1 to 64 internal bounces, got {self.bounces!r}")

    @classmethod
    def of(cls, env: str | os.PathLike, **kw: Any) -> TransmissionProbe:
        """The probe under the map ``env``, a file checked and digested now."""
        lit = EnvironmentProbe.of(env)
        return cls(env=lit.env, digest=lit.digest, **kw)

    def label(self) -> str:
        env = self.env if self.env in ("builtin", "constant") else os.path.basename(self.env)
        return f"the sphere before a tiled background under {env}, {self.samples} paths per pixel"

    def to_dict(self) -> dict[str, Any]:
        return {
            "env": self.env,
            "lights": self.lights,
            "samples": self.samples,
            "bounces": self.bounces,
            "digest": self.digest,
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> TransmissionProbe:
        return cls(
            env=str(d.get("env", "builtin")),
            lights=int(d.get("lights", FIT_LIGHTS)),
            samples=int(d.get("samples", 8)),
            bounces=int(d.get("bounces", 4)),
            digest=str(d.get("digest", "")),
        )

    def directional(self) -> tuple[np.ndarray, np.ndarray]:
        """The directional lights [L, 3] towards them and RGB intensities [L, 3] drawing the reflection (the
        map unturned, seed 0: what the transmission probe samples)."""
        return _directional(self.env, self.lights, 0.0, 0)


@dataclass(frozen=True)
class Scene:
    resolution: int = 128
    lights: tuple[PointLight, ...] = (PointLight(),)
    camera_distance: float = 8.0
    sphere_radius: float = 2.0
    light_distance: float | None = None
    fov: float | None = None
    #: an environment lighting the sphere in views of its own (see the module docstring)
    environment: EnvironmentProbe | None = None
    #: one more view: the sphere before a tiled background, for what a material transmits (module docstring)
    transmission: TransmissionProbe | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.resolution, int) or not 8 <= self.resolution <= 8192:
            raise MatremapError(f"scene resolution must be an integer in [8, 8192], got {self.resolution!r}")
        if not self.lights and self.environment is None and self.transmission is None:
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
        d = {
            "resolution": self.resolution,
            "lights": [light.to_dict() for light in self.lights],
            "camera_distance": self.camera_distance,
            "sphere_radius": self.sphere_radius,
            "light_distance": self.effective_light_distance,
            "fov": self.effective_fov,
        }
        if self.environment is not None:  # absent for the point-light probe: its keys stay as they were
            d["environment"] = self.environment.to_dict()
        if self.transmission is not None:
            d["transmission"] = self.transmission.to_dict()
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Scene:
        lights = tuple(PointLight(**light) for light in d.get("lights", [{"theta": 0.0}]))
        kw = {k: d[k] for k in ("resolution", "camera_distance", "sphere_radius", "light_distance", "fov") if k in d}
        env, through = d.get("environment"), d.get("transmission")
        return cls(
            lights=lights,
            environment=EnvironmentProbe.from_dict(env) if env else None,
            transmission=TransmissionProbe.from_dict(through) if through else None,
            **kw,
        )

    # -- views ---------------------------------------------------------------------------------
    @property
    def kind(self) -> str:
        """``point`` (the paper's), ``env``, ``mixed`` (point lights and an environment) or ``transmission``
        (any of them and the transmission view)."""
        if self.transmission is not None:
            return "transmission"
        if self.environment is None:
            return "point"
        return "mixed" if self.lights else "env"

    def describe(self) -> str:
        """The probe in words, for logs and reports."""
        parts = []
        if self.lights:
            parts.append(f"{len(self.lights)} point light(s) at {', '.join(f'{lt.theta:g}' for lt in self.lights)} deg")
        if self.environment is not None:
            parts.append(f"environment {self.environment.label()}")
        if self.transmission is not None:
            parts.append(f"transmission view: {self.transmission.label()}")
        return f"{self.kind} probe: " + " + ".join(parts)

    def views(self) -> tuple[Scene, ...]:
        """The scenes of one view each that make up this one: the point-light view, then one per rotation
        of the environment, then the transmission view; a scene of one view is its own only view."""
        return _views(self)

    @property
    def view_count(self) -> int:
        env = len(self.environment.rotations) if self.environment else 0
        return (1 if self.lights else 0) + env + (1 if self.transmission else 0)

    def view_weights(self) -> np.ndarray:
        """Per view, 1 / (the mean radiance of a white Lambertian sphere in it); all 1 for a one-view scene."""
        return _view_weights(self)

    @property
    def grey_lighting(self) -> bool:
        """Whether every light is white, so that a grey material renders a grey image (the fitter's grey
        and packed shortcuts rely on it): point lights are; an environment's lights are when the map is grey; the
        transmission view's background is coloured."""
        if self.transmission is not None:
            return False
        if self.environment is None:
            return True
        env = self.environment
        return all(_grey(env.directional(r)[1]) for r in env.rotations)

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
        """Boolean [H, V W]: True on pixels whose centre ray hits the sphere (the views side by side)."""
        return _sphere_hits(self)[0]

    def pixel_indices(self) -> np.ndarray:
        """Flat indices (into the [H, V W] image) of the sphere pixels, view after view and row-major in
        each; faster than the boolean mask."""
        return _sphere_hits(self)[1]

    def sphere_points(self) -> np.ndarray:
        """World positions [V P, 3] of the sphere points seen through the masked pixels (in
        :meth:`pixel_indices` order)."""
        return _sphere_hits(self)[2]


def _grey(intensities: np.ndarray) -> bool:
    return bool(np.all(np.abs(intensities - intensities[:, :1]) <= 1e-12 * np.max(np.abs(intensities))))


@lru_cache(maxsize=32)
def _views(scene: Scene) -> tuple[Scene, ...]:
    if scene.view_count == 1:
        return (scene,)
    out = [replace(scene, environment=None, transmission=None)] if scene.lights else []
    env = scene.environment
    if env is not None:
        out += [
            replace(scene, lights=(), environment=replace(env, rotations=(r,)), transmission=None)
            for r in env.rotations
        ]
    if scene.transmission is not None:
        out.append(replace(scene, lights=(), environment=None))
    return tuple(out)


@lru_cache(maxsize=32)
def _view_weights(scene: Scene) -> np.ndarray:
    views = scene.views()
    if len(views) == 1:
        w = np.ones(1)
    else:
        w = np.array([1.0 / max(white_radiance(v), 1e-12) for v in views])
    w.flags.writeable = False
    return w


def white_radiance(view: Scene) -> float:
    """Mean luminance over the sphere pixels of a white Lambertian (albedo 1) in a one-view scene:
    sum over lights of E cos(theta_i) / pi (E = I / d^2 for a point light, the intensity for a directional
    one)."""
    p = _sphere_hits(replace(view, lights=view.lights or (PointLight(),), environment=None, transmission=None))[2]
    n = p / np.linalg.norm(p, axis=-1, keepdims=True)
    total = np.zeros(len(p))
    for light in view.lights:
        to_light = view.light_position(light) - p
        d2 = np.sum(to_light * to_light, axis=-1)
        cos = np.maximum(np.sum(to_light * n, axis=-1) / np.sqrt(d2), 0.0)
        total += view.light_intensity(light) / d2 * cos
    directional = [view.environment.directional(r) for r in view.environment.rotations] if view.environment else []
    if view.transmission is not None:
        directional.append(view.transmission.directional())
    if directional:
        from matremap.core.envmap import LUMINANCE

        for d, i in directional:
            total += np.maximum(n @ d.T, 0.0) @ (i @ LUMINANCE)
    return float(np.mean(total) / math.pi)


@lru_cache(maxsize=32)
def _sphere_hits(scene: Scene) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mask, flat pixel indices and hit points of the camera rays on the sphere (read-only), for every view
    (the camera is the same in each)."""
    views = scene.view_count
    if views > 1:
        single = replace(scene, lights=(PointLight(),), environment=None, transmission=None)
        mask1, pix1, points1 = _sphere_hits(single)
        n = scene.resolution
        rows, cols = pix1 // n, pix1 % n
        pix = np.concatenate([rows * (views * n) + v * n + cols for v in range(views)])
        out = (np.tile(mask1, (1, views)), pix, np.tile(points1, (views, 1)))
        for a in out:
            a.flags.writeable = False
        return out
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


#: the probes ``--probe`` names
PROBES = ("point", "env", "mixed", "transmission")
#: the default image side of each probe: an environment view shades 64 lights per pixel where the point probe
#: shades one; at 64 x 64 an environment fit under SSIM takes 1-2 s and lands within 1 % of the floor measured at
#: 160 x 160 on the examples (benchmarks/ssim_floor.py)
PROBE_RESOLUTION = {"point": 128, "env": 64, "mixed": 64, "transmission": 64}


def parse_probe(text: str, lights: Iterable[float] = (0.0,), resolution: int | None = None) -> Scene:
    """The probe scene ``--probe`` names: ``point`` (the paper's, point ``lights`` at their angles), ``env`` or
    ``env:FILE`` (the sphere under the built-in studio or an .exr/.hdr lat-long map at the
    :data:`FIT_ROTATIONS`), ``mixed`` or ``mixed:FILE`` (both), ``transmission`` or ``transmission:FILE`` (the
    point lights and the transmission view under the map); ``resolution`` None takes the probe's default."""
    kind, _, env = str(text).partition(":")
    if kind not in PROBES or (kind == "point" and env):
        raise MatremapError(
            f"--probe {text!r}: give point, env, env:FILE.exr, mixed, mixed:FILE.exr, transmission or "
            "transmission:FILE.exr"
        )
    res = resolution or PROBE_RESOLUTION[kind]
    angles = tuple(float(t) for t in lights)
    if kind == "point":
        return Scene.probe(lights=angles, resolution=res)
    if kind == "transmission":
        return transmission_probe(Scene.probe(lights=angles, resolution=res), env or "builtin")
    probe = EnvironmentProbe.of(env or "builtin")
    point = tuple(PointLight(t) for t in angles) if kind == "mixed" else ()
    return Scene(resolution=res, lights=point, environment=probe)


def transmission_probe(scene: Scene, env: str | os.PathLike | None = None) -> Scene:
    """``scene`` with the transmission view added, for a material that lets light through: its point lights
    (the headlight if it has none) at the transmission probe's resolution at most, and the transmission view under
    ``env`` (default: the scene's environment's map, else the built-in studio). An environment's views are
    dropped: the transmission view is drawn under its map already."""
    if scene.transmission is not None:
        return scene
    name = env if env is not None else (scene.environment.env if scene.environment is not None else "builtin")
    through = TransmissionProbe.of(name)
    res = min(scene.resolution, PROBE_RESOLUTION["transmission"])
    return replace(
        scene, resolution=res, lights=scene.lights or (PointLight(),), environment=None, transmission=through
    )


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
