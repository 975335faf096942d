"""``-o OUT`` never removes what matremap did not write: ``--force`` replaces only a folder carrying
matremap's output record, and no output folder may be, hold or lie inside an input, a file an input
references, or the cache (:func:`matremap.core.atomic.staged_folder`)."""

import json
import shutil
from pathlib import Path

import pytest

from matremap.cli import main
from matremap.core import atomic
from matremap.errors import MatremapError

ROOT = Path(__file__).resolve().parents[1]
BRASS = ROOT / "examples" / "brass-gltf"
GOLD = ROOT / "tests" / "data" / "corpus" / "mtlx-gltf_pbr_gold" / "gltf_pbr_gold.mtlx"


def tree(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` with its bytes."""
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def run(args: list[str], capsys) -> tuple[int, str]:
    code = main(args)
    return code, capsys.readouterr().err


@pytest.fixture()
def project(tmp_path, monkeypatch):
    """A user's project: ``proj/in`` holds the brass glTF with its textures in ``proj/in/tex``, and the
    project holds other work of the user's."""
    monkeypatch.setenv("MATREMAP_CACHE", str(tmp_path / "cache"))
    proj = tmp_path / "proj"
    (proj / "in" / "tex").mkdir(parents=True)
    doc = json.loads((BRASS / "brass.gltf").read_text())
    for image in doc["images"]:
        shutil.copy(BRASS / image["uri"], proj / "in" / "tex" / image["uri"])
        image["uri"] = "tex/" + image["uri"]
    (proj / "in" / "brass.gltf").write_text(json.dumps(doc))
    (proj / "notes.txt").write_text("the user's notes")
    (proj / "other").mkdir()
    (proj / "other" / "scene.blend").write_bytes(b"the user's scene")
    return proj


@pytest.mark.parametrize(
    "out",
    [
        ".",  # the project: holds the input
        "in",  # the input's own folder
        "in/tex",  # the folder of the textures the input references
    ],
)
def test_force_never_removes_an_input_or_its_textures(project, capsys, out):
    before = tree(project)
    code, err = run(
        ["remap", str(project / "in" / "brass.gltf"), "--to", "mitsuba06:ward", "-o", str(project / out), "--force"],
        capsys,
    )
    assert code == 2, err
    errors = [line for line in err.splitlines() if line.startswith("matremap: error")]
    assert len(errors) == 1 and ("which the run reads" in err or "input file's folder" in err), err
    assert tree(project) == before


def test_force_never_removes_a_map_set_it_reads(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("MATREMAP_CACHE", str(tmp_path / "cache"))
    proj = tmp_path / "proj"
    shutil.copytree(ROOT / "examples" / "blue-plastic", proj / "maps")
    (proj / "notes.txt").write_text("mine")
    before = tree(proj)
    for out in (proj, proj / "maps", proj / "maps" / "out"):
        code, err = run(["remap", str(proj / "maps"), "--to", "mitsuba06:pbr", "-o", str(out), "--force"], capsys)
        assert code == 2 and "which the run reads" in err, err
    assert tree(proj) == before


def test_force_refuses_a_folder_of_the_users(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("MATREMAP_CACHE", str(tmp_path / "cache"))
    out = tmp_path / "work"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    code, err = run(["remap", str(GOLD), "--to", "gltf:metal-rough", "-o", str(out), "--force"], capsys)
    assert code == 2 and "matremap did not write (keep.txt)" in err, err
    assert tree(out) == {"keep.txt": b"mine"}


def test_force_replaces_matremaps_own_output_but_not_a_file_added_to_it(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("MATREMAP_CACHE", str(tmp_path / "cache"))
    out = tmp_path / "gold"
    args = ["remap", str(GOLD), "--to", "gltf:metal-rough", "-o", str(out)]
    assert run(args, capsys)[0] == 0
    first = tree(out)
    assert atomic.OUTPUT_RECORD in first and "gltf_pbr_gold.mtlx" in first
    code, err = run(args, capsys)  # without --force: refused, as before
    assert code == 2 and "pass --force" in err
    assert run([*args, "--force"], capsys)[0] == 0  # its own output: replaced
    assert tree(out) == first
    (out / "maps-of-mine").mkdir()
    (out / "maps-of-mine" / "a.png").write_bytes(b"mine")
    code, err = run([*args, "--force"], capsys)
    assert code == 2 and "maps-of-mine" in err, err
    assert (out / "maps-of-mine" / "a.png").read_bytes() == b"mine"


@pytest.mark.parametrize("where", ["cache", "above"])
def test_no_output_folder_is_the_cache(tmp_path, capsys, monkeypatch, where):
    cache = tmp_path / "home" / "cache"
    (cache / "transforms").mkdir(parents=True)
    (cache / "transforms" / "t.json").write_text("{}")
    monkeypatch.setenv("MATREMAP_CACHE", str(cache))
    out = {"cache": cache, "above": tmp_path / "home"}[where]
    code, err = run(["remap", str(GOLD), "--to", "gltf:metal-rough", "-o", str(out), "--force"], capsys)
    assert code == 2 and "which the run reads" in err, err
    assert (cache / "transforms" / "t.json").read_text() == "{}"


def test_the_record_lists_every_path_written(tmp_path):
    out = tmp_path / "out"
    with atomic.staged_folder(out) as stage:
        (stage / "maps").mkdir()
        (stage / "maps" / "a.exr").write_bytes(b"a")
        (stage / "verdict.json").write_text("{}")
    assert atomic.written_entries(out) == {"maps", "maps/a.exr", "verdict.json"}
    assert atomic.foreign_entries(out) == []
    atomic.record_written(out, ["log.txt"])  # a file added later by matremap itself
    (out / "log.txt").write_text("x")
    assert atomic.foreign_entries(out) == []
    (out / "maps" / "b.exr").write_bytes(b"b")
    assert atomic.foreign_entries(out) == ["maps/b.exr"]
    with pytest.raises(MatremapError, match=r"did not write \(maps/b\.exr\)"):
        with atomic.staged_folder(out, force=True):
            pass
    assert (out / "maps" / "b.exr").read_bytes() == b"b"


def test_a_forged_record_does_not_cover_more_than_it_lists(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "precious.txt").write_text("mine")
    (out / atomic.OUTPUT_RECORD).write_text(json.dumps({"written_by": "matremap", "entries": ["other"]}))
    with pytest.raises(MatremapError, match="precious.txt"):
        with atomic.staged_folder(out, force=True):
            pass
    (out / atomic.OUTPUT_RECORD).write_text("not json")
    with pytest.raises(MatremapError, match="precious.txt"):
        with atomic.staged_folder(out, force=True):
            pass
    assert (out / "precious.txt").read_text() == "mine"
