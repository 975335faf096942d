"""Fuzzing the material-file readers (issue #19): real files of tests/data/corpus (glTF JSON, GLB,
MaterialX, Mitsuba XML, USD text layers and .usdz packages), mutated, are read as a user's file would be.
Each read must give an asset or raise MatremapError, nothing else. Budgets are fixed and derandomized (the
same examples every run)."""

from __future__ import annotations

import json
import re
import shutil
import struct
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from matremap.errors import MatremapError
from matremap.formats import read_asset

FUZZ = settings(
    max_examples=300, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow], database=None
)
CORPUS = Path(__file__).parent / "data" / "corpus"
GLTF = sorted(CORPUS.glob("gltf-*/*.gltf"))
GLB = sorted(CORPUS.glob("gltf-*/*.glb"))
MTLX = sorted(CORPUS.glob("mtlx-*/**/*.mtlx"))  # nested: documents kept in their repository layout
XML = sorted(CORPUS.glob("mitsuba-*/*.xml"))
USD_TEXT = sorted(p for p in CORPUS.glob("usd-*/*.usd*") if p.read_bytes()[:8] == b"#usda 1.")
USDZ = sorted(CORPUS.glob("usd-*/*.usdz"))
#: USD files are slower to open (a stage, its layers): a smaller fixed budget
FUZZ_USD = settings(
    max_examples=120, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow], database=None
)
#: matremap's own Mitsuba scene using every structure the reader follows (include, path, defaults, spectra,
#: checkerboard, to_uv, bumpmap, mask, blendbsdf, anisotropy); its two files are mutated in turn
SCENE_SEED = Path(__file__).parent / "data" / "mitsuba-fuzz-seed"

scalars = (
    st.none()
    | st.booleans()
    | st.integers(min_value=-(10**20), max_value=10**20)
    | st.floats(allow_nan=False, allow_infinity=False)
    | st.sampled_from([0, 1, -1, 2**31, 1e308, "", "image/png", "KHR_materials_clearcoat", "../x.png", "/etc/passwd"])
    | st.text(max_size=10)
)
json_values = st.recursive(
    scalars,
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=4),
    max_leaves=10,
)


def read(path: Path) -> Any:
    """Read a file as ``matremap remap`` does; a uniform material is built too. MatremapError is a refusal."""
    try:
        asset = read_asset(path)
        if not asset.textured:
            asset.material()
        return asset
    except MatremapError:
        return None


def in_copy(source: Path, write: Callable[[Path], None]) -> Any:
    """Copy ``source``'s folder, let ``write`` change the copy of the file, read it."""
    with tempfile.TemporaryDirectory() as d:
        folder = Path(d) / source.parent.name
        shutil.copytree(source.parent, folder)
        target = folder / source.name
        write(target)
        return read(target)


def paths(doc: Any, prefix: tuple = ()) -> list[tuple]:
    out = [prefix]
    if isinstance(doc, dict):
        for k, v in doc.items():
            out += paths(v, (*prefix, k))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            out += paths(v, (*prefix, i))
    return out


@st.composite
def mutated_json(draw: Any, doc: Any) -> Any:
    """``doc`` with one to three locations replaced, deleted or given an extra key."""
    doc = json.loads(json.dumps(doc))
    for _ in range(draw(st.integers(1, 3))):
        where = draw(st.sampled_from(paths(doc)))
        if not where:
            return draw(json_values)
        parent = doc
        for k in where[:-1]:
            parent = parent[k]
        op = draw(st.sampled_from(["replace", "delete", "add"]))
        if op == "delete" and isinstance(parent, dict):
            del parent[where[-1]]
        elif op == "add" and isinstance(parent, dict):
            parent[draw(st.text(max_size=8))] = draw(json_values)
        else:
            parent[where[-1]] = draw(json_values)
    return doc


@st.composite
def mutated_bytes(draw: Any, data: bytes) -> bytes:
    """``data`` with one to four spans replaced by other bytes (or cut, or repeated)."""
    for _ in range(draw(st.integers(1, 4))):
        i = draw(st.integers(0, max(len(data) - 1, 0)))
        j = min(len(data), i + draw(st.integers(0, 16)))
        data = data[:i] + draw(st.binary(max_size=16) | st.just(data[i:j] * 2)) + data[j:]
    return data


ATTRIBUTE = re.compile(rb'(value|name|type|nodedef|nodename|output|id|filename|uiname)="([^"]*)"')


@st.composite
def mutated_xml(draw: Any, data: bytes) -> bytes:
    """XML with one to three attribute values replaced (numbers, names, empty, long), or spans changed."""
    found = list(ATTRIBUTE.finditer(data))
    if not found or draw(st.booleans()):
        return draw(mutated_bytes(data))
    for _ in range(draw(st.integers(1, 3))):
        m = draw(st.sampled_from(found))
        new = draw(
            st.sampled_from([b"", b"nan", b"inf", b"-1", b"1e400", b"0, 0", b"a" * 300, b"../../x", b"1 2 3 4"])
            | st.text(max_size=12).map(lambda t: t.replace('"', "").encode())
        )
        data = data[: m.start(2)] + new + data[m.end(2) :]
        found = list(ATTRIBUTE.finditer(data))
        if not found:
            break
    return data


USD_VALUE = re.compile(rb"(= |asset |@)([^\n@]{1,60})")


@st.composite
def mutated_usda(draw: Any, data: bytes) -> bytes:
    """A USD text layer with one to three values (after ``=``, in ``@asset@`` paths) replaced, or spans changed."""
    found = list(USD_VALUE.finditer(data))
    if not found or draw(st.booleans()):
        return draw(mutated_bytes(data))
    for _ in range(draw(st.integers(1, 3))):
        m = draw(st.sampled_from(found))
        new = draw(
            st.sampled_from([b"", b"nan", b"inf", b"-1", b"1e400", b"(0, 0)", b"a" * 300, b"../../x.png", b"[1, 2"])
            | st.text(max_size=12).map(lambda t: t.encode())
        )
        data = data[: m.start(2)] + new + data[m.end(2) :]
        found = list(USD_VALUE.finditer(data))
        if not found:
            break
    return data


def test_corpus_reads():
    for f in [*GLTF, *GLB, *MTLX, *XML, *USD_TEXT, *USDZ]:
        read(f)  # refusals are fine (coat, sheen ...); tracebacks are not


@FUZZ
@given(st.sampled_from(GLTF), st.data())
def test_fuzz_gltf_json(path, data):
    doc = data.draw(mutated_json(json.loads(path.read_text())))
    in_copy(path, lambda p: p.write_text(json.dumps(doc)))


def _glb_json(path: Path) -> tuple[dict, bytes]:
    """A GLB's JSON chunk as a document, and the rest of the file after it."""
    raw = path.read_bytes()
    length = struct.unpack_from("<I", raw, 12)[0]
    return json.loads(raw[20 : 20 + length]), raw[20 + length :]


def _glb(doc: Any, rest: bytes) -> bytes:
    body = json.dumps(doc).encode()
    body += b" " * (-len(body) % 4)
    chunk = struct.pack("<II", len(body), 0x4E4F534A) + body
    return struct.pack("<III", 0x46546C67, 2, 12 + len(chunk) + len(rest)) + chunk + rest


@FUZZ
@given(st.sampled_from(GLB), st.data())
def test_fuzz_glb_json_chunk(path, data):
    doc, rest = _glb_json(path)
    mutated = _glb(data.draw(mutated_json(doc)), rest)
    in_copy(path, lambda p: p.write_bytes(mutated))


@FUZZ
@given(st.sampled_from(GLB), st.data())
def test_fuzz_glb_bytes(path, data):
    raw = path.read_bytes()
    head = raw[: min(len(raw), 4096)]  # headers, the JSON chunk and the start of the binary chunk
    mutated = data.draw(mutated_bytes(head)) + raw[len(head) :]
    in_copy(path, lambda p: p.write_bytes(mutated))


@FUZZ
@given(st.sampled_from(MTLX), st.data())
def test_fuzz_materialx(path, data):
    mutated = data.draw(mutated_xml(path.read_bytes()))
    in_copy(path, lambda p: p.write_bytes(mutated))


@FUZZ
@given(st.sampled_from(XML), st.data())
def test_fuzz_mitsuba_xml(path, data):
    mutated = data.draw(mutated_xml(path.read_bytes()))
    in_copy(path, lambda p: p.write_bytes(mutated))


def read_every_material(path: Path, limit: int | None = None) -> None:
    """Every material of a file (the fuzzed text may change which there are), read and its baked textures
    evaluated as ``remap`` would; refusals are fine."""
    from matremap.formats import material_names

    try:
        names = material_names(path)
    except MatremapError:
        return
    for name in names[:limit]:
        try:
            asset = read_asset(path, name)
            for ref in [*asset.textures.values(), asset.normal]:
                if ref is not None and ref.bake is not None:
                    ref.bake()
            if not asset.textured:
                asset.material()
        except MatremapError:
            pass


@FUZZ_USD
@given(st.sampled_from(USD_TEXT), st.data())
def test_fuzz_usd_text(path, data):
    pytest.importorskip("pxr")
    mutated = data.draw(mutated_usda(path.read_bytes()))
    with tempfile.TemporaryDirectory() as d:
        folder = Path(d) / path.parent.name
        shutil.copytree(path.parent, folder)
        (folder / path.name).write_bytes(mutated)
        read_every_material(folder / path.name, 3)


@FUZZ_USD
@given(st.sampled_from(USDZ), st.data())
def test_fuzz_usdz_bytes(path, data):
    pytest.importorskip("pxr")
    raw = path.read_bytes()
    head = raw[: min(len(raw), 2048)]  # the zip's first local header and the start of the root layer
    mutated = data.draw(mutated_bytes(head)) + raw[len(head) :]
    with tempfile.TemporaryDirectory() as d:
        f = Path(d) / path.name
        f.write_bytes(mutated)
        read_every_material(f, 3)


def test_the_scene_seed_reads_whole():
    from matremap.formats import material_names

    main = SCENE_SEED / "main.xml"
    assert len(material_names(main)) == 6
    read_every_material(main)


@settings(
    max_examples=150, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow], database=None
)
@given(st.sampled_from(["main.xml", "parts/mats.xml"]), st.data())
def test_fuzz_mitsuba_scene_structure(name, data):
    source = SCENE_SEED / name
    mutated = data.draw(mutated_xml(source.read_bytes()))
    with tempfile.TemporaryDirectory() as d:
        folder = Path(d) / "seed"
        shutil.copytree(SCENE_SEED, folder)
        (folder / name).write_bytes(mutated)
        read_every_material(folder / "main.xml")
