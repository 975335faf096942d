"""glTF 2.0 materials in and out (``.gltf`` JSON and ``.glb`` binary), as ``gltf:metal-rough``.

References are to the glTF 2.0 specification (Khronos, version 2.0.1, 2021) and the Khronos
extension READMEs:

* §3.9.2 "Metallic-Roughness Material": ``baseColorFactor`` (linear RGBA, default 1) times the
  ``baseColorTexture`` (sRGB-encoded); ``metallicFactor`` / ``roughnessFactor`` (default 1) times
  the blue / green channels of the linear ``metallicRoughnessTexture`` (red and alpha unused);
* §3.9.3 "Additional Textures": ``normalTexture`` (tangent space, ``scale`` scales its x and y),
  ``occlusionTexture`` and ``emissive*`` (matremap does not remap them: they are noted, and a
  written copy keeps them);
* §3.9.4 / §3.9.5 ``alphaMode``, ``doubleSided``; §3.8 "Texture Data" (textures, images, samplers;
  ``texCoord``); §3.6 "Binary Data Storage" (buffers, buffer views, ``data:`` URIs);
* §4 "GLB File Format Specification": a 12-byte header (magic ``glTF``, version 2, length), a JSON
  chunk padded with spaces and an optional BIN chunk padded with zeros, all 4-byte aligned; the
  BIN chunk is the buffer with index 0 that has no ``uri``;
* KHR_materials_ior (``ior``, default 1.5) and KHR_materials_specular (``specularFactor`` and the
  alpha channel of ``specularTexture``; ``specularColorFactor`` and the sRGB RGB of
  ``specularColorTexture``), which the dialect in
  :mod:`matremap.renderers.embedded.evaluators.gltf` evaluates.

A reader picks one material and returns a :class:`~matremap.formats.asset.MaterialAsset` whose
``document`` is a :class:`GltfDocument` (the parsed JSON and, for a ``.glb``, its BIN chunk).
Images stored inside the file (buffer views, ``data:`` URIs) are extracted once to a cache folder,
``<cache>/gltf-images/<hash of the file>`` of matremap's private cache (:func:`matremap.core.diskcache.cache_dir`),
named by their content's digest and checked against it when reused, so that every texture has a real path;
such textures are marked ``extracted`` (a map set copies them rather than pointing into the cache).

The file is untrusted: external URIs must resolve inside the file's folder or a folder the user allowed
(:mod:`matremap.formats.confine`), a GLB's chunks and buffer views must lie inside the file and their
offsets be non-negative integers, ``data:`` URIs must be valid base64, and the JSON may nest at most
:data:`MAX_JSON_DEPTH` levels; anything else is refused with one line.

The writer copies the source file with the chosen material replaced, or writes a small file of its
own (the material on a UV sphere) when there is no glTF source.
"""

from __future__ import annotations

import base64
import binascii
import copy
import dataclasses
import hashlib
import json
import math
import os
import re
import struct
from dataclasses import dataclass
from glob import escape as glob_escape
from pathlib import Path
from typing import Any
from urllib.parse import quote, unquote, unquote_to_bytes

import numpy as np

from matremap.core.atomic import AtomicFiles
from matremap.core.imageio import atomic_output, check_output, linear_to_srgb
from matremap.core.material import Material
from matremap.dialects import get_model
from matremap.errors import MatremapError
from matremap.formats.asset import MaterialAsset, TextureRef
from matremap.formats.confine import Confinement, resolve_reference

MODEL = "gltf:metal-rough"
IOR = "KHR_materials_ior"
SPECULAR = "KHR_materials_specular"
DEFAULT_IOR = 1.5
#: GLB (§4.4): magic "glTF", chunk types "JSON" and "BIN\0"
GLB_MAGIC = 0x46546C67
CHUNK_JSON = 0x4E4F534A
CHUNK_BIN = 0x004E4942
#: the deepest JSON nesting read (glTF files nest about ten levels; deeper is an attack or a broken file)
MAX_JSON_DEPTH = 100
_MIME_SUFFIX = {"image/png": ".png", "image/jpeg": ".jpg", "image/webp": ".webp", "image/ktx2": ".ktx2"}


@dataclass
class GltfDocument:
    """What a reader parsed: the JSON, the GLB BIN chunk (None for a ``.gltf``), whether the file was
    binary, and the folder its relative URIs resolve against."""

    json: dict[str, Any]
    bin: bytes | None
    binary: bool
    base: Path


# ---------------------------------------------------------------------------------------------
# parsing


def _parse(path: Path, data: bytes) -> tuple[dict[str, Any], bytes | None]:
    """The JSON object and the BIN chunk of a .glb or .gltf file's bytes (§4.4, §3.1)."""
    suffix = path.suffix.lower()
    if suffix == ".glb":
        text, bin_chunk = _glb_chunks(path, data)
    elif suffix == ".gltf":
        if data[:4] == b"glTF":
            raise MatremapError(f"{path} is a binary glTF (GLB), not JSON; rename it to .glb")
        text, bin_chunk = data, None
    else:
        raise MatremapError(f"{path}: a glTF file ends in .gltf or .glb, not {suffix or 'nothing'}")
    try:
        obj = json.loads(text.decode("utf-8-sig"))
    except UnicodeDecodeError:
        raise MatremapError(
            f"{path} is not a JSON glTF: it is not UTF-8 text"
            + ("; if it is a binary glTF, name it .glb" if suffix == ".gltf" else "")
        ) from None
    except json.JSONDecodeError as e:
        raise MatremapError(
            f"{path} is not valid glTF JSON: {e.msg} at line {e.lineno}, column {e.colno}; fix or re-export the file"
        ) from None
    except RecursionError:
        obj = None  # nested past what the parser can follow: refused below, with the depth check's words
    except ValueError:  # an integer of more digits than Python converts
        raise MatremapError(
            f"{path} is not valid glTF JSON: a number in it has too many digits to read; fix or re-export the file"
        ) from None
    if obj is None or _too_deep(obj):
        raise MatremapError(
            f"{path}: its JSON nests deeper than {MAX_JSON_DEPTH} levels; a glTF file is far shallower, "
            f"so it is broken or hostile (re-export it)"
        )
    if not isinstance(obj, dict):
        raise MatremapError(f"{path}: a glTF file is a JSON object with 'asset'; this one is not")
    asset = obj.get("asset")
    version = asset.get("version") if isinstance(asset, dict) else None
    if not isinstance(version, str):
        raise MatremapError(f"{path} has no asset.version; it is not a glTF 2.0 file (re-export it)")
    if version.split(".")[0] != "2":
        raise MatremapError(
            f"{path} is glTF {version}; matremap reads glTF 2.0 (convert it, e.g. with the Khronos "
            f"glTF 1.0 to 2.0 converter)"
        )
    return obj, bin_chunk


def _too_deep(obj: Any) -> bool:
    """Whether JSON value ``obj`` nests more than :data:`MAX_JSON_DEPTH` arrays/objects (walked
    without recursion)."""
    level: list[Any] = [obj]
    for _ in range(MAX_JSON_DEPTH + 1):
        level = [v for x in level for v in (x.values() if isinstance(x, dict) else x if isinstance(x, list) else ())]
        level = [v for v in level if isinstance(v, dict | list)]
        if not level:
            return False
    return True


def _glb_chunks(path: Path, data: bytes) -> tuple[bytes, bytes | None]:
    """The JSON chunk and the BIN chunk (None if there is none) of a GLB file's bytes (§4.4)."""
    if data[:4] != b"glTF":
        if data.lstrip()[:1] == b"{":
            raise MatremapError(f"{path} holds JSON text, not a binary glTF; rename it to .gltf")
        raise MatremapError(
            f"{path} is not a binary glTF: it does not start with the 'glTF' magic; "
            f"re-export it as .glb (or give the file its real extension)"
        )
    if len(data) < 20:
        raise MatremapError(f"{path} is truncated ({len(data)} bytes, shorter than a GLB header); re-export it")
    _, version, length = struct.unpack_from("<III", data, 0)
    if version != 2:
        raise MatremapError(f"{path} is a GLB version {version} file; matremap reads glTF 2.0 (GLB version 2)")
    if length > len(data):
        raise MatremapError(
            f"{path} is truncated: its header says {length} bytes, the file has {len(data)}; re-export it"
        )
    chunks: list[tuple[int, bytes]] = []
    pos = 12
    while pos + 8 <= length:
        clen, ctype = struct.unpack_from("<II", data, pos)
        if pos + 8 + clen > length:
            raise MatremapError(f"{path} is truncated: a chunk runs past the end of the file; re-export it")
        chunks.append((ctype, data[pos + 8 : pos + 8 + clen]))
        pos += 8 + clen
    if not chunks or chunks[0][0] != CHUNK_JSON:
        raise MatremapError(f"{path}: the first GLB chunk is not JSON; the file is corrupt, re-export it")
    return chunks[0][1], (chunks[1][1] if len(chunks) > 1 and chunks[1][0] == CHUNK_BIN else None)


def _cache_dir(data: bytes) -> Path:
    """The folder of a file's extracted images in matremap's private cache (created 0700, refused when
    another user owns it or others may write to it), never in a shared temporary folder."""
    from matremap.core.diskcache import private_cache_dir

    return private_cache_dir("gltf-images", hashlib.sha256(data).hexdigest()[:20])


def _digest_matches(f: Path, digest: str) -> bool:
    """Whether cache file ``f`` is a regular file whose content has ``digest`` (a prefix of its SHA-256)."""
    return f.is_file() and not f.is_symlink() and hashlib.sha256(f.read_bytes()).hexdigest()[: len(digest)] == digest


def _cached_copy(folder: Path, stem: str, suffix: str, data: bytes) -> Path:
    """``data`` stored under a name that carries its digest; an existing file is reused only when its
    content still has that digest (an edited or truncated cache file is written again)."""
    digest = hashlib.sha256(data).hexdigest()[:16]
    f = folder / f"{stem}-{digest}{suffix}"
    if not _digest_matches(f, digest):
        with atomic_output(f) as tmp, open(tmp, "wb") as out:
            out.write(data)
    return f


def _data_uri(path: Path, uri: str, what: str) -> tuple[str, bytes]:
    """(media type, bytes) of a ``data:`` URI (RFC 2397; base64 or percent-encoded); ``what`` names
    the item holding it (in errors)."""
    head, _, payload = uri[5:].partition(",")
    mime = head.split(";")[0]
    if head.endswith(";base64"):
        try:
            text = "".join(unquote(payload).split())  # line breaks and spaces are not part of base64
            return mime, base64.b64decode(text.encode("ascii"), validate=True)
        except (binascii.Error, UnicodeEncodeError):
            raise MatremapError(
                f"{path}: {what} is a data: URI whose base64 payload is not valid base64; re-export the file"
            ) from None
    return mime, unquote_to_bytes(payload)


def _sniff(data: bytes) -> str:
    if data[:8] == b"\x89PNG\r\n\x1a\n":
        return ".png"
    if data[:3] == b"\xff\xd8\xff":
        return ".jpg"
    if data[:4] == b"RIFF" and data[8:12] == b"WEBP":
        return ".webp"
    return ".bin"


def _index(value: Any) -> bool:
    """Whether a JSON value is a valid index or count (a non-negative integer, not a boolean)."""
    return isinstance(value, int) and not isinstance(value, bool) and value >= 0


class _Reader:
    """Resolves the indices of one document (textures, images, buffers) to files and bytes; external
    files must lie where ``confinement`` allows (the file's folder, or an allowed folder)."""

    def __init__(self, path: Path, doc: GltfDocument, data: bytes, confinement: Confinement | None = None):
        self.path, self.doc, self.data = path, doc, data
        self.confinement = confinement
        self._buffers: dict[int, bytes] = {}
        self._images: dict[int, Path] = {}
        #: the images that are matremap's extracted copies (in its cache), not files of the asset
        self.extracted: set[Path] = set()

    def item(self, key: str, index: Any, where: str) -> dict[str, Any]:
        found = self.doc.json.get(key)
        items: list[Any] = found if isinstance(found, list) else []
        n = len(items)
        if not _index(index) or not index < n:
            raise MatremapError(
                f"{self.path}: {where} refers to {key}[{index!r}], but the file has {n}; the file is broken, "
                f"re-export it"
            )
        obj = items[index]
        if not isinstance(obj, dict):
            raise MatremapError(f"{self.path}: {key}[{index}] is not an object; the file is broken, re-export it")
        return obj

    def external(self, uri: str, what: str) -> Path:
        """The file a relative (or absolute) URI names, confined; refused for other URI schemes."""
        if re.match(r"[A-Za-z][A-Za-z0-9+.-]*://", uri):
            raise MatremapError(
                f"{self.path}: {what} {uri!r} is not a local file; matremap reads files beside the glTF "
                f"(download it and fix the uri)"
            )
        return resolve_reference(unquote(uri), self.doc.base, f"{self.path}: {what}", self.confinement)

    def buffer(self, index: Any, where: str) -> bytes:
        buf = self.item("buffers", index, where)
        if index in self._buffers:
            return self._buffers[index]
        uri = buf.get("uri")
        if uri is None:
            if index != 0 or self.doc.bin is None:
                raise MatremapError(
                    f"{self.path}: buffers[{index}] has no uri and no GLB BIN chunk holds it; re-export the file"
                )
            data = self.doc.bin
        elif not isinstance(uri, str):
            raise MatremapError(f"{self.path}: buffers[{index}].uri is not a string; the file is broken, re-export it")
        elif uri.startswith("data:"):
            data = _data_uri(self.path, uri, f"buffers[{index}]")[1]
        else:
            f = self.external(uri, f"buffer {index} uri")
            if not f.is_file():
                raise MatremapError(
                    f"{self.path}: buffer file {uri!r} not found at {f}; put it beside {self.path.name} or fix its uri"
                )
            data = f.read_bytes()
        need = buf.get("byteLength", 0)
        if not _index(need):
            raise MatremapError(
                f"{self.path}: buffers[{index}].byteLength is {need!r}, not a byte count; the file is broken, "
                f"re-export it"
            )
        if len(data) < need:
            raise MatremapError(
                f"{self.path}: buffers[{index}] holds {len(data)} bytes but says byteLength "
                f"{need}; the file is truncated, re-export it"
            )
        self._buffers[index] = data
        return data

    def buffer_view(self, index: Any, where: str) -> bytes:
        bv = self.item("bufferViews", index, where)
        data = self.buffer(bv.get("buffer"), f"bufferViews[{index}]")
        off, n = bv.get("byteOffset", 0), bv.get("byteLength")
        for key, value in (("byteOffset", off), ("byteLength", n)):
            if not _index(value):
                raise MatremapError(
                    f"{self.path}: bufferViews[{index}].{key} is {value!r}, not a non-negative integer; "
                    f"the file is broken, re-export it"
                )
        if off + n > len(data):
            raise MatremapError(
                f"{self.path}: bufferViews[{index}] (bytes {off} to {off + n}) runs past the end of its buffer "
                f"({len(data)} bytes); the file is broken, re-export it"
            )
        return data[off : off + n]

    def image(self, index: Any, where: str) -> Path:
        """A file holding image ``index``: the external file itself, or an extracted copy."""
        img = self.item("images", index, where)
        if index in self._images:
            return self._images[index]
        uri = img.get("uri")
        if uri is not None and not isinstance(uri, str):
            raise MatremapError(f"{self.path}: images[{index}].uri is not a string; the file is broken, re-export it")
        if uri is not None and not uri.startswith("data:"):
            f = self.external(uri, f"image {index} uri")
            if not f.is_file():
                raise MatremapError(
                    f"{self.path}: image {uri!r} ({where}) not found at {f}; put it beside "
                    f"{self.path.name} or fix its uri"
                )
            self._images[index] = f
            return f
        if uri is not None:
            mime, data = _data_uri(self.path, uri, f"images[{index}]")
        elif "bufferView" in img:
            mime, data = img.get("mimeType", ""), self.buffer_view(img["bufferView"], f"images[{index}]")
        else:
            raise MatremapError(f"{self.path}: images[{index}] has neither a uri nor a bufferView; re-export the file")
        suffix = (_MIME_SUFFIX.get(mime) if isinstance(mime, str) else None) or _sniff(data)
        f = _cached_copy(_cache_dir(self.data), f"image{index}", suffix, data)
        self._images[index] = f
        self.extracted.add(f)
        return f


def _without_alpha(path: Path) -> Path:
    """A copy of an image with alpha, without it, in the cache folder.

    PNG stores colour unassociated with alpha (§3.8.2 images are PNG or JPEG); OpenImageIO
    premultiplies colour by alpha on read unless told otherwise, which would darken base colours
    and packed channels wherever alpha < 1. The copy keeps the stored colour values. It lives in the
    folder of the image's own content and carries its digest in its name, checked when reused."""
    import tempfile

    import OpenImageIO as oiio

    folder = _cache_dir(path.read_bytes())
    for f in sorted(folder.glob(f"{glob_escape(path.stem)}-rgb-*.png")):
        if _digest_matches(f, f.stem.rsplit("-", 1)[-1]):
            return f
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    inp = oiio.ImageInput.open(str(path), config)
    if inp is None:
        raise MatremapError(f"cannot read {path}: {oiio.geterror().strip()}; re-export it as PNG or JPEG")
    spec = inp.spec()
    fmt = oiio.UINT16 if str(spec.format) == "uint16" else oiio.UINT8
    pixels = inp.read_image(0, 0, 0, spec.nchannels, fmt)
    inp.close()
    if pixels is None:
        raise MatremapError(f"cannot read {path}: the image is corrupt; re-export it")
    colour = np.ascontiguousarray(pixels[..., :3] if spec.nchannels == 4 else pixels[..., :1])
    fd, tmp = tempfile.mkstemp(prefix=".rgb.", suffix=".png", dir=folder)
    os.close(fd)
    try:
        o = oiio.ImageOutput.create(tmp)
        if o is None or not o.open(tmp, oiio.ImageSpec(spec.width, spec.height, colour.shape[-1], fmt)):
            raise MatremapError(f"cannot write an alpha-free copy of {path} in {folder}: {oiio.geterror().strip()}")
        o.write_image(colour)
        o.close()
        data = Path(tmp).read_bytes()
    finally:
        os.unlink(tmp)
    return _cached_copy(folder, f"{path.stem}-rgb", ".png", data)


def _select(path: Path, materials: list[Any], material: str | int | None) -> int:
    names = [m.get("name") if isinstance(m, dict) else None for m in materials]
    if material is None:
        return 0
    if isinstance(material, str) and material in names:
        return names.index(material)
    idx: int | None = None
    if isinstance(material, int) and not isinstance(material, bool):
        idx = material
    elif isinstance(material, str) and material.strip().lstrip("-").isdigit():
        idx = int(material)
    if idx is not None and 0 <= idx < len(materials):
        return idx
    listing = ", ".join(f"{i}: {n!r}" if n else f"{i}: (unnamed)" for i, n in enumerate(names))
    raise MatremapError(f"{path} has no material {material!r}; its materials are {listing} (pick one by name or index)")


def _number(path: Path, where: str, value: Any, default: Any, size: int = 1) -> Any:
    if value is None:
        return default
    vals = value if isinstance(value, list) else [value]
    if len(vals) != size or not all(
        isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in vals
    ):
        raise MatremapError(
            f"{path}: {where} must be {'a number' if size == 1 else f'{size} numbers'}, got {value!r}; fix the file"
        )
    return [float(v) for v in vals] if size > 1 else float(vals[0])


def _materials(p: Path) -> tuple[bytes, dict[str, Any], bytes | None, list[Any]]:
    """The file's bytes, its JSON, its binary chunk and its (non-empty) material list."""
    if not p.is_file():
        raise MatremapError(f"{p} not found")
    data = p.read_bytes()
    obj, bin_chunk = _parse(p, data)
    mats = obj.get("materials")
    if not isinstance(mats, list) or not mats:
        raise MatremapError(f"{p} has no materials; export it with its materials")
    return data, obj, bin_chunk, mats


def material_names(path: str | os.PathLike) -> list[str]:
    """The names of a file's materials, in order ("material N" for an unnamed one)."""
    mats = _materials(Path(path))[3]
    names = [m.get("name") if isinstance(m, dict) else None for m in mats]
    return [n if isinstance(n, str) and n else f"material {i}" for i, n in enumerate(names)]


def read(
    path: str | os.PathLike, material: str | int | None = None, *, confinement: Confinement | None = None
) -> MaterialAsset:
    """Read one material of a ``.gltf`` / ``.glb`` file as a ``gltf:metal-rough`` asset.

    ``material``: a name or an index (the first material by default). Textures become
    :class:`TextureRef`: base colour (sRGB, RGB, times baseColorFactor), roughness and metallic
    (green and blue of the metallicRoughnessTexture, §3.9.2), specular (alpha of
    specularTexture) and specularColor (sRGB RGB of specularColorTexture) of
    KHR_materials_specular; the normal map as ``asset.normal``. Inputs matremap does not remap
    are listed in ``asset.notes``. External images and buffers must lie in the file's folder or
    a folder ``confinement`` allows (default: the one in effect, :mod:`matremap.formats.confine`).
    """
    p = Path(path)
    data, obj, bin_chunk, mats = _materials(p)
    doc = GltfDocument(obj, bin_chunk, p.suffix.lower() == ".glb", p.parent)
    idx = _select(p, mats, material)
    m = mats[idx]
    if not isinstance(m, dict):
        raise MatremapError(f"{p}: materials[{idx}] is not an object; the file is broken, re-export it")
    given = m.get("name")
    name = given if isinstance(given, str) and given else f"material {idx}"
    notes: list[str] = []
    if material is None and len(mats) > 1:
        notes.append(f"{p.name} has {len(mats)} materials; using the first, {name!r} (choose another by name or index)")
    where = f"material {name!r}"
    pbr = m.get("pbrMetallicRoughness", {}) or {}
    ext = m.get("extensions", {}) or {}
    if (
        not isinstance(pbr, dict)
        or not isinstance(ext, dict)
        or not all(isinstance(ext.get(k) or {}, dict) for k in (IOR, SPECULAR))
    ):
        raise MatremapError(f"{p}: {where} has a malformed pbrMetallicRoughness or extensions; re-export the file")
    constants = _read_factors(p, where, pbr, ext, notes)
    reader = _Reader(p, doc, data, confinement)
    textures = _MaterialTextures(reader, where, notes)
    maps = {
        k: _marked(t, reader.extracted) for k, t in textures.read_maps(pbr, ext.get(SPECULAR) or {}, constants).items()
    }
    normal = textures.read_normal(m)
    normal = _marked(normal, reader.extracted) if normal is not None else None
    _note_unremapped(m, ext, obj, notes)
    return MaterialAsset(
        path=p,
        format="gltf",
        name=name,
        model=MODEL,
        constants=constants,
        textures=maps,
        normal=normal,
        notes=notes,
        document=doc,
        index=idx,
        lost=lost_look(ext),
    )


def _marked(ref: TextureRef, extracted: set[Path]) -> TextureRef:
    """``ref`` marked ``extracted`` when its file is one of matremap's extracted copies."""
    return dataclasses.replace(ref, extracted=True) if ref.path in extracted else ref


def _read_factors(path: Path, where: str, pbr: dict[str, Any], ext: dict[str, Any], notes: list[str]) -> dict[str, Any]:
    """The material's uniform values: the pbrMetallicRoughness factors, KHR_materials_ior's ior and
    KHR_materials_specular's factors (each at its default when absent), checked against the model."""
    base = _number(path, f"{where} baseColorFactor", pbr.get("baseColorFactor"), [1.0] * 4, 4)
    constants: dict[str, Any] = {
        "baseColor": base[:3],
        "metallic": _number(path, f"{where} metallicFactor", pbr.get("metallicFactor"), 1.0),
        "roughness": _number(path, f"{where} roughnessFactor", pbr.get("roughnessFactor"), 1.0),
    }
    if base[3] < 1.0:
        notes.append(f"baseColorFactor alpha {base[3]:g} ignored (matremap remaps opaque reflectance)")
    ior_ext = ext.get(IOR) or {}
    spec_ext = ext.get(SPECULAR) or {}
    constants["ior"] = _number(path, f"{where} {IOR}.ior", ior_ext.get("ior"), DEFAULT_IOR)
    if constants["ior"] == 0.0:
        raise MatremapError(
            f"{path}: {where} has {IOR} ior 0 (full specular), which gltf:metal-rough cannot express; "
            f"give it an ior in [1, 5]"
        )
    constants["specular"] = _number(path, f"{where} {SPECULAR}.specularFactor", spec_ext.get("specularFactor"), 1.0)
    constants["specularColor"] = _number(
        path, f"{where} {SPECULAR}.specularColorFactor", spec_ext.get("specularColorFactor"), [1.0] * 3, 3
    )
    try:
        Material.create(MODEL, constants)
    except MatremapError as e:
        raise MatremapError(f"{path}: {where}: {e}; fix the value in the file") from None
    return constants


def _channel(c: int, nch: int) -> int:
    """File channel of glTF colour channel c (0 R, 1 G, 2 B) in a file of ``nch`` channels: grey files replicate."""
    return c if nch >= 3 else 0


def _alpha_channel(nch: int) -> int | None:
    """File channel of glTF's alpha in a file of ``nch`` channels; None when it has no alpha."""
    return {4: 3, 2: 1}.get(nch)


def _dict(value: Any) -> dict[str, Any]:
    """A JSON value that should be an object, or {} when it is not one."""
    return value if isinstance(value, dict) else {}


class _MaterialTextures:
    """Reads the textures of one material (``where`` names it in messages), noting what it does not honour."""

    def __init__(self, reader: _Reader, where: str, notes: list[str]) -> None:
        self.reader, self.where, self.notes = reader, where, notes

    def file(self, info: Any, slot: str) -> tuple[Path, int]:
        """The image file of a textureInfo and its channel count; notes what is not honoured."""
        r, p, where = self.reader, self.reader.path, self.where
        if not isinstance(info, dict) or "index" not in info:
            raise MatremapError(f"{p}: {where} {slot} is not a textureInfo with an index; re-export the file")
        tex = r.item("textures", info["index"], f"{where} {slot}")
        src = tex.get("source")
        if src is None:  # an extension may give the only source (EXT_texture_webp, KHR_texture_basisu)
            src = next(
                (e["source"] for e in _dict(tex.get("extensions")).values() if isinstance(e, dict) and "source" in e),
                None,
            )
        if src is None:
            raise MatremapError(
                f"{p}: {where} {slot} uses textures[{info['index']}], which has no image source; re-export the file"
            )
        f = r.image(src, f"{where} {slot}")
        if info.get("texCoord", 0) != 0:
            self.notes.append(f"{slot} uses texCoord {info['texCoord']}; the map is taken as it is (UV set ignored)")
        if "KHR_texture_transform" in _dict(info.get("extensions")):
            self.notes.append(f"{slot}: KHR_texture_transform ignored; the map is taken untransformed")
        from matremap.svbrdf.textures import image_info

        return f, image_info(f, "linear", colour=False).channels

    def colour_file(self, f: Path, n: int) -> tuple[Path, int]:
        """The file to take colour channels from (and its channel count): an alpha-free copy (in the
        cache, so marked extracted) when the image has alpha."""
        if n not in (2, 4):
            return f, n
        copy = _without_alpha(f)
        self.reader.extracted.add(copy)
        return copy, n - 1

    def read_maps(
        self, pbr: dict[str, Any], spec_ext: dict[str, Any], constants: dict[str, Any]
    ) -> dict[str, TextureRef]:
        """The parameters' textures, each scaled by its factor in ``constants``: base colour,
        roughness and metallic (one packed texture), specular and specularColor."""
        textures: dict[str, TextureRef] = {}
        if "baseColorTexture" in pbr:
            raw = self.file(pbr["baseColorTexture"], "baseColorTexture")
            f, n = self.colour_file(*raw)
            rgb = tuple(_channel(c, n) for c in range(3))
            textures["baseColor"] = TextureRef(f, rgb, "srgb", tuple(constants["baseColor"]))
            if raw[1] in (2, 4):
                self.notes.append("baseColorTexture alpha ignored (matremap remaps opaque reflectance)")
        if "metallicRoughnessTexture" in pbr:
            f, n = self.colour_file(*self.file(pbr["metallicRoughnessTexture"], "metallicRoughnessTexture"))
            textures["roughness"] = TextureRef(f, (_channel(1, n),), "linear", constants["roughness"])
            textures["metallic"] = TextureRef(f, (_channel(2, n),), "linear", constants["metallic"])
        if "specularTexture" in spec_ext:
            f, n = self.file(spec_ext["specularTexture"], "specularTexture")
            a = _alpha_channel(n)
            if a is None:
                self.notes.append(
                    "specularTexture has no alpha channel, so it is 1 everywhere; using specularFactor alone"
                )
            else:
                textures["specular"] = TextureRef(f, (a,), "linear", constants["specular"])
        if "specularColorTexture" in spec_ext:
            f, n = self.colour_file(*self.file(spec_ext["specularColorTexture"], "specularColorTexture"))
            rgb = tuple(_channel(c, n) for c in range(3))
            textures["specularColor"] = TextureRef(f, rgb, "srgb", tuple(constants["specularColor"]))
        return textures

    def read_normal(self, m: dict[str, Any]) -> TextureRef | None:
        """The normal map (used as stored: its scale is noted, not applied)."""
        if "normalTexture" not in m:
            return None
        f, _ = self.file(m["normalTexture"], "normalTexture")
        scale = _number(self.reader.path, f"{self.where} normalTexture.scale", m["normalTexture"].get("scale"), 1.0)
        if scale != 1:
            self.notes.append(f"normalTexture scale {scale:g} ignored; the normal map is used as stored (scale 1)")
        return TextureRef(f, None, "linear", 1.0)


def lost_look(ext: dict[str, Any]) -> list[str]:
    """The extensions that carry the material's look and that no matremap model has: mostly transmissive
    (KHR_materials_transmission, factor above 0.5: glass) or a coloured sheen (KHR_materials_sheen:
    velvet). A clear coat (colourless in glTF) only changes the gloss and is noted instead."""
    lost = []
    tr = ext.get("KHR_materials_transmission")
    if isinstance(tr, dict):
        factor = _number(Path("KHR_materials_transmission"), "transmissionFactor", tr.get("transmissionFactor"), 0.0)
        if factor > 0.5 or "transmissionTexture" in tr:
            lost.append(f"KHR_materials_transmission (transmissionFactor {factor:g})")
    sh = ext.get("KHR_materials_sheen")
    if isinstance(sh, dict):
        colour = _number(Path("KHR_materials_sheen"), "sheenColorFactor", sh.get("sheenColorFactor"), [0.0] * 3, 3)
        if max(colour) > 0.5 or "sheenColorTexture" in sh:
            lost.append("KHR_materials_sheen (a coloured sheen)")
    return lost


def _note_unremapped(m: dict[str, Any], ext: dict[str, Any], obj: dict[str, Any], notes: list[str]) -> None:
    """Note the material's inputs matremap leaves alone (a written copy keeps them)."""
    emissive = m.get("emissiveFactor", [0, 0, 0])
    if "emissiveTexture" in m or (isinstance(emissive, list) and any(v != 0 for v in emissive)):
        notes.append("emission (emissiveFactor/emissiveTexture) is not remapped; a written copy keeps it")
    if "occlusionTexture" in m:
        notes.append("occlusionTexture is not remapped; a written copy keeps it")
    mode = m.get("alphaMode", "OPAQUE")
    if mode != "OPAQUE":
        notes.append(f"alphaMode {mode} ignored: matremap remaps the material as opaque")
    for name in sorted(set(ext) - {IOR, SPECULAR}):
        notes.append(
            f"{name} is not remapped (matremap fits the base metallic-roughness layer); a written copy keeps it"
        )
    listed = obj.get("extensionsRequired")
    required = {e for e in (listed if isinstance(listed, list) else []) if isinstance(e, str)} - {IOR, SPECULAR}
    if required:
        notes.append(f"the file requires {', '.join(sorted(required))}; matremap ignores them")


# ---------------------------------------------------------------------------------------------
# writing


def _result_values(result: Any) -> tuple[dict[str, Any], dict[str, np.ndarray], Path | None, list[Path]]:
    """(constants, maps as linear float arrays, normal map file, input files) of a Material or MapSet."""
    from matremap.regress.quantities import material_values
    from matremap.svbrdf.textures import MapSet, read_image

    if isinstance(result, Material):
        model = result.model
    elif isinstance(result, MapSet):
        model = result.model
    else:
        raise MatremapError(f"cannot write {type(result).__name__} as glTF; give a material or a map set")
    if get_model(model).id != MODEL:
        raise MatremapError(
            f"glTF stores {MODEL} materials, and this result is {model}; remap it onto {MODEL} "
            f"first (e.g. matremap remap ... --to {MODEL})"
        )
    spec = get_model(MODEL)
    if isinstance(result, Material):
        return dict(material_values(result)), {}, None, []
    consts: dict[str, Any] = {p.name: p.default_array if p.channels == 3 else p.default for p in spec.params}
    for k, v in result.constants.items():
        if k in spec.param_names:
            consts[k] = v
    maps: dict[str, np.ndarray] = {}
    for name, f in result.maps.items():
        pspec = spec.param(name)
        if name == "ior":
            raise MatremapError(
                f"{f}: {IOR} has no texture, so a map of ior cannot be written to glTF; use a uniform ior"
            )
        img, _ = read_image(f, result.colorspace.get(name), colour=pspec.channels == 3 and pspec.role != "other")
        if pspec.channels == 3:
            img = np.repeat(img[..., :1], 3, axis=-1) if img.shape[-1] == 1 else img[..., :3]
        else:
            img = img[..., 0]
        maps[name] = np.clip(img, *pspec.bounds)
    sizes = {a.shape[:2] for a in maps.values()}
    if len(sizes) > 1:
        raise MatremapError("the maps differ in size; resample them to one size before writing glTF")
    return consts, maps, result.normal, list(result.files)


def _png(array: np.ndarray) -> bytes:
    """8-bit PNG bytes of a uint8 array [H, W, C]."""
    from matremap.core.imageio import png_bytes

    return png_bytes(array)


def _code(values: np.ndarray, srgb: bool) -> np.ndarray:
    v = np.clip(np.asarray(values, dtype=np.float64), 0.0, 1.0)
    if srgb:
        v = linear_to_srgb(v)
    return np.round(v * 255.0).astype(np.uint8)


def _split_factor(a: np.ndarray) -> tuple[np.ndarray, list[float]]:
    """A map [H, W, 3] as (texture in [0, 1], per-channel factor): the factor is 1 unless the map exceeds 1."""
    factor = np.maximum(a.reshape(-1, 3).max(axis=0), 1.0)
    return a / factor, [float(x) for x in factor]


@dataclass
class _NewImage:
    """An encoded texture for one slot of the material, and the source's textureInfo it replaces
    (its sampler, texCoord and transform are kept)."""

    slot: str
    data: bytes
    mime: str
    copy_from: dict[str, Any] | None

    def file_name(self, out: Path) -> str:
        """Its file name beside a .gltf ``out``."""
        return f"{out.stem}_{self.slot}{'.jpg' if self.mime == 'image/jpeg' else '.png'}"


def _uv_sphere(n_lat: int = 16, n_lon: int = 32) -> tuple[dict[str, Any], bytes]:
    """A unit UV sphere (+Y up, counter-clockwise front faces, v down the image) as glTF JSON + buffer."""
    t = np.linspace(0.0, np.pi, n_lat + 1)[:, None]
    ph = np.linspace(0.0, 2.0 * np.pi, n_lon + 1)[None, :]
    pos = np.stack(np.broadcast_arrays(np.sin(t) * np.sin(ph), np.cos(t), np.sin(t) * np.cos(ph)), -1)
    pos = pos.reshape(-1, 3).astype(np.float32)
    uv = np.stack(np.broadcast_arrays(ph / (2 * np.pi), t / np.pi), -1).reshape(-1, 2).astype(np.float32)
    idx = []
    for i in range(n_lat):
        for j in range(n_lon):
            a, b = i * (n_lon + 1) + j, (i + 1) * (n_lon + 1) + j
            c, d = b + 1, a + 1
            if i > 0:
                idx.append((a, b, d))
            if i < n_lat - 1:
                idx.append((d, b, c))
    ind = np.array(idx, dtype=np.uint16).reshape(-1)
    blobs = [pos.tobytes(), pos.tobytes(), uv.tobytes(), ind.tobytes()]
    offsets = np.cumsum([0] + [len(b) for b in blobs])
    views = [
        {"buffer": 0, "byteOffset": int(o), "byteLength": len(b), "target": 34963 if k == 3 else 34962}
        for k, (o, b) in enumerate(zip(offsets, blobs, strict=False))
    ]
    acc = [
        {
            "bufferView": 0,
            "componentType": 5126,
            "count": len(pos),
            "type": "VEC3",
            "min": [float(x) for x in pos.min(axis=0)],
            "max": [float(x) for x in pos.max(axis=0)],
        },
        {"bufferView": 1, "componentType": 5126, "count": len(pos), "type": "VEC3"},
        {"bufferView": 2, "componentType": 5126, "count": len(uv), "type": "VEC2"},
        {"bufferView": 3, "componentType": 5123, "count": len(ind), "type": "SCALAR"},
    ]
    data = b"".join(blobs)
    doc = {
        "asset": {"version": "2.0", "generator": "matremap"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": "probe sphere"}],
        "meshes": [
            {"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2}, "indices": 3, "material": 0}]}
        ],
        "accessors": acc,
        "bufferViews": views,
        "buffers": [{"byteLength": len(data)}],
        "materials": [{}],
    }
    return doc, data


def _rebase(uri: str, src: Path, out_dir: Path) -> str:
    """A relative URI of a file beside the source, as seen from ``out_dir``."""
    if uri.startswith("data:") or "://" in uri:
        return uri
    rel = os.path.relpath(src / unquote(uri), out_dir)
    return quote(rel.replace(os.sep, "/"))


def _rebase_uris(doc: dict[str, Any], src: Path, out_dir: Path) -> None:
    """Rewrite the relative URIs of buffers and images (files beside the source) as seen from ``out_dir``."""
    for key in ("buffers", "images"):
        for item in doc.get(key, []):
            if isinstance(item, dict) and isinstance(item.get("uri"), str):
                item["uri"] = _rebase(item["uri"], src, out_dir)


def _glb(doc: dict[str, Any], bin_data: bytes | None) -> bytes:
    """GLB bytes (§4.4): header, JSON chunk padded with spaces, BIN chunk padded with zeros."""
    text = json.dumps(doc, separators=(",", ":")).encode("utf-8")
    text += b" " * (-len(text) % 4)
    chunks = struct.pack("<II", len(text), CHUNK_JSON) + text
    if bin_data is not None:
        b = bytes(bin_data) + b"\0" * (-len(bin_data) % 4)
        chunks += struct.pack("<II", len(b), CHUNK_BIN) + b
    return struct.pack("<III", GLB_MAGIC, 2, 12 + len(chunks)) + chunks


def _uses_extension(doc: dict[str, Any], name: str) -> bool:
    return any(isinstance(m, dict) and name in (m.get("extensions") or {}) for m in doc.get("materials", []))


@dataclass
class _Target:
    """The glTF being written, before the new material goes in: its JSON, the bytes of buffer 0
    when it is binary (a GLB's BIN chunk or the buffer a new file writes; None otherwise), the folder
    the source's relative URIs resolve against (None for a new file), the material's index, and the
    source's files (never to be overwritten)."""

    json: dict[str, Any]
    bin: bytes | None
    base: Path | None
    index: int
    inputs: list[Path]

    @classmethod
    def of(cls, source: MaterialAsset | None) -> _Target:
        """A copy of the glTF ``source``'s document, or a UV sphere (material named after any other source)."""
        gdoc = source.document if source is not None and isinstance(source.document, GltfDocument) else None
        if source is None or gdoc is None:
            doc, bin_data = _uv_sphere()
            if source is not None:
                doc["materials"][0]["name"] = source.name
            return cls(doc, bin_data, None, 0, [])
        doc = copy.deepcopy(gdoc.json)
        _check_writable_source(source.path, doc, source.index)
        inputs = [
            source.path,
            *(t.path for t in source.textures.values()),
            *([source.normal.path] if source.normal else []),
        ]
        for key in ("buffers", "images"):
            for item in doc.get(key, []):
                uri = item.get("uri") if isinstance(item, dict) else None
                if isinstance(uri, str) and not uri.startswith("data:") and "://" not in uri:
                    inputs.append(gdoc.base / unquote(uri))
        return cls(doc, gdoc.bin, gdoc.base, source.index, inputs)


def _base_colour_image(pbr: dict[str, Any], consts: dict[str, Any], maps: dict[str, np.ndarray]) -> _NewImage | None:
    """Set baseColorFactor (keeping its alpha); the sRGB texture of a base colour map, if any."""
    old = pbr.pop("baseColorTexture", None)
    alpha = float((pbr.get("baseColorFactor") or [1, 1, 1, 1])[3])
    if "baseColor" not in maps:
        pbr["baseColorFactor"] = [*(float(x) for x in np.broadcast_to(consts["baseColor"], (3,))), alpha]
        return None
    tex, factor = _split_factor(maps["baseColor"])
    pbr["baseColorFactor"] = [*factor, alpha]
    return _NewImage("baseColor", _png(_code(tex, True)), "image/png", old)


def _metallic_roughness_image(
    pbr: dict[str, Any], consts: dict[str, Any], maps: dict[str, np.ndarray]
) -> _NewImage | None:
    """Set roughnessFactor and metallicFactor (1 where a map carries the values); roughness and
    metallic maps packed into the G and B channels of one linear texture (§3.9.2), if any."""
    old = pbr.pop("metallicRoughnessTexture", None)
    image = None
    if "roughness" in maps or "metallic" in maps:
        shape = next(a.shape[:2] for k, a in maps.items() if k in ("roughness", "metallic"))
        packed = np.ones((*shape, 3))
        for k, c in (("roughness", 1), ("metallic", 2)):
            if k in maps:
                packed[..., c] = maps[k]
        image = _NewImage("metallicRoughness", _png(_code(packed, False)), "image/png", old)
    for k in ("roughness", "metallic"):
        pbr[f"{k}Factor"] = 1.0 if k in maps else float(np.asarray(consts[k]).reshape(-1)[0])
    return image


def _specular_image(
    consts: dict[str, Any], maps: dict[str, np.ndarray], old: dict[str, Any]
) -> tuple[dict[str, Any], _NewImage | None]:
    """KHR_materials_specular's factors ({} when they and the maps are at the defaults) and one
    texture holding specularColor (sRGB RGB) and specular (alpha), if either is a map. ``old``: the
    source's extension object."""
    spec_f = 1.0 if "specular" in maps else float(np.asarray(consts["specular"]).reshape(-1)[0])
    tint_tex: np.ndarray | None = None
    if "specularColor" in maps:
        tint_tex, tint_f = _split_factor(maps["specularColor"])
    else:
        tint_f = [float(x) for x in np.broadcast_to(consts["specularColor"], (3,))]
    image = None
    if "specular" in maps or tint_tex is not None:
        shape = next(a.shape[:2] for k, a in maps.items() if k in ("specular", "specularColor"))
        rgba = np.full((*shape, 4), 255, dtype=np.uint8)
        if tint_tex is not None:
            rgba[..., :3] = _code(tint_tex, True)
        if "specular" in maps:
            rgba[..., 3] = _code(maps["specular"], False)
        else:
            rgba = rgba[..., :3]
        copy_from = old.get("specularColorTexture") or old.get("specularTexture")
        image = _NewImage("specular", _png(rgba), "image/png", copy_from)
    if spec_f != 1.0 or any(v != 1.0 for v in tint_f) or "specular" in maps or tint_tex is not None:
        return {"specularFactor": spec_f, "specularColorFactor": tint_f}, image
    return {}, image


def _normal_image(mat: dict[str, Any], normal: Path | None, source: MaterialAsset | None) -> _NewImage | None:
    """The result's normal map as a texture (a PNG or JPEG file as it is, anything else encoded as
    PNG), unless it is the source's own (which the copy keeps)."""
    if normal is None:
        return None
    if source is not None and source.normal is not None and Path(normal).resolve() == source.normal.path.resolve():
        return None
    old = mat.pop("normalTexture", None)
    suffix = Path(normal).suffix.lower()
    if suffix in (".png", ".jpg", ".jpeg"):
        return _NewImage("normal", Path(normal).read_bytes(), "image/png" if suffix == ".png" else "image/jpeg", old)
    from matremap.svbrdf.textures import read_image

    image, _ = read_image(normal, "linear", colour=False)
    return _NewImage("normal", _png(_code(image[..., :3], False)), "image/png", old)


def _refuse_overwrites(out: Path, planned: list[Path], inputs: list[Path], force: bool) -> None:
    """Refuse to write any ``planned`` file over an input (even with ``force``) or, without
    ``force``, over an existing file."""
    inputs_resolved = {Path(f).resolve() for f in inputs}
    for f in planned:
        if f.resolve() in inputs_resolved:
            raise MatremapError(f"writing {out} would overwrite the input {f}; choose another output name")
        if f != out:
            check_output(f, force)


def _check_writable_source(path: Path, doc: dict[str, Any], index: int) -> None:
    """Refuse a source document whose parts the writer edits have the wrong JSON types (the reader
    looks only at the material it reads); null arrays are dropped, empty or null material members
    become empty objects."""
    for key in ("buffers", "bufferViews", "images", "textures", "extensionsUsed", "extensionsRequired"):
        if key in doc and doc[key] is None:
            del doc[key]
        if key in doc and not isinstance(doc[key], list):
            raise MatremapError(f"{path}: {key} is not an array; the file is broken, re-export it")
    for key in ("buffers", "bufferViews", "images", "textures"):
        if not all(isinstance(x, dict) for x in doc.get(key, [])):
            raise MatremapError(f"{path}: an item of {key} is not an object; the file is broken, re-export it")
    if not all(_index(bv.get("buffer")) for bv in doc.get("bufferViews", [])):
        raise MatremapError(f"{path}: a bufferView has no valid buffer index; the file is broken, re-export it")
    for key in ("extensionsUsed", "extensionsRequired"):
        if key in doc:
            doc[key] = [e for e in doc[key] if isinstance(e, str)]
    mat = doc["materials"][index]
    for key in ("pbrMetallicRoughness", "extensions"):
        if not mat.get(key):
            mat[key] = {}
        elif not isinstance(mat[key], dict):
            raise MatremapError(f"{path}: materials[{index}].{key} is not an object; re-export the file")


def _add_bin_buffer(doc: dict[str, Any]) -> bytes:
    """Insert an empty buffer 0 (a GLB's BIN chunk) and shift every buffer view's buffer index."""
    doc.setdefault("buffers", []).insert(0, {"byteLength": 0})
    for bv in doc.get("bufferViews", []):
        bv["buffer"] += 1
        meshopt = _dict(bv.get("extensions")).get("EXT_meshopt_compression")
        if isinstance(meshopt, dict) and "buffer" in meshopt:
            meshopt["buffer"] += 1
    return b""


def _add_images(
    doc: dict[str, Any], new: list[_NewImage], out: Path, blob: bytearray | None, files: AtomicFiles
) -> dict[str, dict[str, Any]]:
    """Add the new images (appended to ``blob`` as buffer views of buffer 0 for a .glb, staged as
    files beside a .gltf, where ``blob`` is None) and their textures; returns the textureInfo of each
    slot, which keeps the sampler, UV set and transform of the texture it replaces."""
    images = doc.setdefault("images", [])
    textures = doc.setdefault("textures", [])
    infos: dict[str, dict[str, Any]] = {}
    for im in new:
        image: dict[str, Any] = {"name": f"{out.stem}_{im.slot}"}
        if blob is not None:
            blob += b"\0" * (-len(blob) % 4)
            doc.setdefault("bufferViews", []).append({"buffer": 0, "byteOffset": len(blob), "byteLength": len(im.data)})
            blob += im.data
            image.update(bufferView=len(doc["bufferViews"]) - 1, mimeType=im.mime)
        else:
            image["uri"] = quote(im.file_name(out))
            files.write_bytes(out.parent / im.file_name(out), im.data)
        images.append(image)
        texture: dict[str, Any] = {"source": len(images) - 1}
        info: dict[str, Any] = {"index": len(textures)}
        if isinstance(im.copy_from, dict):
            old = im.copy_from.get("index")
            old_tex = textures[old] if isinstance(old, int) and 0 <= old < len(textures) else {}
            if isinstance(old_tex, dict) and "sampler" in old_tex:
                texture["sampler"] = old_tex["sampler"]
            info.update({k: v for k, v in im.copy_from.items() if k != "index"})
        textures.append(texture)
        infos[im.slot] = info
    if not images:
        doc.pop("images")
    if not textures:
        doc.pop("textures")
    return infos


def _set_material(
    mat: dict[str, Any],
    consts: dict[str, Any],
    maps: dict[str, np.ndarray],
    spec_ext: dict[str, Any],
    infos: dict[str, dict[str, Any]],
) -> None:
    """Point the material at its new textures and set (or drop, at their defaults) its extensions."""
    pbr, exts = mat["pbrMetallicRoughness"], mat["extensions"]
    if "baseColor" in infos:
        pbr["baseColorTexture"] = infos["baseColor"]
    if "metallicRoughness" in infos:
        pbr["metallicRoughnessTexture"] = {k: v for k, v in infos["metallicRoughness"].items() if k != "strength"}
    if "normal" in infos:
        mat["normalTexture"] = infos["normal"]
    ior = float(np.asarray(consts["ior"]).reshape(-1)[0])
    if abs(ior - DEFAULT_IOR) > 1e-6:
        exts[IOR] = {"ior": ior}
    else:
        exts.pop(IOR, None)
    if spec_ext:
        if "specular" in infos:
            slot = {k: v for k, v in infos["specular"].items() if k != "scale"}
            if "specular" in maps:
                spec_ext["specularTexture"] = dict(slot)
            if "specularColor" in maps:
                spec_ext["specularColorTexture"] = dict(slot)
        exts[SPECULAR] = spec_ext
    else:
        exts.pop(SPECULAR, None)
    if not exts:
        mat.pop("extensions")


def _update_extension_lists(doc: dict[str, Any]) -> None:
    """extensionsUsed / extensionsRequired as the materials now use IOR and SPECULAR."""
    used = [e for e in doc.get("extensionsUsed", []) if e not in (IOR, SPECULAR)]
    used += [e for e in (IOR, SPECULAR) if _uses_extension(doc, e)]
    if used:
        doc["extensionsUsed"] = used
    else:
        doc.pop("extensionsUsed", None)
    if "extensionsRequired" in doc:
        doc["extensionsRequired"] = [e for e in doc["extensionsRequired"] if e in used]
        if not doc["extensionsRequired"]:
            doc.pop("extensionsRequired")


def write(out: str | os.PathLike, result: Any, source: MaterialAsset | None = None, force: bool = False) -> Path:
    """Write ``result`` (a ``gltf:metal-rough`` Material or MapSet) as ``out`` (.gltf or .glb).

    With a glTF ``source``: a copy of the source file (as ``out``'s kind) with its material replaced.
    Factors carry the uniform values; maps become new textures (PNG files beside a .gltf, buffer views
    in the BIN chunk of a .glb): baseColor (sRGB), roughness and metallic packed into one
    metallicRoughnessTexture (G and B, §3.9.2), specular (alpha) and specularColor (sRGB RGB) of
    KHR_materials_specular. KHR_materials_ior / KHR_materials_specular are written only where they
    differ from their defaults. The source's normal, occlusion and emissive textures are kept unless
    the result brings a normal map. Without a glTF source, the material is written on a UV sphere.

    The file and the files beside it (textures, ``.bin``) are written together or not at all;
    existing files are replaced only with ``force``, and input files never.
    """
    out = Path(out)
    kind = out.suffix.lower()
    if kind not in (".gltf", ".glb"):
        raise MatremapError(f"cannot write {out} as glTF: name it .gltf or .glb")
    consts, maps, normal, inputs = _result_values(result)
    check_output(out, force)
    target = _Target.of(source)
    doc = target.json
    mat = doc["materials"][target.index]
    pbr = mat.setdefault("pbrMetallicRoughness", {})
    old_spec = dict(mat.setdefault("extensions", {}).get(SPECULAR) or {})
    # the new textures, encoded in memory before anything is written
    base_image = _base_colour_image(pbr, consts, maps)
    mr_image = _metallic_roughness_image(pbr, consts, maps)
    spec_ext, spec_image = _specular_image(consts, maps, old_spec)
    normal_image = _normal_image(mat, normal, source)
    images = [im for im in (base_image, mr_image, spec_image, normal_image) if im is not None]
    bin_file = out.parent / f"{out.stem}.bin"
    planned = [out]
    if kind == ".gltf":
        planned += [out.parent / im.file_name(out) for im in images]
        planned += [bin_file] if target.bin is not None else []
    _refuse_overwrites(out, planned, [*inputs, *target.inputs], force)

    if target.base is not None and target.base.resolve() != out.parent.resolve():
        _rebase_uris(doc, target.base, out.parent)
    if kind == ".glb" and images and target.bin is None:
        target.bin = _add_bin_buffer(doc)
    blob = bytearray(target.bin or b"")
    with AtomicFiles(force) as files:
        infos = _add_images(doc, images, out, blob if kind == ".glb" else None, files)
        if target.bin is not None:
            doc["buffers"][0]["byteLength"] = len(blob)
            if kind == ".gltf":
                doc["buffers"][0]["uri"] = quote(bin_file.name)
                files.write_bytes(bin_file, bytes(blob))
            else:
                doc["buffers"][0].pop("uri", None)
        _set_material(mat, consts, maps, spec_ext, infos)
        _update_extension_lists(doc)
        if kind == ".glb":
            files.write_bytes(out, _glb(doc, bytes(blob) if target.bin is not None else None))
        else:
            files.write_bytes(out, (json.dumps(doc, indent=1) + "\n").encode("utf-8"))
    return out


__all__ = ["GltfDocument", "read", "write"]
