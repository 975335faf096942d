"""A value the run cannot take is refused before any work: a ``--fix`` that is not a parameter or option of the
target, or outside its bounds or choices, exits 2 at once, with nothing written and no cache entry made (it
used to run every fit of a sweep, each failing, and leave an empty sweep database in the cache)."""

from __future__ import annotations

from pathlib import Path

import pytest

from matremap.cli import main

ROOT = Path(__file__).resolve().parents[1]
GOLD = ROOT / "tests" / "data" / "corpus" / "mtlx-gltf_pbr_gold" / "gltf_pbr_gold.mtlx"


@pytest.mark.parametrize(
    "source, target, fix, said",
    [
        (ROOT / "examples" / "bronze", "mitsuba06:pbr", "distribution=gx", "is not one of"),
        (ROOT / "examples" / "bronze", "mitsuba06:pbr", "alpha=7", "alpha"),
        (ROOT / "examples" / "bronze", "mitsuba06:pbr", "clearcoat=1", "clearcoat"),
        (GOLD, "mitsuba3:roughconductor", "distribution=gx", "is not one of"),
    ],
)
def test_a_bad_fix_is_refused_before_any_fit(tmp_path, capsys, monkeypatch, source, target, fix, said):
    cache = tmp_path / "cache"
    monkeypatch.setenv("MATREMAP_CACHE", str(cache))
    code = main(["remap", str(source), "--to", target, "--fix", fix, "-o", str(tmp_path / "out"), "--sweep"])
    captured = capsys.readouterr()
    assert code == 2 and said in captured.err, captured.err
    assert "sweep:" not in captured.err and "fit:" not in captured.err  # refused before any work
    assert not (tmp_path / "out").exists()
    assert not any(cache.rglob("*.sqlite")) and not any(cache.rglob("*.json"))
