"""A glTF of UV spheres, one per material, for writing materials that have no glTF of their own.

glTF 2.0 (Khronos, 2.0.1) §3.7 "Geometry" (POSITION, NORMAL, TEXCOORD_0 attributes; indexed triangles,
counter-clockwise front faces), §3.6.2 "Buffer Views" (``target`` 34962 ARRAY_BUFFER / 34963
ELEMENT_ARRAY_BUFFER), §3.6.2.4 "Data Alignment" (an accessor's offset is a multiple of its component size;
every view here starts on 4 bytes), §5.1.1 accessor ``min``/``max`` (required for POSITION). The spheres
are +Y up with ``v`` down the image (the UV origin is the image's top left, §3.8.4.2), side by side along
+X, two units apart.
"""

from __future__ import annotations

from typing import Any

import numpy as np


def uv_sphere(n_lat: int = 16, n_lon: int = 32) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A unit UV sphere: positions (= normals) [N, 3] float32, UVs [N, 2] float32, indices [M] uint16."""
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
    return pos, uv, np.array(idx, dtype=np.uint16).reshape(-1)


def spheres_document(names: list[str]) -> tuple[dict[str, Any], bytes]:
    """A glTF JSON (buffer 0 without a uri) and its buffer: one sphere node per material, the spheres
    sharing one mesh's accessors; material ``i`` is named ``names[i]`` (left empty for the writer)."""
    pos, uv, ind = uv_sphere()
    blobs = [pos.tobytes(), pos.tobytes(), uv.tobytes(), ind.tobytes()]
    offsets = np.cumsum([0] + [len(b) for b in blobs])
    views = [
        {"buffer": 0, "byteOffset": int(o), "byteLength": len(b), "target": 34963 if k == 3 else 34962}
        for k, (o, b) in enumerate(zip(offsets, blobs, strict=False))
    ]
    accessors = [
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
    attributes = {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2}
    n = max(len(names), 1)
    data = b"".join(blobs)
    doc: dict[str, Any] = {
        "asset": {"version": "2.0", "generator": "matremap"},
        "scene": 0,
        "scenes": [{"nodes": list(range(n))}],
        "nodes": [
            {"mesh": i, "name": f"probe sphere {i}" if n > 1 else "probe sphere", "translation": [2.0 * i, 0.0, 0.0]}
            if n > 1
            else {"mesh": 0, "name": "probe sphere"}
            for i in range(n)
        ],
        "meshes": [{"primitives": [{"attributes": attributes, "indices": 3, "material": i}]} for i in range(n)],
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": len(data)}],
        "materials": [{"name": name} if name else {} for name in (names or [""])],
    }
    return doc, data


__all__ = ["spheres_document", "uv_sphere"]
