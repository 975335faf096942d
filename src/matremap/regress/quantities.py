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
from matremap.core.optics import dielectric_f0, f0_from_ior, ior_from_f0
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
    if spec.reflectance:
        out.append("reflectance")
    if diffuse_param(spec) is not None:
        out.append("diffuse")
    return tuple(out)


def _rgb(v: np.ndarray, channels: int) -> np.ndarray:
    v = as_floats(v)
    return np.repeat(v[..., None], 3, axis=-1) if channels == 1 else v


def read(spec: ModelSpec, values: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Quantities from parameter arrays: scalars [...], RGB [..., 3]; roughness [...], the others [..., 3]."""
    out: dict[str, np.ndarray] = {}
    rp = roughness_param(spec)
    if rp is not None:
        out["roughness"] = as_floats(values[rp.name])
    if spec.reflectance:
        kind, *names = spec.reflectance
        ch = {p.name: p.channels for p in spec.params}
        if kind == "param":
            out["reflectance"] = _rgb(values[names[0]], ch[names[0]])
        elif kind == "dielectric":  # (interior IOR[, exterior IOR])
            eta = as_floats(values[names[0]]) / (as_floats(values[names[1]]) if len(names) > 1 else 1.0)
            out["reflectance"] = _rgb(f0_from_ior(eta), 1)
        elif kind == "conductor":  # (eta, k) or (eta, k, exterior IOR)
            ext = as_floats(values[names[2]])[..., None] if len(names) > 2 else 1.0
            eta = _rgb(values[names[0]], ch[names[0]]) / ext
            k = _rgb(values[names[1]], ch[names[1]]) / ext
            out["reflectance"] = f0_from_ior(eta, k)
        elif kind == "metal-rough":  # glTF: F0 = mix(dielectric f0, baseColor, metallic)
            base, metallic, ior, specular, tint = names
            m = as_floats(values[metallic])[..., None]
            f0_d = dielectric_f0(
                as_floats(values[ior])[..., None], as_floats(values[specular])[..., None], _rgb(values[tint], 3)
            )
            out["reflectance"] = f0_d * (1.0 - m) + _rgb(values[base], 3) * m
        else:  # pragma: no cover - specs are checked by tests
            raise ValueError(kind)
    dp = diffuse_param(spec)
    if dp is not None:
        out["diffuse"] = as_floats(values[dp.name])
        if spec.reflectance and spec.reflectance[0] == "metal-rough":  # a metal's base colour is no albedo
            out["diffuse"] = out["diffuse"] * (1.0 - as_floats(values[spec.reflectance[2]])[..., None])
    return out


def as_floats(v: Any) -> np.ndarray:
    """An array of floats, keeping float32 (texture maps) as float32."""
    a = np.asarray(v)
    return a if a.dtype in (np.float32, np.float64) else a.astype(float)


def write(spec: ModelSpec, quantities: Mapping[str, np.ndarray], template: Mapping[str, Any]) -> dict[str, np.ndarray]:
    """Parameter arrays for ``quantities``; parameters no quantity drives keep ``template``'s value
    (returned as read-only broadcast views: no memory per texel)."""
    if "roughness" in quantities:
        shape = np.shape(quantities["roughness"])
    else:
        shape = np.shape(next(iter(quantities.values())))[:-1]
    out: dict[str, np.ndarray] = {}
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
    if spec.reflectance and "reflectance" in quantities:
        f0 = clip(as_floats(quantities["reflectance"]), 0.0, 1.0 - 1e-7)
        kind, *names = spec.reflectance
        ch = {p.name: p.channels for p in spec.params}
        if kind == "param":
            out[names[0]] = f0 if ch[names[0]] == 3 else f0.mean(axis=-1)
            driven.append(names[0])
        elif kind == "dielectric":
            out[names[0]] = ior_from_f0(f0.mean(axis=-1)) * (out[names[1]] if len(names) > 1 else 1.0)
            driven.append(names[0])
        elif kind == "conductor":
            ext = out[names[2]][..., None] if len(names) > 2 else 1.0
            eta = _rgb(out[names[0]], ch[names[0]]) / ext
            k2 = (f0 * (eta + 1) ** 2 - (eta - 1) ** 2) / (1.0 - f0)
            out[names[1]] = np.sqrt(np.maximum(k2, 0.0)) * ext
            driven.append(names[1])
        elif kind == "metal-rough":
            driven += _write_metal_rough(names, f0, quantities.get("diffuse"), out)
    dp = diffuse_param(spec)
    if dp is not None and "diffuse" in quantities and spec.reflectance[:1] != ("metal-rough",):
        out[dp.name] = as_floats(quantities["diffuse"])
        driven.append(dp.name)
    bounds = {p.name: p.bounds for p in spec.params}
    for name in driven:  # stay inside what the renderer accepts (in place: these arrays are ours)
        a = out[name]
        if uniform(a):
            out[name] = clip(a, *bounds[name])
            continue
        if not a.flags.writeable or not a.flags.owndata:
            a = np.array(a)
        out[name] = np.clip(a, *bounds[name], out=a)
    return out


def _write_metal_rough(
    names: list[str], f0: np.ndarray, diffuse: np.ndarray | None, out: dict[str, np.ndarray]
) -> list[str]:
    """glTF metallic-roughness from F0 and albedo, the template's metallic deciding per texel:
    a metal (metallic >= 0.5) takes F0 as base colour; a dielectric takes the albedo as base colour
    and F0 through specularColor = F0 / f0(ior) / specular (KHR_materials_specular), written only
    where it differs from the template's."""
    base, metallic, ior, specular, tint = names
    metal = (np.asarray(out[metallic]) >= 0.5)[..., None]
    albedo = np.asarray(out[base]) if diffuse is None else as_floats(diffuse)
    out[base] = np.where(metal, f0, albedo)
    driven = [base]
    if not np.all(metal):
        f0_ior = dielectric_f0(np.asarray(out[ior])[..., None], 1.0, 1.0)
        scale = np.maximum(np.asarray(out[specular])[..., None] * f0_ior, 1e-12)
        current = dielectric_f0(
            np.asarray(out[ior])[..., None], np.asarray(out[specular])[..., None], np.asarray(out[tint])
        )
        if np.max(np.abs(np.where(metal, current, f0) - current)) > 1e-4 * max(float(np.max(current)), 1e-12):
            out[tint] = np.where(metal, np.asarray(out[tint]), f0 / scale)
            driven.append(tint)
    return driven


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
