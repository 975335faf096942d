"""Hostile inputs to the readers and the command line end in one short, printable line with the right exit
status: expansion bombs in Mitsuba XML are bounded, deep MaterialX graphs evaluate (or are refused naming
the limit), byte order marks and declared encodings read, special files and non-UTF-8 names are named as
such, a full disk is exit 4 naming the folder, and nothing half-written stays behind."""

from __future__ import annotations

import errno
import importlib.util
import io
import os
import sqlite3
import sys
import tempfile
from pathlib import Path

import pytest

from matremap.cli import main
from matremap.errors import MAX_LINE, MatremapError, one_line, shorten
from matremap.formats import read_asset
from matremap.formats.mitsuba_scene import MAX_EXPANDED, MAX_INCLUDES, load_scene

needs_materialx = pytest.mark.skipif(
    importlib.util.find_spec("MaterialX") is None, reason="MaterialX not installed: pip install 'matremap[materialx]'"
)
TESTS = Path(__file__).parent


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("MATREMAP_CACHE", str(tmp_path / "cache"))
    monkeypatch.delenv("MATREMAP_CACHE_DIR", raising=False)
    return tmp_path / "cache"


def mtlx_chain(length: int, first: str = "", value: str = "0.001, 0.001, 0.001") -> str:
    """A MaterialX document whose base colour is a chain of ``length`` nodes (a constant, then adds)."""
    nodes = [
        first
        or '<constant name="n0" type="color3"><input name="value" type="color3" value="0.2, 0.3, 0.4"/></constant>'
    ]
    for i in range(1, length):
        nodes.append(
            f'<add name="n{i}" type="color3"><input name="in1" type="color3" nodename="n{i - 1}"/>'
            f'<input name="in2" type="color3" value="{value}"/></add>'
        )
    return (
        '<?xml version="1.0"?>\n<materialx version="1.39">\n'
        + "\n".join(nodes)
        + f'\n<standard_surface name="s" type="surfaceshader"><input name="base_color" type="color3" '
        f'nodename="n{length - 1}"/></standard_surface>\n'
        '<surfacematerial name="mat" type="material"><input name="surfaceshader" type="surfaceshader" nodename="s"/>'
        "</surfacematerial>\n</materialx>\n"
    )


def one_error_line(err: str, alone: bool = True) -> str:
    """The last line on stderr, a matremap error line; ``alone``: the only one."""
    lines = err.strip().splitlines()
    assert len(lines) == 1 or (lines and not alone), lines
    assert lines[-1].startswith("matremap: error: "), lines[-1]
    return lines[-1]


def leftovers(folder: Path) -> list[Path]:
    return [p for p in folder.rglob(".matremap-*")]


# -- Mitsuba XML: expansion bounds ------------------------------------------------------------------


def test_nested_defaults_are_refused_in_one_short_line(tmp_path):
    """Each <default> repeating the one before twice doubles: refused at the bound, in a short message
    (unbounded, 22 levels made a 33-million-character value and an error quoting it)."""
    defaults = '<default name="d0" value="0.5 0.5 "/>' + "".join(
        f'<default name="d{i}" value="$d{i - 1}$d{i - 1}"/>' for i in range(1, 23)
    )
    (tmp_path / "s.xml").write_text(
        f'<scene version="3.0.0">{defaults}<bsdf type="diffuse" id="x"><rgb name="reflectance" value="$d22"/>'
        "</bsdf></scene>"
    )
    with pytest.raises(MatremapError, match=f"past {MAX_EXPANDED:,} characters") as e:
        load_scene(tmp_path / "s.xml")
    assert len(str(e.value)) < 400


def test_expansion_bound_counts_every_use(tmp_path):
    """A default below the bound used many times over makes more than the bound in all: refused too."""
    big = "x" * (MAX_EXPANDED // 10)
    uses = "".join(f'<string name="s{i}" value="$big"/>' for i in range(12))
    (tmp_path / "s.xml").write_text(
        f'<scene version="3.0.0"><default name="big" value="{big}"/><bsdf type="diffuse">{uses}</bsdf></scene>'
    )
    with pytest.raises(MatremapError, match="expand the scene's parameters past"):
        load_scene(tmp_path / "s.xml")


def test_include_fan_out_is_refused(tmp_path):
    """Files each including the next eight times (no cycle, shallow) multiply: refused at MAX_INCLUDES."""
    for level in range(4):
        inner = "".join(f'<include filename="f{level + 1}.xml"/>' for _ in range(8))
        (tmp_path / f"f{level}.xml").write_text(f'<scene version="3.0.0">{inner}</scene>')
    (tmp_path / "f4.xml").write_text('<scene version="3.0.0"><default name="z" value="1"/></scene>')
    (tmp_path / "s.xml").write_text('<scene version="3.0.0"><include filename="f0.xml"/><bsdf type="diffuse"/></scene>')
    with pytest.raises(MatremapError, match=f"more than {MAX_INCLUDES} <include>s"):
        load_scene(tmp_path / "s.xml")


def test_included_bytes_are_bounded(tmp_path, monkeypatch):
    import matremap.formats.mitsuba_scene as scene

    monkeypatch.setattr(scene, "MAX_SCENE_BYTES", 4000)
    (tmp_path / "part.xml").write_text('<scene version="3.0.0">' + "<!-- padding -->" * 100 + "</scene>")
    (tmp_path / "s.xml").write_text(
        '<scene version="3.0.0">' + '<include filename="part.xml"/>' * 3 + '<bsdf type="diffuse"/></scene>'
    )
    with pytest.raises(MatremapError, match="more than 4,000 bytes of XML"):
        load_scene(tmp_path / "s.xml")


def test_cli_refuses_the_default_bomb_in_one_line(tmp_path, capsys):
    defaults = '<default name="d0" value="xxxxxxxx"/>' + "".join(
        f'<default name="d{i}" value="$d{i - 1}$d{i - 1}"/>' for i in range(1, 30)
    )
    (tmp_path / "s.xml").write_text(
        f'<scene version="3.0.0">{defaults}<bsdf type="diffuse" id="x"><rgb name="reflectance" value="$d29"/>'
        "</bsdf></scene>"
    )
    assert main(["remap", str(tmp_path / "s.xml"), "--to", "mitsuba06:diffuse", "-o", str(tmp_path / "out")]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert "characters" in line and len(line) < 300
    assert not (tmp_path / "out").exists()


# -- MaterialX: graph depth, encodings ----------------------------------------------------------------


@needs_materialx
@pytest.mark.parametrize("length", [200, 600])
def test_deep_materialx_chains_evaluate(tmp_path, length):
    """A chain of hundreds of nodes is evaluated (the interpreter's default stack held about 160)."""
    (tmp_path / "m.mtlx").write_text(mtlx_chain(length, value="0.0001, 0.0001, 0.0001"))
    values = read_asset(tmp_path / "m.mtlx").material().values
    assert values["base_color"] == pytest.approx(
        [0.2 + 0.0001 * (length - 1), 0.3 + 0.0001 * (length - 1)] + [0.4 + 0.0001 * (length - 1)]
    )


@needs_materialx
def test_materialx_chain_past_the_limit_is_refused_naming_it(tmp_path):
    from matremap.formats.mtlx_graph import MAX_DEPTH

    (tmp_path / "m.mtlx").write_text(mtlx_chain(MAX_DEPTH + 10))
    with pytest.raises(MatremapError, match=f"deeper than {MAX_DEPTH}"):
        read_asset(tmp_path / "m.mtlx").material()


@needs_materialx
@pytest.mark.parametrize(
    "encode",
    [
        lambda text: b"\xef\xbb\xbf" + text.encode(),
        lambda text: text.replace('version="1.0"?>', 'version="1.0" encoding="UTF-16"?>').encode("utf-16"),
        lambda text: text.replace('version="1.0"?>', 'version="1.0" encoding="UTF-16"?>').encode("utf-16-le"),
        lambda text: text.replace('version="1.0"?>', 'version="1.0" encoding="ISO-8859-1"?>').encode("latin-1"),
    ],
    ids=["utf-8 BOM", "utf-16 BOM", "utf-16 without BOM", "latin-1 declared"],
)
def test_materialx_byte_order_marks_and_declared_encodings_read(tmp_path, encode):
    text = mtlx_chain(2)
    (tmp_path / "plain.mtlx").write_text(text)
    (tmp_path / "m.mtlx").write_bytes(encode(text))
    expected = read_asset(tmp_path / "plain.mtlx").material().values
    assert read_asset(tmp_path / "m.mtlx").material().values["base_color"] == pytest.approx(expected["base_color"])


@needs_materialx
def test_materialx_unknown_declared_encoding_is_one_line(tmp_path):
    text = mtlx_chain(2).replace('version="1.0"?>', 'version="1.0" encoding="x-no-such-codec"?>')
    (tmp_path / "m.mtlx").write_text(text)
    with pytest.raises(MatremapError) as e:
        read_asset(tmp_path / "m.mtlx")
    assert "\n" not in str(e.value)


@needs_materialx
def test_materialx_huge_value_is_quoted_short(tmp_path, capsys):
    (tmp_path / "m.mtlx").write_text(mtlx_chain(2, value="9" * 1_000_000 + "x"))
    assert main(["remap", str(tmp_path / "m.mtlx"), "--to", "gltf:metal-rough", "-o", str(tmp_path / "out")]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert len(line) <= MAX_LINE + 60
    assert "characters cut" in line


# -- special files and names --------------------------------------------------------------------------


@needs_materialx
def test_materialx_fifo_texture_is_named_a_fifo(tmp_path):
    image = '<image name="n0" type="color3"><input name="file" type="filename" value="tex.png"/></image>'
    (tmp_path / "m.mtlx").write_text(mtlx_chain(2, first=image))
    os.mkfifo(tmp_path / "tex.png")
    with pytest.raises(MatremapError, match="is a FIFO"):
        read_asset(tmp_path / "m.mtlx")


def test_mitsuba_fifo_bitmap_is_named_a_fifo(tmp_path):
    (tmp_path / "s.xml").write_text(
        '<scene version="3.0.0"><bsdf type="diffuse"><texture type="bitmap" name="reflectance">'
        '<string name="filename" value="tex.png"/></texture></bsdf></scene>'
    )
    os.mkfifo(tmp_path / "tex.png")
    with pytest.raises(MatremapError, match="is a FIFO"):
        read_asset(tmp_path / "s.xml")


def test_mitsuba_fifo_include_is_named_a_fifo(tmp_path):
    (tmp_path / "s.xml").write_text('<scene version="3.0.0"><include filename="i.xml"/><bsdf type="diffuse"/></scene>')
    os.mkfifo(tmp_path / "i.xml")
    with pytest.raises(MatremapError, match="is a FIFO"):
        load_scene(tmp_path / "s.xml")


def non_utf8_folder(tmp_path: Path) -> Path:
    """A folder whose name holds the byte 0xff (not UTF-8), with a textured glTF in it."""
    sys.path.insert(0, str(TESTS.parent / "benchmarks"))
    try:
        from hostile_inputs import textured_gltf
    finally:
        sys.path.pop(0)
    src = textured_gltf(tmp_path / "asset", "base.png")
    folder = Path(os.fsdecode(os.fsencode(tmp_path) + b"/a\xff"))
    os.rename(tmp_path / "asset", folder)
    return folder / src.name


def test_cli_non_utf8_folder_is_one_clean_line(tmp_path, capsys):
    src = non_utf8_folder(tmp_path)
    assert main(["remap", str(src), "--to", "mitsuba06:ward", "-o", str(tmp_path / "out")]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert "a\\xff" in line and "UTF-8" in line
    assert not (tmp_path / "out").exists()


def test_cli_non_utf8_output_refused_before_work(tmp_path, capsys):
    (tmp_path / "m.xml").write_text('<scene version="3.0.0"><bsdf type="diffuse"/></scene>')
    out = os.fsdecode(os.fsencode(tmp_path) + b"/out\xfe")
    assert main(["remap", str(tmp_path / "m.xml"), "--to", "mitsuba06:diffuse", "-o", out]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert line.startswith("matremap: error: -o ") and "out\\xfe" in line
    assert sorted(os.listdir(tmp_path)) == ["m.xml"]


def test_printed_paths_keep_their_bytes(monkeypatch):
    """After the command line set up its streams, a file name that is not UTF-8 prints as its own bytes."""
    raw = io.BytesIO()
    monkeypatch.setattr(sys, "stdout", io.TextIOWrapper(raw, encoding="utf-8"))
    assert main(["models"]) == 0
    print(os.fsdecode(b"wrote out/m\xff.xml"))
    sys.stdout.flush()
    assert raw.getvalue().endswith(b"wrote out/m\xff.xml\n")


# -- the environment: a full disk, refused folders ------------------------------------------------------


@pytest.mark.parametrize(
    "code, filename", [(errno.ENOSPC, False), (errno.EDQUOT, False), (errno.ENOSPC, True)], ids=str
)
def test_full_disk_is_exit_4_naming_the_folder(tmp_path, capsys, monkeypatch, code, filename):
    import matremap.core.imageio as imageio

    def full(path, data):
        Path(path).write_bytes(b"half")  # a partial file, then the disk is full
        raise OSError(code, os.strerror(code), *([path] if filename else []))

    monkeypatch.setattr(imageio, "_oiio_write", full)
    (tmp_path / "images").mkdir()
    out = tmp_path / "images" / "probe.png"
    assert main(["render", "mitsuba06:diffuse,reflectance=0.5", "--size", "16", "-o", str(out)]) == 4
    line = one_error_line(capsys.readouterr().err)
    assert f"holding {tmp_path / 'images'} " in line and "is full" in line and "free space" in line
    assert ".matremap-" not in line
    assert list((tmp_path / "images").iterdir()) == []  # nothing half-written


def test_sqlite_full_is_exit_4(tmp_path, capsys, monkeypatch):
    """SQLite's own "database or disk is full" (its page limit reached mid-sweep) is the environment."""
    from matremap.sweep import store

    sys.path.insert(0, str(TESTS))
    try:
        from test_sweep import GRID, SWEEP_ARGS
    finally:
        sys.path.pop(0)
    connect = store.SweepStore._connect

    def small(p: Path) -> sqlite3.Connection:
        conn = connect(p)
        conn.execute(f"PRAGMA max_page_count={conn.execute('PRAGMA page_count').fetchone()[0] + 8}")
        return conn

    monkeypatch.setattr(store.SweepStore, "_connect", staticmethod(small))
    db = tmp_path / "s.sqlite"
    assert main([*SWEEP_ARGS, "--grid", GRID, "--db", str(db), "--workers", "1"]) == 4
    line = one_error_line(capsys.readouterr().err, alone=False)  # after the sweep's first line
    assert "database or disk is full" in line and f"holding {tmp_path} " in line


def test_read_only_output_parent_is_cannot_write(tmp_path, capsys, monkeypatch):
    """The system refusing a file in the folder written into is "cannot write" that folder, not "cannot
    read" a hidden temporary name (simulated: the tests may run as root, whom permissions do not stop)."""
    ro = tmp_path / "ro"
    ro.mkdir()
    mkstemp = tempfile.mkstemp

    def refused(suffix=None, prefix=None, dir=None, text=False):
        if dir is not None and Path(dir) == ro:
            raise PermissionError(errno.EACCES, "Permission denied", os.path.join(dir, f"{prefix}abcdefgh{suffix}"))
        return mkstemp(suffix, prefix, dir, text)

    monkeypatch.setattr(tempfile, "mkstemp", refused)
    assert main(["render", "mitsuba06:diffuse,reflectance=0.5", "--size", "16", "-o", str(ro / "p.png")]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert line.startswith(f"matremap: error: cannot write {ro}") and ".matremap-" not in line


@needs_materialx
def test_write_into_a_subfolder_is_refused_before_work(tmp_path, capsys):
    (tmp_path / "m.mtlx").write_text(mtlx_chain(2))
    args = ["remap", str(tmp_path / "m.mtlx"), "--to", "gltf:metal-rough", "-o", str(tmp_path / "out")]
    assert main([*args, "--write", "a/b/c.gltf"]) == 2
    line = one_error_line(capsys.readouterr().err)  # one line: no fit ran first
    assert "--write c.gltf" in line and ".matremap-" not in line
    assert sorted(os.listdir(tmp_path)) == ["cache", "m.mtlx"] or sorted(os.listdir(tmp_path)) == ["m.mtlx"]


# -- the line itself ------------------------------------------------------------------------------------


def test_one_line_is_short_printable_and_keeps_the_fix():
    message = "value " + "x" * 10**6 + "\nis bad; fix it"
    line = one_line(message)
    assert "\n" not in line and len(line) <= MAX_LINE + 40 and line.endswith("is bad; fix it")
    assert one_line(os.fsdecode(b"cannot read a\xff.png")) == "cannot read a\\xff.png"
    hidden = "cannot write /t/.matremap-partial-123x456-out-ab_d5fgh/a/c.gltf and /t/.matremap-tmp-1-m-abcdefgh.png"
    assert one_line(hidden) == "cannot write /t/out/a/c.gltf and /t/m.png"
    assert shorten("y" * 1000).count("y") < 100


def test_gltf_fifo_image_is_named_a_fifo(tmp_path):
    sys.path.insert(0, str(TESTS.parent / "benchmarks"))
    try:
        from hostile_inputs import textured_gltf
    finally:
        sys.path.pop(0)
    src = textured_gltf(tmp_path / "asset", "base.png")
    (tmp_path / "asset" / "base.png").unlink()
    os.mkfifo(tmp_path / "asset" / "base.png")
    with pytest.raises(MatremapError, match="is a FIFO"):
        read_asset(src)
