"""Mitsuba 3's ``blendbsdf`` of two BSDFs of one model, read as one material blended texel by texel.

Source: Mitsuba 3.9 ``src/bsdfs/blendbsdf.cpp``: ``f = (1 - weight) f_0 + weight f_1`` with ``weight`` a
scalar texture (``eval_1``: a colour weight counts by the mean of its channels). When both children are the same
``mitsuba3:*`` model with the same options, each parameter ``p`` of the result is
``(1 - weight) p_0 + weight p_1``: exactly Mitsuba's blend for the parameters the BSDF is linear in
(diffuse and specular reflectances), an approximation for the others (alpha, eta, k, IORs), which Mitsuba
mixes as two lobes -- a note names those that differ between the children. Anything else (two models,
two option sets, a normal map or mask on a child) is refused in one line.
"""

from __future__ import annotations

from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from matremap.dialects import get_model
from matremap.errors import MatremapError
from matremap.formats.mitsuba_plugins import CONSTANT_ONLY, Parts, plugin_of
from matremap.formats.mitsuba_textures import TextureSource, constant_source


def _value(parts: Parts, name: str) -> tuple[Any, TextureSource | None]:
    """(constant, texture) of parameter ``name`` in ``parts`` (the model's default when not given)."""
    if name in parts.textures:
        return None, parts.textures[name]
    spec = get_model(parts.model)
    return np.asarray(parts.constants.get(name, spec.param(name).default), dtype=float), None


def _blend_sample(a: TextureSource, b: TextureSource, weight: TextureSource, size: tuple[int, int]) -> np.ndarray:
    w = weight.values(size)[..., :1]
    return (1.0 - w) * a.values(size) + w * b.values(size)


def blend_parts(
    first: Parts, second: Parts, weight: tuple[float, TextureSource | None], label: str, path: Path
) -> Parts:
    """The material of ``blendbsdf(first, second, weight)`` (module doc); ``weight`` is a constant or a
    scalar texture; ``path`` the scene file (constants turned into textures are attributed to it)."""
    if first.model != second.model:
        raise MatremapError(
            f"material {label!r} is a blendbsdf of a {first.model} and a {second.model}: matremap blends only two "
            "BSDFs of one model (their parameters texel by texel); convert the two separately"
        )
    spec = get_model(first.model)
    options = {
        o.name: (str(first.constants.get(o.name, o.default)), str(second.constants.get(o.name, o.default)))
        for o in spec.options
    }
    differ = {k: v for k, v in options.items() if v[0] != v[1]}
    if differ:
        detail = ", ".join(f"{k} {a!r} vs {b!r}" for k, (a, b) in differ.items())
        raise MatremapError(f"material {label!r} is a blendbsdf of two {first.model} with different options ({detail})")
    for child in (first, second):
        if child.normal is not None or child.opacity is not None:
            raise MatremapError(
                f"material {label!r} is a blendbsdf whose child carries a normal map or a mask; matremap blends "
                "plain BSDFs only"
            )
    out = Parts(label, first.model, notes=[*first.notes, *second.notes])
    out.constants.update({k: v[0] for k, v in options.items() if k in first.constants or k in second.constants})
    w_const, w_tex = weight
    names = {*first.constants, *first.textures, *second.constants, *second.textures} - set(options)
    nonlinear = []
    for name in sorted(names):
        (ca, ta), (cb, tb) = _value(first, name), _value(second, name)
        if ta is None and tb is None and (w_tex is None or np.array_equal(ca, cb)):
            mixed = (1.0 - w_const) * ca + w_const * cb if w_tex is None else ca
            out.constants[name] = float(mixed) if mixed.size == 1 else [float(x) for x in mixed]
        else:
            if name in CONSTANT_ONLY.get(plugin_of(first.model), ()):
                raise MatremapError(
                    f"material {label!r} is a blendbsdf whose two BSDFs differ in {name}, which Mitsuba takes as a "
                    "number: a texture-weighted blend of it cannot be written"
                )
            src_a = ta or constant_source(path, ca)
            src_b = tb or constant_source(path, cb)
            w = w_tex or constant_source(path, np.array([w_const]))
            mix = partial(_blend_sample, src_a, src_b, w)
            out.textures[name] = TextureSource(src_a.path, _size(src_a, src_b, w), mix)
        if not spec.param(name).scales_image and not (ta is None and tb is None and np.allclose(ca, cb)):
            nonlinear.append(name)
    out.notes.append(f"blendbsdf: the parameters of its two {first.model} blended by its weight, texel by texel")
    if nonlinear:
        out.notes.append(
            f"blendbsdf: {', '.join(nonlinear)} differ between the two BSDFs; blending them is an approximation "
            "(Mitsuba mixes two lobes)"
        )
    return out


def _size(*sources: TextureSource) -> tuple[int, int] | None:
    sizes = [s.size for s in sources if s.size is not None]
    return max(sizes, key=lambda hw: hw[0] * hw[1]) if sizes else None


__all__ = ["blend_parts"]
