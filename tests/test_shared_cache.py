"""Runs sharing a cache compute each transform once: the second waits for the first
(:func:`matremap.core.locks.exclusive` around :func:`matremap.remap.cached_transform`)."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

import matremap
from matremap.core.locks import exclusive

ROOT = Path(__file__).resolve().parents[1]
SRC = str(Path(matremap.__file__).resolve().parents[1])

HOLD = """
import sys, time
from matremap.core.locks import exclusive
with exclusive(sys.argv[1]):
    print("held", flush=True)
    time.sleep(float(sys.argv[2]))
"""


def test_a_second_holder_waits_until_the_first_lets_go(tmp_path):
    lock = tmp_path / "t.lock"
    child = subprocess.Popen(
        [sys.executable, "-c", HOLD, str(lock), "1.5"],
        stdout=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONPATH": SRC},
    )
    try:
        assert child.stdout is not None and child.stdout.readline().strip() == "held"
        waited: list[float] = []
        t0 = time.monotonic()
        with exclusive(lock, on_wait=lambda: waited.append(time.monotonic() - t0)):
            held_after = time.monotonic() - t0
        assert len(waited) == 1 and waited[0] < 0.5  # said at once that it waits
        assert child.poll() is not None or held_after >= 1.0  # and got the lock only when the child let go
    finally:
        child.wait(timeout=30)


def test_a_lock_of_a_killed_holder_is_free(tmp_path):
    lock = tmp_path / "t.lock"
    child = subprocess.Popen(
        [sys.executable, "-c", HOLD, str(lock), "60"],
        stdout=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONPATH": SRC},
    )
    assert child.stdout is not None and child.stdout.readline().strip() == "held"
    child.kill()
    child.wait(timeout=30)
    waited: list[bool] = []
    with exclusive(lock, on_wait=lambda: waited.append(True)):
        pass
    assert waited == []


@pytest.mark.slow
def test_two_remaps_sharing_a_cache_sweep_once(tmp_path):
    env = {**os.environ, "MATREMAP_CACHE": str(tmp_path / "cache"), "PYTHONPATH": SRC}
    args = ["remap", str(ROOT / "examples" / "bronze"), "--to", "mitsuba06:pbr", "--fix", "distribution=as"]
    args += ["--sweep", "--no-evaluate", "--workers", "1"]
    runs = [
        subprocess.Popen(
            [sys.executable, "-m", "matremap", *args, "-o", f"out{i}"],
            cwd=tmp_path,
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        for i in range(2)
    ]
    errs = [r.communicate(timeout=600)[1] for r in runs]
    assert [r.returncode for r in runs] == [0, 0], errs
    swept = [e for e in errs if "points fitted" in e]
    assert len(swept) == 1, errs  # one run swept; the other took its transform from the cache
    assert sum("transform: cached" in e for e in errs) == 1, errs
