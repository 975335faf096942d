import signal
import sqlite3
import subprocess
import sys
import time

import numpy as np
import pytest

from matremap.cli import main
from matremap.core.material import Material
from matremap.dialects import get_model
from matremap.errors import MatremapError
from matremap.sweep.executors import InlineExecutor, make_executor
from matremap.sweep.grid import parse_grid
from matremap.sweep.run import SweepConfig, run_sweep
from matremap.sweep.store import SweepStore

SOURCE = Material.create("mitsuba06:ward", {"variant": "ward", "diffuseReflectance": 0.0})
GRID = "alpha=0.05:0.8:4,specularReflectance=0.02:0.2:3"


def config(**kw):
    base = dict(source=SOURCE, target="mitsuba06:pbr", fix={"distribution": "as"}, scene=None)
    base.update(kw)
    if base["scene"] is None:
        from matremap.core.scene import Scene

        base["scene"] = Scene(resolution=48)
    return SweepConfig(**base)


def table(db):
    with sqlite3.connect(db) as c:
        return sorted(c.execute("SELECT key, target, loss, renders, status FROM points").fetchall())


# -- grids ---------------------------------------------------------------------------------------
def test_grid_forms_and_cartesian_order():
    spec = get_model("mitsuba06:ward")
    g = parse_grid("alpha=0.1:0.3:3, specularReflectance=0.01:1:3:log, variant=ward;balanced", spec)
    assert g.shape == (3, 3, 2) and len(g) == 18
    assert g.axes[1].values == pytest.approx((0.01, 0.1, 1.0))
    first = g.material(SOURCE, (0, 0, 1))
    assert first.options["variant"] == "balanced" and first.values["alpha"][0] == pytest.approx(0.1)
    per_channel = parse_grid("diffuseReflectance.g=0:1:2", spec)
    m = per_channel.material(Material.create("mitsuba06:ward", {"diffuseReflectance": 0.5}), (1,))
    np.testing.assert_array_equal(m.values["diffuseReflectance"], [0.5, 1.0, 0.5])


def test_grid_from_toml(tmp_path):
    f = tmp_path / "grid.toml"
    f.write_text('[grid]\nalpha = { start = 0.1, stop = 0.5, count = 5, spacing = "log" }\nvariant = ["ward"]\n')
    g = parse_grid(str(f), get_model("mitsuba06:ward"))
    assert g.shape == (5, 1) and g.axes[0].values[-1] == pytest.approx(0.5)


@pytest.mark.parametrize(
    "text, message",
    [
        ("alpha=0.1:0.5", "LO:HI:COUNT"),
        ("alpha=0.1:0.1:3", "empty range"),
        ("alpha=0.1:0.5:0", "at least 1"),
        ("alpha=0:0.5:3:log", "positive bounds"),
        ("shininess=1:2:3", "has no parameter 'shininess'"),
        ("alpha=0.1:9:3", "outside the range"),
        ("alpha=a:b:3", "not a number"),
        ("variant=phong", "not one of"),
        ("alpha.r=0.1:0.2:2", "only RGB parameters"),
        ("alpha=0.1:0.2:2,alpha=0.3;0.4", "given twice"),
        ("", "no parameter to sweep"),
    ],
)
def test_malformed_grids_are_refused(text, message):
    with pytest.raises(MatremapError, match=message):
        parse_grid(text, get_model("mitsuba06:ward"))


# -- running, resuming, executors ----------------------------------------------------------------
def test_sweep_fills_the_database_and_resumes_without_duplicates(tmp_path):
    db = tmp_path / "s.sqlite"
    grid = parse_grid(GRID, SOURCE.spec)
    s1 = run_sweep(config(), grid, str(db), InlineExecutor())
    assert (s1.done, s1.skipped, s1.failed) == (12, 0, 0)
    s2 = run_sweep(config(), grid, str(db), InlineExecutor())
    assert (s2.done, s2.skipped) == (0, 12)
    bigger = parse_grid("alpha=0.05:0.8:4,specularReflectance=0.02:0.2:5", SOURCE.spec)
    s3 = run_sweep(config(), bigger, str(db), InlineExecutor())
    assert s3.skipped == 12 and s3.done == 8  # the shared ρs values 0.02, 0.11 and 0.2 are reused
    rows = SweepStore.open(db).rows()
    assert len(rows) == len({r["key"] for r in rows}) == 20
    ok = rows[0]
    assert ok["status"] == "ok" and ok["renders"] > 0 and ok["seconds"] > 0 and ok["target"]["distribution"] == "as"


def test_a_database_with_another_configuration_is_refused(tmp_path):
    db = tmp_path / "s.sqlite"
    grid = parse_grid("alpha=0.1:0.2:2", SOURCE.spec)
    run_sweep(config(), grid, str(db), InlineExecutor())
    before = db.read_bytes()
    with pytest.raises(MatremapError, match="different configuration .*strategy"):
        run_sweep(config(strategy="simple"), grid, str(db), InlineExecutor())
    from matremap.core.scene import Scene

    with pytest.raises(MatremapError, match="scene.resolution"):
        run_sweep(config(scene=Scene(resolution=64)), grid, str(db), InlineExecutor())
    assert db.read_bytes() == before


def test_rows_are_identical_with_one_worker_a_pool_and_dask(tmp_path):
    pytest.importorskip("distributed")
    grid = parse_grid(GRID, SOURCE.spec)
    tables = []
    for name, kw in (("inline", {"workers": 1}), ("pool", {"workers": 2}), ("dask", {"dask_local": 2})):
        db = tmp_path / f"{name}.sqlite"
        with make_executor(**kw) as (ex, _):
            summary = run_sweep(config(), grid, str(db), ex)
        assert summary.done == 12
        tables.append(table(db))
    assert tables[0] == tables[1] == tables[2]


def test_continuation_warm_starts_and_saves_renders(tmp_path):
    grid = parse_grid("alpha=0.1:0.6:2,specularReflectance=0.02:0.2:6", SOURCE.spec)
    run_sweep(config(), grid, str(tmp_path / "cold.sqlite"), InlineExecutor())
    run_sweep(config(continuation=True), grid, str(tmp_path / "warm.sqlite"), InlineExecutor())
    cold = SweepStore.open(tmp_path / "cold.sqlite").rows()
    warm = SweepStore.open(tmp_path / "warm.sqlite").rows()
    assert sum(r["warm"] for r in warm) == 10  # all but the first point of each line
    assert np.mean([r["renders"] for r in warm]) < np.mean([r["renders"] for r in cold])
    by_key = {r["key"]: r for r in cold}
    for r in warm:
        c = by_key[r["key"]]
        assert r["target"]["alpha"] == pytest.approx(c["target"]["alpha"], rel=2e-3)


def test_round_trip_fits_back_onto_the_source_model(tmp_path):
    grid = parse_grid("alpha=0.1:0.3:2", SOURCE.spec)
    run_sweep(
        config(round_trip=True, source=SOURCE.with_params({"specularReflectance": 0.1})),
        grid,
        str(tmp_path / "rt.sqlite"),
        InlineExecutor(),
    )
    for r in SweepStore.open(tmp_path / "rt.sqlite").rows():
        assert r["back"]["alpha"] == pytest.approx(r["source"]["alpha"], rel=5e-3)
        assert r["back"]["variant"] == "ward"


def test_a_failing_point_is_recorded_and_the_sweep_goes_on(tmp_path):
    # Blender's specular_color cannot exceed 1: fitting a bright Ward lobe hits the bound but does not
    # fail; a failure comes from a renderer error, simulated with a model the target renderer lacks
    import matremap.sweep.run as sweep_mod

    grid = parse_grid("alpha=0.1:0.2:2", SOURCE.spec)
    real_fit = sweep_mod.fit_steps
    calls = []

    def flaky(*a, **kw):
        calls.append(1)
        if len(calls) == 1:
            raise RuntimeError("renderer crashed")
        return real_fit(*a, **kw)

    sweep_mod.fit_steps = flaky
    try:
        s = run_sweep(config(), grid, str(tmp_path / "f.sqlite"), InlineExecutor())
    finally:
        sweep_mod.fit_steps = real_fit
    assert (s.done, s.failed) == (2, 1)
    failed = SweepStore.open(tmp_path / "f.sqlite").rows("failed")
    assert "renderer crashed" in failed[0]["message"]


# -- the command line, interruption, crashes -----------------------------------------------------
SWEEP_ARGS = [
    "sweep",
    "--source",
    "mitsuba06:ward,variant=ward,diffuseReflectance=0",
    "--to",
    "mitsuba06:pbr",
    "--fix",
    "distribution=as",
    "--size",
    "48",
    "--no-progress",
]


def test_cli_sweep_and_resume(tmp_path, capsys):
    db = tmp_path / "c.sqlite"
    assert main(SWEEP_ARGS + ["--grid", GRID, "--db", str(db), "--workers", "1"]) == 0
    assert "12 points fitted" in capsys.readouterr().err
    assert main(SWEEP_ARGS + ["--grid", GRID, "--db", str(db), "--workers", "1"]) == 0
    assert "12 already in the database" in capsys.readouterr().err


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--grid", "alpha=0.1:0.5", "--db", "{db}"], "LO:HI:COUNT"),
        (["--grid", "alpha=0.2:0.2:4", "--db", "{db}"], "empty range"),
        (["--grid", "roughness=0.1:0.5:3", "--db", "{db}"], "has no parameter"),
        (["--grid", GRID, "--db", "{db}", "--scheduler", "tcp://127.0.0.1:9"], "cannot reach the Dask scheduler"),
        (["--grid", GRID, "--db", "/nonexistent/folder/s.sqlite"], "does not exist"),
        (["--grid", GRID, "--db", "{db}", "--strategy", "simple"], "different configuration"),
    ],
)
def test_cli_bad_sweep_input_leaves_the_database_untouched(tmp_path, capsys, extra, message):
    db = tmp_path / "keep.sqlite"
    assert main(SWEEP_ARGS + ["--grid", "alpha=0.1:0.2:2", "--db", str(db), "--workers", "1"]) == 0
    before = db.read_bytes()
    capsys.readouterr()
    code = main(SWEEP_ARGS + [a.format(db=db) for a in extra] + ["--workers", "1"])
    err = capsys.readouterr().err
    assert code == 2 and message in err, err
    assert db.read_bytes() == before


def _start_cli_sweep(db, grid, workers=1):
    return subprocess.Popen(
        [
            sys.executable,
            "-m",
            "matremap.cli",
            *SWEEP_ARGS[:-1],
            "--grid",
            grid,
            "--db",
            str(db),
            "--workers",
            str(workers),
            "--no-progress",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _wait_for_rows(db, n, proc, timeout=60):
    t0 = time.time()
    while time.time() - t0 < timeout:
        if db.exists():
            try:
                with sqlite3.connect(db) as c:
                    if c.execute("SELECT COUNT(*) FROM points").fetchone()[0] >= n:
                        return
            except sqlite3.Error:
                pass
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.05)
    raise AssertionError("sweep made no progress")


BIG = "alpha=0.05:0.9:40,specularReflectance=0.02:0.2:5"


def test_sigkill_mid_sweep_leaves_a_valid_database_that_resumes(tmp_path):
    db = tmp_path / "k.sqlite"
    proc = _start_cli_sweep(db, BIG)
    _wait_for_rows(db, 10, proc)
    proc.kill()
    proc.wait()
    with sqlite3.connect(db) as c:
        assert c.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
        saved = c.execute("SELECT COUNT(*) FROM points").fetchone()[0]
    assert 10 <= saved < 200
    small = "alpha=0.05:0.9:40,specularReflectance=0.02:0.2:5"
    s = run_sweep(config(scene=None), parse_grid(small, SOURCE.spec), str(db), InlineExecutor())
    assert s.skipped == saved and s.skipped + s.done == 200
    rows = SweepStore.open(db).rows()
    assert len(rows) == len({r["key"] for r in rows}) == 200


def test_ctrl_c_stops_cleanly_and_keeps_finished_points(tmp_path):
    db = tmp_path / "i.sqlite"
    proc = _start_cli_sweep(db, BIG, workers=2)
    _wait_for_rows(db, 10, proc)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "interrupted" in err and "Traceback" not in err
    with sqlite3.connect(db) as c:
        assert c.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
        assert c.execute("SELECT COUNT(*) FROM points").fetchone()[0] >= 10


def test_a_renderer_that_cannot_draw_the_model_is_refused_before_any_fit(tmp_path):
    """It used to fit every point, fail each, print "100 points fitted (100 failed)" and exit 0."""
    grid = parse_grid("alpha=0.1:0.2:2", SOURCE.spec)
    bad = SweepConfig(source=SOURCE, target="mitsuba06:pbr", fix={"distribution": "as"}, target_renderer="cycles")
    with pytest.raises(MatremapError, match="cannot draw mitsuba06:pbr; 'embedded' does"):
        run_sweep(bad, grid, str(tmp_path / "x.sqlite"), InlineExecutor())
    assert not (tmp_path / "x.sqlite").exists()


def test_failed_points_are_retried_and_environment_failures_never_stored(tmp_path):
    """A point that failed is not a result: the next run fits it again and replaces the failed row; a
    renderer that is unavailable stops the sweep without storing anything for its points."""
    import matremap.sweep.run as sweep_mod
    from matremap.errors import RendererUnavailable

    grid = parse_grid("alpha=0.1:0.2:2", SOURCE.spec)
    db = str(tmp_path / "f.sqlite")
    real_fit = sweep_mod.fit_steps
    sweep_mod.fit_steps = lambda *a, **kw: (_ for _ in ()).throw(RendererUnavailable("Mitsuba 3 is not installed"))
    try:
        with pytest.raises(RendererUnavailable, match="not installed"):
            run_sweep(config(), grid, db, InlineExecutor())
    finally:
        sweep_mod.fit_steps = real_fit
    assert SweepStore.open(db).rows() == []  # nothing cached for the points it could not fit
    calls = []

    def flaky(*a, **kw):
        calls.append(1)
        if len(calls) == 1:
            raise RuntimeError("a numerical failure")
        return real_fit(*a, **kw)

    sweep_mod.fit_steps = flaky
    try:
        first = run_sweep(config(), grid, db, InlineExecutor())
    finally:
        sweep_mod.fit_steps = real_fit
    assert (first.done, first.failed) == (2, 1)
    again = run_sweep(config(), grid, db, InlineExecutor())  # the retry fits the failed point only
    assert (again.done, again.failed) == (1, 0)
    store = SweepStore.open(db)
    assert len(store.rows("ok")) == 2 and store.rows("failed") == []


def test_rows_come_back_in_one_order_whatever_order_lines_finish(tmp_path):
    """Lines finish in any order (a set of futures); learning from rows in insertion order made the SVR's
    held-out split, and so its hyper-parameters, change from run to run."""
    grid = parse_grid("alpha=0.1:0.3:3,specularReflectance=0.05:0.1:2", SOURCE.spec)
    db = str(tmp_path / "o.sqlite")
    run_sweep(config(), grid, db, InlineExecutor())
    store = SweepStore.open(db)
    rows = store.rows()
    assert [r["key"] for r in rows] == sorted(r["key"] for r in rows)
    reversed_db = tmp_path / "r.sqlite"
    with SweepStore.create_or_open(reversed_db, config().to_dict()) as other:
        other.add(list(reversed(rows)))
        assert [r["key"] for r in other.rows()] == [r["key"] for r in rows]


#: set by the test in this process only: a forked worker inherits the new value, a spawned one imports afresh
_STATE = {"mark": "imported"}


def _mark(_: object = None) -> str:
    return _STATE["mark"]


def test_worker_pools_are_spawned_not_forked():
    """A forked worker inherits the locks the parent's threads held (OpenImageIO's pool, BLAS): a batch run
    from a long-lived process (the test suite) hung in OpenImageIO's write_scanlines. A spawned worker starts
    from a fresh import, so it does not see what this process changed after importing."""
    from matremap.batch import item_executor
    from matremap.sweep.executors import make_executor

    _STATE["mark"] = "changed in the parent"
    try:
        with make_executor(2) as (ex, _):
            assert ex.submit(_mark).result() == "imported"
        with item_executor(2, None, None, 2) as (ex, _):
            assert ex.submit(_mark).result() == "imported"
    finally:
        _STATE["mark"] = "imported"
