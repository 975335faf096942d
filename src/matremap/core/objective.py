"""Objectives: what a fit makes small between the target's probe pixels and the source's (issue 18).

A fit is a least-squares problem, min 1/2 ||r(x)||^2; an objective turns the target's sphere pixels into the
residual vector r. The paper's (Sztrajman et al. 2019, §3) is the L2 difference of linear HDR images; the
evaluation, though, judges under an environment map with SSIM (Wang, Bovik, Sheikh and Simoncelli, "Image
quality assessment: from error visibility to structural similarity", IEEE TIP 13(4), 2004), which weighs
every region's structure alike where L2 is dominated by the brightest highlights. ``benchmarks/ssim_floor.py``
measures the gap; these objectives are the candidates it compares:

``l2``     (t - s) / ||s||: linear radiance, the paper's; its square sum is the reported relative RMSE^2.
           Affine parameters are solved in closed form under it (:mod:`matremap.core.varpro`).
``log``    (ln(k + t) - ln(k + s)) / sqrt(n): relative differences, highlights compressed; k is
           :data:`LOG_FLOOR` of the view's white-Lambertian radiance (views are weighted to make that 1,
           :meth:`~matremap.core.scene.Scene.view_weights`), so that near-black pixels do not dominate.
``ssim``   sqrt(1 - SSIM_i) per sphere pixel and channel, / sqrt(n): its square sum is the mean 1 - SSIM over
           the sphere, the measure the evaluation reports. SSIM is computed as scikit-image's
           ``structural_similarity`` computes it by default (Wang et al.'s constants K1 = 0.01, K2 = 0.03, a
           uniform 7 x 7 window, sample covariances, the data range of the source view), on each view's whole
           image (background black), channel by channel. A floor of :data:`SSIM_FLOOR` under the root keeps
           its derivative finite where the images agree.

An objective is made for one goal (the source's pixels of one stage) by :func:`make`; ``residuals(images)``
maps target pixels [N, P, C] to residual rows [N, R], and :func:`measure` turns a residual row into the
number a fit under it reports as its loss: the relative RMSE (``l2``), the RMS log difference (``log``), the
mean 1 - SSIM (``ssim``) -- 0 for a perfect match, about 1 for none, whichever the objective. Only ``l2`` is
linear in the images, so the fitter solves affine parameters in closed form under ``l2`` only and fits the
others' final stage jointly.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from matremap.errors import MatremapError

if TYPE_CHECKING:
    from matremap.core.scene import Scene

OBJECTIVES = ("l2", "log", "ssim")
#: the log objective's offset, as a fraction of a white Lambertian's radiance in the (weighted) view
LOG_FLOOR = 0.02
#: SSIM's stabilising constants and window (Wang et al. 2004; scikit-image's defaults)
SSIM_K1, SSIM_K2, SSIM_WINDOW = 0.01, 0.03, 7
#: 1 - SSIM below this counts as this under the root of the ssim objective's residual
SSIM_FLOOR = 1e-6


class Objective(Protocol):
    name: str
    #: whether residuals are affine in the images (closed-form solves are exact under it)
    linear: bool

    def residuals(self, images: np.ndarray) -> np.ndarray:
        """Residual rows [N, R] of target pixels [N, P, C] (C the goal's channels)."""
        ...


def check(name: str) -> str:
    if name not in OBJECTIVES:
        raise MatremapError(f"unknown objective {name!r}; choose one of {', '.join(OBJECTIVES)}")
    return name


def measure(name: str, residuals: np.ndarray) -> float:
    """The loss a fit under ``name`` reports for its residual row: sqrt(sum r^2) (``l2``: the relative RMSE;
    ``log``: the RMS log difference), or sum r^2 (``ssim``: the mean 1 - SSIM)."""
    total = float(np.sum(np.square(residuals)))
    return total if name == "ssim" else float(np.sqrt(total))


def make(name: str, goal: np.ndarray, scene: Scene) -> Objective:
    """The objective ``name`` for the source pixels ``goal`` [P, C] of ``scene``'s probe."""
    check(name)
    goal = np.asarray(goal, dtype=np.float64)
    if name == "l2":
        return L2(goal)
    if name == "log":
        return Log(goal)
    return SSIM(goal, scene)


@dataclass
class L2:
    """(t - s) / ||s||."""

    goal: np.ndarray
    name: str = "l2"
    linear: bool = True

    def __post_init__(self) -> None:
        norm = float(np.linalg.norm(self.goal))
        self.scale = 1.0 / norm if norm > 0 else 1.0

    def residuals(self, images: np.ndarray) -> np.ndarray:
        return ((images - self.goal) * self.scale).reshape(len(images), -1)


@dataclass
class Log:
    """(ln(k + t) - ln(k + s)) / sqrt(n), k = :data:`LOG_FLOOR`."""

    goal: np.ndarray
    name: str = "log"
    linear: bool = False

    def __post_init__(self) -> None:
        self.base = np.log(LOG_FLOOR + np.maximum(self.goal, 0.0))
        self.scale = 1.0 / np.sqrt(max(self.goal.size, 1))

    def residuals(self, images: np.ndarray) -> np.ndarray:
        out = np.log(LOG_FLOOR + np.maximum(images, 0.0)) - self.base
        return (out * self.scale).reshape(len(images), -1)


class SSIM:
    """sqrt(1 - SSIM) per sphere pixel and channel, / sqrt(n) (see the module docstring)."""

    name = "ssim"
    linear = False

    def __init__(self, goal: np.ndarray, scene: Scene) -> None:
        self.res = scene.resolution
        self.views = scene.view_count
        mask = scene.mask().reshape(self.res, self.views, self.res).transpose(1, 0, 2)  # [V, H, W]
        #: index of the sphere pixels in a batch of view images [N, V, H, W, C]
        self.where: Any = (slice(None), *np.nonzero(mask))
        self.channels = goal.shape[1]
        self.scale = 1.0 / np.sqrt(max(goal.size, 1))
        s = self._images(goal[None])[0]  # [V, H, W, C]
        data_range = s.reshape(self.views, -1).max(axis=1) - s.reshape(self.views, -1).min(axis=1)
        data_range = np.where(data_range > 0, data_range, 1.0)
        self.c1 = ((SSIM_K1 * data_range) ** 2)[:, None, None, None]
        self.c2 = ((SSIM_K2 * data_range) ** 2)[:, None, None, None]
        self.s = s
        self.mu_s = self._mean(s[None])[0]
        self.var_s = self._mean(s[None] * s[None])[0] - self.mu_s * self.mu_s

    def _images(self, pixels: np.ndarray) -> np.ndarray:
        """Sphere pixels [N, P, C] -> whole view images [N, V, H, W, C], black off the sphere."""
        out = np.zeros((len(pixels), self.views, self.res, self.res, pixels.shape[2]))
        out[self.where] = pixels
        return out

    def _mean(self, a: np.ndarray) -> np.ndarray:
        """The window mean over each view's image (axes 2, 3 of [N, V, H, W, C]), mirrored at the edges."""
        from scipy.ndimage import uniform_filter

        return uniform_filter(a, size=(1, 1, SSIM_WINDOW, SSIM_WINDOW, 1), mode="reflect")

    def ssim(self, pixels: np.ndarray) -> np.ndarray:
        """SSIM per sphere pixel and channel [N, P, C] of target pixels [N, P, C] against the goal."""
        t = self._images(pixels)
        n = SSIM_WINDOW * SSIM_WINDOW
        cov = n / (n - 1.0)  # sample covariances, as scikit-image's default
        mu_t = self._mean(t)
        var_t = cov * (self._mean(t * t) - mu_t * mu_t)
        var_s = cov * self.var_s[None]
        cov_ts = cov * (self._mean(t * self.s[None]) - mu_t * self.mu_s[None])
        mu_s = self.mu_s[None]
        num = (2.0 * mu_t * mu_s + self.c1) * (2.0 * cov_ts + self.c2)
        den = (mu_t * mu_t + mu_s * mu_s + self.c1) * (var_t + var_s + self.c2)
        full = num / den
        return full[self.where]

    def residuals(self, images: np.ndarray) -> np.ndarray:
        d = np.maximum(1.0 - self.ssim(images), SSIM_FLOOR)
        return (np.sqrt(d) * self.scale).reshape(len(images), -1)


__all__ = ["OBJECTIVES", "Objective", "check", "make", "measure"]
