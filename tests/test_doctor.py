"""``matremap doctor`` (issue 20, must-have 4): it reports this installation as it is (versions checked
against the packages' own metadata, the cache's size against files written here), and a piece whose
import is missing, hangs or crashes the interpreter is reported with the command that installs it while
the rest is still checked; only a broken core makes it fail (exit 4)."""

from __future__ import annotations

import importlib.metadata as md
import importlib.util
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

from matremap import __version__
from matremap.cli import main

SRC = Path(__file__).resolve().parents[1] / "src"


def pieces(doc):
    return {p["name"]: p for p in doc["pieces"]}


def test_doctor_reports_versions_and_the_cache(capsys, tmp_path, monkeypatch):
    cache = tmp_path / "cache"
    (cache / "transforms").mkdir(parents=True)
    (cache / "transforms" / "t.json").write_bytes(b"x" * 1000)
    (cache / "table.npz").write_bytes(b"y" * 24)
    monkeypatch.setenv("MATREMAP_CACHE", str(cache))
    code = main(["doctor", "--json"])
    doc = json.loads(capsys.readouterr().out)
    assert code == 0 and doc["core_ok"]
    assert doc["matremap"] == __version__ and doc["python"] == platform.python_version()
    assert doc["cache"] == {
        "path": str(cache),
        "from": "$MATREMAP_CACHE",
        "exists": True,
        "bytes": 1024,
        "files": 2,
        "transforms": 1,
    }
    got = pieces(doc)
    assert got["numpy"]["version"] == md.version("numpy") and got["embedded"]["status"] == "ok"
    for name, dist, module in (
        ("mitsuba3", "mitsuba", "mitsuba"),
        ("usd", "usd-core", "pxr"),
        ("scikit-learn", "scikit-learn", "sklearn"),
        ("dask", "dask", "dask"),
    ):
        if importlib.util.find_spec(module):
            assert got[name]["status"] == "ok" and got[name]["version"] == md.version(dist), got[name]
        else:
            assert got[name]["status"] == "missing" and dist in got[name]["install"]
    if got["mitsuba3"]["status"] == "ok":
        assert "llvm_ad_rgb" in got["mitsuba3"]["detail"]
    if got["materialx"]["status"] == "ok":  # the standard libraries loaded: their node definitions counted
        assert Path(got["materialx"]["detail"].split("data libraries ")[1].split(" (")[0]).is_dir()

    assert main(["doctor"]) == 0
    text = capsys.readouterr().out
    assert text.splitlines()[0].startswith(f"matremap {__version__} on Python {platform.python_version()}")
    assert f"{cache} (set by $MATREMAP_CACHE): 1.0 KB in 2 files, 1 learned transforms" in text
    assert text.splitlines()[-1].startswith("the core works")


def _fake_modules(folder: Path, modules: dict[str, str]) -> Path:
    for name, code in modules.items():
        (folder / name).mkdir(parents=True)
        (folder / name / "__init__.py").write_text(code)
    return folder


def _doctor(tmp_path: Path, modules: dict[str, str], timeout: float = 15.0) -> tuple[int, dict, float]:
    fake = _fake_modules(tmp_path / "fake", modules)
    env = {**os.environ, "PYTHONPATH": f"{fake}{os.pathsep}{SRC}", "MATREMAP_CACHE": str(tmp_path / "cache")}
    env["MATREMAP_BPY_PYTHON"] = str(tmp_path / "no-such-python")
    t0 = time.monotonic()
    proc = subprocess.run(
        [sys.executable, "-m", "matremap.cli", "doctor", "--json", "--timeout", str(timeout)],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )
    return proc.returncode, json.loads(proc.stdout), time.monotonic() - t0


def test_missing_hanging_and_crashing_imports_are_reported_and_the_rest_checked(tmp_path):
    code, doc, seconds = _doctor(
        tmp_path,
        {
            "pxr": "raise ModuleNotFoundError(\"No module named 'pxr'\")",
            "sklearn": "import time\ntime.sleep(120)\n",
            "pyarrow": "import os\nos.abort()\n",
        },
        timeout=6.0,  # each import's own limit: the real ones take about a second, the hanging one is cut here
    )
    got = pieces(doc)
    assert code == 0 and doc["core_ok"]  # optional pieces missing: still exit 0
    assert got["usd"]["status"] == "missing" and "usd-core" in got["usd"]["install"]
    assert got["usd"]["install"].startswith(f"{sys.executable} -m pip install")
    assert got["scikit-learn"]["status"] == "broken" and "timed out after 6 s" in got["scikit-learn"]["detail"]
    assert "scikit-learn" in got["scikit-learn"]["install"]
    assert got["pyarrow"]["status"] == "broken" and "crashed (signal 6)" in got["pyarrow"]["detail"]
    assert got["cycles"]["status"] == "missing" and "bpy==5.0.1" in got["cycles"]["install"]
    assert got["numpy"]["status"] == "ok" and got["embedded"]["status"] == "ok"
    assert seconds < 6 + 30  # the hanging import was killed at its timeout
    assert doc["cache"]["exists"] is False and doc["cache"]["bytes"] == 0


def test_a_broken_core_fails_with_the_command_to_fix_it(tmp_path):
    code, doc, _ = _doctor(tmp_path, {"OpenImageIO": "raise ImportError('libOpenImageIO.so.3.2: cannot open')"})
    got = pieces(doc)
    assert code == 4 and not doc["core_ok"]
    assert got["OpenImageIO"]["status"] == "broken" and "cannot open" in got["OpenImageIO"]["detail"]
    assert "pip install 'OpenImageIO'" in got["OpenImageIO"]["install"]
