"""The glTF being written: a copy of the source (or spheres), new textures added, unused ones dropped.

References: glTF 2.0 (Khronos, 2.0.1) §3.6 (buffers and buffer views; a GLB's buffer 0 is its BIN chunk),
§3.6.2.4 (data alignment: views start on 4 bytes here, so every accessor stays aligned), §3.8 (images,
textures, samplers; ``textureInfo``: ``index``, ``texCoord``, extensions), §3.12 "Extensions"
(``extensionsUsed`` lists every extension the file uses, ``extensionsRequired`` a subset of it), §4.4 (GLB).

A copy keeps everything the converted materials do not own: meshes, nodes, animations, skins, cameras,
samplers, other materials and their textures, texture transforms and extensions. A texture a replaced
material used and that nothing in the file refers to any more is dropped with its image (and, in a GLB, the
image's bytes), and every index into ``textures``, ``images`` and ``bufferViews`` is renumbered; geometry
bytes move only as a whole view, so accessors read the same values.
"""

from __future__ import annotations

import json
import os
import struct
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from urllib.parse import quote, unquote

import numpy as np

from matremap.core.atomic import AtomicFiles
from matremap.core.imageio import check_output
from matremap.errors import MatremapError
from matremap.formats.asset import CarriedInput, TextureRef
from matremap.formats.gltf_container import CHUNK_BIN, CHUNK_JSON, GLB_MAGIC, GltfDocument, is_index
from matremap.formats.gltf_extensions import EMISSIVE_STRENGTH, IOR, SPEC_GLOSS, SPECULAR
from matremap.formats.gltf_mesh import spheres_document
from matremap.formats.gltf_textures import TRANSFORM, as_dict

#: the extensions the writer adds or removes (the others are kept as the source lists them)
MANAGED = (IOR, SPECULAR, EMISSIVE_STRENGTH, TRANSFORM, SPEC_GLOSS)


@dataclass
class NewImage:
    """An encoded texture for one slot of material ``material``, and the source's textureInfo it replaces
    (its sampler and extensions are kept, except a transform: the maps are baked)."""

    slot: str
    data: bytes
    mime: str
    copy_from: dict[str, Any] | None
    material: int = 0
    stem: str = ""

    def file_name(self, out: Path) -> str:
        """Its file name beside a .gltf ``out``."""
        return f"{out.stem}{self.stem}_{self.slot}{'.jpg' if self.mime == 'image/jpeg' else '.png'}"


@dataclass
class Replacement:
    """One material to replace: its index, the result's constants (a ``gltf:pbr`` result's include its layers),
    maps and normal map file, what it carries (``copied``: the material is a copy of the glTF it came from,
    which keeps its own emission and occlusion), the source's normal map and the UV set its maps are on."""

    index: int
    consts: dict[str, Any]
    maps: dict[str, np.ndarray]
    normal: Path | None
    carried: dict[str, CarriedInput]
    copied: bool
    source_normal: TextureRef | None
    uv_set: int = 0
    spec_ext: dict[str, Any] = field(default_factory=dict)
    old_spec: dict[str, Any] = field(default_factory=dict)
    #: the copied material was read into gltf:pbr (its coat or sheen fitted): a gltf:metal-rough result absorbed
    #: them, so the copy drops those extensions instead of keeping them over the new base
    source_layered: bool = False


@dataclass
class Target:
    """The glTF being written, before the new materials go in: its JSON, the bytes of buffer 0 when it is
    binary (a GLB's BIN chunk or the spheres' buffer; None otherwise), the folder the source's relative
    URIs resolve against (None for a new file), and the source's files (never to be overwritten)."""

    json: dict[str, Any]
    bin: bytes | None
    base: Path | None
    inputs: list[Path]

    @classmethod
    def copy_of(cls, path: Path, gdoc: GltfDocument, inputs: list[Path]) -> Target:
        """A copy of the document ``gdoc`` read from ``path``."""
        doc = editable_copy(gdoc.json)
        files = [path, *inputs]
        for key in ("buffers", "images"):
            for item in doc.get(key) or []:
                uri = item.get("uri") if isinstance(item, dict) else None
                if isinstance(uri, str) and not uri.startswith("data:") and "://" not in uri:
                    files.append(gdoc.base / unquote(uri))
        return cls(doc, gdoc.bin, gdoc.base, files)

    @classmethod
    def spheres(cls, names: list[str]) -> Target:
        """A new file: one UV sphere per material (named ``names``)."""
        doc, data = spheres_document(names)
        return cls(doc, data, None, [])


def editable_copy(node: Any) -> Any:
    """A copy of JSON value ``node`` the writer may edit, sharing what it never edits: every ``extras`` value
    (application data, glTF §3.12: carried as it is, never looked into) and every non-empty array of plain values
    (numbers, strings: the writer replaces such arrays, never changes them). A document's size in memory is then held
    once however large its extras or its accessors' arrays."""
    if isinstance(node, dict):
        return {k: (v if k == "extras" else editable_copy(v)) for k, v in node.items()}
    if isinstance(node, list):
        if node and not any(isinstance(v, dict | list) for v in node):
            return node
        return [editable_copy(v) for v in node]
    return node


def texture_infos(node: Any, key: str = "") -> Iterator[dict[str, Any]]:
    """Every textureInfo under ``node``: an object with an ``index`` held under a key ending in
    ``Texture`` (the core's and every KHR material extension's naming); ``extras`` (application data) are not
    glTF's references and are not looked into."""
    if isinstance(node, dict):
        if key.endswith(("Texture", "texture")) and "index" in node:
            yield node
        for k, v in node.items():
            if k != "extras":
                yield from texture_infos(v, k)
    elif isinstance(node, list):
        for v in node:
            yield from texture_infos(v, key)


def material_textures(mat: Any) -> set[int]:
    """The texture indices a material uses."""
    return {i["index"] for i in texture_infos(mat) if is_index(i["index"])}


def check_writable_source(path: Path, doc: dict[str, Any], indices: list[int]) -> None:
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
    if not all(is_index(bv.get("buffer")) for bv in doc.get("bufferViews", [])):
        raise MatremapError(f"{path}: a bufferView has no valid buffer index; the file is broken, re-export it")
    for key in ("extensionsUsed", "extensionsRequired"):
        if key in doc:
            doc[key] = [e for e in doc[key] if isinstance(e, str)]
    for index in indices:
        mat = doc["materials"][index]
        for key in ("pbrMetallicRoughness", "extensions"):
            if not mat.get(key):
                mat[key] = {}
            elif not isinstance(mat[key], dict):
                raise MatremapError(f"{path}: materials[{index}].{key} is not an object; re-export the file")


def refuse_overwrites(out: Path, planned: list[Path], inputs: list[Path], force: bool) -> None:
    """Refuse to write any ``planned`` file over an input (even with ``force``) or, without
    ``force``, over an existing file."""
    inputs_resolved = {Path(f).resolve() for f in inputs}
    for f in planned:
        if f.resolve() in inputs_resolved:
            raise MatremapError(f"writing {out} would overwrite the input {f}; choose another output name")
        if f != out:
            check_output(f, force)


def confine_uris(doc: dict[str, Any], src: Path, where: Path) -> None:
    """Refuse a copy of a source whose buffers or images (not only the converted materials' textures, which the
    reader confined) name a file outside ``src`` (the source's folder) and the allowed folders."""
    from matremap.formats.confine import resolve_reference

    for key in ("buffers", "images"):
        for i, item in enumerate(doc.get(key, [])):
            uri = item.get("uri") if isinstance(item, dict) else None
            if isinstance(uri, str) and not uri.startswith("data:") and "://" not in uri:
                resolve_reference(unquote(uri), src, f"{where}: {key[:-1]} {i} uri")


def rebase_uris(doc: dict[str, Any], src: Path, out_dir: Path) -> None:
    """Rewrite the relative URIs of buffers and images (files beside the source) as seen from ``out_dir``."""
    for key in ("buffers", "images"):
        for item in doc.get(key, []):
            uri = item.get("uri") if isinstance(item, dict) else None
            if isinstance(uri, str) and not uri.startswith("data:") and "://" not in uri:
                rel = os.path.relpath(src / unquote(uri), out_dir)
                item["uri"] = quote(rel.replace(os.sep, "/"))


def add_bin_buffer(doc: dict[str, Any]) -> bytes:
    """Insert an empty buffer 0 (a GLB's BIN chunk) and shift every buffer view's buffer index."""
    doc.setdefault("buffers", []).insert(0, {"byteLength": 0})
    for bv in doc.get("bufferViews", []):
        bv["buffer"] += 1
        meshopt = as_dict(bv.get("extensions")).get("EXT_meshopt_compression")
        if isinstance(meshopt, dict) and "buffer" in meshopt:
            meshopt["buffer"] += 1
    return b""


def new_info(im: NewImage, index: int, uv_set: int, textures: list[dict[str, Any]]) -> tuple[dict, dict]:
    """(the texture, the textureInfo) of a new image: the replaced texture's sampler and the replaced
    textureInfo's members kept, except its transform (the maps are baked) and UV set (the maps')."""
    texture: dict[str, Any] = {"source": index}
    info: dict[str, Any] = {}
    if isinstance(im.copy_from, dict):
        old = im.copy_from.get("index")
        old_tex = textures[old] if isinstance(old, int) and 0 <= old < len(textures) else {}
        if isinstance(old_tex, dict) and "sampler" in old_tex:
            texture["sampler"] = old_tex["sampler"]
        for k, v in im.copy_from.items():
            if k == "extensions":
                kept = {n: e for n, e in as_dict(v).items() if n != TRANSFORM}
                if kept:
                    info[k] = kept
            elif k not in ("index", "texCoord"):
                info[k] = v
    if uv_set:
        info["texCoord"] = uv_set
    return texture, info


def add_images(
    doc: dict[str, Any],
    new: list[NewImage],
    out: Path,
    blob: bytearray | None,
    files: AtomicFiles,
    uv_sets: dict[int, int],
) -> dict[int, dict[str, dict[str, Any]]]:
    """Add the new images (appended to ``blob`` as buffer views of buffer 0 for a .glb, staged as
    files beside a .gltf, where ``blob`` is None) and their textures; returns the textureInfo of each
    material's slots."""
    images = doc.setdefault("images", [])
    textures = doc.setdefault("textures", [])
    infos: dict[int, dict[str, dict[str, Any]]] = {}
    for im in new:
        image: dict[str, Any] = {"name": f"{out.stem}{im.stem}_{im.slot}"}
        if blob is not None:
            blob += b"\0" * (-len(blob) % 4)
            doc.setdefault("bufferViews", []).append({"buffer": 0, "byteOffset": len(blob), "byteLength": len(im.data)})
            blob += im.data
            image.update(bufferView=len(doc["bufferViews"]) - 1, mimeType=im.mime)
        else:
            image["uri"] = quote(im.file_name(out))
            files.write_bytes(out.parent / im.file_name(out), im.data)
        images.append(image)
        texture, info = new_info(im, len(images) - 1, uv_sets.get(im.material, 0), textures)
        info = {"index": len(textures), **info}
        textures.append(texture)
        infos.setdefault(im.material, {})[im.slot] = info
    for key in ("images", "textures"):
        if not doc[key]:
            doc.pop(key)
    return infos


def _renumber(kept: list[int]) -> dict[int, int]:
    return {old: new for new, old in enumerate(kept)}


def drop_unused(doc: dict[str, Any], candidates: set[int], blob: bytearray | None) -> bytearray | None:
    """Drop the textures among ``candidates`` nothing refers to any more, the images only they used, and
    those images' buffer views (their bytes cut out of ``blob``, buffer 0, when it is given); renumber
    every reference. Returns the new buffer 0 bytes (or None)."""
    textures, images, views = doc.get("textures", []), doc.get("images", []), doc.get("bufferViews", [])
    dropped = {t for t in candidates if t < len(textures)} - material_textures(doc)
    if not dropped:
        return blob
    keep_t = [i for i in range(len(textures)) if i not in dropped]
    tmap = _renumber(keep_t)
    for info in texture_infos(doc):
        if is_index(info["index"]) and info["index"] in tmap:
            info["index"] = tmap[info["index"]]
    doc["textures"] = [textures[i] for i in keep_t]

    def sources(tex: dict[str, Any]) -> list[Any]:
        return [tex.get("source")] + [as_dict(e).get("source") for e in as_dict(tex.get("extensions")).values()]

    used_images = {s for t in doc["textures"] for s in sources(t) if is_index(s)}
    if "EXT_lights_image_based" in as_dict(doc.get("extensions")):
        used_images |= set(range(len(images)))  # its image references are not textures: keep every image
    gone = {s for t in dropped for s in sources(textures[t]) if is_index(s) and s < len(images)} - used_images
    keep_i = [i for i in range(len(images)) if i not in gone]
    imap = _renumber(keep_i)
    for tex in doc["textures"]:
        for holder in [tex, *(e for e in as_dict(tex.get("extensions")).values() if isinstance(e, dict))]:
            if is_index(holder.get("source")) and holder["source"] in imap:
                holder["source"] = imap[holder["source"]]
    doc["images"] = [images[i] for i in keep_i]
    views_gone = {images[i].get("bufferView") for i in gone} - {v for v in _view_refs(doc) if is_index(v)}
    views_gone = {v for v in views_gone if is_index(v) and v < len(views)}
    for key in ("textures", "images"):
        if not doc[key]:
            doc.pop(key)
    return _drop_views(doc, views_gone, blob) if views_gone else blob


def _view_refs(node: Any) -> Iterator[Any]:
    if isinstance(node, dict):
        for k, v in node.items():
            if k == "bufferView":
                yield v
            elif k != "extras":
                yield from _view_refs(v)
    elif isinstance(node, list):
        for v in node:
            yield from _view_refs(v)


def _set_view_refs(node: Any, vmap: dict[int, int]) -> None:
    if isinstance(node, dict):
        for k, v in node.items():
            if k == "bufferView" and is_index(v) and v in vmap:
                node[k] = vmap[v]
            elif k != "extras":
                _set_view_refs(v, vmap)
    elif isinstance(node, list):
        for v in node:
            _set_view_refs(v, vmap)


def _drop_views(doc: dict[str, Any], gone: set[int], blob: bytearray | None) -> bytearray | None:
    """Remove buffer views ``gone``; cut their bytes (whole multiples of 4, where no kept view overlaps
    them) out of buffer 0's ``blob`` and move the later views' offsets back."""
    views = doc["bufferViews"]
    if blob is not None:
        kept = [v for i, v in enumerate(views) if i not in gone and v.get("buffer") == 0]
        cuts = []
        for i in sorted(gone, key=lambda i: views[i].get("byteOffset", 0)):
            v = views[i]
            a = v.get("byteOffset", 0)
            b = a + (v["byteLength"] + 3) // 4 * 4
            if v.get("buffer") == 0 and a % 4 == 0 and b <= len(blob):
                overlap = any(k.get("byteOffset", 0) < b and a < k.get("byteOffset", 0) + k["byteLength"] for k in kept)
                if not overlap:
                    cuts.append((a, b))
        for a, b in reversed(cuts):
            del blob[a:b]
        for v in kept:
            off = v.get("byteOffset", 0)
            v["byteOffset"] = off - sum(b - a for a, b in cuts if b <= off)
    keep_v = [i for i in range(len(views)) if i not in gone]
    doc["bufferViews"] = [views[i] for i in keep_v]
    _set_view_refs({k: v for k, v in doc.items() if k != "bufferViews"}, _renumber(keep_v))
    if not doc["bufferViews"]:
        doc.pop("bufferViews")
    return blob


def extension_names(node: Any) -> set[str]:
    """The names of every extension used under ``node`` (the keys of its ``extensions`` objects)."""
    found: set[str] = set()
    stack = [node]
    while stack:
        item = stack.pop()
        if isinstance(item, dict):
            found |= {k for k in as_dict(item.get("extensions")) if isinstance(k, str)}
            stack += [v for k, v in item.items() if k not in ("extensionsUsed", "extensionsRequired", "extras")]
        elif isinstance(item, list):
            stack += item
    return found


def update_extension_lists(doc: dict[str, Any]) -> None:
    """extensionsUsed: the source's list without the :data:`MANAGED` extensions no longer used, plus every
    extension the file now uses (§3.12: each one must be listed); extensionsRequired: a subset of it."""
    found = extension_names(doc)
    given = doc.get("extensionsUsed", [])
    listed = [e for e in given if isinstance(e, str)] if isinstance(given, list) else []  # a broken list: names only
    used = [e for e in listed if e not in MANAGED or e in found]
    used += sorted(found - set(used))
    if used:
        doc["extensionsUsed"] = used
    else:
        doc.pop("extensionsUsed", None)
    if "extensionsRequired" in doc:
        doc["extensionsRequired"] = [e for e in doc["extensionsRequired"] if e in used]
        if not doc["extensionsRequired"]:
            doc.pop("extensionsRequired")


#: a written .gltf's JSON is indented when it is shorter than this (compact, it takes as many bytes as it holds)
INDENTED_BYTES = 1 << 20


def json_bytes(doc: dict[str, Any]) -> bytes:
    """A .gltf's JSON text: compact (as a GLB's), indented when that is short (:data:`INDENTED_BYTES`), so that a
    large document is written about its own size, once, by the json module's C encoder."""
    text = json.dumps(doc, separators=(",", ":"))
    if len(text) < INDENTED_BYTES:
        text = json.dumps(doc, indent=1)
    return (text + "\n").encode("utf-8")


def glb_bytes(doc: dict[str, Any], bin_data: bytes | None) -> bytes:
    """GLB bytes (§4.4): header, JSON chunk padded with spaces, BIN chunk padded with zeros."""
    text = json.dumps(doc, separators=(",", ":")).encode("utf-8")
    text += b" " * (-len(text) % 4)
    chunks = struct.pack("<II", len(text), CHUNK_JSON) + text
    if bin_data is not None:
        b = bytes(bin_data) + b"\0" * (-len(bin_data) % 4)
        chunks += struct.pack("<II", len(b), CHUNK_BIN) + b
    return struct.pack("<III", GLB_MAGIC, 2, 12 + len(chunks)) + chunks


__all__ = [
    "NewImage",
    "Replacement",
    "Target",
    "add_bin_buffer",
    "add_images",
    "check_writable_source",
    "drop_unused",
    "editable_copy",
    "extension_names",
    "glb_bytes",
    "json_bytes",
    "material_textures",
    "confine_uris",
    "rebase_uris",
    "refuse_overwrites",
    "texture_infos",
    "update_extension_lists",
]
