"""Errors meant for people, and the exit status each one gives.

Every problem a user can cause (a bad model id, a value out of range, a malformed file) raises
:class:`MatremapError` with one sentence naming the problem and, where there is one, the fix. The command
line prints that sentence on stderr and exits with the error's :attr:`~MatremapError.exit_code`:

====  ========================================================================================
code  meaning
====  ========================================================================================
0     converted, and every measure of the quality gate within its threshold
2     bad input or usage (:class:`MatremapError`): nothing was written
3     converted, but the result failed the quality gate (:class:`QualityGateFailed`): the files are in
      the output folder and its report says FAILED and why
4     a renderer or the environment failed (:class:`RendererUnavailable`): not installed, crashed,
      timed out; or the disk or quota is full (:class:`NoSpace`); nothing was written and nothing was
      cached, so a retry after the fix starts afresh
70    an internal error (a bug, not the input): one line naming the exception; ``matremap --debug ...``
      shows the traceback (what the system raised -- a refused file, a full disk, memory -- is mapped
      by :func:`system_error` instead)
130   interrupted
====  ========================================================================================
"""

from __future__ import annotations

import errno
import os
import re
from collections.abc import Sequence
from pathlib import Path

#: exit status of a converted result that failed the quality gate
EXIT_QUALITY = 3
#: exit status of a renderer or environment failure
EXIT_RENDERER = 4
#: exit status of an unexpected exception (a bug): BSD's EX_SOFTWARE
EXIT_INTERNAL = 70
#: exit status when interrupted (128 + SIGINT)
EXIT_INTERRUPTED = 130
#: the longest error line the command line prints; a longer one is cut in its middle (its fix is at its end)
MAX_LINE = 600
#: errno values of a full disk or an exhausted quota
NO_SPACE = (errno.ENOSPC, errno.EDQUOT)
#: errno values of a file the system refused to the user (permissions, a read-only file system)
REFUSED = (errno.EACCES, errno.EPERM, errno.EROFS)
#: how matremap's temporary names start (:data:`matremap.core.atomic.MARK`): never shown to a user
_MARK = ".matremap-"


class MatremapError(ValueError):
    """A user-facing error: the message names the problem and how to fix it (exit status 2)."""

    exit_code = 2


class RendererUnavailable(MatremapError):
    """A renderer cannot be used here (not installed, crashed, timed out): the environment, not the input.
    Never cached as a result; exit status 4."""

    exit_code = EXIT_RENDERER


class QualityGateFailed(MatremapError):
    """The result was written but failed the quality gate; the message gives the worst measure (exit 3)."""

    exit_code = EXIT_QUALITY


class TransformChecksumError(MatremapError):
    """A transform file's content does not match the checksum stored in it (edited or damaged since it was
    written), or a transform that must carry one has none. A cached transform that fails this is
    recomputed; a shipped one means a damaged installation."""


class NoSpace(MatremapError):
    """The disk (or quota) of a folder matremap writes is full: the environment, exit status 4. What was
    being written is discarded, as for any failure; the message names the folder and the fix."""

    exit_code = EXIT_RENDERER


def shown(text: object) -> str:
    """``text`` (a path, a name, a message) as it can be printed: the bytes of a file name that are not
    UTF-8 (held as surrogates, :func:`os.fsdecode`) shown as ``\\xNN``, other lone surrogates as ``\\uNNNN``."""
    if isinstance(text, bytes):
        text = os.fsdecode(text)
    return re.sub("[\ud800-\udfff]", _escape_surrogate, str(text))


def _escape_surrogate(m: re.Match[str]) -> str:
    code = ord(m.group())
    return f"\\x{code - 0xDC00:02x}" if 0xDC80 <= code <= 0xDCFF else f"\\u{code:04x}"


def not_a_file(path: str | os.PathLike[str], what: str) -> str:
    """Why ``path``, which should be a regular file (``what`` names it), is not one: not found, a folder,
    or a special file (a FIFO, a device, a socket: reading one would block or never end)."""
    import stat

    p = shown(os.fspath(path))
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):
        return f"{what} {p} not found; check the file name"
    if stat.S_ISDIR(mode):
        return f"{what} {p} is a folder, not a file; name the file in it"
    kind = "a FIFO (named pipe)" if stat.S_ISFIFO(mode) else "a socket" if stat.S_ISSOCK(mode) else "a device"
    return f"{what} {p} is {kind}, not a regular file; matremap reads files only (copy the data into one)"


def shorten(text: object, limit: int = 80) -> str:
    """``text`` as a message quotes a value: printable (:func:`shown`), cut in its middle past ``limit``
    characters."""
    return shown(_cut(str(text), limit))


def _cut(text: str, limit: int, dropped: int = 0) -> str:
    """``text`` cut in its middle past ``limit`` characters; ``dropped`` characters were cut before."""
    if len(text) <= limit + 30 and not dropped:  # the mark of a cut is longer than a few characters
        return text
    head = limit * 2 // 3
    tail = max(limit - head, 0) if len(text) > limit else len(text) - head
    cut = len(text) - head - tail + dropped
    return f"{text[:head]}...[{cut:,} characters cut]...{text[len(text) - tail :]}"


def one_line(message: str, limit: int = MAX_LINE) -> str:
    """A message as the command line prints it: one line (runs of white space, line breaks included,
    made one space), printable (:func:`shown`), with matremap's temporary names given as the names they
    stand for (:func:`unhidden`), and at most about ``limit`` characters, cut in its middle so that its
    end, the fix, stays."""
    dropped = max(len(message) - 4 * limit, 0)
    if dropped:  # a huge message: its middle goes before it is split into words
        message = message[: 2 * limit] + message[-2 * limit :]
    return shown(_cut(unhidden(" ".join(message.split()) or "(no message)"), limit, dropped))


#: a temporary name of :mod:`matremap.core.atomic` that carries the name it stands for: an output folder
#: being written whole (``partial``) or a file being written (``tmp``, its suffix kept)
_TEMPORARY = re.compile(r"\.matremap-(?:partial|tmp)-\d+(?:x\d+)?-(?P<name>[^/\s]+?)-[a-z0-9_]{8}(?P<suffix>\.\w+)?\b")


def unhidden(text: str) -> str:
    """``text`` with the hidden temporary names matremap writes under (an output folder being written,
    a file being written) replaced by the names the user gave."""
    return _TEMPORARY.sub(lambda m: m.group("name") + (m.group("suffix") or ""), text)


def encode_paths(error: UnicodeError) -> tuple[str | bytes, int]:
    """A codec error handler (registered as ``matremap-paths``) for matremap's output streams: the bytes
    of a file name that are not UTF-8 (held as surrogates) written back as they were, so a printed path
    names the file; any other unencodable character as ``\\uNNNN``."""
    if not isinstance(error, UnicodeEncodeError):
        raise error
    part = error.object[error.start : error.end]
    if all(0xDC80 <= ord(c) <= 0xDCFF for c in part):
        return bytes(ord(c) - 0xDC00 for c in part), error.end
    return "".join(f"\\u{ord(c):04x}" for c in part), error.end


def visible_folder(path: str | os.PathLike[str]) -> Path:
    """The folder a user knows ``path`` by: the one holding it, or for a path inside one of matremap's
    hidden temporary folders (``.matremap-*``), the folder holding that."""
    p = Path(os.fsdecode(path))
    parts = p.parts
    for i, part in enumerate(parts):
        if part.startswith(_MARK):
            return Path(*parts[:i]) if i else Path(".")
    return p.parent


def system_error(e: BaseException, writes: Sequence[str | os.PathLike[str]] = ()) -> MatremapError | None:
    """The user-facing error of an exception the system raised, or None for one that is a bug.

    * a full disk or quota (``ENOSPC``, ``EDQUOT``, SQLite's "database or disk is full"): :class:`NoSpace`
      (exit 4) naming the folder (the file's, else the first of ``writes``, the folders the command
      writes) and the fix;
    * a file or folder the system refused (permissions, a read-only file system, a missing folder):
      ``cannot write`` when it lies in one of ``writes`` (or under matremap's temporary names), else
      ``cannot read`` (exit 2);
    * memory: exit 2 with the fix.
    """
    if isinstance(e, MemoryError):
        return MatremapError("not enough memory for this input; use smaller maps or free memory, then retry")
    full = no_space(e, writes)
    if full is not None:
        return full
    if isinstance(e, OSError) and e.filename is not None:
        path = Path(os.fsdecode(e.filename))
        reason = e.strerror or str(e)
        hidden = any(part.startswith(_MARK) for part in path.parts)
        if hidden or _under(path, writes):
            where = shown(visible_folder(path) if hidden else path)
            return MatremapError(f"cannot write {where}: {reason}; write into a folder you may write (-o)")
        return MatremapError(f"cannot read {shown(path)}: {reason}")
    return None


def no_space(e: BaseException, writes: Sequence[str | os.PathLike[str]] = ()) -> NoSpace | None:
    """:class:`NoSpace` for a full disk or quota (``ENOSPC``, ``EDQUOT``, SQLite's "database or disk is
    full"), naming the folder written (the file's, else ``writes``) and the fix; None for anything else."""
    import sqlite3

    full_db = isinstance(e, sqlite3.OperationalError) and "database or disk is full" in str(e)
    if not (full_db or (isinstance(e, OSError) and e.errno in NO_SPACE)):
        return None
    filename = getattr(e, "filename", None)
    folders = [visible_folder(filename)] if filename is not None else list(dict.fromkeys(map(_folder, writes)))
    named = " or ".join(shown(f) for f in folders)
    where = f"the disk (or your quota) holding {named} is full" if folders else "the disk is full"
    reason = "database or disk is full" if full_db else (getattr(e, "strerror", None) or str(e))
    return NoSpace(
        f"{where} ({reason}); free space there, or write elsewhere (-o, --db, MATREMAP_CACHE for the cache), then rerun"
    )


def _folder(path: str | os.PathLike[str]) -> Path:
    """The folder a written path stands for: itself when it is a folder (or has no suffix), else its own."""
    p = Path(os.path.abspath(path))
    return p if p.is_dir() or not p.suffix else p.parent


def _under(path: Path, folders: Sequence[str | os.PathLike[str]]) -> bool:
    """Whether ``path`` is one of ``folders``, lies in one, or is a folder one of them would be made in."""
    try:
        p = Path(os.path.abspath(path))
        for folder in folders:
            f = Path(os.path.abspath(folder))
            if p == f or p.is_relative_to(f) or f.is_relative_to(p):
                return True
    except (OSError, ValueError):
        return False
    return False
