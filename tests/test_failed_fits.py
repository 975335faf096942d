"""Failed fits are not cached for ever (issue 19, finding 3): a remap whose sweep had a failed point does not
cache the transform it learned without that point, so the next run, the failure gone (the renderer
installed, say), fits the failed point again instead of reusing the incomplete transform."""

from __future__ import annotations

from pathlib import Path

import pytest

from matremap.cli import main

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


@pytest.mark.slow
def test_a_transform_learned_with_failed_points_is_not_cached(tmp_path, capsys, monkeypatch):
    import matremap.sweep.run as sweep_run

    real, calls = sweep_run.fit_steps, []

    def flaky(*args, **kwargs):
        calls.append(1)
        if len(calls) == 1:
            raise RuntimeError("a numerical failure")
        return real(*args, **kwargs)

    cache = tmp_path / "cache"
    args = ["remap", str(EXAMPLES / "blue-plastic"), "--to", "mitsuba06:pbr", "--fix", "distribution=as"]
    args += ["--sweep", "--no-evaluate", "--workers", "1", "--cache", str(cache)]
    monkeypatch.setattr(sweep_run, "fit_steps", flaky)
    assert main([*args, "-o", str(tmp_path / "first")]) in (0, 3)
    err = capsys.readouterr().err
    assert "1 failed" in err and "not cached" in err, err
    assert list(cache.glob("*.json")) == []  # before: cached, and every later run reused it
    assert (tmp_path / "first" / "transform.json").is_file()  # what this run applied is still written
    monkeypatch.setattr(sweep_run, "fit_steps", real)
    assert main([*args, "-o", str(tmp_path / "second")]) == 0
    err = capsys.readouterr().err
    assert "sweep: done: 1 points fitted (0 failed)" in err, err  # only the failed point, from the database
    assert len(list(cache.glob("*.json"))) == 1
    assert main([*args, "-o", str(tmp_path / "third")]) == 0
    assert "transform: cached" in capsys.readouterr().err
