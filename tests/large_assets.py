"""The larger public test assets, fetched on demand (``python tools/fetch_assets.py NAME``) and skipped when absent.

The assets, their sources and licences are listed in tests/data/large.json and tests/data/corpus/README.md
("Larger assets, fetched on demand"); they live in ``tests/data/large/<name>`` (git-ignored), or
``$MATREMAP_LARGE_ASSETS/<name>``. :func:`large_asset` gives a test an asset's folder: it skips the test when the
folder is absent, and fails it when the folder is there but its files are not the manifest's (a stale or edited
copy), saying how to fetch it again.
"""

from __future__ import annotations

import importlib.util
import sys
from functools import cache
from pathlib import Path
from types import ModuleType

import pytest

TOOL = Path(__file__).resolve().parents[1] / "tools" / "fetch_assets.py"


@cache
def fetch_tool() -> ModuleType:
    """tools/fetch_assets.py as a module (tools/ is not a package): its manifest reader and blob check."""
    spec = importlib.util.spec_from_file_location("fetch_assets", TOOL)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up while the class is made
    spec.loader.exec_module(module)
    return module


@cache
def _problems(folder: Path, name: str) -> tuple[str, ...]:
    tool = fetch_tool()
    return tuple(tool.problems(folder, tool.load_manifest()[name]))


def large_asset(name: str) -> Path:
    """The folder of the fetched asset ``name`` (a key of tests/data/large.json), every file checked against its git
    blob id once per session; ``pytest.skip`` when it has not been fetched."""
    tool = fetch_tool()
    if name not in tool.load_manifest():
        raise ValueError(f"no asset {name!r} in {tool.MANIFEST}")
    folder = tool.default_dest() / name
    if not folder.is_dir():
        pytest.skip(f"{name} absent; fetch with python tools/fetch_assets.py {name}")
    wrong = _problems(folder, name)
    if wrong:
        pytest.fail(
            f"{folder} is not the manifest's {name} ({wrong[0]}); fetch it again with "
            f"python tools/fetch_assets.py --force {name}"
        )
    return folder
