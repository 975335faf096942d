"""Fuzzing matremap's own readers (issue #19): the transform loader, the material JSON parser, the map-set
manifest loader and the sweep-database reader are fed mutated versions of valid inputs and arbitrary
JSON. Each must succeed or raise MatremapError, nothing else; a transform that loads must give finite
outputs. Budgets are fixed and derandomized (the same examples every run)."""

from __future__ import annotations

import contextlib
import json
import shutil
import sqlite3
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from matremap.cli.common import load_material
from matremap.core.material import Material, parse_material
from matremap.errors import MatremapError
from matremap.regress import library
from matremap.regress.data import load_training_data
from matremap.regress.transform import Transform
from matremap.sweep.store import COLUMNS, SweepStore

FUZZ = settings(
    max_examples=400, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow], database=None
)
CORPUS = Path(__file__).parent / "data" / "corpus"

scalars = (
    st.none()
    | st.booleans()
    | st.integers(min_value=-(10**30), max_value=10**30)
    | st.floats(allow_nan=True, allow_infinity=True)
    | st.sampled_from([0, 1, -1, 0.5, 1e-300, 1e308, 3, "", "ggx", "as", "mitsuba06:ward", "roughness", "constant"])
    | st.text(max_size=12)
)
json_values = st.recursive(
    scalars,
    lambda inner: st.lists(inner, max_size=5) | st.dictionaries(st.text(max_size=10), inner, max_size=5),
    max_leaves=12,
)


def refused_or_done(f: Callable[[], Any]) -> Any:
    """``f()``, or None when it raised MatremapError; any other exception fails the test."""
    try:
        return f()
    except MatremapError:
        return None


def paths(doc: Any, prefix: tuple = ()) -> list[tuple]:
    """Every location (a tuple of keys / indices) inside a JSON document, the root included."""
    out = [prefix]
    if isinstance(doc, dict):
        for k, v in doc.items():
            out += paths(v, (*prefix, k))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            out += paths(v, (*prefix, i))
    return out


@st.composite
def mutated(draw: Any, seeds: list[Any]) -> Any:
    """A seed document with one to three locations replaced, deleted or given an extra key."""
    doc = json.loads(json.dumps(draw(st.sampled_from(seeds))))
    for _ in range(draw(st.integers(1, 3))):
        where = draw(st.sampled_from(paths(doc)))
        if not where:
            return draw(json_values)
        parent = doc
        for k in where[:-1]:
            parent = parent[k]
        op = draw(st.sampled_from(["replace", "delete", "add"]))
        key = where[-1]
        if op == "delete" and isinstance(parent, dict):
            del parent[key]
        elif op == "add" and isinstance(parent, dict):
            parent[draw(st.text(max_size=8))] = draw(json_values)
        else:
            parent[key] = draw(json_values)
    return doc


# -- transforms ----------------------------------------------------------------------------------------------
def _shipped(name: str) -> dict:
    return json.loads((library.LIBRARY_DIR / f"{name}.json").read_text())


def _svr_seed() -> dict:
    """A small SVR transform (none is shipped): Ward's roughness through two support vectors."""
    doc = _shipped("ward-as")
    doc.pop("checksum")
    doc["method"] = "svr"
    doc["mappings"]["roughness"] = {
        "kind": "svr",
        "inputs": ["roughness"],
        "per_channel": False,
        "x_mean": [0.3],
        "x_scale": [0.2],
        "y_mean": 0.3,
        "y_scale": 0.2,
        "support_vectors": [[-1.0], [1.0]],
        "dual_coef": [-0.5, 0.5],
        "intercept": 0.0,
        "gamma": 1.0,
    }
    doc["mappings"]["reflectance"] = {
        "kind": "svr",
        "inputs": ["roughness", "reflectance"],
        "per_channel": True,
        "x_mean": [0.3, 0.2],
        "x_scale": [0.2, 0.1],
        "y_mean": 0.2,
        "y_scale": 0.1,
        "support_vectors": [[0.0, -1.0], [0.0, 1.0]],
        "dual_coef": [-1.0, 1.0],
        "intercept": 0.0,
        "gamma": 0.5,
    }
    return doc


def _chain_seed() -> dict:
    a, b = (Transform.load(library.LIBRARY_DIR / f"{n}.json") for n in ("ward-as", "as-ward"))
    return Transform.chain([a, b]).to_dict()


TRANSFORM_SEEDS = [_shipped("ward-as"), _shipped("gltf-metal-ward"), _shipped("conductor-cycles"), _svr_seed()]
TRANSFORM_SEEDS.append(_chain_seed())


def test_transform_seeds_load_and_apply():
    for doc in TRANSFORM_SEEDS:
        t = Transform.from_dict(doc)
        out, _ = t.apply({})
        assert all(np.isfinite(v).all() for v in out.values())


def _apply_finite(t: Transform) -> None:
    """Apply a loaded transform to its source defaults and to a small map; whatever comes out is finite."""
    from matremap.dialects import get_model

    spec = get_model(t.source)
    rough = next((p for p in spec.params if p.role == "roughness"), None)
    inputs: list[dict[str, Any]] = [{}]
    if rough is not None:
        lo, hi = rough.bounds
        inputs.append({rough.name: np.linspace(lo, min(hi, lo + 2.0), 7)})
    for values in inputs:
        result = refused_or_done(lambda v=values: t.apply(v))
        if result is not None:
            out, outside = result
            for name, a in out.items():
                assert np.isfinite(np.asarray(a, dtype=float)).all(), f"{t.describe()}: {name} not finite"


@FUZZ
@given(mutated(TRANSFORM_SEEDS))
def test_fuzz_transform_documents(doc):
    t = refused_or_done(lambda: Transform.from_dict(doc, "fuzzed transform"))
    if t is not None:
        _apply_finite(t)


@FUZZ
@given(json_values)
def test_fuzz_transform_arbitrary_json(doc):
    refused_or_done(lambda: Transform.from_dict(doc, "fuzzed transform"))


@settings(FUZZ, max_examples=200)
@given(st.binary(max_size=300) | st.text(max_size=300).map(str.encode))
def test_fuzz_transform_file_bytes(data):
    with tempfile.TemporaryDirectory() as d:
        f = Path(d) / "t.json"
        f.write_bytes(data)
        refused_or_done(lambda: Transform.load(f))


@settings(FUZZ, max_examples=150)
@given(st.sampled_from(TRANSFORM_SEEDS[:3]), st.integers(0, 10**6), st.sampled_from([b"0", b"9", b"-", b"e", b"\x00"]))
def test_fuzz_checksummed_transform_byte_edits(doc, position, byte):
    """One byte of a sealed transform file changed: refused (checksum or syntax) or, if the text still
    means the same content, loaded."""
    text = json.dumps(doc, indent=1).encode()
    i = position % len(text)
    edited = text[:i] + byte + text[i + 1 :]
    with tempfile.TemporaryDirectory() as d:
        f = Path(d) / "t.json"
        f.write_bytes(edited)
        t = refused_or_done(lambda: Transform.load(f, require_checksum=True))
        if t is not None:
            assert t.to_dict() == Transform.from_dict(doc).to_dict()


# -- materials -------------------------------------------------------------------------------------------------
MATERIAL_SEEDS = [
    Material.create("mitsuba06:ward", {"alpha": 0.2}).to_dict(),
    Material.create("gltf:metal-rough", {"metallic": 1.0}).to_dict(),
    Material.create("cycles:principled").to_dict(),
    Material.create("mitsuba06:roughconductor").to_dict(),
]


@FUZZ
@given(mutated(MATERIAL_SEEDS) | json_values)
def test_fuzz_material_json(doc):
    text = json.dumps(doc)
    m = refused_or_done(lambda: parse_material(text) if text.lstrip().startswith("{") else None)
    if m is not None:
        assert all(np.isfinite(v).all() for v in m.values.values())


@FUZZ
@given(st.text(max_size=400))
def test_fuzz_material_argument_text(text):
    """Whatever the command line is given as a material: a path, inline JSON or MODEL,name=value."""
    refused_or_done(lambda: load_material(text))
    refused_or_done(lambda: load_material("{" + text))
    refused_or_done(lambda: load_material("mitsuba06:ward," + text))


# -- manifests -------------------------------------------------------------------------------------------------
MANIFEST_SEEDS = [
    {"model": "mitsuba06:ward", "maps": {"diffuseReflectance": "a.png"}, "params": {"alpha": 0.2}},
    {
        "model": "gltf:metal-rough",
        "maps": {"baseColor": "a.png"},
        "normal": "n.png",
        "params": {"metallic": 1.0, "roughness": 0.4},
        "colorspace": {"a.png": "srgb"},
    },
]


@pytest.fixture(scope="module")
def maps_folder():
    with tempfile.TemporaryDirectory() as d:
        root = Path(d)
        shutil.copy(CORPUS / "gltf-BoxTextured" / "CesiumLogoFlat.png", root / "a.png")
        shutil.copy(CORPUS / "gltf-TwoSidedPlane" / "TwoSidedPlane_Normal.png", root / "n.png")
        yield root


@settings(FUZZ, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(mutated(MANIFEST_SEEDS) | json_values)
def test_fuzz_manifest(maps_folder, doc):
    from matremap.svbrdf.textures import load_map_set

    (maps_folder / "material.json").write_text(json.dumps(doc))
    refused_or_done(lambda: load_map_set(maps_folder))


# -- sweep databases -----------------------------------------------------------------------------------------
def _sweep_config() -> dict:
    from matremap.sweep.run import SweepConfig

    return SweepConfig(source=Material.create("mitsuba06:ward"), target="mitsuba06:pbr").to_dict()


def _row(i: int) -> dict:
    source = Material.create("mitsuba06:ward", {"alpha": 0.05 + 0.1 * i}).to_dict()["params"]
    target = Material.create("mitsuba06:pbr", {"alpha": 0.05 + 0.1 * i}).to_dict()["params"]
    return {
        "key": json.dumps({"alpha": source["alpha"]}),
        "swept": {"alpha": source["alpha"]},
        "source": source,
        "target": target,
        "loss": 0.01,
        "renders": 10,
        "seconds": 0.5,
        "status": "ok",
        "stages": {"specular": {"loss": 0.01}},
        "warnings": [],
        "finished": 1.0,
    }


@pytest.fixture(scope="module")
def clean_db():
    with tempfile.TemporaryDirectory() as d:
        db = Path(d) / "clean.sqlite"
        with SweepStore.create_or_open(db, _sweep_config()) as store:
            store.add([_row(i) for i in range(4)])
        yield db


def test_clean_sweep_database_reads(clean_db):
    assert len(load_training_data(clean_db)) == 4


cell_values = (
    st.none()
    | st.integers(min_value=-(2**63), max_value=2**63 - 1)
    | st.floats(allow_nan=True, allow_infinity=True)
    | st.text(max_size=30)
    | st.binary(max_size=12)
    | json_values.map(json.dumps)
)


@settings(FUZZ, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(
    st.integers(0, 3),
    st.sampled_from([*COLUMNS, "meta.config", "meta.schema", "json.source", "json.target", "json.swept"]),
    cell_values,
    st.data(),
)
def test_fuzz_sweep_database_rows(clean_db, row, column, value, data):
    with tempfile.TemporaryDirectory() as d:
        db = Path(d) / "s.sqlite"
        shutil.copy(clean_db, db)
        key = _row(row)["key"]
        with sqlite3.connect(db) as conn, contextlib.suppress(sqlite3.IntegrityError):  # NOT NULL, UNIQUE
            if column.startswith("meta."):
                conn.execute("UPDATE meta SET value = ? WHERE key = ?", (value, column[5:]))
            elif column.startswith("json."):  # a value inside a JSON column changed
                name = column[5:]
                (text,) = conn.execute(f"SELECT {name} FROM points WHERE key = ?", (key,)).fetchone()
                doc = data.draw(mutated([json.loads(text)]))
                conn.execute(f"UPDATE points SET {name} = ? WHERE key = ?", (json.dumps(doc), key))
            else:
                conn.execute(f"UPDATE points SET {column} = ? WHERE key = ?", (value, key))
        conn.close()

        def read() -> None:
            with SweepStore.open(db) as store:
                store.rows()
                store.count()
                store.finished_keys()
            load_training_data(db)

        refused_or_done(read)
