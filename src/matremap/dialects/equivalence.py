"""Models that are the same BRDF under other names: a remap between them is a renaming, not a fit.

Each :class:`Equivalence` pairs two models whose renderers draw the same image for the same values once
the parameters are renamed and some values are held (for example Mitsuba 0.6's exterior IOR at 1, since
Mitsuba 3's conductor has none). Every pair is a measured fact, not an assumption: ``tests/test_equivalence.py``
renders both sides over a set of values (with the real renderer where it draws the model) and holds the
relative RMSE below 1e-3. Measured on the probe (128², 0° and 45°): Lambertian Mitsuba 0.6 / Mitsuba 3 /
Cycles ≤ 6e-7; rough conductor Mitsuba 0.6 (extEta 1) / Mitsuba 3 ~1e-5.

Not listed, because they are *not* equal: Mitsuba 0.6 and Mitsuba 3 ``roughplastic`` (same parameters, but
Mitsuba 3's diffuse layer differs: relative RMSE 0.02 to 0.59 over α 0.05 to 0.6), Blender Internal's
Lambert (its ``diffuse_intensity`` convention), and models whose normal maps are shaded differently when a
normal map is present (Cycles' bump shadowing term; :attr:`~matremap.core.models.ModelSpec.normal_mapping`).
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from matremap.dialects import get_model


@dataclass(frozen=True)
class Equivalence:
    """Model ``source`` equals model ``target`` with ``names`` (source name -> target name, parameters and
    options alike) when the source holds ``source_requires`` and the target is given ``target_requires``
    (parameter or option values)."""

    source: str
    target: str
    names: Mapping[str, str]
    source_requires: Mapping[str, Any] = field(default_factory=dict)
    target_requires: Mapping[str, Any] = field(default_factory=dict)

    def reversed(self) -> Equivalence:
        return Equivalence(
            self.target,
            self.source,
            {b: a for a, b in self.names.items()},
            self.target_requires,
            self.source_requires,
        )

    def refusal(self, constants: Mapping[str, Any], mapped: Collection[str], normal_map: bool) -> str | None:
        """Why a material with these constant values, these parameters as maps and (or not) a normal map
        is not drawn the same by the target; None when it is."""
        source, target = get_model(self.source), get_model(self.target)
        if normal_map and source.normal_mapping != target.normal_mapping:
            return f"{self.target} shades normal maps differently ({target.normal_mapping})"
        for name, value in self.source_requires.items():
            if name in mapped:
                return f"{name} is a map; {self.target} needs it uniform at {value}"
            held = constants.get(name, _default(source, name))
            if not _equal(held, value):
                return f"{name} is {held}; {self.target} draws the same only at {value}"
        for name in source.option_names:
            value = str(constants.get(name, source.option(name).default))
            if name not in self.names:
                continue
            option = target.option(self.names[name])
            if value not in option.choices:
                return f"{self.target} has no {option.name} {value!r}"
        return None

    def rename(self, values: Mapping[str, Any]) -> dict[str, Any]:
        """Source values (parameters or options) as the target names them, with the target's requirements."""
        out = {self.names[k]: v for k, v in values.items() if k in self.names}
        out.update(self.target_requires)
        return out


def _default(spec: Any, name: str) -> Any:
    return spec.option(name).default if name in spec.option_names else spec.param(name).default


def _equal(a: Any, b: Any) -> bool:
    if isinstance(a, str) or isinstance(b, str):
        return str(a) == str(b)
    return bool(np.all(np.asarray(a, dtype=float) == np.asarray(b, dtype=float)))


#: the measured pairs, each in one direction (:func:`equivalence` finds both)
EQUIVALENCES: tuple[Equivalence, ...] = (
    Equivalence("mitsuba06:diffuse", "mitsuba3:diffuse", {"reflectance": "reflectance"}),
    Equivalence("mitsuba06:diffuse", "cycles:diffuse", {"reflectance": "Color"}),
    Equivalence("mitsuba3:diffuse", "cycles:diffuse", {"reflectance": "Color"}),
    Equivalence(
        "mitsuba06:roughconductor",
        "mitsuba3:roughconductor",
        {
            "alpha": "alpha",
            "eta": "eta",
            "k": "k",
            "specularReflectance": "specular_reflectance",
            "distribution": "distribution",
        },
        source_requires={"extEta": 1.0},
        target_requires={"material": "custom"},
    ),
)


def equivalence(source: str, target: str) -> Equivalence | None:
    """The renaming that takes model ``source`` to model ``target`` when the dialects show them equal
    (a model is equal to itself); None otherwise."""
    source, target = get_model(source).id, get_model(target).id
    if source == target:
        spec = get_model(source)
        return Equivalence(source, target, {n: n for n in (*spec.param_names, *spec.option_names)})
    for e in EQUIVALENCES:
        if (e.source, e.target) == (source, target):
            return e
        if (e.target, e.source) == (source, target):
            return e.reversed()
    return None
