"""Writing several files all or nothing, even when the process is killed.

A material file often comes with files beside it (a glTF's textures and ``.bin``, the maps of a
Mitsuba scene or a MaterialX document, the maps of a converted map set). :class:`AtomicFiles`
writes such a group so that a reader never sees half of it::

    with AtomicFiles(force=force) as files:
        files.write_bytes(out_dir / "a_baseColor.png", png)
        files.write_text(out_dir / "a.gltf", text)   # stage the main file last: it is moved last

Each destination is refused up front if it already exists (unless ``force``) or its folder is
missing (unless ``make_folders``). Files are written under their own names into a hidden staging
folder beside their destination (same file system, so a rename moves them) and moved into place only
when the ``with`` block ends without an error. A destination folder that does not exist yet is staged
whole and appears with one rename. If the block fails, or a move fails, every staged file is removed,
files already moved are taken back (a file that ``force`` replaced is restored) and folders created
for the group are removed again: the destination looks as it did before. A file moved into place gets
the permissions a new file would get (``0o666`` less the umask). SIGINT is held back while the files
are moved (it is acted on once they are all in place).

**Killed processes.** Everything matremap writes beside an output before it is complete is named
``.matremap-<kind>-<owner>-...``, ``<owner>`` the writing process's id (and its start time, where the
system tells it, so that a reused id is not mistaken for it). Before the moves, each staging folder gets
a journal of what it will move (:data:`JOURNAL`); once every move is done, the first staging folder gets
a ``committed`` mark. Whoever next writes into that folder (:func:`clean_stale`) finds what a dead owner
left and puts it right: a staging folder without a journal, an unpublished whole folder or a temporary
file is removed; a group whose moves began but were not all done is taken back, from the journal, to
the state before it (the moves are undone one by one, in a way that a second interruption cannot spoil);
a folder :func:`staged_folder` was swapping in is restored or finished. So a SIGKILL at any moment leaves
the previous state or the complete result as soon as the next run starts, and that run needs no
``--force``. A process still alive is never touched.

:func:`atomic_output` is the one-file version of the same idea (its temporary
names carry the same mark).
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import tempfile
import threading
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from types import TracebackType

from matremap.errors import MatremapError

#: every temporary name matremap writes beside an output starts with this
MARK = ".matremap-"
#: prefix of the hidden staging folders of :class:`AtomicFiles`
STAGING_PREFIX = MARK + "staging-"
#: what the "already exists" error tells the user to do
FORCE_HINT = "pass --force to overwrite it"
#: the journal a staging folder holds while its files are moved
JOURNAL = "journal.json"
#: the mark the first staging folder of a group gets once every file is in place
COMMITTED = "committed"


# ---------------------------------------------------------------------------------------------
# owners


def _stat_fields(pid: int) -> list[str]:
    """The fields of ``/proc/PID/stat`` after the command name (Linux; proc(5)), or [] where the system has none."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return []
    return stat[stat.rfind(")") + 2 :].split()


def _start_time(pid: int) -> str:
    """The process's start time in clock ticks since boot (Linux), or "" where the system does not say."""
    fields = _stat_fields(pid)
    return fields[19] if len(fields) > 19 else ""


def _zombie(pid: int) -> bool:
    """Whether the process has exited and only waits to be reaped (state Z or X in proc(5)): it writes nothing more."""
    fields = _stat_fields(pid)
    return bool(fields) and fields[0] in ("Z", "X")


def owner_token(pid: int | None = None) -> str:
    """This process's mark in temporary names: ``<pid>`` or ``<pid>x<start time>``."""
    pid = os.getpid() if pid is None else pid
    start = _start_time(pid)
    return f"{pid}x{start}" if start else str(pid)


def temp_prefix(kind: str, stem: str = "") -> str:
    """The prefix of a temporary name of ``kind`` (staging, partial, old, tmp) owned by this process."""
    return f"{MARK}{kind}-{owner_token()}-" + (f"{stem}-" if stem else "")


def _alive(token: str) -> bool:
    """Whether the process a token names still runs (the same process: the same start time, where known)."""
    pid_text, _, start = token.partition("x")
    try:
        pid = int(pid_text)
    except ValueError:
        return True  # not a mark matremap wrote: leave it alone
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    if _zombie(pid):  # killed, not yet reaped (an orphan whose new parent reaps late)
        return False
    return not start or _start_time(pid) in ("", start)


def _owner(name: str) -> tuple[str, str] | None:
    """(kind, owner token) of a marked name, or None."""
    if not name.startswith(MARK):
        return None
    parts = name[len(MARK) :].split("-", 2)
    return (parts[0], parts[1]) if len(parts) >= 2 else None


@contextmanager
def atomic_output(path: Path) -> Iterator[str]:
    """Yield a temporary file name beside ``path``; on success it replaces ``path`` (with the
    permissions a new file would get), on failure it is removed. The name carries this process's mark
    (:func:`temp_prefix`), so that a run after a SIGKILL removes it."""
    fd, tmp = tempfile.mkstemp(prefix=temp_prefix("tmp", path.stem), suffix=path.suffix, dir=path.parent)
    os.close(fd)
    try:
        yield tmp
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


# ---------------------------------------------------------------------------------------------
# cleaning up after a dead owner


def clean_stale(folder: str | os.PathLike[str]) -> list[Path]:
    """Put right what dead matremap processes left in ``folder`` (see the module doc); returns what was
    handled. Never raises: what cannot be handled now is left for the next run."""
    handled: list[Path] = []
    try:
        entries = sorted(Path(folder).iterdir())
    except OSError:
        return handled
    for entry in entries:
        found = _owner(entry.name)
        if found is None or _alive(found[1]):
            continue
        with contextlib.suppress(OSError, ValueError):
            _clean(entry, found[0])
            handled.append(entry)
    return handled


def _clean(entry: Path, kind: str) -> None:
    if kind == "staging" and entry.is_dir():
        _recover_staging(entry)
    elif kind == "old" and entry.is_dir():
        _recover_old(entry)
    elif entry.is_dir() and not entry.is_symlink():
        shutil.rmtree(entry)
    elif entry.exists() or entry.is_symlink():
        entry.unlink()


def _recover_staging(staging: Path) -> None:
    """A dead group's staging folder: nothing moved yet (no journal) -> removed; moves begun -> the whole
    group taken back (every folder of it, from the first staging folder's journal), unless it was
    marked committed, then its staging folders are removed."""
    journal = _read_journal(staging)
    if journal is None:
        shutil.rmtree(staging)
        return
    primary = Path(journal["primary"])
    if primary != staging:
        if primary.is_dir():
            _recover_staging(primary)  # it handles this folder too
        if staging.exists():  # the group was decided and its first folder removed: nothing to take back
            _remove(staging)
        return
    committed = (staging / COMMITTED).exists()
    for folder in reversed([Path(p) for p in journal["stagings"]]):
        if folder.is_dir():
            if not committed:
                _take_back(folder)
            _remove(folder)


def _read_journal(staging: Path) -> dict | None:
    try:
        doc = json.loads((staging / JOURNAL).read_text())
    except FileNotFoundError:
        return None
    if not isinstance(doc, dict) or not {"primary", "stagings", "moves"} <= set(doc):
        raise ValueError(f"{staging / JOURNAL} is not a journal matremap wrote")
    return doc


def _take_back(staging: Path) -> None:
    """Undo the moves a staging folder's journal lists, each in two renames that a repeat undoes no
    further: the new file back into the staging folder, then the previous one (if any) into place."""
    journal = _read_journal(staging)
    if journal is None:
        return
    for dest_text, new_text, old_text in reversed(journal["moves"]):
        dest, new, old = Path(dest_text), Path(new_text), Path(old_text)
        if not (new.exists() or new.is_symlink()) and (dest.exists() or dest.is_symlink()):
            os.replace(dest, new)
        if old.exists() or old.is_symlink():
            os.replace(old, dest)


def _remove(staging: Path) -> None:
    """A staging folder removed, its journal first (so that no later run undoes a finished group)."""
    (staging / JOURNAL).unlink(missing_ok=True)
    shutil.rmtree(staging, ignore_errors=True)


def _recover_old(old: Path) -> None:
    """A folder :func:`staged_folder` moved aside to put a new one in its place: put back when the new
    one never arrived, else removed."""
    inside = [p for p in old.iterdir()]
    if len(inside) == 1 and not (old.parent / inside[0].name).exists():
        os.replace(inside[0], old.parent / inside[0].name)
    shutil.rmtree(old)


# ---------------------------------------------------------------------------------------------
# signals


@contextmanager
def _sigint_held() -> Iterator[None]:
    """SIGINT (and SIGTERM) held back while the block runs, then acted on (main thread, POSIX only)."""
    if not hasattr(signal, "pthread_sigmask") or threading.current_thread() is not threading.main_thread():
        yield
        return
    held = {signal.SIGINT, signal.SIGTERM}
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, held)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


# ---------------------------------------------------------------------------------------------
# a group of files


class AtomicFiles:
    """A group of files written together or not at all; a context manager (see the module doc).

    ``force``: replace existing destinations; ``make_folders``: create missing destination folders
    (and remove them again if the group fails); ``exists_hint``: the advice that follows
    "<file> already exists; " when a destination exists without ``force``.
    """

    def __init__(self, force: bool = False, *, make_folders: bool = False, exists_hint: str = FORCE_HINT) -> None:
        self.force = force
        self.make_folders = make_folders
        self.exists_hint = exists_hint
        self._staged: dict[Path, Path] = {}  # destination -> staged file, in staging order
        self._staging: dict[Path, Path] = {}  # destination folder -> its staging folder
        self._whole: set[Path] = set()  # destination folders staged whole (they did not exist)
        self._created: list[Path] = []  # folders made for the group, outermost first
        self._cleaned: set[Path] = set()
        self._open = False

    # -- the context -------------------------------------------------------------------------
    def __enter__(self) -> AtomicFiles:
        if self._open:
            raise RuntimeError("an AtomicFiles group is used once")
        self._open = True
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        try:
            if exc_type is None:
                self.commit()
            else:
                self._remove_created_folders()
        finally:
            self._remove_staging()

    # -- staging -----------------------------------------------------------------------------
    @property
    def destinations(self) -> list[Path]:
        """The destinations staged so far, in the order they will be moved into place."""
        return list(self._staged)

    def check(self, path: str | os.PathLike[str]) -> Path:
        """Refuse ``path`` as a destination now, before any work: it exists (without ``force``), or its
        folder is missing (without ``make_folders``). Returns it as a Path. What dead runs left in its
        folder (or the nearest existing one) is put right first (:func:`clean_stale`)."""
        p = Path(path)
        self._clean_once(next((f for f in p.parents if f.is_dir()), p.parent))
        if p in self._staged:
            raise MatremapError(f"two outputs would be written to {p}; give them different names")
        if not self.make_folders and not p.parent.is_dir():
            raise MatremapError(f"cannot write {p}: folder {p.parent} does not exist")
        if p.exists() and not self.force:
            raise MatremapError(f"{p} already exists; {self.exists_hint}")
        if p.is_dir():
            raise MatremapError(f"cannot write {p}: it is a folder")
        return p

    def _clean_once(self, folder: Path) -> None:
        if folder not in self._cleaned:
            self._cleaned.add(folder)
            clean_stale(folder)

    def stage(self, path: str | os.PathLike[str]) -> Path:
        """The file to write ``path``'s content to (same name, in the staging folder); nothing is
        created there. The caller (or a worker process it passes the name to) writes it before the
        group ends."""
        if not self._open:
            raise RuntimeError("stage files inside a `with AtomicFiles(...)` block")
        p = self.check(path)
        self._staged[p] = self._staging_folder(p.parent) / "new" / p.name
        return self._staged[p]

    def discard(self, path: str | os.PathLike[str]) -> None:
        """Leave ``path`` out of the group after all: its staged file is removed and nothing is moved there."""
        staged = self._staged.pop(Path(path), None)
        if staged is not None:
            staged.unlink(missing_ok=True)

    def write_bytes(self, path: str | os.PathLike[str], data: bytes) -> Path:
        """Stage ``path`` with ``data``; returns the destination."""
        self.stage(path).write_bytes(data)
        return Path(path)

    def write_text(self, path: str | os.PathLike[str], text: str) -> Path:
        """Stage ``path`` with ``text`` (UTF-8); returns the destination."""
        self.stage(path).write_text(text, encoding="utf-8")
        return Path(path)

    def copy(self, src: str | os.PathLike[str], path: str | os.PathLike[str]) -> Path:
        """Stage ``path`` as a byte copy of ``src``; returns the destination."""
        shutil.copyfile(src, self.stage(path))
        return Path(path)

    def _staging_folder(self, folder: Path) -> Path:
        """The staging folder of a destination folder: inside it, or beside it when it does not exist yet
        (then it is staged whole, as ``new``, and renamed into place in one step)."""
        if folder not in self._staging:
            whole = not folder.exists()
            if whole:
                self._make_folder(folder.parent)
                self._whole.add(folder)
            staging = Path(tempfile.mkdtemp(prefix=temp_prefix("staging"), dir=folder.parent if whole else folder))
            self._staging[folder] = staging
            (staging / "new").mkdir()
            (staging / "old").mkdir()
        return self._staging[folder]

    def _make_folder(self, folder: Path) -> None:
        missing = [f for f in (folder, *folder.parents) if not f.exists()]
        folder.mkdir(parents=True, exist_ok=True)
        self._created.extend(reversed(missing))

    # -- the end -----------------------------------------------------------------------------
    def commit(self) -> None:
        """Move every staged file into place (called when the ``with`` block ends without an error).
        On any failure, what was moved is taken back and the error is raised."""
        for dest, tmp in self._staged.items():
            if not tmp.is_file():
                raise MatremapError(f"cannot write {dest}: nothing was written for it")
            if dest.exists() and not self.force:  # it appeared while the group was being written
                raise MatremapError(f"{dest} already exists; {self.exists_hint}")
        umask = os.umask(0)
        os.umask(umask)
        for tmp in self._staged.values():
            os.chmod(tmp, 0o666 & ~umask)
        with _sigint_held():
            self._write_journals()
            try:
                for folder, staging in self._staging.items():
                    if folder in self._whole:
                        os.chmod(staging / "new", 0o777 & ~umask)
                        os.replace(staging / "new", folder)
                        continue
                    for dest, tmp in self._staged.items():
                        if dest.parent != folder:
                            continue
                        if dest.exists() or dest.is_symlink():
                            os.replace(dest, staging / "old" / dest.name)
                        os.replace(tmp, dest)
                if self._staging:
                    (next(iter(self._staging.values())) / COMMITTED).touch()
            except BaseException:
                for staging in reversed(self._staging.values()):
                    _take_back(staging)
                self._remove_created_folders()
                raise

    def _moves(self, folder: Path, staging: Path) -> list[tuple[str, str, str]]:
        """(destination, staged, previous-file place) of every move into ``folder``."""
        if folder in self._whole:
            return [(str(folder), str(staging / "new"), str(staging / "old" / folder.name))]
        return [
            (str(dest), str(tmp), str(staging / "old" / dest.name))
            for dest, tmp in self._staged.items()
            if dest.parent == folder
        ]

    def _write_journals(self) -> None:
        """Each staging folder's journal, written before the first move (see the module doc)."""
        stagings = [str(s) for s in self._staging.values()]
        for folder, staging in self._staging.items():
            doc = {"primary": stagings[0], "stagings": stagings, "moves": self._moves(folder, staging)}
            tmp = staging / (JOURNAL + ".tmp")
            tmp.write_text(json.dumps(doc))
            os.replace(tmp, staging / JOURNAL)

    def _remove_staging(self) -> None:
        for staging in reversed(self._staging.values()):  # the first one, holding the group's mark, last
            _remove(staging)
        self._staging.clear()

    def _remove_created_folders(self) -> None:
        self._remove_staging()
        for folder in reversed(self._created):
            try:
                folder.rmdir()
            except OSError:  # not empty: something else was put there meanwhile
                pass
        self._created.clear()


# ---------------------------------------------------------------------------------------------
# a whole folder


#: the record a published output folder carries of what matremap wrote in it (relative paths)
OUTPUT_RECORD = ".matremap.json"


def written_entries(folder: str | os.PathLike[str]) -> set[str] | None:
    """The relative paths (files and folders) the output record of ``folder`` lists, or None when the folder
    has no record matremap wrote."""
    try:
        doc = json.loads((Path(folder) / OUTPUT_RECORD).read_text())
    except (OSError, ValueError):
        return None
    entries = doc.get("entries") if isinstance(doc, dict) and doc.get("written_by") == "matremap" else None
    if not isinstance(entries, list) or not all(isinstance(e, str) for e in entries):
        return None
    return set(entries)


def _tree_entries(folder: Path) -> list[str]:
    """Every path under ``folder`` (files, folders, links), relative, sorted; links are not followed."""
    found = []
    for root, dirs, files in os.walk(folder):
        rel = Path(root).relative_to(folder)
        found += [(rel / name).as_posix() for name in [*dirs, *files]]
    return sorted(found)


def record_written(folder: str | os.PathLike[str], names: list[str] | None = None) -> None:
    """Write ``folder``'s output record: every path in it now (``names`` None), or the paths it already
    lists plus ``names`` (relative paths), for files added after the folder was published."""
    folder = Path(folder)
    entries = set(_tree_entries(folder)) if names is None else (written_entries(folder) or set()) | set(names)
    with atomic_output(folder / OUTPUT_RECORD) as tmp:
        Path(tmp).write_text(_record_text(entries))


def _record_text(entries: set[str]) -> str:
    return json.dumps({"written_by": "matremap", "entries": sorted(entries - {OUTPUT_RECORD})}, indent=0) + "\n"


def _write_record(stage: Path, entries: set[str]) -> None:
    """The record of a staging folder, written in place (nothing sees the folder before it is moved in)."""
    (stage / OUTPUT_RECORD).write_text(_record_text(entries))


def foreign_entries(folder: Path) -> list[str]:
    """The paths under ``folder`` that its output record does not list (all of them when it has none)."""
    written = written_entries(folder) or set()
    return [e for e in _tree_entries(folder) if e != OUTPUT_RECORD and e not in written]


def _contains(folder: Path, path: Path) -> bool:
    return path == folder or folder in path.parents


def check_output_folder(
    out: Path, protected: Iterable[str | os.PathLike[str]] = (), enclosing: Iterable[str | os.PathLike[str]] = ()
) -> None:
    """Refuse ``out`` as an output folder when it is, or holds, one of the ``protected`` paths (the inputs,
    the files they reference, the cache): replacing ``out`` would remove them; or when it lies inside one of
    the ``enclosing`` folders (a map set's folder, whose files a later run would read as maps). Paths are
    compared resolved (links followed)."""
    target = out.resolve()
    for p in protected:
        q = Path(p).resolve()
        if _contains(target, q):
            what = "is a folder" if q == target else f"holds {q.relative_to(target)},"
            raise MatremapError(f"{out} {what} which the run reads; choose an output folder apart from the inputs")
    for p in enclosing:
        if _contains(Path(p).resolve(), target):
            raise MatremapError(f"{out} lies inside {p}, which the run reads; choose an output folder apart from it")


@contextmanager
def staged_folder(
    out: str | os.PathLike[str],
    force: bool = False,
    protected: Iterable[str | os.PathLike[str]] = (),
    enclosing: Iterable[str | os.PathLike[str]] = (),
) -> Iterator[Path]:
    """A whole output folder written all or nothing: the block writes into a hidden folder beside
    ``out`` (``.matremap-partial-<owner>-<name>-*``), which replaces ``out`` when the block ends without
    an error and is removed when it fails, so a failed run leaves nothing behind and a retry needs no
    ``--force``. The published folder carries an output record (:data:`OUTPUT_RECORD`) of every path in
    it. An existing ``out`` that is not empty is replaced only with ``force``, and only when everything in
    it is listed in its record (a folder matremap wrote); anything else in it is refused, force or not, so
    ``--force`` never removes a file matremap did not write. ``out`` may not be or hold a ``protected``
    path, nor lie inside an ``enclosing`` folder (:func:`check_output_folder`). The replaced folder is moved aside into
    ``.matremap-old-*`` for the moment of the swap. What dead runs left beside ``out`` is put right first
    (:func:`clean_stale`). Only ``out``'s parent folders may be created (they are left in place)."""
    out = Path(out)
    check_output_folder(out, protected, enclosing)
    if out.parent.is_dir():
        clean_stale(out.parent)
    if out.exists() and not out.is_dir():
        raise MatremapError(f"{out} exists and is not a folder; choose an output folder")
    if out.is_dir() and any(out.iterdir()):
        foreign = foreign_entries(out)
        if foreign:
            shown = ", ".join(foreign[:3]) + (f" and {len(foreign) - 3} more" if len(foreign) > 3 else "")
            raise MatremapError(
                f"{out} holds files matremap did not write ({shown}); choose a new or empty output folder "
                "(--force replaces only a folder matremap wrote)"
            )
        if not force:
            raise MatremapError(f"{out} exists and is not empty; pass --force to replace it")
    out.parent.mkdir(parents=True, exist_ok=True)
    stage = Path(tempfile.mkdtemp(prefix=temp_prefix("partial", out.name), dir=out.parent))
    try:
        yield stage
        _write_record(stage, set(_tree_entries(stage)))
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        raise
    os.chmod(stage, 0o777 & ~_umask())
    with _sigint_held():
        old = None
        if out.exists():
            old = Path(tempfile.mkdtemp(prefix=temp_prefix("old", out.name), dir=out.parent))
            os.replace(out, old / out.name)
        try:
            os.replace(stage, out)
        except OSError:
            if old is not None:
                os.replace(old / out.name, out)
            shutil.rmtree(stage, ignore_errors=True)
            raise
        finally:
            if old is not None:
                shutil.rmtree(old, ignore_errors=True)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


__all__ = [
    "FORCE_HINT",
    "MARK",
    "OUTPUT_RECORD",
    "STAGING_PREFIX",
    "AtomicFiles",
    "atomic_output",
    "check_output_folder",
    "clean_stale",
    "foreign_entries",
    "owner_token",
    "record_written",
    "staged_folder",
    "temp_prefix",
    "written_entries",
]
