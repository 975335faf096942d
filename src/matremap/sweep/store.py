"""The remapping database: one SQLite file per sweep, written as points finish.

Each finished grid point is one row (source and target parameters, loss, renders, seconds, status),
committed on its own in WAL mode, so a sweep killed at any moment (SIGKILL included) loses at most
the points in flight and never leaves a corrupt file. The sweep's configuration (models, fixed
values, strategy, scene, renderers, package version) is stored once; opening the file for a sweep
with another configuration is refused, so results are never mixed.
"""

from __future__ import annotations

import json
import math
import sqlite3
import time
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any

from matremap.errors import MatremapError, no_space

SCHEMA_VERSION = 1
#: seconds a connection waits for another process's write lock
BUSY_TIMEOUT = 30.0

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
            columns = {row[1] for row in conn.execute("PRAGMA table_info(points)")}
        except sqlite3.DatabaseError as e:
            conn.close()
            raise MatremapError(f"{p} is not a matremap sweep database ({e})") from None
        damage = _damage(conn)
        if damage:
            conn.close()
            raise SweepDatabaseDamaged(
                f"{p} is damaged ({damage}); move it aside and run the sweep again into a new --db file"
            )
        if version is None or _loads(version[0]) != SCHEMA_VERSION:
            conn.close()
            raise MatremapError(f"{p} is not a matremap sweep database of schema {SCHEMA_VERSION}")
        missing = [c for c in COLUMNS if c not in columns]
        if missing:
            conn.close()
            raise MatremapError(
                f"{p} lacks the column(s) {', '.join(missing)} of a sweep database; it was altered: "
                "run the sweep again into a new --db file"
            )
        return cls(p, conn)

    @classmethod
    def create_or_open(cls, path: str | Path, config: Mapping[str, Any]) -> SweepStore:
        """Open the database for this configuration, creating it if it does not exist; a database
        made with another configuration is refused (with the differing keys named). Two sweeps
        starting on a new file at once agree: the first to take the write lock writes the schema and
        its configuration, the other waits for it and is then checked against it like any resume."""
        p = Path(path)
        if not p.parent.is_dir():
            raise MatremapError(f"cannot create {p}: folder {p.parent} does not exist")
        conn = cls._connect(p)
        try:
            conn.execute("BEGIN IMMEDIATE")  # one writer at a time; the others wait (busy timeout)
            tables = {name for (name,) in conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
            created = "meta" not in tables and not tables
            if created:
                for statement in _SCHEMA.split(";"):
                    if statement.strip():
                        conn.execute(statement)
                conn.executemany(
                    "INSERT INTO meta (key, value) VALUES (?, ?)",
                    [
                        ("schema", json.dumps(SCHEMA_VERSION)),
                        ("config", json.dumps(config, sort_keys=True)),
                        ("created", json.dumps(time.time())),
                    ],
                )
            conn.commit()
        except sqlite3.DatabaseError as e:
            conn.close()
            raise no_space(e, [p]) or MatremapError(f"cannot use {p} as a sweep database: {e}") from None
        except BaseException:
            conn.close()
            raise
        if created:
            return cls(p, conn)
        conn.close()
        store = cls.open(p)
        diff = _diff(store.config, config)
        if diff:
            store.close()
            raise MatremapError(
                f"{p} holds a sweep with a different configuration ({', '.join(diff[:6])} differ); "
                "use another --db file, or repeat the original command to resume"
            )
        return store

    @staticmethod
    def _connect(p: Path) -> sqlite3.Connection:
        try:
            conn = sqlite3.connect(p, timeout=BUSY_TIMEOUT)
            # switching a new file to WAL while another process creates it answers "locked" at once,
            # without waiting: wait here as the busy timeout would
            deadline = time.monotonic() + BUSY_TIMEOUT
            while True:
                try:
                    conn.execute("PRAGMA journal_mode=WAL")
                    break
                except sqlite3.OperationalError as e:
                    if "locked" not in str(e) or time.monotonic() > deadline:
                        raise
                    time.sleep(0.02)
            conn.execute("PRAGMA synchronous=NORMAL")
        except sqlite3.Error as e:
            raise no_space(e, [p]) or MatremapError(f"cannot open database {p}: {e}") from None
        return conn

    def close(self) -> None:
        self.conn.close()

    def __enter__(self) -> SweepStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- meta --------------------------------------------------------------------------------
    def _meta(self, key: str) -> Any:
        try:
            row = self.conn.execute("SELECT value FROM meta WHERE key = ?", (key,)).fetchone()
        except sqlite3.Error as e:
            raise MatremapError(f"cannot read {self.path}: {e}") from None
        value = None if row is None else _loads(row[0])
        if value is _BAD:
            raise MatremapError(f"{self.path}: its stored {key} is not valid JSON; the database was altered")
        return value

    def set_meta(self, key: str, value: Any) -> None:
        with self.conn:
            self.conn.execute("INSERT OR REPLACE INTO meta (key, value) VALUES (?, ?)", (key, json.dumps(value)))

    @property
    def config(self) -> dict[str, Any]:
        config = self._meta("config")
        if not isinstance(config, dict):
            raise MatremapError(f"{self.path} holds no sweep configuration; the database was altered")
        return config

    @property
    def grid(self) -> dict[str, Any] | None:
        """The grid of the latest run (JSON form of :class:`matremap.sweep.grid.Grid`)."""
        return self._meta("grid")

    # -- rows --------------------------------------------------------------------------------
    def finished_keys(self) -> set[str]:
        """The points fitted successfully; a failed point is not finished: a resumed sweep retries it."""
        try:
            return {k for (k,) in self.conn.execute("SELECT key FROM points WHERE status = 'ok'")}
        except sqlite3.DatabaseError as e:
            raise MatremapError(f"cannot read the points of {self.path}: {e}") from None

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
        # by key, not by insertion: lines finish in any order, and what is learned must not depend on it
        try:
            raw = self.conn.execute(q + " ORDER BY key", args).fetchall()
        except sqlite3.Error as e:
            raise MatremapError(f"cannot read the points of {self.path}: {e}") from None
        params = _model_params(self._meta("config"))
        return [check_row(dict(zip(COLUMNS, values, strict=True)), str(self.path), params) for values in raw]

    def count(self) -> dict[str, int]:
        return dict(self.conn.execute("SELECT status, COUNT(*) FROM points GROUP BY status").fetchall())


_BAD = object()


class SweepDatabaseDamaged(MatremapError):
    """A sweep database whose pages SQLite's own check finds damaged."""


def _damage(conn: sqlite3.Connection) -> str:
    """What SQLite's ``quick_check`` (each page's structure, in one pass) finds wrong, or "" when nothing."""
    try:
        found = [row[0] for row in conn.execute("PRAGMA quick_check(3)")]
    except sqlite3.OperationalError as e:
        if "locked" in str(e) or "busy" in str(e):
            return ""  # another process writing it: not damage
        return str(e)
    except sqlite3.DatabaseError as e:
        return str(e)
    return "" if found == ["ok"] else "; ".join(str(f) for f in found)[:200]


def discard_if_damaged(path: str | Path, log: Callable[[str], None] | None = None) -> str | None:
    """Remove a damaged database (and its write-ahead log) that a cache holds, so that its sweep runs again,
    with a note to ``log``; what was wrong, or None when it is sound or absent."""
    p = Path(path)
    if not p.is_file():
        return None
    try:
        SweepStore.open(p).close()
    except SweepDatabaseDamaged as e:
        for f in (p, p.with_name(p.name + "-wal"), p.with_name(p.name + "-shm")):
            f.unlink(missing_ok=True)
        damage = str(e).split(" (", 1)[1].split("); ", 1)[0] if " (" in str(e) else str(e)
        if log is not None:
            log(f"note: the cached sweep database {p.name} was damaged ({damage}); sweeping again")
        return damage
    except MatremapError:
        return None  # another problem: the sweep says it in its own words
    return None


def _loads(text: Any) -> Any:
    """Stored JSON text as values; :data:`_BAD` for anything that is not (text, depth, size)."""
    if not isinstance(text, str):
        return _BAD
    try:
        return json.loads(text)
    except (ValueError, RecursionError):
        return _BAD


def _model_params(config: Any) -> tuple[dict[str, int], dict[str, int]] | None:
    """Parameter name -> channels (0 for an option) of the sweep's source and target models, or None if
    the configuration does not name known models (the rows are then checked for types only)."""
    from matremap.dialects import get_model

    try:
        specs = get_model(config["source"]["model"]), get_model(config["target"]["model"])
    except (KeyError, TypeError, MatremapError):
        return None
    source, target = ({**{p.name: p.channels for p in s.params}, **{o: 0 for o in s.option_names}} for s in specs)
    return source, target


_NUMBER_COLUMNS = ("loss", "seconds", "back_loss", "finished")
_INT_COLUMNS = ("renders", "warm")


def check_row(r: dict[str, Any], where: str, params: tuple[dict[str, int], dict[str, int]] | None) -> dict[str, Any]:
    """A stored row with its JSON columns decoded, checked as the readers use it: one MatremapError naming
    the point and the column for text where a number goes, bad JSON or a missing parameter."""
    key = r["key"]
    at = f"{where}: point {str(key)[:80]!r}"
    if not isinstance(key, str) or r["status"] not in ("ok", "failed"):
        raise MatremapError(f"{at}: not a row of a sweep (key {key!r}, status {r['status']!r}); the file was altered")
    for c in JSON_COLUMNS:
        if r[c] is not None:
            r[c] = _loads(r[c])
            if r[c] is _BAD:
                raise MatremapError(f"{at}: column {c} is not valid JSON; the file was altered")
    for c in _NUMBER_COLUMNS + _INT_COLUMNS:
        v = r[c]
        ok_type = int if c in _INT_COLUMNS else (int, float)
        if v is not None and (isinstance(v, bool) or not isinstance(v, ok_type) or not math.isfinite(v)):
            raise MatremapError(f"{at}: column {c} holds {str(v)[:40]!r}, not a number; the file was altered")
    if r["finished"] is None:
        raise MatremapError(f"{at}: column finished is empty; the file was altered")
    for c, kind in (("swept", dict), ("source", dict), ("target", dict), ("back", dict), ("warnings", list)):
        if (r[c] is not None or c in ("swept", "source")) and not isinstance(r[c], kind):
            raise MatremapError(f"{at}: column {c} holds {type(r[c]).__name__}, not a JSON {kind.__name__}")
    if r["status"] == "ok":
        if r["target"] is None or r["loss"] is None:
            raise MatremapError(f"{at}: a successful fit without its target parameters or loss; the file was altered")
        if params is not None:
            for c, names in zip(("source", "target"), params, strict=True):
                _check_params(r[c], names, f"{at}: {c}")
    return r


def _check_params(values: dict[str, Any], channels: dict[str, int], at: str) -> None:
    """Every parameter of the model present, a finite number or a list of that many finite numbers;
    every option (``channels`` 0) a string."""
    for name, n in channels.items():
        v = values.get(name)
        if n == 0:
            if not isinstance(v, str):
                raise MatremapError(f"{at} option {name} is {str(v)[:40]!r}, not a string")
            continue
        items = (v if isinstance(v, list) and len(v) == n else [None]) if n > 1 else [v]
        if not all(not isinstance(x, bool) and isinstance(x, (int, float)) and math.isfinite(x) for x in items):
            raise MatremapError(f"{at} parameter {name} is {str(v)[:40]!r}, not {n} finite number(s)")
