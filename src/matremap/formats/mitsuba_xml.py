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

import numpy as np

from matremap.core.atomic import AtomicFiles
from matremap.core.imageio import check_output
from matremap.core.material import Material
from matremap.errors import MatremapError
from matremap.formats.asset import MaterialAsset
from matremap.formats.common import (
    check_map_destinations,
    map_destination,
    pick_material,
    place_map,
    result_parts,
)
from matremap.formats.confine import Confinement
from matremap.formats.mitsuba_bsdfs import BsdfReader
from matremap.formats.mitsuba_plugins import (
    CONSTANT_ONLY,
    FORMAT,
    IOR_TABLE,
    MODELS,
    PLUGINS,
    PRINCIPLED_SCALARS,
    plugin_of,
)
from matremap.formats.mitsuba_scene import load_scene


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


# ---------------------------------------------------------------------------------------------
# Writing


def _num(x: float) -> str:
    return repr(float(x))


def _rgb(v: np.ndarray) -> str:
    return ", ".join(_num(x) for x in np.asarray(v, dtype=float).reshape(-1))


def _bsdf_xml(m: Material, textures: Mapping[str, ET.Element]) -> ET.Element:
    spec = m.spec
    plugin = plugin_of(spec.id)
    bsdf = ET.Element("bsdf", {"type": plugin})

    def value(name: str) -> None:
        if name in textures:
            bsdf.append(textures[name])
            return
        p = spec.param(name)
        v = m.values[name]
        if p.channels == 3:
            ET.SubElement(bsdf, "rgb", {"name": name, "value": _rgb(v)})
        else:
            ET.SubElement(bsdf, "float", {"name": name, "value": _num(v[0])})

    if "distribution" in m.options:
        ET.SubElement(bsdf, "string", {"name": "distribution", "value": m.options["distribution"]})
    if plugin == "diffuse":
        value("reflectance")
    elif plugin == "roughconductor":
        value("alpha")
        if m.options["material"] == "custom":
            value("eta")
            value("k")
        else:
            ET.SubElement(bsdf, "string", {"name": "material", "value": m.options["material"]})
        value("specular_reflectance")
    elif plugin == "roughplastic":
        for name in ("alpha", "int_ior", "ext_ior"):
            value(name)
        ET.SubElement(bsdf, "boolean", {"name": "nonlinear", "value": m.options["nonlinear"]})
        value("specular_reflectance")
        value("diffuse_reflectance")
    else:
        for name in ("base_color", *PRINCIPLED_SCALARS, "specular"):
            value(name)
    return bsdf


def _bitmap(name: str, filename: str, raw: bool) -> ET.Element:
    t = ET.Element("texture", {"type": "bitmap", "name": name})
    ET.SubElement(t, "string", {"name": "filename", "value": filename})
    ET.SubElement(t, "boolean", {"name": "raw", "value": "true" if raw else "false"})
    return t


def _probe_scene(bsdf: ET.Element) -> ET.Element:
    """The scene around the BSDF: probe sphere, probe camera, constant white environment."""
    from matremap.core.scene import Scene

    probe = Scene()
    scene = ET.Element("scene", {"version": "3.0.0"})
    for name, value in (("spp", "64"), ("resolution", "256"), ("max_depth", "3")):
        ET.SubElement(scene, "default", {"name": name, "value": value})
    integrator = ET.SubElement(scene, "integrator", {"type": "path"})
    ET.SubElement(integrator, "integer", {"name": "max_depth", "value": "$max_depth"})
    ET.SubElement(integrator, "boolean", {"name": "hide_emitters", "value": "true"})
    sensor = ET.SubElement(scene, "sensor", {"type": "perspective"})
    ET.SubElement(sensor, "float", {"name": "fov", "value": _num(probe.effective_fov)})
    ET.SubElement(sensor, "string", {"name": "fov_axis", "value": "x"})
    tw = ET.SubElement(sensor, "transform", {"name": "to_world"})
    ET.SubElement(
        tw, "lookat", {"origin": f"0, 0, {_num(probe.camera_distance)}", "target": "0, 0, 0", "up": "0, 1, 0"}
    )
    sampler = ET.SubElement(sensor, "sampler", {"type": "independent"})
    ET.SubElement(sampler, "integer", {"name": "sample_count", "value": "$spp"})
    film = ET.SubElement(sensor, "film", {"type": "hdrfilm"})
    ET.SubElement(film, "integer", {"name": "width", "value": "$resolution"})
    ET.SubElement(film, "integer", {"name": "height", "value": "$resolution"})
    ET.SubElement(film, "string", {"name": "pixel_format", "value": "rgb"})
    ET.SubElement(film, "rfilter", {"type": "box"})
    scene.append(bsdf)
    shape = ET.SubElement(scene, "shape", {"type": "sphere", "id": "probe_sphere"})
    # Mitsuba's local sphere frame -> world so that its UVs are matremap's (see renderers/mitsuba3_svbrdf.py):
    # local x -> -z, y -> -x, z (the pole) -> +y, scaled by the radius
    r = float(probe.sphere_radius)
    rows = [[0.0, -r, 0.0, 0.0], [0.0, 0.0, r, 0.0], [-r, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
    st = ET.SubElement(shape, "transform", {"name": "to_world"})
    ET.SubElement(st, "matrix", {"value": " ".join(_num(x) for row in rows for x in row)})
    ET.SubElement(shape, "ref", {"id": bsdf.get("id", "material")})
    emitter = ET.SubElement(scene, "emitter", {"type": "constant"})
    ET.SubElement(emitter, "rgb", {"name": "radiance", "value": "1, 1, 1"})
    return scene


def write(out: str | Path, result: Any, source: MaterialAsset | None = None, force: bool = False) -> Path:
    """Write ``result`` (a Material or MapSet of a ``mitsuba3:*`` model) as a Mitsuba 3 scene XML
    that renders the material on the probe sphere; maps are copied beside it as
    ``<stem>_<param>.png|.exr``. ``source`` is not used (the scene is written from scratch).
    The scene and its maps are written together or not at all."""
    out = Path(out)
    m, maps, cs, normal = result_parts(result, "Mitsuba 3 XML", MODELS)
    check_output(out, force, (".xml",))
    _check_textured(m, maps)
    check_map_destinations(out, [*maps, *(["normal"] if normal else [])], force)
    with AtomicFiles(force) as files:
        textures = {name: _place_texture(m, name, src, cs[name], out, files) for name, src in maps.items()}
        bsdf = _bsdf_xml(m, textures)
        if normal is not None:
            dest = place_map(normal, map_destination(out, "normal"), True, "linear", 3, files)
            wrapper = ET.Element("bsdf", {"type": "normalmap", "id": "material"})
            wrapper.append(_bitmap("normalmap", dest.name, raw=True))
            wrapper.append(bsdf)
            bsdf = wrapper
        else:
            bsdf.set("id", "material")
        scene = _probe_scene(bsdf)
        ET.indent(scene, space="    ")
        files.write_text(
            out,
            '<?xml version="1.0" encoding="utf-8"?>\n'
            f"<!-- written by matremap: {m.spec.id} on the probe sphere under a white environment -->\n"
            + ET.tostring(scene, encoding="unicode")
            + "\n",
        )
    return out


def _check_textured(m: Material, maps: Mapping[str, Path]) -> None:
    """Refuse maps of parameters Mitsuba 3 takes as numbers only."""
    plugin = plugin_of(m.spec.id)
    for name in maps:
        if name in CONSTANT_ONLY.get(plugin, ()):
            raise MatremapError(
                f"{m.spec.id}: Mitsuba 3 takes {name} as a number, not a texture; give it as a constant"
            )
        if name in ("eta", "k") and m.options.get("material") != "custom":
            raise MatremapError(f"{m.spec.id}: a map for {name} needs material=custom")


def _place_texture(m: Material, name: str, src: Path, colorspace: str, out: Path, files: AtomicFiles) -> ET.Element:
    """Stage the map of parameter ``name`` beside ``out`` and return its ``bitmap`` element: kept as it
    is where Mitsuba would decode it as ``colorspace`` says (non-raw: integer files sRGB, float files
    linear; raw: as stored), else converted to linear EXR."""
    from matremap.svbrdf.textures import image_info

    p = m.spec.param(name)
    colour = p.channels == 3 and p.role != "roughness"
    info = image_info(src, colorspace)
    expected = ("srgb" if info.integer else "linear") if colour else "linear"
    dest = place_map(src, map_destination(out, name), colorspace == expected, colorspace, p.channels, files)
    return _bitmap(name, dest.name, raw=not colour)


__all__ = ["FORMAT", "IOR_TABLE", "MODELS", "PLUGINS", "read", "write"]
