"""Uniform remapping: fit a target model's parameters so that its render matches a source render.

Sztrajman et al. 2019, §3: render the probe scene with the source material, then minimise the
L2 difference of linear HDR images over the target's parameters inside their bounds. The paper used
SciPy's trust-region reflective least squares; here a bounded Levenberg-Marquardt in ask/tell form
(:mod:`matremap.core.descent`) reaches the same minima (the authors' table reproduces to the same
0.056 %) without an SVD of the Jacobian per iteration, and lets a fit be suspended between renders:
:func:`fit_steps` is a fit as a generator of render requests, so that a sweep runs many fits in lockstep
(:mod:`matremap.core.lockstep`); :func:`fit` drives one. The target renderer is a black box; the Jacobian
is taken by forward differences, all columns in one batched render. The parameters the image is affine in
(:attr:`~matremap.core.models.ModelSpec.affine`) are solved in closed form for every trial of the others
(variable projection, :mod:`matremap.core.varpro`) in every stage of every strategy but ``simple``.

Strategies:

``simple``       all free parameters at once against the full render;
``two-stage``    diffuse parameters against the diffuse-only render and specular parameters
                 (roles specular, roughness, fresnel) against the specular-only render, merged
                 (the robust default: it never trades a lobe for the other, so sweeps stay smooth);
``three-stage``  two-stage, then all parameters jointly from that start.
``separable``    all free parameters against the full render, the ones the image is affine in
                 (:attr:`~matremap.core.models.ModelSpec.affine`) solved in closed form for each trial
                 of the others (variable projection, :mod:`matremap.core.varpro`): the joint optimum
                 of ``simple`` at about the cost of a fit over the nonlinear parameters alone.

The loss reported is the relative RMSE over sphere pixels, ||t - s|| / ||s||. Under another objective
(:mod:`matremap.core.objective`) the strategy's result is refined by one more stage over every free parameter
under that objective, no roughness below half the L2 fit's; under an environment probe the L2 stages are made on
the headlight probe (:func:`_fit_body` says why). The loss is then the objective's measure
(the mean 1 - SSIM under ``ssim``) on the probe asked for, the relative RMSE being reported beside it.
"""

from __future__ import annotations

import time
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, cast

import numpy as np

from matremap.core import varpro
from matremap.core.calibrate import irradiance_ratio, same_units
from matremap.core.descent import Descent, descend
from matremap.core.lockstep import RenderRequest, Steps, run
from matremap.core.material import Material, white_reference
from matremap.core.models import SPECULAR_ROLES, ModelSpec, ParamSpec
from matremap.core.objective import check as check_objective
from matremap.core.objective import make as make_objective
from matremap.core.objective import measure
from matremap.core.scene import Scene
from matremap.dialects import get_model
from matremap.errors import MatremapError
from matremap.renderers.base import Renderer, check_probe, probe_support

STRATEGIES = ("simple", "two-stage", "three-stage", "separable")
DIFFUSE, SPECULAR, FULL = "diffuse", "specular", "full"
#: strategies that fit the full render only (no diffuse and specular stages)
JOINT = ("simple", "separable")

#: relative forward-difference step (images are float32, so well above sqrt(eps64))
FD_STEP = 1e-4
#: a source part whose energy is below this fraction of the full render counts as absent
ABSENT = 1e-9
#: a relative RMSE this small is float32 round-off: the images match
EXACT = 1e-6
#: cap on residual evaluations per stage (a converging fit of a few unknowns needs 3-10; more means it is
#: lost), and per unknown for larger stages: a 12-unknown joint fit of coloured layers (a coat's weight
#: trading against its colour) converges slowly but surely (SciPy's own default is 100 per unknown)
MAX_EVALUATIONS = 50
EVALUATIONS_PER_UNKNOWN = 10
#: the descent's ftol / xtol / gtol (:func:`matremap.core.descent.descend`)
FIT_TOL = 1e-4
#: the longest step of a variable in one descent step, as a fraction of its scale
STEP_LIMIT = 0.5


@dataclass
class StageReport:
    name: str
    params: list[str]
    start: dict[str, Any]
    result: dict[str, Any]
    loss: float
    renders: int
    evaluations: int
    seconds: float
    message: str

    def to_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


@dataclass
class FitResult:
    source: Material
    target: Material
    strategy: str
    loss: float
    renders: int
    seconds: float
    irradiance_scale: float
    scene: Scene
    source_renderer: str
    target_renderer: str
    stages: list[StageReport] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    #: what the fit made small (:mod:`matremap.core.objective`); ``loss`` is its measure at the result
    #: (:func:`~matremap.core.objective.measure`: the relative RMSE under ``l2``, the mean 1 - SSIM under
    #: ``ssim``), ``relative_rmse`` the paper's measure whatever the objective
    objective: str = "l2"
    relative_rmse: float = 0.0

    @property
    def params(self) -> dict[str, Any]:
        return self.target.to_dict()["params"]

    def to_dict(self) -> dict[str, Any]:
        return {
            "model": self.target.model,
            "params": self.params,
            "loss": self.loss,
            "objective": self.objective,
            "relative_rmse": self.relative_rmse,
            "renders": self.renders,
            "seconds": self.seconds,
            "strategy": self.strategy,
            "irradiance_scale": self.irradiance_scale,
            "source": self.source.to_dict(),
            "scene": self.scene.to_dict(),
            "renderers": {"source": self.source_renderer, "target": self.target_renderer},
            "stages": [s.to_dict() for s in self.stages],
            "warnings": list(self.warnings),
        }


class _Counter:
    """Asks for renders (a :class:`~matremap.core.lockstep.RenderRequest` per batch) and counts every image."""

    def __init__(self, scene: Scene) -> None:
        self.scene = scene
        self.indices = scene.pixel_indices()
        self.images = 0

    def pixels(self, renderer: Renderer, materials: Sequence[Material]) -> Steps[np.ndarray]:
        """Sphere pixels [N, P, 3] as float64 (a generator: ``yield from``)."""
        if not materials:
            return np.zeros((0, self.indices.size, 3))
        self.images += len(materials)
        pix = yield RenderRequest(renderer, tuple(materials), self.scene)
        return np.asarray(pix, dtype=np.float64)


def part(material: Material, which: str) -> Material | None:
    """The material restricted to its diffuse or specular part (None if it has no such part)."""
    if which == FULL:
        return material
    overrides = material.spec.part_overrides(which, material.values)
    if overrides is None:
        return None
    values = dict(material.values)
    for name, v in overrides.items():
        values[name] = np.full_like(values[name], v)
    return Material(material.model, values, material.options)


def fd_step(p: ParamSpec, x: np.ndarray) -> np.ndarray:
    """The forward-difference step of a parameter at ``x`` (its encoded value): :data:`FD_STEP` relative,
    and never below :data:`FD_STEP` of the parameter's scale (1 for a log-encoded one, else its range
    capped at 1, so an albedo at 0 or a roughness at 0.001 still moves the image above float32 noise)."""
    lo, hi = p.bounds
    scale = 1.0 if p.log else min(hi - lo, 1.0)
    return FD_STEP * np.maximum(np.abs(x), 1e-2 * scale if not p.log else scale)


class _Problem:
    """Least-squares problem over the free parameters of a target template.

    In ``grey`` mode (the source image has equal RGB channels and every target value is grey)
    each RGB parameter is one grey variable and only the first image channel is compared: the
    same optimum at a fraction of the cost. ``residual``, ``jacobian`` and ``solve`` are generators
    of render requests (:mod:`matremap.core.lockstep`).
    """

    def __init__(
        self,
        template: Material,
        free: Sequence[ParamSpec],
        which: str,
        goal: np.ndarray,
        renderer: Renderer,
        counter: _Counter,
        grey: bool = False,
        objective: str = "l2",
    ) -> None:
        self.template = template
        self.free = list(free)
        self.which = which
        self.grey = grey
        self.goal = goal[:, :1] if grey else goal
        self.norm = float(np.linalg.norm(self.goal))
        #: None for the paper's L2 (computed inline, as it always was); else the objective's residuals
        self.objective = None if objective == "l2" else make_objective(objective, self.goal, counter.scene)
        self.renderer = renderer
        self.counter = counter
        self.width = [1 if grey else p.channels for p in self.free]
        self.slices: list[slice] = []
        i = 0
        for w in self.width:
            self.slices.append(slice(i, i + w))
            i += w
        self.size = i
        lo, hi = [], []
        for p, w in zip(self.free, self.width, strict=True):
            a, b = p.bounds
            if p.log:
                a, b = np.log(max(a, 1e-300)), np.log(b)
            lo += [a] * w
            hi += [b] * w
        self.lower, self.upper = np.array(lo), np.array(hi)
        self._last: tuple[np.ndarray, np.ndarray] | None = None
        self.evaluations = 0

    def encode(self, m: Material) -> np.ndarray:
        parts = []
        for p, w in zip(self.free, self.width, strict=True):
            v = m.values[p.name]
            v = np.array([v.mean()]) if w < p.channels else v
            parts.append(np.log(np.maximum(v, 1e-300)) if p.log else v)
        return np.clip(np.concatenate(parts), self.lower, self.upper) if parts else np.zeros(0)

    def decode(self, x: np.ndarray) -> Material:
        values = dict(self.template.values)
        for p, s in zip(self.free, self.slices, strict=True):
            v = np.exp(x[s]) if p.log else x[s]
            v = np.broadcast_to(np.clip(v, *p.bounds), (p.channels,))
            for name in (p.name, *p.tied):
                values[name] = v.copy()
        return Material(self.template.model, values, self.template.options)

    def _pixels(self, xs: Sequence[np.ndarray]) -> Steps[np.ndarray]:
        # a stage only fits a part the target has, so no part is None here
        mats = cast("list[Material]", [part(self.decode(x), self.which) for x in xs])
        pix = yield from self.counter.pixels(self.renderer, mats)
        return pix[:, :, :1] if self.grey else pix

    def residual(self, x: np.ndarray) -> Steps[np.ndarray]:
        if self._last is not None and np.array_equal(self._last[0], x):
            return self._last[1]
        self.evaluations += 1
        img = yield from self._pixels([x])
        r = self._residual_of(img[0])
        self._last = (x.copy(), r)
        return r

    def _residual_of(self, img: np.ndarray) -> np.ndarray:
        """The residual of one render's pixels [P, C]."""
        if self.objective is None:
            return ((img - self.goal) / self.norm).ravel()
        return self.objective.residuals(img[None])[0]

    def perturbations(self, x: np.ndarray) -> list[tuple[np.ndarray, list[int], np.ndarray]]:
        """The points of a forward-difference Jacobian at ``x``: (point, variables moved, their steps).
        One per scalar variable; one per RGB parameter when the model's channels are independent
        (channel c of the image depends on channel c only)."""
        separable = self.template.spec.channel_separable
        columns: list[tuple[np.ndarray, list[int], np.ndarray]] = []
        for p, s in zip(self.free, self.slices, strict=True):
            idx = list(range(s.start, s.stop))
            groups = [idx] if (separable and len(idx) == 3) else [[i] for i in idx]
            for g in groups:
                h = fd_step(p, x[g])
                h = np.where(x[g] + h > self.upper[g], -h, h)
                xp = x.copy()
                xp[g] += h
                columns.append((xp, g, h))
        return columns

    def columns(self, r0: np.ndarray, columns: list, images: np.ndarray) -> np.ndarray:
        """The Jacobian [residuals, variables] from the renders of :meth:`perturbations` (built by
        columns, returned as a Fortran-ordered view)."""
        if self.objective is None:
            diffs = (images - self.goal).reshape(len(columns), -1) * (1.0 / self.norm) - r0
        else:
            diffs = self.objective.residuals(images) - r0
        return self.columns_of(columns, diffs)

    def columns_of(self, columns: list, diffs: np.ndarray) -> np.ndarray:
        """The Jacobian from the residual differences [columns, residuals] of :meth:`perturbations`."""
        jac_t = np.zeros((self.size, diffs.shape[1]))
        for (_, g, h), diff in zip(columns, diffs, strict=True):
            if len(g) == 1:
                jac_t[g[0]] = diff / h[0]
            else:  # an RGB parameter perturbed at once: channel k of the image is its column k
                for k, var in enumerate(g):
                    jac_t[var, k::3] = diff[k::3] / h[k]
        return jac_t.T

    def jacobian(self, x: np.ndarray) -> Steps[np.ndarray]:
        r0 = yield from self.residual(x)
        columns = self.perturbations(x)
        images = yield from self._pixels([c[0] for c in columns])
        return self.columns(r0, columns, images)

    def initial_guess(self, x0: np.ndarray) -> Steps[np.ndarray]:
        """A start near the optimum, from one batched render: a few values of the first roughness
        parameter are tried, and the parameters the image scales with (albedos, F0) are multiplied
        by the least-squares intensity ratio of the best candidate."""
        rough = next((i for i, p in enumerate(self.free) if p.role == "roughness"), None)
        linear = [i for i, p in enumerate(self.free) if p.scales_image]
        candidates = [x0] if rough is None else []
        if rough is not None:
            p, sl = self.free[rough], self.slices[rough]
            for v in roughness_candidates(p):
                xc = x0.copy()
                xc[sl] = np.log(v) if p.log else v
                candidates.append(xc)
        if rough is None and not linear:
            return x0
        best, best_err, best_k, best_img = x0, np.inf, 1.0, None
        images = yield from self._pixels(candidates)
        for xc, img in zip(candidates, images, strict=True):
            tt = float(np.sum(img * img))
            k = float(np.sum(img * self.goal)) / tt if (linear and tt > 0) else 1.0
            k = k if k > 0 else 1.0
            err = float(np.sum((k * img - self.goal) ** 2))
            if err < best_err:
                best, best_err, best_k, best_img = xc, err, k, img
        x = best.copy()
        for i in linear:
            sl, p = self.slices[i], self.free[i]
            x[sl] = x[sl] + np.log(best_k) if p.log else x[sl] * best_k
        x = np.clip(x, self.lower, self.upper)
        if best_img is not None and np.array_equal(x, best):
            # the descent starts on a candidate: its residual is known (the renderer draws a material the same
            # alone or in a batch), not a render more
            self._last = (x.copy(), self._residual_of(best_img))
        return x

    def solve(self, start: Material, coarse: bool = True) -> Steps[tuple[Material, Descent]]:
        x0 = self.encode(start)
        # a start on a bound (e.g. a diffuse albedo of 0) stalls the descent: move inside
        span = np.minimum(self.upper - self.lower, 1.0)
        x0 = np.where((x0 <= self.lower) | (x0 >= self.upper), self.lower + 0.5 * span, x0)
        if coarse:
            x0 = yield from self.initial_guess(x0)
            x0 = np.where((x0 <= self.lower) | (x0 >= self.upper), self.lower + 0.5 * span, x0)
        sol = yield from descend(
            self.residual,
            self.jacobian,
            x0,
            self.lower,
            self.upper,
            tol=FIT_TOL,
            max_evaluations=max(MAX_EVALUATIONS, EVALUATIONS_PER_UNKNOWN * self.size),
            exact=EXACT,
            limit=self.step_limit,
        )
        result = yield from self.result(sol.x)
        return result, sol

    def step_limit(self, x: np.ndarray) -> np.ndarray:
        """The longest step of each variable at ``x`` in one descent step: :data:`STEP_LIMIT` of its value,
        and at least that fraction of a tenth of its scale (its range capped at 1; 1 for a log-encoded
        variable, which then moves by at most a factor e^0.5)."""
        out = np.empty(self.size)
        for p, s in zip(self.free, self.slices, strict=True):
            lo, hi = p.bounds
            out[s] = STEP_LIMIT * (1.0 if p.log else np.maximum(np.abs(x[s]), 0.1 * min(hi - lo, 1.0)))
        return out

    def result(self, x: np.ndarray) -> Steps[Material]:
        """The material of a solution ``x``."""
        return self.decode(x)
        yield  # a generator, as the projected problem's (which may render)


class _Projected(_Problem):
    """A stage over the nonlinear parameters with the affine ones solved in closed form at every trial
    (variable projection, :mod:`matremap.core.varpro`).

    Each trial renders the basis: the image with the affine parameters at their lower bounds and with
    each one at 1. When the model's channels are independent and every other value is grey, the basis
    images are grey too, so they are *packed* into the channels of one RGB render (affine parameter j at 1
    in channel j + 1 only, everything at its lower bound in channel 0): one render per trial instead of
    1 + L. The Jacobian is Kaufman's (the derivative at the solved values, projected off the free affine
    directions), one render per nonlinear variable (packed as well)."""

    def __init__(
        self,
        template: Material,
        nonlinear: Sequence[ParamSpec],
        linear: Sequence[ParamSpec],
        which: str,
        goal: np.ndarray,
        renderer: Renderer,
        counter: _Counter,
        grey: bool = False,
    ) -> None:
        super().__init__(template, nonlinear, which, goal, renderer, counter, grey)
        self.linear = list(linear)
        ch = self.goal.shape[1]
        self.lo = np.array([p.bounds[0] for p in self.linear], dtype=float)
        self.hi = np.array([min(1.0, p.bounds[1]) for p in self.linear], dtype=float)
        self.hi = np.where(self.hi > self.lo, self.hi, self.lo + 1.0)  # a basis step of 1 above the lower bound
        self.unit_span = bool(np.all(self.hi - self.lo == 1.0))
        self.theta_lower = np.array([p.bounds[0] for p in self.linear], dtype=float)
        self.theta_upper = np.array([p.bounds[1] for p in self.linear], dtype=float)
        spec = template.spec
        limit = spec.affine_sum_limit
        # channel by channel: every affine parameter has a value per image channel, no sum across them
        self.by_channel = spec.channel_separable and limit is None and all(ch == 1 or p.channels == 3 for p in linear)
        self.packed = self.by_channel and counter.scene.grey_lighting and self._grey_basis() and 1 + len(linear) <= 3
        self.layout = varpro.unknowns([p.channels for p in self.linear], ch)
        self.sums = varpro.sum_rows(self.layout, ch) if limit is not None else None
        self.limit = limit
        self._solved: tuple[np.ndarray, np.ndarray, Any] | None = None

    def _grey_basis(self) -> bool:
        """Whether every basis image is grey: each value other than the affine ones grey, and the
        nonlinear parameters staying grey (scalars, or one grey variable in grey mode)."""
        low = part(self._at(self.template, list(self.lo)), self.which)
        if low is None:
            return False
        names = {p.name for p in self.linear}
        grey_values = all(np.all(v == v[0]) for k, v in low.values.items() if k not in names)
        return grey_values and all(p.channels == 1 or self.grey for p in self.free)

    def with_theta(self, m: Material, theta: Any) -> Material:
        """``m`` with the affine parameters at ``theta`` (a [L, channels] array, or the layout of
        :mod:`varpro`)."""
        values = dict(m.values)
        for j, p in enumerate(self.linear):
            if isinstance(theta, np.ndarray) and theta.ndim == 2:
                parts = theta[j]
            else:
                parts = np.array([theta[k] for k, u in enumerate(self.layout) if u.param == j], dtype=float)
            values[p.name] = np.broadcast_to(np.clip(parts, *p.bounds), (p.channels,)).copy()
        return Material(m.model, values, m.options)

    def _at(self, m: Material, values: Sequence[Any]) -> Material:
        v = dict(m.values)
        for p, x in zip(self.linear, values, strict=True):
            v[p.name] = np.broadcast_to(np.asarray(x, dtype=float), (p.channels,)).copy()
        return Material(m.model, v, m.options)

    def basis_materials(self, m: Material) -> list[Material]:
        """The renders of the basis at ``m``'s nonlinear values (see the class docstring)."""
        lo, hi, n = self.lo, self.hi, len(self.linear)
        if self.packed:
            values = [np.array([lo[j]] * 3) for j in range(n)]
            for j in range(n):
                values[j][j + 1] = hi[j]
            return [self._at(m, values)]
        return [self._at(m, list(lo))] + [self._at(m, [hi[j] if i == j else lo[i] for i in range(n)]) for j in range(n)]

    def _render(self, materials: Sequence[Material]) -> Steps[np.ndarray]:
        mats = cast("list[Material]", [part(m, self.which) for m in materials])
        pix = yield from self.counter.pixels(self.renderer, mats)
        return pix[:, :, :1] if (self.grey and not self.packed) else pix

    def basis(self, images: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The offset (all affine at their lower bounds) [P, ch] and the basis [L, P, ch] of one trial's
        renders ([L, P, 1] when packed: grey, the same in every channel)."""
        n = len(self.linear)
        if self.packed:  # the offset [P, 1] broadcasts over the channels
            img = images[0]
            base = img[:, :1]
            b = (img[:, 1 : 1 + n] - base).T[:, :, None]
        else:
            base = images[0]
            b = images[1 : 1 + n] - base
        if self.unit_span:
            return base, b
        return base, b / (self.hi - self.lo)[:, None, None]

    def offset(self, base: np.ndarray, b: np.ndarray) -> np.ndarray:
        """The image with every affine parameter at 0, from a trial's offset and basis."""
        return base - varpro.combine_channels(np.repeat(self.lo[:, None], base.shape[1], axis=1), b)

    def affine_fit(self, base: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, Any]:
        """The residual at the affine optimum of one trial, and that optimum."""
        offset = self.offset(base, b) if np.any(self.lo) else base
        target = varpro.channel_difference(self.goal, offset)
        if self.by_channel:
            by_channel = varpro.solve_channels(b, target, self.theta_lower, self.theta_upper)
            return varpro.affine_residual(offset, by_channel.theta, b, self.goal, 1.0 / self.norm).ravel(), by_channel
        a = varpro.design(b, self.layout)
        rhs = target.ravel()
        lower = np.array([self.theta_lower[u.param] for u in self.layout])
        upper = np.array([self.theta_upper[u.param] for u in self.layout])
        sol = varpro.solve(a, rhs, lower, upper, self.sums, self.limit)
        return ((a @ sol.theta) - rhs) / self.norm, sol

    def solve_theta(self, xs: Sequence[np.ndarray]) -> Steps[list[tuple[np.ndarray, Any]]]:
        """For each trial ``x``: the residual at the affine optimum, and that optimum (one batched render)."""
        per = len(self.basis_materials(self.template))
        mats = [m for x in xs for m in self.basis_materials(self.decode(x))]
        pix = yield from self._render(mats)
        return [self.affine_fit(*self.basis(pix[i * per : (i + 1) * per])) for i in range(len(xs))]

    def residual(self, x: np.ndarray) -> Steps[np.ndarray]:
        if self._solved is not None and np.array_equal(self._solved[0], x):
            return self._solved[1]
        self.evaluations += 1
        solved = yield from self.solve_theta([x])
        r, sol = solved[0]
        self._solved = (x.copy(), r, sol)
        return r

    def jacobian(self, x: np.ndarray) -> Steps[np.ndarray]:
        yield from self.residual(x)
        assert self._solved is not None
        _, r0, sol = self._solved
        if not self.packed:  # perturbed renders at the solved affine values
            self.template = self.with_theta(self.template, sol.theta)
            jac = yield from super().jacobian(x)
        else:  # perturbed bases, combined with the solved values
            columns = self.perturbations(x)
            pix = yield from self._render([m for c in columns for m in self.basis_materials(self.decode(c[0]))])
            diffs = np.empty((len(columns), r0.size))
            for i in range(len(columns)):
                base, b = self.basis(pix[i : i + 1])
                offset = self.offset(base, b) if np.any(self.lo) else base
                diffs[i] = varpro.affine_residual(offset, sol.theta, b, self.goal, 1.0 / self.norm).ravel()
                diffs[i] -= r0
            jac = self.columns_of(columns, diffs)
        if self.by_channel:
            return varpro.project_channels(jac, sol)
        return varpro.project_out(jac, sol.free_basis)

    def initial_guess(self, x0: np.ndarray) -> Steps[np.ndarray]:
        """The best of a few roughness values, each with its affine optimum (one batched render)."""
        rough = next((i for i, p in enumerate(self.free) if p.role == "roughness"), None)
        if rough is None:
            return x0
        p, sl = self.free[rough], self.slices[rough]
        candidates = []
        for v in roughness_candidates(p, count=4):
            xc = x0.copy()
            xc[sl] = np.log(v) if p.log else v
            candidates.append(xc)
        solved = yield from self.solve_theta(candidates)
        errors = [float(r @ r) for r, _ in solved]
        best = int(np.argmin(errors))
        # the descent starts here: its first residual is this one (the renderer draws a material the same alone
        # or in a batch), not a render more
        self._solved = (candidates[best].copy(), *solved[best])
        return candidates[best]

    def result(self, x: np.ndarray) -> Steps[Material]:
        yield from self.residual(x)
        assert self._solved is not None
        return self.with_theta(self.decode(x), self._solved[2].theta)


def roughness_candidates(p: ParamSpec, count: int = 5) -> np.ndarray:
    """Values tried for a roughness parameter before the least-squares descent: geometric steps
    over the parameter's range (an exponent's range is capped at [1, 1e4])."""
    lo, hi = p.bounds
    if p.log:
        lo, hi = max(lo, 1.0), min(hi, 1e4)
    else:
        lo, hi = max(lo, 0.03 * hi), 0.9 * hi
    return np.geomspace(lo, hi, count)


def is_grey(pixels: np.ndarray) -> bool:
    """Whether an image's three channels are equal (to float32 precision)."""
    scale = float(np.max(np.abs(pixels))) or 1.0
    # channel by channel: numpy broadcasts [P, 1] against [P, 3] three elements at a time, 5x slower
    spread = max((float(np.max(np.abs(pixels[:, c] - pixels[:, 0]))) for c in range(1, pixels.shape[1])), default=0.0)
    return spread <= 1e-6 * scale


def channel_sum(image: np.ndarray) -> np.ndarray:
    """The sum of an image's channels [P, C] -> [P], added left to right as ``image.sum(axis=-1)`` adds them,
    without its reduction over rows of three (8x slower)."""
    out = image[:, 0].copy()
    for c in range(1, image.shape[1]):
        out += image[:, c]
    return out


def _values_dict(m: Material, names: Sequence[str]) -> dict[str, Any]:
    d = m.to_dict()["params"]
    return {n: d[n] for n in names}


def target_template(
    spec: ModelSpec, fix: Mapping[str, Any] | None, untied: Collection[str] = ()
) -> tuple[Material, list[ParamSpec]]:
    """Target material to start from (defaults, ``fit_value`` for held parameters, then ``fix``)
    and the parameters a fit adjusts. Each follower of :attr:`~ModelSpec.isotropic` that is neither fixed nor
    in ``untied`` is tied to its leader: not a parameter of its own, it takes the leader's value (the leader's
    fixed value when the leader is fixed), so the target stays isotropic."""
    held = {p.name: p.fit_value for p in spec.params if not p.fit and p.fit_value is not None}
    template = Material.create(spec.id).with_params(held).with_params(dict(fix or {}))
    spec = spec.specialise(template.values)  # e.g. a metal's base colour is its specular colour
    fixed = set(fix or {})
    free = [p for p in spec.params if p.fit and p.name not in fixed]
    for follower, leader in spec.isotropic:
        if follower in fixed or follower in untied:
            continue
        template = template.with_params({follower: template.values[leader]})
        free = [replace(p, tied=(*p.tied, follower)) if p.name == leader else p for p in free if p.name != follower]
    return template, free


def tie(m: Material, params: Sequence[ParamSpec]) -> Material:
    """``m`` with each parameter tied to one of ``params`` (:attr:`~matremap.core.models.ParamSpec.tied`) set to
    that one's value."""
    tied = {name: m.values[p.name] for p in params for name in p.tied}
    return m.with_params(tied) if tied else m


def fit(
    source: Material,
    target_model: str | ModelSpec,
    strategy: str = "two-stage",
    scene: Scene | None = None,
    source_renderer: Renderer | None = None,
    target_renderer: Renderer | None = None,
    *,
    fix: Mapping[str, Any] | None = None,
    free: Sequence[str] = (),
    start: Mapping[str, Any] | None = None,
    coarse: bool | None = None,
    objective: str = "l2",
) -> FitResult:
    """Remap a uniform ``source`` material onto ``target_model`` (see the module docstring).

    ``fix`` sets target options or holds parameters at given values; ``free`` also fits parameters
    that are held by default (e.g. ``eta`` of a conductor); ``start`` gives starting values (a warm
    start). ``coarse`` (default: only without ``start``) tries a few roughness values and an
    intensity ratio in one batched render before the descent. ``objective`` (:mod:`matremap.core.objective`):
    other than ``l2``, the strategy's result is refined by a last stage over every free parameter under
    it. The fit's renders are made as it asks for them (:func:`fit_steps` is the same fit in ask/tell form,
    for :func:`~matremap.core.lockstep.lockstep`).
    """
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
    source_renderer: Renderer | None = None,
    target_renderer: Renderer | None = None,
    *,
    fix: Mapping[str, Any] | None = None,
    free: Sequence[str] = (),
    start: Mapping[str, Any] | None = None,
    coarse: bool | None = None,
    objective: str = "l2",
) -> Steps[FitResult]:
    """:func:`fit` as a generator of render requests (:mod:`matremap.core.lockstep`); returns the
    :class:`FitResult`. The arguments are checked before the first request."""
    t0 = time.perf_counter()
    if strategy not in STRATEGIES:
        raise MatremapError(f"unknown strategy {strategy!r}; choose one of {', '.join(STRATEGIES)}")
    check_objective(objective)
    spec = target_model if isinstance(target_model, ModelSpec) else get_model(target_model)
    scene = scene or Scene()
    if (
        source_renderer is None
        or target_renderer is None
        or isinstance(source_renderer, str)
        or isinstance(target_renderer, str)
    ):
        raise TypeError("core.fit.fit draws with Renderer objects; matremap.fit resolves renderer names")
    src_r, tgt_r = source_renderer, target_renderer
    for r, model in ((src_r, source.model), (tgt_r, spec.id)):
        if not r.can_render(model):
            raise MatremapError(f"renderer {r.name!r} cannot render model {model}")
        check_probe(r, scene)
    # an isotropic source stays isotropic: the target's anisotropy is freed by an anisotropic source or by the user
    anisotropic = source.spec.anisotropic(source.values)
    spec, template, free_params = _fit_setup(spec, fix, free, start, anisotropic)
    if coarse is None:
        coarse = not start
    return (
        yield from _fit_body(source, spec, strategy, scene, src_r, tgt_r, template, free_params, coarse, t0, objective)
    )


def _fit_body(
    source: Material,
    spec: ModelSpec,
    strategy: str,
    scene: Scene,
    src_r: Renderer,
    tgt_r: Renderer,
    template: Material,
    free_params: list[ParamSpec],
    coarse: bool,
    t0: float,
    objective: str = "l2",
) -> Steps[FitResult]:
    """Long: the two probes of an objective fit and the loss where it was made are read best together.

    The renders of a checked fit: irradiance, source goals, the strategy's stages under L2, then under an
    objective other than L2 one more stage over every free parameter, the final loss. Under an environment
    probe the L2 stages are made on the headlight probe, which resolves a lobe's width wherever the
    environment's few lights may not: a lobe narrower than their spacing vanishes between them, and the SSIM
    objective would take that for a match (a blue plastic sweep under the mixed probe put 106 of 120 AS fits at
    alpha 1e-4, learned a constant diffuse and failed the gate at 1 - SSIM 0.52). So the objective's stage, on
    the environment, keeps each roughness at least half the headlight's (:func:`_around`), and runs from two
    starts, the headlight's fit and the L2 fit under the environment itself (bounded alike), the better kept:
    they lie in different basins (the examples' blue plastic under the built-in studio: 0.0990 from the first,
    0.0751 from the second, the floor 0.0749)."""
    counter = _Counter(scene)
    headlight = objective != "l2" and scene.environment is not None
    first = _Counter(headlight_probe(scene)) if headlight else counter
    scale = yield from _irradiance(source, spec, src_r, tgt_r, first)
    goals, sharpened, warnings = yield from _resolved_goals(source, strategy, scale, src_r, first)
    stages: list[StageReport] = []
    lobe = (yield from _source_lobe(source, goals, src_r, first)) if sharpened is None else None
    if _matte(lobe, goals):
        template, free_params = _lobe_off(template, free_params, stages)
    current = yield from _strategy_stages(strategy, template, free_params, goals, tgt_r, first, stages, coarse)
    if scene.environment is None and scene.transmission is None and objective == "l2" and sharpened is None:
        current = yield from _unresolved_lobe(
            source, current, template, free_params, goals[FULL], lobe, src_r, tgt_r, first, stages, warnings
        )
    if headlight:
        for stage in stages:
            stage.name = f"headlight {stage.name}"
    goal, where = goals[FULL], first
    if objective != "l2" and sharpened is None:
        starts = [current]
        params = _around(current, free_params)
        if headlight:  # a second start: the L2 fit under the environment itself (another basin), bounded alike
            scale = yield from _irradiance(source, spec, src_r, tgt_r, counter)
            env_goals = yield from _source_goals(source, strategy, scale, src_r, counter)
            goal = env_goals[FULL]
            there: list[StageReport] = []
            env_fit = yield from _strategy_stages(
                strategy, template, free_params, env_goals, tgt_r, counter, there, coarse
            )
            starts.append(_clip_to(env_fit, params))
            stages += [replace(stage, name=f"environment {stage.name}") for stage in there]
        best: tuple[float, Material] | None = None
        for start in starts:
            result = yield from _run_stage(
                FULL,
                params,
                start,
                goal,
                1.0,
                tgt_r,
                counter,
                stages,
                name=objective,
                coarse=False,
                objective=objective,
            )
            if best is None or stages[-1].loss < best[0]:
                best = (stages[-1].loss, result)
        assert best is not None
        current = best[1]
        where = counter
    elif objective != "l2":
        warnings.append(f"the {objective} stage is skipped: the source's lobe is narrower than the probe resolves")
    # the loss is measured where the fit was made (at the resolvable width for a too-narrow highlight)
    final = (yield from where.pixels(tgt_r, [current]))[0]
    rmse = float(np.linalg.norm(final - goal) / np.linalg.norm(goal))
    loss = rmse
    if objective != "l2" and where is counter:
        loss = measure(objective, make_objective(objective, goal, scene).residuals(final[None]))
    if sharpened is not None:
        current = yield from _towards_mirror(
            source, sharpened, current, strategy, scale, src_r, tgt_r, free_params, first, stages
        )
    return FitResult(
        source=source,
        target=current,
        strategy=strategy,
        loss=loss,
        renders=counter.images + (first.images if first is not counter else 0),
        seconds=time.perf_counter() - t0,
        irradiance_scale=scale,
        scene=scene,
        source_renderer=src_r.name,
        target_renderer=tgt_r.name,
        stages=stages,
        warnings=warnings,
        objective=objective,
        relative_rmse=rmse,
    )


def _source_lobe(
    source: Material, goals: Mapping[str, np.ndarray], renderer: Renderer, counter: _Counter
) -> Steps[np.ndarray | None]:
    """The source's specular part on the probe: the staged goal; else rendered alone, or full minus diffuse where
    only the diffuse part can be drawn; black for a model that is all diffuse (its diffuse-only render is itself);
    None where neither part can be drawn."""
    if SPECULAR in goals:
        return goals[SPECULAR]
    spec = source.spec.specialise(source.values)
    if spec.diffuse_only is not None and not spec.part_overrides(DIFFUSE, source.values):
        return np.zeros_like(goals[FULL])
    specular, diffuse = part(source, SPECULAR), part(source, DIFFUSE)
    if specular is not None:
        return (yield from counter.pixels(renderer, [specular]))[0]
    if diffuse is None:
        return None
    full, other = yield from counter.pixels(renderer, [source, diffuse])
    return np.maximum(full - other, 0.0)


def _matte(lobe: np.ndarray | None, goals: Mapping[str, np.ndarray]) -> bool:
    """Whether the source has no specular part: its lobe (:func:`_source_lobe`) holds no energy (:data:`ABSENT`)."""
    return lobe is not None and float(np.sum(lobe**2)) <= ABSENT * float(np.sum(goals[FULL] ** 2))


def _lobe_values(template: Material, params: Sequence[ParamSpec]) -> dict[str, Any]:
    """The target's specular lobe switched off: its weights and Fresnel at their lowest (a dielectric's IOR at 1
    reflects nothing) and its roughness, which then draws nothing, at its value in ``template`` (the target's
    default, a held value or the start's)."""
    return {
        p.name: p.bounds[0] if p.role in ("specular", "fresnel") else template.values[p.name]
        for p in params
        if p.role in SPECULAR_ROLES
    }


def _lobe_off(
    template: Material, free_params: list[ParamSpec], stages: list[StageReport]
) -> tuple[Material, list[ParamSpec]]:
    """A matte source gives a target without a lobe, whatever the strategy: the lobe's parameters are set off
    (:func:`_lobe_values`) and not fitted. Fitted jointly, a lobe the probe cannot tell from none goes anywhere
    (a Lambertian onto Mitsuba 3's principled: specular 0.45 at roughness 0.03, its highlight a dot the
    headlight's 128 pixels miss)."""
    lobe = [p for p in free_params if p.role in SPECULAR_ROLES]
    rest = [p for p in free_params if p.role not in SPECULAR_ROLES]
    if not lobe or not rest:
        return template, free_params
    off = _lobe_values(template, lobe)
    result = template.with_params(off)
    names = [p.name for p in lobe]
    stages.append(
        StageReport(
            "no lobe",
            names,
            _values_dict(template, names),
            _values_dict(result, names),
            0.0,
            0,
            0,
            0.0,
            "the source has no specular part; the target's lobe set off",
        )
    )
    return result, rest


#: environment views (their resolution) that judge a lobe the point probe does not resolve
CHECK_PROBE = "env"
#: a fitted lobe is hidden when its highlight covers this many times fewer pixels than the source's (twice narrower)
NARROWER = 4


def _unresolved_lobe(
    source: Material,
    fitted: Material,
    template: Material,
    free_params: list[ParamSpec],
    goal: np.ndarray,
    source_lobe: np.ndarray | None,
    src_r: Renderer,
    tgt_r: Renderer,
    counter: _Counter,
    stages: list[StageReport],
    warnings: list[str],
) -> Steps[Material]:
    """Long: the check, its candidates and its cost are read best together.

    A fitted lobe the point probe does not resolve (its share of the render, fitted minus lobe off, covers fewer
    than :data:`MIN_HIGHLIGHT_PIXELS`, and :data:`NARROWER` times fewer than the source's lobe, which the probe
    resolves): the probe cannot tell it from none, and
    the fit may have put any weight on it (a glTF grey at roughness 1 onto Mitsuba 3's principled: specular 0.78
    at roughness 0.03, near-mirror under any light but the headlight). The choice is then made under the
    environment views (:data:`CHECK_PROBE`), which show a lobe of any width: among the fit, the lobe off with
    the rest refitted, and the lobe's weight refitted at the starting roughness, the closest to the source there
    (relative RMSE) is kept. Cost: two more point-probe fits and one environment render per candidate and of the
    source, only where the check fires."""
    from matremap.core.scene import parse_probe

    lobe = [p for p in free_params if p.role in SPECULAR_ROLES]
    rest = [p for p in free_params if p.role not in SPECULAR_ROLES]
    if not lobe or not rest or not any(p.role in ("specular", "fresnel") for p in lobe):
        return fitted
    off = fitted.with_params(_lobe_values(template, lobe))
    with_lobe, without = yield from counter.pixels(tgt_r, [fitted, off])
    share = np.maximum(with_lobe - without, 0.0)
    covered = highlight_pixels(share)
    if float(np.sum(share**2)) <= ABSENT * float(np.sum(goal**2)) or covered >= MIN_HIGHLIGHT_PIXELS:
        return fitted
    if source_lobe is not None and covered * NARROWER > highlight_pixels(source_lobe):
        return fitted  # as narrow as the source's own, which the probe resolves: a fit of it, not a hidden lobe
    views = _Counter(parse_probe(CHECK_PROBE))
    why = probe_support(src_r, views.scene) or probe_support(tgt_r, views.scene)
    if why is not None:  # no environment to judge under: the fit stands, said so
        warnings.append(f"the fitted lobe covers {covered} pixel(s) of the point probe: unchecked ({why})")
        return fitted
    found: list[StageReport] = []
    none = yield from _run_stage(FULL, rest, off, goal, 1.0, tgt_r, counter, found, name="check: no lobe")
    held = [p for p in free_params if p.role != "roughness"]
    rough = fitted.with_params({p.name: template.values[p.name] for p in lobe if p.role == "roughness"})
    at_start = yield from _run_stage(FULL, held, rough, goal, 1.0, tgt_r, counter, found, name="check: start roughness")
    candidates = [fitted, none, at_start]
    env_scale = yield from _irradiance(source, fitted.spec, src_r, tgt_r, views)
    seen = (yield from views.pixels(src_r, [source]))[0] * env_scale
    images = yield from views.pixels(tgt_r, candidates)
    norm = float(np.linalg.norm(seen)) or 1.0
    errors = [float(np.linalg.norm(image - seen)) / norm for image in images]
    best = int(np.argmin(errors))
    names = ("the fit", "no lobe", "the starting roughness")
    stages += found
    stages[-1].message += "; under the environment: " + ", ".join(
        f"{n} {e:.4g}" for n, e in zip(names, errors, strict=True)
    )
    counter.images += views.images
    warnings.append(
        f"the fitted lobe covers {covered} pixel(s) of the point probe, too few to resolve it: "
        f"chosen under the environment views ({names[best]}, relative RMSE {errors[best]:.4g} against the fit's "
        f"{errors[0]:.4g})"
    )
    return candidates[best]


def headlight_probe(scene: Scene) -> Scene:
    """The point-light probe beside an environment probe: its own point lights (the mixed probe's) or the
    paper's headlight, at the point probe's resolution."""
    from matremap.core.scene import PROBE_RESOLUTION

    lights = tuple(light.theta for light in scene.lights) or (0.0,)
    return Scene.probe(lights, max(scene.resolution, PROBE_RESOLUTION["point"]))


def _irradiance(source: Material, spec: ModelSpec, src_r: Renderer, tgt_r: Renderer, counter: _Counter) -> Steps[float]:
    """The irradiance scale from the source's units to the target's on the counter's probe (1 within a family)."""
    if same_units(source.model, spec.id):
        return 1.0
    white_s, white_t = white_reference(source.spec.family), white_reference(spec.family)
    src = yield from counter.pixels(src_r, [white_s])
    tgt = yield from counter.pixels(tgt_r, [white_t])
    return irradiance_ratio(src[0], tgt[0], f"{source.spec.family} in {src_r.name}")


#: how far below the L2 fit's an objective's stage may take a roughness: a factor on the lobe's width
AROUND = 2.0


def _clip_to(m: Material, params: Sequence[ParamSpec]) -> Material:
    """``m`` with the values of ``params`` clipped into their (narrowed) bounds."""
    return tie(m.with_params({p.name: np.clip(m.values[p.name], *p.bounds) for p in params}), params)


def _around(fitted: Material, params: Sequence[ParamSpec]) -> list[ParamSpec]:
    """``params`` with each roughness bounded below at its value in ``fitted`` over :data:`AROUND` (a factor on
    alpha; its square on an exponent, whose lobe width goes as its inverse square root; for an exponent the
    bound is above, where the lobe narrows)."""
    out = []
    for p in params:
        if p.role == "roughness":
            v = float(np.mean(fitted.values[p.name]))
            lo, hi = p.bounds
            if p.log:  # an exponent: the lobe narrows as it grows
                hi = min(hi, v * AROUND**2)
            else:
                lo = max(lo, v / AROUND)
            p = replace(p, bounds=(lo, hi)) if lo < hi else p
        out.append(p)
    return out


def _resolved_goals(
    source: Material, strategy: str, scale: float, renderer: Renderer, counter: _Counter
) -> Steps[tuple[dict[str, np.ndarray], tuple[Material, float] | None, list[str]]]:
    """The source goals the fit matches, where the probe resolves them: for a highlight narrower than
    it resolves, those of the widened source (:func:`_below_resolution`, returned too); and the warnings.
    A source that renders black everywhere is refused."""
    scene = counter.scene
    goals = yield from _source_goals(source, strategy, scale, renderer, counter)
    which = FULL if strategy in JOINT else SPECULAR
    warnings: list[str] = []
    # the transmission view resolves a narrow lobe in the blur of the background seen through it
    sharpened, seen = None, goals[which]
    if scene.transmission is None:
        specular = part(source, SPECULAR) if strategy in JOINT else None
        if specular is not None:  # a joint fit's full render: its diffuse hides a mirror's unresolved highlight
            which, seen = SPECULAR, (yield from counter.pixels(renderer, [specular]))[0]
        sharpened = yield from _below_resolution(source, seen, which, renderer, counter)
    if sharpened is not None:
        warnings.append(_sharpened_note(source, sharpened, scene))
        goals = yield from _source_goals(sharpened[0], strategy, scale, renderer, counter)
    elif scene.transmission is None:
        warnings += _check_resolution(seen, scene)
    if not np.any(goals[FULL] > 0):
        raise MatremapError(
            f"{source.model} renders black on the probe ({scene.describe()}): there is nothing to fit; "
            "check its parameters (is every reflectance 0?)"
        )
    return goals, sharpened, warnings


def _fit_setup(
    spec: ModelSpec,
    fix: Mapping[str, Any] | None,
    free: Sequence[str],
    start: Mapping[str, Any] | None,
    anisotropic: bool = False,
) -> tuple[ModelSpec, Material, list[ParamSpec]]:
    """The target spec as the fit sees it, the material to start from and the parameters to fit (an anisotropic
    target's pairs tied unless ``anisotropic``: the source is, or ``free`` names a follower)."""
    untied = [f for f, _ in spec.isotropic] if anisotropic else free
    template, free_params = target_template(spec, fix, untied)
    spec = spec.specialise(template.values)
    for name in free:
        p = spec.param(name)
        if p.name in (fix or {}):
            raise MatremapError(f"{name} is both fixed and freed; drop one of --fix {name}=... / --free {name}")
        if all(q.name != p.name for q in free_params):
            free_params.append(p)
    if start:
        template = template.with_params({k: v for k, v in start.items() if k not in (fix or {})})
        template = tie(template, free_params)
    if not free_params:
        raise MatremapError(f"nothing to fit: every parameter of {spec.id} is fixed")
    return spec, template, free_params


def _source_goals(
    source: Material, strategy: str, scale: float, renderer: Renderer, counter: _Counter
) -> Steps[dict[str, np.ndarray]]:
    """The irradiance-matched source pixels each stage fits: full, and for the staged strategies the
    diffuse-only and specular-only parts (zero where the source has no such part). A source whose specular
    part no override isolates (Mitsuba 3's principled: its metallic lobe takes the base colour) but whose
    diffuse part can be drawn has the difference full - diffuse as its specular goal: the lobes add (a
    source without a specular part gets 0 either way). It was taken for black, and the target's specular
    part switched off."""
    which = [FULL] if strategy in JOINT else [DIFFUSE, SPECULAR, FULL]
    src_parts = [part(source, w) for w in which]
    rendered = yield from counter.pixels(renderer, [m for m in src_parts if m is not None])
    goals: dict[str, np.ndarray] = {}
    it = iter(rendered)
    for w, m in zip(which, src_parts, strict=True):
        if m is None:
            goals[w] = np.zeros((counter.indices.size, 3))
        else:  # within a family (scale 1) the render itself, not its product by 1
            goals[w] = next(it) if scale == 1.0 else scale * next(it)
    spec = source.spec.specialise(source.values)
    if strategy not in JOINT and spec.specular_only is None and spec.diffuse_only is not None:
        goals[SPECULAR] = np.maximum(goals[FULL] - goals[DIFFUSE], 0.0)
    return goals


def _strategy_stages(
    strategy: str,
    template: Material,
    free_params: list[ParamSpec],
    goals: Mapping[str, np.ndarray],
    renderer: Renderer,
    counter: _Counter,
    stages: list[StageReport],
    coarse: bool,
) -> Steps[Material]:
    """Run the strategy's stages under L2 from ``template``: diffuse then specular (two-stage), everything at
    once (simple, separable), or both and then everything (three-stage); each stage appends its report."""
    current = template
    if strategy in ("two-stage", "three-stage"):
        total = float(np.sum(goals[FULL] ** 2)) or 1.0
        diffuse_free = [p for p in free_params if p.role == "diffuse"]
        specular_free = [p for p in free_params if p.role in SPECULAR_ROLES]
        order = [(DIFFUSE, diffuse_free), (SPECULAR, specular_free)]
        # a part the source has not is switched off first: the other is then fitted as the target draws it
        # without it (a Lambertian onto OpenPBR: its diffuse fitted under a 1.5-IOR specular layer, 0.24)
        order.sort(key=lambda stage: float(np.sum(goals[stage[0]] ** 2)) > ABSENT * total)
        first_stage = len(stages)
        for which_part, params in order:
            current = yield from _run_stage(
                which_part,
                params,
                current,
                goals[which_part],
                total,
                renderer,
                counter,
                stages,
                coarse=coarse,
                project=True,
            )
        if strategy == "two-stage":
            parts = max((s.loss for s in stages[first_stage:]), default=0.0)
            current = yield from _coupled(current, free_params, goals[FULL], parts, renderer, counter, stages)
    if strategy == "separable":
        return (
            yield from _run_stage(
                FULL,
                free_params,
                current,
                goals[FULL],
                1.0,
                renderer,
                counter,
                stages,
                name="separable",
                coarse=coarse,
                project=True,
            )
        )
    if strategy in ("simple", "three-stage"):
        name = "joint" if strategy == "three-stage" else FULL
        current = yield from _run_stage(
            FULL,
            free_params,
            current,
            goals[FULL],
            1.0,
            renderer,
            counter,
            stages,
            name=name,
            coarse=coarse and strategy == "simple",
        )

    return current


#: a two-stage fit whose full render is further than this from the source's (relative RMSE), and ``COUPLING`` times
#: further than either stage from its part, is refined jointly
COUPLED = 0.1
COUPLING = 2.0


def _coupled(
    current: Material,
    free_params: list[ParamSpec],
    goal: np.ndarray,
    parts: float,
    renderer: Renderer,
    counter: _Counter,
    stages: list[StageReport],
) -> Steps[Material]:
    """A two-stage fit refined over every free parameter at once, from where it stands, when its full render is
    more than ``COUPLED`` off and ``COUPLING`` times further than the worst of its stages from its part (``parts``):
    each part matched on its own and the whole did not, so the target's parts depend on each other's parameters (a
    fit as far off as its stages is a target that cannot draw the source, and is left as it is). Mitsuba 3's
    ``roughplastic`` darkens its diffuse as alpha grows (to a third at alpha 1, the energy its tabulated rough
    transmittance loses; Mitsuba 3 issue 1155, a furnace test at alpha 1), so a diffuse fitted at the starting
    alpha was far too dark at the fitted one: UsdPreviewSurface at roughness 1 came out 0.62 off (stages 0.046 and
    4e-7), jointly 0.005 (the coat's IOR at 1, its diffuse 0.49). The refinement is kept when closer."""
    norm = float(np.linalg.norm(goal)) or 1.0
    before = float(np.linalg.norm((yield from counter.pixels(renderer, [current]))[0] - goal)) / norm
    if not (before > COUPLED and before > COUPLING * parts):
        return current
    joint = yield from _run_stage(
        FULL, free_params, current, goal, 1.0, renderer, counter, stages, name="joint (coupled parts)", coarse=False
    )
    after = float(np.linalg.norm((yield from counter.pixels(renderer, [joint]))[0] - goal)) / norm
    if after < before:
        return joint
    stages[-1].message += f"; not kept ({after:.4g} against the two stages' {before:.4g})"
    return current


#: a highlight must cover at least this many pixels (above half its peak, a 3x3 block) to be fitted
MIN_HIGHLIGHT_PIXELS = 9


#: how far a source's roughness is raised per step when its highlight is narrower than the probe resolves
SHARPEN_STEP = 1.5
SHARPEN_STEPS = 16


def roughness_of(spec: ModelSpec) -> ParamSpec | None:
    """The parameter that sets the width of the model's specular lobe (role ``roughness``)."""
    return next((p for p in spec.params if p.role == "roughness"), None)


def highlight_pixels(image: np.ndarray) -> int:
    """Pixels of a (specular) image at or above half its peak luminance; 0 for a black image."""
    luminance = channel_sum(image)
    peak = float(luminance.max()) if luminance.size else 0.0
    return int(np.count_nonzero(luminance >= 0.5 * peak)) if peak > 0 else 0


def _below_resolution(
    source: Material, goal: np.ndarray, which: str, renderer: Renderer, counter: _Counter
) -> Steps[tuple[Material, float] | None]:
    """When the source's highlight covers fewer than :data:`MIN_HIGHLIGHT_PIXELS` (a mirror under point
    lights shows none), the source with its lobe widened until the probe resolves it, and the factor by
    which its roughness was raised; None when it is resolved, or when no widening shows a lobe (the
    source has no specular part). The widths tried are rendered in one batch.

    Below the probe's resolution a lobe's width cannot be measured, only its energy: the fit is made at
    the narrowest resolvable width and the target's roughness then scaled back by the same factor towards
    its mirror limit (:func:`_towards_mirror`), so roughness 0 maps to roughness 0 and a mirror's
    reflectance is fitted where the probe can see it."""
    rp = roughness_of(source.spec)
    if rp is None or highlight_pixels(goal) >= MIN_HIGHLIGHT_PIXELS:
        return None
    value = float(source.values[rp.name][0])
    lo, hi = rp.bounds
    if rp.log:  # an exponent (Phong): the lobe narrows as it grows, so widen by lowering it
        start = min(max(value, lo), hi)
        widths = [start / SHARPEN_STEP ** (2 * k) for k in range(1, SHARPEN_STEPS + 1)]
        widths = [w for w in widths if w >= lo]
    else:
        start = max(value, lo, 1e-3)
        widths = [start * SHARPEN_STEP**k for k in range(1, SHARPEN_STEPS + 1)]
        widths = [w for w in widths if w <= hi]
    if not widths:
        return None
    candidates = [source.with_params({rp.name: w}) for w in widths]
    parts = [part(m, which) for m in candidates]
    if any(m is None for m in parts):  # no such part to widen (a model without a specular-only render)
        return None
    images = yield from counter.pixels(renderer, [m for m in parts if m is not None])
    for m, w, image in zip(candidates, widths, images, strict=False):
        if highlight_pixels(image) >= MIN_HIGHLIGHT_PIXELS:
            ratio = (value / w) if not rp.log else (w / value) ** 0.5 if value > 0 else 0.0
            return m, float(np.clip(ratio, 0.0, 1.0))
    return None


def _towards_mirror(
    source: Material,
    sharpened: tuple[Material, float],
    fitted: Material,
    strategy: str,
    scale: float,
    src_r: Renderer,
    tgt_r: Renderer,
    free_params: list[ParamSpec],
    counter: _Counter,
    stages: list[StageReport],
) -> Steps[Material]:
    """The target fitted at the widened source lobe, extrapolated to the source's own (narrower) lobe.

    A second fit, one widening step further, gives the local power law target roughness ~ source
    roughness^k between the two resolvable widths (k = 1/2 from Mitsuba's alpha to glTF's roughness,
    whose alpha is its square; k = 1 between alphas); the target roughness is carried along it to the
    source's width, so roughness 0 maps to the target's mirror limit. Exponents (Phong) work the same on
    their inverse square root."""
    rp_s, rp_t = roughness_of(source.spec), roughness_of(fitted.spec)
    if rp_s is None or rp_t is None:
        return fitted
    widened, ratio = sharpened
    w1 = float(widened.values[rp_s.name][0])
    w2 = w1 / SHARPEN_STEP**2 if rp_s.log else min(w1 * SHARPEN_STEP, rp_s.bounds[1])
    further = widened.with_params({rp_s.name: w2})
    goals = yield from _source_goals(further, strategy, scale, src_r, counter)
    second = yield from _strategy_stages(strategy, fitted, free_params, goals, tgt_r, counter, stages, coarse=False)

    def width(v: float, log: bool) -> float:  # a roughness-like measure of a lobe's width
        return v**-0.5 if log else v

    t1, t2 = (width(float(m.values[rp_t.name][0]), rp_t.log) for m in (fitted, second))
    s1, s2 = width(w1, rp_s.log), width(w2, rp_s.log)
    k = np.log(t2 / t1) / np.log(s2 / s1) if t1 > 0 and t2 > 0 and t2 != t1 and s2 != s1 else 1.0
    k = float(np.clip(k, 0.25, 4.0))
    target_width = t1 * ratio**k
    lo, hi = rp_t.bounds
    value = target_width**-2 if rp_t.log and target_width > 0 else (hi if rp_t.log else target_width)
    value = float(np.clip(value, lo, hi))
    return tie(fitted.with_params({rp_t.name: [value] * 3 if rp_t.channels == 3 else value}), free_params)


def _sharpened_note(source: Material, sharpened: tuple[Material, float], scene: Scene) -> str:
    """The warning of a fit made at a widened lobe (:func:`_below_resolution`)."""
    rp = roughness_of(source.spec)
    name = rp.name if rp is not None else "roughness"
    return (
        f"the source highlight ({name} {float(source.values[name][0]):.4g}) is narrower than the probe resolves "
        f"at {scene.resolution}x{scene.resolution}: fitted at {name} {float(sharpened[0].values[name][0]):.4g} "
        f"and the target's roughness scaled towards the mirror limit by {sharpened[1]:.4g}"
    )


def _check_resolution(specular: np.ndarray, scene: Scene) -> list[str]:
    """Warn when the source highlight is too small for the image to resolve it."""
    luminance = channel_sum(specular)
    peak = float(luminance.max()) if luminance.size else 0.0
    if peak <= 0:
        return []
    covered = int(np.count_nonzero(luminance >= 0.5 * peak))
    if covered >= MIN_HIGHLIGHT_PIXELS:
        return []
    return [
        f"the source highlight covers {covered} pixel(s) at {scene.resolution}x{scene.resolution}: "
        f"too few to fit its shape; raise the resolution (--size {4 * scene.resolution})"
    ]


def _run_stage(
    which: str,
    params: list[ParamSpec],
    current: Material,
    goal: np.ndarray,
    total_energy: float,
    renderer: Renderer,
    counter: _Counter,
    stages: list[StageReport],
    name: str | None = None,
    coarse: bool = True,
    project: bool = False,
    objective: str = "l2",
) -> Steps[Material]:
    """Long: one stage's set-up, its two degenerate cases and its report are read best together.

    Fit ``params`` of ``current`` to ``goal`` (the ``which`` part) under ``objective``; ``project``: solve the
    parameters the model is affine in by variable projection (exact under L2 only, so not under another)."""
    t0 = time.perf_counter()
    renders0 = counter.images
    names = [p.name for p in params]
    name = name or which
    energy = float(np.sum(goal * goal))
    has_part = current.spec.part_overrides(which, current.values) is not None

    def report(result: Material, loss: float, evaluations: int, message: str) -> None:
        stages.append(
            StageReport(
                name,
                names,
                _values_dict(current, names),
                _values_dict(result, names),
                loss,
                counter.images - renders0,
                evaluations,
                time.perf_counter() - t0,
                message,
            )
        )

    if energy <= ABSENT * total_energy:
        # the source has no such part: switch the target's part off (lowest allowed values; a dielectric's IOR at
        # its lowest is 1, no reflection: its specular weight alone left OpenPBR's 1.5-IOR layer on a Lambertian)
        off = {p.name: p.bounds[0] for p in params if p.role in ("diffuse", "specular", "fresnel")}
        result = current.with_params(off)
        report(result, 0.0, 0, "source part is black; target part set to its minimum")
        return result
    if not has_part or not params:
        why = "target model has no such part" if not has_part else "no free parameter for this part"
        report(current, 1.0, 0, f"{why}; {100 * energy / total_energy:.3g}% of the source energy is unmatched")
        return current
    # grey goal and grey parameters (grey parameters render grey images in an RGB renderer)
    grey = counter.scene.grey_lighting and is_grey(goal) and all(np.all(v == v[0]) for v in current.values.values())
    affine = current.spec.affine_params(current.options) if project and objective == "l2" else ()
    linear = [p for p in params if p.name in affine]
    if linear:
        nonlinear = [p for p in params if p.name not in affine]
        problem: _Problem = _Projected(current, nonlinear, linear, which, goal, renderer, counter, grey=grey)
        if not nonlinear:  # nothing to descend on: the closed form is the fit
            result = yield from problem.result(np.zeros(0))
            r = yield from problem.residual(np.zeros(0))
            report(result, float(np.linalg.norm(r)), 1, "solved in closed form")
            return result
    else:
        problem = _Problem(current, params, which, goal, renderer, counter, grey=grey, objective=objective)
    result, sol = yield from problem.solve(current, coarse=coarse)
    report(result, float(np.sqrt(2.0 * sol.cost)), problem.evaluations, str(sol.message))
    return result
