"""matremap's on-disk cache: numerically integrated tables, learned transforms, extracted glTF images.

The folder is ``$MATREMAP_CACHE`` (or the older name ``$MATREMAP_CACHE_DIR``), else the per-user
cache folder ``$XDG_CACHE_HOME/matremap`` or ``~/.cache/matremap``. matremap creates it, and every
folder inside it, with mode 0700, and uses a folder only while it is owned by the current user and
not writable by the group or others (:func:`ensure_private`): another user must not be able to plant
files that matremap would then read as its own. Whoever needs the cache to work (the glTF reader's
extracted images) gets a one-line error otherwise; optional tables skip caching silently.

Tables are ``.npz`` files named with a digest of what decides them, written atomically; a failure to
write is ignored (the table is rebuilt next time), and files of other versions of the same table are
removed. Temporary files carry their writer's mark (:func:`matremap.core.atomic.temp_prefix`): a run
that finds one left by a killed process removes it (:func:`~matremap.core.atomic.clean_stale`, on every
folder :func:`private_cache_dir` hands out).
"""

from __future__ import annotations

import os
import stat
import sys
import tempfile
import zipfile
import zlib
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from matremap.core.atomic import clean_stale, temp_prefix
from matremap.errors import MatremapError

#: the environment variables naming the cache folder, first found wins
CACHE_ENV = ("MATREMAP_CACHE", "MATREMAP_CACHE_DIR")
#: part of the key of every cached result (swept databases, learned transforms): bump it in the commit that
#: changes what fitting, sweeping or learning would give for the same inputs, so results cached by an older
#: matremap are recomputed rather than reused (3: a scale mapping's domain reaches 0; 4: Principled metals read
#: F0 from their base colour; 5: a source's specular part no override isolates is full - diffuse, and Mitsuba 3's
#: principled metal is its specular part; 6: OpenPBR and Standard Surface metals read F0 from their base colour,
#: a reflectance mapping may carry a per-channel tint; 7: a roughness at its bound where the source's is at
#: its own is learned from, not excluded; 8: so is a roughness at its bound fitted within LOSS_MIN; 9: the F0 a
#: k_alpha mapping scales reaches down to 0 in the learned domain; 10: a target quantity the sweep held is learned
#: as a constant, as is a reflectance a constant predicts as well, and k(alpha) coefficients stay within 1e3;
#: 11: a two-stage fit whose parts are coupled is refined jointly, Standard Surface's thin wall blurs, and the
#: transmission view draws a glass's mirror reflection; 12: a sweep that frees a target's layer starts it at the
#: source's and keeps the better of a three-stage and a simple fit, a transform learns the layers its sweep
#: varies, and any parameter at its bound fitted as closely as the sweep's typical fit is learned from)
RESULTS_REVISION = 12


def cache_dir() -> Path:
    """Where the cache is (see the module doc); neither created nor checked here (see :func:`private_cache_dir`)."""
    for name in CACHE_ENV:
        env = os.environ.get(name)
        if env:
            return Path(env).expanduser()
    xdg = os.environ.get("XDG_CACHE_HOME")
    base = Path(xdg) if xdg and Path(xdg).is_absolute() else Path.home() / ".cache"
    return base / "matremap"


def ensure_private(folder: Path) -> Path:
    """``folder``, created with mode 0700 if missing (its parents as usual); refused with one line when
    it is not a folder, is owned by another user, or is writable by the group or others."""
    hint = f"set MATREMAP_CACHE to a folder of your own (mode 700), or fix {folder}"
    try:
        if not folder.exists():
            folder.parent.mkdir(parents=True, exist_ok=True)
            try:
                folder.mkdir(mode=0o700)
                os.chmod(folder, 0o700)  # whatever the umask
            except FileExistsError:  # made meanwhile: checked below like any existing folder
                pass
        st = os.stat(folder)
    except OSError as e:
        raise MatremapError(f"cannot create the cache folder {folder}: {e.strerror or e}; {hint}") from None
    if not stat.S_ISDIR(st.st_mode):
        raise MatremapError(f"the cache folder {folder} is not a folder; {hint}")
    if hasattr(os, "getuid") and st.st_uid != os.getuid():
        raise MatremapError(f"the cache folder {folder} is owned by another user (uid {st.st_uid}); {hint}")
    if st.st_mode & (stat.S_IWGRP | stat.S_IWOTH):
        raise MatremapError(
            f"the cache folder {folder} is writable by other users (mode {stat.S_IMODE(st.st_mode):o}); {hint}"
        )
    return folder


def private_cache_dir(*parts: str) -> Path:
    """The cache folder, or the folder ``parts`` inside it, each level created and checked by
    :func:`ensure_private` (raises :class:`~matremap.errors.MatremapError` when one is unsafe)."""
    folder = ensure_private(cache_dir())
    for part in parts:
        folder = ensure_private(folder / part)
    clean_stale(folder)  # what killed runs left
    return folder


def trusted(path: Path) -> bool:
    """Whether a cached table at ``path`` may be read: its folder is private to this user
    (:func:`ensure_private`); a table planted in a shared folder is ignored and rebuilt."""
    try:
        ensure_private(path.parent)
    except MatremapError:
        return False
    return True


def load_tables(path: Path, spec: str, shapes: Mapping[str, tuple[int, ...]]) -> dict[str, np.ndarray] | None:
    """The arrays :func:`save_tables` wrote to ``path``, as float arrays of the given ``shapes``; None when
    the table must be rebuilt: missing, unreadable or damaged (each array's CRC-32 in the .npz is verified
    on reading; a note says so), made for another ``spec``, of another shape, holding NaN or infinity, or
    in a folder others can write (:func:`trusted`)."""
    if not trusted(path):  # a table in a folder others can write is not read
        return None
    try:
        with np.load(path, allow_pickle=False) as z:
            if str(z["spec"]) != spec:
                return None
            data = {name: np.array(z[name], dtype=float) for name in shapes}
    except FileNotFoundError:
        return None
    except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as e:
        # the zip's CRC-32 of each array is its checksum: a damaged table raised BadZipFile (an internal error)
        print(f"matremap: note: the cached table {path} is damaged ({e}); rebuilding it", file=sys.stderr)
        return None
    ok = all(data[k].shape == shape and np.isfinite(data[k]).all() for k, shape in shapes.items())
    return data if ok else None


def save_tables(path: Path, stale: str, **arrays: np.ndarray) -> None:
    """Write ``arrays`` to ``path`` (.npz) atomically and remove the files matching the glob
    ``stale`` beside it (other versions); give up silently if that fails or the folder is not private
    (:func:`ensure_private`)."""
    tmp = None
    try:
        ensure_private(path.parent)
        clean_stale(path.parent)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=temp_prefix("tmp", path.stem), suffix=".tmp")
        with os.fdopen(fd, "wb") as f:
            np.savez(f, **arrays)  # type: ignore[arg-type]  # numpy's stub: a key could be allow_pickle
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
        tmp = None
        for old in path.parent.glob(stale):
            if old != path:
                old.unlink(missing_ok=True)
    except (OSError, MatremapError):
        pass
    finally:
        if tmp is not None:
            try:
                os.unlink(tmp)
            except OSError:
                pass
