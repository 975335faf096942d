"""Where the files a material file names may lie, and where a named output may go.

A glTF image or buffer URI, a MaterialX ``file`` input and a Mitsuba ``bitmap`` filename are paths an
untrusted file chooses. matremap reads them only when they resolve (symbolic links followed, ``..``
collapsed) inside the asset's own folder, or inside a folder the user allowed (``--allow-path DIR``).
Anything else is refused with one line that names the reference as the file wrote it; the line is the
same whether or not the named file exists, so a refused reference tells nothing about the disk.

:class:`Confinement` holds the allowed folders; :func:`resolve_reference` resolves one reference or
raises. A reader given no confinement takes the one in effect (:func:`allowed_paths`, which the command
line enters around a command); with none in effect, only the asset's folder is allowed.
:func:`output_inside` checks that a user-named output file stays inside its output folder.
:func:`recorded_references` collects every reference the readers resolve inside it: the files an output
folder must never hold (see :func:`matremap.core.atomic.staged_folder`).
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass
from pathlib import Path

from matremap.errors import MatremapError

#: the folders allowed beyond each asset's own, for the readers called in this context
_ALLOWED: ContextVar[tuple[Path, ...]] = ContextVar("matremap_allowed_paths", default=())
#: where the references resolved in this context are collected (None: not collected)
_RECORDED: ContextVar[list[Path] | None] = ContextVar("matremap_recorded_references", default=None)


@dataclass(frozen=True)
class Confinement:
    """The folders (resolved) that file references may point into besides the asset's own folder."""

    roots: tuple[Path, ...] = ()

    @classmethod
    def of(cls, dirs: Iterable[str | os.PathLike]) -> Confinement:
        """The confinement allowing ``dirs`` (each an existing folder; refused otherwise)."""
        roots = []
        for d in dirs:
            p = Path(d).expanduser()
            if not p.is_dir():
                raise MatremapError(f"--allow-path {str(d)!r} is not a folder; give an existing folder")
            roots.append(p.resolve())
        return cls(tuple(roots))

    @classmethod
    def current(cls) -> Confinement:
        """The confinement in effect (see :func:`allowed_paths`); only the asset's folder when none is."""
        return cls(_ALLOWED.get())

    def allows(self, path: Path, asset_folder: Path) -> bool:
        """Whether resolved ``path`` lies inside ``asset_folder`` (resolved here) or an allowed folder."""
        return any(path.is_relative_to(root) for root in (asset_folder.resolve(), *self.roots))


def resolve_reference(ref: str, asset_folder: Path, what: str, confinement: Confinement | None = None) -> Path:
    """The file a material file's reference ``ref`` names (relative to ``asset_folder``, or absolute),
    resolved; raises when it lies outside the asset folder and the allowed folders. ``what`` names the
    reference for the message (e.g. ``image 3 uri``); the file is not looked at, so the message is the
    same whether it exists or not."""
    conf = confinement if confinement is not None else Confinement.current()
    raw = Path(ref)
    try:
        resolved = (raw if raw.is_absolute() else asset_folder / raw).resolve()
    except (OSError, RuntimeError, ValueError):  # a symlink loop, a NUL byte
        resolved = None
    if resolved is None or not conf.allows(resolved, asset_folder):
        raise MatremapError(
            f"{what} {ref!r} points outside the asset folder {asset_folder.resolve()}; "
            f"pass --allow-path DIR to allow it"
        )
    recorded = _RECORDED.get()
    if recorded is not None:
        recorded.append(resolved)
    return resolved


@contextmanager
def recorded_references() -> Iterator[list[Path]]:
    """A list that receives every reference :func:`resolve_reference` resolves inside the block (resolved
    paths, in the order read; a reference read twice is listed twice)."""
    found: list[Path] = []
    token = _RECORDED.set(found)
    try:
        yield found
    finally:
        _RECORDED.reset(token)


@contextmanager
def allowed_paths(dirs: Iterable[str | os.PathLike]) -> Iterator[Confinement]:
    """Allow references into ``dirs`` (besides each asset's folder) for the readers called inside."""
    conf = Confinement.of(dirs)
    token = _ALLOWED.set(conf.roots)
    try:
        yield conf
    finally:
        _ALLOWED.reset(token)


def output_inside(out_dir: str | os.PathLike, name: str, option: str = "--write") -> Path:
    """``out_dir / name``, refused when ``name`` (given with ``option``) resolves outside ``out_dir``."""
    folder = Path(out_dir).resolve()
    target = (folder / name).resolve()
    if Path(name).is_absolute() or target == folder or not target.is_relative_to(folder):
        raise MatremapError(f"{option} {name!r} points outside the output folder {out_dir}; give a file name inside it")
    return target


__all__ = ["Confinement", "allowed_paths", "output_inside", "recorded_references", "resolve_reference"]
