"""Every converted material of one input written into one glTF (issue 20: whole files).

With a glTF source, the output is a copy of it in which each converted material is replaced in place
(:func:`matremap.formats.gltf_write.commit`): meshes, nodes, animations, samplers, texture transforms and
the extensions it does not touch are kept, primitives keep pointing at the same material indices, and the
textures only the replaced materials used are dropped with their images. Results are matched to the
source's materials by name, as :func:`matremap.formats.gltf_read.material_names` gives them ("material N"
for an unnamed one; repeated names in file order). Without a glTF source, a fresh file holds one UV sphere
per material, side by side (:mod:`matremap.formats.gltf_mesh`).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from matremap.errors import MatremapError
from matremap.formats.asset import MaterialAsset
from matremap.formats.gltf_container import GltfDocument
from matremap.formats.gltf_edit import Replacement, Target
from matremap.formats.gltf_extensions import LAYERED_MODEL
from matremap.formats.gltf_read import material_names, read
from matremap.formats.gltf_write import commit, result_values


def _indices(source: Path, names: list[str]) -> list[int]:
    """The source's material index of each result name (each index used once, in file order)."""
    have = material_names(source)
    taken: set[int] = set()
    found = []
    for name in names:
        idx = next((i for i, n in enumerate(have) if n == name and i not in taken), None)
        if idx is None:
            raise MatremapError(
                f"{source} has no material {name!r} left to replace; its materials are {', '.join(map(repr, have))}"
            )
        taken.add(idx)
        found.append(idx)
    return found


def write_all(
    out: Path,
    results: list[tuple[str, Any]],
    source: Path | None,
    force: bool = False,
    assets: Mapping[str, MaterialAsset] | None = None,
) -> Path:
    """Write every ``(material name, result)`` (``gltf:metal-rough`` Materials or MapSets) into ``out``
    (.gltf or .glb): a copy of the glTF ``source`` with those materials replaced, or, without one, a
    new file with one sphere per material carrying the emission, opacity and occlusion of ``assets``
    (the materials as read from a source of another format). All files or none; inputs are never
    overwritten."""
    out = Path(out)
    if out.suffix.lower() not in (".gltf", ".glb"):
        raise MatremapError(f"cannot write {out} as glTF: name it .gltf or .glb")
    if not results:
        raise MatremapError(f"no material to write into {out}")
    values = [result_values(r) for _, r in results]
    inputs = [f for v in values for f in v[3]]
    if source is None:
        target = Target.spheres([name for name, _ in results])
        carried = [dict(assets[name].carried) if assets and name in assets else {} for name, _ in results]
        reps = [Replacement(i, c, m, n, carried[i], False, None) for i, (c, m, n, _) in enumerate(values)]
        return commit(out, target, reps, inputs, force)
    indices = _indices(source, [name for name, _ in results])
    own = [read(source, i) for i in indices]
    gdoc = own[0].document
    assert isinstance(gdoc, GltfDocument)
    target = Target.copy_of(source, gdoc, [t.path for a in own for t in a.textures.values()])
    reps = []
    for asset, (consts, maps, normal, _) in zip(own, values, strict=True):
        adoc = asset.document
        uv_set = adoc.uv_set if isinstance(adoc, GltfDocument) else 0
        reps.append(
            Replacement(
                asset.index,
                consts,
                maps,
                normal,
                dict(asset.carried),
                True,
                asset.normal,
                uv_set,
                source_layered=asset.model == LAYERED_MODEL,
            )
        )
    return commit(out, target, reps, inputs, force)


__all__ = ["write_all"]
