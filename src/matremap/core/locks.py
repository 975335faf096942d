"""One process at a time on a piece of shared work, the others waiting for its result.

Two runs that need the same cached result (one transform of the cache, one batch folder) would each
compute it: :func:`exclusive` holds an advisory lock (``flock(2)``, released by the kernel when the
holder exits, however it exits) on a lock file beside the result, so that the second run waits for the
first and then finds its result in place. The lock files stay (empty; removing one while another
process waits on it would let a third in).
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Iterator
from pathlib import Path

from matremap.errors import MatremapError


@contextlib.contextmanager
def exclusive(lock_file: str | os.PathLike[str], on_wait: Callable[[], None] | None = None) -> Iterator[None]:
    """Hold the exclusive lock of ``lock_file`` (created if missing) for the block; when another process
    holds it, call ``on_wait`` once (to say so) and wait. Where the system has no ``flock`` (Windows) the
    block runs unlocked."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not on POSIX
        yield
        return
    path = Path(lock_file)
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o600)
    except OSError as e:
        raise MatremapError(f"cannot create the lock file {path}: {e.strerror or e}") from None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            if on_wait is not None:
                on_wait()
            fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # releases the lock


__all__ = ["exclusive"]
