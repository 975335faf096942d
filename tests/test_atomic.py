"""AtomicFiles: a group of files is written entirely or not at all."""

from __future__ import annotations

import os
import stat
import subprocess
import sys

import pytest

from matremap.core import atomic
from matremap.core.atomic import STAGING_PREFIX, AtomicFiles
from matremap.errors import MatremapError


def listing(folder):
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


def test_files_appear_together_when_the_block_ends(tmp_path):
    with AtomicFiles() as files:
        files.write_bytes(tmp_path / "a.bin", b"\0\1")
        staged = files.stage(tmp_path / "b.png")
        staged.write_bytes(b"png")
        assert staged.name == "b.png" and staged.parent.parent.name.startswith(STAGING_PREFIX)
        files.copy(staged, tmp_path / "c.png")
        files.write_text(tmp_path / "main.gltf", "{}")
        assert not (tmp_path / "a.bin").exists() and not (tmp_path / "main.gltf").exists()  # nothing yet
        assert files.destinations == [tmp_path / n for n in ("a.bin", "b.png", "c.png", "main.gltf")]
    assert listing(tmp_path) == ["a.bin", "b.png", "c.png", "main.gltf"]  # and no staging folder
    assert (tmp_path / "a.bin").read_bytes() == b"\0\1" and (tmp_path / "c.png").read_bytes() == b"png"
    assert (tmp_path / "main.gltf").read_text() == "{}"


def test_a_failure_in_the_block_leaves_nothing(tmp_path):
    (tmp_path / "keep.txt").write_text("mine")
    with pytest.raises(ValueError, match="encoding failed"), AtomicFiles() as files:
        files.write_bytes(tmp_path / "a.png", b"a")
        files.write_bytes(tmp_path / "b.png", b"b")
        raise ValueError("encoding failed")
    assert listing(tmp_path) == ["keep.txt"]


def test_an_interrupt_leaves_nothing(tmp_path):
    with pytest.raises(KeyboardInterrupt), AtomicFiles() as files:
        files.write_bytes(tmp_path / "a.png", b"a")
        raise KeyboardInterrupt
    assert listing(tmp_path) == []


def test_an_existing_file_is_refused_before_anything_is_written(tmp_path):
    (tmp_path / "b.png").write_bytes(b"old")
    with pytest.raises(MatremapError) as e, AtomicFiles() as files:
        files.write_bytes(tmp_path / "a.png", b"a")
        files.write_bytes(tmp_path / "b.png", b"new")
    assert str(e.value) == f"{tmp_path / 'b.png'} already exists; pass --force to overwrite it"
    assert listing(tmp_path) == ["b.png"] and (tmp_path / "b.png").read_bytes() == b"old"


def test_check_refuses_up_front_and_the_hint_can_be_changed(tmp_path):
    (tmp_path / "x.exr").write_bytes(b"old")
    files = AtomicFiles(exists_hint="choose an empty output folder or pass --force")
    with pytest.raises(MatremapError, match=r"x\.exr already exists; choose an empty output folder or pass --force"):
        files.check(tmp_path / "x.exr")
    assert files.check(tmp_path / "y.exr") == tmp_path / "y.exr"
    assert AtomicFiles(force=True).check(tmp_path / "x.exr") == tmp_path / "x.exr"
    with pytest.raises(MatremapError, match="folder .* does not exist"):
        files.check(tmp_path / "nope" / "y.exr")
    assert listing(tmp_path) == ["x.exr"]


def test_force_replaces_existing_files(tmp_path):
    (tmp_path / "a.png").write_bytes(b"old")
    with AtomicFiles(force=True) as files:
        files.write_bytes(tmp_path / "a.png", b"new")
        files.write_bytes(tmp_path / "b.png", b"b")
    assert listing(tmp_path) == ["a.png", "b.png"] and (tmp_path / "a.png").read_bytes() == b"new"


def test_a_file_that_appears_meanwhile_is_not_clobbered(tmp_path):
    with pytest.raises(MatremapError, match="already exists"), AtomicFiles() as files:
        files.write_bytes(tmp_path / "a.png", b"a")
        files.write_bytes(tmp_path / "b.png", b"b")
        (tmp_path / "b.png").write_bytes(b"someone else's")
    assert listing(tmp_path) == ["b.png"] and (tmp_path / "b.png").read_bytes() == b"someone else's"


def test_a_failed_move_takes_back_every_file_and_restores_replaced_ones(tmp_path, monkeypatch):
    (tmp_path / "a.png").write_bytes(b"old a")
    real = os.replace
    calls = []

    def replace(src, dst):
        calls.append(dst)
        if str(dst) == str(tmp_path / "c.gltf"):
            raise OSError("disk full")
        real(src, dst)

    monkeypatch.setattr(atomic.os, "replace", replace)
    with pytest.raises(OSError, match="disk full"), AtomicFiles(force=True) as files:
        files.write_bytes(tmp_path / "a.png", b"new a")
        files.write_bytes(tmp_path / "b.png", b"b")
        files.write_bytes(tmp_path / "c.gltf", b"main")
    assert tmp_path / "b.png" in calls  # a.png and b.png were moved before c.gltf failed
    assert listing(tmp_path) == ["a.png"] and (tmp_path / "a.png").read_bytes() == b"old a"


def test_a_staged_file_never_written_fails_the_group(tmp_path):
    with pytest.raises(MatremapError, match=r"cannot write .*b\.png: nothing was written"), AtomicFiles() as files:
        files.write_bytes(tmp_path / "a.png", b"a")
        files.stage(tmp_path / "b.png")
    assert listing(tmp_path) == []


def test_one_destination_is_staged_once(tmp_path):
    with pytest.raises(MatremapError, match="two outputs would be written to"), AtomicFiles(force=True) as files:
        files.write_bytes(tmp_path / "a.png", b"a")
        files.write_bytes(tmp_path / "a.png", b"b")
    assert listing(tmp_path) == []


def test_folders_are_made_on_request_and_removed_with_a_failed_group(tmp_path):
    out = tmp_path / "new" / "maps"
    with pytest.raises(MatremapError, match="does not exist"), AtomicFiles() as files:
        files.write_bytes(out / "a.png", b"a")
    with pytest.raises(RuntimeError), AtomicFiles(make_folders=True) as files:
        files.write_bytes(out / "a.png", b"a")
        raise RuntimeError
    assert listing(tmp_path) == []
    with AtomicFiles(make_folders=True) as files:
        files.write_bytes(out / "a.png", b"a")
    assert listing(tmp_path) == ["new", "new/maps", "new/maps/a.png"]


def test_files_in_several_folders(tmp_path):
    (tmp_path / "one").mkdir()
    (tmp_path / "two").mkdir()
    with pytest.raises(RuntimeError), AtomicFiles() as files:
        files.write_bytes(tmp_path / "one" / "a", b"a")
        files.write_bytes(tmp_path / "two" / "b", b"b")
        raise RuntimeError
    assert listing(tmp_path) == ["one", "two"]
    with AtomicFiles() as files:
        files.write_bytes(tmp_path / "one" / "a", b"a")
        files.write_bytes(tmp_path / "two" / "b", b"b")
    assert listing(tmp_path) == ["one", "one/a", "two", "two/b"]


@pytest.mark.skipif(not hasattr(os, "umask"), reason="POSIX permissions")
def test_files_get_the_permissions_of_a_new_file(tmp_path):
    umask = os.umask(0o022)
    try:
        with AtomicFiles() as files:
            files.write_bytes(tmp_path / "a.png", b"a")
            staged = files.stage(tmp_path / "b.png")
            staged.write_bytes(b"b")
            os.chmod(staged, 0o600)  # as tempfile.mkstemp makes them
    finally:
        os.umask(umask)
    for name in ("a.png", "b.png"):
        assert stat.S_IMODE((tmp_path / name).stat().st_mode) == 0o644


def test_another_process_can_write_a_staged_file(tmp_path):
    with AtomicFiles() as files:
        staged = files.stage(tmp_path / "band.txt")
        subprocess.run([sys.executable, "-c", f"open({str(staged)!r}, 'w').write('rows')"], check=True)
    assert (tmp_path / "band.txt").read_text() == "rows"


def test_staging_is_only_inside_the_block(tmp_path):
    files = AtomicFiles()
    with pytest.raises(RuntimeError, match="inside a `with AtomicFiles"):
        files.stage(tmp_path / "a.png")
    with files:
        pass
    with pytest.raises(RuntimeError, match="used once"), files:
        pass


def test_staged_folder_appears_whole_or_not_at_all(tmp_path):
    from matremap.core.atomic import staged_folder

    out = tmp_path / "out"
    with pytest.raises(RuntimeError):
        with staged_folder(out) as stage:
            (stage / "maps").mkdir()
            (stage / "maps" / "a.png").write_bytes(b"x")
            raise RuntimeError("the renderer died")
    assert not out.exists() and list(tmp_path.iterdir()) == []  # nothing left, not even the staging folder
    with staged_folder(out) as stage:  # the retry needs no force
        (stage / "a.txt").write_text("1")
        assert not out.exists()  # nothing visible until the block ends
    assert (out / "a.txt").read_text() == "1"
    with pytest.raises(MatremapError, match="not empty; pass --force"):
        with staged_folder(out):
            pass
    with staged_folder(out, force=True) as stage:
        (stage / "b.txt").write_text("2")
    assert sorted(p.name for p in out.iterdir()) == [".matremap.json", "b.txt"]  # replaced whole, with its record
    assert [p.name for p in tmp_path.iterdir()] == ["out"]


# -- killed at any point (issue 19, finding 8 and must-have 6) ------------------------------------------------

# A child process that writes a group (one file replaced and one added in an existing folder, a folder that
# does not exist yet) or swaps a whole folder in, and SIGKILLs itself right after its Nth os.replace (N < 0:
# right before the first): every point of the commit where the files on disk change. N = 0 runs to the
# end and prints how many renames there were.
KILLED_AT = r"""
import os, signal, sys
from pathlib import Path
from matremap.core import atomic

out, n, what = Path(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
calls, real = [0], os.replace


def replace(src, dst):
    calls[0] += 1
    if n < 0:
        os.kill(os.getpid(), signal.SIGKILL)
    real(src, dst)
    if calls[0] == n:
        os.kill(os.getpid(), signal.SIGKILL)


os.replace = replace
if what == "group":
    with atomic.AtomicFiles(force=True, make_folders=True) as files:
        files.write_bytes(out / "one" / "a.png", b"new a")
        files.write_bytes(out / "one" / "b.png", b"new b")
        files.write_bytes(out / "two" / "c.gltf", b"new c")
elif what == "folder":
    with atomic.staged_folder(out / "result", force=True) as stage:
        (stage / "x.txt").write_text("new")
else:  # recover what an earlier child left, killed again at the Nth rename
    for folder in (out / "one", out):
        atomic.clean_stale(folder)
print(calls[0])
"""


def killed_at(tmp_path, n: int, what: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    return subprocess.run(
        [sys.executable, "-c", KILLED_AT, str(tmp_path), str(n), what], env=env, capture_output=True, text=True
    )


def group_state(tmp_path) -> str:
    """'previous', 'complete' or what else the visible files are (marked temporary entries aside)."""
    files = {
        str(p.relative_to(tmp_path)): p.read_bytes()
        for p in tmp_path.rglob("*")
        if p.is_file() and not any(part.startswith(atomic.MARK) for part in p.relative_to(tmp_path).parts)
    }
    if files == {"one/a.png": b"old a"}:
        return "previous"
    if files == {"one/a.png": b"new a", "one/b.png": b"new b", "two/c.gltf": b"new c"}:
        return "complete"
    return f"mixed: {files}"


def marked(tmp_path) -> list[str]:
    return [str(p.relative_to(tmp_path)) for p in tmp_path.rglob(".matremap-*")]


def previous_group(tmp_path) -> None:
    (tmp_path / "one").mkdir(parents=True)
    (tmp_path / "one" / "a.png").write_bytes(b"old a")


def test_a_group_killed_at_any_rename_is_put_right_by_the_next_run(tmp_path):
    previous_group(tmp_path / "count")
    renames = int(killed_at(tmp_path / "count", 0, "group").stdout)
    assert renames >= 6  # two journals, a file moved aside, two files and a folder moved in
    for n in [-1, *range(1, renames + 1)]:
        folder = tmp_path / f"killed-{n}"
        previous_group(folder)
        p = killed_at(folder, n, "group")
        assert p.returncode == -9, p.stderr
        assert marked(folder), n  # the dead run's staging is there
        start = folder / ("one" if n % 2 else "")  # from the first folder or from the second: the same
        atomic.clean_stale(start)
        atomic.clean_stale(folder / "one")
        atomic.clean_stale(folder)
        assert group_state(folder) in ("previous", "complete"), n
        assert marked(folder) == [], n
        if group_state(folder) == "previous":  # the run again, without force for the new files
            with AtomicFiles(force=True, make_folders=True) as files:
                files.write_bytes(folder / "one" / "a.png", b"new a")
                files.write_bytes(folder / "one" / "b.png", b"new b")
                files.write_bytes(folder / "two" / "c.gltf", b"new c")
            assert group_state(folder) == "complete" and marked(folder) == []


def test_a_recovery_killed_at_any_rename_is_finished_by_the_next(tmp_path):
    previous_group(tmp_path / "count")
    renames = int(killed_at(tmp_path / "count", 0, "group").stdout)
    middle = renames  # killed with every file moved but the group not yet marked committed
    previous_group(tmp_path / "count2")
    killed_at(tmp_path / "count2", middle, "group")
    undo = int(killed_at(tmp_path / "count2", 0, "recover").stdout)
    assert undo >= 3 and group_state(tmp_path / "count2") == "previous"
    for m in range(1, undo + 1):
        folder = tmp_path / f"killed-{m}"
        previous_group(folder)
        killed_at(folder, middle, "group")
        assert killed_at(folder, m, "recover").returncode == -9
        atomic.clean_stale(folder / "one")
        atomic.clean_stale(folder)
        assert group_state(folder) == "previous" and marked(folder) == [], m


def test_a_folder_swap_killed_at_any_rename_leaves_the_old_or_the_new_folder(tmp_path):
    def previous(folder):  # an output matremap wrote (it carries the record)
        (folder / "result").mkdir(parents=True)
        (folder / "result" / "x.txt").write_text("old")
        atomic.record_written(folder / "result")

    previous(tmp_path / "count")
    renames = int(killed_at(tmp_path / "count", 0, "folder").stdout)
    assert renames == 2 and (tmp_path / "count" / "result" / "x.txt").read_text() == "new"
    for n, expected in ((-1, "old"), (1, "old"), (2, "new")):  # 1: the old folder moved aside, the new not in
        folder = tmp_path / f"killed-{n}"
        previous(folder)
        assert killed_at(folder, n, "folder").returncode == -9
        assert marked(folder)
        atomic.clean_stale(folder)
        assert (folder / "result" / "x.txt").read_text() == expected
        assert marked(folder) == []


def test_a_live_runs_files_are_never_touched(tmp_path):
    staging = tmp_path / (atomic.temp_prefix("staging") + "abc")
    staging.mkdir()
    (tmp_path / (atomic.temp_prefix("tmp", "a") + "x.png")).write_bytes(b"being written")
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        other = tmp_path / f"{atomic.MARK}partial-{atomic.owner_token(child.pid)}-out-x"
        other.mkdir()
        assert atomic.clean_stale(tmp_path) == []
        assert staging.is_dir() and other.is_dir() and len(list(tmp_path.iterdir())) == 3
    finally:
        child.kill()
        child.wait()
    assert atomic.clean_stale(tmp_path) == [other] and not other.exists()  # dead now


def test_a_reused_process_id_is_not_its_old_owner(tmp_path):
    """The mark carries the process's start time: a live process with the dead one's id is another one."""
    token = atomic.owner_token()
    if "x" not in token:
        pytest.skip("this system does not give process start times")
    pid, start = token.split("x")
    stale = tmp_path / f"{atomic.MARK}partial-{pid}x{int(start) - 1}-out-x"
    stale.mkdir()
    assert atomic.clean_stale(tmp_path) == [stale] and not stale.exists()


def test_a_partial_folder_of_an_exited_but_unreaped_owner_is_removed(tmp_path):
    """A killed worker whose new parent has not reaped it yet (a zombie) writes nothing more: its leftovers go."""
    import time
    from pathlib import Path

    child = subprocess.Popen([sys.executable, "-c", "pass"])
    token = atomic.owner_token(child.pid)
    stat = Path(f"/proc/{child.pid}/stat")
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and stat.read_text().rsplit(")", 1)[1].split()[0] != "Z":
        time.sleep(0.02)  # exited, not waited for: a zombie
    try:
        left = tmp_path / f"{atomic.MARK}partial-{token}-out-x"
        left.mkdir()
        assert atomic.clean_stale(tmp_path) == [left] and not left.exists()
    finally:
        child.wait()
