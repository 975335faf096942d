import json

import numpy as np
import pytest

from matremap.core.material import Material
from matremap.core.scene import Scene
from matremap.regress import svr
from matremap.regress.data import load_training_data
from matremap.regress.transform import Transform, learn_transform
from matremap.sweep.executors import InlineExecutor
from matremap.sweep.grid import parse_grid
from matremap.sweep.run import SweepConfig, run_sweep
from matremap.sweep.store import SweepStore

SVR = pytest.importorskip("sklearn.svm").SVR

WARD = Material.create("mitsuba06:ward", {"variant": "ward", "diffuseReflectance": 0.0})
GRID = "alpha=0.05:0.9:8,specularReflectance=0.02:0.25:6"


@pytest.fixture(scope="module")
def ward_db(tmp_path_factory):
    db = tmp_path_factory.mktemp("svr") / "w2as.sqlite"
    config = SweepConfig(source=WARD, target="mitsuba06:pbr", fix={"distribution": "as"}, scene=Scene(resolution=48))
    run_sweep(config, parse_grid(GRID, WARD.spec), str(db), InlineExecutor())
    return db


@pytest.fixture(scope="module")
def svr_t(ward_db):
    return learn_transform(ward_db, method="svr")


@pytest.fixture(scope="module")
def param_t(ward_db):
    return learn_transform(ward_db, method="parametric")


def _plain_json(obj):
    if isinstance(obj, dict):
        return all(isinstance(k, str) and _plain_json(v) for k, v in obj.items())
    if isinstance(obj, list):
        return all(_plain_json(v) for v in obj)
    return obj is None or type(obj) in (str, int, float, bool)


def test_mappings_are_svrs_with_chosen_hyperparameters(svr_t):
    assert svr_t.method == "svr"
    for q in ("roughness", "reflectance"):
        m = svr_t.mappings[q]
        assert m["kind"] == "svr" and m["kernel"] == "rbf"
        assert m["C"] in svr.C_GRID and m["gamma"] in svr.GAMMA_GRID and m["epsilon"] in svr.EPSILON_GRID
        assert 0 < len(m["support_vectors"]) == len(m["dual_coef"]) <= m["n_train"] <= svr.MAX_POINTS
        assert len(m["heldout_rmse_grid"]) == len(svr.C_GRID) * len(svr.GAMMA_GRID) * len(svr.EPSILON_GRID)
    assert svr_t.mappings["reflectance"]["per_channel"] and svr_t.mappings["reflectance"]["inputs"] == [
        "roughness",
        "reflectance",
    ]
    assert svr_t.mappings["diffuse"]["kind"] == "constant"  # the sweep holds the Ward diffuse at 0


def test_predictions_reproduce_the_training_points(ward_db, svr_t, param_t):
    rows = SweepStore.open(ward_db).rows("ok")
    alpha = np.array([r["source"]["alpha"] for r in rows])
    rho = np.array([r["source"]["specularReflectance"] for r in rows])
    fitted_alpha = np.array([r["target"]["alpha"] for r in rows])
    fitted_f0 = np.array([r["target"]["F0"] for r in rows])
    for t in (svr_t, param_t):
        out, outside = t.apply({"alpha": alpha, "specularReflectance": rho})
        assert not outside.any()
        assert np.max(np.abs(out["alpha"] / fitted_alpha - 1)) < 0.03
        assert np.max(np.abs(out["F0"] - fitted_f0)) < 0.01 * np.ptp(fitted_f0)
    assert svr_t.errors["roughness"]["heldout_rmse"] < 0.01 * np.ptp(fitted_alpha)


def test_json_round_trip_applies_identically_and_is_plain_json(svr_t, tmp_path):
    path = svr_t.save(tmp_path / "svr.json")
    text = path.read_text()
    doc = json.loads(text)
    assert _plain_json(doc) and "pickle" not in text.lower()
    assert doc["method"] == "svr" and doc["mappings"]["roughness"]["kind"] == "svr"
    again = Transform.load(path)
    rng = np.random.default_rng(3)
    x = {"alpha": rng.uniform(0.05, 0.9, 50), "specularReflectance": rng.uniform(0.02, 0.25, (50, 3))}
    a, b = svr_t.apply(x)[0], again.apply(x)[0]
    for k in a:
        np.testing.assert_array_equal(a[k], b[k])
    again2 = Transform.from_dict(json.loads(json.dumps(svr_t.to_dict())))
    np.testing.assert_array_equal(again2.apply(x)[0]["F0"], a["F0"])


def test_evaluate_matches_sklearn_predict_on_the_learned_mapping(ward_db, svr_t):
    """Refit scikit-learn's SVR on the same standardised points with the chosen parameters: the
    numpy evaluation of the stored mapping agrees with its predict."""
    data = load_training_data(ward_db)
    m = svr_t.mappings["reflectance"]
    X = np.stack([np.broadcast_to(data.x["roughness"][:, None], (len(data), 3)), data.x["reflectance"]], axis=-1)
    Xa, ya = svr.subsample(*svr.pooled_points(X, data.y["reflectance"], np.arange(len(data)), True), 0)
    x_mean, x_scale = np.array(m["x_mean"]), np.array(m["x_scale"])
    model = SVR(kernel="rbf", C=m["C"], gamma=m["gamma"], epsilon=m["epsilon"], tol=1e-4)
    model.fit((Xa - x_mean) / x_scale, (ya - m["y_mean"]) / m["y_scale"])
    rng = np.random.default_rng(0)
    alpha, rho = rng.uniform(0.02, 1.0, (7, 11)), rng.uniform(0.0, 0.3, (7, 11, 3))
    ours = svr.evaluate(m, {"roughness": alpha, "reflectance": rho})
    cols = np.stack([np.repeat(alpha[..., None], 3, -1).ravel(), rho.ravel()], axis=1)
    theirs = model.predict((cols - x_mean) / x_scale) * m["y_scale"] + m["y_mean"]
    np.testing.assert_allclose(ours.ravel(), theirs, rtol=0, atol=1e-9)


@pytest.mark.parametrize("d", [1, 2, 3])
def test_evaluate_matches_sklearn_on_random_models_and_chunks(d, monkeypatch):
    rng = np.random.default_rng(d)
    z = rng.normal(size=(300, d))
    u = np.sin(z).sum(axis=1) + 0.05 * rng.normal(size=300)
    model = SVR(kernel="rbf", C=10.0, gamma=1.0, epsilon=0.01).fit(z, u)
    names = ["roughness", "reflectance", "diffuse"][:d]
    m = svr.mapping_from_model(model, names, False, np.zeros(d), np.ones(d), 0.0, 1.0)
    q = rng.normal(size=(1000, d))
    x = {n: q[:, i] if n == "roughness" else np.repeat(q[:, i : i + 1], 3, axis=1) for i, n in enumerate(names)}
    monkeypatch.setattr(svr, "CHUNK_ENTRIES", 5000)  # many chunks, with a ragged last one
    np.testing.assert_allclose(svr.evaluate(m, x), model.predict(q), rtol=0, atol=1e-9)


def test_apply_is_vectorised_over_any_shape(svr_t):
    rng = np.random.default_rng(1)
    alpha = rng.uniform(0.1, 0.8, (4, 5))
    rho = rng.uniform(0.03, 0.2, (4, 5, 3))
    out, outside = svr_t.apply({"alpha": alpha, "specularReflectance": rho})
    assert out["alpha"].shape == (4, 5) and out["F0"].shape == (4, 5, 3) and outside.shape == (4, 5)
    one, _ = svr_t.apply({"alpha": alpha[2, 3], "specularReflectance": rho[2, 3]})
    np.testing.assert_allclose(one["F0"], out["F0"][2, 3], rtol=1e-9)
    np.testing.assert_allclose(one["alpha"], out["alpha"][2, 3], rtol=1e-9)
    grey, _ = svr_t.apply({"alpha": alpha, "specularReflectance": rho[..., 0]})  # scalar rho_s map
    assert grey["F0"].shape == (4, 5, 3)
    np.testing.assert_allclose(grey["F0"][..., 1], grey["F0"][..., 0])
    # each channel depends on its own input only
    swapped, _ = svr_t.apply({"alpha": alpha, "specularReflectance": rho[..., ::-1]})
    np.testing.assert_allclose(swapped["F0"], out["F0"][..., ::-1], rtol=1e-12)


def test_too_few_points_are_refused(ward_db):
    from matremap.errors import MatremapError

    data = load_training_data(ward_db)
    with pytest.raises(MatremapError, match="too few"):
        svr.learn(data.subset(np.arange(3)))
