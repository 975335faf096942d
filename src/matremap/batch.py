"""Many files at once: every material of every input file, in parallel, resumable, with one summary.

``matremap remap PATH... --to MODEL -o OUT`` with several inputs, a folder or a glob lands here. Each
material of each file is one *item*, remapped by :func:`matremap.remap.remap_file` into its own folder
``OUT/<file>/<material>/`` (all or nothing, as for one file). Items run in parallel worker processes
(one per core by default). An item's folder holds ``item.json``: the key it was made with (a digest of
the input file and every file it references, the target, the options and matremap's version) and its
summary row; a rerun skips items whose key is unchanged, so an edited input (or texture) is redone.

At the end ``OUT/summary.csv``, ``OUT/summary.json`` and ``OUT/index.html`` list every item: file,
material, models, route (identity, library, cached or new sweep, fit), the quality gate's measures,
the verdict (passed, failed, refused, error) and seconds; the page shows each item's source and target
renders and sorts by any column. The exit status is 0 only when every item passed; otherwise the worst
one's (:mod:`matremap.errors`).

OUT is the batch's alone: it may not hold an input, a file an input names or the cache, nor files a batch
did not write (:func:`check_out`); a search of the inputs does not enter it; one batch at a time writes it
(:func:`batch_lock`); and what a killed batch or worker left there is removed by the next one
(:func:`clean_leftovers`). SECURITY.md ("Batches") states each rule and the test that holds it.
"""

from __future__ import annotations

import csv
import glob
import hashlib
import html
import itertools
import json
import os
import re
import signal
import stat
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, Executor, Future, ProcessPoolExecutor, wait
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

from matremap import __version__
from matremap.core.atomic import MARK, OUTPUT_RECORD, clean_stale, record_written
from matremap.core.imageio import write_text
from matremap.errors import EXIT_INTERRUPTED, EXIT_QUALITY, MatremapError

#: the exit status of bad input (MatremapError's)
EXIT_INPUT = MatremapError.exit_code

#: the per-item record a rerun compares against
ITEM_FILE = "item.json"
#: verdicts in the order of how bad they are
VERDICTS = ("passed", "failed", "refused", "error")


@dataclass(frozen=True)
class Item:
    """One material of one file, and the folder its result goes to (relative to OUT)."""

    file: Path
    material: int
    name: str
    slot: str


_SURROGATE = re.compile("[\ud800-\udfff]")


def printable(text: str) -> str:
    """``text`` as valid Unicode, for the summary, the page and the terminal: a byte of a file name that is not
    UTF-8 (held by Python as a lone surrogate) shown as ``\\xNN``, any other lone surrogate (a material name
    written with an invalid ``\\u`` escape) as ``\\uXXXX``."""

    def shown(m: re.Match[str]) -> str:
        code = ord(m.group())
        return f"\\x{code - 0xDC00:02x}" if 0xDC80 <= code <= 0xDCFF else f"\\u{code:04x}"

    return _SURROGATE.sub(shown, text) if isinstance(text, str) else text


@dataclass
class Row:
    """One line of the summary."""

    file: str
    material: str
    slot: str
    source_model: str = ""
    target_model: str = ""
    route: str = ""
    verdict: str = "error"
    exit_code: int = EXIT_INPUT
    reason: str = ""
    measures: dict[str, float] = field(default_factory=dict)
    seconds: float = 0.0
    output: str = ""
    thumbnails: dict[str, str] = field(default_factory=dict)
    #: the file holding every converted material of the input (relative to OUT), when one was written
    whole_file: str = ""

    def __post_init__(self) -> None:
        for name in ("file", "material", "slot", "source_model", "target_model", "route", "reason", "output"):
            setattr(self, name, printable(getattr(self, name)))

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass
class BatchResult:
    """The rows of the items that finished; ``interrupted``: how many did not (Ctrl-C)."""

    rows: list[Row]
    skipped: int
    out: Path
    interrupted: int = 0

    def counts(self) -> dict[str, int]:
        return {v: sum(r.verdict == v for r in self.rows) for v in VERDICTS}

    @property
    def exit_code(self) -> int:
        """130 when interrupted; else 0 when every item passed, else the highest exit status among them."""
        if self.interrupted:
            return EXIT_INTERRUPTED
        return max((r.exit_code for r in self.rows), default=0)

    def line(self) -> str:
        """The batch in one line: how many passed, failed and were refused (and the worst one's reason)."""
        c = self.counts()
        if self.interrupted:
            total = len(self.rows) + self.interrupted
            return (
                f"interrupted: {len(self.rows)} of {total} material(s) finished and kept ({c['passed']} passed, "
                f"{c['failed']} failed, {c['refused']} refused, {c['error']} error(s)); rerun the same command "
                f"to do the other {self.interrupted}"
            )
        worst = max((r for r in self.rows if r.verdict != "passed"), key=lambda r: r.exit_code, default=None)
        tail = f"; worst: {worst.file} [{worst.material}]: {worst.reason}" if worst else ""
        unread = sum(not r.material for r in self.rows)
        what = f"{len(self.rows) - unread} material(s)" + (f" and {unread} unreadable file(s)" if unread else "")
        return (
            f"{what}: {c['passed']} passed, {c['failed']} failed the quality gate, "
            f"{c['refused']} refused, {c['error']} error(s) ({self.skipped} unchanged, not redone){tail}"
        )


def expand_inputs(
    paths: Sequence[str | os.PathLike],
    skipped: list[Path] | None = None,
    exclude: Sequence[Path] = (),
    written: list[Path] | None = None,
) -> list[Path]:
    """Material files named by ``paths``: files as given, folders searched recursively, glob patterns
    expanded; each file once, in the order found. A path that names nothing is an error. An ``.xml`` file a
    folder or a pattern finds is taken only when it looks like a Mitsuba scene (:func:`looks_like_scene`) and
    no other scene found there includes it (:func:`included_files`): asset folders hold other XML (metadata,
    licences, exports) and scene parts; those are appended to ``skipped``. A search never enters the folders
    ``exclude`` (the batch's OUT, the cache), a folder matremap wrote (:func:`written_by_matremap`; appended to
    ``written``) or one of matremap's temporary names."""
    from matremap.formats import is_material_file

    fences = [Path(os.path.realpath(e)) for e in exclude]
    marks: dict[Path, bool] = {}  # folder -> whether matremap wrote it, each looked at once
    found: list[Path] = []
    for raw in paths:
        text = str(raw)
        if any(ch in text for ch in "*?["):
            matches = [Path(m) for m in sorted(glob.glob(text, recursive=True))]
            kept = [m for m in matches if not _fenced(m, _glob_base(text), fences, written, marks)]
            files = _scanned([m for m in kept if m.is_file() and is_material_file(m)], skipped)
            if not files:
                raise MatremapError(f"{text}: the pattern matches no material file ({SUFFIXES})")
        elif Path(text).is_dir():
            tree = walk_files(Path(text), fences, written)
            files = _scanned(sorted(p for p in tree if p.is_file() and is_material_file(p)), skipped)
            if not files:
                raise MatremapError(f"{text}: the folder holds no material file ({SUFFIXES})")
        elif Path(text).is_file():
            files = [Path(text)]
        else:
            raise MatremapError(f"{text} not found")
        found += [f for f in files if f.resolve() not in {g.resolve() for g in found}]
    return found


#: what a batch keeps in OUT while it runs: locked for the batch's duration (:func:`batch_lock`), and the mark
#: of a folder a batch wrote
LOCK_FILE = ".matremap.lock"
#: the bytes of a file read to decide whether matremap wrote it (a verdict, a summary)
_SMALL = 1 << 20


def written_by_matremap(folder: Path, names: Iterable[str] | None = None) -> bool:
    """Whether ``folder`` is one matremap wrote: one carrying its output record, a batch's OUT (its lock file, or a
    batch's ``summary.json``),
    a batch item's folder (``item.json``) or a remap's output folder (its ``verdict.json``). ``names``: the
    names of the files in it, when the caller listed them already."""
    if names is None:
        try:
            names = [e.name for e in os.scandir(folder)]
        except OSError:
            return False
    names = set(names)
    if LOCK_FILE in names or OUTPUT_RECORD in names:
        return True
    if ITEM_FILE in names and _json_keys(folder / ITEM_FILE) >= {"key", "row"}:
        return True
    if "summary.json" in names and _json_keys(folder / "summary.json") >= {"counts", "items", "exit_code"}:
        return True
    return "verdict.json" in names and _json_keys(folder / "verdict.json") >= {"passed", "checks"}


def _json_keys(path: Path) -> set[str]:
    """The keys of the JSON object in a small regular file, else an empty set."""
    data = read_bounded(path, _SMALL)
    try:
        doc = json.loads(data) if data is not None and len(data) < _SMALL else None
    except ValueError:
        return set()
    return set(doc) if isinstance(doc, dict) else set()


def _fenced(
    path: Path, base: Path, fences: Sequence[Path], written: list[Path] | None, marks: dict[Path, bool]
) -> bool:
    """Whether ``path``, found under ``base``, lies in a folder a search does not enter (see :func:`expand_inputs`);
    ``marks``: the folders looked at so far."""
    real = Path(os.path.realpath(path))
    if any(real == f or f in real.parents for f in fences):
        return True
    inner = path.relative_to(base).parts if path.is_relative_to(base) else ()
    if any(part.startswith(MARK) for part in inner):
        return True
    for depth in range(1, len(inner)):
        folder = base.joinpath(*inner[:depth])
        if folder not in marks:
            marks[folder] = written_by_matremap(folder)
        if marks[folder]:
            if written is not None and folder not in written:
                written.append(folder)
            return True
    return False


def _glob_base(pattern: str) -> Path:
    """The folder a glob pattern searches from: its parts before the first one with a wildcard."""
    parts = Path(pattern).parts
    fixed = list(itertools.takewhile(lambda part: not any(ch in part for ch in "*?["), parts))
    return Path(*fixed) if fixed else Path()


def walk_files(root: Path, fences: Sequence[Path], written: list[Path] | None = None) -> Iterator[Path]:
    """The files under ``root`` (folder links not followed), without the folders ``fences`` and, below
    ``root``, the folders matremap wrote (appended to ``written``) and matremap's temporary names."""
    for folder, dirs, names in os.walk(root):
        here = Path(folder)
        if here != root and written_by_matremap(here, names):
            dirs.clear()
            if written is not None:
                written.append(here)
            continue
        dirs[:] = [
            d for d in dirs if not d.startswith(MARK) and not any(Path(os.path.realpath(here / d)) == f for f in fences)
        ]
        yield from (here / n for n in names if not n.startswith(MARK))


#: the suffixes a folder or a pattern is searched for, as messages name them
SUFFIXES = ".gltf, .glb, .mtlx, Mitsuba .xml, .usda, .usdc, .usdz, .usd"
#: an XML declaration, processing instruction, comment or document type before the root element
_PROLOGUE = re.compile(rb"\s*(<\?.*?\?>|<!--.*?-->|<!DOCTYPE[^>]*>)", re.S)
_ROOT = re.compile(rb"\s*<([A-Za-z_][\w.:-]*)")


def looks_like_scene(path: Path) -> bool:
    """Whether an ``.xml`` file's root element is a Mitsuba scene's (``<scene>`` or ``<bsdf>``), read from its
    first 64 KB without parsing it; a file whose root is not found there is taken (its reader decides)."""
    if path.suffix.lower() != ".xml":
        return True
    try:
        with path.open("rb") as f:
            head = f.read(65536).removeprefix(b"\xef\xbb\xbf")
    except OSError:
        return True
    pos = 0
    while (m := _PROLOGUE.match(head, pos)) is not None:
        pos = m.end()
    root = _ROOT.match(head, pos)
    return root is None or root.group(1) in (b"scene", b"bsdf")


#: a Mitsuba ``<include filename="..."/>`` (its attribute in either quotes)
_INCLUDE = re.compile(rb"""<include\b[^>]*?\bfilename\s*=\s*(?:"([^"]*)"|'([^']*)')""")


def included_files(scenes: Sequence[Path]) -> set[Path]:
    """The files among ``scenes`` that one of them ``<include>``s (beside the including file, where Mitsuba
    looks first): parts of a scene, converted through the scene that includes them, not as scenes of their own."""
    found = {f.resolve() for f in scenes}
    parts: set[Path] = set()
    for f in scenes:
        if f.suffix.lower() != ".xml":
            continue
        try:
            text = f.read_bytes()
        except OSError:
            continue
        for m in _INCLUDE.finditer(text):
            name = (m.group(1) or m.group(2) or b"").decode("utf-8", "replace")
            target = (f.parent / name).resolve()
            if name and target in found and target != f.resolve():
                parts.add(target)
    return parts


def _scanned(files: list[Path], skipped: list[Path] | None) -> list[Path]:
    """The files a folder or a pattern found, without the XML files that are not Mitsuba scenes and the
    scene parts another scene found here includes."""
    scenes = [f for f in files if looks_like_scene(f)]
    parts = included_files(scenes)
    kept = [f for f in scenes if f.resolve() not in parts]
    if skipped is not None:
        skipped += [f for f in files if f not in kept]
    return kept


#: the longest name of a folder a batch makes (a file's, an item's): with the staging mark
#: (:func:`matremap.core.atomic.temp_prefix`) in front, well under the 255 bytes file systems allow
MAX_SLUG = 96


def _slug(text: str, prefix: str = "") -> str:
    """A folder name for ``text``: ``prefix``, then its letters, digits and ``._-``; a longer one cut to
    :data:`MAX_SLUG` characters, ending in a digest of the whole text (two long names that begin alike stay
    apart)."""
    slug = prefix + (re.sub(r"[^A-Za-z0-9._-]+", "_", text).strip("._") or "material")
    if len(slug) <= MAX_SLUG:
        return slug
    digest = hashlib.sha256(text.encode("utf-8", "surrogatepass")).hexdigest()[:10]
    return f"{slug[: MAX_SLUG - 11]}-{digest}"


def plan(files: Sequence[Path], material: str | None = None, unread: dict[Path, str] | None = None) -> list[Item]:
    """Every material of every file (or only the one named ``material``), each with its own folder.

    A file whose materials cannot be listed (malformed, or a format matremap refuses) raises, unless
    ``unread`` is given: then its one-line reason goes there and the other files are planned. With
    ``material``, files without it are left out; it is an error only when no file has it."""
    from matremap.formats import material_names

    items: list[Item] = []
    lacking: list[tuple[Path, list[str]]] = []
    for f, folder in file_folders(files).items():
        try:
            names = material_names(f)
        except MatremapError as e:
            if unread is None:
                raise
            unread[f] = str(e)
            continue
        mine = [
            Item(f, i, name, f"{folder}/{_slug(name, f'{i:03d}-' if len(names) > 1 else '')}")
            for i, name in enumerate(names)
            if material is None or material in (name, str(i))
        ]
        if not mine:
            lacking.append((f, names))
        items += mine
    if material is not None and not items and lacking:
        if len(lacking) == 1:
            f, names = lacking[0]
            raise MatremapError(f"{f} has no material {material!r}; its materials are {', '.join(names)}")
        raise MatremapError(f"none of the {len(lacking)} files has a material {material!r}")
    return items


def file_folders(files: Sequence[Path]) -> dict[Path, str]:
    """Each file's output folder (relative to OUT): its name, numbered from the second file of that name."""
    stems: dict[str, int] = {}
    out = {}
    for f in files:
        stem = _slug(f.name)
        stems[stem] = stems.get(stem, 0) + 1
        out[f] = stem if stems[stem] == 1 else _slug(f"{f.name}-{stems[stem]}")
    return out


#: what separates a file name from the text around it in the formats read here: JSON and XML quotes and
#: punctuation, path separators, USD's @asset@ delimiters, the control bytes of binary containers
_NAME_DELIMITERS = re.compile(rb"[\x00-\x1f\"'<>/\\@=,;()\[\]{}|*?]+")


def _names_in(data: bytes) -> set[str]:
    """The strings of ``data`` that could be file names (also percent-decoded, as glTF URIs are written)."""
    from urllib.parse import unquote

    names: set[str] = set()
    for token in _NAME_DELIMITERS.split(data):
        t = token.strip()
        if t and len(t) <= 255:
            text = t.decode("utf-8", "replace")
            names.update((text, unquote(text)))
    return names


#: the bytes of one file change detection reads: a file larger than this is keyed by its size and
#: modification time instead of its content, and only its first bytes are searched for file names
MAX_READ = 256 << 20


def read_bounded(path: Path, limit: int) -> bytes | None:
    """The first ``limit`` + 1 bytes of ``path`` when it is a regular file (a FIFO, a device or a socket is
    never opened for a blocking read), else None."""
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    except (OSError, ValueError):
        return None
    with os.fdopen(fd, "rb") as f:
        try:
            if not stat.S_ISREG(os.fstat(fd).st_mode):
                return None
            return f.read(limit + 1)
        except OSError:
            return None


def _file_digest(h: Any, path: Path) -> None:
    """Feed ``path``'s content to ``h`` (streamed, at most :data:`MAX_READ` bytes), or its size and modification
    time when it is larger; what is not a regular file feeds a word saying so."""
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    except (OSError, ValueError):
        h.update(b"unreadable")
        return
    with os.fdopen(fd, "rb") as f:
        try:
            st = os.fstat(fd)
            if not stat.S_ISREG(st.st_mode):
                h.update(b"not a regular file")
            elif st.st_size > MAX_READ:
                h.update(f"size {st.st_size} modified {st.st_mtime_ns}".encode())
            else:
                left = MAX_READ
                while left > 0 and (chunk := f.read(min(1 << 20, left))):
                    h.update(chunk)
                    left -= len(chunk)
        except OSError:
            h.update(b"unreadable")


class References:
    """The files a material file references, for the key a rerun compares: found by name under the file's own
    folder and the allowed folders (``--allow-path``), and through the material files among them (a Mitsuba
    ``<include>``, a USD sublayer), so that a texture named only in an included file counts. Over-inclusion (a
    file of the same name that is not used) only makes a rerun redo more. Each folder is listed once.

    Only regular files whose real path (links followed) lies inside those folders count, each read at most
    :data:`MAX_READ` bytes; the folders ``exclude`` (the batch's OUT, the cache) and folders matremap wrote
    are not searched."""

    def __init__(self, allow: Sequence[str | os.PathLike] = (), exclude: Sequence[str | os.PathLike] = ()) -> None:
        self.allow = [Path(a).resolve() for a in allow]
        self.exclude = [Path(os.path.realpath(e)) for e in exclude]
        self._trees: dict[Path, dict[str, list[Path]]] = {}
        self._files: dict[Path, list[Path]] = {}
        self._digests: dict[Path, str] = {}

    def _tree(self, root: Path) -> dict[str, list[Path]]:
        if root not in self._trees:
            index: dict[str, list[Path]] = {}
            for path in walk_files(root, self.exclude):
                index.setdefault(path.name, []).append(path)
            self._trees[root] = index
        return self._trees[root]

    def _confined(self, path: Path, roots: Sequence[Path]) -> Path | None:
        """``path``'s real path when it is a regular file inside one of ``roots``, outside the excluded folders."""
        real = Path(os.path.realpath(path))
        inside = any(real == r or r in real.parents for r in roots)
        fenced = any(real == e or e in real.parents for e in self.exclude)
        try:
            regular = stat.S_ISREG(os.stat(real).st_mode)
        except OSError:
            regular = False
        return real if inside and not fenced and regular else None

    def files(self, file: Path) -> list[Path]:
        """``file`` first, then every file it references (see the class), in a fixed order."""
        if file not in self._files:
            self._files[file] = self._search(file)
        return self._files[file]

    def _search(self, file: Path) -> list[Path]:
        from matremap.formats import READERS

        roots = list(dict.fromkeys([file.parent.resolve(), *self.allow]))
        seen = {file.resolve(): file}
        queue = [file]
        while queue:
            data = read_bounded(queue.pop(0), MAX_READ)
            if data is None:
                continue
            for name in sorted(_names_in(data)):
                for p in (p for root in roots for p in self._tree(root).get(name, ())):
                    real = self._confined(p, roots)
                    if real is not None and real not in seen:
                        seen[real] = p
                        if p.suffix.lower() in READERS:
                            queue.append(p)
        return [file, *sorted(p for p in seen.values() if p != file)]

    def digest(self, file: Path) -> str:
        """A digest of the bytes of ``file`` and of the files it references, with their names."""
        if file not in self._digests:
            h = hashlib.sha256()
            for p in self.files(file):
                h.update(os.fsencode(p.name))
                _file_digest(h, p)
            self._digests[file] = h.hexdigest()
        return self._digests[file]


def item_key(item: Item, target: str, options: Mapping[str, Any], references: References | None = None) -> str:
    """A digest of everything that decides an item's result: the file's bytes and those of every file it
    references (:class:`References`), the material, the target, the options, matremap's version and its
    results revision."""
    h = hashlib.sha256()
    h.update((references or References()).digest(item.file).encode())
    from matremap.core.diskcache import RESULTS_REVISION

    doc = {
        "material": item.material,
        "target": target,
        "options": options,
        "version": __version__,
        "revision": RESULTS_REVISION,
    }
    h.update(json.dumps(doc, sort_keys=True, default=str).encode())
    return h.hexdigest()


def run_batch(
    paths: Sequence[str | os.PathLike],
    target: str,
    out: str | os.PathLike,
    *,
    material: str | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    dask_local: int | None = None,
    options: Mapping[str, Any] | None = None,
    allow_paths: Sequence[str | os.PathLike] | None = None,
    log: Callable[[str], None] = print,
    progress: bool = True,
) -> BatchResult:
    """Remap every material of the files ``paths`` name onto ``target`` into ``out`` (see the module
    docstring). ``options``: keyword arguments of :func:`matremap.remap.remap_file` (no ``log``: each
    item logs to ``OUT/<item>/log.txt``). ``workers``: local processes (default: the cores); ``scheduler``
    (a Dask scheduler address) or ``dask_local`` (a local Dask cluster of that many workers) run the items
    on Dask instead. ``allow_paths``: folders outside each file's own that its references may point into
    (``--allow-path``). Ctrl-C stops the workers: finished items are kept, the others leave nothing behind
    and are redone by a rerun; the result then says how many were left (``interrupted``, exit status 130)
    and no whole-file outputs are assembled.

    Before anything is written, OUT is refused (:func:`check_out`) when it is, or holds, an input, a file
    an input names or the cache, or when it is a folder of other files than a batch's. OUT is locked while
    the batch runs (:func:`batch_lock`): a second batch into it waits, then redoes nothing the first did."""
    from matremap.dialects import get_model

    target = get_model(target).id
    log = _printable_log(log)
    if workers is not None and workers < 1:
        raise MatremapError(f"--workers must be at least 1, got {workers}")
    out = Path(out)
    options = dict(options or {})
    allow = [str(p) for p in allow_paths or ()]
    fences = _fences(out, options)
    skipped: list[Path] = []
    written: list[Path] = []
    files = expand_inputs(paths, skipped, fences, written)
    references = References(allow, fences)
    check_out(out, files, references, fences[1:])
    unread: dict[Path, str] = {}
    items = plan(files, material, unread)
    keys = {item: item_key(item, target, options, references) for item in items}
    _notes(log, unread, skipped, written)
    out.mkdir(parents=True, exist_ok=True)
    with batch_lock(out, log):
        clean_leftovers(out, items)
        rows: dict[Item, Row] = {}
        todo: list[tuple[Item, str]] = []
        for item in items:
            done = _finished(out, item, keys[item])
            if done is not None:
                rows[item] = done
            else:
                todo.append((item, keys[item]))
        return _run(
            out,
            files,
            items,
            unread,
            rows,
            todo,
            target,
            options,
            allow,
            (workers, scheduler, dask_local),
            log,
            progress,
        )


def _notes(
    log: Callable[[str], None], unread: Mapping[Path, str], skipped: Sequence[Path], written: Sequence[Path]
) -> None:
    """The lines saying what the batch leaves out: unreadable files, foreign XML, folders matremap wrote."""
    for f, why in unread.items():
        log(f"refused  {f.name}: {why}")
    for what, found in (
        (".xml file(s) left out (not Mitsuba scenes, or parts another scene includes)", skipped),
        ("folder(s) matremap wrote left out", written),
    ):
        if found:
            tail = ", ".join(map(str, found[:3])) + (" ..." if len(found) > 3 else "")
            log(f"note: {len(found)} {what}: {tail}")


def _run(
    out: Path,
    files: Sequence[Path],
    items: Sequence[Item],
    unread: Mapping[Path, str],
    rows: dict[Item, Row],
    todo: Sequence[tuple[Item, str]],
    target: str,
    options: Mapping[str, Any],
    allow: Sequence[str],
    where: tuple[int | None, str | None, int | None],
    log: Callable[[str], None],
    progress: bool,
) -> BatchResult:
    """The items of :func:`run_batch` still to do, run; the summary written (OUT locked)."""
    with item_executor(*where, len(todo)) as (executor, desc):
        log(
            f"batch: {len(items)} material(s) in {len(files) - len(unread)} file(s); {len(rows)} unchanged, "
            f"{len(todo)} to do on {desc}"
        )
        work = partial(remap_item, target=target, out=str(out), options=options, allow=allow)
        stopped = run_items(executor, work, todo, rows, log, progress)
    if stopped:  # what is on disk decides: an item that wrote its item.json as it was stopped is done
        discard_partial(out, stopped)
        for item, key in todo:
            done = None if item in rows else _finished(out, item, key)
            if done is not None:
                rows[item] = done
        result = BatchResult(_in_order(files, items, rows, unread), len(items) - len(todo), out)
        result.interrupted = len(items) - sum(i in rows for i in items)
        write_summary(result)
        return result
    result = BatchResult(_in_order(files, items, rows, unread), len(items) - len(todo), out)
    from matremap.formats import allowed_paths

    for f in dict.fromkeys(i.file for i in items):
        mine = [i for i in items if i.file == f]
        with allowed_paths(allow):  # the whole file may copy what the input names, as the workers read it
            whole = assemble(out, f, [(i, rows[i]) for i in mine], target, log)
        for i in mine:
            rows[i].whole_file = whole
    write_summary(result)
    return result


def _printable_log(log: Callable[[str], None]) -> Callable[[str], None]:
    """``log`` given each line as valid Unicode (:func:`printable`): file and material names may not be."""
    return lambda line: log(printable(line))


def _fences(out: Path, options: Mapping[str, Any]) -> list[Path]:
    """The folders no search of a batch enters: OUT first, then the cache folders."""
    from matremap.core.diskcache import cache_dir

    found = [out, cache_dir()] + ([Path(options["cache"])] if options.get("cache") else [])
    return [Path(os.path.realpath(f)) for f in found]


def _inside(path: Path, folder: Path) -> bool:
    """Whether the real path of ``path`` is ``folder`` (a real path) or lies in it."""
    real = Path(os.path.realpath(path))
    return real == folder or folder in real.parents


def check_out(out: Path, files: Sequence[Path], references: References, caches: Sequence[Path] = ()) -> None:
    """Refuse OUT (one line) before anything is written, when:

    * it is, or holds, an input file, or a file an input names by its path (a texture, an included scene);
    * it is, holds, or lies in a cache folder (``caches``);
    * it exists and is not a folder;
    * it is a folder that holds files and was not written by a batch (:func:`is_batch_out`): a batch writes
      ``summary.csv`` and a folder per file, which would replace the user's files of those names."""
    real = Path(os.path.realpath(out))
    for f in files:
        if _inside(f, real):
            raise MatremapError(f"{out} is or holds the input {f}; choose an output folder outside the inputs")
    for cache in caches:
        if _inside(cache, real) or _inside(real, cache):
            raise MatremapError(
                f"{out} is, holds or lies in the cache folder {cache}; choose an output folder outside it"
            )
    if out.exists() and not out.is_dir():
        raise MatremapError(f"{out} exists and is not a folder; choose an output folder")
    if not out.is_dir():
        return
    held = {name for _, _, names in os.walk(out) for name in names}
    for doc in [g for f in files for g in references.files(f) if g.suffix.lower() in _readers()]:
        for named in _named_inside(doc, real, held):
            raise MatremapError(f"{out} holds {named}, which {doc} names; choose an output folder outside the inputs")
    with os.scandir(out) as entries:
        holds = any(entries)
    if holds and not is_batch_out(out):
        raise MatremapError(
            f"{out} holds other files than a matremap batch's output (a batch writes summary.csv and a folder "
            "per file there); choose a new or empty output folder"
        )


def _readers() -> Mapping[str, Any]:
    from matremap.formats import READERS

    return READERS


def is_batch_out(out: Path) -> bool:
    """Whether the folder ``out`` is a batch's output: it holds the batch's lock file (:data:`LOCK_FILE`,
    made before anything else) or a batch's ``summary.json``."""
    return (out / LOCK_FILE).is_file() or _json_keys(out / "summary.json") >= {"counts", "items", "exit_code"}


#: what separates a path from the text around it (as :data:`_NAME_DELIMITERS`, path separators aside)
_PATH_DELIMITERS = re.compile(rb"[\x00-\x1f\"'<>@=,;()\[\]{}|*?]+")


def _named_inside(file: Path, folder: Path, held: set[str]) -> Iterator[Path]:
    """The files inside ``folder`` (a real path) that ``file`` names by a path, relative to its own folder or
    absolute; ``held``: the names of the files ``folder`` holds (only those names are looked at)."""
    from urllib.parse import unquote

    data = read_bounded(file, MAX_READ) or b""
    for token in _PATH_DELIMITERS.split(data):
        text = unquote(token.strip().decode("utf-8", "replace")).removeprefix("file://")
        name = text.replace("\\", "/").rsplit("/", 1)[-1]
        if not text or len(text) > 4096 or name not in held:
            continue
        path = Path(text) if os.path.isabs(text) else file.parent / text
        if path.is_file() and _inside(path, folder):
            yield path


@contextmanager
def batch_lock(out: Path, log: Callable[[str], None]) -> Iterator[None]:
    """OUT locked for the block (``flock`` of :data:`LOCK_FILE` in it, released by the system however the
    process ends). A second batch into the same OUT waits for the first (one line says so; Ctrl-C stops
    the wait), then finds the first one's items done and redoes none of them: waiting, not refusing, so that
    both runs end with the whole result and its exit status. Without ``fcntl`` (Windows) nothing is locked."""
    try:
        import fcntl
    except ImportError:
        yield
        return
    path = out / LOCK_FILE
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0), 0o644)
    except OSError as e:
        raise MatremapError(f"cannot lock {out} ({path}: {e.strerror or e}); choose another output folder") from None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 32, 0).decode("ascii", "replace").strip() or "?"
            log(f"waiting: another batch (process {holder}) is writing {out}; this one continues when it ends")
            fcntl.flock(fd, fcntl.LOCK_EX)
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        yield
    finally:
        os.close(fd)


def clean_leftovers(out: Path, items: Iterable[Item]) -> None:
    """Put right what dead runs left in OUT and in the folders of ``items`` (their staging and temporary
    names; :func:`matremap.core.atomic.clean_stale`): a batch whose process or workers were killed."""
    folders = [Path()]
    for item in items:
        slot = Path(item.slot)
        folders += [*reversed(slot.parents[:-1]), slot]
    for folder in dict.fromkeys(out / f for f in folders):
        if folder.is_dir():
            clean_stale(folder)


def _in_order(
    files: Sequence[Path], items: Sequence[Item], rows: Mapping[Item, Row], unread: Mapping[Path, str]
) -> list[Row]:
    """The summary's rows in the order of the files: each file's finished items, or the one row of a file
    whose materials could not be listed (refused, with its reason)."""
    folders = file_folders(files)
    ordered = []
    for f in files:
        if f in unread:
            ordered.append(Row(str(f), "", folders[f], verdict="refused", exit_code=EXIT_INPUT, reason=unread[f]))
        ordered += [rows[i] for i in items if i.file == f and i in rows]
    return ordered


class _NotATerminal:
    """A worker's stderr as progress bars see it: not a terminal (they draw nothing); text still goes through."""

    def __init__(self, stream: Any) -> None:
        self._stream = stream

    def isatty(self) -> bool:
        return False

    def __getattr__(self, name: str) -> Any:
        return getattr(self._stream, name)


def _worker_init(parent: int) -> None:
    """A local worker leaves Ctrl-C to the batch, which stops the workers itself, dies with the batch's
    process ``parent`` however that ends (:func:`matremap.sweep.executors.die_with_parent`), and draws no
    progress bars of its own (the batch's is the one on the terminal)."""
    import sys

    from matremap.sweep.executors import die_with_parent, quiet_progress_lock

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    die_with_parent(parent)
    sys.stderr = _NotATerminal(sys.stderr)
    quiet_progress_lock()


@contextmanager
def item_executor(
    workers: int | None, scheduler: str | None, dask_local: int | None, todo: int
) -> Iterator[tuple[Executor, str]]:
    """Where the items run: Dask (:func:`matremap.sweep.executors.make_executor`) when a scheduler or a
    local Dask cluster is asked for, else local worker processes (at most one per item; a process even
    for one worker, so that a renderer crashing takes down one item, not the batch)."""
    if scheduler or dask_local:
        from matremap.sweep.executors import make_executor

        with make_executor(None, scheduler, dask_local) as (executor, desc):
            yield executor, desc
        return
    if workers is not None and workers < 1:
        raise MatremapError(f"--workers must be at least 1, got {workers}")
    n = max(1, min(workers or os.cpu_count() or 1, todo or 1))
    from matremap.sweep.executors import process_pool

    pool = process_pool(n, _worker_init, (os.getpid(),))
    pool.slots = n  # type: ignore[attr-defined]
    try:
        yield pool, f"{n} local worker process{'es' if n > 1 else ''}"
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def run_items(
    executor: Executor,
    work: Callable[[Item, str], dict[str, Any]],
    todo: Sequence[tuple[Item, str]],
    rows: dict[Item, Row],
    log: Callable[[str], None],
    progress: bool,
) -> list[Item]:
    """Long: the loop, its progress bar and its clean stop on Ctrl-C belong together.

    Run ``work(item, key)`` for every item on ``executor``, a few in flight at a time, filling ``rows`` as
    items finish (one log line each) with a progress bar over the batch (on a terminal; its status names
    the items running and is refreshed every second). On Ctrl-C: nothing more starts, the local workers
    are killed (:func:`stop_local_workers`), items that finished are kept. Returns the items whose result
    did not come back (empty when all did)."""
    from tqdm import tqdm

    slots = max(1, int(getattr(executor, "slots", 1)))
    queue = iter(todo)
    pending: dict[Future[dict[str, Any]], Item] = {}
    bar = tqdm(total=len(todo), unit="material", desc="remap", disable=None if progress else True, dynamic_ncols=True)

    def collect(finished: Iterable[Future[dict[str, Any]]], stopping: bool = False) -> None:
        for fut in finished:
            item = pending.pop(fut)
            if fut.cancelled() or (stopping and fut.exception() is not None):
                continue  # stopped before it finished (interrupted, or its worker was stopped): not a result
            r = rows[item] = _row_of(fut, item)
            bar.update(1)
            bar.clear()
            log(f"{r.verdict:>7}  {item.file.name} [{item.name}] {r.reason}")

    try:
        while True:
            for item, key in itertools.islice(queue, max(2 * slots - len(pending), 0)):
                pending[executor.submit(work, item, key)] = item
            if not pending:
                return []
            finished, _ = wait(list(pending), timeout=1.0, return_when=FIRST_COMPLETED)
            collect(finished)
            running = [i.slot for f, i in pending.items() if f.running()][:slots]  # the pool queues one more
            bar.set_postfix_str(", ".join(running[:3]) + (" ..." if len(running) > 3 else ""), refresh=True)
    except KeyboardInterrupt:
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)  # a second Ctrl-C must not cut the clean-up
        try:
            if isinstance(executor, ProcessPoolExecutor):
                stop_local_workers(executor)  # the pool then fails every pending future (not cancelled first:
            else:  # Python 3.11's pool raises in its own thread when it fails a cancelled one)
                for fut in pending:
                    fut.cancel()
            finished, _ = wait(list(pending), timeout=5)  # killed workers answer at once; Dask tasks are left
            collect(finished, stopping=True)
        finally:
            signal.signal(signal.SIGINT, previous)
        return [item for item, _ in todo if item not in rows]
    finally:
        bar.close()


def stop_local_workers(executor: Executor) -> None:
    """Kill the worker processes of this process's pool (SIGKILL: a renderer or an image library can
    neither delay it nor half finish a file). What they were converting is in staging folders
    (:func:`discard_partial` removes them) and has no ``item.json``. (Dask's workers are stopped by
    closing their client and cluster.)"""
    import multiprocessing

    children = multiprocessing.active_children()
    for child in children:
        if child.pid:
            try:
                os.kill(child.pid, signal.SIGKILL)
            except OSError:
                continue
    for child in children:  # reaped: a process that is gone no longer owns its staging folders
        child.join(timeout=5)


def discard_partial(out: Path, items: Iterable[Item]) -> None:
    """Remove what stopped items left once their workers are gone: every staging folder, partial folder and
    temporary file of a dead matremap process in their folders (:func:`clean_leftovers`), and a file's folder
    made for them alone and left empty."""
    items = list(items)
    clean_leftovers(out, items)
    for item in items:
        folder = out / item.slot
        if folder.parent != out and folder.parent.is_dir() and not any(folder.parent.iterdir()):
            folder.parent.rmdir()  # the file's folder, made for this item alone


def assemble(out: Path, source: Path, done: Sequence[tuple[Item, Row]], target: str, log: Callable[[str], None]) -> str:
    """One file holding every converted material of ``source`` (``OUT/<file>/<name>``, the target's
    format; :func:`matremap.formats.write_all`); its path relative to OUT, or "" when there is none (no
    file format takes the target, the format cannot hold several, or no material converted)."""
    from matremap.core.material import Material
    from matremap.formats import READERS, write_all
    from matremap.remap import converted_set, default_suffix

    fmt = READERS[source.suffix.lower()][0]
    suffix = default_suffix(target, fmt) or (
        source.suffix.lower() if fmt == "gltf" and target == "gltf:metal-rough" else None
    )
    converted = [(i, r) for i, r in done if r.verdict in ("passed", "failed")]
    if suffix is None or not converted:
        return ""
    results: list[tuple[str, Any]] = []
    for item, _ in converted:
        folder = out / item.slot
        if (folder / "maps" / "material.json").is_file():
            results.append((item.name, converted_set(folder / "maps")))
        else:
            results.append((item.name, Material.from_dict(json.loads((folder / "material.json").read_text()))))
    dest = out / done[0][0].slot.split("/")[0] / f"{source.stem}{suffix}"
    try:
        written = write_all(dest, results, source, force=True)
    except MatremapError as e:
        log(f"note: {source.name}: the materials stay one file each ({e})")
        return ""
    log(f"wrote {written} ({len(results)} of {len(done)} material(s))")
    return str(written.relative_to(out))


def _finished(out: Path, item: Item, key: str) -> Row | None:
    """The row of an item already made with this key (its output still there), else None."""
    try:
        doc = json.loads((out / item.slot / ITEM_FILE).read_text())
        row = Row(**doc["row"]) if isinstance(doc, dict) and doc.get("key") == key else None
    except (OSError, ValueError, TypeError, KeyError):
        return None
    if row is None or row.verdict == "error" or (row.output and not (out / row.output).exists()):
        return None  # errors (a renderer missing, a crash) are retried, never kept as results
    return row


def _row_of(fut: Future[dict[str, Any]], item: Item) -> Row:
    try:
        return Row(**fut.result())
    except Exception as e:  # noqa: BLE001 - a worker that died (killed, out of memory) is this item's error
        return Row(str(item.file), item.name, item.slot, reason=f"internal error: {type(e).__name__}: {e}")


def remap_item(
    item: Item, key: str, *, target: str, out: str, options: Mapping[str, Any], allow: Sequence[str] = ()
) -> dict[str, Any]:
    """One item, in a worker: ``remap_file`` into ``OUT/<slot>`` (staged, moved in whole when done), then
    ``item.json`` with its row. A worker killed on the way leaves no ``item.json``, so a rerun redoes it."""
    from matremap.formats import allowed_paths
    from matremap.remap import remap_file
    from matremap.sweep.executors import limit_blas_threads

    limit_blas_threads()
    folder = Path(out) / item.slot
    folder.parent.mkdir(parents=True, exist_ok=True)
    row = Row(str(item.file), item.name, item.slot)
    lines: list[str] = []
    t0 = time.perf_counter()
    try:
        with allowed_paths(allow):
            res = remap_file(item.file, target, folder, material=item.material, force=True, log=lines.append, **options)
        row.source_model, row.target_model = res.source_model, res.target_model
        row.route = _route(res)
        row.measures = {c.name: float(c.value) for c in res.verdict.checks}
        row.verdict = "passed" if res.verdict.passed else "failed"
        row.exit_code = 0 if res.verdict.passed else EXIT_QUALITY
        row.reason = res.verdict.line()
        row.output = str(Path(item.slot) / res.file.name) if res.file else item.slot
        row.thumbnails = _thumbnails(folder, item.slot)
    except MatremapError as e:
        row.verdict = "refused" if e.exit_code == EXIT_INPUT else "error"
        row.exit_code, row.reason = e.exit_code, str(e)
    except KeyboardInterrupt:
        raise
    except Exception as e:  # noqa: BLE001 - one item's bug must not stop the batch; it is reported
        row.verdict, row.exit_code = "error", 70
        row.reason = f"internal error: {type(e).__name__}: {e}"
    row.seconds = round(time.perf_counter() - t0, 2)
    if folder.is_dir():
        write_text(folder / "log.txt", "\n".join(lines) + "\n")
        write_text(folder / ITEM_FILE, json.dumps({"key": key, "row": row.to_dict()}, indent=1) + "\n")
        record_written(folder, ["log.txt", ITEM_FILE])  # so that a rerun may replace the folder
    elif row.verdict in ("refused", "error"):  # nothing was written: keep the reason beside the others
        folder.mkdir(parents=True)
        write_text(folder / "log.txt", "\n".join([*lines, row.reason]) + "\n")
        write_text(folder / ITEM_FILE, json.dumps({"key": key, "row": row.to_dict()}, indent=1) + "\n")
        record_written(folder, ["log.txt", ITEM_FILE])
    return row.to_dict()


def _route(res: Any) -> str:
    if res.remap is None:
        return "identity" if any(c.where == "identity" for c in res.verdict.checks) else "fit"
    r = res.remap
    if r.identity:
        return "identity"
    if r.transform is None:
        return "library"
    return "cached sweep" if r.cached else "sweep"


def _thumbnails(folder: Path, slot: str) -> dict[str, str]:
    """Source and target renders of an item, relative to OUT: the first environment rotation of its
    report, or its probe comparison strip."""
    images = folder / "report" / "images"
    out = {}
    for kind in ("source", "target"):
        found = sorted(images.glob(f"r*_full_{kind}.png")) if images.is_dir() else []
        if found:
            out[kind] = f"{slot}/report/images/{found[0].name}"
    if not out and (folder / "compare.png").is_file():
        out["compare"] = f"{slot}/compare.png"
    return out


# -- the summary ------------------------------------------------------------------------------------

COLUMNS = (
    "file",
    "material",
    "source_model",
    "target_model",
    "route",
    "verdict",
    "seconds",
    "reason",
    "output",
    "whole_file",
)


def write_summary(result: BatchResult) -> None:
    """``summary.csv``, ``summary.json`` and ``index.html`` in the output folder."""
    out = result.out
    measures = sorted({m for r in result.rows for m in r.measures})
    lines: list[list[Any]] = [[*COLUMNS, *measures]]
    for r in result.rows:
        d = r.to_dict()
        lines.append([*(d[c] for c in COLUMNS), *(r.measures.get(m, "") for m in measures)])
    import io

    buf = io.StringIO()
    csv.writer(buf).writerows(lines)
    write_text(out / "summary.csv", buf.getvalue())
    doc = {
        "counts": result.counts(),
        "interrupted": result.interrupted,
        "exit_code": result.exit_code,
        "items": [r.to_dict() for r in result.rows],
    }
    write_text(out / "summary.json", json.dumps(doc, indent=1) + "\n")
    write_text(out / "index.html", index_page(result.rows, result.line()))


_SORT_SCRIPT = """
function sortBy(th) {
  const table = th.closest('table'), body = table.tBodies[0], col = th.cellIndex;
  const dir = th.dataset.dir === 'asc' ? 'desc' : 'asc';
  for (const h of th.parentNode.cells) delete h.dataset.dir;
  th.dataset.dir = dir;
  const key = tr => { const c = tr.cells[col]; const v = c.dataset.value ?? c.textContent;
                      const n = parseFloat(v); return isNaN(n) ? v : n; };
  const rows = Array.from(body.rows).sort((a, b) => {
    const x = key(a), y = key(b); const r = x < y ? -1 : x > y ? 1 : 0; return dir === 'asc' ? r : -r; });
  rows.forEach(r => body.appendChild(r));
}
window.addEventListener('DOMContentLoaded', () => {
  const want = new URLSearchParams(location.search).get('sort');
  if (want) { const th = document.querySelector(`th[data-key="${want}"]`); if (th) sortBy(th); }
});
"""


def _worst_measure(row: Row) -> float:
    """The sort key "error": the item's dissimilarity if measured, else its probe fit error."""
    for name in ("dssim", "fit_error"):
        if name in row.measures:
            return row.measures[name]
    return float("inf") if row.verdict != "passed" else 0.0


def _written(row: Row) -> str:
    """Links to what an item wrote: its own output, and the input's whole file when there is one."""
    links = [(row.output, "output"), (row.whole_file, "whole file")]
    return "<br>".join(f'<a href="{html.escape(p)}">{label}: {html.escape(p)}</a>' for p, label in links if p)


def index_page(rows: Iterable[Row], title_line: str) -> str:
    """The batch's page: one row per item with its thumbnails and verdict, sortable by every column
    (click a header; ``index.html?sort=error`` opens sorted by error)."""
    e = html.escape
    head = "".join(
        f'<th data-key="{k}" onclick="sortBy(this)">{e(label)}</th>'
        for k, label in (
            ("file", "file"),
            ("material", "material"),
            ("models", "source → target"),
            ("route", "route"),
            ("verdict", "verdict"),
            ("error", "error"),
            ("seconds", "seconds"),
            ("images", "source | target"),
            ("reason", "why"),
            ("written", "written"),
        )
    )
    body = []
    for r in rows:
        thumbs = "".join(
            f'<img src="{e(path)}" alt="{e(kind)}" title="{e(kind)}" height="96">'
            for kind, path in r.thumbnails.items()
        )
        err = _worst_measure(r)
        body.append(
            f'<tr class="{e(r.verdict)}"><td>{e(r.file)}</td><td>{e(r.material)}</td>'
            f"<td>{e(r.source_model)} → {e(r.target_model)}</td><td>{e(r.route)}</td>"
            f'<td data-value="{VERDICTS.index(r.verdict)}">{e(r.verdict)}</td>'
            f'<td data-value="{"Infinity" if err == float("inf") else err}">'  # parseFloat reads "Infinity"
            f"{'' if err == float('inf') else f'{err:.4f}'}</td>"
            f"<td>{r.seconds:.1f}</td><td>{thumbs}</td><td>{e(r.reason)}</td><td>{_written(r)}</td></tr>"
        )
    return (
        '<!doctype html><html><head><meta charset="utf-8"><title>matremap batch</title><style>'
        "body{font:14px sans-serif;margin:1em}table{border-collapse:collapse}td,th{border:1px solid #ccc;"
        "padding:3px 6px;vertical-align:top}th{cursor:pointer;background:#eee}tr.failed td{background:#fde}"
        "tr.refused td,tr.error td{background:#fed}</style>"
        f"<script>{_SORT_SCRIPT}</script></head><body><h1>matremap batch</h1><p>{e(title_line)}</p>"
        f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table></body></html>\n"
    )
