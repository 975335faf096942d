"""Stability analysis, sweep report (plots, summary) and export, on small sweeps run in-process."""

from __future__ import annotations

import copy
import csv
import sys

import numpy as np
import pytest

from matremap.core.material import Material
from matremap.dialects import get_model
from matremap.errors import MatremapError
from matremap.sweep.executors import InlineExecutor
from matremap.sweep.grid import Grid, parse_grid
from matremap.sweep.report import export_table, round_trip_stats, write_report
from matremap.sweep.run import SweepConfig, run_sweep
from matremap.sweep.stability import analyse, line_jumps
from matremap.sweep.store import SweepStore, point_key

PLOTS = ("specular.png", "roughness.png", "loss.png", "roundtrip.png")


def make_sweep(path, source, target, fix, grid, round_trip=False):
    material = Material.create(*source)
    config = SweepConfig(source=material, target=target, fix=fix, round_trip=round_trip)
    summary = run_sweep(config, parse_grid(grid, material.spec), str(path), InlineExecutor())
    assert summary.failed == 0
    return path


@pytest.fixture(scope="module")
def ward_db(tmp_path_factory):
    """Ward -> the authors' AS model, 6 x 5, with round trip: smooth and well behaved."""
    return make_sweep(
        tmp_path_factory.mktemp("ward") / "ward2as.sqlite",
        ("mitsuba06:ward", {"variant": "ward", "diffuseReflectance": 0}),
        "mitsuba06:pbr",
        {"distribution": "as"},
        "alpha=0.05:0.6:6,specularReflectance=0.02:0.2:5",
        round_trip=True,
    )


@pytest.fixture(scope="module")
def conductor_db(tmp_path_factory):
    """Rough conductor (eta 1, so F0 = k^2 / (4 + k^2)) -> Ward, round trip: large k needs Ward rho_s > 1."""
    return make_sweep(
        tmp_path_factory.mktemp("conductor") / "as2ward.sqlite",
        ("mitsuba06:roughconductor", {"distribution": "as", "eta": 1}),
        "mitsuba06:ward",
        {"variant": "ward"},
        "alpha=0.05:0.4:5,k=0.3:4:6",
        round_trip=True,
    )


def load(db):
    with SweepStore.open(db) as store:
        return store.rows(), store.grid, store.config


def key_at(grid, index):
    return point_key(Grid.from_dict(grid).values_at(index))


# ---------------------------------------------------------------------------------------------
# Flag rules


def test_smooth_sweep_has_no_flags(ward_db):
    rows, grid, config = load(ward_db)
    a = analyse(rows, grid, config)
    assert len(a.index) == 30 and not a.off_grid
    assert a.tested == ("alpha", "F0", "diffuseReflectance")  # specularReflectance is held, not fitted
    # diffuseReflectance sits at its lower bound 0, but was set (black source part), not optimised
    assert a.counts == {} and a.flagged_keys == []


@pytest.mark.parametrize(
    ("index", "param", "factor"),
    [
        ((2, 2), "alpha", 1.15),
        ((3, 1), "F0", 0.8),
        ((0, 2), "alpha", 0.85),
        ((5, 4), "F0", 1.3),
    ],
)
def test_a_corrupted_value_is_flagged_as_a_jump_and_only_there(ward_db, index, param, factor):
    rows, grid, config = load(ward_db)
    key = key_at(grid, index)
    bad = copy.deepcopy(rows)
    row = next(r for r in bad if r["key"] == key)
    value = row["target"][param]
    row["target"][param] = [v * factor for v in value] if isinstance(value, list) else value * factor
    a = analyse(bad, grid, config)
    assert a.flags[key] == [f"jump:{param}"]
    assert a.flagged_keys == [key]


def test_line_jumps_ignores_smooth_curves_and_finds_outliers_and_steps():
    x = np.linspace(0.03, 0.99, 8)
    concave = 0.6 * x / (0.3 + x)  # like alpha2 = f(alpha1), strongly curved
    assert line_jumps(x, concave) == []
    assert line_jumps(x, x**2) == []
    assert line_jumps(x, np.sqrt(x)) == []

    outlier = concave.copy()
    outlier[4] *= 1.2
    assert [i for i, _, _ in line_jumps(x, outlier)] == [4]

    step = concave.copy()
    step[4:] += 0.1
    found = line_jumps(x, step)
    assert [(i, kind) for i, kind, _ in found] == [(3, "step"), (4, "step")]

    # missing points are closed over; lines too short are not judged
    gappy = outlier.copy()
    gappy[1] = np.nan
    assert [i for i, _, _ in line_jumps(x, gappy)] == [4]
    assert line_jumps(x[:3], [0.1, 0.9, 0.1]) == []


def test_above1_flags_where_ward_is_clamped_and_not_at_small_f0(conductor_db):
    rows, grid, config = load(conductor_db)
    a = analyse(rows, grid, config)
    above = {k for k, reasons in a.flags.items() if "above1:specularReflectance" in reasons}
    assert above, "some k values should need rho_s > 1"
    for r in rows:
        rho = max(r["target"]["specularReflectance"])
        assert (r["key"] in above) == (rho > 1.0)
    small_f0 = [r["key"] for r in rows if r["swept"]["k"] <= 1.1]  # F0 <= 0.23
    assert not any("above1:specularReflectance" in a.flags[k] for k in small_f0)
    # away from the clamped corner nothing at all is flagged
    calm = [r["key"] for r in rows if r["swept"]["k"] <= 1.8 and r["swept"]["alpha"] <= 0.32]
    assert not any(a.flags[k] for k in calm)
    assert a.counts["above1:specularReflectance"] == len(above)
    assert a.kind_counts()["above1"] == len(above)


def test_failed_bound_loss_and_off_grid_rows(ward_db):
    rows, grid, config = load(ward_db)
    rows = copy.deepcopy(rows)
    failed, at_bound, lossy = key_at(grid, (1, 1)), key_at(grid, (4, 3)), key_at(grid, (2, 3))
    for r in rows:
        if r["key"] == failed:
            r.update(status="failed", target=None, loss=None, message="RuntimeError: boom")
        elif r["key"] == at_bound:
            r["target"]["alpha"] = 1.0  # pbr's alpha range is [1e-4, 1]
        elif r["key"] == lossy:
            r["loss"] = 0.5
    off = copy.deepcopy(rows[0])
    off.update(key='{"alpha": 0.7, "specularReflectance": 0.02}', swept={"alpha": 0.7, "specularReflectance": 0.02})
    rows.append(off)
    a = analyse(rows, grid, config)
    assert a.flags[failed] == ["failed"]
    assert "bound:alpha" in a.flags[at_bound]
    assert a.flags[lossy] == ["loss"]
    assert a.off_grid == [off["key"]] and a.flags[off["key"]] == []
    assert len(a.failed_rows) == 1 and len(a.ok_rows) == 30


def test_a_roughness_at_its_bound_is_learned_from_where_the_source_is_at_its_own(ward_db):
    """Source alpha 1 (Ward's upper bound) fitted at pbr alpha 1 is the ends of the ranges meeting, not a
    stuck fit; the same target value from an interior source alpha stays flagged."""
    rows, grid, config = load(ward_db)
    rows = copy.deepcopy(rows)
    end, inner = key_at(grid, (5, 2)), key_at(grid, (4, 2))
    hi = get_model("mitsuba06:ward").param("alpha").bounds[1]
    for r in rows:
        if r["key"] in (end, inner):
            r["target"]["alpha"] = 1.0
        if r["key"] == end:
            r["source"]["alpha"] = hi
    a = analyse(rows, grid, config)
    assert not any(f.startswith("bound") for f in a.flags[end])
    assert "bound:alpha" in a.flags[inner]


def test_a_roughness_at_its_bound_fitted_closely_is_a_saturation_not_a_stuck_fit(ward_db):
    """An interior source alpha fitted at pbr's alpha 1 within LOSS_MIN (or the sweep's median loss) is the closest
    the target gets, and as close as anywhere (the mapping saturates there: a rough base under a sheen): learned
    from; the same fit further off than both stays flagged."""
    from matremap.sweep.stability import LOSS_MIN

    rows, grid, config = load(ward_db)
    rows = copy.deepcopy(rows)
    typical = max(LOSS_MIN, float(np.median([r["loss"] for r in rows])))
    close, far = key_at(grid, (4, 2)), key_at(grid, (4, 3))
    for r in rows:
        if r["key"] in (close, far):
            r["target"]["alpha"] = 1.0
            r["loss"] = 0.5 * LOSS_MIN if r["key"] == close else 3.0 * typical
    a = analyse(rows, grid, config)
    assert not any(f.startswith("bound") for f in a.flags[close])
    assert "bound:alpha" in a.flags[far]


# ---------------------------------------------------------------------------------------------
# Round trip


def test_round_trip_recovers_the_source_parameters(ward_db):
    rows, grid, _ = load(ward_db)
    stats = round_trip_stats(rows, grid)
    assert set(stats) == {"alpha", "specularReflectance"}
    for t in stats.values():
        assert t.n == 30
        assert t.slope == pytest.approx(1.0, abs=0.02)
        assert t.r2 > 0.999 and t.r2_identity > 0.999


def test_round_trip_of_a_grey_rgb_axis_is_one_entry(conductor_db):
    rows, grid, _ = load(conductor_db)
    stats = round_trip_stats(rows, grid)
    assert set(stats) == {"alpha", "k"}
    assert stats["alpha"].slope == pytest.approx(1.0, abs=0.05)


# ---------------------------------------------------------------------------------------------
# Report


def check_png(path):
    import matplotlib.image as mpimg

    img = mpimg.imread(path)
    assert img.ndim == 3 and img.shape[0] >= 300 and img.shape[1] >= 400
    rgb = np.round(img[..., :3] * 255).astype(np.int64)
    colours = np.unique(rgb[..., 0] * 65536 + rgb[..., 1] * 256 + rgb[..., 2])
    assert colours.size > 50  # drawn, not blank
    assert np.count_nonzero(np.any(rgb != rgb[0, 0], axis=-1)) > 0.02 * rgb[..., 0].size


def test_report_writes_the_plots_and_a_summary(ward_db, tmp_path):
    out = tmp_path / "report" / "nested"
    text = write_report(ward_db, out)
    for name in PLOTS:
        check_png(out / name)
    assert sorted(p.name for p in out.iterdir()) == sorted(PLOTS)  # no temporary files left
    assert "points: 30 ok, 0 failed" in text
    assert "flagged: none" in text
    assert "loss (relative RMSE): median" in text and "renders" in text and "warm-started: 0 of 30" in text
    assert "slope 1.0" in text or "slope 0.99" in text
    assert "least-squares line with intercept" in text
    assert all(str(out / name) in text for name in PLOTS)


def test_report_counts_flags(conductor_db, tmp_path):
    text = write_report(conductor_db, tmp_path)
    assert "above1:specularReflectance" in text
    for name in PLOTS:
        check_png(tmp_path / name)


def test_report_does_not_overwrite_without_force(ward_db, tmp_path):
    (tmp_path / "loss.png").write_bytes(b"mine")
    (tmp_path / "other.png").write_bytes(b"not ours")
    with pytest.raises(MatremapError, match=r"loss\.png already exists; pass --force"):
        write_report(ward_db, tmp_path)
    assert (tmp_path / "loss.png").read_bytes() == b"mine"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["loss.png", "other.png"]  # nothing written
    write_report(ward_db, tmp_path, force=True)
    check_png(tmp_path / "loss.png")
    assert (tmp_path / "other.png").read_bytes() == b"not ours"
    with pytest.raises(MatremapError, match=r"specular\.png, .*roundtrip\.png already exist; pass --force"):
        write_report(ward_db, tmp_path)


def test_report_on_a_one_dimensional_grid(tmp_path):
    db = make_sweep(
        tmp_path / "line.sqlite",
        ("mitsuba06:ward", {"variant": "ward", "diffuseReflectance": 0}),
        "mitsuba06:pbr",
        {"distribution": "as"},
        "alpha=0.05:0.5:5",
    )
    text = write_report(db, tmp_path / "out")
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["loss.png", "roughness.png"]
    assert "specular.png skipped" in text
    check_png(tmp_path / "out" / "loss.png")


def test_not_a_database_gives_a_matremap_error(tmp_path):
    bogus = tmp_path / "notes.sqlite"
    bogus.write_text("this is not a database\n" * 100)
    with pytest.raises(MatremapError):
        write_report(bogus, tmp_path / "out")
    with pytest.raises(MatremapError):
        export_table(bogus, tmp_path / "t.csv")
    with pytest.raises(MatremapError, match="not found"):
        write_report(tmp_path / "missing.sqlite", tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_any_parameter_at_its_bound_fitted_closely_is_learned_from(ward_db):
    """Not only a roughness: an F0 at its upper bound (or a rough plastic's coat IOR at 1, its coat turned off to draw
    a roughness-1 specular as diffuse: the usd-wg TextureCoordinateTest, whose brightest grid point was excluded and
    58 % of its texels then fell outside the learned domain) fitted within LOSS_MIN is the closest the target gets;
    the same fit further off than the sweep's typical one stays flagged."""
    from matremap.sweep.stability import LOSS_MIN

    rows, grid, config = load(ward_db)
    rows = copy.deepcopy(rows)
    typical = max(LOSS_MIN, float(np.median([r["loss"] for r in rows])))
    close, far = key_at(grid, (2, 2)), key_at(grid, (2, 3))
    hi = get_model("mitsuba06:pbr").param("F0").bounds[1]
    for r in rows:
        if r["key"] in (close, far):
            r["target"]["F0"] = [hi] * 3
            r["loss"] = 0.5 * LOSS_MIN if r["key"] == close else 3.0 * typical
    a = analyse(rows, grid, config)
    assert not any(f.startswith("bound") for f in a.flags[close])
    assert "bound:F0" in a.flags[far]


# ---------------------------------------------------------------------------------------------
# Export

REQUIRED = [
    "source.variant",
    "source.alpha",
    "source.specularReflectance.r",
    "source.specularReflectance.g",
    "source.specularReflectance.b",
    "target.distribution",
    "target.alpha",
    "target.F0.r",
    "target.F0.g",
    "target.F0.b",
    "back.alpha",
    "back.specularReflectance.r",
    "back_loss",
    "loss",
    "renders",
    "seconds",
    "status",
    "flagged",
    "flags",
]


def test_export_csv(ward_db, tmp_path):
    path = tmp_path / "table.csv"
    assert export_table(ward_db, path) == 30
    with path.open(newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 30
    assert set(REQUIRED) <= set(rows[0])
    rows_db, _, _ = load(ward_db)
    by_alpha = {(r["swept"]["alpha"], r["swept"]["specularReflectance"]): r for r in rows_db}
    for row in rows:
        src = by_alpha[(float(row["source.alpha"]), float(row["source.specularReflectance.r"]))]
        assert float(row["target.F0.g"]) == src["target"]["F0"][1]  # exact (repr) floats
        assert row["status"] == "ok" and row["flagged"] == "False" and row["flags"] == ""
        assert row["target.distribution"] == "as"


def test_export_parquet(conductor_db, tmp_path):
    pq = pytest.importorskip("pyarrow.parquet")
    path = tmp_path / "table.parquet"
    assert export_table(conductor_db, path) == 30
    t = pq.read_table(path)
    assert t.num_rows == 30
    names = set(t.column_names)
    assert {
        "source.k.r",
        "target.specularReflectance.b",
        "target.variant",
        "back.k.g",
        "back_loss",
        "loss",
        "renders",
        "seconds",
        "status",
        "flagged",
        "flags",
    } <= names
    flagged = t.column("flagged").to_pylist()
    flags = t.column("flags").to_pylist()
    assert any(flagged) and all(bool(f) == g for f, g in zip(flags, flagged, strict=True))
    assert any("above1:specularReflectance" in f for f in flags)


def test_export_refuses_unknown_types_and_explains_missing_pyarrow(ward_db, tmp_path, monkeypatch):
    with pytest.raises(MatremapError, match="use .csv or .parquet"):
        export_table(ward_db, tmp_path / "table.xlsx")
    monkeypatch.setitem(sys.modules, "pyarrow", None)
    with pytest.raises(MatremapError, match="pip install pyarrow"):
        export_table(ward_db, tmp_path / "table.parquet")
    assert not (tmp_path / "table.parquet").exists()


def test_cli_sweep_report_and_export(ward_db, tmp_path, capsys):
    from matremap.cli import main

    assert main(["sweep-report", str(ward_db), "-o", str(tmp_path / "r")]) == 0
    assert "points: 30 ok" in capsys.readouterr().out
    assert main(["sweep-report", str(ward_db), "-o", str(tmp_path / "r")]) == 2
    assert "--force" in capsys.readouterr().err
    assert main(["export", str(ward_db), "-o", str(tmp_path / "t.csv")]) == 0
    assert "30 rows" in capsys.readouterr().err


def test_a_sweep_whose_every_fit_found_no_match_is_flagged_and_not_learned_from(ward_db, tmp_path):
    """Every fit at loss 1 (a source part drawn black, say: Mitsuba 3 principled onto UsdPreviewSurface) has no
    outlier, so the robust z-score flagged none and a constant transform was learned from them."""
    import shutil

    from matremap.regress.data import load_training_data

    rows, grid, config = load(ward_db)
    rows = copy.deepcopy(rows)
    for r in rows:
        r["loss"] = 1.0
    a = analyse(rows, grid, config)
    assert all("loss" in a.flags[r["key"]] for r in rows)
    db = tmp_path / "lost.sqlite"
    shutil.copyfile(ward_db, db)
    import sqlite3

    with sqlite3.connect(db) as con:
        con.execute("UPDATE points SET loss = 1.0")
    with pytest.raises(MatremapError, match="every fit of the sweep found no match"):
        load_training_data(db)


def test_no_match_is_judged_on_the_objectives_own_scale(ward_db):
    """A loss of 0.6 is 'no match' as a relative RMSE, but a poor match as 1 - SSIM (a pure-specular Ward as AS
    under the mixed probe reads 0.48-0.62, and dropping those rows left a sweep without its diffuse axis)."""
    rows, grid, config = load(ward_db)
    key = key_at(grid, (2, 2))
    bad = copy.deepcopy(rows)
    next(r for r in bad if r["key"] == key)["loss"] = 0.6
    assert "loss" in analyse(bad, grid, config).flags[key]
    ssim = {**config, "objective": "ssim"}
    assert not any("above" in d for d in analyse(bad, grid, ssim).details[key])
    next(r for r in bad if r["key"] == key)["loss"] = 0.95
    assert any("above 0.9" in d for d in analyse(bad, grid, ssim).details[key])
