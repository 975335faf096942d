"""Reflectance models as data, and materials (a model plus parameter values).

A :class:`ModelSpec` describes a shading model the way its renderer exposes it: an id
``family:name`` (``mitsuba06:ward``, ``cycles:glossy``), the renderer's own parameter names with
channels, bounds, defaults and roles, the categorical options that select a formula
(``variant``, ``distribution``), and the parameter overrides that render only its diffuse or only
its specular part. Nothing here evaluates a BRDF: renderers do that, and a renderer may be a
black box (see :mod:`matremap.renderers`).

The registry at the bottom is the one place that knows every model.
"""

from __future__ import annotations

import difflib
import json
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from matremap.errors import MatremapError

ROLES = ("diffuse", "specular", "roughness", "fresnel", "other")
#: roles fitted in the specular stage of a two-stage fit
SPECULAR_ROLES = ("specular", "roughness", "fresnel")


@dataclass(frozen=True)
class ParamSpec:
    """One continuous parameter of a model, named as its renderer names it.

    ``bounds`` are the values the renderer accepts (validation and fit bounds alike).
    ``fit`` says whether a target fit adjusts it by default; a parameter that is not fitted holds
    ``fit_value`` (or ``default`` when that is None) unless the user fixes it.
    ``log`` asks the fitter to work on log(value) (for exponents spanning decades).
    ``linear`` marks a parameter the image scales with (see :attr:`scales_image`).
    """

    name: str
    role: str
    default: float | tuple[float, float, float]
    bounds: tuple[float, float]
    channels: int = 1
    fit: bool = True
    fit_value: float | None = None
    log: bool = False
    linear: bool | None = None
    doc: str = ""

    @property
    def scales_image(self) -> bool:
        """Whether the image scales (roughly) in proportion to this parameter: albedos, colours,
        F0. Defaults to the diffuse and specular roles; a fitter's start heuristic uses it."""
        return self.linear if self.linear is not None else self.role in ("diffuse", "specular")

    def __post_init__(self) -> None:
        if self.role not in ROLES:
            raise ValueError(f"{self.name}: unknown role {self.role!r}")
        if self.channels not in (1, 3):
            raise ValueError(f"{self.name}: channels must be 1 or 3")

    @property
    def default_array(self) -> np.ndarray:
        return np.broadcast_to(np.asarray(self.default, dtype=float), (self.channels,)).copy()

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "role": self.role,
            "channels": "rgb" if self.channels == 3 else "scalar",
            "default": list(self.default) if isinstance(self.default, tuple) else self.default,
            "bounds": list(self.bounds),
            "fit": self.fit,
            **({"fit_value": self.fit_value} if self.fit_value is not None else {}),
            "doc": self.doc,
        }


@dataclass(frozen=True)
class OptionSpec:
    """A categorical option that picks a formula (``variant``, ``distribution``)."""

    name: str
    choices: tuple[str, ...]
    default: str
    doc: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "choices": list(self.choices), "default": self.default, "doc": self.doc}


@dataclass(frozen=True)
class ModelSpec:
    """A reflectance model as its renderer exposes it.

    ``diffuse_only`` / ``specular_only`` are parameter overrides that make the renderer draw only
    that part (e.g. ``{"specularReflectance": 0}``); ``None`` means the model has no such part.
    ``white_diffuse`` is a parameter set that makes it a white Lambertian surface of albedo 1,
    used to match irradiance between renderers (None if the model cannot be diffuse).
    """

    id: str
    params: tuple[ParamSpec, ...]
    options: tuple[OptionSpec, ...] = ()
    diffuse_only: Mapping[str, float] | None = None
    specular_only: Mapping[str, float] | None = None
    summary: str = ""
    doc: str = ""
    channel_separable: bool = True
    reflectance: tuple[str, ...] = ()
    specialisations: tuple[tuple[str, float, Mapping[str, Any]], ...] = ()

    def specialise(self, values: Mapping[str, Any]) -> ModelSpec:
        """The spec as a fit sees it when parameters are held at given values.

        ``specialisations`` lists ``(param, value, changes)``: when ``values[param]`` equals
        ``value``, ``changes`` apply (``roles``: parameter -> new role; ``diffuse_only`` /
        ``specular_only``: new overrides). A glTF material held at metallic 1 has no diffuse part
        and its base colour is the specular colour."""
        spec = self
        for name, value, changes in self.specialisations:
            if name not in values or not np.all(np.asarray(values[name], dtype=float) == value):
                continue
            roles = changes.get("roles", {})
            params = tuple(replace(p, role=roles[p.name]) if p.name in roles else p for p in spec.params)
            extra = {k: changes[k] for k in ("diffuse_only", "specular_only") if k in changes}
            spec = replace(spec, params=params, **extra)
        return spec

    @property
    def family(self) -> str:
        return self.id.split(":", 1)[0]

    def param(self, name: str) -> ParamSpec:
        for p in self.params:
            if p.name == name:
                return p
        raise MatremapError(
            f"model {self.id} has no parameter {name!r}; its parameters are "
            f"{', '.join(self.param_names)}"
            + (f" and options {', '.join(o.name for o in self.options)}" if self.options else "")
        )

    def option(self, name: str) -> OptionSpec:
        for o in self.options:
            if o.name == name:
                return o
        raise KeyError(name)

    def part_overrides(self, part: str, values: Mapping[str, Any] | None = None) -> Mapping[str, float] | None:
        """The overrides that draw one part ("full", "specular", "diffuse") of a material with these
        ``values`` (constants or per-texel maps; see :meth:`specialise`); None when it has no such part."""
        spec = self.specialise(values or {})
        return {"full": {}, "specular": spec.specular_only, "diffuse": spec.diffuse_only}[part]

    @property
    def param_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.params)

    @property
    def option_names(self) -> tuple[str, ...]:
        return tuple(o.name for o in self.options)

    def params_with_roles(self, roles: Iterable[str]) -> tuple[ParamSpec, ...]:
        roles = tuple(roles)
        return tuple(p for p in self.params if p.role in roles)

    def to_dict(self) -> dict[str, Any]:
        return {
            "id": self.id,
            "summary": self.summary,
            "params": [p.to_dict() for p in self.params],
            "options": [o.to_dict() for o in self.options],
            "diffuse_only": dict(self.diffuse_only) if self.diffuse_only is not None else None,
            "specular_only": dict(self.specular_only) if self.specular_only is not None else None,
        }


# --------------------------------------------------------------------------------------------
# Materials


@dataclass(frozen=True)
class Material:
    """A model id with a full set of validated parameter values and options.

    ``values[name]`` is a float array of shape (channels,); ``options[name]`` a string.
    Build one with :meth:`create` (validates and fills defaults) or :meth:`from_dict`.
    """

    model: str
    values: Mapping[str, np.ndarray]
    options: Mapping[str, str] = field(default_factory=dict)

    @property
    def spec(self) -> ModelSpec:
        return get_model(self.model)

    @classmethod
    def create(cls, model: str, params: Mapping[str, Any] | None = None) -> Material:
        spec = get_model(model)
        values = {p.name: p.default_array for p in spec.params}
        options = {o.name: o.default for o in spec.options}
        return cls(spec.id, values, options).with_params(params or {})

    def with_params(self, params: Mapping[str, Any]) -> Material:
        """A copy with some parameters or options changed (validated)."""
        spec = self.spec
        values = dict(self.values)
        options = dict(self.options)
        for name, raw in params.items():
            if name in spec.option_names:
                options[name] = _validate_option(spec, spec.option(name), raw)
            else:
                values[name] = _validate_value(spec, spec.param(name), raw)
        return Material(spec.id, values, options)

    def get(self, name: str) -> np.ndarray | str:
        return self.options[name] if name in self.options else self.values[name]

    def to_dict(self) -> dict[str, Any]:
        spec = self.spec
        params: dict[str, Any] = dict(self.options)
        for p in spec.params:
            v = self.values[p.name]
            params[p.name] = float(v[0]) if p.channels == 1 else [float(x) for x in v]
        return {"model": self.model, "params": params}

    @classmethod
    def from_dict(cls, obj: Any, where: str = "material") -> Material:
        if not isinstance(obj, Mapping):
            raise MatremapError(
                f'{where}: expected a JSON object like {{"model": "mitsuba06:ward", "params": {{...}}}}'
            )
        unknown = set(obj) - {"model", "params"}
        if unknown:
            raise MatremapError(f"{where}: unknown key(s) {', '.join(sorted(unknown))}; expected 'model' and 'params'")
        if "model" not in obj or not isinstance(obj["model"], str):
            raise MatremapError(
                f'{where}: missing "model" (a model id such as "mitsuba06:ward"; see `matremap models`)'
            )
        params = obj.get("params", {})
        if not isinstance(params, Mapping):
            raise MatremapError(f'{where}: "params" must be an object of parameter names to values')
        return cls.create(obj["model"], params)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Material):
            return NotImplemented
        return (
            self.model == other.model
            and dict(self.options) == dict(other.options)
            and self.values.keys() == other.values.keys()
            and all(np.array_equal(self.values[k], other.values[k]) for k in self.values)
        )

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        return f"Material({json.dumps(self.to_dict()['params'])[:200]}, model={self.model!r})"


def _validate_option(spec: ModelSpec, opt: OptionSpec, raw: Any) -> str:
    if isinstance(raw, bool):
        raw = "true" if raw else "false"
    if not isinstance(raw, str) or raw not in opt.choices:
        raise MatremapError(f"{spec.id}: option {opt.name}={raw!r} is not one of {', '.join(opt.choices)}")
    return raw


def _validate_value(spec: ModelSpec, p: ParamSpec, raw: Any) -> np.ndarray:
    if isinstance(raw, str) and raw.strip():
        parts = raw.replace(":", " ").replace(",", " ").split()
        try:
            raw = [float(x) for x in parts] if len(parts) > 1 else float(parts[0])
        except ValueError:
            raise MatremapError(f"{spec.id}: {p.name}={raw!r} is not a number") from None
    if isinstance(raw, bool):
        raise MatremapError(f"{spec.id}: {p.name} must be a number, not {raw!r}")
    try:
        arr = np.asarray(raw, dtype=float)
    except (TypeError, ValueError):
        raise MatremapError(f"{spec.id}: {p.name}={raw!r} is not a number") from None
    if arr.ndim > 1:
        raise MatremapError(f"{spec.id}: {p.name} must be a number or a list of 3, got {raw!r}")
    kind = "an RGB triple or one grey value" if p.channels == 3 else "a single number"
    if arr.ndim == 1 and arr.size != p.channels and not (p.channels == 3 and arr.size == 1):
        raise MatremapError(f"{spec.id}: {p.name} takes {kind}, got {arr.size} values")
    arr = np.broadcast_to(arr.reshape(-1), (p.channels,)).astype(float)
    if not np.all(np.isfinite(arr)):
        raise MatremapError(f"{spec.id}: {p.name} is not finite ({raw!r}); give {kind}")
    lo, hi = p.bounds
    if np.any(arr < lo) or np.any(arr > hi):
        raise MatremapError(f"{spec.id}: {p.name}={_fmt(arr)} is outside its range [{lo:g}, {hi:g}]")
    return arr


def _fmt(arr: np.ndarray) -> str:
    return f"{arr[0]:g}" if arr.size == 1 or np.all(arr == arr[0]) else "[" + ", ".join(f"{x:g}" for x in arr) + "]"


def parse_material(text: str) -> Material:
    """Parse a material given inline: JSON (``{"model": ..., "params": {...}}``) or the compact form
    ``MODEL,name=value,name=value`` with RGB values written ``r:g:b``."""
    text = text.strip()
    if text.startswith("{"):
        try:
            obj = json.loads(text)
        except json.JSONDecodeError as e:
            raise MatremapError(f"inline material is not valid JSON: {e.msg} at character {e.pos}") from None
        return Material.from_dict(obj, "inline material")
    model, *assignments = [s.strip() for s in text.split(",")]
    params: dict[str, Any] = {}
    for a in assignments:
        if "=" not in a:
            raise MatremapError(f"in material {text!r}: {a!r} is not NAME=VALUE")
        k, v = a.split("=", 1)
        params[k.strip()] = v.strip()
    return Material.create(model, params)


# --------------------------------------------------------------------------------------------
# Registry

_REGISTRY: dict[str, ModelSpec] = {}
_WHITE: dict[str, tuple[str, dict[str, Any]]] = {}
_LOADED = False


def register(spec: ModelSpec) -> ModelSpec:
    """Add a model to the registry (renderer backends call this for the models they bring)."""
    if spec.id in _REGISTRY and _REGISTRY[spec.id] != spec:
        raise ValueError(f"model {spec.id} registered twice with different specs")
    for part in (spec.diffuse_only, spec.specular_only):
        for name in part or {}:
            if name not in spec.param_names:
                raise ValueError(f"{spec.id}: override names unknown parameter {name}")
    _REGISTRY[spec.id] = spec
    return spec


def register_white_reference(family: str, model: str, params: Mapping[str, Any]) -> None:
    """Name the material that is a white Lambertian surface (albedo 1) in a renderer family;
    irradiance matching compares renders of these between renderers."""
    _WHITE[family] = (model, dict(params))


def white_reference(family: str) -> Material:
    """The white Lambertian reference material of a renderer family."""
    _load_builtin()
    if family not in _WHITE:
        raise MatremapError(f"renderer family {family!r} names no white diffuse reference material")
    model, params = _WHITE[family]
    return Material.create(model, params)


def _load_builtin() -> None:
    global _LOADED
    if not _LOADED:
        _LOADED = True
        from matremap.renderers import cycles, mitsuba3  # noqa: F401  (register their models; nothing heavy is imported)
        from matremap.renderers.embedded import dialects  # noqa: F401  (registers the embedded dialects)


def get_model(model_id: str) -> ModelSpec:
    """The spec of a model id; an unknown id raises with the nearest known ids."""
    _load_builtin()
    if not isinstance(model_id, str):
        raise MatremapError(f"a model id must be a string like 'mitsuba06:ward', got {model_id!r}")
    try:
        return _REGISTRY[model_id]
    except KeyError:
        near = difflib.get_close_matches(model_id, list(_REGISTRY), n=3, cutoff=0.5)
        hint = f"; did you mean {' or '.join(near)}?" if near else "; `matremap models` lists them"
        raise MatremapError(f"unknown model {model_id!r}{hint}") from None


def list_models() -> list[ModelSpec]:
    _load_builtin()
    return [_REGISTRY[k] for k in sorted(_REGISTRY)]


__all__ = [
    "ROLES",
    "SPECULAR_ROLES",
    "Material",
    "ModelSpec",
    "OptionSpec",
    "ParamSpec",
    "get_model",
    "list_models",
    "parse_material",
    "register",
    "register_white_reference",
    "white_reference",
]
