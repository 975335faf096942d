"""Fetch the larger public test assets listed in tests/data/large.json into a folder outside git.

The developers' guide keeps small third-party files in tests/data/corpus and asks that larger ones be
fetched on demand and skipped when absent: this tool does the fetching, ``tests/large_assets.py`` the skipping.
Each asset is a folder (``gltf-SheenChair``, ...) holding the files the manifest names, each checked against its
git blob id (the SHA-1 of ``b"blob <size>\\0" + bytes``, what ``git hash-object`` prints) before anything is
kept. The files are gathered in a temporary folder beside the destination and renamed into place at the end, so a
failed download or a wrong file leaves nothing behind.

Usage::

    python tools/fetch_assets.py                    # every asset, from GitHub
    python tools/fetch_assets.py gltf-SheenChair    # one asset
    python tools/fetch_assets.py --from-git DIR gltf-SheenChair   # from a local clone or mirror of the repository
    python tools/fetch_assets.py --list             # names, sizes, licences and whether each is here

Sources: by default ``https://raw.githubusercontent.com/<repository>/<commit>/<path>`` (the asset's repository,
then its mirrors, at the manifest's commit); ``--from-git DIR`` reads ``<commit>:<path>`` from a git clone or a
bare mirror with ``git cat-file``. ``--base-url`` replaces the raw.githubusercontent.com prefix (any URL urllib
opens, ``file://`` included). Destination: ``--dest DIR``, else ``$MATREMAP_LARGE_ASSETS``, else
``tests/data/large`` (git-ignored).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
import urllib.error
import urllib.parse
import urllib.request
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

ROOT = Path(__file__).resolve().parents[1]
MANIFEST = ROOT / "tests" / "data" / "large.json"
DEFAULT_DEST = ROOT / "tests" / "data" / "large"
ENV_DEST = "MATREMAP_LARGE_ASSETS"
RAW_GITHUB = "https://raw.githubusercontent.com"
TIMEOUT = 60.0  # seconds per request


class FetchError(Exception):
    """A problem the user can fix, said in one line."""


@dataclass(frozen=True)
class AssetFile:
    """One file of an asset: its path in the repository, its path in the asset's folder, git blob id, size."""

    path: str
    to: str
    blob: str
    size: int


@dataclass(frozen=True)
class Asset:
    """One asset of the manifest: where it comes from, under which licence, and its files."""

    name: str
    repository: str
    mirrors: tuple[str, ...]
    commit: str
    licence: str
    credit: str
    files: tuple[AssetFile, ...]

    @property
    def size(self) -> int:
        return sum(f.size for f in self.files)


def git_blob_id(data: bytes) -> str:
    """The git blob id of ``data``: SHA-1 of ``"blob <len>\\0"`` + the bytes (git's object format, as
    ``git hash-object`` computes it)."""
    return hashlib.sha1(b"blob %d\0" % len(data) + data).hexdigest()


def default_dest() -> Path:
    """Where the assets live: ``$MATREMAP_LARGE_ASSETS`` when set, else tests/data/large."""
    env = os.environ.get(ENV_DEST)
    return Path(env) if env else DEFAULT_DEST


def _file(name: str, row: dict) -> AssetFile:
    f = AssetFile(str(row["path"]), str(row["to"]), str(row["blob"]).lower(), int(row["bytes"]))
    to = PurePosixPath(f.to)
    if to.is_absolute() or ".." in to.parts or not to.parts:
        raise FetchError(f"{name}: file {f.path} goes to {f.to!r}, outside the asset's folder; fix the manifest")
    if len(f.blob) != 40 or any(c not in "0123456789abcdef" for c in f.blob):
        raise FetchError(f"{name}: file {f.path} has blob {f.blob!r}, not a 40-digit git id; fix the manifest")
    return f


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def load_manifest(path: Path = MANIFEST) -> dict[str, Asset]:
    """The assets of the manifest at ``path`` by name."""
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
        assets = {}
        for name, a in doc["assets"].items():
            files = tuple(_file(name, row) for row in a["files"])
            assets[name] = Asset(
                name, a["repository"], tuple(a.get("mirrors", ())), a["commit"], a["licence"], a["credit"], files
            )
        return assets
    except OSError as e:
        raise FetchError(f"cannot read the manifest {path}: {e.strerror or e}") from None
    except (ValueError, KeyError, TypeError, AttributeError) as e:
        raise FetchError(f"{path} is not a valid asset manifest ({type(e).__name__}: {e}); fix it") from None


def problems(folder: Path, asset: Asset) -> list[str]:
    """What differs between ``folder`` and the manifest's files (empty when every file is there and verifies)."""
    out = []
    for f in asset.files:
        p = folder / f.to
        if not p.is_file():
            out.append(f"{f.to} missing")
        elif p.stat().st_size != f.size or git_blob_id(p.read_bytes()) != f.blob:
            out.append(f"{f.to} is not blob {f.blob}")
    return out


def from_git(gitdir: Path, asset: Asset) -> Callable[[AssetFile], tuple[bytes, str]]:
    """A reader of the asset's files from the git clone or mirror ``gitdir`` at the manifest's commit."""

    def git(*args: str) -> subprocess.CompletedProcess[bytes]:
        try:
            return subprocess.run(["git", "-C", str(gitdir), *args], capture_output=True, check=False)
        except FileNotFoundError:
            raise FetchError("git is not installed; install it, or fetch without --from-git") from None

    if git("rev-parse", "--git-dir").returncode != 0:
        raise FetchError(f"{gitdir} is not a git repository; give --from-git a clone or mirror of {asset.repository}")
    if git("cat-file", "-e", f"{asset.commit}^{{commit}}").returncode != 0:
        raise FetchError(
            f"{gitdir} has no commit {asset.commit} ({asset.name}); run git -C {gitdir} fetch origin {asset.commit}, "
            f"or fetch without --from-git"
        )

    def read(f: AssetFile) -> tuple[bytes, str]:
        r = git("cat-file", "blob", f"{asset.commit}:{f.path}")
        if r.returncode != 0:
            raise FetchError(f"{asset.name}: {gitdir} has no {f.path} at {asset.commit[:12]}; check the manifest")
        return r.stdout, f"{gitdir} {asset.commit[:12]}:{f.path}"

    return read


def from_urls(base: str, asset: Asset) -> Callable[[AssetFile], tuple[bytes, str]]:
    """A reader of the asset's files from ``<base>/<repository>/<commit>/<path>``, trying the repository and then
    each mirror. Not exercised against GitHub where it was written (no network there); tests use ``file://``."""

    def read(f: AssetFile) -> tuple[bytes, str]:
        errors = []
        for repo in (asset.repository, *asset.mirrors):
            url = f"{base.rstrip('/')}/{repo}/{asset.commit}/{urllib.parse.quote(f.path)}"
            try:
                with urllib.request.urlopen(url, timeout=TIMEOUT) as r:
                    return r.read(), url
            except (urllib.error.URLError, OSError, ValueError) as e:
                errors.append(f"{url}: {getattr(e, 'reason', None) or e}")
        raise FetchError(
            f"{asset.name}: could not download {f.path} ({'; '.join(errors)}); check the network, or use --from-git DIR"
        )

    return read


def fetch(asset: Asset, dest: Path, read: Callable[[AssetFile], tuple[bytes, str]], force: bool = False) -> str:
    """Fetch ``asset`` into ``dest/<name>`` with ``read`` (a file -> its bytes and where they came from), every file
    checked against its blob id, and say what was done. The files are written to a temporary folder in ``dest``,
    renamed to the asset's folder once all verified; on any failure the temporary folder is removed (and ``dest``
    itself, when this call created it and it is empty). An asset folder already there is kept when it verifies,
    refused when it differs, unless ``force``."""
    target = dest / asset.name
    if target.exists():
        wrong = problems(target, asset)
        if not wrong:
            return f"{asset.name}: already in {target}"
        if not force:
            raise FetchError(f"{target} differs from the manifest ({wrong[0]}); run again with --force to replace it")
    created = not dest.exists()
    dest.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{asset.name}.", suffix=".partial", dir=dest))
    tmp.chmod(0o777 & ~_umask())  # mkdtemp's folder is private (0700); the asset's is an ordinary folder
    try:
        for f in asset.files:
            data, where = read(f)
            got = git_blob_id(data)
            if got != f.blob:
                raise FetchError(
                    f"{asset.name}: {where} is blob {got} ({len(data)} bytes), the manifest says {f.blob} "
                    f"({f.size} bytes); nothing written"
                )
            out = tmp / f.to
            out.parent.mkdir(parents=True, exist_ok=True)
            out.write_bytes(data)
        old = dest / f".{asset.name}.old-{os.getpid()}"
        if target.exists():  # --force: the differing folder goes only once the new one is complete
            target.rename(old)
        try:
            tmp.rename(target)
        except OSError:
            if old.exists():
                old.rename(target)
            raise
        shutil.rmtree(old, ignore_errors=True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        if created and not any(dest.iterdir()):
            dest.rmdir()
        raise
    return f"{asset.name}: {len(asset.files)} files, {asset.size / 1e6:.1f} MB -> {target}"


def listing(assets: dict[str, Asset], dest: Path) -> list[str]:
    """One line per asset: name, size, whether it is in ``dest``, licence and credit."""
    lines = []
    for a in assets.values():
        folder = dest / a.name
        state = "absent" if not folder.exists() else ("present" if not problems(folder, a) else "differs")
        lines.append(f"{a.name:24} {a.size / 1e6:5.1f} MB  {state:8} {a.licence}; {a.credit}")
    return lines


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("names", nargs="*", metavar="NAME", help="assets to fetch (default: all)")
    p.add_argument("--from-git", type=Path, metavar="DIR", help="read the files from this git clone or mirror")
    p.add_argument("--dest", type=Path, help=f"folder of the assets (default: ${ENV_DEST} or tests/data/large)")
    p.add_argument("--force", action="store_true", help="replace an asset folder that differs from the manifest")
    p.add_argument("--list", action="store_true", help="list the assets and whether each is present")
    p.add_argument("--manifest", type=Path, default=MANIFEST, help="asset manifest (default: tests/data/large.json)")
    p.add_argument("--base-url", default=RAW_GITHUB, help=f"prefix of the download URLs (default: {RAW_GITHUB})")
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    dest = args.dest or default_dest()
    try:
        assets = load_manifest(args.manifest)
        if args.list:
            print("\n".join(listing(assets, dest)))
            return 0
        unknown = [n for n in args.names if n not in assets]
        if unknown:
            raise FetchError(f"no asset {unknown[0]!r} in {args.manifest}; choose from {', '.join(assets)}")
        for name in args.names or list(assets):
            a = assets[name]
            read = from_git(args.from_git, a) if args.from_git else from_urls(args.base_url, a)
            print(fetch(a, dest, read, force=args.force), flush=True)
    except FetchError as e:
        print(f"fetch_assets: {e}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("fetch_assets: interrupted; nothing half-written was kept", file=sys.stderr)
        return 130
    except OSError as e:
        print(f"fetch_assets: {e.filename or dest}: {e.strerror or e}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
