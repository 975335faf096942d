"""Mitsuba 3 scene XML in and out.

Sources: the Mitsuba 3 documentation, "Scene format"
(https://mitsuba.readthedocs.io/en/stable/src/key_topics/scene_format.html) and plugin reference
(``plugins_bsdfs.html``, ``plugins_textures.html``), and Mitsuba 3.9's ``src/core/parser.cpp``.

**Reading.** :func:`read` accepts a ``<scene>`` or a bare ``<bsdf>`` document, loaded as Mitsuba loads
it (:mod:`matremap.formats.mitsuba_scene`: ``<include>``, ``<path>``, ``<default>``/``$name``, ids
across files, all confined to the scene's folder or ``--allow-path`` folders). The materials of a scene
are its top-level ``<bsdf>`` elements (included files' too), then the ``<bsdf>`` elements written
inside ``<shape>`` elements, in document order; ``material`` picks one by ``id`` (or ``shape id/bsdf``
for an anonymous one inside a shape) or by index; :func:`material_names` lists them all. How each
plugin, wrapper and texture is read: :mod:`matremap.formats.mitsuba_bsdfs`,
:mod:`matremap.formats.mitsuba_textures`, :mod:`matremap.formats.spectra`.

The XML is parsed with defusedxml: entity declarations (entity expansion, external entities) are
refused whatever the expat version, as are documents nested deeper than
:data:`~matremap.formats.common.MAX_XML_DEPTH` elements.

**Writing.** :func:`write` writes a scene (version 3.0.0) holding the material as the top-level
BSDF ``material`` (inside a ``normalmap`` wrapper when the map set has a normal map, and a ``mask``
wrapper when the source carried an opacity), its maps copied beside the XML as ``bitmap`` textures
(``raw`` for data maps; files converted to linear EXR where their encoding is not what Mitsuba would
assume), and the probe sphere of :mod:`matremap.core.scene` (radius 2, turned so that Mitsuba's UVs
are matremap's) under a constant white environment, seen by the probe camera; ``$spp``,
``$resolution`` and ``$max_depth`` are ``<default>`` parameters, so ``mitsuba file.xml`` or
``mi.load_file(file)`` renders it as it is. A carried emission becomes an ``area`` emitter on the
sphere (a BSDF cannot emit). :func:`write_all` writes every converted material of a file into one
scene (:mod:`matremap.formats.mitsuba_write`).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from matremap.errors import MatremapError
from matremap.formats.asset import MaterialAsset
from matremap.formats.common import (
    pick_material,
)
from matremap.formats.confine import Confinement
from matremap.formats.mitsuba_bsdfs import BsdfReader
from matremap.formats.mitsuba_plugins import (
    FORMAT,
    IOR_TABLE,
    MODELS,
    PLUGINS,
)
from matremap.formats.mitsuba_scene import MitsubaScene, load_scene


def material_names(path: str | Path) -> list[str]:
    """The names of a scene's BSDFs (their ids, or the names :mod:`~matremap.formats.mitsuba_bsdfs` gives
    unnamed ones), in order, included files' too."""
    return [n for n, _ in _materials(Path(path), None)[1]]


def _materials(p: Path, confinement: Confinement | None) -> tuple[BsdfReader, list[tuple[str, ET.Element]]]:
    """The scene's reader and its BSDFs as (name, element)."""
    scene = load_scene(p, confinement)
    reader = BsdfReader(scene)
    found = reader.candidates()
    if not found:
        raise MatremapError(f"{p} holds no <bsdf>; matremap reads a scene's BSDFs (top-level or inside shapes)")
    return reader, found


def read(
    path: str | Path, material: str | int | None = None, *, confinement: Confinement | None = None
) -> MaterialAsset:
    """One material of a Mitsuba 3 scene (or bare ``<bsdf>``) XML file as a :class:`MaterialAsset`
    of a ``mitsuba3:*`` model. ``material``: a BSDF id (see the module doc for names) or an index;
    the first by default. Included files, bitmaps and search paths must lie in the scene's folder or a
    folder ``confinement`` allows (default: the one in effect, :mod:`matremap.formats.confine`)."""
    p = Path(path)
    reader, found = _materials(p, confinement)
    index = pick_material(p, [n for n, _ in found], material, "BSDF")
    asset = reader.asset(*found[index], index)
    legacy = [f for f in reader.scene.files if f.legacy]
    if legacy:
        version = legacy[0].raw.get("version")
        asset.notes.insert(0, f"version {version} file: camelCase parameter names read as Mitsuba 3's snake_case names")
    return asset


def write(out: str | Path, result: Any, source: MaterialAsset | None = None, force: bool = False) -> Path:
    """Write ``result`` (a Material or MapSet of a ``mitsuba3:*`` model) as a Mitsuba 3 scene XML. With a
    Mitsuba scene as ``source``: a copy of that scene with the source's BSDF replaced (its id, wrappers,
    shapes, emitters, sensors and includes kept, as :func:`write_all` copies one; the glTF and USD writers
    copy their sources the same way). Otherwise a scene that renders the material on the probe sphere,
    maps copied beside it as ``<stem>_<param>.png|.exr``; from ``source`` (any other format) the carried
    opacity is written as a ``mask`` wrapper and the carried emission as an ``area`` emitter on the sphere
    (a note in ``source.notes`` says so). The scene and its maps are written together or not at all."""
    from matremap.formats.mitsuba_write import write_copied_scene, write_probe_scene

    if source is not None and source.format == FORMAT and isinstance(source.document, MitsubaScene):
        return write_copied_scene(Path(out), [(source.name, result)], Path(source.path), force)
    return write_probe_scene(Path(out), result, source, force)


def write_all(
    out: str | Path,
    results: list[tuple[str, Any]],
    source: Path | None,
    force: bool = False,
    assets: Mapping[str, MaterialAsset] | None = None,
) -> Path:
    """Every ``(name, result)`` into one Mitsuba 3 scene: when ``source`` is a Mitsuba scene, a copy of it
    (and of its included files) with those BSDFs replaced, ids kept, everything else kept, file names
    rewritten to point at the source's files; else a fresh scene with each material a top-level BSDF
    (id = its name) on a probe sphere of its own, with the opacity (a ``mask``) and emission (an ``area``
    emitter) of ``assets``, the materials as read from a source of another format
    (:mod:`matremap.formats.mitsuba_write`)."""
    from matremap.formats.mitsuba_write import write_copied_scene, write_spheres_scene

    if source is not None:
        return write_copied_scene(Path(out), results, Path(source), force)
    return write_spheres_scene(Path(out), results, force, assets)


__all__ = ["FORMAT", "IOR_TABLE", "MODELS", "PLUGINS", "material_names", "read", "write", "write_all"]
