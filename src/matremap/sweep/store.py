"""The remapping database: one SQLite file per sweep, written as points finish.

Each finished grid point is one row (source and target parameters, loss, renders, seconds, status),
committed on its own in WAL mode, so a sweep killed at any moment (SIGKILL included) loses at most
the points in flight and never leaves a corrupt file. The sweep's configuration (models, fixed
values, strategy, scene, renderers, package version) is stored once; opening the file for a sweep
with another configuration is refused, so results are never mixed.
"""

from __future__ import annotations

import json
import sqlite3
import time
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from matremap.errors import MatremapError

SCHEMA_VERSION = 1

_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS points (
    key TEXT PRIMARY KEY,          -- canonical JSON of the swept values
    swept TEXT NOT NULL,           -- the swept values, JSON object label -> value
    source TEXT NOT NULL,          -- full source parameters, JSON
    target TEXT,                   -- fitted target parameters, JSON (NULL when failed)
    loss REAL,
    renders INTEGER,
    seconds REAL,
    status TEXT NOT NULL,          -- 'ok' or 'failed'
    message TEXT,
    stages TEXT,                   -- per-stage details, JSON
    warnings TEXT,                 -- JSON list
    warm INTEGER NOT NULL DEFAULT 0,   -- 1 when warm-started from a neighbour
    back TEXT,                     -- round trip: source parameters fitted back, JSON
    back_loss REAL,
    finished REAL NOT NULL         -- unix time
);
"""

COLUMNS = (
    "key",
    "swept",
    "source",
    "target",
    "loss",
    "renders",
    "seconds",
    "status",
    "message",
    "stages",
    "warnings",
    "warm",
    "back",
    "back_loss",
    "finished",
)
JSON_COLUMNS = ("swept", "source", "target", "stages", "warnings", "back")


def point_key(swept: Mapping[str, Any]) -> str:
    """Canonical key of a grid point: its swept values as sorted JSON (floats by repr: exact)."""
    return json.dumps(dict(swept), sort_keys=True)


def _diff(a: Mapping[str, Any], b: Mapping[str, Any], prefix: str = "") -> list[str]:
    out = []
    for k in sorted(set(a) | set(b)):
        va, vb = a.get(k), b.get(k)
        if isinstance(va, Mapping) and isinstance(vb, Mapping):
            out += _diff(va, vb, f"{prefix}{k}.")
        elif va != vb:
            out.append(f"{prefix}{k}")
    return out


class SweepStore:
    """A sweep database. Use :meth:`create_or_open` to start or resume, :meth:`open` to read."""

    def __init__(self, path: Path, conn: sqlite3.Connection) -> None:
        self.path = path
        self.conn = conn

    # -- opening ---------------------------------------------------------------------------
    @classmethod
    def open(cls, path: str | Path) -> SweepStore:
        """Open an existing database for reading (and appending)."""
        p = Path(path)
        if not p.is_file():
            raise MatremapError(f"database {p} not found")
        conn = cls._connect(p)
        try:
            version = conn.execute("SELECT value FROM meta WHERE key = 'schema'").fetchone()
        except sqlite3.DatabaseError as e:
            conn.close()
            raise MatremapError(f"{p} is not a matremap sweep database ({e})") from None
        if version is None or int(json.loads(version[0])) != SCHEMA_VERSION:
            conn.close()
            raise MatremapError(f"{p} is not a matremap sweep database of schema {SCHEMA_VERSION}")
        return cls(p, conn)

    @classmethod
    def create_or_open(cls, path: str | Path, config: Mapping[str, Any]) -> SweepStore:
        """Open the database for this configuration, creating it if it does not exist; a database
        made with another configuration is refused (with the differing keys named)."""
        p = Path(path)
        if p.exists():
            store = cls.open(p)
            stored = store.config
            diff = _diff(stored, config)
            if diff:
                store.close()
                raise MatremapError(
                    f"{p} holds a sweep with a different configuration ({', '.join(diff[:6])} differ); "
                    "use another --db file, or repeat the original command to resume"
                )
            return store
        if not p.parent.is_dir():
            raise MatremapError(f"cannot create {p}: folder {p.parent} does not exist")
        try:
            conn = cls._connect(p)
            with conn:
                conn.executescript(_SCHEMA)
                conn.executemany(
                    "INSERT INTO meta (key, value) VALUES (?, ?)",
                    [
                        ("schema", json.dumps(SCHEMA_VERSION)),
                        ("config", json.dumps(config, sort_keys=True)),
                        ("created", json.dumps(time.time())),
                    ],
                )
        except sqlite3.Error as e:
            raise MatremapError(f"cannot create database {p}: {e}") from None
        return cls(p, conn)

    @staticmethod
    def _connect(p: Path) -> sqlite3.Connection:
        try:
            conn = sqlite3.connect(p, timeout=30.0)
            conn.execute("PRAGMA journal_mode=WAL")
            conn.execute("PRAGMA synchronous=NORMAL")
        except sqlite3.Error as e:
            raise MatremapError(f"cannot open database {p}: {e}") from None
        return conn

    def close(self) -> None:
        self.conn.close()

    def __enter__(self) -> SweepStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- meta --------------------------------------------------------------------------------
    def _meta(self, key: str) -> Any:
        row = self.conn.execute("SELECT value FROM meta WHERE key = ?", (key,)).fetchone()
        return None if row is None else json.loads(row[0])

    def set_meta(self, key: str, value: Any) -> None:
        with self.conn:
            self.conn.execute("INSERT OR REPLACE INTO meta (key, value) VALUES (?, ?)", (key, json.dumps(value)))

    @property
    def config(self) -> dict[str, Any]:
        return self._meta("config")

    @property
    def grid(self) -> dict[str, Any] | None:
        """The grid of the latest run (JSON form of :class:`matremap.sweep.grid.Grid`)."""
        return self._meta("grid")

    # -- rows --------------------------------------------------------------------------------
    def finished_keys(self) -> set[str]:
        """The points fitted successfully; a failed point is not finished: a resumed sweep retries it."""
        return {k for (k,) in self.conn.execute("SELECT key FROM points WHERE status = 'ok'")}

    def add(self, rows: Iterable[Mapping[str, Any]]) -> int:
        """Insert finished points in one transaction; a point already fitted is left as it is, a point
        that had failed is replaced by its retry."""
        values = []
        for r in rows:
            r = {"warm": 0, **r}  # the column's default when a row does not say
            values.append(
                tuple(json.dumps(r.get(c)) if c in JSON_COLUMNS and r.get(c) is not None else r.get(c) for c in COLUMNS)
            )
        with self.conn:
            cur = self.conn.executemany(
                f"INSERT INTO points ({', '.join(COLUMNS)}) VALUES ({', '.join('?' * len(COLUMNS))}) "
                f"ON CONFLICT(key) DO UPDATE SET {', '.join(f'{c} = excluded.{c}' for c in COLUMNS if c != 'key')} "
                "WHERE points.status != 'ok'",
                values,
            )
        return cur.rowcount

    def rows(self, status: str | None = None) -> list[dict[str, Any]]:
        q = f"SELECT {', '.join(COLUMNS)} FROM points"
        args: tuple[Any, ...] = ()
        if status is not None:
            q += " WHERE status = ?"
            args = (status,)
        out = []
        # by key, not by insertion: lines finish in any order, and what is learned must not depend on it
        for values in self.conn.execute(q + " ORDER BY key", args):
            r = dict(zip(COLUMNS, values, strict=True))
            for c in JSON_COLUMNS:
                if r[c] is not None:
                    r[c] = json.loads(r[c])
            out.append(r)
        return out

    def count(self) -> dict[str, int]:
        return dict(self.conn.execute("SELECT status, COUNT(*) FROM points GROUP BY status").fetchall())
