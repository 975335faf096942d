"""What a remap of one uniform material decides around its fit, made alike by ``matremap remap`` and
``matremap fit``: the values the target is held at (chosen from the source), the probe an anisotropic fit is
made under, and the quality gate's verdict on the fit (:mod:`matremap.svbrdf.quality`).

* **Held values.** A target parameter that decides what the others mean (glTF's ``metallic``, a
  :attr:`~matremap.core.models.ModelSpec.specialisations` entry) and that the user left open is chosen from the
  source: 1 (a metal) for a source without a diffuse part, else 0 (a dielectric); 0 for a source that lets light
  through; a uniform partial metal's is freed, started at the source's and fitted with the ``simple`` strategy.
* **Anisotropy.** An isotropic source stays isotropic (the fit ties the target's anisotropy,
  :attr:`~matremap.core.models.ModelSpec.isotropic`). A fit with two free roughnesses (an anisotropic source, or
  a pair the user freed) is made under lights at :data:`ANISOTROPIC_PROBE_LIGHTS`: under the headlight alone the
  half vector has no component along the sphere's tangent, so one roughness only scales the image and a fit
  trades it for a darker F0 at zero error.
* **Verdict.** The fit's relative error on its probe (``fit_error``), and colour and energy of the source and
  target renders there (:func:`~matremap.svbrdf.quality.image_checks`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from matremap.core.material import Material
from matremap.dialects import get_model
from matremap.regress import quantities as qty
from matremap.svbrdf.quality import Check, Thresholds, Verdict, image_checks

#: the probe's lights for a fit with two free roughnesses (see the module docstring)
ANISOTROPIC_PROBE_LIGHTS = (0.0, 45.0)


@dataclass
class Held:
    """The target's values as a uniform remap holds them (:func:`choose_held`)."""

    #: the user's fixes and the values chosen for the target
    fix: dict[str, Any]
    #: parameters freed for this source, with their starting values (a partial metal's metalness)
    start: dict[str, float] = field(default_factory=dict)

    @property
    def strategy(self) -> str | None:
        """The strategy the choice needs (``simple`` for a freed metalness), None for the user's."""
        return "simple" if self.start else None


def choose_held(source: Material, target: str, fix: Mapping[str, Any], log: Callable[[str], None]) -> Held:
    """The target's held values for ``source`` (:func:`complete_fix`, :func:`glass_is_dielectric`,
    :func:`free_partial_metal`); ``fix``: the user's."""
    full = complete_fix(source.model, qty.material_values(source), target, fix)
    full = glass_is_dielectric(source, target, full, fix)
    full, start = free_partial_metal(source, target, fix, full, log)
    return Held(full, start)


def complete_fix(source_model: str, values: Mapping[str, Any], target: str, fix: Mapping[str, Any]) -> dict[str, Any]:
    """The user's target fixes, plus a choice for each target parameter that decides what the
    target's parameters mean and that the user left open: a glTF ``metallic`` is 1 for a source
    without a diffuse part (a metal), else 0 (a uniform partial metal: :func:`free_partial_metal`)."""
    out = dict(fix)
    for name, value, _ in get_model(target).specialisations:
        if name not in out:
            out[name] = value if no_diffuse(source_model, values) else 0.0
    return out


def glass_is_dielectric(source: Material, target: str, fix: dict[str, Any], held: Mapping[str, Any]) -> dict[str, Any]:
    """``fix`` with the target's metalness at 0 where the source lets light through: :func:`complete_fix` takes a
    source without a diffuse part for a metal, and a Mitsuba 3 glass has none (bk7 onto glTF: 0.73 held a metal,
    0.023 a dielectric). The user's ``--fix`` (``held``) stays."""
    from matremap.renderers.embedded.transmission import transmits

    if not transmits(source):
        return fix
    return {**fix, **{name: 0.0 for name, _, _ in get_model(target).specialisations if name not in held}}


def free_partial_metal(
    source: Material, target: str, user_fix: Mapping[str, Any], fix: dict[str, Any], log: Callable[[str], None]
) -> tuple[dict[str, Any], dict[str, float]]:
    """A uniform source that is a partial metal (its own glTF ``metallic``, OpenPBR ``base_metalness``, Cycles
    ``Metallic``, ... strictly between 0 and 1): the target's metalness, where the user left it open, is freed and
    started at the source's (returned: ``fix`` without it, and name -> start), to be fitted with the ``simple``
    strategy: its base colour is both its diffuse and its metal's colour, which the staged strategies'
    diffuse-only and specular-only parts split apart. Held at 0 and fitted in stages, 58 of the 98
    MetalRoughSpheresNoTextures spheres failed the gate onto UsdPreviewSurface (sphere mat_36, metallic 0.83: 0.98;
    freed: 0.0001). The models mix their metal in differently (UsdPreviewSurface's Storm whitens a partial
    metal's highlight), so the value is fitted, not copied."""
    partial = partial_metal(source.model, qty.material_values(source))
    names = [name for name, _, _ in get_model(target).specialisations if name not in user_fix]
    if partial is None or not names:
        return fix, {}
    log(f"partial metal: {', '.join(names)} freed from the source's {partial:.3g}, fitted with the simple strategy")
    return {k: v for k, v in fix.items() if k not in names}, dict.fromkeys(names, partial)


def partial_metal(model: str, values: Mapping[str, Any]) -> float | None:
    """The source's own metalness where it is one uniform value strictly between 0 and 1, else None."""
    for name, _, _ in get_model(model).specialisations:
        v = values.get(name)
        if v is None or isinstance(v, (tuple, str)):
            continue
        a = np.asarray(v, dtype=float).reshape(-1)
        if a.size == 1 and 0.0 < a[0] < 1.0:
            return float(a[0])
    return None


def no_diffuse(model: str, values: Mapping[str, Any]) -> bool:
    """Whether a material of ``model`` with ``values`` has no diffuse part (none drawn, or a black albedo)."""
    spec = get_model(model)
    dp = qty.diffuse_param(spec)
    if dp is None or spec.specialise(values).diffuse_only is None:
        return True
    v = values.get(dp.name, spec.param(dp.name).default)
    return float(np.max(np.asarray(v, dtype=float))) <= 0.0


def anisotropic_lights(source_model: str, target: str, free: Sequence[str] = ()) -> tuple[float, ...] | None:
    """:data:`ANISOTROPIC_PROBE_LIGHTS` when a fit from ``source_model`` onto ``target`` sees two roughnesses (an
    anisotropic source's, or the target's untied by ``free``), else None (the caller's probe)."""
    source_spec = get_model(source_model)
    anisotropic_source = sum(p.role == "roughness" and p.fit for p in source_spec.params) >= 2
    untied = any(f in free for f, _ in get_model(target).isotropic)
    return ANISOTROPIC_PROBE_LIGHTS if anisotropic_source or untied else None


def fit_verdict(r: Any, thresholds: Thresholds) -> Verdict:
    """The gate's verdict on a uniform fit ``r`` (a :class:`~matremap.core.fit.FitResult`): its relative error on
    its probe, and the luminance and CIEDE2000 of the (irradiance-matched) source and target renders there; the
    images are skipped where the source's highlight is narrower than the probe resolves (the fit error, measured
    at the narrowest resolvable width, is then the measure)."""
    from matremap.core.fit import FULL, part
    from matremap.renderers import get_renderer
    from matremap.renderers.base import render_images

    where = "relative RMSE" if r.objective == "l2" else f"{r.objective} loss"
    checks = [Check("fit_error", r.loss, thresholds.fit_error, f"{where} on the {r.scene.kind} probe")]
    if any("narrower than the probe resolves" in w for w in r.warnings):
        checks.append(
            Check("image_checks", 0.0, 0.0, "skipped: the source's highlight is below the probe's resolution")
        )
        return Verdict(checks)
    scene = r.scene
    fitted = r.source  # the source as fitted: itself, or a glass widened to the target's narrowest lobe
    src = render_images(get_renderer(r.source_renderer), [part(fitted, FULL) or fitted], scene)[0]
    src = src * r.irradiance_scale
    tgt = render_images(get_renderer(r.target_renderer), [r.target], scene)[0]
    return Verdict(checks + image_checks([("probe render", src, tgt)], scene.mask(), thresholds))
