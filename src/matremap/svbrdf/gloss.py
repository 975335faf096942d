"""Measures that see gloss: the highlight of each view against the source's, and HDR-FLIP.

SSIM, the luminance error and CIEDE2000 average over the object, where the highlight is a few per cent of the
pixels: a lobe 1.5 times sharper or duller, or a highlight removed, moves them less than a correct conversion
between two models already does. Here each view's **highlight image** -- the specular-only render, or, for a model
without one (Mitsuba 3's ``principled``: its metallic lobe takes the base colour), the full render less the
diffuse-only render, or the full render of a model that is all specular -- is reduced to two statistics of its
luminance Y over the pixels that face the camera (:func:`facing`: the grazing rim, where Schlick's Fresnel
brightens one model and not another, is not the lobe's width):

* ``energy``: mean Y, the light the lobe reflects;
* ``sharpness``: the 99.5th percentile of Y over the mean Y: a narrower lobe concentrates the same energy
  into fewer, brighter pixels (the peak-to-mean ratio of a reflected light grows as 1/alpha^2 for small alpha).

Each is compared with the source's as log(target / source) per view; the gate takes |median| over the views (the
turn of the environment: a change the same way in most views), and names the view furthest that way. A highlight
that shows on one side only is infinitely off. ``flip``: the mean HDR-FLIP error (Andersson et al., "FLIP: A
Difference Evaluator for Alternating Images", HPG 2020, and its HDR extension 2021; NVIDIA's ``flip-evaluator``)
of the full renders over the object's pixels, averaged over the views.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from matremap.errors import MatremapError
from matremap.svbrdf.quality import Check, Thresholds

#: the percentile of the highlight image's luminance read as its peak
PEAK_PERCENTILE = 99.5
#: the share of the object's inset (its radius, on a sphere) left out at its outline by :func:`facing`
RIM = 0.2
#: a highlight image whose mean luminance is below this fraction of the full render's shows no highlight
#: (its energy is compared, its sharpness is not: the peak of nothing is noise)
NO_HIGHLIGHT = 1e-3


@dataclass(frozen=True)
class Highlight:
    """The highlight of one view: mean luminance and peak over mean, and the full render's mean luminance."""

    energy: float
    sharpness: float
    full: float

    @property
    def visible(self) -> bool:
        return bool(self.energy > NO_HIGHLIGHT * max(self.full, 1e-12))


def facing(mask: np.ndarray) -> np.ndarray:
    """The pixels of ``mask`` at least :data:`RIM` of the object's largest inset from its outline: on a sphere, those
    whose normal is within about 53 degrees of the view (sin 53 = 0.8), away from the grazing rim where two models'
    Fresnel terms differ most (Schlick's brightens it, Ward's has none) and which is not the lobe's width."""
    from scipy.ndimage import distance_transform_edt

    m = np.asarray(mask, dtype=bool)
    if not m.any():
        return m
    d = distance_transform_edt(np.pad(m, 1))[1:-1, 1:-1]
    return np.asarray(d > RIM * float(d.max()))


def highlight(gloss: np.ndarray, full: np.ndarray, mask: np.ndarray) -> Highlight:
    """The highlight statistics of one view: ``gloss`` the highlight image, ``full`` the full render (linear RGB,
    [H, W, 3]), over the ``mask`` pixels (callers pass :func:`facing` of the object's)."""
    from matremap.svbrdf.quality import luminance

    y = np.maximum(luminance(np.asarray(gloss)[mask]), 0.0)
    yf = luminance(np.asarray(full)[mask])
    energy = float(y.mean()) if y.size else 0.0
    peak = float(np.percentile(y, PEAK_PERCENTILE)) if y.size else 0.0
    return Highlight(energy, peak / energy if energy > 0.0 else 0.0, float(yf.mean()) if yf.size else 0.0)


def energy_error(source: Highlight, target: Highlight) -> float:
    """log ratio of the highlights' energies (target over source); a highlight that shows on one side only
    (:attr:`Highlight.visible`) is infinitely off."""
    if not source.visible and not target.visible:
        return 0.0
    if source.visible != target.visible:
        return float("inf") if target.visible else float("-inf")
    return signed_log_ratio(source.energy, target.energy)


def sharpness_error(source: Highlight, target: Highlight) -> float:
    """log ratio of the highlights' peak-to-mean ratios (target over source, > 0: sharper); 0 where either shows no
    highlight (the energy says so)."""
    if not (source.visible and target.visible):
        return 0.0
    return signed_log_ratio(source.sharpness, target.sharpness)


def flip_error(source: np.ndarray, target: np.ndarray, mask: np.ndarray) -> float:
    """Mean HDR-FLIP error of ``target`` against the reference ``source`` (linear RGB, [H, W, 3]) over the ``mask``
    pixels (``flip-evaluator``, its default exposures and ACES tone mapper)."""
    try:
        import flip_evaluator  # type: ignore[import-untyped]
    except ImportError:  # pragma: no cover - a dependency of the package
        raise MatremapError("the quality gate needs flip-evaluator: pip install flip-evaluator") from None
    s = np.ascontiguousarray(np.maximum(np.asarray(source, dtype=np.float32), 0.0))
    t = np.ascontiguousarray(np.maximum(np.asarray(target, dtype=np.float32), 0.0))
    if not float(s.max()) > 0.0 and not float(t.max()) > 0.0:
        return 0.0
    error_map, _, _ = flip_evaluator.evaluate(s, t, "HDR", applyMagma=False, computeMeanError=False)
    e = np.asarray(error_map, dtype=np.float64)
    e = e[..., 0] if e.ndim == 3 else e
    return float(e[mask].mean()) if mask.any() else float(e.mean())


def signed_log_ratio(source: float, target: float) -> float:
    """log(target / source): 0 when both are 0, +-inf when only one is."""
    if source <= 0.0 or target <= 0.0:
        return 0.0 if source <= 0.0 and target <= 0.0 else (float("inf") if target > 0.0 else float("-inf"))
    return float(np.log(target / source))


def median_and_worst(values: Sequence[float], views: Sequence[str]) -> tuple[float, str]:
    """|median| over the views of signed values (a change the same way in most views, not a difference between two
    models' Fresnel at one grazing view), and the view furthest that way."""
    if not values:
        return 0.0, ""
    a = np.asarray(values, dtype=np.float64)
    m = float(np.median(a))
    k = int(np.argmax(a * (1.0 if m >= 0.0 else -1.0)))
    return abs(m), f"median over {len(a)} view(s), target {'above' if m >= 0 else 'below'} source; " + (
        f"furthest {views[k]}: {a[k]:+.3g}"
    )


@dataclass(frozen=True)
class View:
    """One view of the turntable: the source's and the target's full renders and highlight images (linear RGB,
    the source already in the target's irradiance units)."""

    where: str
    source: np.ndarray
    target: np.ndarray
    source_highlight: np.ndarray
    target_highlight: np.ndarray


def gloss_checks(views: Sequence[View], mask: np.ndarray, thresholds: Thresholds) -> list[Check]:
    """``highlight_energy`` and ``highlight_sharpness`` (median over the views of each view's |log ratio|, the worst
    view named) and ``flip`` (mean HDR-FLIP over the views, the worst named) of the turntable ``views``."""
    if not views:
        return []
    names = [v.where for v in views]
    energy, sharp, flip = [], [], []
    front = facing(mask)
    for v in views:
        hs = highlight(v.source_highlight, v.source, front)
        ht = highlight(v.target_highlight, v.target, front)
        energy.append(energy_error(hs, ht))
        sharp.append(sharpness_error(hs, ht))
        flip.append(flip_error(v.source, v.target, mask))
    e, e_where = median_and_worst(energy, names)
    s, s_where = median_and_worst(sharp, names)
    k = int(np.argmax(flip))
    f_where = f"mean over {len(flip)} view(s); worst {names[k]}: {flip[k]:.3g}"
    return [
        Check("highlight_energy", e, thresholds.highlight_energy, e_where),
        Check("highlight_sharpness", s, thresholds.highlight_sharpness, s_where),
        Check("flip", float(np.mean(flip)), thresholds.flip, f_where),
    ]


__all__ = [
    "NO_HIGHLIGHT",
    "PEAK_PERCENTILE",
    "RIM",
    "Highlight",
    "energy_error",
    "View",
    "facing",
    "flip_error",
    "gloss_checks",
    "highlight",
    "signed_log_ratio",
    "median_and_worst",
    "sharpness_error",
]
