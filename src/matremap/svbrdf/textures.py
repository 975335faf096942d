"""Texture maps: reading and writing PNG, JPEG, TIFF and EXR through OpenImageIO, and map sets.

Pixel values are handed to the rest of matremap as linear float32 arrays ``[H, W, C]``:

* 8- and 16-bit files (PNG, JPEG, TIFF) holding colours are decoded from sRGB (IEC 61966-2-1)
  to linear on read and encoded back on write; data maps (roughness, normal maps, masks) are read
  as linear code values / (2^bits - 1);
* float files (EXR, float TIFF) are linear as stored.

:class:`MapReader` and :class:`MapWriter` stream bands of rows (OIIO ``read_scanlines`` /
``write_scanlines``), so a 16K x 16K map never has to be in memory whole. Every image is refused,
from its header and before any texel is decoded, when it holds more texels than the limit in effect
(:func:`texel_limit`, ``--max-texels``; :data:`DEFAULT_MAX_TEXELS` by default).

A *map set* (:class:`MapSet`) binds files to the parameters of a model, either through a manifest
(``material.json`` or ``material.toml`` in the folder)::

    {"model": "mitsuba06:ward",
     "maps": {"specularReflectance": "ward_specular.png", "alpha": "ward_roughness.png",
              "diffuseReflectance": "ward_diffuse.png"},
     "normal": "ward_normal.png",
     "params": {"variant": "ward"},
     "colorspace": {"ward_specular.png": "srgb"}}

or through file-name conventions, when the model is given by the caller:

* ``*_diffuse.EXT``   -> the model's RGB diffuse-role parameter (sRGB if 8/16-bit),
* ``*_specular.EXT``  -> its specular reflectance (the parameter its ``reflectance`` names; sRGB),
* ``*_roughness.EXT`` -> its roughness-role parameter (linear),
* ``*_normal.EXT``    -> the tangent-space normal map (linear; copied unchanged by a conversion),

where EXT is png, jpg, jpeg, tif, tiff or exr (a file named just ``diffuse.png`` also counts).
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from matremap.core.imageio import atomic_output, check_output, linear_to_srgb, oiio_name, srgb_to_linear
from matremap.core.models import ModelSpec
from matremap.dialects import get_model
from matremap.errors import MatremapError, not_a_file

COLORSPACES = ("srgb", "linear")
_CS_ALIASES = {
    "srgb": "srgb",
    "s-rgb": "srgb",
    "srgb_texture": "srgb",
    "linear": "linear",
    "lin": "linear",
    "raw": "linear",
    "data": "linear",
    "non-color": "linear",
    "lin_srgb": "linear",
}
#: OIIO format names -> the extensions matremap writes
_FORMATS = {"png": "png", "jpeg": "jpg", "tiff": "tif", "openexr": "exr", "targa": "tga"}
#: the formats matremap writes maps in; a map read in another (a USD asset's Targa texture) is written as PNG (8 or
#: 16 bits) or EXR
WRITTEN_FORMATS = ("png", "jpg", "tif", "exr")
MAP_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".exr")
MANIFESTS = ("material.json", "material.toml")
CONVENTIONS = ("diffuse", "specular", "roughness", "normal")
#: output format overrides: name -> (format, pixel type)
OUT_FORMATS = {
    "png8": ("png", "uint8"),
    "png16": ("png", "uint16"),
    "jpg": ("jpg", "uint8"),
    "tif8": ("tif", "uint8"),
    "tif16": ("tif", "uint16"),
    "tif32": ("tif", "float"),
    "exr": ("exr", "float"),
    "exr16": ("exr", "half"),
}


#: the largest image (width x height) read unless ``--max-texels`` says otherwise: 2^30 texels, a
#: 32768 x 32768 map. Memory does not grow with the map size (maps are read in bands), but the time
#: and the output files do (a 16K x 16K remap takes minutes and writes gigabytes); a header beyond this
#: is far more likely a corrupt or hostile file than a texture
DEFAULT_MAX_TEXELS = 1 << 30
_TEXEL_LIMIT: ContextVar[int] = ContextVar("matremap_texel_limit", default=DEFAULT_MAX_TEXELS)


@contextmanager
def texel_limit(texels: int | None) -> Iterator[int]:
    """While the block runs, refuse every image whose header declares more than ``texels`` texels
    (width x height), before any of its pixels is decoded. None keeps the limit in effect."""
    if texels is None:
        yield _TEXEL_LIMIT.get()
        return
    if int(texels) < 1:
        raise MatremapError(f"--max-texels {texels}: give a positive number of texels (width x height)")
    token = _TEXEL_LIMIT.set(int(texels))
    try:
        yield int(texels)
    finally:
        _TEXEL_LIMIT.reset(token)


def _check_texels(path: str | os.PathLike, width: int, height: int) -> None:
    limit = _TEXEL_LIMIT.get()
    if width * height > limit:
        raise MatremapError(
            f"{path} is {width} x {height} = {width * height:,} texels, more than the limit of {limit:,}; "
            f"pass --max-texels {width * height} to read it anyway, or downsample it"
        )


def _oiio():
    try:
        import OpenImageIO as oiio
    except ImportError:  # pragma: no cover - it is a dependency
        raise MatremapError("texture I/O needs OpenImageIO: pip install openimageio") from None
    return oiio


# ---------------------------------------------------------------------------------------------
# transfer functions


_LUTS: dict[tuple[str, str], np.ndarray] = {}


def _decode_lut(pixel_type: str, colorspace: str) -> np.ndarray:
    key = (pixel_type, colorspace)
    if key not in _LUTS:
        top = 255 if pixel_type == "uint8" else 65535
        codes = np.arange(top + 1, dtype=np.float64) / top
        lut = srgb_to_linear(codes) if colorspace == "srgb" else codes
        _LUTS[key] = lut.astype(np.float32)
    return _LUTS[key]


def normalise_colorspace(name: Any, where: str = "") -> str:
    key = str(name).strip().lower()
    if key not in _CS_ALIASES:
        raise MatremapError(f"{where}unknown colour space {name!r}; use one of {', '.join(COLORSPACES)}")
    return _CS_ALIASES[key]


# ---------------------------------------------------------------------------------------------
# image info, streaming reader and writer


@dataclass(frozen=True)
class ImageInfo:
    """What a file holds and how its values are encoded.

    ``format``: png, jpg, tif, exr, or tga (read only: :meth:`written`); ``pixel_type``: uint8, uint16, half or float;
    ``colorspace``: srgb or linear (how integer code values map to linear values; float files are
    linear unless a manifest says otherwise)."""

    format: str
    pixel_type: str
    channels: int
    width: int
    height: int
    colorspace: str = "linear"
    compression: str | None = None
    path: str = ""

    @property
    def integer(self) -> bool:
        return self.pixel_type in ("uint8", "uint16")

    @property
    def bits(self) -> int:
        return {"uint8": 8, "uint16": 16, "half": 16, "float": 32}[self.pixel_type]

    @property
    def suffix(self) -> str:
        return "." + self.format

    def like(self, **changes: Any) -> ImageInfo:
        return replace(self, **changes)

    def written(self) -> ImageInfo:
        """This format as a map is written: itself, or for a format matremap reads only (Targa), PNG for integer
        pixels and EXR for float ones."""
        if self.format in WRITTEN_FORMATS:
            return self
        return self.like(format="png", compression=None) if self.integer else self.like(format="exr", compression=None)


def default_colorspace(pixel_type: str, colour: bool) -> str:
    """sRGB for colour maps in 8/16-bit files, linear otherwise."""
    return "srgb" if colour and pixel_type in ("uint8", "uint16") else "linear"


def _open_input(path: str | os.PathLike):
    oiio = _oiio()
    p = Path(path)
    if not p.is_file():
        raise MatremapError(not_a_file(p, "map"))
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)  # maps are data: colour must not be multiplied by alpha
    inp = oiio.ImageInput.open(oiio_name(p), config)
    if inp is None:
        msg = oiio.geterror().strip().splitlines()
        raise MatremapError(
            f"cannot read {p}: it is not a readable image ({msg[0] if msg else 'unknown error'}); "
            f"re-export it as PNG, JPEG, TIFF or EXR"
        )
    return inp


def image_info(path: str | os.PathLike, colorspace: str | None = None, colour: bool = True) -> ImageInfo:
    """Read a file's header. ``colorspace`` None picks :func:`default_colorspace`."""
    inp = _open_input(path)
    try:
        return _info_from(inp, path, colorspace, colour)
    finally:
        inp.close()


def _info_from(inp, path, colorspace, colour) -> ImageInfo:
    spec = inp.spec()
    _check_texels(path, spec.width, spec.height)
    fmt = _FORMATS.get(inp.format_name())
    if fmt is None:
        raise MatremapError(f"{path}: {inp.format_name()} images are not supported; use PNG, JPEG, TIFF, EXR or TGA")
    base = str(spec.format)
    pixel_type = base if base in ("uint8", "uint16", "half", "float") else "float"
    cs = normalise_colorspace(colorspace, f"{path}: ") if colorspace else default_colorspace(pixel_type, colour)
    comp = spec.get_string_attribute("compression") or None
    return ImageInfo(fmt, pixel_type, spec.nchannels, spec.width, spec.height, cs, comp, str(path))


class MapReader:
    """Reads bands of rows of one image, in order, as linear float32 ``[rows, W, C]``.

    The file stays open between bands: sequential formats (PNG, JPEG) are decoded once from top to
    bottom however many bands are read."""

    def __init__(
        self, path: str | os.PathLike, colorspace: str | None = None, colour: bool = True, check_finite: bool = True
    ):
        self.path = Path(path)
        self._inp = _open_input(path)
        self.info = _info_from(self._inp, path, colorspace, colour)
        self.check_finite = check_finite

    def read_rows(self, y0: int, y1: int) -> np.ndarray:
        return self.decode(self.read_codes(y0, y1))

    def read_codes(self, y0: int, y1: int) -> np.ndarray:
        """Rows ``y0:y1`` as stored, ``[rows, W, C]``: uint8 or uint16 code values, float32 for float files
        (refused when not finite, if :attr:`check_finite`); :meth:`decode` makes them linear values."""
        oiio = _oiio()
        info = self.info
        if not 0 <= y0 < y1 <= info.height:
            raise ValueError(f"rows {y0}:{y1} outside 0:{info.height}")
        fmt = {"uint8": oiio.UINT8, "uint16": oiio.UINT16}.get(info.pixel_type, oiio.FLOAT)
        raw = self._inp.read_scanlines(0, 0, y0, y1, 0, 0, info.channels, fmt)
        if raw is None or not isinstance(raw, np.ndarray) or raw.size != (y1 - y0) * info.width * info.channels:
            msg = (self._inp.geterror() or oiio.geterror() or "no pixel data").strip().splitlines()
            raise MatremapError(
                f"cannot read rows {y0}-{y1 - 1} of {self.path}: the file is corrupt or truncated "
                f"({msg[0] if msg else 'read failed'}); re-export it"
            )
        raw = raw.reshape(y1 - y0, info.width, info.channels)
        if info.integer:
            return raw
        out = np.asarray(raw, dtype=np.float32)
        if self.check_finite and not np.isfinite(out.sum(dtype=np.float64)):
            bad = ~np.isfinite(out).all(axis=(1, 2))
            if bad.any():
                row = y0 + int(np.argmax(bad))
                raise MatremapError(
                    f"{self.path} holds NaN or infinite texels (first in row {row}); "
                    f"replace them with finite values before converting"
                )
        return out

    def decode(self, codes: np.ndarray) -> np.ndarray:
        """Values of :meth:`read_codes` (any shape, any selection of them) as linear float32."""
        info = self.info
        if info.integer:
            return _decode_lut(info.pixel_type, info.colorspace)[codes]
        out = np.asarray(codes, dtype=np.float32)
        if info.colorspace == "srgb":
            out = srgb_to_linear(np.clip(out, 0.0, 1.0))
        return out

    def close(self) -> None:
        if self._inp is not None:
            self._inp.close()
            self._inp = None

    def __enter__(self) -> MapReader:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def read_region(
    path: str | os.PathLike, y0: int, y1: int, colorspace: str | None = None, colour: bool = True
) -> tuple[np.ndarray, ImageInfo]:
    """Rows ``y0:y1`` of an image as linear float32 ``[y1 - y0, W, C]``. To stream a whole
    sequential file (PNG, JPEG) band after band, keep one :class:`MapReader` open instead."""
    with MapReader(path, colorspace, colour) as r:
        return r.read_rows(y0, y1), r.info


def read_image(
    path: str | os.PathLike, colorspace: str | None = None, colour: bool = True
) -> tuple[np.ndarray, ImageInfo]:
    """A whole image as linear float32 ``[H, W, C]`` and its :class:`ImageInfo`. ``colour`` False
    reads 8/16-bit files as data (linear) unless ``colorspace`` says otherwise."""
    with MapReader(path, colorspace, colour) as r:
        return r.read_rows(0, r.info.height), r.info


class MapWriter:
    """Writes an image band by band (rows in order) from linear float arrays ``[rows, W, C]``,
    encoding them as ``info`` says (format, pixel type, colour space). Counts values that an
    integer file cannot hold (outside [0, 1]) in :attr:`clipped`."""

    def __init__(self, path: str | os.PathLike, info: ImageInfo):
        oiio = _oiio()
        self.path, self.info = str(path), info
        self.clipped = 0
        fmt = {"uint8": oiio.UINT8, "uint16": oiio.UINT16, "half": oiio.HALF}.get(info.pixel_type, oiio.FLOAT)
        spec = oiio.ImageSpec(info.width, info.height, info.channels, fmt)
        if info.format == "png":
            spec.attribute("png:compressionLevel", 3)
        elif info.format == "jpg":
            spec.attribute("Compression", "jpeg:95")
        elif info.compression and info.format in ("exr", "tif"):
            spec.attribute("compression", info.compression)
        if info.format == "png" and info.colorspace == "srgb":
            spec.attribute("oiio:ColorSpace", "sRGB")
        spec.attribute("oiio:UnassociatedAlpha", 1)  # write colour as given, not divided by alpha
        self._out = oiio.ImageOutput.create(oiio_name(self.path))
        if self._out is None or not self._out.open(self.path, spec):
            raise MatremapError(f"cannot write {path}: {oiio.geterror().strip()}")
        self._next = 0

    def write_rows(self, y0: int, data: np.ndarray) -> None:
        info = self.info
        data = np.asarray(data)
        if data.ndim == 2:
            data = data[..., None]
        if y0 != self._next or data.shape[1:] != (info.width, info.channels):
            raise ValueError(f"band at row {y0} with shape {data.shape} does not follow row {self._next}")
        if info.integer:
            top = 255 if info.pixel_type == "uint8" else 65535
            self.clipped += int(np.count_nonzero((data < 0) | (data > 1)))
            enc = (
                linear_to_srgb(data.astype(np.float32, copy=False))
                if info.colorspace == "srgb"
                else np.clip(data, 0.0, 1.0).astype(np.float32)
            )
            enc *= top
            enc += 0.5
            out = enc.astype(np.uint8 if top == 255 else np.uint16)
        else:
            out = data.astype(np.float32, copy=False)
            if info.colorspace == "srgb":
                out = linear_to_srgb(out)
        if not self._out.write_scanlines(y0, y0 + data.shape[0], 0, np.ascontiguousarray(out)):
            raise MatremapError(f"cannot write {self.path}: {self._out.geterror().strip()}")
        self._next = y0 + data.shape[0]

    def close(self) -> None:
        if self._out is not None:
            ok = self._out.close()
            self._out = None
            if ok is False:  # pragma: no cover - disk full and the like
                raise MatremapError(f"cannot finish writing {self.path}")

    def __enter__(self) -> MapWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def write_image_like(path: str | os.PathLike, array: np.ndarray, info: ImageInfo, force: bool = False) -> Path:
    """Write a linear float image ``[H, W, C]`` (or ``[H, W]``) with ``info``'s format, pixel type
    and colour space (size and channel count come from ``array``), atomically."""
    a = np.asarray(array, dtype=np.float32)
    if a.ndim == 2:
        a = a[..., None]
    p = check_output(path, force)
    if p.suffix.lower() not in MAP_SUFFIXES:
        p = p.with_suffix(info.suffix)
    info = info.like(height=a.shape[0], width=a.shape[1], channels=a.shape[2])
    with atomic_output(p) as tmp:
        w = MapWriter(tmp, info)
        try:
            w.write_rows(0, a)
        finally:
            w.close()
    return p


def transform_image(
    src: str | os.PathLike, colorspace: str, dest: str | os.PathLike, values: Callable[[np.ndarray], np.ndarray]
) -> tuple[int, int]:
    """``src`` read band by band (linear float32 ``[rows, W, C]``, decoded as ``colorspace`` says), each band
    through ``values`` (to ``[rows, W, C']``), written to ``dest`` as linear float EXR, atomically; returns
    (height, width). Memory: a band (about a million texels), whatever the image size."""
    dest = Path(dest)
    with MapReader(src, colorspace, colour=True) as r, atomic_output(dest) as tmp:
        height, width = r.info.height, r.info.width
        rows = max(8, min(512, (1 << 20) // max(width, 1)))
        writer: MapWriter | None = None
        try:
            for y0 in range(0, height, rows):
                band = np.atleast_3d(np.asarray(values(r.read_rows(y0, min(height, y0 + rows))), dtype=np.float32))
                if writer is None:
                    writer = MapWriter(tmp, ImageInfo("exr", "float", band.shape[-1], width, height, "linear"))
                writer.write_rows(y0, band)
        finally:
            if writer is not None:
                writer.close()
    return height, width


def output_info(info: ImageInfo, out_format: str | None) -> ImageInfo:
    """``info`` with the file format / pixel type replaced as ``out_format`` (a key of
    :data:`OUT_FORMATS`) says; None keeps them (a format read only becomes one written: :meth:`ImageInfo.written`)."""
    if out_format is None:
        return info.written()
    if out_format not in OUT_FORMATS:
        raise MatremapError(f"unknown output format {out_format!r}; use one of {', '.join(OUT_FORMATS)}")
    fmt, pixel_type = OUT_FORMATS[out_format]
    cs = info.colorspace if pixel_type in ("uint8", "uint16") else "linear"
    if info.colorspace == "srgb" and not info.integer and pixel_type in ("uint8", "uint16"):
        cs = "srgb"
    return info.like(
        format=fmt, pixel_type=pixel_type, colorspace=cs, compression=info.compression if fmt == info.format else None
    )


# ---------------------------------------------------------------------------------------------
# map sets


@dataclass
class MapSet:
    """Files bound to the parameters of a model.

    ``maps``: parameter name -> file; ``colorspace``: parameter name -> srgb/linear for each map;
    ``info``: parameter name -> :class:`ImageInfo`; ``normal``: the normal map, if any;
    ``constants``: parameter values and options given as numbers/strings (not maps);
    ``size``: (H, W); ``notes``: things the loader decided and the user should know."""

    model: str
    maps: dict[str, Path]
    root: Path
    size: tuple[int, int] = (0, 0)
    normal: Path | None = None
    constants: dict[str, Any] = field(default_factory=dict)
    colorspace: dict[str, str] = field(default_factory=dict)
    info: dict[str, ImageInfo] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)

    @property
    def spec(self) -> ModelSpec:
        return get_model(self.model)

    @property
    def files(self) -> list[Path]:
        return [*self.maps.values(), *([self.normal] if self.normal else [])]

    @property
    def options(self) -> dict[str, str]:
        return {k: v for k, v in self.constants.items() if k in self.spec.option_names}


def _is_colour(spec: ModelSpec, name: str) -> bool:
    p = spec.param(name)
    return p.channels == 3 and p.role in ("diffuse", "specular", "fresnel")


def convention_params(spec: ModelSpec) -> dict[str, str | None]:
    """File-name role -> the model's parameter it binds (None where the model has none)."""
    from matremap.regress.quantities import diffuse_param, roughness_param

    dp, rp = diffuse_param(spec), roughness_param(spec)
    sp = spec.reflectance.specular_map_param if spec.reflectance is not None else None
    return {"diffuse": dp.name if dp else None, "specular": sp, "roughness": rp.name if rp else None}


def _find_by_convention(root: Path) -> dict[str, Path]:
    found: dict[str, list[Path]] = {}
    for f in sorted(root.iterdir()):
        if not f.is_file() or f.suffix.lower() not in MAP_SUFFIXES or f.name.startswith("."):
            continue
        stem = f.stem.lower()
        for role in CONVENTIONS:
            if stem == role or stem.endswith("_" + role):
                found.setdefault(role, []).append(f)
    for role, files in found.items():
        if len(files) > 1:
            raise MatremapError(
                f"{root}: several files match *_{role} ({', '.join(f.name for f in files)}); "
                f"keep one or bind them in a material.json"
            )
    return {role: files[0] for role, files in found.items()}


def _read_manifest(path: Path) -> dict[str, Any]:
    from matremap.core.documents import read_document

    obj = read_document(path, "manifest")
    if not isinstance(obj, dict):
        raise MatremapError(f"{path}: the manifest must be an object with 'model' and 'maps'")
    return obj


def load_map_set(
    path: str | os.PathLike,
    model: str | None = None,
    params: Mapping[str, Any] | None = None,
    *,
    confine: bool = False,
) -> MapSet:
    """Load a map set from a folder (with a manifest, else by file-name conventions) or from a
    manifest file. ``model`` is required for conventions (and must agree with a manifest);
    ``params`` adds constants/options (a manifest's win). ``confine``: refuse, before looking at them,
    files the manifest names outside the map set's folder and the folders allowed with ``--allow-path``
    (the command line confines the map sets a user gives it; map sets matremap unpacks itself name the
    asset's own textures, already confined by the asset's reader)."""
    p = Path(path)
    if not p.exists():
        raise MatremapError(f"map set {p} not found; give a folder of maps or a material.json")
    manifest = p if p.is_file() else next((p / m for m in MANIFESTS if (p / m).is_file()), None)
    root = p.parent if p.is_file() else p
    found = _bind_manifest(manifest, root, model) if manifest is not None else _bind_conventions(root, model)
    if confine:
        _check_confined(found, root)
    spec = get_model(found.model)
    constants = _check_bindings(spec, found.files, {**dict(params or {}), **found.constants}, found.where)
    ms = MapSet(spec.id, found.files, root, normal=found.normal, constants=constants)
    for name, f in found.files.items():
        cs = found.colorspace.get(f.name, found.colorspace.get(name))
        ms.info[name] = image_info(f, cs, colour=_is_colour(spec, name))
        ms.colorspace[name] = ms.info[name].colorspace
        _check_channels(spec, name, ms.info[name], ms.notes)
    ms.size = _common_size(ms, found.colorspace)
    return ms


@dataclass
class _Bindings:
    """What a manifest or the file-name conventions bind: parameter -> file, normal map, constants."""

    model: str
    files: dict[str, Path]
    normal: Path | None
    constants: dict[str, Any]
    colorspace: dict[str, str]
    where: str


def _check_confined(found: _Bindings, root: Path) -> None:
    """Refuse a file named outside ``root`` and the allowed folders (the message is the same whether it
    exists: :func:`matremap.formats.confine.resolve_reference` does not look at the file)."""
    from matremap.formats.confine import resolve_reference

    named = [*found.files.items(), *([("normal", found.normal)] if found.normal else [])]
    for name, f in named:
        resolve_reference(os.path.relpath(f, root), root, f"map set {root}: the {name} map")


def _bind_manifest(manifest: Path, root: Path, model: str | None) -> _Bindings:
    """The bindings a ``material.json``/``.toml`` declares, checked."""
    if manifest.suffix.lower() not in (".json", ".toml"):
        raise MatremapError(f"{manifest} is not a manifest; give a folder or a material.json/.toml")
    obj = _read_manifest(manifest)
    unknown = set(obj) - {"model", "maps", "normal", "params", "colorspace", "size", "notes", "provenance"}
    if unknown:
        raise MatremapError(
            f"{manifest}: unknown keys {', '.join(sorted(unknown))}; use model, maps, normal, params, colorspace"
        )
    mmodel = obj.get("model")
    if not isinstance(mmodel, str):
        raise MatremapError(f"{manifest}: 'model' must name a model, e.g. \"mitsuba06:ward\"")
    if model is not None and get_model(model).id != get_model(mmodel).id:
        raise MatremapError(
            f"{manifest} says the maps are for {mmodel}, not {model}; drop the model argument or fix the manifest"
        )
    maps_obj = obj.get("maps", {})
    if not isinstance(maps_obj, dict) or not all(_file_name(v) for v in maps_obj.values()):
        raise MatremapError(f"{manifest}: 'maps' must map parameter names to file names")
    if obj.get("normal") is not None and not _file_name(obj["normal"]):
        raise MatremapError(f"{manifest}: 'normal' must be the file name of a normal map")
    normal = root / obj["normal"] if obj.get("normal") is not None else None
    cs_obj = obj.get("colorspace", {}) or {}
    if not isinstance(cs_obj, dict) or not all(isinstance(v, str) for v in cs_obj.values()):
        raise MatremapError(f"{manifest}: 'colorspace' must map file or parameter names to srgb/linear")
    colorspace = {k: normalise_colorspace(v, f"{manifest}: {k}: ") for k, v in cs_obj.items()}
    params = obj.get("params", {}) or {}
    if not isinstance(params, dict):
        raise MatremapError(f"{manifest}: 'params' must map parameter names to values, e.g. {{\"alpha\": 0.2}}")
    files = {k: root / v for k, v in maps_obj.items()}
    return _Bindings(mmodel, files, normal, dict(params), colorspace, str(manifest))


def _file_name(v: Any) -> bool:
    """Whether a manifest value can name a file: a non-empty string of a sane length without NUL."""
    return isinstance(v, str) and 0 < len(v.strip()) and len(v) <= 4096 and "\0" not in v


def _bind_conventions(root: Path, model: str | None) -> _Bindings:
    """The bindings of maps named ``*_diffuse``, ``*_specular``, ``*_roughness``, ``*_normal``."""
    if model is None:
        raise MatremapError(
            f"{root} has no material.json or material.toml; name the maps' model "
            f"(e.g. --model mitsuba06:ward) to use the *_diffuse/*_specular/*_roughness/"
            f"*_normal file-name conventions"
        )
    spec = get_model(model)
    found = _find_by_convention(root)
    if not found:
        raise MatremapError(
            f"{root} holds no maps named *_diffuse, *_specular, *_roughness or *_normal "
            f"(png, jpg, tif, exr); rename them or write a material.json"
        )
    bind = convention_params(spec)
    files, normal = {}, None
    for role, f in found.items():
        if role == "normal":
            normal = f
            continue
        name = bind[role]
        if name is None:
            raise MatremapError(
                f"{f.name}: model {spec.id} has no {role} parameter to bind it to; bind the maps in a material.json"
            )
        files[name] = f
    return _Bindings(spec.id, files, normal, {}, {}, str(root))


def _check_bindings(
    spec: ModelSpec, files: Mapping[str, Path], constants: dict[str, Any], where: str
) -> dict[str, Any]:
    """Maps bind parameters (not options) of the model, none twice; constants are validated and
    returned as plain numbers (options as strings)."""
    for name in files:
        if name in spec.option_names:
            raise MatremapError(f"{where}: {name} is an option of {spec.id}, not a parameter a map can drive")
        spec.param(name)  # unknown names raise, listing the valid ones
    clash = set(files) & set(constants)
    if clash:
        raise MatremapError(f"{where}: {sorted(clash)[0]} is given both as a map and as a value; keep one")
    if not files:
        raise MatremapError(
            f"{where} binds no map to a parameter of {spec.id}; add maps or use the file-name conventions"
        )
    if not constants:
        return constants
    from matremap.core.material import Material

    Material.create(spec.id, constants)  # validates names, ranges and options
    return {
        k: (
            v
            if k in spec.option_names
            else (
                float(np.asarray(v, dtype=float).reshape(-1)[0])
                if np.size(v) == 1
                else [float(x) for x in np.asarray(v, dtype=float).reshape(-1)]
            )
        )
        for k, v in constants.items()
    }


def _common_size(ms: MapSet, colorspace: Mapping[str, str]) -> tuple[int, int]:
    """The maps' one size (height, width); the normal map must have 3 channels and the same size."""
    sizes = {name: (i.height, i.width) for name, i in ms.info.items()}
    names = {name: ms.maps[name].name for name in ms.info}
    if ms.normal is not None:
        ninfo = image_info(ms.normal, colorspace.get(ms.normal.name, "linear"), colour=False)
        if ninfo.channels not in (3, 4):
            raise MatremapError(
                f"normal map {ms.normal.name} has {ninfo.channels} channel(s); a tangent-space normal map needs 3 (RGB)"
            )
        sizes["normal map"] = (ninfo.height, ninfo.width)
        names["normal map"] = ms.normal.name
    if len(set(sizes.values())) > 1:
        listing = ", ".join(f"{names[k]} {h}x{w}" for k, (h, w) in sizes.items())
        raise MatremapError(f"the maps differ in size ({listing}); resample them to one size")
    return next(iter(sizes.values()))


def _check_channels(spec: ModelSpec, name: str, info: ImageInfo, notes: list[str]) -> None:
    p = spec.param(name)
    fname = Path(info.path).name
    if p.channels == 3:
        if info.channels == 4:
            notes.append(f"{fname}: alpha channel ignored")
        elif info.channels not in (1, 3):
            raise MatremapError(
                f"{fname} has {info.channels} channels but {name} is RGB; save it as RGB (3 channels) or grey (1)"
            )
    else:
        if info.channels in (3, 4):
            notes.append(f"{fname}: {name} is a scalar; using the first channel of this RGB file (it must be grey)")
        elif info.channels != 1:
            raise MatremapError(
                f"{fname} has {info.channels} channels but {name} is a scalar; save it as a grey (1-channel) image"
            )


def map_values(spec: ModelSpec, name: str, band: np.ndarray, path: Path, y0: int) -> np.ndarray:
    """A band read from a map ``[rows, W, C]`` as the parameter's array: scalar ``[rows, W]`` or
    RGB ``[rows, W, 3]`` (a grey file gives ``[rows, W]``, which transforms broadcast)."""
    p = spec.param(name)
    c = band.shape[-1]
    if p.channels == 3:
        return band[..., 0] if c == 1 else band[..., :3]
    if c >= 3:
        spread = band[..., :3].max(axis=-1) - band[..., :3].min(axis=-1)
        if spread.max() > 2.5 / 255:
            row = y0 + int(np.argmax(spread.max(axis=1) > 2.5 / 255))
            raise MatremapError(f"{path.name} is coloured (row {row}) but {name} is a scalar; save it as a grey image")
    return band[..., 0]


def save_manifest(
    out_dir: str | os.PathLike,
    map_set: MapSet,
    extra: Mapping[str, Any] | None = None,
    name: str = "material.json",
    force: bool = True,
) -> Path:
    """Write ``material.json`` describing ``map_set`` (file names relative to ``out_dir``)."""
    out = Path(out_dir)
    doc = manifest_dict(map_set, out)
    doc.update(extra or {})
    p = check_output(out / name, force)
    with atomic_output(p) as tmp, open(tmp, "w") as f:
        f.write(json.dumps(doc, indent=1) + "\n")
    return p


def manifest_dict(map_set: MapSet, out_dir: Path) -> dict[str, Any]:
    def rel(f: Path) -> str:
        try:
            return str(Path(f).relative_to(out_dir))
        except ValueError:
            return str(f)

    doc: dict[str, Any] = {"model": map_set.model, "maps": {k: rel(v) for k, v in map_set.maps.items()}}
    if map_set.normal is not None:
        doc["normal"] = rel(map_set.normal)
    if map_set.constants:
        doc["params"] = map_set.constants
    if map_set.colorspace:
        doc["colorspace"] = {rel(map_set.maps[k]): v for k, v in map_set.colorspace.items() if k in map_set.maps}
    return doc
