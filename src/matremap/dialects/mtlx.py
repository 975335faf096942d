"""MaterialX 1.39 surface shaders as models: OpenPBR Surface and Autodesk Standard Surface (opaque part).

Parameters are named exactly as the MaterialX 1.39 inputs of ``ND_open_pbr_surface_surfaceshader`` and
``ND_standard_surface_surfaceshader``, with their defaults. Only the opaque reflection of each shader is
modelled, and each one's transmission: subsurface, thin film, emission, opacity, anisotropy and normal inputs are
not parameters here (a file using them is refused by its reader, not silently flattened). OpenPBR's
``transmission_weight`` ("Translucent base") takes that share of the dielectric base's diffuse away in
reflection (its specular reflection stays); what it transmits -- ``transmission_color`` and
``transmission_depth`` (Beer-Lambert, or a tint of the interface at depth 0) and ``geometry_thin_walled`` -- is
drawn by the transmission probe (``renderers/embedded/transmission.py``).

mtlx:open_pbr_surface -- OpenPBR Surface specification v1.1 (ASWF, 2024; text of v1.1.1), reduced to a
mixture of lobes with albedo scaling as its section "Reduction to a mixture of lobes" derives
(evaluated by ``renderers/embedded/evaluators/openpbr.py``, which cites each section):

  f = F fuzz + (1 - F E_fuzz) [ C coat + lerp(1, T_coat (1 - E_coat), C) Delta_C base ]
  base = lerp(specular + (1 - E_specular) base_weight EON(base_color, base_diffuse_roughness),
              metal, base_metalness)

  with the dielectric specular lobe's IOR ratio from specular_ior (over the coat where coat_weight,
  with the spec's TIR fix) modulated by specular_weight and its Fresnel tinted by specular_color; the
  metal's F82-tint Fresnel (F0 = base_weight base_color, tint = specular_color, times specular_weight);
  the coat's own GGX lobe (coat_roughness, coat_ior), its absorption coat_color along the refracted
  view and light paths, its darkening Delta_C (coat_darkening) and its roughening of the base lobes; the
  Zeltner et al. LTC fuzz (fuzz_weight, fuzz_color, fuzz_roughness). Option ``multiscatter``: Turquin's
  energy compensation on every GGX lobe (default) or none.

mtlx:standard_surface -- Autodesk Standard Surface specification v1.0.1 (``1.0.1.1``), section "Closures":
the closure mixture with reflectance() the lobes' directional albedos
(``renderers/embedded/evaluators/standard_surface.py``):

  coat_layer = coat coat_brdf + lerp(1, coat_color (1 - E_coat), coat) specular_mixture
  specular_mixture = metalness metal_brdf + (1 - metalness) specular_reflection_layer
  specular_reflection_layer = specular specular_color specular_brdf
                              + (1 - specular specular_color E_specular) transmission_sheen_mix
  transmission_sheen_mix = transmission transm_color specular_btdf + (1 - transmission) sheen_layer
  sheen_layer = sheen sheen_color sheen_brdf + (1 - sheen E_sheen) base base_color oren_nayar

  ("Specular transmission"): specular_btdf reflects nothing, so in reflection ``transmission`` takes that share
  of the sheen and diffuse away; what it transmits (transm_color = transmission_color at transmission_depth 0,
  else Beer-Lambert inside; ``thin_walled``) is drawn by the transmission probe
  (``renderers/embedded/transmission.py``). Not parameters: transmission_scatter (and its anisotropy),
  transmission_dispersion, transmission_extra_roughness (their defaults 0).

  metal_brdf with Gulbrandsen's artist-friendly Fresnel (reflectivity base base_color, edge tint
  specular specular_color); Estevez-Kulla ("Charlie") sheen; Oren-Nayar diffuse (diffuse_roughness).
"""

from __future__ import annotations

import shlex
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from matremap.core.models import ModelSpec, OptionSpec, ParamSpec
from matremap.core.reflectance import Dielectric, Metalness


def _rgb(name: str, role: str, default: float, fit: bool = True, doc: str = "") -> ParamSpec:
    return ParamSpec(name, role, (default,) * 3, (0.0, 1.0), channels=3, fit=fit, doc=doc)


def _held(
    name: str, default: float, bounds: tuple[float, float] = (0.0, 1.0), role: str = "other", doc: str = ""
) -> ParamSpec:
    return ParamSpec(name, role, default, bounds, fit=False, doc=doc)


_MULTISCATTER = OptionSpec(
    "multiscatter",
    ("turquin", "none"),
    "turquin",
    "energy compensation of the GGX lobes: Turquin 2019 (the lobe times 1 + F0 (1 - E)/E) or none",
)

OPEN_PBR_SURFACE = ModelSpec(
    id="mtlx:open_pbr_surface",
    microfacet="ggx",
    summary="OpenPBR Surface 1.1 (opaque): EON diffuse, F82-tint metal, coat, fuzz; albedo-scaled layers",
    params=(
        _held("base_weight", 1.0, doc="multiplier of base_color (diffuse albedo and metal F0)"),
        _rgb("base_color", "diffuse", 0.8, doc="diffuse albedo; the metal's F0"),
        _held("base_metalness", 0.0, role="specular", doc="mix of metal over dielectric (held at 0 in fits)"),
        _held("base_diffuse_roughness", 0.0, doc="EON (energy-preserving Oren-Nayar) roughness"),
        _held("specular_weight", 1.0, (0.0, 10.0), doc="multiplies the dielectric F0 (through the IOR) and the metal"),
        _rgb("specular_color", "other", 1.0, fit=False, doc="tints the dielectric Fresnel; the metal's F82 edge tint"),
        ParamSpec("specular_roughness", "roughness", 0.3, (0.0, 1.0), doc="alpha = roughness^2"),
        ParamSpec("specular_ior", "fresnel", 1.5, (1.0, 5.0), doc="IOR of the base dielectric"),
        _held("coat_weight", 0.0, role="specular", doc="coverage of the coat (held at 0 in fits: --free coat_weight)"),
        _rgb("coat_color", "other", 1.0, fit=False, doc="square of the coat's normal-incidence transmittance"),
        _held("coat_roughness", 0.0, doc="roughness of the coat's GGX lobe"),
        _held("coat_ior", 1.6, (1.0, 5.0), doc="IOR of the coat"),
        _held("coat_darkening", 1.0, doc="1: the coat darkens the base by internal reflection; 0: compensated"),
        _held("fuzz_weight", 0.0, doc="coverage of the fuzz (Zeltner et al. LTC sheen)"),
        _rgb("fuzz_color", "other", 1.0, fit=False, doc="reflection albedo colour of the fuzz"),
        _held("fuzz_roughness", 0.5, doc="fuzz roughness (fibre-like at 0, dusty at 1)"),
        _held("transmission_weight", 0.0, doc="share of the dielectric base that is translucent (refracts)"),
        _rgb("transmission_color", "other", 1.0, fit=False, doc="colour of the transmitted light (see depth)"),
        _held("transmission_depth", 0.0, (0.0, 1e6), doc="distance at which white light takes transmission_color"),
        _held("geometry_thin_walled", 0.0, doc="1: a thin shell (no refraction), 0: the boundary of a volume"),
    ),
    options=(_MULTISCATTER,),
    # the diffuse part keeps the fuzz (a sheen is absorbed by a diffuse) and the coat's tint (coat_ior 1: no
    # coat reflection, no darkening); the specular part is every lobe over a black base, without the fuzz
    diffuse_only={"base_metalness": 0.0, "specular_weight": 0.0, "coat_ior": 1.0},
    specular_only={"base_color": 0.0, "fuzz_weight": 0.0},
    specialisations=(
        (
            "base_metalness",
            1.0,
            {"roles": {"base_color": "specular", "specular_ior": "other"}, "diffuse_only": None, "specular_only": {}},
        ),
    ),
    reflectance=Metalness("base_color", "base_metalness", Dielectric("specular_ior")),
)

STANDARD_SURFACE = ModelSpec(
    id="mtlx:standard_surface",
    microfacet="ggx",
    summary="Autodesk Standard Surface 1.0.1: Oren-Nayar, artist-friendly metal, coat, sheen, specular transmission",
    params=(
        _held("base", 1.0, doc="multiplier of base_color"),
        _rgb("base_color", "diffuse", 0.8, doc="diffuse albedo; the metal's reflectivity at normal incidence"),
        _held("diffuse_roughness", 0.0, doc="Oren-Nayar roughness"),
        _held("metalness", 0.0, role="specular", doc="mix of metal over the dielectric layers (held at 0 in fits)"),
        _held("specular", 1.0, doc="weight of the dielectric specular lobe; multiplier of the metal's edge tint"),
        _rgb("specular_color", "other", 1.0, fit=False, doc="tint of the dielectric lobe; the metal's edge colour"),
        ParamSpec("specular_roughness", "roughness", 0.2, (0.0, 1.0), doc="alpha = roughness^2"),
        ParamSpec("specular_IOR", "fresnel", 1.5, (1.0, 5.0), doc="IOR of the dielectric specular lobe"),
        _held("coat", 0.0, role="specular", doc="weight of the coat (held at 0 in fits: --free coat)"),
        _rgb("coat_color", "other", 1.0, fit=False, doc="tint of everything under the coat"),
        _held("coat_roughness", 0.1, doc="roughness of the coat's GGX lobe (alpha = roughness^2)"),
        _held("coat_IOR", 1.5, (1.0, 5.0), doc="IOR of the coat"),
        _held("sheen", 0.0, doc="weight of the sheen lobe"),
        _rgb("sheen_color", "other", 1.0, fit=False, doc="colour of the sheen lobe"),
        _held("sheen_roughness", 0.3, doc="roughness of the sheen lobe"),
        _held("transmission", 0.0, doc="share of the dielectric base that is specular transmission (refracts)"),
        _rgb("transmission_color", "other", 1.0, fit=False, doc="tint of the transmission (see depth)"),
        _held("transmission_depth", 0.0, (0.0, 1e6), doc="distance at which white light takes transmission_color"),
        _held("thin_walled", 0.0, doc="1: a thin shell (no refraction), 0: the boundary of a solid"),
    ),
    options=(_MULTISCATTER,),
    diffuse_only={"metalness": 0.0, "specular": 0.0, "coat_IOR": 1.0},  # keeps the sheen and the coat's tint
    specular_only={"base_color": 0.0, "sheen": 0.0},
    specialisations=(
        (
            "metalness",
            1.0,
            {"roles": {"base_color": "specular", "specular_IOR": "other"}, "diffuse_only": None, "specular_only": {}},
        ),
    ),
    reflectance=Metalness("base_color", "metalness", Dielectric("specular_IOR")),
)

#: the models of this dialect, in the order they are listed
MODELS = (OPEN_PBR_SURFACE, STANDARD_SURFACE)
#: a white Lambertian surface of albedo 1 in this family (no specular lobe, Lambertian diffuse)
WHITE_REFERENCE = ("mtlx:standard_surface", {"base": 1.0, "base_color": 1.0, "specular": 0.0})

#: the layers of the layered models (any dialect) a fit can lose: layer -> the parameter weighing it in
LAYERS: dict[str, dict[str, str]] = {
    OPEN_PBR_SURFACE.id: {"coat": "coat_weight", "sheen": "fuzz_weight", "transmission": "transmission_weight"},
    STANDARD_SURFACE.id: {"coat": "coat", "sheen": "sheen", "transmission": "transmission"},
    "mitsuba3:principled": {"coat": "clearcoat", "sheen": "sheen", "transmission": "spec_trans"},
    "gltf:pbr": {"coat": "clearcoat", "sheen": "sheenColor", "transmission": "transmission"},
    "cycles:principled": {"coat": "Coat Weight", "sheen": "Sheen Weight", "transmission": "Transmission Weight"},
    "usd:preview_surface": {"coat": "clearcoat"},
    # Mitsuba 3's glasses transmit whatever their parameters: the multiplier of what goes through stands for a weight
    **{
        glass: {"transmission": "specular_transmittance"}
        for glass in ("mitsuba3:dielectric", "mitsuba3:roughdielectric", "mitsuba3:thindielectric")
    },
}


@dataclass(frozen=True)
class Layer:
    """A layer's parameters in one model: its weight, colour and roughness (None where the model has none).
    ``gloss``: the roughness parameter is a gloss (1 - roughness, Mitsuba 3's clearcoat_gloss);
    ``weighted_colour``: the colour is also the weight (glTF's sheenColor: no sheen at black)."""

    weight: str
    colour: str | None = None
    roughness: str | None = None
    gloss: bool = False
    weighted_colour: bool = False


#: the parameters of each layer of the layered models (its weight is :data:`LAYERS`')
LAYER_PARAMS: dict[str, dict[str, Layer]] = {
    OPEN_PBR_SURFACE.id: {
        "coat": Layer("coat_weight", "coat_color", "coat_roughness"),
        "sheen": Layer("fuzz_weight", "fuzz_color", "fuzz_roughness"),
    },
    STANDARD_SURFACE.id: {
        "coat": Layer("coat", "coat_color", "coat_roughness"),
        "sheen": Layer("sheen", "sheen_color", "sheen_roughness"),
    },
    "mitsuba3:principled": {
        "coat": Layer("clearcoat", None, "clearcoat_gloss", gloss=True),
        "sheen": Layer("sheen", None, None),
    },
    "gltf:pbr": {
        "coat": Layer("clearcoat", None, "clearcoatRoughness"),
        "sheen": Layer("sheenColor", "sheenColor", "sheenRoughness", weighted_colour=True),
    },
    "cycles:principled": {
        "coat": Layer("Coat Weight", "Coat Tint", "Coat Roughness"),
        "sheen": Layer("Sheen Weight", "Sheen Tint", "Sheen Roughness"),
    },
    "usd:preview_surface": {"coat": Layer("clearcoat", None, "clearcoatRoughness")},
}


def freed_layers(
    source_model: str, source_values: Mapping[str, Any], target: ModelSpec, held: Iterable[str] = ()
) -> tuple[list[str], dict[str, Any]]:
    """The target parameters to free, and where to start them, for each layer the source has (weight > 0) and
    the target too (:data:`LAYER_PARAMS`): a coat is fitted with the target's coat, a sheen with its sheen,
    instead of being absorbed into the base. The start is the source layer's weight, colour and roughness
    (gloss = 1 - roughness), clipped to the target's bounds: from the layers at 0 a fit can stay in the minimum
    where the layer is off (docs/models.md). Parameters in ``held`` (the user's --fix) stay held."""
    source, layers = LAYER_PARAMS.get(source_model, {}), LAYER_PARAMS.get(target.id, {})
    spec = target
    held = set(held)
    free: list[str] = []
    start: dict[str, Any] = {}
    for name, src in source.items():
        tgt = layers.get(name)
        weight = _layer_amount(source_values, src)
        if tgt is None or weight <= 0.0:
            continue
        colour = layer_colour(source_values, src)
        rough = float(np.mean(source_values.get(src.roughness, 0.5))) if src.roughness else 0.5
        rough = 1.0 - rough if src.gloss else rough
        values: dict[str, Any] = {tgt.weight: weight}
        if tgt.weighted_colour:
            values[tgt.weight] = (weight * colour).tolist()
        elif tgt.colour is not None:
            values[tgt.colour] = colour.tolist()
        if tgt.roughness is not None:
            values[tgt.roughness] = 1.0 - rough if tgt.gloss else rough
        for param, v in values.items():
            if param in held:
                continue
            lo, hi = spec.param(param).bounds
            free.append(param)
            start[param] = np.clip(np.asarray(v, dtype=float), lo, hi).tolist()
    return free, start


def _layer_amount(values: Mapping[str, Any], layer: Layer) -> float:
    """How much of a layer a material has: its weight (glTF's sheen: the largest channel of its colour)."""
    return float(np.max(np.asarray(values.get(layer.weight, 0.0), dtype=float)))


def layer_colour(values: Mapping[str, Any], layer: Layer) -> np.ndarray:
    """A layer's colour as RGB (white where the model has none; glTF's sheenColor divided by its weight)."""
    if layer.colour is None:
        return np.ones(3)
    c = np.broadcast_to(np.asarray(values.get(layer.colour, 1.0), dtype=float), (3,))
    if layer.weighted_colour:
        top = float(np.max(c))
        return c / top if top > 0 else np.ones(3)
    return np.array(c)


def layers_on(model: str, values: Mapping[str, Any]) -> list[str]:
    """The layers (:data:`LAYERS`) a material of ``model`` has: those whose weight is above 0."""
    return [
        layer
        for layer, weight in LAYERS.get(model, {}).items()
        if float(np.max(np.asarray(values.get(weight, 0.0), dtype=float))) > 0.0
    ]


#: the layers a weight map may blend per texel (:func:`layer_weights`)
BLENDED_LAYERS = ("coat", "sheen")


def layer_weights(spec: ModelSpec) -> list[str]:
    """The scalar weights of ``spec``'s coat and sheen (:data:`LAYERS`): the parameters whose map blends a
    layered and a bare material per texel, as each model mixes its layer in linearly by its weight (OpenPBR 1.1
    coat_weight and fuzz_weight, Standard Surface 1.0.1 coat and sheen, glTF clearcoat, Cycles Coat Weight and
    Sheen Weight, Mitsuba 3 principled clearcoat and sheen)."""
    layers = LAYERS.get(spec.id, {})
    names = [layers[layer] for layer in BLENDED_LAYERS if layer in layers]
    return [n for n in names if spec.param(n).channels == 1]


def transmission_weight(spec: ModelSpec) -> str | None:
    """The scalar weight of ``spec``'s transmission (:data:`LAYERS`), or None (a model without one, or whose
    transmission is a colour: Mitsuba 3's glasses): a map of it blends per texel the material letting light through
    and the same material opaque, as each model mixes its transmission into the dielectric base linearly by its weight
    (OpenPBR 1.1 transmission_weight, Standard Surface 1.0.1 transmission, glTF KHR_materials_transmission
    transmissionFactor, Cycles Transmission Weight, Mitsuba 3 principled spec_trans)."""
    name = LAYERS.get(spec.id, {}).get("transmission")
    return name if name is not None and spec.param(name).channels == 1 else None


#: the parameters only the light a model lets through uses (its tint, the depth that tint is reached at, a volume,
#: a thin wall): where a texel lets no light through they draw nothing (OpenPBR 1.1 "Transmission", Standard Surface
#: 1.0.1 "Specular transmission", glTF KHR_materials_volume)
THROUGH_PARAMS: dict[str, tuple[str, ...]] = {
    OPEN_PBR_SURFACE.id: ("transmission_color", "transmission_depth", "geometry_thin_walled"),
    STANDARD_SURFACE.id: ("transmission_color", "transmission_depth", "thin_walled"),
    "gltf:pbr": ("thickness", "attenuationDistance", "attenuationColor"),
}
#: models whose transmission has a colour of its own, so that a texel wholly letting light through shows none of the
#: base colour (OpenPBR's and Standard Surface's base_color is the diffuse albedo only; glTF's, Blender's and Mitsuba's
#: base colour is the glass's tint too)
OWN_TINT = (OPEN_PBR_SURFACE.id, STANDARD_SURFACE.id)


def layer_roughnesses(model: str) -> list[str]:
    """The roughness (or gloss) parameters of ``model``'s layers (:data:`LAYER_PARAMS`): a map of one is blended per
    texel between a few levels of it (:class:`matremap.svbrdf.mixed.Levels`)."""
    return [layer.roughness for layer in LAYER_PARAMS.get(model, {}).values() if layer.roughness is not None]


def layer_textures(model: str, maps: Iterable[str]) -> list[str]:
    """The parameters among ``maps`` (a material's textured parameters) that are a layer's weight, colour or
    roughness (:data:`LAYERS`, :data:`LAYER_PARAMS`)."""
    names = set(LAYERS.get(model, {}).values())
    for layer in LAYER_PARAMS.get(model, {}).values():
        names |= {n for n in (layer.weight, layer.colour, layer.roughness) if n is not None}
    return [m for m in maps if m in names]


def coat_tint(model: str, values: Mapping[str, Any]) -> np.ndarray | None:
    """What a coloured coat does to the colour of everything under it, lerp(1, coat colour, coat weight) per
    channel ([..., 3], values may be maps), or None for a model without a coat colour. Standard Surface 1.0.1
    ("Coating": the base is multiplied by coat_color where coat is 1) and OpenPBR 1.1 (coat_color is the square
    of the coat's normal-incidence transmittance: light crosses it twice) both tint so; their (1 - E_coat)
    terms are left out: this is the hue the base is seen with, for the gate's map checks, not a render."""
    layer = LAYER_PARAMS.get(model, {}).get("coat")
    if layer is None or layer.colour is None:
        return None
    weight = np.asarray(values.get(layer.weight, 0.0), dtype=float)
    colour = np.asarray(values.get(layer.colour, 1.0), dtype=float)
    weight = weight[..., None] if weight.ndim else weight
    return 1.0 + np.clip(weight, 0.0, 1.0) * (colour - 1.0)


def opaque_share(model: str, values: Mapping[str, Any]) -> np.ndarray | None:
    """The share of a base that does not let light through, 1 - transmission weight ([...], values may be maps),
    or None for a model without a scalar transmission weight: the diffuse a transmissive material shows is its
    albedo times this share (OpenPBR 1.1 mixes its base as (1 - transmission_weight) diffuse + transmission_weight
    transmission; Standard Surface 1.0.1, glTF KHR_materials_transmission and Blender's Principled BSDF alike).
    For the gate's map checks: the base colour of a clear glass is its tint, not a diffuse anyone sees."""
    name = LAYERS.get(model, {}).get("transmission")
    if name is None or model not in LAYER_PARAMS:  # a glass's transmittance is a colour, and it has no diffuse
        return None
    return 1.0 - np.clip(np.asarray(values.get(name, 0.0), dtype=float), 0.0, 1.0)


def absorbed_layers(
    source_model: str, source_values: Mapping[str, Any], target_model: str, target_values: Mapping[str, Any]
) -> list[str]:
    """One note per layer the source has (weight > 0) that the fitted target has not: a target without such
    a layer, or with it held off (then how to free it). The fit's other parameters absorbed its look."""
    notes = []
    target_layers = LAYERS.get(target_model, {})
    for layer, weight in LAYERS.get(source_model, {}).items():
        amount = float(np.max(np.asarray(source_values.get(weight, 0.0), dtype=float)))
        if amount <= 0.0:
            continue
        own = target_layers.get(layer)
        if own is not None and float(np.max(np.asarray(target_values.get(own, 0.0), dtype=float))) > 0.0:
            continue
        where = (
            f"{target_model} has no {layer} layer"
            if own is None
            else f"{target_model}'s {own} stayed 0 (free it with --free {shlex.quote(own)} --strategy simple)"
        )
        notes.append(
            f"the source's {layer} layer ({weight} {amount:.3g}) was absorbed into the other parameters: {where}"
        )
    return notes
