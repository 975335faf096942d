"""Uniform remapping as users call it: renderers given by name (or not at all) and resolved here.

:func:`matremap.core.fit.fit` draws with the :class:`~matremap.renderers.base.Renderer` objects it is
handed and never looks one up. This façade is where names become renderers: ``None`` means the
model's own renderer (:func:`~matremap.renderers.registry.renderer_for`), so
``fit(mitsuba3_material, "mitsuba06:ward")`` renders the source in Mitsuba 3 without being told.
:func:`fit_steps` is the same fit in ask/tell form (for fits in lockstep), and
:func:`comparison_strip` draws the source | target | difference picture of a result.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from matremap import transmissive
from matremap.core import fit as core_fit
from matremap.core.lockstep import Steps, run
from matremap.core.material import Material
from matremap.core.models import ModelSpec
from matremap.core.scene import Scene
from matremap.dialects import get_model
from matremap.dialects.mtlx import absorbed_layers
from matremap.errors import MatremapError
from matremap.renderers.base import Renderer, probe_support, render_images
from matremap.renderers.registry import get_renderer, resolve_renderer


def fit(
    source: Material,
    target_model: str | ModelSpec,
    strategy: str = "two-stage",
    scene: Scene | None = None,
    source_renderer: str | Renderer | None = None,
    target_renderer: str | Renderer | None = None,
    *,
    fix: Mapping[str, Any] | None = None,
    free: Sequence[str] = (),
    start: Mapping[str, Any] | None = None,
    coarse: bool | None = None,
    objective: str = "l2",
) -> core_fit.FitResult:
    """:func:`matremap.core.fit.fit` with renderers given by name, object or None (the model's own); a source
    that transmits is fitted on the transmission probe (:mod:`matremap.transmissive`)."""
    return run(
        fit_steps(
            source,
            target_model,
            strategy,
            scene,
            source_renderer,
            target_renderer,
            fix=fix,
            free=free,
            start=start,
            coarse=coarse,
            objective=objective,
        )
    )


def fit_steps(
    source: Material,
    target_model: str | ModelSpec,
    strategy: str = "two-stage",
    scene: Scene | None = None,
    source_renderer: str | Renderer | None = None,
    target_renderer: str | Renderer | None = None,
    *,
    fix: Mapping[str, Any] | None = None,
    free: Sequence[str] = (),
    start: Mapping[str, Any] | None = None,
    coarse: bool | None = None,
    objective: str = "l2",
) -> Steps[core_fit.FitResult]:
    """:func:`fit` in ask/tell form (:func:`matremap.core.fit.fit_steps`): a generator of render requests for
    :func:`~matremap.core.lockstep.lockstep`. Renderer names are resolved when it starts."""
    spec = target_model if isinstance(target_model, ModelSpec) else get_model(target_model)
    through = transmissive.setup(source, spec, scene, strategy, free, start, fix)
    src_r = _probe_renderer(source_renderer, source.model, through)
    tgt_r = _probe_renderer(target_renderer, spec.id, through)
    result = yield from core_fit.fit_steps(
        through.source or source,
        spec,
        through.strategy,
        through.scene,
        src_r,
        tgt_r,
        fix=fix,
        free=through.free,
        start=through.start or None,
        coarse=coarse,
        objective=objective,
    )
    result.warnings.extend(through.notes)
    result.warnings.extend(absorbed_layers(source.model, source.values, spec.id, result.target.values))
    return result


def _probe_renderer(name: str | Renderer | None, model: str, through: transmissive.TransmissiveFit) -> Renderer:
    """The renderer of ``model`` (``name``, None for the model's own); when the fit is on the transmission probe
    and the model's own renderer does not draw it, the embedded emulation, with a note (a renderer the user named
    is kept, and refused by the fit in one line if it cannot)."""
    renderer = resolve_renderer(name, model)
    if name is not None or through.scene is None or probe_support(renderer, through.scene) is None:
        return renderer
    embedded = get_renderer("embedded")
    kind = "transmission" if through.scene.transmission is not None else through.scene.kind
    if not embedded.can_render(model):
        if kind != "transmission":  # the probe the user chose (env, mixed), not one a glass brings
            raise MatremapError(
                f"the {renderer.name} renderer draws the point-light probe only, not the {kind} probe, and the "
                f"embedded renderer does not emulate {model}: use --probe point"
            )
        from matremap.renderers.embedded.transmission import INTERFACES

        raise MatremapError(
            f"the source transmits light: it is fitted on the transmission probe, which the {renderer.name} renderer "
            f"does not draw and the embedded renderer does not emulate {model}; remap onto a model with transmission "
            f"the embedded renderer draws ({', '.join(sorted(INTERFACES))})"
        )
    through.notes.append(
        f"{model} drawn by the embedded emulation: the {renderer.name} renderer does not draw the {kind} probe"
    )
    return embedded


def comparison_strip(result: core_fit.FitResult, gap: int = 4, labels: bool = True) -> np.ndarray:
    """[H (+ a caption band), 3W + 2 gap, 3] linear image of a fit (W: the probe's views side by side):
    source (irradiance-matched), target,
    and |target - source| scaled so that 10 % of the source's peak reads as the peak; exposure puts the
    source's 99.5th percentile at 1 (sRGB-encoded when written as PNG). ``labels``: a band above
    names each panel (the models and the difference's scale)."""
    scene = result.scene
    src = render_images(get_renderer(result.source_renderer), [result.source], scene)[0] * result.irradiance_scale
    tgt = render_images(get_renderer(result.target_renderer), [result.target], scene)[0]
    peak = float(np.percentile(src[scene.mask()], 99.5)) or 1.0
    diff = np.abs(tgt - src) / (0.1 * peak) * peak
    h, w = tgt.shape[:2]
    spacer = np.full((h, gap, 3), 0.02 * peak, dtype=np.float32)
    strip = np.concatenate([src, spacer, tgt, spacer, diff.astype(np.float32)], axis=1) / peak
    if not labels:
        return strip
    names = [f"source {result.source.model}", f"target {result.target.model}", "|difference| x10"]
    band = caption_band(strip.shape[1], [(i * (w + gap), w, t) for i, t in enumerate(names)])
    return np.concatenate([band, strip], axis=0)


def caption_band(width: int, captions: list[tuple[int, int, str]], height: int = 18) -> np.ndarray:
    """A dark [height, width, 3] band with each caption ``(x, panel width, text)`` written in white
    (matplotlib's Agg rasteriser), all at the size that fits the tightest panel."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width / 100, height / 100), dpi=100, facecolor=(0.08, 0.08, 0.08))
    canvas = FigureCanvasAgg(fig)
    size = min([9.0, *(1.35 * 72 * w / 100 / max(len(text), 1) for _, w, text in captions)])
    for x, _, text in captions:
        fig.text((x + 3) / width, 0.5, text, color="white", fontsize=size, va="center", ha="left")
    canvas.draw()
    rgba = np.asarray(canvas.buffer_rgba(), dtype=np.float32)[..., :3] / 255.0
    return (rgba**2.2).astype(np.float32)  # linear, as the strip; written sRGB-encoded


__all__ = ["caption_band", "comparison_strip", "fit", "fit_steps"]
