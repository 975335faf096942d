"""The bpy worker process: where its Python is, starting it, and the requests it answers.

``bpy`` 5.0.1 needs Python 3.11 and numpy < 2, so it lives in its own venv and runs in a persistent
worker process (:mod:`matremap.renderers.cycles.worker`) that this module talks to over a pipe: a
request is length-prefixed JSON, a reply a JSON header and optional ``.npy`` payload. The worker's
Python is ``$MATREMAP_BPY_PYTHON`` or else ``<repo>/.venv-bpy/bin/python``.
"""

from __future__ import annotations

import io
import json
import os
import select
import shutil
import struct
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from matremap.errors import MatremapError, RendererUnavailable

ENV_PYTHON = "MATREMAP_BPY_PYTHON"

REPO = Path(__file__).resolve().parents[4]

DEFAULT_PYTHON = REPO / ".venv-bpy" / "bin" / "python"

WORKER = Path(__file__).with_name("worker.py")

INSTALL_HINT = (
    "Blender's bpy is not set up: create its own venv with `python3.11 -m venv .venv-bpy && "
    ".venv-bpy/bin/pip install bpy==5.0.1` in the repository, or point the environment variable "
    f"{ENV_PYTHON} at a Python that can `import bpy` (bpy 5.0.1 pins numpy<2, so not the main venv)"
)

#: the models Cycles draws: those of its dialect


def find_python(python: str | os.PathLike | None = None) -> str:
    """The Python that runs the worker: the argument, ``$MATREMAP_BPY_PYTHON``, or ``<repo>/.venv-bpy``."""
    for candidate, where in ((python, "the python argument"), (os.environ.get(ENV_PYTHON), ENV_PYTHON)):
        if candidate:
            if not os.access(candidate, os.X_OK):
                raise RendererUnavailable(f"{where} names {candidate!r}, which is not an executable; {INSTALL_HINT}")
            return str(candidate)
    if os.access(DEFAULT_PYTHON, os.X_OK):
        return str(DEFAULT_PYTHON)
    raise RendererUnavailable(INSTALL_HINT)


def bpy_available() -> bool:
    """Whether a bpy venv is found (does not start it)."""
    try:
        find_python()
    except MatremapError:
        return False
    return True


class _WorkerDied(Exception):
    pass


#: the environment variable that hands the worker its scratch folder (its render files)
SCRATCH_ENV = "MATREMAP_CYCLES_SCRATCH"


def scratch_folder(kind: str) -> Path:
    """A new folder for files the Cycles worker reads or writes, marked as this process's
    (:func:`~matremap.core.atomic.temp_prefix`) in the private cache's ``cycles`` folder, whose stale
    entries (of killed runs) every later run removes; the system temporary folder if the cache is unusable.
    Each worker left a ``matremap-cycles-*`` folder with its last render in /tmp, killed or not."""
    from matremap.core.atomic import temp_prefix
    from matremap.core.diskcache import private_cache_dir

    try:
        parent: Path | None = private_cache_dir("cycles")
    except MatremapError:
        parent = None
    return Path(tempfile.mkdtemp(prefix=temp_prefix(kind), dir=parent))


class WorkerClient:
    """A persistent bpy worker process and the requests it answers over a pipe.

    ``timeout`` (seconds) bounds one request; a worker that dies or hangs is restarted and the
    request retried once, then a :class:`MatremapError` says what happened (with the tail of the
    worker's stderr). ``geometry`` is the probe's sphere, for the renderer built on this client.
    """

    def __init__(self, python: str | None = None, timeout: float = 120.0, geometry: str = "points") -> None:
        self._configure(python, timeout, geometry)

    def _configure(self, python: str | None, timeout: float, geometry: str) -> None:
        """Set up a client that has no worker yet (``__init__``, and ``__setstate__`` in a process pool)."""
        self.python = find_python(python)
        self.timeout = float(timeout)
        self.geometry = geometry
        self._proc: subprocess.Popen[bytes] | None = None
        self._log: Any = None
        self._scratch: Path | None = None
        self.renders = 0  # Cycles images (one per material and light)
        self.restarts = 0
        self.blender_version: str | None = None

    def __repr__(self) -> str:
        return f"{type(self).__name__}(python={self.python!r})"

    def __getstate__(self) -> dict[str, Any]:  # for process pools: each copy starts its own worker
        return {"python": self.python, "timeout": self.timeout, "geometry": self.geometry}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self._configure(**state)

    def __del__(self) -> None:
        try:
            self.close()
        except Exception:
            pass

    # -- the worker ----------------------------------------------------------------------------
    @property
    def pid(self) -> int | None:
        return self._proc.pid if self._proc is not None and self._proc.poll() is None else None

    def start(self) -> None:
        """Start the worker (done on the first render) and wait until bpy is imported."""
        if self.pid is not None:
            return
        if self._proc is not None:  # it died since the last request
            self.restarts += 1
        self.close()
        self._log = tempfile.TemporaryFile()
        self._scratch = scratch_folder("worker")
        # Blender makes its own blender_* folder in the temporary folder and a killed worker leaves it there
        scratch = str(self._scratch)
        env = {**os.environ, SCRATCH_ENV: scratch, "TMPDIR": scratch, "TEMP": scratch, "TMP": scratch}
        try:
            self._proc = subprocess.Popen(
                [self.python, str(WORKER)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self._log, env=env
            )
        except OSError as e:
            raise RendererUnavailable(f"cannot start the Cycles worker with {self.python}: {e}; {INSTALL_HINT}") from e
        try:
            header, _ = self._reply(time.monotonic() + max(self.timeout, 60.0))
        except _WorkerDied as e:
            self.close()
            raise RendererUnavailable(f"the Cycles worker did not start ({e}): {INSTALL_HINT}") from None
        self.blender_version = header.get("blender")

    def close(self) -> None:
        """Stop the worker (a later render starts a new one)."""
        proc, self._proc = self._proc, None
        if proc is not None:
            if proc.poll() is None:
                proc.kill()
            proc.wait()
            for f in (proc.stdin, proc.stdout):
                if f is not None:
                    f.close()
        if self._log is not None:
            self._log.close()
            self._log = None
        if self._scratch is not None:
            shutil.rmtree(self._scratch, ignore_errors=True)
            self._scratch = None

    def request(self, request: dict[str, Any]) -> np.ndarray:
        """Send a request whose reply carries images; returns them."""
        header, payload = self._exchange(request)
        if not header.get("nbytes"):
            raise MatremapError(f"the Cycles worker sent no images for {request.get('op')!r}")
        return np.load(io.BytesIO(payload))

    def call(self, request: dict[str, Any]) -> dict[str, Any]:
        """Send a request whose reply is data (``write_blend``, ``inspect_blend``); returns its ``info``."""
        header, _ = self._exchange(request)
        return header.get("info", {})

    def _exchange(self, request: dict[str, Any]) -> tuple[dict[str, Any], bytes]:
        body = json.dumps(request).encode()
        for attempt in (1, 2):
            try:
                self.start()
                stdin = self._running().stdin
                if stdin is None:
                    raise _WorkerDied("the worker has no stdin pipe")
                stdin.write(struct.pack(">I", len(body)) + body)
                stdin.flush()
                header, payload = self._reply(time.monotonic() + self.timeout)
            except (_WorkerDied, BrokenPipeError, OSError) as e:
                why = f"{e}; its stderr ends with: {self._stderr_tail()}"
                self.close()
                self.restarts += 1
                if attempt == 2:
                    raise RendererUnavailable(f"the Cycles worker failed twice: {why}") from None
                continue
            if not header.get("ok"):
                raise MatremapError(f"Cycles failed to render: {header.get('error')}")
            return header, payload
        raise AssertionError("unreachable")

    def _running(self) -> subprocess.Popen[bytes]:
        """The worker process, once :meth:`start` has launched it."""
        if self._proc is None:
            raise _WorkerDied("the worker is not running")
        return self._proc

    def _read(self, n: int, deadline: float) -> bytes:
        proc = self._running()
        out = proc.stdout
        if out is None:
            raise _WorkerDied("the worker has no stdout pipe")
        fd = out.fileno()
        buf = bytearray()
        while len(buf) < n:
            left = deadline - time.monotonic()
            if left <= 0:
                raise _WorkerDied(f"no reply within {self.timeout:g} s")
            ready, _, _ = select.select([fd], [], [], left)
            if not ready:
                continue
            chunk = os.read(fd, n - len(buf))
            if not chunk:
                code = proc.wait()
                raise _WorkerDied(f"the worker exited with status {code}")
            buf += chunk
        return bytes(buf)

    def _reply(self, deadline: float) -> tuple[dict[str, Any], bytes]:
        (n,) = struct.unpack(">I", self._read(4, deadline))
        header = json.loads(self._read(n, deadline))
        payload = self._read(int(header["nbytes"]), deadline) if header.get("nbytes") else b""
        return header, payload

    def _stderr_tail(self, chars: int = 800) -> str:
        if self._log is None:
            return "(nothing)"
        try:
            self._log.seek(0, os.SEEK_END)
            size = self._log.tell()
            self._log.seek(max(0, size - chars))
            return self._log.read().decode(errors="replace").strip() or "(nothing)"
        except (OSError, ValueError):
            return "(unreadable)"


_shared: WorkerClient | None = None


def shared_client(client: WorkerClient | None = None) -> WorkerClient:
    """``client``, or the one worker client (600 s timeout) this process shares for scenes other than
    the probe's (environment renders, .blend files)."""
    global _shared
    if client is not None:
        return client
    if _shared is None:
        _shared = WorkerClient(timeout=600.0)
    return _shared


__all__ = [
    "DEFAULT_PYTHON",
    "ENV_PYTHON",
    "INSTALL_HINT",
    "WorkerClient",
    "bpy_available",
    "find_python",
    "shared_client",
]
