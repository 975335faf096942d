"""Model specs as data, one module per renderer family, and the registry of every model.

Each module (:mod:`.mitsuba06`, :mod:`.mitsuba3`, :mod:`.blender27`, :mod:`.cycles`, :mod:`.gltf`,
:mod:`.mtlx`, :mod:`.usd`) declares
its models as :class:`~matremap.core.models.ModelSpec` values in ``MODELS`` -- the renderer's own
parameter names, ranges, roles and options, and how to draw the diffuse-only and specular-only parts --
and names its white Lambertian reference (``WHITE_REFERENCE``: a model and parameters). Its docstring is
the parameter table and the formula's sources. Nothing here evaluates a BRDF or imports a renderer:
renderers say which models they draw (:meth:`~matremap.renderers.base.Renderer.can_render`).

This package is the one place that knows every dialect; adding a model is adding one entry to a
module's ``MODELS`` (and, for the embedded renderer, its evaluator).
"""

from __future__ import annotations

import difflib
from types import ModuleType
from typing import Any

from matremap.core.models import ModelSpec
from matremap.dialects import blender27, cycles, gltf, mitsuba06, mitsuba3, mtlx, usd
from matremap.errors import MatremapError

#: the dialect modules, one per renderer family
FAMILIES: dict[str, ModuleType] = {
    "mitsuba06": mitsuba06,
    "mitsuba3": mitsuba3,
    "blender27": blender27,
    "cycles": cycles,
    "gltf": gltf,
    "usd": usd,
    "mtlx": mtlx,
}


def _collect() -> dict[str, ModelSpec]:
    models: dict[str, ModelSpec] = {}
    for family, module in FAMILIES.items():
        for spec in module.MODELS:
            if spec.family != family:
                raise ValueError(f"{spec.id} is declared in the {family} dialect")
            if spec.id in models:
                raise ValueError(f"model {spec.id} declared twice")
            for part in (spec.diffuse_only, spec.specular_only):
                for name in part or {}:
                    if name not in spec.param_names:
                        raise ValueError(f"{spec.id}: override names unknown parameter {name}")
            models[spec.id] = spec
    return models


#: every model, by id
MODELS: dict[str, ModelSpec] = _collect()


def get_model(model_id: str) -> ModelSpec:
    """The spec of a model id; an unknown id raises with the nearest known ids."""
    if not isinstance(model_id, str):
        raise MatremapError(f"a model id must be a string like 'mitsuba06:ward', got {model_id!r}")
    try:
        return MODELS[model_id]
    except KeyError:
        near = difflib.get_close_matches(model_id, list(MODELS), n=3, cutoff=0.5)
        hint = f"; did you mean {' or '.join(near)}?" if near else "; `matremap models` lists them"
        raise MatremapError(f"unknown model {model_id!r}{hint}") from None


def list_models() -> list[ModelSpec]:
    """Every model, sorted by id."""
    return [MODELS[k] for k in sorted(MODELS)]


def white_reference_params(family: str) -> tuple[str, dict[str, Any]]:
    """The white Lambertian reference (albedo 1) of a renderer family: (model id, parameters)."""
    module = FAMILIES.get(family)
    if module is None or getattr(module, "WHITE_REFERENCE", None) is None:
        raise MatremapError(f"renderer family {family!r} names no white diffuse reference material")
    model, params = module.WHITE_REFERENCE
    return model, dict(params)


__all__ = ["FAMILIES", "MODELS", "get_model", "list_models", "white_reference_params"]
