"""The real Mitsuba 3 renderer (PyPI ``mitsuba``), behind the same protocol as the embedded one.

Install with ``pip install 'matremap[mitsuba]'`` (or ``pip install mitsuba``). Importing this module
does not import Mitsuba: the renderer imports it when it is created and says how to install it when that fails.

The probe scene is built exactly as the embedded renderer sees it (see :mod:`matremap.core.scene`):

* a ``sphere`` of the scene's radius at the origin carrying the material's BSDF;
* a ``perspective`` sensor at (0, 0, d) looking at the origin, +y up, ``fov`` = the scene's full
  field of view along x, an ``hdrfilm`` of the scene's resolution with a ``box`` reconstruction filter;
* the ``direct`` integrator (one emitter sample, no BSDF samples: a point light cannot be hit by
  BSDF sampling) with a ``stratified`` sampler, ``jitter=false`` and 1 sample per pixel: the one
  camera ray of each pixel goes through the pixel centre, so a render is deterministic and
  noise-free, and equal to the embedded renderer's geometry to float32 precision;
* one scene per point light, summed: Mitsuba's emitter sampling picks *one* light per sample,
  which would make multi-light renders noisy; with one light per scene the point light is
  sampled deterministically. Each point light has ``intensity`` = the scene's radiant intensity.

A loaded scene is cached per (scene, light, model, options); a batch of images (:meth:`Mitsuba3Renderer.render`)
is a loop that changes the BSDF's parameters with ``mi.traverse`` and renders again (``spp`` and ``seed`` are
always passed to ``mi.render``: Mitsuba otherwise keeps the last call's sample count).

Variants: ``auto`` by default, as for the environment renders: ``llvm_ad_rgb`` when it works here, else
``scalar_rgb`` (which works from the wheel alone). Any ``*_rgb`` variant may be chosen with
``Mitsuba3Renderer(variant=...)`` or the environment variable ``MATREMAP_MITSUBA_VARIANT``; ``llvm_ad_rgb``
needs a libLLVM >= 17 (Debian ``libllvm19``, which Mitsuba finds without any environment variable even next
to LLVM 14/15; LLVM 15 and 16 crash inside Mitsuba on the first render, which cannot be caught), so
``auto`` picks it only when such a library is found and a tiny render in a child process succeeds
(:func:`llvm_renders`, ~2 s once per process). It agrees with ``scalar_rgb`` to 2e-6 and renders ~2x
faster here (centre rays; 8x at 256 spp).

Batches (:meth:`Mitsuba3Renderer.render_pixels`, what fits call): in a JIT variant no image is rendered;
Mitsuba's own probe rays, intersections and light samples are made once per scene and light, and each
material's BSDF is evaluated over all of them with ``BSDF.eval`` by one reused compiled kernel: equal to
the rendered pixels, ~0.2 ms per material at 128^2 instead of 6-20 ms. ``roughplastic`` is the exception
in cost: Mitsuba rebuilds its rough-transmittance table whenever ``alpha`` or ``eta`` changes (~25-35 ms).

The models and their parameters are in :mod:`matremap.dialects.mitsuba3`.
"""

from __future__ import annotations

import os
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from matremap.core.material import Material, SVMaterial
from matremap.core.scene import Scene
from matremap.dialects.mitsuba3 import (
    CONDUCTORS,
    DIFFUSE,
    DISTRIBUTIONS,
    PRINCIPLED,
    ROUGHCONDUCTOR,
    ROUGHPLASTIC,
)
from matremap.errors import MatremapError
from matremap.renderers.base import EnvironmentLight, EnvironmentRender, check_can_render, check_environment
from matremap.renderers.mitsuba3.environment import NOT_TEXTURABLE, Mitsuba3EnvironmentRender
from matremap.renderers.mitsuba3.plugins import (
    GLASS_PLUGINS,
    INSTALL_HINT,
    MODELS,
    Binding,
    bsdf_dict,
    choose_variant,
    import_mitsuba,
    llvm_renders,
    llvm_usable,
    mitsuba_call,
    mitsuba_installed,
    probe_sensor,
)

#: models whose IORs Mitsuba keeps as one ``eta`` = int_ior / ext_ior, set through ``mi.traverse``
ETA_MODELS = ("mitsuba3:roughplastic", *GLASS_PLUGINS)


class _Loaded:
    """One loaded Mitsuba scene (one light) and its traversed parameters."""

    def __init__(self, mi, scene_dict: dict[str, Any], bindings: list[Binding], model: str) -> None:
        self.mi = mi
        self.model = model
        self.scene = mitsuba_call(mi, "load the probe scene", mi.load_dict, scene_dict)
        self.params = mi.traverse(self.scene)
        self.bindings = bindings
        self.current: dict[str, np.ndarray] = {}

    def set(self, m: Material) -> None:
        """Write the material's values into the scene (only those that changed)."""
        mi, changed = self.mi, False
        for b in self.bindings:
            v = m.values[b.param]
            old = self.current.get(b.param)
            if old is not None and np.array_equal(old, v):
                continue
            key = "sphere.bsdf." + b.key
            self.params[key] = mi.Color3f(*(float(x) for x in v)) if b.rgb else mi.Float(float(v[0]))
            self.current[b.param] = v.copy()
            changed = True
        if self.model in ETA_MODELS:
            eta = m.values["int_ior"] / m.values["ext_ior"]
            old_eta = self.current.get("eta")
            if old_eta is None or not np.array_equal(old_eta, eta):
                self.params["sphere.bsdf.eta"] = mi.Float(float(eta[0]))
                self.current["eta"] = eta
                changed = True
        if changed:
            mitsuba_call(mi, "update the material", self.params.update)


class _ProbeSamples:
    """The probe's shading points as Mitsuba sees them, for one light: the centre ray of each sphere pixel
    (``scene.pixel_indices()`` order) through the probe's sensor, its intersection with the sphere and the
    light's sample there (``Scene.sample_emitter_direction``, visibility tested), as Dr.Jit arrays."""

    def __init__(self, mi, loaded: _Loaded, scene: Scene) -> None:
        import drjit as dr

        res = scene.resolution
        pix = scene.pixel_indices()
        iy, ix = pix // res, pix % res
        position = mi.Point2f(mi.Float((ix + 0.5) / res), mi.Float((iy + 0.5) / res))
        sensor = loaded.scene.sensors()[0]
        ray, _ = sensor.sample_ray(0.0, 0.5, position, mi.Point2f(0.5, 0.5))
        self.si = loaded.scene.ray_intersect(ray)
        ds, weight = loaded.scene.sample_emitter_direction(self.si, mi.Point2f(0.5, 0.5), True)
        self.wo = self.si.to_local(ds.d)
        self.weight = dr.select(self.si.is_valid(), weight, 0.0)
        self.context = mi.BSDFContext()
        dr.eval(self.si, self.wo, self.weight)


class _Bsdf:
    """One BSDF object of a (model, options) and its traversed parameters, re-set per material."""

    def __init__(self, mi, m: Material) -> None:
        bsdf, self.bindings = bsdf_dict(m.model, dict(m.options), m)
        self.mi = mi
        self.model = m.model
        self.bsdf = mitsuba_call(mi, "load the BSDF", mi.load_dict, bsdf)
        self.params = mi.traverse(self.bsdf)
        self.current: dict[str, np.ndarray] = {b.param: m.values[b.param].copy() for b in self.bindings}
        if m.model in ETA_MODELS:
            self.current["eta"] = m.values["int_ior"] / m.values["ext_ior"]

    def set(self, m: Material) -> None:
        """Write the material's values into the BSDF (only those that changed)."""
        mi, changed = self.mi, False
        for b in self.bindings:
            v = m.values[b.param]
            if np.array_equal(self.current[b.param], v):
                continue
            self.params[b.key] = mi.Color3f(*(float(x) for x in v)) if b.rgb else mi.Float(float(v[0]))
            self.current[b.param] = v.copy()
            changed = True
        if self.model in ETA_MODELS:
            eta = m.values["int_ior"] / m.values["ext_ior"]
            if not np.array_equal(self.current["eta"], eta):
                self.params["eta"] = mi.Float(float(eta[0]))
                self.current["eta"] = eta
                changed = True
        if changed:
            mitsuba_call(mi, "update the material", self.params.update)

    def shade(self, probe: _ProbeSamples) -> np.ndarray:
        """float32 [P, 3]: the BSDF (cosine included) times the light's weight at every probe point, which is
        what the ``direct`` integrator adds per pixel for a point light (its MIS weight is 1)."""
        value = self.bsdf.eval(probe.context, probe.si, probe.wo) * probe.weight
        return np.asarray(value, dtype=np.float32).T


class Mitsuba3Renderer:
    """The probe scene rendered by Mitsuba 3 (``mitsuba3:*`` models).

    ``spp=1`` (default) shoots one ray through each pixel centre: deterministic and noise-free, the
    same pixels as the embedded renderer. ``spp > 1`` jitters stratified samples inside each pixel
    (box filter, ``seed``): an anti-aliased render that no longer equals the centre-ray images.
    """

    name = "mitsuba3"

    def __init__(self, variant: str | None = None, spp: int = 1, seed: int = 0, cache_size: int = 64) -> None:
        self._configure(variant, spp, seed, cache_size)

    def _configure(self, variant: str | None, spp: int, seed: int, cache_size: int) -> None:
        """Set up a renderer with an empty scene cache (``__init__``, and ``__setstate__`` in a process pool)."""
        self.mi = import_mitsuba()
        # as the environment renders: the JIT variant when it works here (vectorised probe renders)
        self.variant = choose_variant(self.mi, variant or os.environ.get("MATREMAP_MITSUBA_VARIANT") or "auto")
        if not (isinstance(spp, int) and spp >= 1):
            raise MatremapError(f"spp must be a positive integer, got {spp!r}")
        self.spp = spp
        self.seed = int(seed)
        self.cache_size = cache_size
        self._cache: OrderedDict[tuple, _Loaded] = OrderedDict()
        self._probe_samples: dict[tuple[Scene, int], _ProbeSamples] = {}
        self._bsdfs: dict[tuple, _Bsdf] = {}
        self.renders = 0  # images rendered by Mitsuba (one per material and light)
        self._activate()

    def __repr__(self) -> str:
        return f"Mitsuba3Renderer(variant={self.variant!r}, spp={self.spp})"

    def __getstate__(self) -> dict[str, Any]:  # for process pools: scenes are rebuilt in the worker
        return {"variant": self.variant, "spp": self.spp, "seed": self.seed, "cache_size": self.cache_size}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self._configure(**state)

    def _activate(self) -> None:
        if self.mi.variant() != self.variant:
            self.mi.set_variant(self.variant)
            self._cache.clear()  # scenes of another variant are unusable
            self._probe_samples.clear()
            self._bsdfs.clear()

    # -- protocol ----------------------------------------------------------------------------
    @classmethod
    def can_render(cls, model_id: str) -> bool:
        return model_id in MODELS

    @classmethod
    def environment_support(cls, model_id: str, geometry: str) -> str | None:
        """Mitsuba 3 draws its own models on the sphere, when it is installed."""
        if model_id not in MODELS:
            return f"Mitsuba 3 does not draw {model_id}"
        if geometry != "sphere":
            return f"{model_id} is drawn by Mitsuba 3, which renders the sphere only; use --geometry sphere"
        return None if mitsuba_installed() else INSTALL_HINT

    @classmethod
    def supports_textures(cls, model_id: str, param: str) -> bool:
        return param not in NOT_TEXTURABLE.get(model_id, ())

    def prepare_environment(
        self, material: SVMaterial, light: EnvironmentLight, geometry: str, resolution: int, part: str
    ) -> EnvironmentRender:
        check_environment(self, material, geometry, resolution, part)
        return Mitsuba3EnvironmentRender(material, light.env, resolution, part)

    def render(self, materials: Sequence[Material], scene: Scene) -> np.ndarray:
        """float32 [N, H, W, 3], linear radiance."""
        materials = list(materials)
        check_can_render(self, materials)
        self._activate()
        res = scene.resolution
        out = np.zeros((len(materials), res, res, 3), dtype=np.float32)
        for i, m in enumerate(materials):
            for light in range(len(scene.lights)):
                out[i] += self._render_one(m, scene, light)
        return out

    #: materials per render call a caller should batch (:func:`matremap.core.lockstep.lockstep`)
    batch_size = 512

    @property
    def vectorised(self) -> bool:
        """Whether the variant is a JIT one (llvm, cuda): the BSDF is then evaluated over all the probe's
        shading points at once (:meth:`render_pixels`) instead of rendering an image per material."""
        return self.spp == 1 and not self.variant.startswith("scalar_")

    def render_pixels(self, materials: Sequence[Material], scene: Scene) -> np.ndarray:
        """The sphere pixels of :meth:`render`, float32 [N, P, 3] in ``scene.pixel_indices()`` order.

        In a JIT variant (:attr:`vectorised`) no image is rendered: per light, Mitsuba's own centre rays,
        intersections and light samples of the probe are made once (cached with the scene) and each
        material's BSDF is evaluated over all of them with ``BSDF.eval`` -- the sum the ``direct``
        integrator makes, equal to the rendered pixels (tests/test_lockstep.py). A BSDF object per
        (model, options) is re-set per material through ``mi.traverse`` and evaluated by the same compiled
        kernel every time (Dr.Jit reuses a kernel whose trace is unchanged; the values are not baked in),
        so a batch of N materials costs N kernel launches and no compilation after the first."""
        materials = list(materials)
        if not self.vectorised:
            images = self.render(materials, scene)
            return np.take(images.reshape(len(images), -1, 3), scene.pixel_indices(), axis=1)
        check_can_render(self, materials)
        self._activate()
        out = np.zeros((len(materials), scene.pixel_indices().size, 3), dtype=np.float32)
        for light in range(len(scene.lights)):
            for i, m in enumerate(materials):
                probe = self._samples(m, scene, light)
                bsdf = self._bsdf(m)
                bsdf.set(m)
                out[i] += mitsuba_call(self.mi, "render", bsdf.shade, probe)
                self.renders += 1
        return out

    def _samples(self, m: Material, scene: Scene, light: int) -> _ProbeSamples:
        """The probe's shading points for one light (the intersections do not depend on the BSDF)."""
        key = (scene, light)
        hit = self._probe_samples.get(key)
        if hit is None:
            hit = self._probe_samples[key] = _ProbeSamples(self.mi, self._loaded(m, scene, light), scene)
        return hit

    def _bsdf(self, m: Material) -> _Bsdf:
        key = (m.model, tuple(sorted(m.options.items())))
        hit = self._bsdfs.get(key)
        if hit is None:
            hit = self._bsdfs[key] = _Bsdf(self.mi, m)
        return hit

    # -- internals ---------------------------------------------------------------------------
    def _render_one(self, m: Material, scene: Scene, light: int) -> np.ndarray:
        loaded = self._loaded(m, scene, light)
        loaded.set(m)
        img = mitsuba_call(self.mi, "render", self.mi.render, loaded.scene, spp=self.spp, seed=self.seed)
        self.renders += 1
        return np.asarray(img, dtype=np.float32).reshape(scene.resolution, scene.resolution, -1)[..., :3]

    def _loaded(self, m: Material, scene: Scene, light: int) -> _Loaded:
        options = dict(m.options)
        key = (scene, light, m.model, tuple(sorted(options.items())))
        hit = self._cache.get(key)
        if hit is not None:
            self._cache.move_to_end(key)
            return hit
        bsdf, bindings = bsdf_dict(m.model, options, m)
        loaded = _Loaded(self.mi, self.scene_dict(scene, light, bsdf), bindings, m.model)
        loaded.current = {b.param: m.values[b.param].copy() for b in bindings}
        if m.model in ETA_MODELS:
            loaded.current["eta"] = m.values["int_ior"] / m.values["ext_ior"]
        self._cache[key] = loaded
        while len(self._cache) > self.cache_size:
            self._cache.popitem(last=False)
        return loaded

    def scene_dict(self, scene: Scene, light: int, bsdf: dict[str, Any]) -> dict[str, Any]:
        """The ``mi.load_dict`` dictionary of the probe scene with one of its lights."""
        mi = self.mi
        jitter = self.spp > 1
        lt = scene.lights[light]
        return {
            "type": "scene",
            "integrator": {"type": "direct", "emitter_samples": 1, "bsdf_samples": 0},
            "sensor": probe_sensor(
                mi, scene, {"type": "stratified", "sample_count": self.spp, "jitter": jitter, "seed": self.seed}
            ),
            "sphere": {"type": "sphere", "center": [0.0, 0.0, 0.0], "radius": float(scene.sphere_radius), "bsdf": bsdf},
            "light": {
                "type": "point",
                "position": [float(x) for x in scene.light_position(lt)],
                "intensity": {"type": "rgb", "value": float(scene.light_intensity(lt))},
            },
        }


@dataclass(frozen=True)
class AutodiffFit:
    """The result of :func:`fit_roughconductor_autodiff`."""

    material: Material
    loss: float  # sum of squared differences over sphere pixels / sum of squared target values
    evaluations: int  # forward + backward renders (each one Mitsuba image per light)
    seconds: float


def _autodiff_mitsuba() -> Any:
    """Mitsuba switched to ``llvm_ad_rgb`` (process-wide), or an error saying what it needs."""
    mi = import_mitsuba()
    if "llvm_ad_rgb" not in mi.variants() or not llvm_renders():
        raise MatremapError("gradient-based fitting needs Mitsuba's llvm_ad_rgb variant: install Debian libllvm19")
    if mi.variant() != "llvm_ad_rgb":
        mi.set_variant("llvm_ad_rgb")
    return mi


def _autodiff_inputs(
    target: np.ndarray, scene: Scene, distribution: str, start: Material | None
) -> tuple[np.ndarray, Material]:
    """The target image and the starting rough conductor of :func:`fit_roughconductor_autodiff`, checked."""
    res = scene.resolution
    target = np.asarray(target, dtype=np.float32)
    if target.shape != (res, res, 3):
        raise MatremapError(f"the target image must be [{res}, {res}, 3], got shape {target.shape}")
    if distribution not in DISTRIBUTIONS:
        raise MatremapError(f"distribution must be one of {', '.join(DISTRIBUTIONS)}, got {distribution!r}")
    m0 = start or Material.create(
        "mitsuba3:roughconductor", {"distribution": distribution, "alpha": 0.2, "eta": 1.0, "k": 2.0}
    )
    if m0.model != "mitsuba3:roughconductor" or m0.options.get("material", "custom") != "custom":
        raise MatremapError("the start must be a mitsuba3:roughconductor with material=custom")
    return target, m0.with_params({"distribution": distribution})


def fit_roughconductor_autodiff(
    target: np.ndarray,
    scene: Scene,
    distribution: str = "ggx",
    start: Material | None = None,
    max_evaluations: int = 200,
) -> AutodiffFit:
    """Fit ``mitsuba3:roughconductor`` (``alpha`` and RGB ``k``; ``eta`` held at the start's, 1 by
    default) to ``target``, an image [H, W, 3] of ``scene`` (all its lights), with gradients from
    Mitsuba's autodiff (``llvm_ad_rgb``, which must render here: :func:`llvm_renders`).

    L-BFGS-B on log alpha and log k, one forward and one backward render per evaluation, centre
    rays (noise-free, as :class:`Mitsuba3Renderer`). Only the rough conductor: Mitsuba 3.9's
    gradient of ``roughplastic``'s alpha is wrong (it ignores the diffuse layer's dependence on
    alpha) and ``principled``'s roughness is ~2 % off, so fit those with :func:`matremap.core.fit.fit`
    (finite differences). Switches Mitsuba to ``llvm_ad_rgb`` (process-wide).
    """
    import time

    from scipy.optimize import minimize

    t0 = time.perf_counter()
    mi = _autodiff_mitsuba()
    import drjit as dr

    target, m0 = _autodiff_inputs(target, scene, distribution, start)
    renderer = Mitsuba3Renderer(variant="llvm_ad_rgb")  # for its scene_dict: centre rays, 1 spp
    bsdf, _ = bsdf_dict(m0.model, dict(m0.options), m0)
    scenes = [
        mitsuba_call(mi, "load the probe scene", mi.load_dict, renderer.scene_dict(scene, i, bsdf))
        for i in range(len(scene.lights))
    ]
    params = [mi.traverse(s) for s in scenes]
    mask = np.repeat(scene.mask()[..., None], 3, axis=2).astype(np.float32)
    tgt = mi.TensorXf(target * mask)
    msk = mi.TensorXf(mask)
    norm = float(np.sum((target * mask).astype(np.float64) ** 2)) or 1.0
    evaluations = 0

    def loss_and_grad(x: np.ndarray) -> tuple[float, np.ndarray]:
        nonlocal evaluations
        evaluations += 1
        a = mi.Float(float(np.exp(x[0])))
        k = mi.Color3f(*(float(v) for v in np.exp(x[1:])))
        dr.enable_grad(a, k)
        img = None
        for s, p in zip(scenes, params, strict=True):
            p["sphere.bsdf.alpha.value"] = a
            p["sphere.bsdf.k.value"] = k
            p.update()
            one = mi.render(s, p, spp=1, seed=0, seed_grad=1)
            img = one if img is None else img + one
        loss = dr.sum(dr.square(img * msk - tgt), axis=None) / norm
        dr.backward(loss)
        ga = float(np.asarray(dr.grad(a)).ravel()[0])
        gk = np.asarray(dr.grad(k), dtype=float).ravel()[:3]
        value = float(np.asarray(loss).ravel()[0])
        return value, np.concatenate([[ga * np.exp(x[0])], gk * np.exp(x[1:])])

    spec = ROUGHCONDUCTOR
    lo_a, hi_a = spec.param("alpha").bounds
    hi_k = spec.param("k").bounds[1]
    x0 = np.log(np.concatenate([m0.values["alpha"][:1], np.clip(m0.values["k"], 1e-3, hi_k)]))
    bounds = [(np.log(lo_a), np.log(hi_a))] + [(np.log(1e-3), np.log(hi_k))] * 3
    r = mitsuba_call(
        mi,
        "fit",
        minimize,
        loss_and_grad,
        x0,
        jac=True,
        method="L-BFGS-B",
        bounds=bounds,
        options={"maxfun": max_evaluations, "ftol": 1e-12, "gtol": 1e-9},
    )
    best = m0.with_params({"alpha": float(np.exp(r.x[0])), "k": np.exp(r.x[1:]).tolist()})
    return AutodiffFit(best, float(r.fun), evaluations, time.perf_counter() - t0)


__all__ = [
    "AutodiffFit",
    "CONDUCTORS",
    "DIFFUSE",
    "INSTALL_HINT",
    "MODELS",
    "Mitsuba3Renderer",
    "PRINCIPLED",
    "ROUGHCONDUCTOR",
    "ROUGHPLASTIC",
    "choose_variant",
    "fit_roughconductor_autodiff",
    "import_mitsuba",
    "llvm_renders",
    "llvm_usable",
]
