"""Checks of written glTF files, independent of matremap: pygltflib loads them, and the rules of the Khronos
glTF Validator that can be checked offline are checked here (glTF 2.0 §3.6.2 buffer views inside their
buffers, §3.6.2.4 accessor alignment, §5.1 accessor bounds and POSITION min/max, §3.8.4 sampler enums,
§3.12 extensionsUsed / extensionsRequired, images that decode). :func:`khronos_validator` runs the
official validator (npm ``gltf-validator``) when node can load it, else returns None.
"""

from __future__ import annotations

import functools
import json
import os
import shutil
import subprocess
from pathlib import Path
from typing import Any

SIZES = {5120: 1, 5121: 1, 5122: 2, 5123: 2, 5125: 4, 5126: 4}
COMPONENTS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
MAG = {9728, 9729}
MIN = {9728, 9729, 9984, 9985, 9986, 9987}
WRAP = {33071, 33648, 10497}
INSTALL = "npm install gltf-validator && export NODE_PATH=$PWD/node_modules  (or GLTF_VALIDATOR=<that folder>)"


def load(path: Path) -> Any:
    """The file loaded by pygltflib (cached while the file is unchanged)."""
    st = Path(path).stat()
    return _load(str(path), st.st_mtime_ns, st.st_size)


@functools.lru_cache(maxsize=16)
def _load(path: str, mtime: int, size: int) -> Any:
    import pygltflib

    g = pygltflib.GLTF2().load(path)
    assert g is not None and g.asset.version == "2.0"
    return g


def buffer_bytes(g: Any, path: Path, i: int) -> bytes:
    b = g.buffers[i]
    if b.uri is None:
        return g.binary_blob()
    if b.uri.startswith("data:"):
        import base64

        return base64.b64decode(b.uri.split(",", 1)[1])
    from urllib.parse import unquote

    return (path.parent / unquote(b.uri)).read_bytes()


def view_bytes(g: Any, path: Path, i: int) -> bytes:
    v = g.bufferViews[i]
    data = buffer_bytes(g, path, v.buffer)
    return data[(v.byteOffset or 0) : (v.byteOffset or 0) + v.byteLength]


def accessor_bytes(g: Any, path: Path, i: int) -> bytes:
    """The bytes an accessor reads (its elements, strided views taken element by element)."""
    a = g.accessors[i]
    if a.bufferView is None:
        return b""
    v = g.bufferViews[a.bufferView]
    data = view_bytes(g, path, a.bufferView)
    elem = SIZES[a.componentType] * COMPONENTS[a.type]
    stride = v.byteStride or elem
    off = a.byteOffset or 0
    if stride == elem:
        return data[off : off + elem * a.count]
    return b"".join(data[off + k * stride : off + k * stride + elem] for k in range(a.count))


def offline_check(path: Path) -> list[str]:
    """The validator's rules checkable here; returns the problems found (empty when valid)."""
    import OpenImageIO as oiio

    g = load(path)
    problems: list[str] = []
    raw = json.loads(g.to_json())
    for i, b in enumerate(g.buffers):
        if len(buffer_bytes(g, path, i)) < b.byteLength:
            problems.append(f"buffers[{i}] shorter than its byteLength")
    for i, v in enumerate(g.bufferViews):
        if (v.byteOffset or 0) + v.byteLength > g.buffers[v.buffer].byteLength:
            problems.append(f"bufferViews[{i}] runs past its buffer")
        if v.byteStride is not None and (v.byteStride % 4 or not 4 <= v.byteStride <= 252):
            problems.append(f"bufferViews[{i}].byteStride {v.byteStride}")
    for i, a in enumerate(g.accessors):
        if a.bufferView is None:
            continue
        v = g.bufferViews[a.bufferView]
        elem = SIZES[a.componentType] * COMPONENTS[a.type]
        stride = v.byteStride or elem
        off = a.byteOffset or 0
        if off + stride * (a.count - 1) + elem > v.byteLength:
            problems.append(f"accessors[{i}] runs past its bufferView")
        if (off + (v.byteOffset or 0)) % SIZES[a.componentType]:
            problems.append(f"accessors[{i}] is not aligned to its component size")
    for m in g.meshes:
        for p in m.primitives:
            pos = g.accessors[p.attributes.POSITION]
            if pos.min is None or pos.max is None:
                problems.append("a POSITION accessor has no min/max")
            if p.material is not None and not 0 <= p.material < len(g.materials):
                problems.append(f"a primitive's material {p.material} does not exist")
    for i, s in enumerate(g.samplers):
        bad = [
            (k, x)
            for k, x, ok in (("magFilter", s.magFilter, MAG), ("minFilter", s.minFilter, MIN), ("wrapS", s.wrapS, WRAP))
            if x is not None and x not in ok
        ]
        if s.wrapT is not None and s.wrapT not in WRAP:
            bad.append(("wrapT", s.wrapT))
        problems += [f"samplers[{i}].{k} = {x}" for k, x in bad]
    for i, t in enumerate(g.textures):
        if t.source is not None and not 0 <= t.source < len(g.images):
            problems.append(f"textures[{i}].source out of range")
        if t.sampler is not None and not 0 <= t.sampler < len(g.samplers):
            problems.append(f"textures[{i}].sampler out of range")
    for i, im in enumerate(g.images):
        if im.bufferView is not None:
            data = view_bytes(g, path, im.bufferView)
            if im.mimeType not in ("image/png", "image/jpeg"):
                problems.append(f"images[{i}] mimeType {im.mimeType}")
        elif im.uri is not None and not im.uri.startswith("data:"):
            from urllib.parse import unquote

            data = (path.parent / unquote(im.uri)).read_bytes()
        else:
            continue
        tmp = path.parent / f".check-image-{i}"
        tmp.write_bytes(data)
        try:
            buf = oiio.ImageBuf(str(tmp))
            if buf.has_error or buf.spec().width < 1 or not buf.read():
                problems.append(f"images[{i}] does not decode")
        finally:
            tmp.unlink()
    used = set(raw.get("extensionsUsed", []))
    found = set()

    def walk(node: Any) -> None:
        if isinstance(node, dict):
            found.update((node.get("extensions") or {}).keys())
            for k, v in node.items():
                if k not in ("extensionsUsed", "extensionsRequired"):
                    walk(v)
        elif isinstance(node, list):
            for v in node:
                walk(v)

    walk(raw)
    if found - used:
        problems.append(f"extensions used but not listed: {sorted(found - used)}")
    if not set(raw.get("extensionsRequired", [])) <= used:
        problems.append("extensionsRequired not a subset of extensionsUsed")
    for i, info in enumerate(texture_infos(raw)):
        if not 0 <= info["index"] < len(g.textures):
            problems.append(f"textureInfo {i} index {info['index']} out of range")
    return problems


def texture_infos(node: Any, key: str = "") -> list[dict[str, Any]]:
    out = []
    if isinstance(node, dict):
        if key.endswith("Texture") and "index" in node:
            out.append(node)
        for k, v in node.items():
            out += texture_infos(v, k)
    elif isinstance(node, list):
        for v in node:
            out += texture_infos(v, key)
    return out


SCRIPT = """
const fs = require('fs'); const path = require('path'); const validator = require('gltf-validator');
const file = process.argv[1];
validator.validateBytes(new Uint8Array(fs.readFileSync(file)), {
  uri: path.basename(file), maxIssues: 200,
  externalResourceFunction: (uri) => new Promise((ok, no) =>
    fs.readFile(path.resolve(path.dirname(file), decodeURIComponent(uri)), (e, d) => e ? no(e.toString()) : ok(d))),
}).then((r) => console.log(JSON.stringify(r.issues))).catch((e) => { console.error(String(e)); process.exit(1); });
"""


def khronos_validator(path: Path) -> dict[str, Any] | None:
    """The official validator's issues (``numErrors``, ``messages``...), or None when node or the
    ``gltf-validator`` package is not available (``GLTF_VALIDATOR``: the node_modules folder holding it)."""
    node = shutil.which("node")
    if node is None:
        return None
    env = dict(os.environ)
    extra = env.get("GLTF_VALIDATOR")
    if extra:
        env["NODE_PATH"] = os.pathsep.join(p for p in (extra, env.get("NODE_PATH", "")) if p)
    probe = subprocess.run([node, "-e", "require('gltf-validator')"], env=env, capture_output=True, timeout=60)
    if probe.returncode != 0:
        return None
    run = subprocess.run([node, "-e", SCRIPT, str(path)], env=env, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    issues: dict[str, Any] = json.loads(run.stdout)
    return issues


def image_digest(g: Any, path: Path, texture: int) -> str:
    """The SHA-256 of the image a texture uses (its bytes, wherever they are stored)."""
    import hashlib
    from urllib.parse import unquote

    im = g.images[g.textures[texture].source]
    data = (
        view_bytes(g, path, im.bufferView)
        if im.bufferView is not None
        else (path.parent / unquote(im.uri)).read_bytes()
    )
    return hashlib.sha256(data).hexdigest()


def resolved(path: Path, node: Any) -> Any:
    """A copy of JSON ``node`` (of the file ``path``) with every textureInfo's index replaced by its image's
    digest, so that the same textures compare equal whatever their indices."""
    node = json.loads(json.dumps(node))
    infos = texture_infos(node)
    g = load(path) if infos else None
    for info in infos:
        info["index"] = image_digest(g, path, info["index"])
    return node


def accessor_digest(path: Path) -> list[bytes]:
    """Every accessor's bytes, in order (geometry, animation and skin data as the file reads it)."""
    g = load(path)
    return [accessor_bytes(g, path, i) for i in range(len(g.accessors))]


def primitive_materials(path: Path) -> list[Any]:
    g = load(path)
    return [p.material for m in g.meshes for p in m.primitives]


__all__ = [
    "INSTALL",
    "accessor_digest",
    "image_digest",
    "resolved",
    "khronos_validator",
    "load",
    "offline_check",
    "primitive_materials",
]
