"""A batch against hostile inputs and careless invocations: change detection that reads only regular files a
material names, inside its folders, boundedly; an OUT that never holds what the batch reads nor the user's own
files; folders and text that any name fits; one batch at a time per OUT; workers that die with the batch and
leftovers that the next run removes."""

from __future__ import annotations

import fcntl
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

import matremap
from matremap.batch import LOCK_FILE, MAX_SLUG, References, expand_inputs, plan
from matremap.cli import main

SRC = str(Path(matremap.__file__).resolve().parents[1])
BRASS = Path(__file__).resolve().parents[1] / "examples" / "brass-gltf"
FAST_CLI = ["--rotations", "0:360:2", "--size", "48", "--env-lights", "32"]
MARK = ".matremap-"


def scene(folder: Path, name: str | bytes = "scene.xml") -> Path:
    """A Mitsuba scene of two uniform materials (fitted in seconds, no renderer needed)."""
    folder.mkdir(parents=True, exist_ok=True)
    path = Path(os.fsdecode(os.path.join(os.fsencode(folder), os.fsencode(name))))
    path.write_text(
        '<scene version="3.0.0">\n'
        '  <bsdf type="diffuse" id="wall"><rgb name="reflectance" value="0.6, 0.5, 0.4"/></bsdf>\n'
        '  <bsdf type="roughconductor" id="steel"><string name="material" value="Cr"/>'
        '<float name="alpha" value="0.2"/></bsdf>\n'
        "</scene>\n"
    )
    return path


def gltf(folder: Path, names: list[str], uri: str | None = None) -> Path:
    """A glTF of red dielectric materials called ``names`` (``uri``: an image its first one names)."""
    folder.mkdir(parents=True, exist_ok=True)
    pbr = {"baseColorFactor": [0.8, 0.1, 0.1, 1], "metallicFactor": 0.0, "roughnessFactor": 0.5}
    doc: dict = {"asset": {"version": "2.0"}, "materials": [{"name": n, "pbrMetallicRoughness": pbr} for n in names]}
    if uri is not None:
        doc["images"] = [{"uri": uri}]
    path = folder / "m.gltf"
    path.write_text(json.dumps(doc))
    return path


def listing(folder: Path) -> dict[str, bytes | None]:
    """Every entry under ``folder`` with its bytes (None for a folder)."""
    return {str(p.relative_to(folder)): (p.read_bytes() if p.is_file() else None) for p in sorted(folder.rglob("*"))}


def env_for(cache: Path) -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": SRC, "MATREMAP_CACHE": str(cache)}


def run(args: list[str], cwd: Path, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "matremap", *args],
        cwd=cwd,
        env=env_for(cwd / "cache"),
        capture_output=True,
        text=True,
        timeout=timeout,
    )


# -- change detection: only regular files the material names, inside its folders, read boundedly ---------------

_CHILD = """
import resource, sys
from pathlib import Path
resource.setrlimit(resource.RLIMIT_AS, (1 << 30, 1 << 30))
from matremap.batch import References
refs = References()
files = refs.files(Path(sys.argv[1]))
print(refs.digest(Path(sys.argv[1])))
print("\\n".join(str(p) for p in files[1:]))
"""


def key_in_child(file: Path) -> tuple[str, list[str]]:
    """A batch's key of ``file`` and the files it counted, computed in a child limited to 1 GB of address
    space and 60 s (a read that blocks or does not end fails here, not the test run)."""
    try:
        p = subprocess.run(
            [sys.executable, "-c", _CHILD, str(file)],
            env=env_for(file.parent / "cache"),
            capture_output=True,
            text=True,
            timeout=60,
        )
    except subprocess.TimeoutExpired:
        pytest.fail("computing the key did not end (a blocking read)")
    assert p.returncode == 0, p.stderr[-500:]
    digest, *files = p.stdout.splitlines()
    return digest, [f for f in files if f]


def test_a_fifo_named_by_the_material_is_not_read(tmp_path):
    src = gltf(tmp_path / "in", ["m"], uri="base.png")
    os.mkfifo(tmp_path / "in" / "base.png")  # nobody ever writes it: opening it for reading blocked for ever
    digest, files = key_in_child(src)
    assert files == []


def test_a_link_to_a_device_or_out_of_the_folder_is_not_read(tmp_path):
    outside = tmp_path / "secret.png"
    outside.write_bytes(b"first")
    src = gltf(tmp_path / "in", ["m"], uri="base.png")
    (tmp_path / "in" / "base.png").symlink_to("/dev/zero")  # read for ever (5.4 GB in 4 s)
    (tmp_path / "in" / "other.png").symlink_to(outside)
    src.write_text(src.read_text().replace('"base.png"', '"base.png"}, {"uri": "other.png"'))
    before, files = key_in_child(src)
    assert files == []
    outside.write_bytes(b"second")  # a file outside the asset folder is no part of the key
    assert key_in_child(src)[0] == before


def test_a_link_inside_the_folder_is_followed(tmp_path):
    src = gltf(tmp_path / "in", ["m"], uri="base.png")
    (tmp_path / "in" / "textures").mkdir()
    (tmp_path / "in" / "textures" / "real.png").write_bytes(b"first")
    (tmp_path / "in" / "base.png").symlink_to("textures/real.png")
    before, files = key_in_child(src)
    assert files == [str(tmp_path / "in" / "base.png")]
    (tmp_path / "in" / "textures" / "real.png").write_bytes(b"second")
    assert key_in_child(src)[0] != before


def test_a_huge_file_is_keyed_by_its_size_and_time_not_read(tmp_path):
    src = gltf(tmp_path / "in", ["m"], uri="base.png")
    big = tmp_path / "in" / "base.png"
    with big.open("wb") as f:
        f.truncate(2 << 30)  # sparse: 2 GB that the child (1 GB of address space) cannot hold
    before, files = key_in_child(src)
    assert files == [str(big)]
    os.utime(big, ns=(1, 1))  # touched: counted as changed
    assert key_in_child(src)[0] != before


# -- names: any file name and material name gives a folder and a summary ---------------------------------------


def test_a_file_name_that_is_not_utf8_converts_and_is_summarised(tmp_path, capsys):
    scene(tmp_path / "in", b"sc\xe9ne.xml")
    scene(tmp_path / "in", "plain.xml")
    out = tmp_path / "out"
    code = main(["remap", str(tmp_path / "in"), "--to", "mitsuba06:ward", "-o", str(out), *FAST_CLI])
    err = capsys.readouterr().err
    assert code == 0, err
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    assert {Path(i["file"]).name for i in summary["items"]} == {"sc\\xe9ne.xml", "plain.xml"}
    assert "sc\\xe9ne.xml" in (out / "summary.csv").read_text(encoding="utf-8")
    assert "sc\\xe9ne.xml" in (out / "index.html").read_text(encoding="utf-8")


def test_a_material_name_with_an_invalid_escape_is_summarised(tmp_path, capsys):
    src = tmp_path / "in"
    src.mkdir()
    pbr = '"pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.1, 0.1, 1], "metallicFactor": 0.0}'
    (src / "m.gltf").write_text(
        '{"asset": {"version": "2.0"}, "materials": [{"name": "bad \\ud800 name", '
        + pbr
        + '}, {"name": "ok", '
        + pbr
        + "}]}"
    )
    out = tmp_path / "out"
    code = main(["remap", str(src), "--to", "mitsuba06:ward", "-o", str(out), *FAST_CLI])
    capsys.readouterr()
    assert code in (0, 3)
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    assert sorted(i["material"] for i in summary["items"]) == ["bad \\ud800 name", "ok"]
    assert "bad \\ud800 name" in (out / "index.html").read_text(encoding="utf-8")
    assert (out / "summary.csv").is_file()


def test_a_long_material_name_gets_a_bounded_folder_and_a_record(tmp_path, capsys):
    long_a, long_b = "x" * 300, "x" * 299 + "y"  # alike for their first 299 characters: two folders still
    src = gltf(tmp_path / "in", [long_a, long_b])
    items = plan(expand_inputs([src]))
    assert len({i.slot for i in items}) == 2 and all(len(part) <= MAX_SLUG for i in items for part in i.slot.split("/"))
    out = tmp_path / "out"
    argv = ["remap", str(src), "--to", "mitsuba06:ward", "-o", str(out), *FAST_CLI]
    code = main(argv)
    capsys.readouterr()
    summary = json.loads((out / "summary.json").read_text())
    assert code in (0, 3) and not [i["reason"] for i in summary["items"] if i["verdict"] == "error"]
    assert all((out / i["slot"] / "item.json").is_file() for i in summary["items"])
    assert main(argv) == code
    assert "(2 unchanged, not redone)" in capsys.readouterr().out  # recorded: a rerun does not retry them


# -- OUT: never what the batch reads, never the user's own files ------------------------------------------------


def refused(argv: list[str], watched: Path, capsys) -> str:
    """Run ``argv``; assert exit 2, one line, and ``watched`` unchanged; return the line."""
    before = listing(watched)
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.count("\n") == 1, err
    assert listing(watched) == before
    return err


def test_out_that_is_or_holds_an_input_is_refused(tmp_path, capsys):
    src = tmp_path / "in"
    scene(src)
    scene(src / "sub", "other.xml")
    assert "is or holds the input" in refused(
        ["remap", str(src), "--to", "mitsuba06:ward", "-o", str(src)], src, capsys
    )
    argv = ["remap", str(src / "sub" / "other.xml"), str(src / "scene.xml"), "--to", "mitsuba06:ward", "-o", str(src)]
    assert "is or holds the input" in refused(argv, src, capsys)
    argv = ["remap", str(src / "sub" / "other.xml"), str(src / "scene.xml"), "--to", "mitsuba06:ward"]
    assert "is or holds the input" in refused([*argv, "-o", str(src / "scene.xml")], src, capsys)


def test_out_that_holds_a_texture_an_input_names_is_refused(tmp_path, capsys):
    src = tmp_path / "in"
    (src / "tex").mkdir(parents=True)
    (src / "tex" / "base.png").write_bytes(b"the user's texture")
    gltf(src, ["a", "b"], uri="tex/base.png")  # two materials: a batch
    err = refused(["remap", str(src / "m.gltf"), "--to", "mitsuba06:ward", "-o", str(src / "tex")], src, capsys)
    assert "base.png, which" in err


def test_out_that_overlaps_the_cache_is_refused(tmp_path, capsys, monkeypatch):
    src = tmp_path / "in"
    scene(src)
    cache = tmp_path / "c" / "cache"
    (cache / "tables").mkdir(parents=True)
    (cache / "tables" / "t.npz").write_bytes(b"cached")
    monkeypatch.setenv("MATREMAP_CACHE", str(cache))
    for out in (cache, cache.parent, cache / "tables"):  # the cache itself, a folder holding it, a folder in it
        err = refused(["remap", str(src), "--to", "mitsuba06:ward", "-o", str(out)], tmp_path / "c", capsys)
        assert "the cache folder" in err


def test_a_folder_of_the_users_files_is_not_written_into(tmp_path, capsys):
    src = tmp_path / "in"
    scene(src)
    for name, content in (("summary.csv", "the user's own table"), ("scene.xml/000-wall/notes.txt", "mine")):
        out = tmp_path / f"out-{name.split('/')[0]}"
        (out / name).parent.mkdir(parents=True, exist_ok=True)
        (out / name).write_text(content)
        err = refused(["remap", str(src), "--to", "mitsuba06:ward", "-o", str(out)], out, capsys)
        assert "other files than a matremap batch" in err
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["remap", str(src), "--to", "mitsuba06:ward", "-o", str(empty), *FAST_CLI]) == 0
    capsys.readouterr()


def test_a_batch_into_its_own_input_folder_converts_only_the_inputs(tmp_path, capsys):
    src = tmp_path / "in"
    gltf(src, ["red", "dark"])
    argv = ["remap", str(src), "--to", "gltf:metal-rough", "-o", str(src / "out"), *FAST_CLI, "--json"]
    counts = []
    for _ in range(3):
        code = main(argv)
        doc = json.loads(capsys.readouterr().out)
        assert code == 0
        counts.append(len(doc["items"]))
    assert counts == [2, 2, 2]  # its own outputs were converted again on every rerun (2, 5, 11)
    assert list(src.rglob("*.gltf")) != [src / "m.gltf"]  # whole files were written there, and left out
    other = tmp_path / "other"  # a folder matremap wrote is left out of another batch too, with a note
    assert main(["remap", str(src), "--to", "gltf:metal-rough", "-o", str(other), *FAST_CLI, "--json"]) == 0
    captured = capsys.readouterr()
    assert len(json.loads(captured.out)["items"]) == 2
    assert "folder(s) matremap wrote left out" in captured.err


def test_a_rerun_into_a_batchs_out_is_taken(tmp_path, capsys):
    """The OUT of a batch (its lock file, or a summary of a run before it had one) is the batch's own."""
    src = tmp_path / "in"
    scene(src)
    out = tmp_path / "out"
    argv = ["remap", str(src), "--to", "mitsuba06:ward", "-o", str(out), *FAST_CLI]
    assert main(argv) == 0
    assert (out / LOCK_FILE).is_file()
    (out / LOCK_FILE).unlink()
    assert main(argv) == 0
    assert "(2 unchanged, not redone)" in capsys.readouterr().out


# -- one batch at a time per OUT --------------------------------------------------------------------------------


def test_two_batches_into_one_out_do_each_item_once(tmp_path):
    src = tmp_path / "in"
    for i in range(2):
        scene(src / f"s{i}")
    argv = [sys.executable, "-m", "matremap", "remap", str(src), "--to", "mitsuba06:ward", "-o", str(tmp_path / "out")]
    procs = [
        subprocess.Popen(
            [*argv, *FAST_CLI, "--workers", "1"],
            env=env_for(tmp_path / f"cache{i}"),
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for i in range(2)
    ]
    outs = [p.communicate(timeout=600) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], outs
    todo = [int(err.split(" unchanged, ")[1].split(" to do")[0]) for _, err in outs]
    assert sorted(todo) == [0, 4], outs  # each item converted once: by the first; the second waited
    assert any("waiting: another batch" in err for _, err in outs)
    assert all("4 material(s): 4 passed" in o for o, _ in outs)


def test_a_batch_waits_for_the_lock_and_writes_nothing_meanwhile(tmp_path):
    src = tmp_path / "in"
    scene(src)
    out = tmp_path / "out"
    out.mkdir()
    fd = os.open(out / LOCK_FILE, os.O_RDWR | os.O_CREAT)
    fcntl.flock(fd, fcntl.LOCK_EX)  # another batch, holding OUT
    argv = [sys.executable, "-m", "matremap", "remap", str(src), "--to", "mitsuba06:ward", "-o", str(out), *FAST_CLI]
    log = tmp_path / "stderr.txt"
    with log.open("w") as err:
        proc = subprocess.Popen(argv, env=env_for(tmp_path / "cache"), stdout=subprocess.DEVNULL, stderr=err)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None and not (out / "scene.xml").exists():
            if "waiting: another batch" in log.read_text():
                time.sleep(2)  # ample time to start converting, were it not waiting
                break
            time.sleep(0.1)
        assert proc.poll() is None and sorted(p.name for p in out.iterdir()) == [LOCK_FILE], log.read_text()
    finally:
        os.close(fd)  # released: it goes on
    assert proc.wait(timeout=300) == 0, log.read_text()
    assert (out / "summary.json").is_file()


# -- orphans and leftovers --------------------------------------------------------------------------------------


def children(pid: int) -> set[int]:
    """The processes whose parent is ``pid``."""
    found = set()
    for stat_file in Path("/proc").glob("[0-9]*/stat"):
        try:
            text = stat_file.read_text()
        except OSError:
            continue
        if int(text[text.rfind(")") + 2 :].split()[1]) == pid:
            found.add(int(stat_file.parent.name))
    return found


def gone(pids: set[int], seconds: float = 15.0) -> bool:
    """Whether every process of ``pids`` ended within ``seconds``; the ones left are killed."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        alive = set()
        for pid in pids:
            try:
                state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
            except OSError:
                continue
            if state != "Z":
                alive.add(pid)
        if not alive:
            return True
        time.sleep(0.1)
    for pid in alive:
        os.kill(pid, signal.SIGKILL)
    return False


def brass_batch(tmp_path: Path, n: int = 4) -> tuple[list[str], Path]:
    src = tmp_path / "in"
    for i in range(n):  # textured materials, seconds each: a signal lands while some are being converted
        shutil.copytree(BRASS, src / f"brass{i}")
    out = tmp_path / "out"
    argv = [sys.executable, "-m", "matremap", "remap", str(src), "--to", "mitsuba06:ward", "-o", str(out)]
    return [*argv, "--rotations", "0:360:2", "--size", "64", "--workers", "2"], out


def staging(out: Path) -> bool:
    try:
        return any(p.name.startswith(MARK) for p in out.glob("*/*"))
    except OSError:
        return False


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM], ids=["SIGKILL", "SIGTERM"])
def test_the_workers_die_with_the_batch_and_the_rerun_cleans_up(tmp_path, sig):
    argv, out = brass_batch(tmp_path)
    cache = tmp_path / "cache"
    proc = subprocess.Popen(argv, env=env_for(cache), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 240
    while proc.poll() is None and not staging(out) and time.monotonic() < deadline:
        time.sleep(0.05)
    workers = children(proc.pid)
    assert proc.poll() is None and workers, "the batch finished before it could be stopped"
    proc.send_signal(sig)
    proc.wait(timeout=60)
    assert gone(workers), "workers outlived the batch"
    rerun = subprocess.run(argv, env=env_for(cache), capture_output=True, text=True, timeout=600)
    assert rerun.returncode == 0, rerun.stderr
    assert not [p for p in out.rglob("*") if p.name.startswith(MARK)]


def test_ctrl_c_leaves_no_staging_folder(tmp_path):
    argv, out = brass_batch(tmp_path)
    proc = subprocess.Popen(
        argv,
        env=env_for(tmp_path / "cache"),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),  # a background shell ignores SIGINT
    )
    deadline = time.monotonic() + 240
    while proc.poll() is None and not staging(out) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert proc.poll() is None, "the batch finished before it could be interrupted"
    os.killpg(proc.pid, signal.SIGINT)  # Ctrl-C: the whole foreground group
    _, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 130, stderr
    assert not [p for p in out.rglob("*") if p.name.startswith(MARK)], stderr  # two .matremap-partial-* were left


def test_references_skip_out_and_the_cache(tmp_path):
    """A texture name that also names a file the batch wrote (in OUT inside the input folder) is no part of the key."""
    src = gltf(tmp_path / "in", ["m"], uri="base.png")
    (tmp_path / "in" / "base.png").write_bytes(b"texture")
    (tmp_path / "in" / "out" / "m.gltf" / "m" / "source").mkdir(parents=True)
    written = tmp_path / "in" / "out" / "m.gltf" / "m" / "source" / "base.png"
    written.write_bytes(b"a copy the batch made")
    refs = References([], [tmp_path / "in" / "out"])
    assert refs.files(src) == [src, tmp_path / "in" / "base.png"]
