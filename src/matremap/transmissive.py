"""Fitting a material that lets light through (issue 16, "Transmission in the probe").

The point-light probe draws a material's reflection only: a glass and a black mirror look alike there. A fit
of a source that transmits (:func:`~matremap.renderers.embedded.transmission.transmits`) is therefore made on
the probe with the transmission view added (:func:`~matremap.core.scene.transmission_probe`: the sphere before a
tiled background under an environment, where refraction, tint and blur show), with a joint strategy (``simple``:
a transmission is neither a diffuse-only nor a specular-only part, so the staged strategies' goals cannot isolate
it). A target that transmits too starts from the source's transmission read across
(:data:`~matremap.renderers.embedded.transmission.EQUIVALENTS`: weight, IOR, roughness, entry tint, thin wall or
volume and its extinction) with the continuous parameters among them freed; a target that cannot transmit is
fitted to the closest look it has, and the fit says the refraction is lost.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from matremap.core.material import Material
from matremap.core.models import ModelSpec
from matremap.core.scene import Scene, transmission_probe

#: the strategies that fit every parameter at once (matremap.core.fit.JOINT)
JOINT_STRATEGY = "simple"


@dataclass
class TransmissiveFit:
    """What a transmissive source changes in a fit: the scene, strategy, parameters freed and their start, and
    the notes that say so."""

    scene: Scene | None
    strategy: str
    free: list[str]
    start: dict[str, Any]
    notes: list[str] = field(default_factory=list)
    #: the source as fitted: itself, or widened to the target's narrowest lobe (:func:`widened`)
    source: Material | None = None


def setup(
    source: Material,
    spec: ModelSpec,
    scene: Scene | None,
    strategy: str,
    free: Sequence[str],
    start: Mapping[str, Any] | None,
    fix: Mapping[str, Any] | None,
) -> TransmissiveFit:
    """The fit's scene, strategy, freed parameters and start for ``source`` onto ``spec``: unchanged unless the
    source transmits (see the module docstring). The user's ``fix`` and ``start`` win over the read-across."""
    from matremap.core.fit import JOINT
    from matremap.renderers.embedded.transmission import EQUIVALENTS, interface_of, transmits

    same = TransmissiveFit(scene, strategy, list(free), dict(start or {}))
    if not transmits(source):
        return same
    iface = interface_of(source)
    probe = transmission_probe(scene or Scene())
    out = TransmissiveFit(probe, strategy, list(free), dict(start or {}))
    share = float(np.mean(iface.weight))
    out.notes.append(f"the source transmits ({share:.2f} of its base): fitted on the {probe.describe()}")
    if strategy not in JOINT:
        out.strategy = JOINT_STRATEGY
        out.notes.append(
            f"strategy {JOINT_STRATEGY} instead of {strategy}: a transmission is no diffuse or specular part"
        )
    reader = EQUIVALENTS.get(spec.id)
    if reader is None:
        out.notes.append(
            f"{spec.id} does not transmit light: the fit takes the closest look it has, the refraction is lost"
        )
        return out
    values, freed = reader(iface)
    wider = widened_for(source, spec, values)
    if wider is not None:
        out.source = wider
        values, freed = reader(interface_of(wider))
        out.notes.append(
            f"the source's lobe (GGX alpha {iface.alpha:.3g}) is narrower than {spec.id}'s narrowest (alpha "
            f"{interface_of(wider).alpha:.3g}, alike at any resolution the probe has): fitted, and judged, at that "
            "width"
        )
    held = set(fix or {})
    moved = set(freed) | {p.name for p in spec.params if p.fit}
    start = {k: inside(spec, k, v) if k in moved else v for k, v in values.items() if k not in held}
    out.start = {**start, **out.start}
    out.free += [name for name in freed if name not in held and name not in out.free]
    out.notes.append(
        f"transmission read across onto {spec.id} and fitted ({', '.join(n for n in freed if n not in held)} freed)"
    )
    return out


def smoothest(spec: ModelSpec, values: Mapping[str, Any]) -> float | None:
    """The narrowest GGX alpha ``spec`` lets through with: its interface at the lower bound of its roughness (the
    read-across ``values`` otherwise; Mitsuba's principled: 0.001), None without a roughness parameter."""
    from matremap.core.fit import roughness_of
    from matremap.renderers.embedded.transmission import interface_of

    rp = roughness_of(spec)
    if rp is None or rp.log:
        return None
    return interface_of(Material.create(spec.id, {**values, rp.name: rp.bounds[0]})).alpha


def widened_for(source: Material, spec: ModelSpec, values: Mapping[str, Any]) -> Material | None:
    """``source`` widened to the narrowest lobe ``spec`` lets through with (:func:`smoothest` of ``values``), or
    None where it is no narrower or cannot be widened: how a fit draws, and judges, a source smoother than its
    target can be."""
    from matremap.renderers.embedded.transmission import interface_of

    narrowest = smoothest(spec, values)
    if narrowest is None or interface_of(source).alpha >= narrowest:
        return None
    return widened(source, narrowest)


def widened(source: Material, alpha: float) -> Material | None:
    """``source`` with its roughness raised until its interface's alpha reaches ``alpha`` (bisection on the
    parameter, whatever its mapping to alpha); None when it has no roughness parameter or cannot reach it. A lobe
    below the probe's resolution: the point and environment lights draw a near-mirror's highlight as bright points
    a perfect mirror does not have, so a smooth glass onto a model that cannot be as smooth (Mitsuba's principled,
    alpha >= 0.001) failed the gate on highlights no image would show."""
    from matremap.core.fit import roughness_of
    from matremap.renderers.embedded.transmission import interface_of

    rp = roughness_of(source.spec)
    if rp is None or rp.log:
        return None
    lo, hi = float(np.mean(source.values[rp.name])), rp.bounds[1]
    if interface_of(source.with_params({rp.name: hi})).alpha < alpha:
        return None
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if interface_of(source.with_params({rp.name: mid})).alpha < alpha else (lo, mid)
    return source.with_params({rp.name: hi})


#: how far inside its bounds a started value on one is put, as a share of the range
NUDGE = 1e-3


def inside(spec: ModelSpec, name: str, value: Any) -> Any:
    """``value`` of the parameter ``name`` moved :data:`NUDGE` of its range inside where it sits on a bound. The
    fitter moves a start on a bound to mid-range (where a descent would stall), which for a smooth glass's
    roughness 0 or a weight of 1 throws away a read-across that is already close (the AttenuationTest's blue glass
    onto OpenPBR: 0.04 from the read-across, 0.79 from roughness 0.5). Only for parameters the fit moves: a
    structural one (a thin wall's thickness 0) stays as it is."""
    lo, hi = spec.param(name).bounds
    step = NUDGE * (min(hi, 1.0 + lo) - lo)
    a = np.asarray(value, dtype=float)
    moved = np.where(a <= lo, lo + step, np.where(a >= hi, hi - step, a))
    return float(moved) if moved.ndim == 0 else moved.tolist()


def interpolation_error(source: Material, fitted: Any, target: Material) -> float:
    """The relative RMSE between ``source`` and ``target`` on the probe ``fitted`` (a
    :class:`~matremap.core.fit.FitResult` of a neighbouring material) was made on, with its renderers and
    irradiance scale: how far a target nothing was fitted to (the blend of a few fits) is from the source. The
    source is drawn as a fit draws its own (a glass the target cannot be as smooth as, widened to the target's
    narrowest lobe)."""
    from matremap.core.fit import FULL, part
    from matremap.renderers import get_renderer
    from matremap.renderers.base import render_pixels
    from matremap.renderers.embedded.transmission import EQUIVALENTS

    through = target.model in EQUIVALENTS  # a target that lets light through: smoothest() reads it
    drawn = (widened_for(source, target.spec, target.values) if through else None) or source
    scene = fitted.scene
    src = render_pixels(get_renderer(fitted.source_renderer), [part(drawn, FULL) or drawn], scene)[0]
    tgt = render_pixels(get_renderer(fitted.target_renderer), [target], scene)[0]
    goal = np.asarray(src, dtype=np.float64) * fitted.irradiance_scale
    return float(np.linalg.norm(np.asarray(tgt, dtype=np.float64) - goal) / max(float(np.linalg.norm(goal)), 1e-12))


__all__ = [
    "JOINT_STRATEGY",
    "NUDGE",
    "TransmissiveFit",
    "inside",
    "interpolation_error",
    "setup",
    "smoothest",
    "widened",
    "widened_for",
]
