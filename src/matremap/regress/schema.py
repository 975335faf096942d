"""What a transform file may hold, checked before a transform is built from it.

A transform is applied to every texel of a user's maps, so its numbers are checked where it is read,
not where it is applied: every coefficient finite and no larger than :data:`MAX_MAGNITUDE`, each
mapping kind with its coefficient count, the inputs it reads spoken by the source model and the
quantity it writes by the target, options and template values the models accept, and sizes bounded.
Every problem is one :class:`~matremap.errors.MatremapError` naming the file and the field.

The checksum (:func:`checksum`) is the sha256 of the canonical JSON of the content without its
``checksum`` field; :meth:`.transform.Transform.save` stores it and loading verifies it.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Mapping
from typing import Any

from matremap.core.material import Material
from matremap.core.models import ModelSpec
from matremap.errors import MatremapError
from matremap.regress import quantities as qty

#: the keys a transform file may have at its top level
KEYS = frozenset(
    {
        "schema",
        "method",
        "source",
        "target",
        "domain",
        "errors",
        "provenance",
        "mappings",
        "template",
        "source_template",
        "steps",
        "checksum",
    }
)
#: largest absolute value of a coefficient or constant (learned ones stay below 1e3)
MAX_MAGNITUDE = 1e6
#: most steps of a chain
MAX_STEPS = 8
#: most support vectors of an SVR mapping (learning keeps at most 800 points)
MAX_SUPPORT = 20_000
#: the mapping kinds and the quantities each may write
KINDS = {
    "polynomial": tuple(q for q in qty.QUANTITIES if qty.is_scalar(q)),
    "k_alpha": ("reflectance",),
    "scale": tuple(q for q in qty.QUANTITIES if not qty.is_scalar(q)),
    "constant": qty.QUANTITIES,
    "svr": ("roughness", "reflectance", "diffuse"),
}
#: most coefficients of a polynomial (degree 4, as :mod:`.parametric` fits)
MAX_POLY_COEFS = 5


def checksum(doc: Mapping[str, Any]) -> str:
    """``sha256:<hex>`` of the canonical JSON (sorted keys, no spaces) of ``doc`` without its checksum."""
    content = {k: v for k, v in doc.items() if k != "checksum"}
    try:
        text = json.dumps(content, sort_keys=True, separators=(",", ":"), ensure_ascii=True, allow_nan=False)
    except (TypeError, ValueError) as e:
        raise MatremapError(f"transform content is not plain finite JSON ({e})") from None
    return "sha256:" + hashlib.sha256(text.encode()).hexdigest()


def number(v: Any, where: str, lo: float = -MAX_MAGNITUDE, hi: float = MAX_MAGNITUDE) -> float:
    """``v`` as a float: a JSON number (not a boolean), finite, within [lo, hi]."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise MatremapError(f"{where} must be a number, got {_show(v)}")
    f = float(v)
    if not math.isfinite(f) or not lo <= f <= hi:
        raise MatremapError(f"{where} = {f!r} is not a finite number in [{lo:g}, {hi:g}]")
    return f


def numbers(v: Any, where: str, sizes: tuple[int, ...], lo: float = -MAX_MAGNITUDE) -> list[float]:
    """``v`` as a list of floats whose length is one of ``sizes``, each checked by :func:`number`."""
    if not isinstance(v, list) or len(v) not in sizes:
        want = " or ".join(str(s) for s in sizes)
        raise MatremapError(f"{where} must be a list of {want} numbers, got {_show(v)}")
    return [number(x, f"{where}[{i}]", lo) for i, x in enumerate(v)]


def _show(v: Any) -> str:
    """A short description of a JSON value for an error message."""
    if isinstance(v, list):
        return f"a list of {len(v)}"
    if isinstance(v, dict):
        return "an object"
    text = repr(v)
    return text if len(text) <= 40 else text[:37] + "..."


def obj(v: Any, where: str) -> Mapping[str, Any]:
    """``v`` if it is a JSON object, else one error naming ``where``."""
    if not isinstance(v, Mapping):
        raise MatremapError(f"{where} must be a JSON object, got {_show(v)}")
    return v


def side(d: Mapping[str, Any], key: str, where: str) -> tuple[ModelSpec, dict[str, str]]:
    """The model and options of ``source`` or ``target``: a known model, options it has, valid values."""
    from matremap.dialects import get_model

    s = obj(d.get(key), f"{where}: '{key}'")
    unknown = set(s) - {"model", "options"}
    if unknown:
        raise MatremapError(f"{where}: '{key}' has unknown keys {', '.join(sorted(unknown))}; use model, options")
    model = s.get("model")
    if not isinstance(model, str):
        raise MatremapError(f"{where}: '{key}.model' must be a model id such as \"mitsuba06:ward\"")
    spec = get_model(model)
    options = dict(obj(s.get("options", {}), f"{where}: '{key}.options'"))
    extra = set(options) - set(spec.option_names)
    if extra:
        names = ", ".join(spec.option_names) or "none"
        unknown_names = ", ".join(sorted(extra))
        raise MatremapError(f"{where}: {key} option(s) {unknown_names} unknown to {spec.id} (it has {names})")
    values(spec, options, f"{where}: {key} options")
    return spec, options


def values(spec: ModelSpec, params: Mapping[str, Any], where: str) -> None:
    """Parameter values and options as a material of ``spec`` accepts them (names, types, ranges)."""
    try:
        Material.create(spec.id, params)
    except MatremapError as e:
        raise MatremapError(f"{where}: {e}") from None


def domain(d: Any, where: str) -> dict[str, list[float]]:
    """``{quantity: [lo, hi]}`` with finite lo <= hi."""
    out = {}
    for name, span in obj(d, f"{where}: 'domain'").items():
        if name not in qty.QUANTITIES:
            raise MatremapError(f"{where}: domain of unknown quantity {name!r}; use {', '.join(qty.QUANTITIES)}")
        lo, hi = numbers(span, f"{where}: domain.{name}", (2,))
        if lo > hi:
            raise MatremapError(f"{where}: domain.{name} = [{lo:g}, {hi:g}] is empty (low above high)")
        out[name] = [lo, hi]
    return out


def errors(d: Any, where: str) -> dict[str, dict[str, float | None]]:
    """``{quantity or step: {measure: number or null}}``."""
    out: dict[str, dict[str, float | None]] = {}
    for name, measures in obj(d, f"{where}: 'errors'").items():
        row: dict[str, float | None] = {}
        for k, v in obj(measures, f"{where}: errors.{name}").items():
            row[k] = None if v is None else number(v, f"{where}: errors.{name}.{k}", lo=0.0)
        out[name] = row
    return out


def mapping(name: str, m: Any, source: ModelSpec, target: ModelSpec, where: str) -> None:
    """One mapping: a known kind allowed for quantity ``name``, which the target speaks, reading only
    quantities the source speaks, with coefficients of the right count, finite and bounded."""
    at = f"{where}: mapping {name}"
    m = obj(m, at)
    if name not in qty.QUANTITIES:
        raise MatremapError(f"{where}: unknown quantity {name!r}; use {', '.join(qty.QUANTITIES)}")
    if name not in qty.available(target):
        raise MatremapError(f"{at}: target model {target.id} has no {name}")
    kind = m.get("kind")
    if not isinstance(kind, str) or kind not in KINDS:
        raise MatremapError(f"{at}: kind {_show(kind)} is not one of {', '.join(KINDS)}")
    if name not in KINDS[kind]:
        raise MatremapError(f"{at}: a {kind} mapping cannot give {name}")
    if kind == "svr":
        inputs = svr_mapping(name, m, at)
    elif kind == "constant":
        v = m.get("value")
        if qty.is_scalar(name):
            number(v, f"{at}.value")
        else:
            numbers(v, f"{at}.value", (3,))
        inputs = []
    else:
        inputs = parametric_mapping(kind, name, m, at)
    missing = [q for q in inputs if q not in qty.available(source)]
    if missing:
        raise MatremapError(f"{at} reads {', '.join(missing)}, which source model {source.id} does not have")


def parametric_mapping(kind: str, name: str, m: Mapping[str, Any], at: str) -> list[str]:
    """Check a polynomial, k_alpha or scale mapping; returns the quantities it reads."""
    if kind == "polynomial":  # of its own counterpart: a roughness of the roughness, a layer's weight of its weight
        source = m.get("input", "roughness")
        if source != name:
            raise MatremapError(f"{at}: a polynomial for {name} reads {name}, not {_show(source)}")
        numbers(m.get("coef"), f"{at}.coef", tuple(range(1, MAX_POLY_COEFS + 1)))
        return [source]
    if kind == "k_alpha":
        uses_roughness = m.get("roughness", True)
        if not isinstance(uses_roughness, bool):
            raise MatremapError(f"{at}.roughness must be true or false")
        if "tint" in m:
            numbers(m["tint"], f"{at}.tint", (3,))
        if not uses_roughness:
            numbers(m.get("coef"), f"{at}.coef", (1,))
            return ["reflectance"]
        c = numbers(m.get("coef"), f"{at}.coef", (5, 6))
        if c[2] < 0 or c[4] < 0:  # exp(-c2 alpha), exp(-c4 alpha^2): a negative rate grows without bound
            raise MatremapError(f"{at}.coef: the exponential rates c2 and c4 must not be negative")
        return ["reflectance", "roughness"]
    source = m.get("input")
    allowed = ("reflectance", "diffuse") if qty.layer_of(name) is None else (name,)
    if source not in allowed:
        raise MatremapError(f"{at}: a scale for {name} reads {' or '.join(allowed)}, not {_show(source)}")
    numbers(m.get("coef"), f"{at}.coef", (1, 3))
    return [str(source)]


def svr_mapping(name: str, m: Mapping[str, Any], at: str) -> list[str]:
    """Check an SVR mapping's arrays (counts agree, finite, scales positive); returns its inputs."""
    inputs = m.get("inputs")
    if (
        not isinstance(inputs, list)
        or not inputs
        or not all(isinstance(q, str) and q in KINDS["svr"] for q in inputs)
        or len(set(inputs)) != len(inputs)
    ):
        raise MatremapError(f"{at}.inputs must be a list of distinct quantities ({', '.join(KINDS['svr'])})")
    per_channel = m.get("per_channel")
    if per_channel is not (name != "roughness"):
        raise MatremapError(f"{at}.per_channel must be {str(name != 'roughness').lower()} for {name}")
    if per_channel and not any(q in ("reflectance", "diffuse") for q in inputs):
        raise MatremapError(f"{at}: a per-channel SVR needs reflectance or diffuse among its inputs")
    d = len(inputs)
    numbers(m.get("x_mean"), f"{at}.x_mean", (d,))
    if min(numbers(m.get("x_scale"), f"{at}.x_scale", (d,))) <= 0:
        raise MatremapError(f"{at}.x_scale must be positive")
    number(m.get("y_mean"), f"{at}.y_mean")
    number(m.get("y_scale"), f"{at}.y_scale")
    number(m.get("intercept"), f"{at}.intercept")
    number(m.get("gamma"), f"{at}.gamma", lo=0.0)
    sv, coef = m.get("support_vectors"), m.get("dual_coef")
    if not isinstance(sv, list) or not isinstance(coef, list) or len(sv) != len(coef) or len(sv) > MAX_SUPPORT:
        raise MatremapError(
            f"{at}: support_vectors and dual_coef must be lists of the same length (at most {MAX_SUPPORT})"
        )
    for i, (row, c) in enumerate(zip(sv, coef, strict=True)):
        numbers(row, f"{at}.support_vectors[{i}]", (d,))
        number(c, f"{at}.dual_coef[{i}]")
    return list(inputs)


def steps_list(d: Mapping[str, Any], where: str) -> list[Any]:
    """A chain's steps: a list of 2..MAX_STEPS transform objects, none of them a chain itself."""
    steps = d.get("steps")
    if not isinstance(steps, list) or not 2 <= len(steps) <= MAX_STEPS:
        raise MatremapError(f"{where}: a chain needs a list of 2 to {MAX_STEPS} steps")
    for i, s in enumerate(steps):
        if isinstance(s, Mapping) and s.get("method") == "chain":
            raise MatremapError(f"{where} step {i + 1}: a chain's steps are single transforms, not chains")
        if isinstance(s, Mapping) and "checksum" in s:
            raise MatremapError(f"{where} step {i + 1}: only the whole file carries a checksum")
    return steps
