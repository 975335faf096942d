"""matremap's on-disk cache: numerically integrated tables and learned transforms.

The folder is ``$MATREMAP_CACHE_DIR`` or ``~/.cache/matremap``. Tables are ``.npz`` files named with
a digest of what decides them, written atomically; a failure to write is ignored (the table is
rebuilt next time), and files of other versions of the same table are removed.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np


def cache_dir() -> Path:
    env = os.environ.get("MATREMAP_CACHE_DIR")
    return Path(env) if env else Path.home() / ".cache" / "matremap"


def save_tables(path: Path, stale: str, **arrays: np.ndarray) -> None:
    """Write ``arrays`` to ``path`` (.npz) atomically and remove the files matching the glob
    ``stale`` beside it (other versions); give up silently if that fails."""
    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.stem + ".", suffix=".tmp")
        with os.fdopen(fd, "wb") as f:
            np.savez(f, **arrays)  # type: ignore[arg-type]  # numpy's stub: a key could be allow_pickle
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
        tmp = None
        for old in path.parent.glob(stale):
            if old != path:
                old.unlink(missing_ok=True)
    except OSError:
        pass
    finally:
        if tmp is not None:
            try:
                os.unlink(tmp)
            except OSError:
                pass
