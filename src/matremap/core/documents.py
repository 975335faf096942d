"""Reading the small JSON / TOML documents users hand over (materials, grids, manifests, transforms).

Every document is checked for nesting depth (:data:`MAX_DEPTH`) as it is read: no file matremap reads
needs more than a handful of levels, and a document nested thousands deep would otherwise end in a
RecursionError in the parser or in whatever walks it next.
"""

from __future__ import annotations

import json
import tomllib
from pathlib import Path
from typing import Any

from matremap.errors import MatremapError

#: deepest nesting of objects / arrays accepted in a document (transforms need about 6)
MAX_DEPTH = 64


def read_document(path: str | Path, what: str) -> Any:
    """Parse a ``.toml`` file as TOML and anything else as JSON; every failure is one
    MatremapError naming ``what`` (e.g. "grid file"), the file and the problem."""
    p = Path(path)
    try:
        text = p.read_text()
    except FileNotFoundError:
        raise MatremapError(f"{what} {p} not found") from None
    except (OSError, ValueError) as e:  # ValueError: undecodable text, a NUL in the name
        reason = e.strerror if isinstance(e, OSError) and e.strerror else e
        raise MatremapError(f"cannot read {what} {p!s:.200}: {reason}") from None
    except MemoryError:
        raise MatremapError(f"cannot read {what} {p}: too large to hold in memory") from None
    if p.suffix.lower() == ".toml":
        try:
            doc = tomllib.loads(text)
        except tomllib.TOMLDecodeError as e:
            raise MatremapError(f"{what} {p} is not valid TOML: {e}") from None
        except RecursionError:
            raise MatremapError(f"{what} {p} is nested too deeply (more than {MAX_DEPTH} levels)") from None
        check_depth(doc, f"{what} {p}")
        return doc
    return parse_json(text, f"{what} {p}")


def parse_json(text: str, what: str) -> Any:
    """JSON text as Python values; invalid JSON, non-standard numbers (NaN, Infinity) and nesting deeper
    than :data:`MAX_DEPTH` are one MatremapError naming ``what``."""

    def no_constant(name: str) -> Any:
        raise MatremapError(f"{what} holds {name}, which is not a JSON number; write a finite number")

    try:
        doc = json.loads(text, parse_constant=no_constant)
    except json.JSONDecodeError as e:
        raise MatremapError(f"{what} is not valid JSON: {e.msg} (line {e.lineno}, column {e.colno})") from None
    except RecursionError:
        raise MatremapError(f"{what} is nested too deeply (more than {MAX_DEPTH} levels)") from None
    check_depth(doc, what)
    return doc


def check_depth(doc: Any, what: str, limit: int = MAX_DEPTH) -> None:
    """Refuse a document whose objects / arrays nest deeper than ``limit`` (walked without recursion)."""
    stack: list[tuple[Any, int]] = [(doc, 1)]
    while stack:
        node, depth = stack.pop()
        if isinstance(node, dict):
            children: Any = node.values()
        elif isinstance(node, list):
            children = node
        else:
            continue
        if depth > limit:
            raise MatremapError(f"{what} is nested too deeply (more than {limit} levels)")
        stack.extend((c, depth + 1) for c in children if isinstance(c, (dict, list)))
