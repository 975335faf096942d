"""Writing rendered images: linear float EXR, sRGB-encoded PNG, raw numpy arrays.

EXR and PNG go through OpenImageIO (imported lazily). Files are written to a temporary name
in the destination folder and moved into place, so a failure never leaves a partial file, and an
existing file is only replaced when the caller says so.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from matremap.core.atomic import atomic_output
from matremap.errors import MatremapError, shown

IMAGE_SUFFIXES = (".exr", ".png", ".npy", ".tif", ".tiff", ".hdr")


def oiio_name(path: str | os.PathLike[str]) -> str:
    """The name OpenImageIO is given for file ``path``: its text, refused in one line when the name holds
    bytes that are not UTF-8 (OpenImageIO takes UTF-8 names only; Python keeps such bytes as surrogates)."""
    name = os.fspath(path)
    name = os.fsdecode(name) if isinstance(name, bytes) else name
    try:
        name.encode("utf-8")
    except UnicodeEncodeError:
        raise MatremapError(
            f"{shown(name)}: this name is not UTF-8 text, and OpenImageIO reads and writes images by UTF-8 names "
            "only; use a UTF-8 name (rename the file or its folder, e.g. convmv -f latin1 -t utf8)"
        ) from None
    return name


def srgb_to_linear(v: np.ndarray) -> np.ndarray:
    """sRGB-encoded values in [0, 1] to linear (IEC 61966-2-1; float32 stays float32)."""
    v = np.asarray(v)
    v = v if v.dtype in (np.float32, np.float64) else v.astype(np.float32)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4).astype(v.dtype, copy=False)


def linear_to_srgb(v: np.ndarray) -> np.ndarray:
    """Linear values to the sRGB encoding (IEC 61966-2-1), clipped to [0, 1] (float32 stays float32)."""
    v = np.asarray(v)
    v = np.clip(v, 0.0, 1.0).astype(v.dtype if v.dtype in (np.float32, np.float64) else np.float32, copy=False)
    out = np.power(v, 1.0 / 2.4, dtype=v.dtype)
    out *= 1.055
    out -= 0.055
    low = v <= 0.0031308
    out[low] = v[low] * 12.92
    return out


def check_output(path: str | os.PathLike, force: bool, suffixes: tuple[str, ...] | None = None) -> Path:
    """Validate an output path before any work is done: known suffix, existing folder, no clobbering."""
    p = Path(path)
    if suffixes is not None and p.suffix.lower() not in suffixes:
        raise MatremapError(f"cannot write {p}: unknown file type {p.suffix!r}; use one of {', '.join(suffixes)}")
    if not p.parent.exists():
        raise MatremapError(f"cannot write {p}: folder {p.parent} does not exist")
    if p.exists() and not force:
        raise MatremapError(f"{p} already exists; pass --force to overwrite it")
    return p


def write_text(path: Path, text: str) -> None:
    """Write a text file atomically."""
    with atomic_output(path) as tmp, open(tmp, "w") as f:
        f.write(text)


def write_image(path: str | os.PathLike, image: np.ndarray, force: bool = False) -> Path:
    """Write a linear RGB float image [H, W, 3]: .exr/.hdr/.tif as float, .png as 8-bit sRGB, .npy raw."""
    p = check_output(path, force, IMAGE_SUFFIXES)
    suffix = p.suffix.lower()
    with atomic_output(p) as tmp:
        if suffix == ".npy":
            with open(tmp, "wb") as f:
                np.save(f, image.astype(np.float32))
        else:
            _write_oiio(tmp, image, suffix)
    return p


def _write_oiio(path: str, image: np.ndarray, suffix: str) -> None:
    if suffix == ".png":
        _oiio_write(path, np.round(linear_to_srgb(image) * 255.0).astype(np.uint8))
    else:
        _oiio_write(path, np.ascontiguousarray(image, dtype=np.float32))


def _oiio_write(path: str, data: np.ndarray) -> None:
    """Write uint8 or float32 pixels [H, W, C] as they are (colour not scaled by an alpha channel)."""
    try:
        import OpenImageIO as oiio
    except ImportError:  # pragma: no cover - it is a dependency
        raise MatremapError("writing EXR/PNG needs OpenImageIO: pip install openimageio") from None
    h, w, c = data.shape
    spec = oiio.ImageSpec(w, h, c, oiio.UINT8 if data.dtype == np.uint8 else oiio.FLOAT)
    spec.attribute("oiio:UnassociatedAlpha", 1)
    out = oiio.ImageOutput.create(oiio_name(path))
    if out is None or not out.open(path, spec):
        raise MatremapError(f"cannot write {path}: {oiio.geterror().strip()}")
    ok = out.write_image(data)
    out.close()
    if not ok:
        raise MatremapError(f"cannot write {path}: {oiio.geterror().strip()}")


def png_bytes(array: np.ndarray) -> bytes:
    """8-bit PNG bytes of a uint8 array [H, W, C] (C = 1..4), values stored as given (an alpha
    channel does not scale the colour). Encoded here (PNG specification, 2nd ed.: IHDR colour types 0/4/2/6,
    filter 0 per row, one zlib IDAT), in memory: the OpenImageIO route wrote each image through a temporary
    folder in the system's temporary folder, which a killed run left behind."""
    import struct
    import zlib

    a = np.ascontiguousarray(array, dtype=np.uint8)
    if a.ndim == 2:
        a = a[..., None]
    h, w, c = a.shape
    if c not in (1, 2, 3, 4):
        raise MatremapError(f"cannot encode a PNG of {c} channels")

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    rows = np.concatenate([np.zeros((h, 1), np.uint8), a.reshape(h, w * c)], axis=1)  # filter byte 0 per row
    ihdr = struct.pack(">IIBBBBB", w, h, 8, {1: 0, 2: 4, 3: 2, 4: 6}[c], 0, 0, 0)
    idat = zlib.compress(rows.tobytes(), 6)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", idat) + chunk(b"IEND", b"")
