"""Material files in and out: glTF 2.0, MaterialX, Mitsuba 3 XML, USD, Blender .blend.

Every reader has the signature ``read(path, material=None, *, confinement=None) -> MaterialAsset``
(``material`` picks one material of the file by name or index; the first by default; ``confinement``
the folders besides the file's own that the files it names may lie in, see
:mod:`matremap.formats.confine`: by default the ones the command line allowed with ``--allow-path``,
else none) and every writer
``write(out, result, source=None, force=False) -> Path`` where ``result`` is a uniform
:class:`~matremap.core.material.Material` or a :class:`~matremap.svbrdf.textures.MapSet` of converted maps, and
``source`` the asset it was remapped from (the glTF writer copies the source file with the new
material). Modules are imported when a format is used.

A writer writes its file and the files beside it (textures, maps, a ``.bin``) together or not at all,
through :class:`~matremap.core.atomic.AtomicFiles`; :mod:`matremap.formats.common` holds what the
format modules share (picking a material, taking a result apart, placing maps beside a document).
"""

from __future__ import annotations

import importlib
import os
from pathlib import Path
from typing import Any

from matremap.errors import MatremapError
from matremap.formats.asset import CarriedInput, MaterialAsset, TextureRef
from matremap.formats.confine import Confinement, allowed_paths

#: file suffix -> (format name, module)
READERS = {
    ".gltf": ("gltf", "gltf"),
    ".glb": ("gltf", "gltf"),
    ".mtlx": ("mtlx", "materialx"),
    ".xml": ("mitsuba-xml", "mitsuba_xml"),
    ".blend": ("blend", "blend"),
    ".usda": ("usd", "usd"),
    ".usdc": ("usd", "usd"),
    ".usdz": ("usd", "usd"),
    ".usd": ("usd", "usd"),
}
#: format name -> (module, the suffixes it writes)
WRITERS = {
    "gltf": ("gltf", (".gltf", ".glb")),
    "mtlx": ("materialx", (".mtlx",)),
    "mitsuba-xml": ("mitsuba_xml", (".xml",)),
    "blend": ("blend", (".blend",)),
    "usd": ("usd", (".usda", ".usdc", ".usdz", ".usd")),
}


def written_constants(model: str) -> tuple[str, ...]:
    """The parameters of ``model`` its own file format's writer takes as numbers only (a map of one is refused
    when written): glTF's ``ior`` and layer values (:data:`matremap.formats.gltf_write.CONSTANT_ONLY`)."""
    from matremap.formats.gltf_read import LAYERED_MODEL, MODEL

    if model in (MODEL, LAYERED_MODEL):
        from matremap.formats.gltf_write import CONSTANT_ONLY

        return CONSTANT_ONLY
    return ()


def written_models(fmt: str) -> tuple[str, ...]:
    """The models the writer of format ``fmt`` (a key of :data:`WRITERS`) takes."""
    if fmt == "gltf":
        from matremap.formats.gltf_read import LAYERED_MODEL, MODEL

        return (MODEL, LAYERED_MODEL)
    if fmt == "mtlx":
        from matremap.formats.mtlx_write import NODES

        return tuple(NODES)
    if fmt == "usd":
        from matremap.formats.gltf_read import MODEL as GLTF
        from matremap.formats.usd import MODEL as USD

        return (USD, GLTF)
    if fmt == "mitsuba-xml":
        from matremap.formats.mitsuba_plugins import MODELS as MITSUBA

        return tuple(MITSUBA)
    if fmt == "blend":
        from matremap.formats.blend import MODELS as CYCLES

        return tuple(CYCLES)
    return ()


def _module(name: str):
    return importlib.import_module(f"{__name__}.{name}")


def is_material_file(path: str | os.PathLike) -> bool:
    return Path(path).suffix.lower() in READERS and Path(path).is_file()


def read_asset(
    path: str | os.PathLike, material: str | int | None = None, *, confinement: Confinement | None = None
) -> MaterialAsset:
    """Read one material of a glTF/.glb, MaterialX or Mitsuba XML file; the files it names must lie in
    its folder or a folder ``confinement`` allows (default: the one in effect, see :func:`allowed_paths`)."""
    p = Path(path)
    if not p.is_file():
        raise MatremapError(f"{p} not found")
    suffix = p.suffix.lower()
    if suffix not in READERS:
        raise MatremapError(f"{p}: matremap reads {', '.join(sorted(READERS))} material files, not {suffix or 'this'}")
    return _module(READERS[suffix][1]).read(p, material, confinement=confinement)


def material_names(path: str | os.PathLike) -> list[str]:
    """The names of the materials of a glTF/.glb, MaterialX or Mitsuba XML file, in the order
    :func:`read_asset` indexes them."""
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix not in READERS:
        raise MatremapError(f"{p}: matremap reads {', '.join(sorted(READERS))} material files, not {suffix or 'this'}")
    names: list[str] = _module(READERS[suffix][1]).material_names(p)
    return names


def format_for(out: str | os.PathLike) -> str:
    """The output format a file name asks for."""
    suffix = Path(out).suffix.lower()
    for fmt, (_, suffixes) in WRITERS.items():
        if suffix in suffixes:
            return fmt
    raise MatremapError(
        f"{out}: matremap writes {', '.join(s for _, ss in WRITERS.values() for s in ss)} files; "
        f"give the output one of these suffixes"
    )


def write_asset(out: str | os.PathLike, result: Any, source: MaterialAsset | None = None, force: bool = False) -> Path:
    """Write ``result`` (a Material or a MapSet) in the format ``out``'s suffix names."""
    module, _ = WRITERS[format_for(out)]
    return _module(module).write(Path(out), result, source=source, force=force)


def write_all(
    out: str | os.PathLike,
    results: list[tuple[str, Any]],
    source: str | os.PathLike | None = None,
    force: bool = False,
) -> Path:
    """Write every ``(material name, result)`` into one file of the format ``out``'s suffix names: a copy
    of ``source`` with those materials replaced when it is of that format, else a fresh file holding all
    of them (see each module's ``write_all``); either way the source's materials as read go along
    (``assets``), so a writer carries their emission, opacity and occlusion into a fresh file."""
    fmt = format_for(out)
    module = _module(WRITERS[fmt][0])
    if not hasattr(module, "write_all"):
        raise MatremapError(f"writing every material into one {fmt} file is not supported yet; see OUT/<file>/*")
    same = (
        source is not None and Path(source).suffix.lower() in READERS and READERS[Path(source).suffix.lower()][0] == fmt
    )
    assets = source_assets(source, [name for name, _ in results]) if source is not None else {}
    path: Path = module.write_all(
        Path(out), results, Path(source) if same and source else None, force=force, assets=assets
    )
    return path


def source_assets(source: str | os.PathLike, names: list[str]) -> dict[str, MaterialAsset]:
    """The materials ``names`` of ``source`` as read (any format), for a writer to carry their emission,
    opacity and occlusion (:attr:`MaterialAsset.carried`); one that no longer reads is left out."""
    out: dict[str, MaterialAsset] = {}
    for name in names:
        try:
            out[name] = read_asset(source, name)
        except MatremapError:
            continue
    return out


__all__ = [
    "READERS",
    "CarriedInput",
    "WRITERS",
    "Confinement",
    "MaterialAsset",
    "TextureRef",
    "allowed_paths",
    "format_for",
    "is_material_file",
    "material_names",
    "read_asset",
    "source_assets",
    "write_all",
    "written_models",
    "write_asset",
]
