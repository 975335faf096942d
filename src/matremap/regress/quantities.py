"""A common vocabulary for remapping: roughness, specular reflectance F0 and diffuse albedo.

Models speak their renderer's names (``alpha``, ``specular_slope``, ``Roughness``; ``F0``,
``specularReflectance``, an IOR pair, a complex IOR). A transform maps these *quantities*:

``roughness``    the model's roughness-role parameter, as given;
``reflectance``  F0 per channel: the parameter itself when it is a reflectance, or F0 of an IOR by
                 eq. (1) of the paper, F0 = ((eta - 1)^2 + k^2) / ((eta + 1)^2 + k^2);
``diffuse``      the model's RGB diffuse-role parameter.

and converts back: F0 -> IOR is eta = (1 + sqrt F0) / (1 - sqrt F0) for dielectrics, and for a
conductor with eta held, k = sqrt((F0 (eta + 1)^2 - (eta - 1)^2) / (1 - F0)).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from matremap.core.material import Material
from matremap.core.models import ModelSpec, ParamSpec
from matremap.core.reflectance import as_floats
from matremap.errors import MatremapError

QUANTITIES = ("roughness", "reflectance", "diffuse")


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
    return tuple(out)


def read(spec: ModelSpec, values: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Quantities from parameter arrays: scalars [...], RGB [..., 3]; roughness [...], the others [..., 3]."""
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
    return out


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
    that overshoots a bound it was trained at by less than its error asks for nothing the target lacks."""
    slack = slack or {}
    if "roughness" in quantities:
        shape = np.shape(quantities["roughness"])
    else:
        shape = np.shape(next(iter(quantities.values())))[:-1]
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
