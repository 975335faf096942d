"""Schemas at every boundary (issue #19): transforms (content, checksum, the finite-output guard), material
JSON, map-set manifests and sweep databases each refuse what is malformed with one MatremapError, and the
command line never shows a traceback."""

from __future__ import annotations

import json
import multiprocessing
import shutil
import sqlite3
from pathlib import Path

import numpy as np
import pytest

from matremap.cli import main
from matremap.cli.common import load_material
from matremap.core.documents import MAX_DEPTH
from matremap.core.material import Material, parse_material
from matremap.errors import EXIT_INTERNAL, MatremapError, TransformChecksumError
from matremap.regress import library
from matremap.regress.transform import Transform
from matremap.sweep.store import SweepStore

CORPUS = Path(__file__).parent / "data" / "corpus"
DEEP = "[" * 100_000 + "]" * 100_000


def shipped(name: str = "ward-as") -> dict:
    """A shipped transform's document without its checksum (so the schema's own checks are reached)."""
    doc = json.loads((library.LIBRARY_DIR / f"{name}.json").read_text())
    doc.pop("checksum")
    return doc


# -- transforms: content ------------------------------------------------------------------------------
def _with(doc: dict, path: str, value) -> dict:
    """A deep copy of ``doc`` with the value at the dotted ``path`` replaced."""
    out = json.loads(json.dumps(doc))
    *head, last = path.split(".")
    node = out
    for k in head:
        node = node[int(k)] if isinstance(node, list) else node[k]
    if isinstance(node, list):
        node[int(last)] = value
    else:
        node[last] = value
    return out


@pytest.mark.parametrize(
    "path, value, message",
    [
        ("mappings.roughness.coef.0", float("nan"), "not a finite number"),
        ("mappings.reflectance.coef.1", float("inf"), "not a finite number"),
        ("mappings.roughness.coef.0", 1e300, "not a finite number in"),
        ("mappings.roughness.coef.0", "0.5", "must be a number"),
        ("mappings.roughness.coef.0", True, "must be a number"),
        ("mappings.reflectance.coef", [1.0, 2.0], "list of 5 or 6 numbers"),
        ("mappings.reflectance.coef.2", -50.0, "must not be negative"),
        ("mappings.diffuse.coef", [0.5] * 7, "list of 1 or 3 numbers"),
        ("mappings.roughness.coef", [0.1] * 9, "list of 1 or 2 or 3 or 4 or 5 numbers"),
        ("mappings.roughness.kind", "exec", "kind 'exec' is not one of"),
        ("mappings.roughness.kind", ["polynomial"], "kind a list of 1 is not one of"),  # found by the fuzzer
        ("mappings.roughness.kind", "k_alpha", "cannot give roughness"),
        ("mappings.diffuse", {"kind": "constant", "value": [0.1, float("nan"), 0.1]}, "not a finite number"),
        ("target.options", {"distribution": "as", "colour": "red"}, "unknown to mitsuba06:pbr"),
        ("target.options", {"distribution": "nope"}, "not one of"),
        ("target.options", {"distribution": 3}, "not one of"),
        ("domain.roughness", [0.7, 0.03], "is empty"),
        ("domain.roughness", [0.03, float("nan")], "not a finite number"),
        ("template.alpha", 1e9, "outside its range"),
        ("template.F0", "grey", "not a number"),
        ("errors.roughness.heldout_rmse", "low", "must be a number"),
        ("provenance", [], "must be a JSON object"),
    ],
)
def test_transform_content_is_validated(path, value, message):
    with pytest.raises(MatremapError, match=message):
        Transform.from_dict(_with(shipped(), path, value), "t.json")


def test_transform_unknown_keys_nested_chains_and_foreign_quantities_are_refused():
    doc = shipped()
    with pytest.raises(MatremapError, match="unknown keys code"):
        Transform.from_dict({**doc, "code": "import os"})
    inner = {**doc, "method": "chain", "steps": [doc, doc]}
    for _ in range(3):
        inner = {**doc, "method": "chain", "steps": [inner, doc]}
    with pytest.raises(MatremapError, match="not chains"):
        Transform.from_dict(inner)
    # a glTF metal target has no diffuse quantity to write; a Ward source has no 'eta' to read
    metal = shipped("ward-gltf-metal")
    with pytest.raises(MatremapError, match="reads roughness, not 'eta'"):
        Transform.from_dict(_with(metal, "mappings.roughness.input", "eta"))


def test_nan_in_a_transform_file_is_refused_at_load(tmp_path):
    text = (library.LIBRARY_DIR / "ward-as.json").read_text()
    doc = json.loads(text)
    doc.pop("checksum")
    doc["mappings"]["reflectance"]["coef"][0] = float("nan")
    f = tmp_path / "nan.json"
    f.write_text(json.dumps(doc))  # json writes NaN, which is not JSON
    with pytest.raises(MatremapError, match="NaN"):
        Transform.load(f)


def test_a_transform_nested_100k_deep_is_one_error(tmp_path):
    f = tmp_path / "deep.json"
    f.write_text('{"schema": ' + DEEP + "}")
    with pytest.raises(MatremapError, match="nested too deeply"):
        Transform.load(f)
    shallow = tmp_path / "shallow.json"
    shallow.write_text('{"provenance": ' + "[" * (MAX_DEPTH + 1) + "]" * (MAX_DEPTH + 1) + "}")
    with pytest.raises(MatremapError, match="nested too deeply"):
        Transform.load(shallow)


def test_output_that_is_not_finite_is_refused_naming_the_transform():
    t = Transform.from_dict(shipped())
    # bypass the schema (as a future bug might): a rate that overflows exp() for every input
    t.mappings["reflectance"]["coef"][2] = -1e308
    with (
        np.errstate(over="ignore"),
        pytest.raises(MatremapError, match=r"mitsuba06:ward -> mitsuba06:pbr .*NaN or infinite reflectance"),
    ):
        t.apply({"alpha": np.full(4, 0.3), "specularReflectance": np.full(4, 0.1)})


# -- transforms: checksum -----------------------------------------------------------------------------
def test_save_stores_a_checksum_and_an_edit_is_detected(tmp_path):
    t = Transform.from_dict(shipped())
    path = t.save(tmp_path / "t.json")
    doc = json.loads(path.read_text())
    assert doc["checksum"].startswith("sha256:") and len(doc["checksum"]) == 7 + 64
    Transform.load(path, require_checksum=True)  # verifies
    doc["mappings"]["roughness"]["coef"][-1] += 0.25  # still a valid transform, but not the one written
    path.write_text(json.dumps(doc, indent=1))
    with pytest.raises(TransformChecksumError, match="changed after it was written"):
        Transform.load(path)
    doc.pop("checksum")  # hand-written: loadable when given explicitly, refused where one is required
    path.write_text(json.dumps(doc))
    assert Transform.load(path).mappings["roughness"]["coef"][-1] == doc["mappings"]["roughness"]["coef"][-1]
    with pytest.raises(TransformChecksumError, match="carries no checksum"):
        Transform.load(path, require_checksum=True)


def test_every_shipped_transform_carries_a_valid_checksum():
    files = sorted(library.LIBRARY_DIR.glob("*.json"))
    assert len(files) == len(library.entries()) >= 20
    for f in files:
        Transform.load(f, require_checksum=True)
        assert library.seal([f]) == []  # sealing again changes nothing


def test_a_damaged_library_says_so(tmp_path):
    for f in list(library.LIBRARY_DIR.glob("*.json"))[:2]:
        shutil.copy(f, tmp_path / f.name)
    victim = sorted(tmp_path.glob("*.json"))[0]
    doc = json.loads(victim.read_text())
    doc["domain"]["roughness"][1] = 5.0
    victim.write_text(json.dumps(doc))
    with pytest.raises(TransformChecksumError, match="library is damaged"):
        library.entries(tmp_path)


# -- the crash on an RGB baseColor map, metallic 1, uniform roughness ---------------------------------
def metal_box(folder: Path, roughness: float) -> Path:
    """BoxTextured (an RGB baseColor texture) made a metal of one roughness."""
    shutil.copytree(CORPUS / "gltf-BoxTextured", folder)
    path = folder / "BoxTextured.gltf"
    doc = json.loads(path.read_text())
    doc["materials"][0]["pbrMetallicRoughness"].update(metallicFactor=1.0, roughnessFactor=roughness)
    path.write_text(json.dumps(doc))
    return path


def test_rgb_base_colour_metal_with_uniform_roughness_outside_the_library_domain(tmp_path):
    from matremap.formats import read_asset
    from matremap.remap import library_transform, load_arrays
    from matremap.svbrdf.textures import load_map_set

    asset = read_asset(metal_box(tmp_path / "box", roughness=0.1))
    map_set = load_map_set(asset.to_map_set(tmp_path / "maps"))
    params, _ = load_arrays(map_set)
    assert np.ndim(params["baseColor"]) == 3 and np.ndim(params["roughness"]) == 0
    log: list[str] = []
    # roughness 0.1 lies below the library's training domain: every texel is outside, so no route
    assert library_transform(map_set, params, "mitsuba06:ward", {}, log.append) is None
    assert any("covers only 0.0% of the texels" in m for m in log) and "that covers the maps" in log[-1]
    t = {e.name: e for e in library.entries()}["gltf-metal-ward"].transform
    out, outside = t.apply({"baseColor": np.full((4, 5, 3), 0.6), "roughness": 0.1, "metallic": 1.0})
    assert outside.shape == (4, 5) and outside.all()
    # a uniform colour out of the domain beside a roughness map: each texel is outside
    out, outside = t.apply({"baseColor": [0.001, 0.5, 0.5], "roughness": np.full((4, 5), 0.3), "metallic": 1.0})
    assert outside.shape == (4, 5) and outside.all()


# -- material JSON --------------------------------------------------------------------------------------
def test_material_json_nested_100k_deep_is_one_error(tmp_path):
    with pytest.raises(MatremapError, match="nested too deeply"):
        parse_material('{"model": "mitsuba06:ward", "params": {"alpha": ' + DEEP + "}}")
    f = tmp_path / "m.json"
    f.write_text('{"model": "mitsuba06:ward", "params": {"alpha": ' + DEEP + "}}")
    with pytest.raises(MatremapError, match="nested too deeply"):
        load_material(str(f))
    with pytest.raises(MatremapError, match="not a JSON number"):
        parse_material('{"model": "mitsuba06:ward", "params": {"alpha": NaN}}')


def test_inline_material_longer_than_a_file_name():
    pad = " " * 300
    text = '{"model": "mitsuba06:ward",' + pad + '"params": {"alpha": 0.2}}'
    assert load_material(text) == Material.create("mitsuba06:ward", {"alpha": 0.2})
    compact = "mitsuba06:ward,alpha=0.2" + ",alpha=0.2" * 40
    assert len(compact) > 255 and load_material(compact).values["alpha"][0] == 0.2


# -- manifests ------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "doc, message",
    [
        ({"model": "mitsuba06:ward", "maps": {"alpha": "a.png"}, "params": [["x", 1]]}, "'params' must map"),
        ({"model": "mitsuba06:ward", "maps": {"alpha": "a.png"}, "params": [1, 2]}, "'params' must map"),
        ({"model": "mitsuba06:ward", "maps": {"alpha": "a.png"}, "normal": {"x": 1}}, "'normal' must be"),
        ({"model": "mitsuba06:ward", "maps": {"alpha": ""}}, "'maps' must map"),
        ({"model": "mitsuba06:ward", "maps": {"alpha": "a.png"}, "colorspace": {"alpha": 3}}, "'colorspace'"),
    ],
)
def test_manifest_types_are_validated(tmp_path, doc, message):
    from matremap.svbrdf.textures import load_map_set

    (tmp_path / "material.json").write_text(json.dumps(doc))
    with pytest.raises(MatremapError, match=message):
        load_map_set(tmp_path)


def test_manifest_nested_100k_deep_is_one_error(tmp_path):
    from matremap.svbrdf.textures import load_map_set

    (tmp_path / "material.json").write_text('{"model": "mitsuba06:ward", "maps": ' + DEEP + "}")
    with pytest.raises(MatremapError, match="nested too deeply"):
        load_map_set(tmp_path)


# -- sweep databases ------------------------------------------------------------------------------------
CONFIG = {
    "source": {"model": "mitsuba06:ward", "params": {}},
    "target": {"model": "mitsuba06:pbr", "fix": {}, "free": []},
}


def good_row(key: str = "a") -> dict:
    return {
        "key": key,
        "swept": {"alpha": 0.1},
        "source": {"variant": "ward", "alpha": 0.1, "specularReflectance": [0.1] * 3, "diffuseReflectance": [0] * 3},
        "target": {
            "distribution": "as",
            "alpha": 0.1,
            "F0": [0.1] * 3,
            "specularReflectance": [1] * 3,
            "diffuseReflectance": [0] * 3,
        },
        "loss": 0.01,
        "renders": 10,
        "seconds": 1.0,
        "status": "ok",
        "finished": 1.0,
    }


def make_db(path: Path) -> Path:
    with SweepStore.create_or_open(path, CONFIG) as store:
        store.add([good_row("a"), good_row("b")])
    return path


@pytest.mark.parametrize(
    "sql, message",
    [
        ("UPDATE points SET loss = 'low' WHERE key = 'a'", "column loss holds 'low', not a number"),
        ("UPDATE points SET renders = 'many' WHERE key = 'a'", "column renders holds 'many'"),
        ("UPDATE points SET target = '{\"alpha\": ' WHERE key = 'a'", "column target is not valid JSON"),
        ("UPDATE points SET source = '[1, 2]' WHERE key = 'a'", "column source holds list"),
        ("UPDATE points SET target = '{\"alpha\": \"x\"}' WHERE key = 'a'", "target parameter"),
        ("UPDATE points SET target = NULL WHERE key = 'a'", "without its target parameters"),
        ("UPDATE points SET status = 'maybe' WHERE key = 'a'", "not a row of a sweep"),
        (
            "UPDATE points SET source = json_remove(source, '$.variant')",
            "source option variant is 'None', not a string",
        ),  # fuzzer
        ("UPDATE points SET swept = '" + "[" * 5000 + "]" * 5000 + "' WHERE key = 'a'", "not valid JSON"),
        ("ALTER TABLE points DROP COLUMN back_loss", "lacks the column"),
        ("UPDATE meta SET value = '{' WHERE key = 'config'", "config is not valid JSON"),
        ("DROP TABLE points", "lacks the column"),
    ],
)
def test_corrupt_sweep_database_rows_are_one_error(tmp_path, sql, message):
    db = make_db(tmp_path / "s.sqlite")
    with sqlite3.connect(db) as conn:
        conn.execute(sql)
    conn.close()
    with pytest.raises(MatremapError, match=message):
        with SweepStore.open(db) as store:
            store.rows()
            store.config  # noqa: B018 - read like the learners read it


def test_a_corrupt_row_stops_learning_with_one_error(tmp_path):
    from matremap.regress.transform import learn_transform

    db = make_db(tmp_path / "s.sqlite")
    with sqlite3.connect(db) as conn:
        conn.execute("UPDATE points SET seconds = 'slow' WHERE key = 'b'")
    conn.close()
    with pytest.raises(MatremapError, match="point 'b': column seconds"):
        learn_transform(db)


def _race(args: tuple[str, int, object]) -> str:
    """One of two sweeps starting on the same new database at once; returns what it was told."""
    db, which, barrier = args
    config = {**CONFIG, "strategy": f"settings-{which}"}
    barrier.wait()  # type: ignore[attr-defined]
    try:
        with SweepStore.create_or_open(db, config):
            return "ok"
    except MatremapError as e:
        return str(e)


def test_two_sweeps_starting_a_new_database_agree_on_its_schema(tmp_path):
    ctx = multiprocessing.get_context("fork")
    with ctx.Manager() as manager, ctx.Pool(2) as pool:
        for i in range(12):
            db = str(tmp_path / f"race{i}.sqlite")
            barrier = manager.Barrier(2)
            results = pool.map(_race, [(db, 0, barrier), (db, 1, barrier)])
            assert sorted(results)[1] == "ok", results  # one of them made it
            loser = sorted(results)[0]
            assert "different configuration" in loser and "strategy" in loser, results


# -- the command line -------------------------------------------------------------------------------------
def test_an_unexpected_exception_is_one_line_with_exit_70(capsys, monkeypatch):
    def broken(args):
        raise ZeroDivisionError("float division by zero")

    monkeypatch.setitem(main.__globals__["PARSERS"], "models", _parser_with(broken))
    code = main(["models"])
    err = capsys.readouterr().err
    assert code == EXIT_INTERNAL == 70
    assert err.count("\n") == 1 and "Traceback" not in err
    assert err.startswith("matremap: internal error: ZeroDivisionError: float division by zero")
    assert "rerun with --debug" in err
    code = main(["--debug", "models"])
    err = capsys.readouterr().err
    assert code == 70 and "Traceback (most recent call last)" in err and 'raise ZeroDivisionError("float' in err


def _parser_with(func):
    def add(sub):
        p = sub.add_parser("models", help="broken for the test")
        p.set_defaults(func=func)

    return add


def test_system_errors_on_a_path_and_interrupts_keep_their_own_lines(capsys, monkeypatch):
    def unreadable(args):
        raise PermissionError(13, "Permission denied", "/data/maps/base.png")

    monkeypatch.setitem(main.__globals__["PARSERS"], "models", _parser_with(unreadable))
    assert main(["models"]) == 2
    assert capsys.readouterr().err == "matremap: error: cannot read /data/maps/base.png: Permission denied\n"

    def interrupted(args):
        raise KeyboardInterrupt

    monkeypatch.setitem(main.__globals__["PARSERS"], "models", _parser_with(interrupted))
    assert main(["models"]) == 130


def test_inline_material_longer_than_255_characters_on_the_command_line(capsys, tmp_path):
    material = '{"model": "mitsuba06:ward", ' + " " * 300 + '"params": {"alpha": 0.2, "specularReflectance": 0.1}}'
    code = main(["render", material, "-o", str(tmp_path / "r.exr"), "--size", "16"])
    err = capsys.readouterr().err
    assert code == 0, err


def test_an_edited_cached_transform_is_recomputed_not_used(tmp_path, capsys):
    """A cached transform edited after it was written (a constant roughness map and a black diffuse came out
    with exit 0 before) is not trusted: the remap notes it, sweeps again and overwrites it."""
    from matremap.cli import main
    from matremap.svbrdf.textures import load_map_set, read_image

    examples = Path(__file__).resolve().parents[1] / "examples"
    cache = tmp_path / "cache"
    args = ["remap", str(examples / "blue-plastic"), "--to", "mitsuba06:pbr", "--fix", "distribution=as"]
    args += ["--sweep", "--no-evaluate"]
    assert main([*args, "-o", str(tmp_path / "first"), "--cache", str(cache)]) == 0
    (cached,) = cache.glob("*.json")
    doc = json.loads(cached.read_text())
    for mapping in doc["mappings"].values():  # every mapping flattened to a constant, the checksum kept
        if "coef" in mapping:
            mapping["coef"] = [0.5] + [0.0] * (len(mapping["coef"]) - 1)
    cached.write_text(json.dumps(doc))
    capsys.readouterr()
    assert main([*args, "-o", str(tmp_path / "second"), "--cache", str(cache)]) == 0
    err = capsys.readouterr().err
    assert "changed after it was written" in err and "recomputing" in err, err
    maps = load_map_set(tmp_path / "second" / "maps")
    diffuse, _ = read_image(maps.maps["diffuseReflectance"], maps.colorspace["diffuseReflectance"])
    assert diffuse.std() > 0.01 and diffuse.mean() > 0.05  # a real map, not a constant or black
    assert json.loads(cached.read_text())["checksum"] != ""  # rewritten with a valid seal


def damage(db: Path) -> None:
    """Overwrite the middle of a database file (whole pages of a b-tree) with garbage."""
    data = bytearray(db.read_bytes())
    start = len(data) // 2 // 4096 * 4096
    data[start : start + 4096] = b"A" * 4096
    db.write_bytes(bytes(data))


def test_a_damaged_sweep_database_is_one_error_and_a_cached_one_is_discarded(tmp_path, capsys):
    """A sweep database with a damaged page raised sqlite3.DatabaseError ('database disk image is malformed')
    from a resumed sweep: an internal error, exit 70, also for the one the transform cache keeps."""
    from matremap.cli import main
    from matremap.sweep.store import SweepDatabaseDamaged, discard_if_damaged

    db = tmp_path / "s.sqlite"
    with SweepStore.create_or_open(db, CONFIG) as store:
        store.add([good_row(f"p{i:03d}") for i in range(300)])  # several pages
    assert discard_if_damaged(db) is None and db.is_file()  # a sound one stays
    damage(db)
    with pytest.raises(SweepDatabaseDamaged, match="is damaged"):
        SweepStore.open(db)
    with pytest.raises(MatremapError, match="is damaged"):
        SweepStore.create_or_open(db, CONFIG)  # a resumed sweep
    capsys.readouterr()
    assert main(["learn", str(db), "-o", str(tmp_path / "t.json")]) == 2
    err = capsys.readouterr().err.strip()
    assert "is damaged" in err and "\n" not in err and not (tmp_path / "t.json").exists()
    assert discard_if_damaged(db) and not db.exists()  # the cache's copy: removed, swept again


def test_a_damaged_cached_sweep_database_is_swept_again(tmp_path, capsys):
    from matremap.cli import main

    examples = Path(__file__).resolve().parents[1] / "examples"
    cache = tmp_path / "cache"
    args = ["remap", str(examples / "blue-plastic"), "--to", "mitsuba06:pbr", "--fix", "distribution=as"]
    args += ["--sweep", "--no-evaluate", "--cache", str(cache)]
    assert main([*args, "-o", str(tmp_path / "first")]) == 0
    (cached,) = cache.glob("*.json")
    cached.unlink()  # the transform gone, its sweep's database kept (resumed next time) and damaged
    (db,) = cache.glob("*.sqlite")
    damage(db)
    capsys.readouterr()
    assert main([*args, "-o", str(tmp_path / "second")]) == 0
    err = capsys.readouterr().err
    assert "was damaged" in err and "sweeping again" in err and "0 already in the database" in err, err
