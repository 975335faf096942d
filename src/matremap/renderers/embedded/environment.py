"""The embedded renderer's environment face: textured materials under an environment map.

The evaluation scene (:mod:`matremap.renderers.textured`: sphere or tilted plane, UVs, normal maps) lit by
an :class:`~matremap.core.envmap.EnvMap` sampled into directional lights
(:func:`~matremap.core.envmap.directional_lights`), shaded by the embedded evaluators. One ray through
each pixel centre, no shadows other than cos > 0: deterministic bit for bit.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from matremap.core.envmap import EnvMap, directional_lights
from matremap.core.models import ModelSpec
from matremap.dialects import get_model
from matremap.errors import MatremapError
from matremap.renderers.base import MIRROR_SAMPLES, PARTS, EnvironmentLight
from matremap.renderers.embedded.geometry import LocalGeometry
from matremap.renderers.embedded.microfacet import ALPHA_MIN
from matremap.renderers.embedded.mirror_samples import density as mirror_density
from matremap.renderers.embedded.mirror_samples import mirror_directions
from matremap.renderers.embedded.mirror_samples import samples as mirror_sample_directions
from matremap.renderers.textured import (
    SurfacePixels,
    check_normal_map,
    check_options,
    sample_texture,
    surface_pixels,
)

#: elements of an [L, P] array per shading chunk: bounds the evaluators' temporaries and keeps them in
#: cache (1 << 16 is 3-4x faster than 1 << 20)
CHUNK_ELEMENTS = 1 << 16

# ---------------------------------------------------------------------------------------------
# parameters


def _per_pixel_params(
    spec: ModelSpec, params: Mapping[str, Any], surf: SurfacePixels, overrides: Mapping[str, float]
) -> dict[str, np.ndarray]:
    """Model parameters as arrays [1, C, 1, P] (textures) or [1, C, 1, 1] (constants)."""
    out: dict[str, np.ndarray] = {}
    for p in spec.params:
        if p.name in overrides:
            raw: Any = overrides[p.name]
        elif p.name in params:
            raw = params[p.name]
        else:
            raw = p.default_array
        a = np.asarray(raw, dtype=float)
        if a.ndim <= 1:  # a constant: scalar or per-channel
            if a.ndim == 1 and a.size not in (1, p.channels):
                raise MatremapError(f"{spec.id}: {p.name} takes {p.channels} value(s), got {a.size}")
            v = np.broadcast_to(a.reshape(-1), (p.channels,)) if a.size == 1 else a
            arr = v.reshape(1, -1, 1, 1)
        else:
            if a.ndim == 3 and a.shape[2] == 1:
                a = a[..., 0]
            if a.ndim == 3 and a.shape[2] != 3 or a.ndim > 3 or min(a.shape[:2]) < 1:
                raise MatremapError(f"{spec.id}: texture {p.name} must be [h, w] or [h, w, 3], got shape {a.shape}")
            if a.ndim == 3 and p.channels == 1:
                if not np.all(a == a[..., :1]):
                    raise MatremapError(
                        f"{spec.id}: {p.name} is a scalar parameter but its texture has different R, G, B; "
                        "give a single-channel map"
                    )
                a = a[..., 0]
            vals = sample_texture(a, surf.uv, surf.wrap_u)  # [P] or [P, 3]
            arr = vals[None, None, None, :] if vals.ndim == 1 else vals.T[None, :, None, :]
        if not np.all(np.isfinite(arr)):
            raise MatremapError(f"{spec.id}: {p.name} has NaN or infinite values")
        out[p.name] = arr
    # grey materials shade the same in every channel: evaluate one channel and broadcast
    if all(v.shape[1] == 1 or np.all(v == v[:, :1]) for v in out.values()):
        out = {k: v[:, :1] for k, v in out.items()}
    return out


def _shading_normals(surf: SurfacePixels, normal_map: np.ndarray | None) -> np.ndarray:
    if normal_map is None:
        return surf.normal
    nm = check_normal_map(normal_map)
    t = sample_texture(nm, surf.uv, surf.wrap_u)
    n = t[:, :1] * surf.tangent + t[:, 1:2] * surf.bitangent + t[:, 2:3] * surf.normal
    length = np.linalg.norm(n, axis=-1, keepdims=True)
    return np.where(length > 1e-12, n / np.maximum(length, 1e-12), surf.normal)


# ---------------------------------------------------------------------------------------------
# rendering


class SVBRDFRender:
    """A material prepared on a geometry: per-pixel parameters and normals, rendered under any
    set of directional lights (the per-rotation loop of an evaluation reuses it)."""

    def __init__(
        self,
        model: str,
        params: Mapping[str, Any],
        options: Mapping[str, str] | None = None,
        geometry: str = "sphere",
        resolution: int = 256,
        part: str = "full",
        normal_map: np.ndarray | None = None,
    ) -> None:
        from matremap.renderers.embedded.evaluators import EVALUATORS, FRAMED

        if part not in PARTS:
            raise MatremapError(f"unknown render part {part!r}; use one of {', '.join(PARTS)}")
        spec = get_model(model)
        if spec.id not in EVALUATORS:
            raise MatremapError(f"model {spec.id} has no embedded evaluator")
        self.spec = spec
        self.evaluator = EVALUATORS[spec.id]
        self.framed = spec.id in FRAMED  # the shading frame is computed for the models that read it
        self.options = check_options(spec, params, options or {})
        self.surface = surface_pixels(geometry, int(resolution))
        overrides = spec.part_overrides(part, params)
        # a model without that part renders black
        self.black = overrides is None
        self.params = {} if overrides is None else _per_pixel_params(spec, params, self.surface, overrides)
        self.normals = _shading_normals(self.surface, normal_map)
        self.resolution = int(resolution)
        # models drawn as Cycles draws them (ModelSpec.normal_mapping == "cycles"): Cycles softens diffuse
        # closures whose normal a normal map bends (bump_shadowing_term) and raises the normal of glossy
        # closures so that the mirror direction stays above the surface
        self.bump_alpha2 = None
        self.specular_params = None  # per-pixel parameters of the glossy closures, when drawn apart
        self.has_diffuse = part != "specular"
        # whether the model has a specular lobe (a specular reflectance; mirror samples serve nothing else);
        # every part of it is sampled alike, so that its parts add up to the full render, but a diffuse part does
        # not draw mirrors: its overrides may switch the lobe off by making it one (glTF's roughness 0)
        self.has_glossy = spec.reflectance is not None
        self.mirror_alpha = ALPHA_MIN if part != "diffuse" else 0.0
        self.glossy_normals = self.normals
        if spec.normal_mapping == "cycles" and normal_map is not None and not self.black:
            self.glossy_normals = ensure_valid_specular_reflection(self.surface.normal, self.surface.view, self.normals)
            self.bump_alpha2 = bump_alpha2(self.surface.normal, self.normals)
            spec_over = spec.part_overrides("specular", params)
            if part == "specular":
                self.specular_params = self.params
            elif part == "full" and spec_over is not None:
                self.specular_params = _per_pixel_params(spec, params, self.surface, spec_over)

    def render(
        self,
        directions: np.ndarray,
        intensities: np.ndarray,
        env: EnvMap | None = None,
        rotation_deg: float = 0.0,
        mirror_samples: int = 0,
    ) -> np.ndarray:
        """Radiance float32 [res, res, 3] under directional lights (unit directions [L, 3] towards
        the light, RGB intensities [L, 3]). With ``env``, the map the lights sample (turned by
        ``rotation_deg``), and ``mirror_samples`` > 0, each pixel also takes that many directions of the map
        about its mirror direction, combined with the lights by multiple importance sampling
        (:mod:`~matremap.renderers.embedded.mirror_samples`): glossy lobes narrower than the lights' spacing,
        and mirrors, then show the map."""
        res = self.resolution
        out = np.zeros((res * res, 3), dtype=np.float32)
        if self.black:
            return out.reshape(res, res, 3)
        wi = np.asarray(directions, dtype=float)
        inten = np.asarray(intensities, dtype=float)
        n_pix = self.surface.pixels.size
        chunk = max(1, CHUNK_ELEMENTS // max(wi.shape[0], 1))
        radiance = np.empty((n_pix, 3))
        if env is None or mirror_samples <= 0 or not self.has_glossy:
            for start in range(0, n_pix, chunk):
                sl = slice(start, min(start + chunk, n_pix))
                radiance[sl] = self._shade(wi, inten[:, None, :], sl)
        else:
            # N_L p_L of each light (the lights are drawn with the map's light density)
            lights_density = len(wi) * env.light_density[env.texels(wi, rotation_deg)]
            for start in range(0, n_pix, chunk):
                sl = slice(start, min(start + chunk, n_pix))
                r = mirror_directions(self.glossy_normals[sl], self.surface.view[sl])
                mixed = lights_density[:, None] + mirror_samples * mirror_density(wi, r)  # [L, p]
                share = (lights_density[:, None] / mixed)[..., None]
                radiance[sl] = self._shade(wi, inten[:, None, :] * share, sl, self.mirror_alpha)
                d, p_b = mirror_sample_directions(r, self.surface.tangent[sl], mirror_samples)
                texels = env.texels(d, rotation_deg)
                mixed = len(wi) * env.light_density[texels] + mirror_samples * p_b[:, None]
                radiance[sl] += self._shade(d, env.radiance[texels] / mixed[..., None], sl, self.mirror_alpha)
        out[self.surface.pixels] = radiance
        return out.reshape(res, res, 3)

    def _shade(self, wi: np.ndarray, weights: np.ndarray, sl: slice, mirror_alpha: float = 0.0) -> np.ndarray:
        """Radiance [p, 3] of the pixels ``sl`` lit from directions ``wi`` ([K, 3], shared by the pixels, or
        [K, p, 3], per pixel) with RGB weights [K, 1 or p, 3] (a light's intensity, or the radiance a sample
        sees over its density); mirrors drawn as lobes of ``mirror_alpha`` (:class:`.geometry.LocalGeometry`)."""
        surf = self.surface
        n = self.normals[sl]
        wo = surf.view[sl]
        cos_i = _dot(wi, n)  # [K, p]
        cos_o = np.broadcast_to(np.sum(n * wo, axis=-1), cos_i.shape)
        i_dot_o = _dot(wi, wo)
        # light from below the geometric surface is blocked by the object itself, whatever the
        # shading normal says (as in a path tracer: the sphere occludes it)
        cos_g = _dot(wi, surf.normal[sl])
        lit = (cos_i > 0.0) & (cos_o > 0.0) & (cos_g > 0.0)
        if self.bump_alpha2 is None:
            frame = _frame(wi, wo, n, surf.tangent[sl], lit) if self.framed else None  # anisotropic models
            geo = LocalGeometry(
                np.where(lit, cos_i, 1.0), np.where(lit, cos_o, 1.0), np.where(lit, i_dot_o, 1.0), frame, mirror_alpha
            )
            fcos = np.where(lit, self._evaluate(self.params, sl, geo, cos_i.shape), 0.0)  # [C, K, p]
        else:
            fcos = self._bumped(wi, sl, (cos_i, cos_o, cos_g, i_dot_o), mirror_alpha)
        out = np.empty((cos_i.shape[1], 3))
        for c in range(3):
            out[:, c] = np.sum(fcos[min(c, fcos.shape[0] - 1)] * weights[..., c], axis=0)
        return out

    def _bumped(self, wi: np.ndarray, sl: slice, cosines: tuple[np.ndarray, ...], mirror_alpha: float) -> np.ndarray:
        """f cos [C, K, p] as Cycles shades with a normal map: a diffuse closure is lit wherever the light is
        above both the bent and the smooth normal, seen from either side, and softened by the bump
        shadowing term; a glossy closure shades with its raised normal. ``cosines``: n.i, n.o, ng.i, i.o."""
        cos_i, cos_o, cos_g, i_dot_o = cosines
        lit = (cos_i > 0.0) & (cos_o > 0.0) & (cos_g > 0.0)
        lit_d = (cos_i > 0.0) & (cos_g > 0.0)
        geo = LocalGeometry(
            np.where(lit_d, cos_i, 1.0), np.where(lit, cos_o, 1.0), np.where(lit, i_dot_o, 1.0), None, mirror_alpha
        )
        # the diffuse closures: the model less its glossy part, at the same geometry
        diffuse: float | np.ndarray = 0.0
        if self.has_diffuse:
            diffuse = self._evaluate(self.params, sl, geo, cos_i.shape)
            if self.specular_params is not None:
                diffuse = diffuse - self._evaluate(self.specular_params, sl, geo, cos_i.shape)
        glossy: float | np.ndarray = 0.0
        if self.specular_params is not None:
            ng = self.glossy_normals[sl]
            gi = _dot(wi, ng)
            go = np.broadcast_to(np.sum(ng * self.surface.view[sl], axis=-1), gi.shape)
            lit_g = (gi > 0.0) & (go > 0.0) & (cos_g > 0.0)
            ggeo = LocalGeometry(
                np.where(lit_g, gi, 1.0), np.where(lit_g, go, 1.0), np.where(lit_g, i_dot_o, 1.0), None, mirror_alpha
            )
            glossy = np.where(lit_g, self._evaluate(self.specular_params, sl, ggeo, gi.shape), 0.0)
        assert self.bump_alpha2 is not None
        term = bump_shadowing(self.bump_alpha2[sl], cos_g)
        return np.asarray(glossy + np.where(lit_d, diffuse, 0.0) * term)

    def _evaluate(
        self, per_pixel: Mapping[str, np.ndarray], sl: slice, geo: LocalGeometry, shape: tuple[int, int]
    ) -> np.ndarray:
        """f cos(theta_i) [C, L, p] of the pixels ``sl``."""
        params = {k: (v[..., sl] if v.shape[-1] > 1 else v) for k, v in per_pixel.items()}
        fcos = np.asarray(self.evaluator(params, self.options, geo))
        channels = fcos.shape[-3] if fcos.ndim >= 3 else 1
        return np.broadcast_to(fcos, (1, channels) + shape)[0]


def _dot(w: np.ndarray, v: np.ndarray) -> np.ndarray:
    """w.v [K, p] of directions ``w`` [K, 3] (shared by the pixels) or [K, p, 3] (per pixel) with ``v`` [p, 3]."""
    return w @ v.T if w.ndim == 2 else np.einsum("kpj,pj->kp", w, v)


def _frame(
    wi: np.ndarray, wo: np.ndarray, n: np.ndarray, tangent: np.ndarray, lit: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(i.s, i.t, o.s, o.t) [L, p] in Mitsuba's shading frame: s = the surface tangent (dp/du) made
    orthogonal to the shading normal ``n``, t = n x s; zero where unlit."""
    s = tangent - n * np.sum(n * tangent, axis=-1, keepdims=True)
    s /= np.maximum(np.linalg.norm(s, axis=-1, keepdims=True), 1e-12)
    t = np.cross(n, s)
    i_s, i_t = _dot(wi, s), _dot(wi, t)
    o_s, o_t = (np.broadcast_to(np.sum(wo * v, axis=-1), lit.shape) for v in (s, t))
    return tuple(np.where(lit, a, 0.0) for a in (i_s, i_t, o_s, o_t))  # type: ignore[return-value]


def ensure_valid_specular_reflection(ng: np.ndarray, view: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Cycles' raising of a glossy closure's normal ``n`` [p, 3] towards the geometric normal
    ``ng`` just enough that the mirror direction of ``view`` lies min(0.9 cos, 0.01) above the
    surface (``ensure_valid_specular_reflection`` in Cycles' ``kernel/closure/bsdf_util.h``): in the
    plane of ng and n, the normal's height solves a quadratic in n_z^2."""
    dot = lambda a, b: np.sum(a * b, axis=-1)  # noqa: E731
    r = mirror_directions(n, view)
    iz = dot(view, ng)
    t = np.minimum(0.9 * iz, 0.01)
    valid = dot(ng, r) >= t
    x = n - dot(n, ng)[:, None] * ng
    length = np.linalg.norm(x, axis=-1, keepdims=True)
    x = np.where(length > 1e-12, x / np.maximum(length, 1e-12), n)
    ix = dot(view, x)
    a = ix * ix + iz * iz
    b = 2.0 * (a + iz * t)
    c = (t + iz) ** 2
    root = np.sqrt(np.maximum(b * b - 4.0 * a * c, 0.0))
    nz2 = np.where(ix < 0.0, 0.25 * (b + root), 0.25 * (b - root)) / np.maximum(a, 1e-30)
    raised = np.sqrt(np.maximum(1.0 - nz2, 0.0))[:, None] * x + np.sqrt(np.maximum(nz2, 0.0))[:, None] * ng
    return np.where(valid[:, None], n, raised)


def bump_alpha2(smooth: np.ndarray, bumped: np.ndarray) -> np.ndarray:
    """Cycles' bump-shadowing roughness of a bent normal [p]: alpha^2 = min(tan^2(d) / 8, 1), d the
    angle between the smooth and the normal-mapped normal (``bump_shadowing_term`` in Cycles'
    ``kernel/closure/bsdf.h``, after Conty Estevez et al. 2019, "A Microfacet-Based Shadowing
    Function to Solve the Bump Terminator Problem")."""
    cos_d = np.clip(np.abs(np.sum(smooth * bumped, axis=-1)), 1e-6, 1.0)
    return np.clip(0.125 * (1.0 / (cos_d * cos_d) - 1.0), 0.0, 1.0)


def bump_shadowing(alpha2: np.ndarray, cos_light: np.ndarray) -> np.ndarray:
    """The factor [L, p] Cycles puts on a diffuse closure with a bent normal: Smith's GGX G1 of
    ``alpha2`` [p] at the light's angle to the smooth normal (cos [L, p]); 0 below 1e-6."""
    c = np.clip(np.abs(cos_light), 1e-6, 1.0)
    tan2 = 1.0 / (c * c) - 1.0
    g1 = 2.0 / (1.0 + np.sqrt(1.0 + alpha2[None, :] * tan2))
    return np.where(np.abs(cos_light) < 1e-6, 0.0, g1)


def render_svbrdf(
    model: str,
    params: Mapping[str, Any],
    options: Mapping[str, str] | None,
    env: EnvMap,
    rotation_deg: float = 0.0,
    geometry: str = "sphere",
    resolution: int = 256,
    part: str = "full",
    normal_map: np.ndarray | None = None,
    lights: int = 256,
    seed: int = 0,
    mirror_samples: int = MIRROR_SAMPLES,
) -> np.ndarray:
    """Render a textured material on the sphere or plane under ``env`` turned by ``rotation_deg``.

    ``params`` maps the model's parameter names to constants or textures (see the module doc);
    missing parameters take the model's defaults, ``options`` its options. ``part`` is ``full``,
    ``specular`` (the model's ``specular_only`` overrides; black when it has no specular part) or
    ``diffuse``. ``lights`` directional lights sample the map, and ``mirror_samples`` directions per pixel
    about its mirror direction (0: the lights alone; see :meth:`SVBRDFRender.render`). Returns linear radiance
    float32 [res, res, 3], black off the object.
    """
    r = SVBRDFRender(model, params, options, geometry, resolution, part, normal_map)
    directions, intensities = directional_lights(env, lights, rotation_deg, seed)
    return r.render(directions, intensities, env, rotation_deg, mirror_samples)


class EmbeddedEnvironmentRender:
    """The embedded renderer's :class:`~matremap.renderers.base.EnvironmentRender`: an
    :class:`SVBRDFRender` lit by the environment's directional lights and its samples about each pixel's
    mirror direction (``light.mirror_samples``) at each rotation."""

    label = "embedded emulation"

    def __init__(self, prepared: SVBRDFRender, light: EnvironmentLight) -> None:
        self.prepared, self.light = prepared, light

    def render(self, rotation_deg: float) -> np.ndarray:
        light = self.light
        return self.prepared.render(*light.directional(rotation_deg), light.env, rotation_deg, light.mirror_samples)
