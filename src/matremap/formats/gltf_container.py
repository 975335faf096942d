"""The glTF 2.0 container: ``.gltf`` JSON and ``.glb`` binary, their buffers and images, read safely.

References are to the glTF 2.0 specification (Khronos, version 2.0.1, 2021):

* §3.6 "Binary Data Storage" (buffers, buffer views, ``data:`` URIs), §3.8 "Texture Data" (images);
* §4 "GLB File Format Specification": a 12-byte header (magic ``glTF``, version 2, length), a JSON
  chunk padded with spaces and an optional BIN chunk padded with zeros, all 4-byte aligned; the
  BIN chunk is the buffer with index 0 that has no ``uri``.

Images stored inside the file (buffer views, ``data:`` URIs) are extracted once to a cache folder,
``<cache>/gltf-images/<hash of the file>`` of matremap's private cache (:func:`matremap.core.diskcache.cache_dir`),
named by their content's digest and checked against it when reused, so that every texture has a real path.

The file is untrusted: external URIs must resolve inside the file's folder or a folder the user allowed
(:mod:`matremap.formats.confine`), a GLB's chunks and buffer views must lie inside the file and their
offsets be non-negative integers, ``data:`` URIs must be valid base64, and the JSON may nest at most
:data:`MAX_JSON_DEPTH` levels and hold at most :data:`MAX_JSON_VALUES` values (its memory); anything else is refused
with one line.
"""

from __future__ import annotations

import base64
import binascii
import hashlib
import json
import re
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from urllib.parse import unquote, unquote_to_bytes

from matremap.core.imageio import atomic_output
from matremap.errors import MatremapError, not_a_file
from matremap.formats.confine import Confinement, resolve_reference

#: GLB (§4.4): magic "glTF", chunk types "JSON" and "BIN\0"
GLB_MAGIC = 0x46546C67
CHUNK_JSON = 0x4E4F534A
CHUNK_BIN = 0x004E4942
#: the deepest JSON nesting read (glTF files nest about ten levels; deeper is an attack or a broken file)
MAX_JSON_DEPTH = 100
#: the most JSON values a glTF's JSON may hold, counted from its text before it is parsed (its commas and opening
#: brackets: an upper bound). Parsed, a value takes 30 to 120 bytes (a number in an array, an object of one
#: member), so this bounds the document's memory to about a gigabyte; a glTF keeps its bulk in binary buffers
#: (200,000 nodes are about 4 million values)
MAX_JSON_VALUES = 1 << 23
MIME_SUFFIX = {"image/png": ".png", "image/jpeg": ".jpg", "image/webp": ".webp", "image/ktx2": ".ktx2"}


@dataclass
class GltfDocument:
    """What a reader parsed: the JSON, the GLB BIN chunk (None for a ``.gltf``), whether the file was
    binary, the folder its relative URIs resolve against, and what the reader found of its material."""

    json: dict[str, Any]
    bin: bytes | None
    binary: bool
    base: Path
    #: the read material's validated extensions (:func:`matremap.formats.gltf_extensions.read_extensions`)
    extensions: dict[str, dict[str, Any]] = field(default_factory=dict)
    #: the UV set (TEXCOORD_n) of the read material's remapped textures
    uv_set: int = 0


# ---------------------------------------------------------------------------------------------
# parsing


def parse_container(path: Path, data: bytes) -> tuple[dict[str, Any], bytes | None]:
    """The JSON object and the BIN chunk of a .glb or .gltf file's bytes (§4.4, §3.1)."""
    suffix = path.suffix.lower()
    if suffix == ".glb":
        text, bin_chunk = glb_chunks(path, data)
    elif suffix == ".gltf":
        if data[:4] == b"glTF":
            raise MatremapError(f"{path} is a binary glTF (GLB), not JSON; rename it to .glb")
        text, bin_chunk = data, None
    else:
        raise MatremapError(f"{path}: a glTF file ends in .gltf or .glb, not {suffix or 'nothing'}")
    values = text.count(b",") + text.count(b"[") + text.count(b"{")
    if values > MAX_JSON_VALUES:
        raise MatremapError(
            f"{path}: its JSON holds about {values:,} values, more than the {MAX_JSON_VALUES:,} matremap reads; "
            f"a glTF keeps its bulk in binary buffers: move large data (extras) out of the JSON or into a buffer"
        )
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
    if obj is None or too_deep(obj):
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


def too_deep(obj: Any) -> bool:
    """Whether JSON value ``obj`` nests more than :data:`MAX_JSON_DEPTH` arrays/objects (walked
    without recursion)."""
    level: list[Any] = [obj]
    for _ in range(MAX_JSON_DEPTH + 1):
        level = [v for x in level for v in (x.values() if isinstance(x, dict) else x if isinstance(x, list) else ())]
        level = [v for v in level if isinstance(v, dict | list)]
        if not level:
            return False
    return True


def glb_chunks(path: Path, data: bytes) -> tuple[bytes, bytes | None]:
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


def cache_dir(data: bytes | Path) -> Path:
    """The folder of a file's extracted images in matremap's private cache (created 0700, refused when
    another user owns it or others may write to it), never in a shared temporary folder; ``data`` is the file's
    content, or the file (hashed in blocks)."""
    from matremap.core.diskcache import private_cache_dir

    digest = file_digest(data) if isinstance(data, Path) else hashlib.sha256(data).hexdigest()
    return private_cache_dir("gltf-images", digest[:20])


def file_digest(f: Path) -> str:
    """The SHA-256 of a file's content (hex), read in blocks: memory does not grow with the file."""
    with open(f, "rb") as data:
        return hashlib.file_digest(data, "sha256").hexdigest()


def digest_matches(f: Path, digest: str) -> bool:
    """Whether cache file ``f`` is a regular file whose content has ``digest`` (a prefix of its SHA-256)."""
    return f.is_file() and not f.is_symlink() and file_digest(f)[: len(digest)] == digest


def cached_copy(folder: Path, stem: str, suffix: str, data: bytes) -> Path:
    """``data`` stored under a name that carries its digest; an existing file is reused only when its
    content still has that digest (an edited or truncated cache file is written again)."""
    digest = hashlib.sha256(data).hexdigest()[:16]
    f = folder / f"{stem}-{digest}{suffix}"
    if not digest_matches(f, digest):
        with atomic_output(f) as tmp, open(tmp, "wb") as out:
            out.write(data)
    return f


def data_uri(path: Path, uri: str, what: str) -> tuple[str, bytes]:
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


def sniff(data: bytes) -> str:
    if data[:8] == b"\x89PNG\r\n\x1a\n":
        return ".png"
    if data[:3] == b"\xff\xd8\xff":
        return ".jpg"
    if data[:4] == b"RIFF" and data[8:12] == b"WEBP":
        return ".webp"
    return ".bin"


def is_index(value: Any) -> bool:
    """Whether a JSON value is a valid index or count (a non-negative integer, not a boolean)."""
    return isinstance(value, int) and not isinstance(value, bool) and value >= 0


class FileReader:
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
        if not is_index(index) or not index < n:
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
            data = data_uri(self.path, uri, f"buffers[{index}]")[1]
        else:
            f = self.external(uri, f"buffer {index} uri")
            if not f.is_file() and f.exists():
                raise MatremapError(f"{self.path}: {not_a_file(f, f'buffer file {uri!r}')}")
            if not f.is_file():
                raise MatremapError(
                    f"{self.path}: buffer file {uri!r} not found at {f}; put it beside {self.path.name} or fix its uri"
                )
            data = f.read_bytes()
        need = buf.get("byteLength", 0)
        if not is_index(need):
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
            if not is_index(value):
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
            if not f.is_file() and f.exists():
                raise MatremapError(f"{self.path}: {not_a_file(f, f'image {uri!r} ({where})')}")
            if not f.is_file():
                raise MatremapError(
                    f"{self.path}: image {uri!r} ({where}) not found at {f}; put it beside "
                    f"{self.path.name} or fix its uri"
                )
            self._images[index] = f
            return f
        if uri is not None:
            mime, data = data_uri(self.path, uri, f"images[{index}]")
        elif "bufferView" in img:
            mime, data = img.get("mimeType", ""), self.buffer_view(img["bufferView"], f"images[{index}]")
        else:
            raise MatremapError(f"{self.path}: images[{index}] has neither a uri nor a bufferView; re-export the file")
        suffix = (MIME_SUFFIX.get(mime) if isinstance(mime, str) else None) or sniff(data)
        f = cached_copy(cache_dir(self.data), f"image{index}", suffix, data)
        self._images[index] = f
        self.extracted.add(f)
        return f
