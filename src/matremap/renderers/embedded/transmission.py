"""The transmission probe: a sphere in front of a tiled background under an environment map, so that what a
transmissive material lets through -- refracted, tinted, blurred -- is in the image.

The opaque probe (point lights, :mod:`.probe`) and the environment renders (:mod:`.environment`) draw a model's
BRDF, which for a transmissive material is only its reflection. This module adds what goes through, by tracing
rays through the sphere deterministically (fixed sample sets, no noise): one ray per pixel centre from the
evaluation camera (:mod:`matremap.renderers.textured`: pinhole at (0, 0, 8), sphere of radius 2 at the origin);
behind the sphere a plane at z = -4 tiled with coloured squares (:func:`background`), the environment elsewhere.

What a model transmits is read from its parameters into an :class:`Interface` -- the physics the probe needs --
by the functions of :data:`INTERFACES`:

* ``gltf:pbr`` (KHR_materials_transmission, KHR_materials_volume; ratified READMEs): the share
  ``transmission`` (1 - metallic) of the dielectric base refracts through a GGX microsurface of the material's
  roughness, weighted by 1 - specular max F (Schlick's F of the IOR and KHR_materials_specular, on the outer
  side's cosine) and tinted by baseColor where it enters; ``thickness`` 0 is a thin wall (no bending), > 0 the
  volume of the object itself, attenuated by Beer-Lambert: sigma = -ln(attenuationColor) / attenuationDistance
  (no attenuation at the default distance, infinity, written 0 here).
* ``mtlx:open_pbr_surface`` (OpenPBR 1.1, "Translucent base", "Thin-walled" and "Transmission" in "Volume"):
  the share transmission_weight (1 - base_metalness) refracts through the specular lobe (its roughness and
  its IOR modulated by specular_weight), weighted by 1 - the exact dielectric Fresnel; transmission_color is a
  tint of the interface when transmission_depth is 0 (or the object thin-walled), else the colour white light
  takes after transmission_depth inside (sigma = -ln(transmission_color) / transmission_depth);
  ``geometry_thin_walled`` 1 makes the surface a thin shell.
* ``mitsuba3:dielectric``, ``roughdielectric``, ``thindielectric`` (Mitsuba 3.9 ``src/bsdfs/``): the boundary of a
  solid of eta = int_ior / ext_ior (below 1 too) with the exact Fresnel, specular_transmittance applied at every
  refraction (so squared on the straight path), Beckmann traced as an equivalent GGX alpha; the thin slab without
  bending, its internal reflections summed into each wall (:func:`mitsuba3_dielectric_interface`,
  :func:`mitsuba3_thindielectric_interface`).

Tracing (:func:`transmitted`): a camera ray enters the sphere through a microfacet normal drawn from the GGX
distribution of visible normals (Heitz 2018, "Sampling the GGX distribution of visible normals", JCGT 7(4)),
refracts by Snell's law, travels to the far side (attenuated), where a second microfacet normal splits it into
the part leaving (1 - F) towards the background and the part reflected back inside (F, followed for
``bounces`` internal reflections; total internal reflection keeps all of it); each sampled direction is weighted
by Smith's G1 of the direction it leaves in (the estimator of VNDF sampling). A smooth interface (alpha below
1e-4) uses the macroscopic normal and one path per pixel; a rough one ``samples`` paths per pixel at fixed
Hammersley points. A thin wall is crossed in and straight out again at the same point (two microfacet normals,
no internal reflection), once at the front and once at the back of the sphere. Light reflected off the outside
is the model's BRDF under the environment's directional lights and its samples about each pixel's mirror direction
(:class:`.environment.SVBRDFRender`, :mod:`.mirror_samples`): a smooth interface reflects the map (the map only:
the tiled plane behind the sphere is not in its reflection). Drawn by the lights alone, a smooth glass's reflection
was missing (an OpenPBR glass of IOR 1.5: 0.044 of mean radiance on the sphere beside the 0.33 it lets through).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import TYPE_CHECKING, Any

import numpy as np

from matremap.core.envmap import EnvMap, directional_lights, resolve
from matremap.core.material import Material
from matremap.core.optics import dielectric_f0, fresnel_dielectric
from matremap.errors import MatremapError
from matremap.renderers.embedded.evaluators.mitsuba3 import principled_eta
from matremap.renderers.embedded.layering import modulated_ior
from matremap.renderers.textured import surface_pixels

#: samples about each pixel's mirror direction for the reflection in the transmission view: fewer than an
#: evaluation's 64 (a glass fit renders the view dozens of times; 64 made each render 0.14 s slower at 64 px, 16
#: 0.08 s), and at 64 px an OpenPBR glass's mean reflection is within 3 % of the 64-sample one
VIEW_MIRROR_SAMPLES = 16

if TYPE_CHECKING:
    from matremap.core.scene import Scene

#: the evaluation camera and sphere (renderers/textured.py)
CAMERA_Z = 8.0
SPHERE_RADIUS = 2.0
#: below this GGX alpha an interface is smooth (one path per pixel)
SMOOTH_ALPHA = 1e-4


@dataclass(frozen=True)
class TransmissionScene:
    """The transmission probe: resolution, the background plane (z, half-size, tile size), the environment
    (a :func:`~matremap.core.envmap.resolve` spec) and its directional lights for the reflection, internal
    bounces followed and paths per pixel of a rough interface."""

    resolution: int = 96
    plane_z: float = -4.0
    plane_half_size: float = 12.0
    tile: float = 0.5
    env: str | EnvMap = "builtin"
    env_lights: int = 256
    bounces: int = 4
    samples: int = 32

    def __post_init__(self) -> None:
        if not isinstance(self.resolution, int) or not 8 <= self.resolution <= 4096:
            raise MatremapError(f"transmission probe resolution must be an integer in [8, 4096], got {self.resolution}")
        if self.bounces < 1 or self.samples < 1:
            raise MatremapError("the transmission probe needs at least one bounce and one sample")


@dataclass(frozen=True)
class Interface:
    """What a material lets through, in physical terms (RGB arrays of shape [3]).

    ``weight``: the share of light reaching the base that is transmitted rather than diffused (before the
    interface's Fresnel); ``eta``: interior over exterior IOR; ``alpha``: GGX alpha of the refracting
    microsurface; ``tint``: colour applied where light crosses the surface inwards (a thin wall: each wall);
    ``sigma``: extinction coefficient inside (per scene unit); ``thin_walled``; ``fresnel``: the fraction
    reflected at a crossing, ``fresnel(cos_outside)`` for a ray crossing with the given cosine on the outer
    (lower-index) side."""

    weight: np.ndarray
    eta: float
    alpha: float
    tint: np.ndarray
    sigma: np.ndarray
    thin_walled: bool
    fresnel: Callable[[np.ndarray], np.ndarray]


def _scalar(values: Mapping[str, Any], name: str) -> float:
    return float(np.asarray(values[name], dtype=float).reshape(-1)[0])


def _rgb(values: Mapping[str, Any], name: str) -> np.ndarray:
    return np.broadcast_to(np.asarray(values[name], dtype=float).reshape(-1), (3,)).astype(float)


def beer_sigma(colour: np.ndarray, distance: float) -> np.ndarray:
    """sigma = -ln(colour) / distance (0 for an infinite or zero distance or a white colour; a black channel
    absorbs everything within 1e-6 of it)."""
    if distance <= 0.0 or not math.isfinite(distance):
        return np.zeros(3)
    return -np.log(np.clip(colour, 1e-6, 1.0)) / distance


def gltf_interface(values: Mapping[str, Any]) -> Interface:
    """``gltf:pbr``'s transmission (see the module docstring)."""
    f0 = dielectric_f0(_scalar(values, "ior"), 1.0, _rgb(values, "specularColor"))
    specular = _scalar(values, "specular")

    def fresnel(cos_outside: np.ndarray) -> np.ndarray:
        m = 1.0 - np.clip(cos_outside, 0.0, 1.0)
        return specular * np.max(f0[:, None] + (1.0 - f0[:, None]) * m**5, axis=0)

    thin = _scalar(values, "thickness") <= 0.0
    sigma = (
        np.zeros(3) if thin else beer_sigma(_rgb(values, "attenuationColor"), _scalar(values, "attenuationDistance"))
    )
    weight = _scalar(values, "transmission") * (1.0 - _scalar(values, "metallic"))
    return Interface(
        weight=np.full(3, weight),
        eta=max(_scalar(values, "ior"), 1.0),
        alpha=_scalar(values, "roughness") ** 2,
        tint=np.clip(_rgb(values, "baseColor"), 0.0, 1.0),
        sigma=sigma,
        thin_walled=thin,
        fresnel=fresnel,
    )


def openpbr_interface(values: Mapping[str, Any]) -> Interface:
    """``mtlx:open_pbr_surface``'s transmission (see the module docstring)."""
    eta = float(modulated_ior(_scalar(values, "specular_ior"), _scalar(values, "specular_weight")))
    eta = max(eta, 1.0 + 1e-9)

    def fresnel(cos_outside: np.ndarray) -> np.ndarray:
        return fresnel_dielectric(np.clip(cos_outside, 1e-9, 1.0), eta)

    thin = _scalar(values, "geometry_thin_walled") >= 0.5
    depth = _scalar(values, "transmission_depth")
    colour = np.clip(_rgb(values, "transmission_color"), 0.0, 1.0)
    volume = not thin and depth > 0.0
    weight = np.clip(_scalar(values, "transmission_weight"), 0.0, 1.0) * (1.0 - _scalar(values, "base_metalness"))
    return Interface(
        weight=np.full(3, weight),
        eta=eta,
        alpha=_scalar(values, "specular_roughness") ** 2,
        tint=np.ones(3) if volume else colour,
        sigma=beer_sigma(colour, depth) if volume else np.zeros(3),
        thin_walled=thin,
        fresnel=fresnel,
    )


def standard_surface_interface(values: Mapping[str, Any]) -> Interface:
    """``mtlx:standard_surface``'s transmission: Autodesk Standard Surface v1.0.1, "Specular transmission".

    The share transmission (1 - metalness) of the dielectric base is ``specular_btdf``: a GGX BTDF of
    specular_roughness (transmission_extra_roughness, default 0, is not a parameter) and specular_IOR, its
    dielectric Fresnel the share reflected at each crossing; transm_color = transmission_color when
    transmission_depth is 0 (a tint, applied once, as OpenPBR's and MaterialX's standard_surface to
    open_pbr_surface translation read it), else white with the interior's extinction
    sigma = -ln(transmission_color) / transmission_depth. ``thin_walled`` 1: "light does not undergo refraction"
    -- no bending: a thin wall crossed in and straight out, each crossing through the rough microsurface of
    specular_IOR, as MaterialX 1.39's ``standard_surface`` graph draws it (its ``transmission_bsdf`` refracts with
    specular_IOR and the transmission roughness whatever ``thin_walled``), so a rough wall blurs what lies behind
    (the spec's "refractive index ... of the surrounding medium" taken literally, eta 1, blurs nothing: a rough
    glTF thin glass fitted 0.43 off); a crossing then loses what the specular layer above reflects (specular
    specular_color times the Fresnel of specular_IOR), and a depth > 0 leaves no tint (no interior). The coat over
    it all (coat_color, 1 - E_coat) is not applied, as for OpenPBR."""
    ior = max(_scalar(values, "specular_IOR"), 1.0 + 1e-9)
    thin = _scalar(values, "thin_walled") >= 0.5
    layer = _scalar(values, "specular") * float(np.max(_rgb(values, "specular_color")))

    def fresnel(cos_outside: np.ndarray) -> np.ndarray:
        f = fresnel_dielectric(np.clip(cos_outside, 1e-9, 1.0), ior)
        return np.clip(layer * f, 0.0, 1.0) if thin else f

    depth = _scalar(values, "transmission_depth")
    colour = np.clip(_rgb(values, "transmission_color"), 0.0, 1.0)
    weight = np.clip(_scalar(values, "transmission"), 0.0, 1.0) * (1.0 - np.clip(_scalar(values, "metalness"), 0, 1))
    return Interface(
        weight=np.full(3, weight),
        eta=ior,
        alpha=_scalar(values, "specular_roughness") ** 2,
        tint=colour if depth <= 0.0 else np.ones(3),
        sigma=beer_sigma(colour, depth) if not thin and depth > 0.0 else np.zeros(3),
        thin_walled=thin,
        fresnel=fresnel,
    )


def mitsuba3_principled_interface(values: Mapping[str, Any]) -> Interface:
    """``mitsuba3:principled``'s transmission: Mitsuba 3.9 ``src/bsdfs/principled.cpp`` (``Principled::eval``).

    The lobe ``sqrt(base_color) bsdf (1 - F) D G ...`` with ``bsdf = (1 - metallic) spec_trans``, GGX alpha
    max(0.001, roughness^2), F the exact dielectric Fresnel of eta = 2/(1 - sqrt(0.08 specular)) - 1 (specular
    0 read as 1e-3), at the boundary of a solid (``principledthin`` is the thin one) with no medium inside.
    Mitsuba weighs *every* crossing by ``bsdf`` and tints it by sqrt(base_color) (an internal reflection by
    ``bsdf F``, untinted); the probe weighs a path once, so ``weight`` = bsdf^2 and ``tint`` = base_color make the
    straight path (in and out) exact, and a path with k internal reflections is bsdf^k too bright (exact at
    spec_trans 1, metallic 0)."""
    eta = max(float(principled_eta(_scalar(values, "specular"), _scalar(values, "spec_trans"))), 1.0 + 1e-9)

    def fresnel(cos_outside: np.ndarray) -> np.ndarray:
        return fresnel_dielectric(np.clip(cos_outside, 1e-9, 1.0), eta)

    bsdf = (1.0 - _scalar(values, "metallic")) * _scalar(values, "spec_trans")
    return Interface(
        weight=np.full(3, bsdf * bsdf),
        eta=eta,
        alpha=max(0.001, _scalar(values, "roughness") ** 2),
        tint=np.clip(_rgb(values, "base_color"), 0.0, 1.0),
        sigma=np.zeros(3),
        thin_walled=False,
        fresnel=fresnel,
    )


def cycles_principled_interface(values: Mapping[str, Any]) -> Interface:
    """``cycles:principled``'s transmission: Blender 5.0 Cycles ``kernel/svm/closure.h``
    (``CLOSURE_BSDF_PRINCIPLED_ID``, "Transmission component") and ``kernel/closure/bsdf_microfacet.h``.

    A GGX glass closure of weight t (1 - Metallic), t = Transmission Weight, alpha = Roughness^2, relative IOR
    the IOR socket (not adjusted by Specular IOR Level; 1/IOR from inside); its Fresnel the real dielectric one
    remapped from [F0(IOR), 1] to [min(F0(IOR) Specular Tint, 1), 1] (the largest channel here: the probe takes
    one share per crossing), unchanged when seen from inside with the outer cosine; what it transmits is tinted
    by sqrt(min(Base Color, 1)). Cycles weighs and tints *every* crossing by that closure, so ``weight`` =
    (t (1 - Metallic))^2 and ``tint`` = Base Color make the straight path exact and a path with k internal
    reflections (t (1 - Metallic))^k too bright (exact for a full glass). Left out: the sheen and coat layers'
    share above the glass, Multiscatter GGX's gain on the glass (1 + F_ms (1 - E)/E of Cycles' glass tables,
    which brightens a rough glass's transmission too: :mod:`.cycles_glass`) and any Volume shader (no
    absorption inside)."""
    ior = max(_scalar(values, "IOR"), 1.0 + 1e-9)
    f0_real = float(dielectric_f0(ior, 1.0, np.ones(3))[0])
    f0 = float(np.max(np.clip(f0_real * np.maximum(_rgb(values, "Specular Tint"), 0.0), 0.0, 1.0)))

    def fresnel(cos_outside: np.ndarray) -> np.ndarray:
        real = fresnel_dielectric(np.clip(cos_outside, 1e-9, 1.0), ior)
        s = np.clip((real - f0_real) / (1.0 - f0_real), 0.0, 1.0)
        return f0 + (1.0 - f0) * s

    share = np.clip(_scalar(values, "Transmission Weight"), 0.0, 1.0) * (
        1.0 - np.clip(_scalar(values, "Metallic"), 0, 1)
    )
    return Interface(
        weight=np.full(3, share * share),
        eta=ior,
        alpha=float(np.clip(_scalar(values, "Roughness"), 0.0, 1.0)) ** 2,
        tint=np.clip(_rgb(values, "Base Color"), 0.0, 1.0),
        sigma=np.zeros(3),
        thin_walled=False,
        fresnel=fresnel,
    )


def mitsuba3_dielectric_interface(values: Mapping[str, Any]) -> Interface:
    """``mitsuba3:dielectric`` and ``mitsuba3:roughdielectric``'s transmission: Mitsuba 3.9 ``src/bsdfs/
    dielectric.cpp`` and ``roughdielectric.cpp`` (``sample``/``eval``, the transmission branch).

    The boundary of a solid of relative IOR eta = int_ior / ext_ior (below 1 too: a medium less dense than the one
    around, which reflects totally past its critical angle when entered), its exact dielectric Fresnel
    (``fresnel.h``) the share reflected at each crossing, smooth or of the roughness alpha (``roughdielectric``'s
    Beckmann is traced as the GGX alpha that lets as much through, :func:`beckmann_as_ggx`). Mitsuba multiplies
    *every* refraction by specular_transmittance (and every reflection by specular_reflectance); the probe tints a
    path once, so ``tint`` = specular_transmittance^2 and ``weight`` 1 make the straight path (in and out) exact; an
    internal reflection is not multiplied by specular_reflectance (exact at its default 1, which Mitsuba says
    should never be touched). No medium inside: Mitsuba's own ``interior`` medium is a shape's, not the BSDF's."""
    eta = _scalar(values, "int_ior") / _scalar(values, "ext_ior")

    def fresnel(cos_outside: np.ndarray) -> np.ndarray:
        return fresnel_dielectric(np.clip(cos_outside, 1e-9, 1.0), eta)

    st = np.clip(_rgb(values, "specular_transmittance"), 0.0, 1.0)
    alpha = _scalar(values, "alpha") if "alpha" in values else 0.0
    if "alpha" in values and values.get("distribution", "beckmann") == "beckmann":
        alpha = beckmann_as_ggx(alpha)
    return Interface(
        weight=np.ones(3),
        eta=eta,
        alpha=alpha,
        tint=st * st,
        sigma=np.zeros(3),
        thin_walled=False,
        fresnel=fresnel,
    )


def beckmann_as_ggx(alpha: float) -> float:
    """The GGX alpha the probe traces for Mitsuba's Beckmann ``alpha`` (the probe samples GGX only): a Beckmann
    glass lets more through than a GGX one of the same alpha (its lobe has no long tail to be masked; Mitsuba
    3.9, IOR 1.5, grey tiles: the GGX probe's mean is 2 % darker at alpha 0.05, 6 % at 0.1, 21 % at 0.3, 23 % at
    0.5). Measured against it, c alpha with c = 0.7 - 0.167 ln(alpha / 0.1) kept in [0.5, 0.8] transmits as
    much (mean within 1-2 %, blurred relative RMSE 0.03-0.045 at 0.05-0.5): an empirical fit, not a derived
    equivalence (benchmarks/transmission_probe.py --mitsuba-glass, tests/test_mitsuba3_glass.py)."""
    if alpha <= 0.0:
        return alpha
    return alpha * float(np.clip(0.7 - 0.167 * math.log(alpha / 0.1), 0.5, 0.8))


def thin_slab_fresnel(cos_outside: np.ndarray, eta: float) -> np.ndarray:
    """The share a probe's thin-wall crossing reflects so that a wall (two crossings) lets through what
    Mitsuba's ``thindielectric`` does: 1 - R' with R' = R + T^2 R / (1 - R^2) = 2R / (1 + R) (``thindielectric.cpp``:
    the slab's internal reflections summed), R the exact Fresnel of eta; so 1 - sqrt((1 - R) / (1 + R))."""
    r = fresnel_dielectric(np.clip(cos_outside, 1e-9, 1.0), eta)
    return 1.0 - np.sqrt((1.0 - r) / (1.0 + r))


def mitsuba3_thindielectric_interface(values: Mapping[str, Any]) -> Interface:
    """``mitsuba3:thindielectric``'s transmission: Mitsuba 3.9 ``src/bsdfs/thindielectric.cpp``
    (``eval_null_transmission``): a thin slab crossed without bending (a null interaction), letting through
    (1 - R') specular_transmittance at each wall with R' = 2R / (1 + R) of eta = int_ior / ext_ior (the slab's
    internal reflections summed; the probe's own thin wall has none, so its Fresnel is
    :func:`thin_slab_fresnel`). A thin wall in the probe's terms: no bending (eta 1), the tint
    specular_transmittance at each wall, weight 1."""
    eta = _scalar(values, "int_ior") / _scalar(values, "ext_ior")

    def fresnel(cos_outside: np.ndarray) -> np.ndarray:
        return thin_slab_fresnel(cos_outside, eta)

    return Interface(
        weight=np.ones(3),
        eta=eta,
        alpha=0.0,
        tint=np.clip(_rgb(values, "specular_transmittance"), 0.0, 1.0),
        sigma=np.zeros(3),
        thin_walled=True,
        fresnel=fresnel,
    )


#: model id -> the reading of its transmission
INTERFACES: dict[str, Callable[[Mapping[str, Any]], Interface]] = {
    "gltf:pbr": gltf_interface,
    "mtlx:open_pbr_surface": openpbr_interface,
    "mtlx:standard_surface": standard_surface_interface,
    "mitsuba3:principled": mitsuba3_principled_interface,
    "cycles:principled": cycles_principled_interface,
    "mitsuba3:dielectric": mitsuba3_dielectric_interface,
    "mitsuba3:roughdielectric": mitsuba3_dielectric_interface,
    "mitsuba3:thindielectric": mitsuba3_thindielectric_interface,
}


def interface_of(material: Material) -> Interface:
    """The :class:`Interface` of a uniform material (its reader sees its options among its values); a model the
    probe cannot read is refused."""
    reader = INTERFACES.get(material.model)
    if reader is None:
        raise MatremapError(
            f"the transmission probe draws {', '.join(sorted(INTERFACES))}, not {material.model}; "
            "remap the material onto one of them first"
        )
    return reader({**material.options, **material.values})


def gltf_equivalent(iface: Interface, thickness: float = 2.0 * SPHERE_RADIUS) -> dict[str, Any]:
    """The gltf:pbr transmission parameters that transmit as ``iface`` does (KHR_materials_transmission and
    _volume read back through :func:`gltf_interface`): transmission, ior, roughness, the entry tint as baseColor,
    a thin wall or a volume of the given ``thickness`` (what rasterisers use; the probe traces the real object),
    and the extinction as attenuationColor after attenuationDistance 1 (0, glTF's infinity, when clear). Only
    the Fresnel form differs (glTF's Schlick for OpenPBR's exact one); a grey weight is assumed."""
    clear = not np.any(iface.sigma > 0.0)
    return {
        "metallic": 0.0,
        "transmission": float(iface.weight[0]),
        "ior": float(iface.eta),
        "roughness": math.sqrt(iface.alpha),
        "baseColor": iface.tint.tolist(),
        "thickness": 0.0 if iface.thin_walled else float(thickness),
        "attenuationColor": [1.0, 1.0, 1.0] if clear else np.exp(-iface.sigma).tolist(),
        "attenuationDistance": 0.0 if clear else 1.0,
    }


def openpbr_equivalent(iface: Interface) -> dict[str, Any]:
    """The ``mtlx:open_pbr_surface`` transmission parameters that transmit as ``iface`` does (read back through
    :func:`openpbr_interface`): transmission_weight, specular_ior (specular_weight 1), specular_roughness, a thin
    wall or a volume; a volume's extinction as the transmission_color white light takes after transmission_depth
    1 (OpenPBR 1.1 "Transmission": its entry tint is white, so a tinted interface over a volume keeps the
    extinction only), a clear object's entry tint as transmission_color at depth 0. A grey weight is assumed."""
    volume = not iface.thin_walled and bool(np.any(iface.sigma > 0.0))
    colour = np.exp(-iface.sigma) if volume else iface.tint
    return {
        "base_metalness": 0.0,
        "transmission_weight": float(iface.weight[0]),
        "specular_weight": 1.0,
        "specular_ior": float(iface.eta),
        "specular_roughness": math.sqrt(iface.alpha),
        "transmission_color": np.clip(colour, 0.0, 1.0).tolist(),
        "transmission_depth": 1.0 if volume else 0.0,
        "geometry_thin_walled": 1.0 if iface.thin_walled else 0.0,
    }


def standard_surface_equivalent(iface: Interface) -> dict[str, Any]:
    """The ``mtlx:standard_surface`` transmission parameters that transmit as ``iface`` does (read back through
    :func:`standard_surface_interface`): as :func:`openpbr_equivalent`, in Standard Surface's names (transmission,
    specular_IOR, specular_roughness, transmission_color at depth 1 for a volume, a tint at depth 0, thin_walled)."""
    open_pbr = openpbr_equivalent(iface)
    return {
        "metalness": 0.0,
        "transmission": open_pbr["transmission_weight"],
        "specular": 1.0,
        "specular_IOR": open_pbr["specular_ior"],
        "specular_roughness": open_pbr["specular_roughness"],
        "transmission_color": open_pbr["transmission_color"],
        "transmission_depth": open_pbr["transmission_depth"],
        "thin_walled": open_pbr["geometry_thin_walled"],
    }


def principled_specular(eta: float) -> float:
    """Mitsuba 3 principled's ``specular`` of a relative IOR: the inverse of eta = 2 / (1 - sqrt(0.08 specular))
    - 1 (``principled.cpp``), i.e. specular = F0 / 0.08 with F0 = ((eta - 1) / (eta + 1))^2, clipped to [0, 1]."""
    return float(np.clip(((eta - 1.0) / (eta + 1.0)) ** 2 / 0.08, 0.0, 1.0))


def mitsuba3_principled_equivalent(iface: Interface) -> dict[str, Any]:
    """The ``mitsuba3:principled`` parameters that transmit as ``iface`` does on its straight path (read back
    through :func:`mitsuba3_principled_interface`): spec_trans = sqrt(weight), the tint as base_color, specular of
    the IOR, roughness sqrt(alpha). Mitsuba's principled is a solid without a medium: a thin wall or an
    absorbing volume has no equivalent, and the fit takes the closest look (the extinction into the tint)."""
    return {
        "metallic": 0.0,
        "spec_trans": math.sqrt(float(iface.weight[0])),
        "base_color": np.clip(iface.tint * np.exp(-iface.sigma * 2.0 * SPHERE_RADIUS), 0.0, 1.0).tolist(),
        "specular": principled_specular(iface.eta),
        "roughness": max(math.sqrt(iface.alpha), 0.001),
    }


def cycles_principled_equivalent(iface: Interface) -> dict[str, Any]:
    """The ``cycles:principled`` parameters that transmit as ``iface`` does on its straight path (read back
    through :func:`cycles_principled_interface`): Transmission Weight = sqrt(weight), the tint as Base Color, the
    IOR, Roughness sqrt(alpha); no thin wall and no absorption inside (the probe's extinction over the sphere's
    diameter is folded into the Base Color as a start)."""
    return {
        "Metallic": 0.0,
        "Transmission Weight": math.sqrt(float(iface.weight[0])),
        "Base Color": np.clip(iface.tint * np.exp(-iface.sigma * 2.0 * SPHERE_RADIUS), 0.0, 1.0).tolist(),
        "IOR": float(np.clip(iface.eta, 1.0, 4.0)),
        "Roughness": math.sqrt(iface.alpha),
    }


#: the alpha a smooth transmission is read across onto ``roughdielectric`` at: just above Mitsuba's floor (1e-4,
#: the bound), so that the start is kept (a start on a bound is moved inside, to ~1e-3, where the directional lights
#: of the environment draw sharp highlights on the sphere: from an OpenPBR smooth glass, fit error 0.69 there,
#: 0.14 here, 0.0000 onto ``dielectric``)
GLASS_ALPHA_FLOOR = 1.01e-4


def mitsuba3_glass_equivalent(iface: Interface, model: str) -> dict[str, Any]:
    """The parameters of a Mitsuba 3 glass (``model``) that transmit as ``iface`` does (read back through
    :func:`mitsuba3_dielectric_interface` / :func:`mitsuba3_thindielectric_interface`): int_ior the relative IOR
    (at least 1) in vacuum (ext_ior 1), roughdielectric's alpha the GGX alpha (distribution ggx);
    specular_transmittance the square root of the tint for a solid (Mitsuba applies it at both crossings), the
    tint itself for a thin wall onto ``thindielectric`` (once per wall, as the probe), and the square root of a
    solid's tint onto ``thindielectric``. The weight (grey) and an interior's extinction over the sphere's
    diameter are folded into the tint as a start: Mitsuba's glasses carry no medium."""
    colour = np.clip(iface.tint * iface.weight * np.exp(-iface.sigma * 2.0 * SPHERE_RADIUS), 0.0, 1.0)
    thin = model == "mitsuba3:thindielectric"
    values: dict[str, Any] = {
        "int_ior": float(np.clip(iface.eta, 1.0, 4.0)),
        "ext_ior": 1.0,
        "specular_transmittance": (colour if thin and iface.thin_walled else np.sqrt(colour)).tolist(),
    }
    if model == "mitsuba3:roughdielectric":  # the probe's alpha is GGX's
        values.update(alpha=float(np.clip(iface.alpha, GLASS_ALPHA_FLOOR, 1.0)), distribution="ggx")
    return values


def _mitsuba3_glass_start(model: str) -> Callable[[Interface], tuple[dict[str, Any], tuple[str, ...]]]:
    freed = ("alpha", "specular_transmittance") if model == "mitsuba3:roughdielectric" else ("specular_transmittance",)
    return lambda iface: (mitsuba3_glass_equivalent(iface, model), freed)


def _gltf_start(iface: Interface) -> tuple[dict[str, Any], tuple[str, ...]]:
    values = gltf_equivalent(iface)
    if iface.eta <= 1.0 + 1e-6:
        # an interface of IOR 1 reflects nothing at any angle, where glTF's Schlick Fresnel at F0 0 still reaches 1 at
        # grazing: its specular factor 0 (KHR_materials_specular scales F0 and F90) is the match (PhysicallyBased's Soap
        # Bubble onto glTF: 0.166 with the rim reflecting, 0.0000 with specular 0)
        values["specular"] = 0.0
    return values, ("transmission",) if values["attenuationDistance"] == 0.0 else ("transmission", "attenuationColor")


def _openpbr_start(iface: Interface) -> tuple[dict[str, Any], tuple[str, ...]]:
    return openpbr_equivalent(iface), ("transmission_weight", "transmission_color")


def _standard_surface_start(iface: Interface) -> tuple[dict[str, Any], tuple[str, ...]]:
    return standard_surface_equivalent(iface), ("transmission", "transmission_color")


def _mitsuba3_principled_start(iface: Interface) -> tuple[dict[str, Any], tuple[str, ...]]:
    return mitsuba3_principled_equivalent(iface), ("spec_trans",)


def _cycles_principled_start(iface: Interface) -> tuple[dict[str, Any], tuple[str, ...]]:
    return cycles_principled_equivalent(iface), ("Transmission Weight",)


#: model id -> the parameters that transmit as an :class:`Interface` does, and the continuous ones among them a
#: fit frees (the structural ones, a thin wall or a volume, stay as read across)
EQUIVALENTS: dict[str, Callable[[Interface], tuple[dict[str, Any], tuple[str, ...]]]] = {
    "gltf:pbr": _gltf_start,
    "mtlx:open_pbr_surface": _openpbr_start,
    "mtlx:standard_surface": _standard_surface_start,
    "mitsuba3:principled": _mitsuba3_principled_start,
    "cycles:principled": _cycles_principled_start,
    **{
        m: _mitsuba3_glass_start(m)
        for m in ("mitsuba3:dielectric", "mitsuba3:roughdielectric", "mitsuba3:thindielectric")
    },
}


# -- the background -------------------------------------------------------------------------------------

#: the tiles' colours (linear RGB): six hues at two brightnesses, so refraction moves and tints visible edges
PALETTE = np.array(
    [
        [0.9, 0.2, 0.15],
        [0.15, 0.7, 0.2],
        [0.15, 0.25, 0.9],
        [0.9, 0.8, 0.15],
        [0.15, 0.8, 0.85],
        [0.85, 0.2, 0.8],
    ]
)


def background(origins: np.ndarray, directions: np.ndarray, scene: TransmissionScene, env: EnvMap) -> np.ndarray:
    """Radiance [N, 3] seen from ``origins`` along unit ``directions`` [N, 3]: the tiled plane z = plane_z
    (tile (i, j) of size ``tile``: PALETTE[(i + 2 j) mod 6], every other tile at 0.35 of its brightness) where
    the ray meets it within ``plane_half_size``, else the environment."""
    dz = directions[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (scene.plane_z - origins[:, 2]) / dz
    hit = origins + np.where(np.isfinite(t), t, 0.0)[:, None] * directions
    on_plane = (dz < 0.0) & (t > 0.0) & (np.max(np.abs(hit[:, :2]), axis=1) < scene.plane_half_size)
    hit = np.where(on_plane[:, None], hit, 0.0)
    i = np.floor(hit[:, 0] / scene.tile).astype(np.int64)
    j = np.floor(hit[:, 1] / scene.tile).astype(np.int64)
    colour = PALETTE[np.mod(i + 2 * j, len(PALETTE))] * np.where(np.mod(i + j, 2) == 0, 1.0, 0.35)[:, None]
    return np.where(on_plane[:, None], colour, env.lookup(directions))


# -- microfacet crossings -------------------------------------------------------------------------------


def _frame(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangents completing the unit normals ``n`` [N, 3] to right-handed frames."""
    helper = np.where(np.abs(n[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    t = np.cross(helper, n)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    return t, np.cross(n, t)


def sample_vndf(wi: np.ndarray, alpha: float, u: np.ndarray) -> np.ndarray:
    """Microfacet normals [N, 3] (local frame, z the macroscopic normal) of the GGX distribution of normals
    visible from the local directions ``wi`` [N, 3] (z > 0), at uniform points ``u`` [N, 2] (Heitz 2018)."""
    vh = np.stack([alpha * wi[:, 0], alpha * wi[:, 1], wi[:, 2]], axis=1)
    vh /= np.linalg.norm(vh, axis=1, keepdims=True)
    lensq = vh[:, 0] ** 2 + vh[:, 1] ** 2
    safe = np.sqrt(np.maximum(lensq, 1e-300))
    t1 = np.where(
        (lensq > 0.0)[:, None], np.stack([-vh[:, 1], vh[:, 0], 0.0 * lensq], axis=1) / safe[:, None], [1, 0, 0]
    )
    t2 = np.cross(vh, t1)
    r = np.sqrt(u[:, 0])
    phi = 2.0 * math.pi * u[:, 1]
    a, b = r * np.cos(phi), r * np.sin(phi)
    s = 0.5 * (1.0 + vh[:, 2])
    b = (1.0 - s) * np.sqrt(np.maximum(1.0 - a * a, 0.0)) + s * b
    nh = a[:, None] * t1 + b[:, None] * t2 + np.sqrt(np.maximum(1.0 - a * a - b * b, 0.0))[:, None] * vh
    ne = np.stack([alpha * nh[:, 0], alpha * nh[:, 1], np.maximum(nh[:, 2], 0.0)], axis=1)
    return ne / np.linalg.norm(ne, axis=1, keepdims=True)


def smith_g1(cos_theta: np.ndarray, alpha: float) -> np.ndarray:
    """Smith's G1 of GGX for directions at ``cos_theta`` to the macroscopic normal (0 below it)."""
    c = np.clip(cos_theta, 1e-12, 1.0)
    tan2 = (1.0 - c * c) / (c * c)
    return np.where(cos_theta > 0.0, 2.0 / (1.0 + np.sqrt(1.0 + alpha * alpha * tan2)), 0.0)


@dataclass
class Crossing:
    """One interface crossing of N rays: the refracted and reflected directions, the fraction reflected, and the
    masking weights of each outgoing direction."""

    refracted: np.ndarray
    reflected: np.ndarray
    reflect_share: np.ndarray
    g_refracted: np.ndarray
    g_reflected: np.ndarray


def cross(
    d: np.ndarray, n: np.ndarray, eta: float, alpha: float, u: np.ndarray, iface: Interface, entering: bool
) -> Crossing:
    """Rays travelling along ``d`` [N, 3] reach an interface whose macroscopic normal ``n`` [N, 3] faces them
    (n . d < 0), with relative IOR ``eta`` (far side over near side); a microfacet normal is drawn at ``u``.
    ``entering``: the near side is the outside (the Fresnel term takes the outer cosine)."""
    wi = -d
    if alpha < SMOOTH_ALPHA:
        m = n
    else:
        t, b = _frame(n)
        local = np.stack([np.sum(wi * t, 1), np.sum(wi * b, 1), np.maximum(np.sum(wi * n, 1), 1e-9)], axis=1)
        local /= np.linalg.norm(local, axis=1, keepdims=True)
        ml = sample_vndf(local, alpha, u)
        m = ml[:, 0:1] * t + ml[:, 1:2] * b + ml[:, 2:3] * n
    cos_i = np.clip(np.sum(wi * m, 1), 1e-9, 1.0)
    sin2_t = (1.0 - cos_i * cos_i) / (eta * eta)
    tir = sin2_t >= 1.0
    cos_t = np.sqrt(np.maximum(1.0 - sin2_t, 0.0))
    refracted = -wi / eta + (cos_i / eta - cos_t)[:, None] * m
    refracted /= np.linalg.norm(refracted, axis=1, keepdims=True)
    reflected = 2.0 * cos_i[:, None] * m - wi
    reflected /= np.linalg.norm(reflected, axis=1, keepdims=True)
    f = np.where(tir, 1.0, iface.fresnel(cos_i if entering else cos_t))
    smooth = alpha < SMOOTH_ALPHA
    g_t = np.ones(len(d)) if smooth else smith_g1(-np.sum(refracted * n, 1), alpha)
    g_r = np.ones(len(d)) if smooth else smith_g1(np.sum(reflected * n, 1), alpha)
    return Crossing(refracted, reflected, f, np.where(tir, 0.0, g_t), g_r)


def far_side(p: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where rays from points ``p`` on the sphere travelling inwards along ``d`` leave it (put back on the sphere,
    so that rounding does not grow over internal reflections), and the distance."""
    t = np.maximum(-2.0 * np.sum(p * d, 1), 0.0)
    q = p + t[:, None] * d
    return q * (SPHERE_RADIUS / np.linalg.norm(q, axis=1, keepdims=True)), t


# -- tracing --------------------------------------------------------------------------------------------


def _points(n: int, salt: int) -> np.ndarray:
    """n fixed points in [0, 1)^2: a Hammersley set shifted by a rotation drawn from ``salt``."""
    k = np.arange(n)
    radical = np.zeros(n)
    f, kk = 0.5, k.copy()
    while np.any(kk):
        radical += f * (kk & 1)
        kk >>= 1
        f *= 0.5
    shift = np.random.default_rng(salt).random(2)
    return np.mod(np.stack([(k + 0.5) / n, radical], axis=1) + shift, 1.0)


def _thin_wall(
    d: np.ndarray, n: np.ndarray, iface: Interface, samples: list[np.ndarray], salt: int
) -> tuple[np.ndarray, np.ndarray]:
    """A thin wall crossed in and straight out at the same place: new directions and [N, 3] weights."""
    inside = cross(d, n, iface.eta, iface.alpha, samples[salt], iface, entering=True)
    out = cross(inside.refracted, n, 1.0 / iface.eta, iface.alpha, samples[salt + 1], iface, entering=False)
    w = (1.0 - inside.reflect_share) * inside.g_refracted * (1.0 - out.reflect_share) * out.g_refracted
    return out.refracted, w[:, None] * iface.tint


def transmitted(
    material: Material, scene: TransmissionScene, env: EnvMap | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Long: the paths (entry, walls or the volume's internal bounces) are one loop read best together.

    Radiance [res, res, 3] the material transmits to the camera through the sphere, and the sphere's mask
    (nothing for a model without transmission: it is opaque)."""
    env = env if env is not None else resolve(scene.env)
    surf = surface_pixels("sphere", scene.resolution)
    out = np.zeros((scene.resolution * scene.resolution, 3))
    if material.model not in INTERFACES:
        return out.reshape(scene.resolution, scene.resolution, 3), surf.mask()
    iface = interface_of(material)
    if not np.any(iface.weight > 0.0):
        return out.reshape(scene.resolution, scene.resolution, 3), surf.mask()
    k = 1 if iface.alpha < SMOOTH_ALPHA else scene.samples
    p0 = surf.normal * SPHERE_RADIUS
    n_pix = len(p0)
    # every pixel traced along k paths: path j of pixel i at row i * k + j
    p = np.repeat(p0, k, axis=0)
    n = np.repeat(surf.normal, k, axis=0)
    d = np.repeat(-surf.view, k, axis=0)
    crossings = 2 * scene.bounces + 4
    samples = [np.tile(_points(k, salt), (n_pix, 1)) for salt in range(crossings)]
    radiance = np.zeros((n_pix * k, 3))
    if iface.thin_walled:
        d, w = _thin_wall(d, n, iface, samples, 0)
        q, _ = far_side(p, d)
        d, w2 = _thin_wall(d, -q / SPHERE_RADIUS, iface, samples, 2)
        radiance += w * w2 * background(q, d, scene, env)
    else:
        entry = cross(d, n, iface.eta, iface.alpha, samples[0], iface, entering=True)
        w = ((1.0 - entry.reflect_share) * entry.g_refracted)[:, None] * iface.tint
        d = entry.refracted
        for bounce in range(scene.bounces):
            q, length = far_side(p, d)
            w = w * np.exp(-iface.sigma[None, :] * length[:, None])
            leave = cross(d, -q / SPHERE_RADIUS, 1.0 / iface.eta, iface.alpha, samples[1 + bounce], iface, False)
            share = ((1.0 - leave.reflect_share) * leave.g_refracted)[:, None]
            radiance += w * share * background(q, leave.refracted, scene, env)
            w = w * (leave.reflect_share * leave.g_reflected)[:, None]
            p, d = q, leave.reflected
    per_pixel = radiance.reshape(n_pix, k, 3).mean(axis=1) * iface.weight[None, :]
    out[surf.pixels] = per_pixel
    return out.reshape(scene.resolution, scene.resolution, 3), surf.mask()


def transmits(material: Material) -> bool:
    """Whether a uniform material lets light through (a model the probe reads, with a transmitted share > 0)."""
    return material.model in INTERFACES and bool(np.any(interface_of(material).weight > 0.0))


@lru_cache(maxsize=8)
def _backdrop(scene: TransmissionScene) -> tuple[EnvMap, tuple[np.ndarray, np.ndarray], np.ndarray]:
    """The map, its directional lights (unturned, seed 0) and the background seen past the sphere [res, res, 3]
    (read-only), shared by every render of a scene."""
    from matremap.core.scene import Scene

    env = resolve(scene.env)
    lights = directional_lights(env, scene.env_lights, 0.0)
    rays = Scene(resolution=scene.resolution).camera_rays().reshape(-1, 3)
    origins = np.broadcast_to([0.0, 0.0, CAMERA_Z], rays.shape)
    seen = background(np.asarray(origins, dtype=float), rays, scene, env)
    seen = seen.reshape(scene.resolution, scene.resolution, 3)
    for a in (*lights, seen):
        a.flags.writeable = False
    return env, lights, seen


def render(material: Material, scene: TransmissionScene | None = None) -> np.ndarray:
    """The transmission probe image [res, res, 3] (float32): on the sphere, the material's reflection of the
    environment (its BRDF under the directional lights and the mirror samples) plus what it transmits; elsewhere
    the background."""
    from matremap.renderers.embedded.environment import SVBRDFRender

    scene = scene or TransmissionScene()
    env, lights, seen = _backdrop(scene)
    through, mask = transmitted(material, scene, env)
    reflected = SVBRDFRender(material.model, dict(material.values), dict(material.options), "sphere", scene.resolution)
    image = through + reflected.render(*lights, env, 0.0, VIEW_MIRROR_SAMPLES).astype(float)
    return np.where(mask[..., None], image, seen).astype(np.float32)


def probe_scene(view: Scene) -> TransmissionScene:
    """The :class:`TransmissionScene` of a probe's transmission view (a :class:`~matremap.core.scene.Scene`
    whose ``transmission`` is set): its resolution, map, lights, paths and bounces."""
    t = view.transmission
    assert t is not None, "a transmission view"
    return TransmissionScene(
        resolution=view.resolution, env=t.env, env_lights=t.lights, bounces=t.bounces, samples=t.samples
    )


def render_view(materials: Sequence[Material], view: Scene) -> np.ndarray:
    """The transmission view of a probe, one image per material: float32 [N, res, res, 3]."""
    scene = probe_scene(view)
    return (
        np.stack([render(m, scene) for m in materials])
        if materials
        else np.zeros((0, view.resolution, view.resolution, 3), np.float32)
    )


__all__ = [
    "cycles_principled_equivalent",
    "mitsuba3_principled_equivalent",
    "mitsuba3_dielectric_interface",
    "mitsuba3_glass_equivalent",
    "mitsuba3_thindielectric_interface",
    "thin_slab_fresnel",
    "beckmann_as_ggx",
    "principled_specular",
    "standard_surface_equivalent",
    "EQUIVALENTS",
    "INTERFACES",
    "PALETTE",
    "Crossing",
    "Interface",
    "TransmissionScene",
    "background",
    "beer_sigma",
    "cross",
    "cycles_principled_interface",
    "far_side",
    "gltf_equivalent",
    "gltf_interface",
    "interface_of",
    "openpbr_equivalent",
    "mitsuba3_principled_interface",
    "openpbr_interface",
    "probe_scene",
    "render",
    "render_view",
    "sample_vndf",
    "smith_g1",
    "transmits",
    "standard_surface_interface",
    "transmitted",
]
