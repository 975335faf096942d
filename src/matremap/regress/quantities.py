"""A common vocabulary for remapping: roughness, specular reflectance F0 and diffuse albedo.

Models speak their renderer's names (``alpha``, ``specular_slope``, ``Roughness``; ``F0``,
``specularReflectance``, an IOR pair, a complex IOR). A transform maps these *quantities*:

``roughness``    the model's roughness-role parameter, as given;
``reflectance``  F0 per channel: the parameter itself when it is a reflectance, or F0 of an IOR by
                 eq. (1) of the paper, F0 = ((eta - 1)^2 + k^2) / ((eta + 1)^2 + k^2);
``diffuse``      the model's RGB diffuse-role parameter;

and for the layered models (:data:`matremap.dialects.mtlx.LAYER_PARAMS`) each layer's own quantities, read only
where asked for (:func:`read`'s ``layers``): ``coat_weight`` / ``sheen_weight`` (how much of the layer: OpenPBR 1.1
coat_weight, fuzz_weight; glTF's sheen, whose colour is its weight, the largest channel of sheenColor),
``coat_colour`` / ``sheen_colour`` (RGB, the colour at full weight: glTF's sheenColor divided by that largest channel)
and ``coat_roughness`` / ``sheen_roughness`` (a gloss read as 1 - gloss, Mitsuba 3's clearcoat_gloss). A model without
a layer's colour or roughness cannot express that quantity.

It converts back: F0 -> IOR is eta = (1 + sqrt F0) / (1 - sqrt F0) for dielectrics, and for a
conductor with eta held, k = sqrt((F0 (eta + 1)^2 - (eta - 1)^2) / (1 - F0)).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from matremap.core.material import Material
from matremap.core.models import ModelSpec, ParamSpec
from matremap.core.reflectance import as_floats
from matremap.dialects.mtlx import LAYER_PARAMS, Layer
from matremap.errors import MatremapError

#: the layers whose quantities a transform may map (:data:`matremap.dialects.mtlx.LAYER_PARAMS`)
LAYERS = ("coat", "sheen")
#: each layer's quantities: its weight, colour (RGB) and roughness
LAYER_QUANTITIES = tuple(f"{layer}_{part}" for layer in LAYERS for part in ("weight", "colour", "roughness"))
QUANTITIES = ("roughness", "reflectance", "diffuse", *LAYER_QUANTITIES)


def is_scalar(name: str) -> bool:
    """Whether a quantity is one value per element (a roughness, a layer's weight) rather than RGB."""
    return not name.endswith("colour") and name not in ("reflectance", "diffuse")


def layer_of(name: str) -> str | None:
    """The layer a quantity belongs to (``coat_roughness`` -> ``coat``), None for the base's."""
    return name.partition("_")[0] if name in LAYER_QUANTITIES else None


def layer_params(spec: ModelSpec) -> dict[str, Layer]:
    """The layers a model has and their parameters (empty for a model without layers)."""
    return dict(LAYER_PARAMS.get(spec.id, {}))


def layer_quantities(spec: ModelSpec, layers: tuple[str, ...] = LAYERS) -> tuple[str, ...]:
    """The quantities of ``layers`` that ``spec`` can express: a layer's weight, and its colour and roughness where
    the model has them."""
    out = []
    for name, layer in layer_params(spec).items():
        if name not in layers:
            continue
        out.append(f"{name}_weight")
        if layer.colour is not None:
            out.append(f"{name}_colour")
        if layer.roughness is not None:
            out.append(f"{name}_roughness")
    return tuple(out)


def roughness_param(spec: ModelSpec) -> ParamSpec | None:
    return next((p for p in spec.params if p.role == "roughness"), None)


def diffuse_param(spec: ModelSpec) -> ParamSpec | None:
    return next((p for p in spec.params if p.role == "diffuse" and p.channels == 3), None)


def available(spec: ModelSpec) -> tuple[str, ...]:
    """The quantities a model can express."""
    out = []
    if roughness_param(spec) is not None:
        out.append("roughness")
    if spec.reflectance is not None:
        out.append("reflectance")
    if diffuse_param(spec) is not None:
        out.append("diffuse")
    return (*out, *layer_quantities(spec))


def read(
    spec: ModelSpec, values: Mapping[str, np.ndarray], layers: tuple[str, ...] | frozenset[str] = ()
) -> dict[str, np.ndarray]:
    """Quantities from parameter arrays: scalars [...], RGB [..., 3]; roughness and the layers' weights and
    roughnesses [...], the others [..., 3]. ``layers``: the layers whose quantities to read too (those the model
    has)."""
    out: dict[str, np.ndarray] = {}
    rp = roughness_param(spec)
    if rp is not None:
        out["roughness"] = as_floats(values[rp.name])
    if spec.reflectance is not None:
        out["reflectance"] = spec.reflectance.f0(values, _channels(spec))
    dp = diffuse_param(spec)
    if dp is not None:
        out["diffuse"] = as_floats(values[dp.name])
        if spec.reflectance is not None:
            out["diffuse"] = spec.reflectance.albedo(out["diffuse"], values)
    for name, layer in layer_params(spec).items():
        if name in layers:
            out.update(read_layer(name, layer, values))
    return out


def read_layer(name: str, layer: Layer, values: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """One layer's quantities from parameter arrays (see the module docstring)."""
    out: dict[str, np.ndarray] = {}
    weight = as_floats(values[layer.weight])
    if layer.weighted_colour:  # glTF's sheenColor: its largest channel is the weight, the rest the colour
        top = np.max(weight, axis=-1)
        out[f"{name}_weight"] = top
        out[f"{name}_colour"] = np.where(top[..., None] > 0, weight / np.maximum(top, 1e-12)[..., None], 1.0)
    else:
        out[f"{name}_weight"] = weight
        if layer.colour is not None:
            out[f"{name}_colour"] = as_floats(values[layer.colour])
    if layer.roughness is not None:
        r = as_floats(values[layer.roughness])
        out[f"{name}_roughness"] = 1.0 - r if layer.gloss else r
    return out


def write_layer(name: str, layer: Layer, quantities: Mapping[str, np.ndarray], out: dict[str, np.ndarray]) -> list[str]:
    """Write one layer's quantities present in ``quantities`` into the parameter arrays ``out`` (which hold the
    template's values); returns the parameters written. glTF's sheenColor is its weight times its colour."""
    written = []
    weight, colour = quantities.get(f"{name}_weight"), quantities.get(f"{name}_colour")
    if layer.weighted_colour:
        if weight is not None or colour is not None:
            old = read_layer(name, layer, out) if weight is None or colour is None else {}
            w = as_floats(weight if weight is not None else old[f"{name}_weight"])
            c = as_floats(colour if colour is not None else old[f"{name}_colour"])
            out[layer.weight] = np.clip(w, 0.0, None)[..., None] * c
            written.append(layer.weight)
    else:
        if weight is not None:
            out[layer.weight] = as_floats(weight)
            written.append(layer.weight)
        if colour is not None and layer.colour is not None:
            out[layer.colour] = as_floats(colour)
            written.append(layer.colour)
    rough = quantities.get(f"{name}_roughness")
    if rough is not None and layer.roughness is not None:
        r = as_floats(rough)
        out[layer.roughness] = 1.0 - r if layer.gloss else r
        written.append(layer.roughness)
    return written


def _channels(spec: ModelSpec) -> dict[str, int]:
    return {p.name: p.channels for p in spec.params}


#: a value moved by more than this share of its parameter's range when clipped counts as clipped (the
#: nudges that keep F0 below 1 or a roughness above its mirror limit do not)
CLIP_TOLERANCE = 1e-3
#: the most of a parameter's range a regression's own error may excuse (a mapping whose held-out error is
#: larger than this is a poor one, and its overshoots count)
SLACK_MAX = 0.02


def write(
    spec: ModelSpec,
    quantities: Mapping[str, np.ndarray],
    template: Mapping[str, Any],
    clipped: dict[str, int] | None = None,
    slack: Mapping[str, float] | None = None,
) -> dict[str, np.ndarray]:
    """Parameter arrays for ``quantities``; parameters no quantity drives keep ``template``'s value
    (returned as read-only broadcast views: no memory per texel). Driven values are clipped to what the
    renderer accepts; ``clipped`` (parameter -> count) adds up the values that moved by more than
    :data:`CLIP_TOLERANCE` of the range (a regression asking for more than the target can give), or by
    more than ``slack`` (quantity -> the regression's own held-out error) where that is larger: a mapping
    that overshoots a bound it was trained at by less than its error asks for nothing the target lacks.
    The roughness is one quantity: each follower of an isotropic pair (:attr:`~ModelSpec.isotropic`) takes its
    leader's value."""
    slack = slack or {}
    name0 = next(iter(quantities))
    shape = np.shape(quantities[name0]) if is_scalar(name0) else np.shape(quantities[name0])[:-1]
    out: dict[str, np.ndarray] = {}
    own_slack: dict[str, float] = {}  # the parameters whose value is the quantity itself
    for p in spec.params:
        v = np.asarray(template[p.name], dtype=float)
        out[p.name] = np.broadcast_to(
            v if p.channels == 3 else v.reshape(()), (*shape, 3) if p.channels == 3 else shape
        )
    driven: list[str] = []
    rp = roughness_param(spec)
    if rp is not None and "roughness" in quantities:
        out[rp.name] = as_floats(quantities["roughness"])
        driven.append(rp.name)
        own_slack[rp.name] = slack.get("roughness", 0.0)
    if spec.reflectance is not None and "reflectance" in quantities:
        f0 = as_floats(quantities["reflectance"])
        if clipped is not None:
            count_clipped(f0, 0.0, 1.0, "reflectance", clipped, slack.get("reflectance", 0.0))
        f0 = clip(f0, 0.0, 1.0 - 1e-7)
        driven += spec.reflectance.write_f0(f0, out, _channels(spec), quantities.get("diffuse"))
    dp = diffuse_param(spec)
    writes_albedo = spec.reflectance is not None and spec.reflectance.writes_albedo
    if dp is not None and "diffuse" in quantities and not writes_albedo:
        out[dp.name] = as_floats(quantities["diffuse"])
        driven.append(dp.name)
        own_slack[dp.name] = slack.get("diffuse", 0.0)
    for name, layer in layer_params(spec).items():
        for param in write_layer(name, layer, quantities, out):
            driven.append(param)
            own_slack[param] = max((v for k, v in slack.items() if layer_of(k) == name), default=0.0)
    bounds = {p.name: p.bounds for p in spec.params}
    for name in driven:  # stay inside what the renderer accepts (in place: these arrays are ours)
        a = out[name]
        if clipped is not None:
            count_clipped(a, *bounds[name], name, clipped, own_slack.get(name, 0.0))
        if uniform(a):
            out[name] = clip(a, *bounds[name])
            continue
        if not a.flags.writeable or not a.flags.owndata:
            a = np.array(a)
        out[name] = np.clip(a, *bounds[name], out=a)
    for follower, leader in spec.isotropic:  # one roughness quantity: an anisotropic model written isotropic
        if leader in driven:
            out[follower] = out[leader] if uniform(out[leader]) else out[leader].copy()
    return out


def count_clipped(a: np.ndarray, lo: float, hi: float, name: str, counts: dict[str, int], slack: float = 0.0) -> None:
    """Add to ``counts[name]`` the values of ``a`` that clipping to [lo, hi] moves by more than
    :data:`CLIP_TOLERANCE` of the range or ``slack`` (at most :data:`SLACK_MAX` of it), whichever is larger
    (a broadcast of one value counts for every element)."""
    width = hi - lo
    tol = max(CLIP_TOLERANCE * width, min(slack, SLACK_MAX * width))
    probe = a[:1] if uniform(a) else a
    n = int(np.count_nonzero((probe < lo - tol) | (probe > hi + tol)))
    if n:
        counts[name] = counts.get(name, 0) + (n * a.shape[0] if uniform(a) else n)


def uniform(a: np.ndarray) -> bool:
    """Whether an array is one value broadcast along its first (element) axis."""
    return a.ndim > 0 and a.shape[0] > 1 and a.strides[0] == 0


def clip(a: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """np.clip that keeps a broadcast of one value a broadcast (no memory per element)."""
    return np.broadcast_to(np.clip(a[:1], lo, hi), a.shape) if uniform(a) else np.clip(a, lo, hi)


def material_values(m: Material) -> dict[str, np.ndarray]:
    """A material's parameter values as arrays (scalars 0-d, RGB (3,))."""
    return {p.name: (m.values[p.name][0] if p.channels == 1 else m.values[p.name]) for p in m.spec.params}


def check_quantities(spec: ModelSpec, needed: tuple[str, ...], role: str) -> None:
    missing = [q for q in needed if q not in available(spec)]
    if missing:
        raise MatremapError(f"{role} model {spec.id} cannot express {', '.join(missing)}")
