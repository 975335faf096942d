"""glTF 2.0 materials in and out (``.gltf`` JSON and ``.glb`` binary), as ``gltf:metal-rough``.

The format is split by concern; this module is its face (``formats.gltf.read``, ``write``, ``write_all``,
``material_names``), as :mod:`matremap.formats` expects of every format module:

* :mod:`matremap.formats.gltf_container`: the JSON / GLB container, buffers and images, read safely;
* :mod:`matremap.formats.gltf_textures`: samplers, KHR_texture_transform, UV sets, baking;
* :mod:`matremap.formats.gltf_extensions`: the KHR material extensions, validated and reported;
* :mod:`matremap.formats.gltf_read`: one material as a :class:`~matremap.formats.asset.MaterialAsset`;
* :mod:`matremap.formats.gltf_mesh`: UV spheres for materials without a glTF of their own;
* :mod:`matremap.formats.gltf_edit`: the copy being written (textures added, unused ones dropped);
* :mod:`matremap.formats.gltf_write`: one converted material written (:func:`write`);
* :mod:`matremap.formats.gltf_write_all`: every converted material of a file in one glTF (:func:`write_all`).
"""

from __future__ import annotations

from matremap.formats.gltf_container import MAX_JSON_DEPTH, GltfDocument
from matremap.formats.gltf_extensions import lost_look
from matremap.formats.gltf_read import MODEL, material_names, read
from matremap.formats.gltf_write import write
from matremap.formats.gltf_write_all import write_all

__all__ = ["MAX_JSON_DEPTH", "MODEL", "GltfDocument", "lost_look", "material_names", "read", "write", "write_all"]
