"""The SVR baseline (paper §5.3): epsilon-SVR with an RBF kernel, one per target quantity.

* target roughness   = SVR of the varying source quantities: roughness, and the channel mean of
  reflectance and diffuse where those vary;
* target reflectance = SVR of (source roughness, that channel's source reflectance), one model
  shared by the channels (they are pooled for training, as the parametric k(alpha) s is), so
  coloured inputs can be applied; likewise target diffuse from (roughness, that channel's diffuse);
* a target quantity whose source counterpart does not vary is a constant, as in :mod:`.parametric`.

Inputs and outputs are standardised. C, gamma (in standardised units) and epsilon are chosen on a
validation split, then the model is refitted on all training points (at most :data:`MAX_POINTS`,
subsampled). Learning needs scikit-learn; applying does not: a mapping is plain JSON numbers
(support vectors, dual coefficients, intercept, kernel parameters, scalings) evaluated here with
numpy, in bounded-memory chunks, for arrays of any shape.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from typing import Any

import numpy as np

from matremap.errors import MatremapError
from matremap.regress.data import TrainingData, holdout_split

MIN_POINTS = 6
#: most training points (after pooling channels and dropping duplicates) an SVR is fitted on
MAX_POINTS = 800
C_GRID = (1.0, 10.0, 100.0, 1000.0)
GAMMA_GRID = (0.1, 1.0, 10.0)
EPSILON_GRID = (1e-3, 1e-2, 0.05)
#: kernel entries (points x support vectors) evaluated at once
CHUNK_ENTRIES = 1 << 21
PER_CHANNEL = ("reflectance", "diffuse")


# -- application ---------------------------------------------------------------------------------
def _design(mapping: dict[str, Any], x: dict[str, np.ndarray]) -> tuple[np.ndarray, tuple[int, ...]]:
    """Input columns [n, d] and the output shape."""
    inputs = mapping["inputs"]
    if mapping["per_channel"]:
        ch = next(np.asarray(x[n], dtype=float) for n in inputs if n in PER_CHANNEL)
        shape = ch.shape
        cols = [
            np.broadcast_to(np.asarray(x[n], dtype=float)[..., None], shape)
            if n not in PER_CHANNEL
            else np.asarray(x[n], dtype=float)
            for n in inputs
        ]
    else:
        cols = [
            np.asarray(x[n], dtype=float) if n not in PER_CHANNEL else np.asarray(x[n], dtype=float).mean(axis=-1)
            for n in inputs
        ]
        shape = np.broadcast_shapes(*(c.shape for c in cols))
        cols = [np.broadcast_to(c, shape) for c in cols]
    return np.stack([c.reshape(-1) for c in cols], axis=1), shape


def predict_standardised(mapping: dict[str, Any], z: np.ndarray) -> np.ndarray:
    """The SVR's decision function on standardised inputs ``z`` [n, d] (standardised output)."""
    sv = np.asarray(mapping["support_vectors"], dtype=float).reshape(-1, z.shape[1])
    coef = np.asarray(mapping["dual_coef"], dtype=float)
    gamma, b = float(mapping["gamma"]), float(mapping["intercept"])
    out = np.empty(len(z))
    if len(sv) == 0:
        out.fill(b)
        return out
    sv_sq = np.einsum("ij,ij->i", sv, sv)
    step = max(1, CHUNK_ENTRIES // len(sv))
    for i in range(0, len(z), step):
        zc = z[i : i + step]
        d2 = np.einsum("ij,ij->i", zc, zc)[:, None] + sv_sq[None, :] - 2.0 * (zc @ sv.T)
        np.maximum(d2, 0.0, out=d2)
        d2 *= -gamma
        np.exp(d2, out=d2)
        out[i : i + step] = d2 @ coef + b
    return out


def evaluate(mapping: dict[str, Any], x: dict[str, np.ndarray]) -> np.ndarray:
    """Apply one SVR mapping (or a constant) to source quantities ``x`` (roughness [...],
    reflectance and diffuse [..., 3]); the result has the target quantity's shape."""
    kind = mapping["kind"]
    if kind == "constant":
        shape = np.shape(x["roughness"]) if "roughness" in x else next(iter(x.values())).shape[:-1]
        v = np.asarray(mapping["value"], dtype=float)
        return np.broadcast_to(v, (*shape, *v.shape)).copy()
    if kind != "svr":
        raise MatremapError(f"unknown SVR mapping kind {kind!r}")
    missing = [n for n in mapping["inputs"] if n not in x]
    if missing:
        raise MatremapError(f"SVR mapping needs source quantities {', '.join(missing)}")
    X, shape = _design(mapping, x)
    z = (X - np.asarray(mapping["x_mean"], dtype=float)) / np.asarray(mapping["x_scale"], dtype=float)
    y = predict_standardised(mapping, z) * float(mapping["y_scale"]) + float(mapping["y_mean"])
    return y.reshape(shape)


# -- fitting -------------------------------------------------------------------------------------
def pooled_points(X: np.ndarray, y: np.ndarray, rows: np.ndarray, per_channel: bool) -> tuple[np.ndarray, np.ndarray]:
    """Training points of the materials ``rows``: channels pooled, exact duplicates dropped."""
    Xr, yr = X[rows], y[rows]
    if per_channel:  # X [n, 3, d], y [n, 3]
        Xr, yr = Xr.reshape(-1, Xr.shape[-1]), yr.reshape(-1)
    _, first = np.unique(np.column_stack([Xr, yr]), axis=0, return_index=True)
    first = np.sort(first)
    return Xr[first], yr[first]


def subsample(X: np.ndarray, y: np.ndarray, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """At most :data:`MAX_POINTS` of the points (a random subset in their order), the same for the same ``seed``."""
    if len(X) <= MAX_POINTS:
        return X, y
    keep = np.sort(np.random.default_rng(seed).choice(len(X), MAX_POINTS, replace=False))
    return X[keep], y[keep]


def _svr(C: float, gamma: float, epsilon: float):
    try:
        from sklearn.svm import SVR
    except ImportError:  # pragma: no cover - depends on the environment
        raise MatremapError(
            "learning an SVR transform needs scikit-learn: pip install 'matremap[svr]' (or scikit-learn)"
        ) from None
    return SVR(kernel="rbf", C=C, gamma=gamma, epsilon=epsilon, tol=1e-4, cache_size=100)


def fit_svr(
    X: np.ndarray, y: np.ndarray, inputs: Sequence[str], per_channel: bool, holdout: float = 0.2, seed: int = 0
) -> dict[str, Any]:
    """One SVR mapping from material rows: X [n, d] and y [n] (scalar target) or X [n, 3, d] and
    y [n, 3] (per channel). Hyper-parameters by validation RMSE on held-out materials."""
    train, test = holdout_split(len(X), holdout, seed)
    Xt, yt = subsample(*pooled_points(X, y, train, per_channel), seed)
    Xv, yv = pooled_points(X, y, test, per_channel)
    x_mean, x_scale = Xt.mean(axis=0), Xt.std(axis=0)
    x_scale[x_scale < 1e-12] = 1.0
    y_mean, y_scale = float(yt.mean()), float(yt.std()) or 1.0
    zt, zv = (Xt - x_mean) / x_scale, (Xv - x_mean) / x_scale
    ut = (yt - y_mean) / y_scale
    scores = []
    for C, gamma, eps in itertools.product(C_GRID, GAMMA_GRID, EPSILON_GRID):
        model = _svr(C, gamma, eps).fit(zt, ut)
        pred = model.predict(zv) * y_scale + y_mean
        scores.append((float(np.sqrt(np.mean((pred - yv) ** 2))), C, gamma, eps))
    best = min(scores)
    _, C, gamma, eps = best

    # refit on every training point (validation materials included) with the chosen parameters
    Xa, ya = subsample(*pooled_points(X, y, np.arange(len(X)), per_channel), seed)
    x_mean, x_scale = Xa.mean(axis=0), Xa.std(axis=0)
    x_scale[x_scale < 1e-12] = 1.0
    y_mean, y_scale = float(ya.mean()), float(ya.std()) or 1.0
    model = _svr(C, gamma, eps).fit((Xa - x_mean) / x_scale, (ya - y_mean) / y_scale)
    mapping = mapping_from_model(model, inputs, per_channel, x_mean, x_scale, y_mean, y_scale)
    mapping.update(
        {"n_train": len(Xa), "heldout_rmse": best[0], "heldout_rmse_grid": [[c, g, e, s] for s, c, g, e in scores]}
    )
    return mapping


def mapping_from_model(
    model: Any,
    inputs: Sequence[str],
    per_channel: bool,
    x_mean: np.ndarray,
    x_scale: np.ndarray,
    y_mean: float,
    y_scale: float,
) -> dict[str, Any]:
    """A fitted ``sklearn.svm.SVR`` (RBF kernel, numeric gamma, trained on standardised data) as
    a plain-JSON mapping."""
    if model.kernel != "rbf" or not isinstance(model.gamma, (int, float)):
        raise MatremapError("only RBF SVRs with a numeric gamma can be stored")
    return {
        "kind": "svr",
        "kernel": "rbf",
        "inputs": list(inputs),
        "per_channel": bool(per_channel),
        "x_mean": [float(v) for v in x_mean],
        "x_scale": [float(v) for v in x_scale],
        "y_mean": float(y_mean),
        "y_scale": float(y_scale),
        "support_vectors": np.asarray(model.support_vectors_, dtype=float).tolist(),
        "dual_coef": np.asarray(model.dual_coef_, dtype=float).ravel().tolist(),
        "intercept": float(model.intercept_[0]),
        "gamma": float(model.gamma),
        "C": float(model.C),
        "epsilon": float(model.epsilon),
    }


def learn(data: TrainingData, holdout: float = 0.2, seed: int = 0) -> dict[str, dict[str, Any]]:
    """Mappings for every quantity the target speaks: an SVR where the source counterpart
    varies, a constant (the value seen in the sweep) where it does not."""
    if len(data) < MIN_POINTS:
        raise data.too_few(MIN_POINTS)
    x, y = data.x, data.y
    varying: list[str] = [n for n in ("roughness", "reflectance", "diffuse") if n in x and data.varies(n)]
    rough = ["roughness"] if "roughness" in varying else []
    mappings: dict[str, dict[str, Any]] = {}
    for name in ("roughness", "reflectance", "diffuse"):
        if name not in y:
            continue
        if name not in varying:
            v = np.median(y[name], axis=0)
            mappings[name] = {"kind": "constant", "value": float(v) if v.ndim == 0 else v.tolist()}
            continue
        if name == "roughness":
            inputs = varying
            X = np.column_stack([x[n] if n == "roughness" else x[n].mean(axis=-1) for n in inputs])
            mappings[name] = fit_svr(X, y[name], inputs, False, holdout, seed)
        else:
            inputs = rough + [name]
            X = np.stack(
                [np.broadcast_to(x[n][:, None], x[name].shape) if n == "roughness" else x[n] for n in inputs], axis=-1
            )
            mappings[name] = fit_svr(X, y[name], inputs, True, holdout, seed)
    if all(m["kind"] == "constant" for m in mappings.values()):
        raise MatremapError("the sweep varies no source quantity the target can follow: nothing to learn")
    from matremap.regress.parametric import learn_layers

    return {**mappings, **learn_layers(data, holdout, seed)}  # a layer's quantities as the parametric method maps them
