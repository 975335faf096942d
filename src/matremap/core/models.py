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

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from matremap.core.reflectance import Reflectance
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
    ``tied`` names the parameters a fit sets to this one's value (an anisotropic roughness held isotropic:
    :attr:`ModelSpec.isotropic`); a fit fills it, a model's own spec leaves it empty.
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
    tied: tuple[str, ...] = ()

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
    #: how the parameters give F0 (:mod:`matremap.core.reflectance`); None: no specular reflectance
    reflectance: Reflectance | None = None
    #: how the renderer shades normals bent by a normal map: "plain" (the bent normal, nothing else) or
    #: "cycles" (Cycles' bump shadowing term on diffuse closures, raised normals on glossy ones)
    normal_mapping: str = "plain"
    specialisations: tuple[tuple[str, float, Mapping[str, Any]], ...] = ()
    #: parameters the probe image is jointly affine in, channel by channel (image = C + sum of value x B,
    #: with C and B independent of them), each with the options it holds under (option -> the values
    #: for which it does); a fit solves them in closed form (variable projection). Checked by rendering
    #: in tests/test_separable.py.
    affine: tuple[tuple[str, Mapping[str, tuple[str, ...]]], ...] = ()
    #: the image is affine in them only where their per-channel sum is at most this (None: everywhere);
    #: beyond it the renderer rescales them (Mitsuba 0.6's ensureEnergyConservation), so a fit loses
    #: nothing by staying inside
    affine_sum_limit: float | None = None
    #: the microfacet distribution of a model that draws one without an option choosing it (``ggx``: glTF 2.0
    #: Appendix B, UsdPreviewSurface, OpenPBR 1.1, Standard Surface 1.0.1, Mitsuba 3's principled); a model with a
    #: ``distribution`` option says it there (:func:`microfacet_of`)
    microfacet: str | None = None
    #: ``(follower, leader)`` pairs of parameters that are equal where the model is isotropic (Mitsuba 3's
    #: anisotropic conductor: alpha_v and alpha_u). A fit onto the model ties each follower to its leader unless
    #: the user fixes or frees it or the source is anisotropic itself (:meth:`anisotropic`): an isotropic source
    #: stays isotropic (:func:`matremap.core.fit.target_template`)
    isotropic: tuple[tuple[str, str], ...] = ()

    def anisotropic(self, values: Mapping[str, Any]) -> bool:
        """Whether a material of this model with ``values`` is anisotropic: a pair of :attr:`isotropic` differs."""
        return any(
            not np.array_equal(np.asarray(values[f], dtype=float), np.asarray(values[lead], dtype=float))
            for f, lead in self.isotropic
            if f in values and lead in values
        )

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

    def affine_params(self, options: Mapping[str, str]) -> tuple[str, ...]:
        """The parameters the image is affine in under these options (see ``affine``)."""
        return tuple(
            name
            for name, needs in self.affine
            if all(str(options.get(o, self.option(o).default)) in values for o, values in needs.items())
        )

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


__all__ = ["ROLES", "SPECULAR_ROLES", "ModelSpec", "OptionSpec", "ParamSpec"]


def microfacet_of(spec: ModelSpec, options: Mapping[str, Any]) -> str | None:
    """The microfacet distribution a material of ``spec`` with ``options`` draws: its ``distribution`` option's
    value (or that option's default), else the model's own (:attr:`ModelSpec.microfacet`), else None."""
    if "distribution" in spec.option_names:
        return str(options.get("distribution", spec.option("distribution").default))
    return spec.microfacet
