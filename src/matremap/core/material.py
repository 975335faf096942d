"""Materials: a model id with a full set of validated parameter values and options.

Build one with :meth:`Material.create` (validates and fills the renderer's defaults),
:meth:`Material.from_dict` or :func:`parse_material` (inline JSON or ``MODEL,name=value,...``).
:class:`SVMaterial` is the spatially varying kind: parameter maps instead of values.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from matremap.core.models import ModelSpec, OptionSpec, ParamSpec
from matremap.dialects import get_model, white_reference_params
from matremap.errors import MatremapError


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
        from matremap.core.documents import parse_json

        return Material.from_dict(parse_json(text, "inline material"), "inline material")
    model, *assignments = [s.strip() for s in text.split(",")]
    params: dict[str, Any] = {}
    for a in assignments:
        if "=" not in a:
            raise MatremapError(f"in material {text!r}: {a!r} is not NAME=VALUE")
        k, v = a.split("=", 1)
        params[k.strip()] = v.strip()
    return Material.create(model, params)


@dataclass(frozen=True)
class SVMaterial:
    """A spatially varying material: a model, its parameter maps (or constants), its options and
    an optional tangent-space normal map in [-1, 1]."""

    model: str
    params: Mapping[str, Any]
    options: Mapping[str, str] = field(default_factory=dict)
    normal: np.ndarray | None = None

    @classmethod
    def of(cls, m: Any) -> SVMaterial:
        """From an SVMaterial, a (model, params, options, normal) tuple (options and normal may be
        left out) or a mapping with those keys."""
        if isinstance(m, SVMaterial):
            return m
        if isinstance(m, Mapping):
            return cls(m["model"], m.get("params", {}), m.get("options") or {}, m.get("normal"))
        if isinstance(m, (tuple, list)) and 2 <= len(m) <= 4:
            model, params, *rest = m
            options = rest[0] if rest else {}
            normal = rest[1] if len(rest) > 1 else None
            return cls(model, params, options or {}, normal)
        raise MatremapError("a material to evaluate is (model, params, options, normal_map)")


def white_reference(family: str) -> Material:
    """The white Lambertian reference material (albedo 1) of a renderer family."""
    model, params = white_reference_params(family)
    return Material.create(model, params)


__all__ = ["Material", "SVMaterial", "parse_material", "white_reference"]
