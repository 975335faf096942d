"""Writing several files all or nothing.

A material file often comes with files beside it (a glTF's textures and ``.bin``, the maps of a
Mitsuba scene or a MaterialX document, the maps of a converted map set). :class:`AtomicFiles`
writes such a group so that a reader never sees half of it::

    with AtomicFiles(force=force) as files:
        files.write_bytes(out_dir / "a_baseColor.png", png)
        files.write_text(out_dir / "a.gltf", text)   # stage the main file last: it is moved last

Each destination is refused up front if it already exists (unless ``force``) or its folder is
missing (unless ``make_folders``). Files are written under their own names into a hidden staging
folder beside their destination (``.matremap-staging-*``, same file system, so a rename moves them)
and moved into place, in the order they were staged, only when the ``with`` block ends without an
error. If the block fails, or a move fails, every staged file is removed, files already moved are
taken back (a file that ``force`` replaced is restored) and folders created for the group are
removed again: the destination looks as it did before. A file moved into place gets the
permissions a new file would get (``0o666`` less the umask).

:func:`matremap.core.imageio.atomic_output` is the one-file version of the same idea.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from types import TracebackType

from matremap.errors import MatremapError

#: prefix of the hidden staging folders
STAGING_PREFIX = ".matremap-staging-"
#: what the "already exists" error tells the user to do
FORCE_HINT = "pass --force to overwrite it"


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
        self._created: list[Path] = []  # folders made for the group, outermost first
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
        folder is missing (without ``make_folders``). Returns it as a Path."""
        p = Path(path)
        if p in self._staged:
            raise MatremapError(f"two outputs would be written to {p}; give them different names")
        if not self.make_folders and not p.parent.is_dir():
            raise MatremapError(f"cannot write {p}: folder {p.parent} does not exist")
        if p.exists() and not self.force:
            raise MatremapError(f"{p} already exists; {self.exists_hint}")
        if p.is_dir():
            raise MatremapError(f"cannot write {p}: it is a folder")
        return p

    def stage(self, path: str | os.PathLike[str]) -> Path:
        """The file to write ``path``'s content to (same name, in the staging folder); nothing is
        created there. The caller (or a worker process it passes the name to) writes it before the
        group ends."""
        if not self._open:
            raise RuntimeError("stage files inside a `with AtomicFiles(...)` block")
        p = self.check(path)
        self._staged[p] = self._staging_folder(p.parent) / "new" / p.name
        return self._staged[p]

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
        if folder not in self._staging:
            if not folder.is_dir():
                self._make_folder(folder)
            staging = Path(tempfile.mkdtemp(prefix=STAGING_PREFIX, dir=folder))
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
        moved: list[tuple[Path, Path | None]] = []  # (destination, where its previous file went)
        try:
            for dest, tmp in self._staged.items():
                backup = None
                if dest.exists() or dest.is_symlink():
                    backup = self._staging[dest.parent] / "old" / dest.name
                    os.replace(dest, backup)
                moved.append((dest, backup))
                os.chmod(tmp, 0o666 & ~umask)
                os.replace(tmp, dest)
        except BaseException:
            self._take_back(moved)
            self._remove_created_folders()
            raise

    @staticmethod
    def _take_back(moved: list[tuple[Path, Path | None]]) -> None:
        for dest, backup in reversed(moved):
            if backup is not None and (backup.exists() or backup.is_symlink()):
                os.replace(backup, dest)
            elif backup is None:
                dest.unlink(missing_ok=True)

    def _remove_staging(self) -> None:
        for staging in self._staging.values():
            shutil.rmtree(staging, ignore_errors=True)
        self._staging.clear()

    def _remove_created_folders(self) -> None:
        self._remove_staging()
        for folder in reversed(self._created):
            try:
                folder.rmdir()
            except OSError:  # not empty: something else was put there meanwhile
                pass
        self._created.clear()


@contextmanager
def staged_folder(out: str | os.PathLike[str], force: bool = False) -> Iterator[Path]:
    """A whole output folder written all or nothing: the block writes into a hidden folder beside
    ``out`` (``.<name>.partial-*``), which replaces ``out`` when the block ends without an error and is
    removed when it fails, so a failed run leaves nothing behind and a retry needs no ``--force``. An
    existing ``out`` that is not empty is refused unless ``force``; with ``force`` it is replaced whole.
    Only ``out``'s parent folders may be created (they are left in place)."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise MatremapError(f"{out} exists and is not a folder; choose an output folder")
    if out.is_dir() and any(out.iterdir()) and not force:
        raise MatremapError(f"{out} exists and is not empty; pass --force to replace it")
    out.parent.mkdir(parents=True, exist_ok=True)
    stage = Path(tempfile.mkdtemp(prefix=f".{out.name}.partial-", dir=out.parent))
    try:
        yield stage
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        raise
    os.chmod(stage, 0o777 & ~_umask())
    old = None
    if out.exists():
        old = Path(tempfile.mkdtemp(prefix=f".{out.name}.old-", dir=out.parent))
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


__all__ = ["FORCE_HINT", "STAGING_PREFIX", "AtomicFiles", "staged_folder"]
