"""The paper's parametric regression (Sztrajman et al. 2019, §5.1).

* target roughness = a polynomial of the source roughness, degree 1-4 chosen by held-out error;
* target reflectance = k(alpha_1) * source reflectance, per channel, with
  k(alpha) = c0 + c1 exp(-c2 alpha) + c3 exp(-c4 alpha^2)          (the paper's form)
  or the same plus c5 / alpha (a variant in the authors' code), chosen by held-out error;
  reflectances are F0 values, so models speaking an IOR go through eq. (1) both ways. The paper's k is
  one for all channels; where the target's F0 has another hue than the source's (a coloured coat over a
  metal, absorbed into a model whose coat has no colour) a per-channel tint t multiplies it,
  t k(alpha) s1, kept when it lowers the held-out error by more than 2 % (matremap's addition); the
  coefficients stay within 1e3 (a fit that runs past it is refitted within it), and a constant F0 (the training
  median) is kept instead where it predicts the held-out points as well (matremap's additions);
* target diffuse = a per-channel scale of the source diffuse (least squares through the origin);
* a target quantity that takes one value over the data (the sweep held it: glTF's ior, a number only, held
  while the source's F0 varied) is that constant, as is one whose source counterpart does not vary;
* a layer's quantities (issue 16, matremap's addition; :mod:`.quantities`): its weight and roughness a polynomial of
  the source layer's own (as roughness above), its colour a per-channel scale of the source layer's colour (as the
  diffuse). Each layer is mapped from its own counterpart alone: a coat's look is its weight, IOR and roughness,
  whatever lies under it (the models layer by albedo scaling), and the held-out errors say how well that holds.

Every mapping is a small JSON object; :func:`evaluate` applies one to arrays of any shape.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.optimize import least_squares

from matremap.errors import MatremapError
from matremap.regress.data import TrainingData, holdout_split

MAX_DEGREE = 4
MIN_POINTS = 6
#: a reflectance tint whose channels differ by at most this share is grey (not applied)
TINT_MIN = 0.01
#: largest coefficient of a k(alpha) fit (:func:`_fit_k_bounded`); transform files may hold up to
#: :data:`matremap.regress.schema.MAX_MAGNITUDE`
COEF_MAX = 1e3


# -- the forms ---------------------------------------------------------------------------------
def k_alpha(alpha: np.ndarray, c: Any) -> np.ndarray:
    """k(alpha) = c0 + c1 exp(-c2 alpha) + c3 exp(-c4 alpha^2) [+ c5 / alpha].
    Keeps alpha's float precision (float32 maps stay float32) and works in place."""
    c = [float(v) for v in c]
    alpha = np.asarray(alpha)
    if not np.issubdtype(alpha.dtype, np.floating):
        alpha = alpha.astype(float)
    k = np.array(alpha, copy=True)  # 0-d stays an array, so the in-place steps work for scalars too
    k *= -c[2]
    np.exp(k, out=k)
    k *= c[1]
    t = np.array(alpha, copy=True)
    t *= alpha
    t *= -c[4]
    np.exp(t, out=t)
    t *= c[3]
    k += t
    k += c[0]
    if len(c) > 5:
        np.maximum(alpha, 1e-6, out=t)
        np.divide(c[5], t, out=t)
        k += t
    return k


def polynomial(coef: Any, x: np.ndarray) -> np.ndarray:
    """Horner's rule in place (np.polyval's coefficient order), keeping x's float precision."""
    coef = [float(v) for v in coef]
    out = np.full_like(x, coef[0], dtype=x.dtype if np.issubdtype(x.dtype, np.floating) else float)
    for c in coef[1:]:
        out *= x
        out += c
    return out


def evaluate(mapping: dict[str, Any], x: dict[str, np.ndarray]) -> np.ndarray:
    """Apply one parametric mapping to source quantities ``x``."""
    kind, coef = mapping["kind"], mapping.get("coef", [])
    if kind == "polynomial":
        return polynomial(coef, np.asarray(x[mapping.get("input", "roughness")]))
    if kind == "k_alpha":
        refl = np.asarray(x["reflectance"])
        if not mapping.get("roughness", True):
            out = refl * float(coef[0])
        else:
            out = k_alpha(x["roughness"], coef)[..., None] * refl
        if "tint" in mapping:
            out = out * np.asarray(mapping["tint"], dtype=out.dtype)
        return out
    if kind == "scale":
        v = np.asarray(x[mapping["input"]])
        return v * np.asarray(coef, dtype=v.dtype if np.issubdtype(v.dtype, np.floating) else float)
    if kind == "constant":
        shape = element_shape(x)
        v = np.asarray(mapping["value"], dtype=float)
        return np.broadcast_to(v, (*shape, *v.shape))
    raise MatremapError(f"unknown parametric mapping kind {kind!r}")


def element_shape(x: dict[str, np.ndarray]) -> tuple[int, ...]:
    """The per-element shape of quantity arrays (a scalar quantity's shape, an RGB one's without its channels)."""
    from matremap.regress.quantities import is_scalar

    name = next((n for n in x if is_scalar(n)), None)
    return np.shape(x[name]) if name is not None else np.shape(next(iter(x.values())))[:-1]


# -- fitting -------------------------------------------------------------------------------------
def _rmse(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean((np.asarray(a) - np.asarray(b)) ** 2)))


def fit_roughness(
    x: np.ndarray, y: np.ndarray, holdout: float = 0.2, seed: int = 0, name: str = "roughness"
) -> dict[str, Any]:
    """Polynomial y = p(x), degree chosen by held-out RMSE, then refitted on all points (``name``: the source
    quantity x is, a roughness or a layer's weight or roughness)."""
    train, test = holdout_split(len(x), holdout, seed)
    scores = {}
    for d in range(1, MAX_DEGREE + 1):
        if len(np.unique(x[train])) <= d:
            break
        coef = np.polyfit(x[train], y[train], d)
        scores[d] = _rmse(np.polyval(coef, x[test]), y[test])
    if not scores:
        raise MatremapError(f"too few distinct {name} values to fit a polynomial (need at least 2)")
    degree = min(scores, key=lambda d: (scores[d] > 1.02 * min(scores.values()), d))  # simplest within 2 %
    coef = np.polyfit(x, y, degree)
    return {
        "kind": "polynomial",
        "input": name,
        "coef": coef.tolist(),
        "degree": degree,
        "heldout_rmse": scores[degree],
        "heldout_rmse_by_degree": {str(d): s for d, s in scores.items()},
    }


def _fit_k(alpha: np.ndarray, s1: np.ndarray, s2: np.ndarray, terms: int, bound: float = np.inf) -> np.ndarray:
    """Least squares on k(alpha) s1 - s2 (pooled channels), from a few starts; ``bound``: every coefficient within
    [-bound, bound] (the rates c2, c4 within [0, bound])."""
    ratio = np.median(s2[s1 > 0] / s1[s1 > 0]) if np.any(s1 > 0) else 1.0
    rates = np.isin(np.arange(terms), (2, 4))  # exp(-c2 alpha), exp(-c4 alpha^2): never negative
    lo, hi = np.where(rates, 0.0, -bound), np.full(terms, bound)

    def from_start(c2: float, c4: float) -> Any:
        x0 = np.clip(np.array([ratio, 0.0, c2, 0.0, c4] + [0.0] * (terms - 5)), lo / 2, hi / 2)
        return least_squares(lambda c: k_alpha(alpha, c) * s1 - s2, x0, bounds=(lo, hi), method="trf")

    starts = ((1.0, 1.0), (5.0, 5.0), (20.0, 2.0), (0.5, 20.0))
    return min((from_start(c2, c4) for c2, c4 in starts), key=lambda sol: sol.cost).x  # the first of the lowest


def _fit_k_bounded(alpha: np.ndarray, s1: np.ndarray, s2: np.ndarray, terms: int) -> tuple[np.ndarray, bool]:
    """:func:`_fit_k`, and where that gives a coefficient past :data:`COEF_MAX` (a fit the data do not determine),
    the best fit with every coefficient within it instead; also whether it was so bounded.

    k is a ratio of reflectances, of order 1 over the data (the shipped library's fits stay below 330 in every
    coefficient). A coefficient past 1e3 is one of two things. Two terms cancelling to three digits or more: with
    c2 -> 0, c0 + c1 exp(-c2 alpha) is the line c0 + c1 - c1 c2 alpha, and least squares walks down that valley
    (c0 = 1478, c1 = -1479, c2 = 0.0047 on a Ward -> Ashikhmin-Shirley sweep; condition number of the
    column-scaled Jacobian 7e7), and a float32 map evaluates k with an error of |c| 2^-24. Or a term anchored at
    alpha = 0 that the data see only through exp(-c2 alpha) << 1: c1 = 8.8e8, c2 = 69 over alpha from 0.34 (a
    spike at the lowest roughness, worth 0.05 there, 8.8e8 at alpha = 0), which no transform file may hold
    (:data:`matremap.regress.schema.MAX_MAGNITUDE`). Bounding the coefficients (a trust region on them, the
    lightest regularisation) keeps the first as good a fit and the second from running off; the held-out
    comparison then weighs it like any other."""
    c = _fit_k(alpha, s1, s2, terms)
    if np.all(np.isfinite(c)) and np.max(np.abs(c)) <= COEF_MAX:
        return c, False
    return _fit_k(alpha, s1, s2, terms, COEF_MAX), True


def fit_reflectance(
    alpha: np.ndarray | None, s1: np.ndarray, s2: np.ndarray, holdout: float = 0.2, seed: int = 0
) -> dict[str, Any]:
    """s2 = k(alpha) s1 per channel (coefficients within :data:`COEF_MAX`: :func:`_fit_k_bounded`); with no source
    roughness, a constant k. The form is chosen by held-out RMSE, then weighed against a constant s2 (the training
    median): within 2 % of the chosen mapping's held-out error, the constant is kept. A target F0 that does not
    follow the source's is the constant it is, not a k(alpha) s1 that can only approximate it: k(alpha) s1 = const
    asks k to undo, at every alpha, a source F0 that varies (300-fold in the sweep where this was met), and the fit
    chases which points each alpha happened to keep."""
    train, test = holdout_split(len(s1), holdout, seed)
    constant = _rmse(np.broadcast_to(np.median(s2[train], axis=0), s2[test].shape), s2[test])
    if alpha is None:
        return _or_constant(_fit_grey_k(s1, s2, train, test), s2, constant)
    s1f, s2f = s1.ravel(), s2.ravel()
    a = np.repeat(alpha, s1.shape[-1])
    ch = s1.shape[-1]
    tr = (train[:, None] * ch + np.arange(ch)).ravel()
    te = (test[:, None] * ch + np.arange(ch)).ravel()
    scores, coefs = {}, {}
    for name, terms in (("paper", 5), ("paper+c5/alpha", 6)):
        c, _ = _fit_k_bounded(a[tr], s1f[tr], s2f[tr], terms)
        scores[name] = _rmse(k_alpha(a[te], c) * s1f[te], s2f[te])
        coefs[name] = terms
    form = min(scores, key=lambda f: (scores[f] > 1.02 * min(scores.values()), coefs[f]))
    c, bounded = _fit_k_bounded(a, s1f, s2f, coefs[form])
    out = {
        "kind": "k_alpha",
        "input": "reflectance",
        "roughness": True,
        "form": form,
        "coef": c.tolist(),
        "heldout_rmse": scores[form],
        "heldout_rmse_by_form": {**scores, "constant": constant},
    }
    if bounded:
        out["bounded"] = COEF_MAX
    return _or_constant(
        _with_tint(out, s1, s2, k_alpha(alpha, c), train, test, out["heldout_rmse_by_form"]), s2, constant
    )


def _fit_grey_k(s1: np.ndarray, s2: np.ndarray, train: np.ndarray, test: np.ndarray) -> dict[str, Any]:
    """s2 = k s1 with one k for every channel (least squares through the origin)."""

    def pooled(rows: np.ndarray) -> float:
        return float(np.sum(s1[rows] * s2[rows]) / max(np.sum(s1[rows] * s1[rows]), 1e-300))

    k = pooled(np.arange(len(s1)))
    grey = _rmse(s1[test] * pooled(train), s2[test])  # held out with the estimator that gives the stored k
    out = {"kind": "k_alpha", "input": "reflectance", "roughness": False, "coef": [k], "heldout_rmse": grey}
    return _with_tint(out, s1, s2, np.full(len(s1), k), train, test, {"k": grey})


def _or_constant(mapping: dict[str, Any], s2: np.ndarray, constant: float) -> dict[str, Any]:
    """``mapping``, or the median of ``s2`` over the training data where that constant's held-out RMSE
    (``constant``) is within 2 % of the mapping's: a target quantity the source does not drive."""
    if constant > 1.02 * mapping["heldout_rmse"]:
        return mapping
    return {
        "kind": "constant",
        "value": np.median(s2, axis=0).tolist(),
        "heldout_rmse": constant,
        "heldout_rmse_by_form": {
            **mapping.get("heldout_rmse_by_form", {"k": mapping["heldout_rmse"]}),
            "constant": constant,
        },
    }


def _scale(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per-channel least-squares scale through the origin of b on a ([n, 3] each)."""
    return np.sum(a * b, axis=0) / np.maximum(np.sum(a * a, axis=0), 1e-300)


def _with_tint(
    mapping: dict[str, Any],
    s1: np.ndarray,
    s2: np.ndarray,
    k: np.ndarray,
    train: np.ndarray,
    test: np.ndarray,
    scores: dict[str, float],
) -> dict[str, Any]:
    """``mapping`` with a per-channel ``tint`` (least squares of s2 on k s1, the grey k as fitted on all points)
    when it lowers the held-out error by more than 2 % and is a colour (its channels differ by more than
    :data:`TINT_MIN`: the paper's grey k stays as it is where the hue is kept); ``scores`` gains the tinted one."""
    if s1.ndim != 2 or s1.shape[-1] != 3:
        return mapping
    ks1 = k[:, None] * s1
    tinted = _rmse(ks1[test] * _scale(ks1[train], s2[train]), s2[test])
    tint = _scale(ks1, s2)
    if not tinted < 0.98 * mapping["heldout_rmse"] or np.ptp(tint) <= TINT_MIN * max(float(np.max(tint)), 1e-12):
        return mapping
    return {
        **mapping,
        "tint": tint.tolist(),
        "heldout_rmse": tinted,
        "heldout_rmse_by_form": {**scores, "tinted": tinted},
    }


def fit_diffuse(
    d1: np.ndarray, d2: np.ndarray, holdout: float = 0.2, seed: int = 0, name: str = "diffuse"
) -> dict[str, Any]:
    """Per-channel scale through the origin (``name``: the source quantity d1 is, the diffuse or a layer's colour)."""

    train, test = holdout_split(len(d1), holdout, seed)
    heldout = _rmse(d1[test] * _scale(d1[train], d2[train]), d2[test])
    return {"kind": "scale", "input": name, "coef": _scale(d1, d2).tolist(), "heldout_rmse": heldout}


#: a target F0 below this in every channel draws no specular lobe: its roughness is whatever the fit left
LOBE_MIN = 1e-4


def lobe_drawn(y: dict[str, np.ndarray]) -> np.ndarray:
    """The rows whose target draws a specular lobe (F0 above :data:`LOBE_MIN` in a channel), where its roughness
    means something: a fit that turned the lobe off (a rough plastic's coat at IOR 1, to draw a rough specular as
    diffuse) leaves the roughness anywhere, and a roughness mapping learned through those rows followed them (glTF
    dielectrics onto Mitsuba 3's rough plastic: held-out roughness RMSE 0.34). All rows where fewer than
    :data:`MIN_POINTS` draw one."""
    n = len(next(iter(y.values())))
    if "reflectance" not in y:
        return np.ones(n, dtype=bool)
    on = np.max(np.asarray(y["reflectance"]), axis=-1) > LOBE_MIN
    return on if int(np.count_nonzero(on)) >= MIN_POINTS else np.ones(n, dtype=bool)


def learn_layers(data: TrainingData, holdout: float = 0.2, seed: int = 0) -> dict[str, dict[str, Any]]:
    """The mappings of the layers' quantities the target speaks (module docstring): each from its source
    counterpart where both vary, else the constant the target took (a layer the sweep held)."""
    from matremap.regress.quantities import LAYER_QUANTITIES, is_scalar

    out: dict[str, dict[str, Any]] = {}
    for name in LAYER_QUANTITIES:
        if name not in data.y:
            continue
        y = data.y[name]
        if name in data.x and data.varies(name) and bool(np.ptp(y) > 1e-12):
            fit = fit_roughness if is_scalar(name) else fit_diffuse
            out[name] = fit(data.x[name], y, holdout, seed, name=name)
        else:
            v = np.median(y, axis=0)
            out[name] = {"kind": "constant", "value": float(v) if v.ndim == 0 else v.tolist()}
    return out


def learn(data: TrainingData, holdout: float = 0.2, seed: int = 0) -> dict[str, dict[str, Any]]:
    """Mappings for every quantity the target speaks: fitted where the data varies, a constant
    (the value seen in the sweep) where it does not -- where the source's quantity is held, and where the
    target's is (a parameter the target takes as a number only, held at one value while the source's varies)."""
    if len(data) < MIN_POINTS:
        raise data.too_few(MIN_POINTS)
    mappings: dict[str, dict[str, Any]] = {}
    x, y = data.x, data.y

    def fitted(name: str) -> bool:  # the source's quantity varies and so does the target's
        return name in x and data.varies(name) and bool(np.ptp(y[name]) > 1e-12)

    if "roughness" in y:
        if fitted("roughness"):
            seen = lobe_drawn(y)
            mappings["roughness"] = fit_roughness(x["roughness"][seen], y["roughness"][seen], holdout, seed)
        else:
            # the rows that draw a lobe; where none does, the fits left the roughness where they started it
            mappings["roughness"] = {"kind": "constant", "value": float(np.median(y["roughness"][lobe_drawn(y)]))}
    if "reflectance" in y:
        if fitted("reflectance"):
            alpha = x["roughness"] if ("roughness" in x and data.varies("roughness")) else None
            mappings["reflectance"] = fit_reflectance(alpha, x["reflectance"], y["reflectance"], holdout, seed)
        else:
            mappings["reflectance"] = {"kind": "constant", "value": np.median(y["reflectance"], axis=0).tolist()}
    if "diffuse" in y:
        if fitted("diffuse"):
            mappings["diffuse"] = fit_diffuse(x["diffuse"], y["diffuse"], holdout, seed)
        else:
            mappings["diffuse"] = {"kind": "constant", "value": np.median(y["diffuse"], axis=0).tolist()}
    mappings.update(learn_layers(data, holdout, seed))
    if not any(name in x and data.varies(name) for name in mappings):
        raise MatremapError("the sweep varies no source quantity the target can follow: nothing to learn")
    return mappings
