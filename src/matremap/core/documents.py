"""Reading the small JSON / TOML documents users hand over (materials, grids, manifests, transforms)."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path
from typing import Any

from matremap.errors import MatremapError


def read_document(path: str | Path, what: str) -> Any:
    """Parse a ``.toml`` file as TOML and anything else as JSON; every failure is one
    MatremapError naming ``what`` (e.g. "grid file"), the file and the problem."""
    p = Path(path)
    try:
        text = p.read_text()
    except FileNotFoundError:
        raise MatremapError(f"{what} {p} not found") from None
    except (OSError, UnicodeDecodeError) as e:
        raise MatremapError(f"cannot read {what} {p}: {e}") from None
    if p.suffix.lower() == ".toml":
        try:
            return tomllib.loads(text)
        except tomllib.TOMLDecodeError as e:
            raise MatremapError(f"{what} {p} is not valid TOML: {e}") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise MatremapError(f"{what} {p} is not valid JSON: {e.msg} (line {e.lineno})") from None
