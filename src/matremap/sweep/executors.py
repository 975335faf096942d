"""Where sweep work runs: in this process, a local process pool, or a Dask cluster.

All three are ``concurrent.futures`` executors (Dask's through ``Client.get_executor()``), so the
sweep has one code path. Dask is optional (``pip install 'matremap[dask]'``) and imported only
when asked for.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
from collections.abc import Callable, Iterator
from concurrent.futures import Executor, Future, ProcessPoolExecutor
from contextlib import contextmanager
from multiprocessing.context import SpawnContext, SpawnProcess
from typing import Any

from matremap.errors import MatremapError

_BLAS_LIMITED = False


def limit_blas_threads() -> None:
    """One BLAS thread in every process that fits: multi-threaded reductions change the last bits
    of results, and sweep rows must not depend on where they were computed (Dask workers run
    single-threaded BLAS by default). The fits' matrices are small: threads do not pay anyway."""
    global _BLAS_LIMITED
    if not _BLAS_LIMITED:
        from threadpoolctl import threadpool_limits

        threadpool_limits(limits=1, user_api="blas")
        _BLAS_LIMITED = True


class InlineExecutor(Executor):
    """Runs each task at submission, in this process (one worker: no pickling, easy debugging)."""

    slots = 1

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Future:
        f: Future = Future()
        try:
            f.set_result(fn(*args, **kwargs))
        except BaseException as e:  # delivered through the future, as a pool would
            if isinstance(e, KeyboardInterrupt):
                raise
            f.set_exception(e)
        return f


def _ignore_sigint(parent: int | None = None) -> None:
    """Pool workers leave Ctrl-C to the parent, which stops the sweep cleanly, and die with it
    (:func:`die_with_parent`; a SIGKILLed sweep's workers otherwise waited for work for ever)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    quiet_progress_lock()
    if parent is not None:
        die_with_parent(parent)


#: how often a worker looks whether its parent is still there (where the system cannot tell it)
PARENT_POLL_SECONDS = 1.0


def die_with_parent(parent: int) -> None:
    """End this worker process when ``parent`` (the process that started it) ends, however it ends (SIGKILL,
    SIGTERM, a crash): on Linux the kernel sends SIGKILL at once (``PR_SET_PDEATHSIG``); everywhere a daemon
    thread checks every :data:`PARENT_POLL_SECONDS` whether the parent is still this process's parent (an
    orphan is adopted by another process) and ends the process if not, even in the middle of a task."""
    import threading
    import time

    if sys.platform.startswith("linux"):
        import ctypes

        with contextlib.suppress(OSError, AttributeError):
            ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL)  # 1: PR_SET_PDEATHSIG
    if os.getppid() != parent:  # the parent died before that took effect
        os._exit(1)

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(PARENT_POLL_SECONDS)
        os._exit(1)

    threading.Thread(target=watch, name="matremap-parent-watch", daemon=True).start()


@contextmanager
def make_executor(
    workers: int | None = None, scheduler: str | None = None, dask_local: int | None = None
) -> Iterator[tuple[Executor, str]]:
    """An executor and a one-line description of it.

    ``scheduler`` (a Dask scheduler address) or ``dask_local`` (start a LocalCluster of that many
    worker processes on loopback) select Dask; otherwise ``workers`` local processes (default: all
    cores; 1 runs in this process).
    """
    if scheduler and dask_local:
        raise MatremapError("give either --scheduler or --dask-local, not both")
    if scheduler or dask_local:
        with _dask_executor(scheduler, dask_local) as (ex, desc):
            yield ex, desc
        return
    n = workers or os.cpu_count() or 1
    if n < 1:
        raise MatremapError(f"--workers must be at least 1, got {workers}")
    if n == 1:
        yield InlineExecutor(), "1 worker (in process)"
        return
    pool = process_pool(n, _ignore_sigint, (os.getpid(),))
    pool.slots = n  # type: ignore[attr-defined]  # how many tasks run at once
    try:
        yield pool, f"{n} local worker processes"
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def quiet_progress_lock() -> None:
    """Give tqdm a thread lock in a worker: its default lock is a multiprocessing semaphore, which a worker
    killed on Ctrl-C never releases, and the spawn start method's resource tracker then warns of it on the
    user's terminal after the one line that says the batch was interrupted."""
    import threading

    from tqdm import tqdm

    tqdm.set_lock(threading.RLock())


class _QuietSpawnProcess(SpawnProcess):
    """A spawned process started with SIGINT blocked (see :func:`spawn_context`)."""

    def start(self) -> None:
        old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            super().start()
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, old)


class _QuietSpawnContext(SpawnContext):
    Process = _QuietSpawnProcess


def spawn_context() -> Any:
    """The ``spawn`` start method, its workers started with Ctrl-C blocked: a worker ignores SIGINT from its
    initializer on (:func:`_ignore_sigint`), but a Ctrl-C that reached it while it was still unpickling its start-up
    data printed a KeyboardInterrupt traceback from multiprocessing's ``spawn_main`` under the sweep's one line
    (seen twice in full test runs). The signal mask is inherited across fork and exec (POSIX), so the child starts
    with SIGINT blocked, and the parent's own mask is restored at once."""
    import multiprocessing as mp

    if not hasattr(signal, "pthread_sigmask"):  # Windows: no signal masks (and no terminal process groups)
        return mp.get_context("spawn")
    return _QuietSpawnContext()


def process_pool(n: int, initializer: Callable[..., Any], initargs: tuple[Any, ...] = ()) -> ProcessPoolExecutor:
    """A pool of ``n`` worker processes *spawned*, not forked: a process that has used OpenImageIO, BLAS or
    a renderer holds threads and their locks, and a forked child inherits a lock another thread held, for
    ever (a batch run from a long-lived process hung in OpenImageIO's ``write_scanlines``). Python's own
    documentation warns against forking a multi-threaded process; ``convert`` spawns for the same reason.
    Workers start with Ctrl-C blocked (:func:`spawn_context`)."""
    return ProcessPoolExecutor(max_workers=n, mp_context=spawn_context(), initializer=initializer, initargs=initargs)


def _check_reachable(address: str) -> None:
    """Fail fast (one line) when nothing listens at a tcp:// scheduler address."""
    import socket
    from urllib.parse import urlsplit

    parts = urlsplit(address if "://" in address else f"tcp://{address}")
    if parts.scheme != "tcp" or not parts.hostname or not parts.port:
        raise MatremapError(f"--scheduler {address!r}: give a Dask scheduler address like tcp://host:8786")
    try:
        socket.create_connection((parts.hostname, parts.port), timeout=5).close()
    except OSError as e:
        raise MatremapError(f"cannot reach the Dask scheduler at {address}: {e.strerror or e}") from None


@contextmanager
def _dask_executor(scheduler: str | None, dask_local: int | None) -> Iterator[tuple[Executor, str]]:
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise MatremapError("Dask is not installed: pip install 'matremap[dask]' (or 'dask[distributed]')") from None
    cluster = None
    try:
        if dask_local:
            if dask_local < 1:
                raise MatremapError(f"--dask-local must be at least 1, got {dask_local}")
            cluster = LocalCluster(
                n_workers=dask_local,
                threads_per_worker=1,
                processes=True,
                host="127.0.0.1",
                dashboard_address=None,
                silence_logs=40,
            )
            client = Client(cluster)
            desc = f"Dask LocalCluster with {dask_local} workers ({cluster.scheduler_address})"
        else:
            assert scheduler is not None  # make_executor passes one of the two
            _check_reachable(scheduler)
            try:
                client = Client(scheduler, timeout=10)
            except (OSError, TimeoutError) as e:
                raise MatremapError(f"cannot reach the Dask scheduler at {scheduler}: {e}") from None
            desc = f"Dask scheduler {scheduler} ({len(client.scheduler_info().get('workers', {}))} workers)"
        executor = client.get_executor(pure=False)
        executor.slots = max(1, sum(w.get("nthreads", 1) for w in client.scheduler_info().get("workers", {}).values()))
        try:
            yield executor, desc
        finally:
            client.close()
    finally:
        if cluster is not None:
            cluster.close()
