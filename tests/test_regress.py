import json

import numpy as np
import pytest

from matremap.cli import main
from matremap.core.material import Material
from matremap.core.optics import f0_from_ior
from matremap.core.scene import Scene
from matremap.errors import MatremapError
from matremap.regress import quantities as qty
from matremap.regress.parametric import k_alpha
from matremap.regress.transform import Transform, learn_transform
from matremap.sweep.executors import InlineExecutor
from matremap.sweep.grid import parse_grid
from matremap.sweep.run import SweepConfig, run_sweep
from matremap.sweep.store import SweepStore

WARD = Material.create("mitsuba06:ward", {"variant": "ward", "diffuseReflectance": 0.0})


def sweep(path, source, target, grid, fix=None, size=48):
    config = SweepConfig(source=source, target=target, fix=fix or {}, scene=Scene(resolution=size))
    run_sweep(config, parse_grid(grid, source.spec), str(path), InlineExecutor())
    return path


@pytest.fixture(scope="module")
def ward_db(tmp_path_factory):
    return sweep(
        tmp_path_factory.mktemp("db") / "w2as.sqlite",
        WARD,
        "mitsuba06:pbr",
        "alpha=0.05:0.9:8,specularReflectance=0.02:0.25:6",
        {"distribution": "as"},
    )


@pytest.fixture(scope="module")
def ward_to_as(ward_db):
    return learn_transform(ward_db)


def test_parametric_transform_reproduces_the_sweep(ward_db, ward_to_as):
    rows = SweepStore.open(ward_db).rows("ok")
    alpha = np.array([r["source"]["alpha"] for r in rows])
    rho = np.array([r["source"]["specularReflectance"] for r in rows])
    out, outside = ward_to_as.apply({"alpha": alpha, "specularReflectance": rho})
    fitted_alpha = np.array([r["target"]["alpha"] for r in rows])
    fitted_f0 = np.array([r["target"]["F0"] for r in rows])
    assert np.max(np.abs(out["alpha"] - fitted_alpha)) < 0.01 * np.ptp(fitted_alpha)
    assert np.max(np.abs(out["F0"] - fitted_f0)) < 0.01 * np.ptp(fitted_f0)
    assert not outside.any()
    assert set(out) == {"alpha", "F0", "specularReflectance", "diffuseReflectance"}
    for q in ("roughness", "reflectance"):
        assert ward_to_as.errors[q]["heldout_rmse"] < 0.01 * np.ptp(
            ward_to_as.domain[q] if q == "roughness" else fitted_f0
        )


def test_reflectance_follows_k_alpha_times_rho(ward_to_as):
    m = ward_to_as.mappings["reflectance"]
    alpha = np.array([0.1, 0.5])
    out, _ = ward_to_as.apply({"alpha": alpha, "specularReflectance": np.array([[0.1, 0.05, 0.02]] * 2)})
    k = k_alpha(alpha, np.array(m["coef"]))
    np.testing.assert_allclose(out["F0"], k[:, None] * [0.1, 0.05, 0.02], rtol=1e-12)
    # hue is preserved exactly: every channel is scaled by the same k
    ratios = out["F0"] / np.array([0.1, 0.05, 0.02])
    np.testing.assert_allclose(ratios, ratios[:, :1].repeat(3, axis=1), rtol=1e-12)


def test_apply_is_vectorised_over_any_shape(ward_to_as):
    rng = np.random.default_rng(1)
    alpha = rng.uniform(0.1, 0.8, (4, 5))
    rho = rng.uniform(0.03, 0.2, (4, 5, 3))
    out, outside = ward_to_as.apply({"alpha": alpha, "specularReflectance": rho})
    assert out["alpha"].shape == (4, 5) and out["F0"].shape == (4, 5, 3) and outside.shape == (4, 5)
    one, _ = ward_to_as.apply({"alpha": alpha[2, 3], "specularReflectance": rho[2, 3]})
    np.testing.assert_allclose(one["F0"], out["F0"][2, 3])


def test_inputs_outside_the_training_domain_are_flagged(ward_to_as):
    _, outside = ward_to_as.apply(
        {"alpha": np.array([0.3, 0.99, 0.3]), "specularReflectance": np.array([[0.1] * 3, [0.1] * 3, [0.1, 0.1, 0.6]])}
    )
    assert outside.tolist() == [False, True, True]


def test_nan_inputs_are_refused(ward_to_as):
    with pytest.raises(MatremapError, match="NaN"):
        ward_to_as.apply({"alpha": np.array([0.3, np.nan]), "specularReflectance": np.array([0.1, 0.1])})


def test_json_round_trip_and_validation(ward_to_as, tmp_path):
    path = ward_to_as.save(tmp_path / "t.json")
    again = Transform.load(path)
    x = {"alpha": np.array([0.2, 0.6]), "specularReflectance": np.array([0.05, 0.2])}
    np.testing.assert_array_equal(again.apply(x)[0]["F0"], ward_to_as.apply(x)[0]["F0"])
    doc = json.loads(path.read_text())
    assert doc["provenance"]["sweep"]["target"]["model"] == "mitsuba06:pbr"
    doc.pop("checksum")  # the schema's own checks (the checksum's are in test_schemas.py)
    for broken, message in (
        ({**doc, "schema": "other/9"}, "schema"),
        ({**doc, "method": "pickle"}, "method"),
        ({k: v for k, v in doc.items() if k != "template"}, "'template' must be a JSON object"),
        ({**doc, "mappings": {"sheen": {"kind": "constant"}}}, "unknown quantity 'sheen'"),
        ({**doc, "target": {"model": "mitsuba06:nope"}}, "unknown model"),
    ):
        with pytest.raises(MatremapError, match=message):
            Transform.from_dict(broken)
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(MatremapError, match="not valid JSON"):
        Transform.load(tmp_path / "bad.json")


def test_reverse_and_chain_make_a_round_trip(ward_db, ward_to_as):
    back = learn_transform(ward_db, reverse=True)
    assert (back.source, back.target) == ("mitsuba06:pbr", "mitsuba06:ward")
    assert back.target_options == {"variant": "ward"}
    round_trip = Transform.chain([ward_to_as, back])
    alpha = np.array([0.2, 0.4, 0.7])
    out, outside = round_trip.apply({"alpha": alpha, "specularReflectance": np.array([0.05, 0.1, 0.2])})
    np.testing.assert_allclose(out["alpha"], alpha, rtol=0.01)
    np.testing.assert_allclose(out["specularReflectance"][:, 0], [0.05, 0.1, 0.2], rtol=0.03)
    with pytest.raises(MatremapError, match="must link up"):
        Transform.chain([ward_to_as, ward_to_as])


def test_f0_and_ior_change_of_variable(tmp_path):
    """A plastic's intIOR is read as F0 by eq. (1) and written back as an IOR."""
    spec = Material.create("mitsuba06:roughplastic").spec
    values = {p.name: np.asarray(Material.create(spec.id).values[p.name]) for p in spec.params}
    values["intIOR"] = np.array([1.5])
    q = qty.read(spec, {k: (v[0] if v.size == 1 else v) for k, v in values.items()})
    f0 = f0_from_ior(1.5 / 1.000277)
    np.testing.assert_allclose(q["reflectance"], [f0] * 3)
    written = qty.write(spec, {"reflectance": q["reflectance"]}, Material.create(spec.id).to_dict()["params"])
    assert written["intIOR"] == pytest.approx(1.5, rel=1e-9)
    conductor = Material.create("mitsuba06:roughconductor").spec
    template = Material.create(conductor.id, {"eta": 1.0}).to_dict()["params"]
    w = qty.write(conductor, {"reflectance": np.array([0.9, 0.5, 0.1])}, template)
    np.testing.assert_allclose(f0_from_ior(w["eta"] / 1.000277, w["k"] / 1.000277), [0.9, 0.5, 0.1], rtol=1e-9)


def test_too_little_or_failed_data_is_refused(tmp_path):
    tiny = sweep(
        tmp_path / "tiny.sqlite",
        WARD,
        "mitsuba06:pbr",
        "alpha=0.1:0.3:2,specularReflectance=0.1:0.2:2",
        {"distribution": "as"},
    )
    with pytest.raises(MatremapError, match="too few"):
        learn_transform(tiny)
    flat = sweep(
        tmp_path / "flat.sqlite",
        WARD.with_params({"alpha": 0.2}),
        "mitsuba06:pbr",
        "diffuseReflectance=0:0:1,variant=ward",
        {"distribution": "as"},
    )
    with pytest.raises(MatremapError, match="too few|nothing to learn"):
        learn_transform(flat)
    failed = tmp_path / "failed.sqlite"
    with SweepStore.create_or_open(failed, {"x": 1}) as store:
        store.add([{"key": "a", "swept": {}, "source": {}, "status": "failed", "finished": 0.0}])
    with pytest.raises(MatremapError, match="no successful fits"):
        learn_transform(failed)


def test_cli_learn_chain_apply(ward_db, tmp_path, capsys):
    t1, t2, chained = tmp_path / "a.json", tmp_path / "b.json", tmp_path / "ab.json"
    assert main(["learn", str(ward_db), "-o", str(t1)]) == 0
    assert main(["learn", str(ward_db), "--reverse", "-o", str(t2)]) == 0
    assert main(["chain", str(t1), str(t2), "-o", str(chained)]) == 0
    capsys.readouterr()
    assert (
        main(
            [
                "apply",
                str(chained),
                "--source",
                "mitsuba06:ward,variant=ward,alpha=0.3,specularReflectance=0.1,diffuseReflectance=0",
                "--json",
            ]
        )
        == 0
    )
    record = json.loads(capsys.readouterr().out)
    assert record["model"] == "mitsuba06:ward" and record["params"]["alpha"] == pytest.approx(0.3, rel=0.01)
    assert record["outside_domain"] is False
    # bad input: exit 2, nothing written
    out = tmp_path / "never.json"
    assert main(["chain", str(t1), str(t1), "-o", str(out)]) == 2
    assert main(["learn", str(tmp_path / "missing.sqlite"), "-o", str(out)]) == 2
    assert main(["learn", str(ward_db), "-o", str(t1)]) == 2  # exists, no --force
    assert not out.exists()
    assert "--force" in capsys.readouterr().err


def test_chunked_apply_equals_one_pass(ward_to_as, monkeypatch):
    import matremap.regress.transform as transform_module

    rng = np.random.default_rng(3)
    values = {
        "alpha": rng.uniform(0.1, 0.8, (37, 29)).astype(np.float32),
        "specularReflectance": rng.uniform(0.03, 0.2, (37, 29, 3)).astype(np.float32),
    }
    whole, outside = ward_to_as.apply(values)
    monkeypatch.setattr(transform_module, "CHUNK", 100)
    chunked, outside_chunked = ward_to_as.apply(values)
    assert set(chunked) == set(whole)
    for k in whole:
        np.testing.assert_array_equal(chunked[k], whole[k])
    np.testing.assert_array_equal(outside_chunked, outside)
    assert chunked["F0"].dtype == np.float32


def test_uniform_inputs_stay_views_and_equal_full_maps(ward_to_as, monkeypatch):
    """A constant map (a broadcast) is evaluated once and stays a view; results equal a real map of
    that value, and an outside-domain texel is still flagged in the chunked path."""
    import matremap.regress.transform as transform_module

    monkeypatch.setattr(transform_module, "CHUNK", 64)
    rng = np.random.default_rng(4)
    alpha = rng.uniform(0.1, 0.8, (20, 30))
    alpha[3, 4] = 0.99  # outside the training domain
    rho = np.broadcast_to(np.array([0.05, 0.1, 0.15]), (20, 30, 3))
    as_view, outside_view = ward_to_as.apply({"alpha": alpha, "specularReflectance": rho})
    as_map, outside_map = ward_to_as.apply({"alpha": alpha, "specularReflectance": np.array(rho)})
    for k in as_map:
        np.testing.assert_allclose(as_view[k], as_map[k], rtol=1e-12)
    np.testing.assert_array_equal(outside_view, outside_map)
    assert outside_view.sum() == 1 and outside_view[3, 4]
    flat, _ = ward_to_as.apply({"alpha": np.broadcast_to(0.3, (20, 30)), "specularReflectance": rho})
    assert flat["F0"].strides[:2] == (0, 0)  # computed once, no memory per texel


def test_learner_table_and_holdout_split():
    from matremap.regress.data import holdout_split
    from matremap.regress.learners import LEARNERS, get_learner
    from matremap.regress.transform import METHODS

    assert set(LEARNERS) == {"parametric", "svr"} and METHODS == (*LEARNERS, "chain")
    with pytest.raises(MatremapError, match="unknown method 'ridge'; choose parametric or svr"):
        get_learner("ridge")
    with pytest.raises(MatremapError, match="unknown method 'ridge'"):
        learn_transform("never-read.sqlite", method="ridge")  # refused before the database is opened
    train, held = holdout_split(10, 0.2, seed=3)
    assert len(held) == 2 and sorted([*train, *held]) == list(range(10))
    np.testing.assert_array_equal(holdout_split(10, 0.2, seed=3)[1], held)
    assert len(holdout_split(3, 0.01, seed=0)[1]) == 1  # at least one point held out


def test_a_constant_beside_a_map_takes_the_maps_shape():
    """A uniform roughness next to a specular map used to crash apply (non-broadcastable output) on four
    public glTF assets."""
    from matremap.regress.library import LIBRARY_DIR

    t = Transform.load(LIBRARY_DIR / "ward-as.json")
    spec_map = np.random.default_rng(0).uniform(0.05, 0.15, (8, 6, 3))
    out, outside = t.apply({"alpha": np.float64(0.2), "specularReflectance": spec_map, "diffuseReflectance": 0.0})
    assert outside.shape == (8, 6) and out["alpha"].shape in ((8, 6), ())
    one, _ = t.apply({"alpha": np.full((8, 6), 0.2), "specularReflectance": spec_map, "diffuseReflectance": 0.0})
    np.testing.assert_allclose(np.broadcast_to(out["F0"], one["F0"].shape), one["F0"])


def test_a_quantity_read_only_by_scales_through_the_origin_answers_down_to_zero():
    """A black albedo is black in every renderer, so a diffuse mapped by a scale through the origin is exact at
    0 even when the sweep's darkest point was not used (a red texture's black channels counted as outside); so is
    the F0 a k_alpha mapping scales, k(alpha) * F0 (SheenChair's peacock velvet, a metal of base colour
    (0, 0.094, 0.099), read wholly outside)."""
    from matremap.regress.transform import training_domain

    x = {
        "diffuse": np.array([[0.12] * 3, [0.8] * 3]),
        "roughness": np.array([0.2, 0.6]),
        "reflectance": np.array([[0.05] * 3, [0.5] * 3]),
    }
    mappings = {
        "diffuse": {"kind": "scale", "input": "diffuse", "coef": [1.0, 1.0, 1.0]},
        "reflectance": {"kind": "k_alpha", "input": "reflectance", "coef": [1.0, 0.0, 0.0, 0.0, 0.0]},
        "roughness": {"kind": "poly", "input": "roughness", "coef": [0.0, 1.0]},
    }
    domain = training_domain(x, mappings)
    assert domain["diffuse"] == [0.0, 0.8]
    assert domain["reflectance"] == [0.0, 0.5]  # k(alpha) * F0: through the origin at every alpha
    assert domain["roughness"] == [0.2, 0.6]  # k's argument: kept as trained
    mappings["diffuse"] = {"kind": "poly", "input": "diffuse", "coef": [0.1, 1.0]}  # an offset: not through 0
    assert training_domain(x, mappings)["diffuse"] == [0.12, 0.8]
    assert domain["roughness"] == [0.2, 0.6]


def test_too_few_points_say_how_many_the_sweep_left_out():
    """A sweep whose fits are poor (UsdPreviewSurface at roughness 1 onto roughplastic: 7 of 8 fits at relative error
    0.61, left out as loss outliers) said only "1 usable points: too few to learn a transform"; it says why."""
    import numpy as np

    from matremap.dialects import get_model
    from matremap.regress.data import TrainingData
    from matremap.regress.parametric import learn

    spec = get_model("gltf:metal-rough")
    x = {"diffuse": np.full((1, 3), 0.5)}
    data = TrainingData(spec, spec, {}, {}, x, dict(x), {}, {"rows": 8, "used": 1, "excluded_flagged": 7}, {})
    with pytest.raises(MatremapError) as e:
        learn(data)
    msg = str(e.value)
    assert "1 usable points" in msg and "7 of its 8 fits were left out" in msg and "\n" not in msg
