"""The heap thresholds the embedded renderer sets (core/heap.py): once, only where nobody tuned the allocator,
and never a different number."""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
from pathlib import Path

import pytest

SRC = str(Path(__file__).resolve().parents[1] / "src")

FIT = """
import json
from matremap.core.heap import keep_heap
from matremap.core.material import Material
from matremap.core.scene import Scene
from matremap.uniform import fit
colours = {"Roughness": 0.4, "Color": [0.6, 0.3, 0.2], "Diffuse Color": [0.2, 0.3, 0.1]}
source = Material.create("cycles:glossy", colours)
r = fit(source, "mitsuba06:pbr", scene=Scene(resolution=48), fix={"distribution": "ggx"})
print(json.dumps({"kept": keep_heap(), "params": r.params, "loss": r.loss}))
"""


def run_fit(**env: str) -> dict:
    clean = {k: v for k, v in os.environ.items() if not k.startswith("MALLOC_") and k != "MATREMAP_KEEP_HEAP"}
    env = {**clean, "PYTHONPATH": SRC, **env}
    p = subprocess.run([sys.executable, "-c", FIT], env=env, capture_output=True, text=True, check=True)
    return json.loads(p.stdout.strip().splitlines()[-1])


glibc = pytest.mark.skipif(
    not sys.platform.startswith("linux") or platform.libc_ver()[0] != "glibc", reason="glibc's mallopt"
)


@glibc
def test_the_embedded_renderer_keeps_the_heap_and_the_fit_is_the_same_without():
    kept, default, tuned = run_fit(), run_fit(MATREMAP_KEEP_HEAP="0"), run_fit(MALLOC_ARENA_MAX="2")
    assert kept["kept"] and not default["kept"] and not tuned["kept"]
    assert kept["params"] == default["params"] == tuned["params"] and kept["loss"] == default["loss"]


def test_keep_heap_applies_once():
    from matremap.core.heap import keep_heap

    assert keep_heap() is keep_heap()
