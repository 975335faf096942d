"""Writing Mitsuba 3 scenes (version 3.0.0): one material on the probe sphere, every material of a file on
spheres of their own, or a copy of a Mitsuba scene with its BSDFs replaced.

Source: the Mitsuba 3 scene format and plugin reference (``diffuse``, ``roughconductor``,
``roughplastic``, ``principled``, ``dielectric``, ``roughdielectric``, ``thindielectric``, ``normalmap``, ``mask``,
``twosided``, ``bitmap``, the ``area`` emitter, ``<include>``), Mitsuba 3.9.

* A converted BSDF is its plugin with Mitsuba's parameter names; maps are copied beside the scene as
  ``bitmap`` textures (``raw`` for data maps; converted to linear EXR where Mitsuba would decode a file
  differently); a map set's normal map becomes a ``normalmap`` wrapper.
* :func:`write_probe_scene`: the probe sphere of :mod:`matremap.core.scene` (radius 2, turned so that
  Mitsuba's UVs are matremap's) under a constant white environment, seen by the probe camera; ``$spp``,
  ``$resolution`` and ``$max_depth`` are ``<default>`` parameters. A carried opacity
  (``MaterialAsset.carried["opacity"]``) becomes a ``mask`` wrapper (a ``mask``-mode cutoff is baked in
  as 0/1); a carried emission becomes an ``area`` emitter on the sphere, since a BSDF cannot emit.
* :func:`write_spheres_scene`: every material a top-level BSDF (id = its name, made unique), each on its
  own probe sphere in a row.
* :func:`write_copied_scene`: the source scene and the files it includes, copied with the named BSDFs
  replaced (the outer element's ``id`` and ``name`` kept, so ``<ref>``s still bind; ``twosided`` and
  ``mask`` wrappers of the source kept around the new BSDF); file names (bitmaps, meshes, environment
  maps, spectra) rewritten relative to the new scene's folder so they still point at the source's
  files, includes rewritten to the copies, ``<path>`` elements dropped (no longer needed); ``<default>``
  and ``$name`` kept. BSDFs not named -- those refused, or not asked for -- stay as they were.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from matremap.core.atomic import AtomicFiles
from matremap.core.imageio import check_output
from matremap.core.material import Material
from matremap.errors import MatremapError
from matremap.formats.asset import CarriedInput, MaterialAsset
from matremap.formats.common import check_map_destinations, map_destination, place_map, result_parts
from matremap.formats.mitsuba_plugins import CONSTANT_ONLY, MODELS, PRINCIPLED_SCALARS, plugin_of

HEADER = '<?xml version="1.0" encoding="utf-8"?>\n'


def num(x: float) -> str:
    return repr(float(x))


def rgb_text(v: Any) -> str:
    return ", ".join(num(x) for x in np.asarray(v, dtype=float).reshape(-1))


def bsdf_element(m: Material, textures: Mapping[str, ET.Element]) -> ET.Element:
    """The core BSDF of material ``m``; parameters in ``textures`` are given by those elements."""
    spec = m.spec
    plugin = plugin_of(spec.id)
    bsdf = ET.Element("bsdf", {"type": plugin})

    def value(name: str) -> None:
        if name in textures:
            bsdf.append(textures[name])
            return
        v = m.values[name]
        if spec.param(name).channels == 3:
            ET.SubElement(bsdf, "rgb", {"name": name, "value": rgb_text(v)})
        else:
            ET.SubElement(bsdf, "float", {"name": name, "value": num(v[0])})

    if "distribution" in m.options:
        ET.SubElement(bsdf, "string", {"name": "distribution", "value": m.options["distribution"]})
    if plugin == "diffuse":
        value("reflectance")
    elif plugin == "roughconductor":
        for name in ("alpha",) if "alpha" in m.values else ("alpha_u", "alpha_v"):
            value(name)
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
    elif plugin in ("dielectric", "roughdielectric", "thindielectric"):
        for name in ("alpha",) if plugin == "roughdielectric" else ():
            value(name)
        for name in ("int_ior", "ext_ior", "specular_reflectance", "specular_transmittance"):
            value(name)
    else:
        for name in ("base_color", *PRINCIPLED_SCALARS, "specular"):
            value(name)
    return bsdf


def bitmap_element(name: str, filename: str, raw: bool) -> ET.Element:
    t = ET.Element("texture", {"type": "bitmap", "name": name})
    ET.SubElement(t, "string", {"name": "filename", "value": filename})
    ET.SubElement(t, "boolean", {"name": "raw", "value": "true" if raw else "false"})
    return t


def check_textured(m: Material, maps: Mapping[str, Path]) -> None:
    """Refuse maps of parameters Mitsuba 3 takes as numbers only."""
    plugin = plugin_of(m.spec.id)
    for name in maps:
        if name in CONSTANT_ONLY.get(plugin, ()):
            raise MatremapError(
                f"{m.spec.id}: Mitsuba 3 takes {name} as a number, not a texture; give it as a constant"
            )
        if name in ("eta", "k") and m.options.get("material") != "custom":
            raise MatremapError(f"{m.spec.id}: a map for {name} needs material=custom")


def place_texture(m: Material, name: str, src: Path, colorspace: str, stem: Path, files: AtomicFiles) -> ET.Element:
    """Stage the map of parameter ``name`` as ``stem`` + suffix and return its ``bitmap`` element: kept as
    it is where Mitsuba would decode it as ``colorspace`` says (non-raw: integer files sRGB, float files
    linear; raw: as stored), else converted to linear EXR."""
    from matremap.svbrdf.textures import image_info

    p = m.spec.param(name)
    colour = p.channels == 3 and p.role != "roughness"
    info = image_info(src, colorspace)
    expected = ("srgb" if info.integer else "linear") if colour else "linear"
    dest = place_map(src, stem, colorspace == expected, colorspace, p.channels, files)
    return bitmap_element(name, os.path.relpath(dest, stem.parent).replace(os.sep, "/"), raw=not colour)


class Converted:
    """A result taken apart for writing: :meth:`stage` places its maps and returns its BSDF element."""

    def __init__(self, result: Any, out: Path, prefix: str) -> None:
        self.material, self.maps, self.colorspace, self.normal = result_parts(result, "Mitsuba 3 XML", MODELS)
        check_textured(self.material, self.maps)
        self.out, self.prefix = out, prefix

    def map_names(self) -> list[str]:
        return [self.prefix + n for n in (*self.maps, *(["normal"] if self.normal else []))]

    def stage(self, files: AtomicFiles) -> ET.Element:
        m, out = self.material, self.out
        textures = {
            name: place_texture(m, name, src, self.colorspace[name], map_destination(out, self.prefix + name), files)
            for name, src in self.maps.items()
        }
        bsdf = bsdf_element(m, textures)
        if self.normal is None:
            return bsdf
        dest = place_map(self.normal, map_destination(out, self.prefix + "normal"), True, "linear", 3, files)
        wrapper = ET.Element("bsdf", {"type": "normalmap"})
        wrapper.append(bitmap_element("normalmap", dest.name, raw=True))
        wrapper.append(bsdf)
        return wrapper


# -- carried inputs --------------------------------------------------------------------------------


def _carried_values(c: CarriedInput, channels: int, cutoff: float | None) -> np.ndarray:
    """A carried input's texture times its value, linear float32 [H, W, channels] (thresholded at ``cutoff``)."""
    from matremap.svbrdf.textures import read_image

    assert c.texture is not None
    ref = c.texture
    img = np.asarray(ref.bake() if ref.bake is not None else read_image(ref.path, ref.colorspace)[0], np.float32)
    img = np.atleast_3d(img)
    if ref.channels is not None:
        img = img[..., list(ref.channels)]
    img = img[..., :1] if channels == 1 else (np.repeat(img, 3, -1) if img.shape[-1] == 1 else img[..., :3])
    img = img * np.asarray(ref.scale, np.float32).reshape(-1)[:channels] * np.float32(_scalar(c.value, 1.0))
    return (img >= cutoff).astype(np.float32) if cutoff is not None else img


def _scalar(value: Any, default: float) -> float:
    return default if value is None else float(np.mean(np.asarray(value, dtype=float)))


def _carried_texture(c: CarriedInput, name: str, channels: int, stem: Path, cutoff: float | None, files) -> ET.Element:
    from matremap.svbrdf.textures import ImageInfo, write_image_like

    values = _carried_values(c, channels, cutoff)
    dest = stem.with_suffix(".exr")
    h, w, ch = values.shape
    write_image_like(files.stage(dest), values, ImageInfo("exr", "float", ch, w, h, "linear"), force=True)
    return bitmap_element(name, dest.name, raw=True)


def mask_wrapper(c: CarriedInput, out: Path, prefix: str, files: AtomicFiles, inner: ET.Element) -> ET.Element:
    """``inner`` inside a ``mask`` of the carried opacity."""
    cutoff = float(c.settings.get("cutoff", 0.5)) if c.settings.get("mode") == "mask" else None
    mask = ET.Element("bsdf", {"type": "mask"})
    if c.texture is not None:
        mask.append(_carried_texture(c, "opacity", 1, map_destination(out, prefix + "opacity"), cutoff, files))
    else:
        v = np.asarray(1.0 if c.value is None else c.value, dtype=float).reshape(-1)
        v = (v >= cutoff).astype(float) if cutoff is not None else v
        tag = "float" if v.size == 1 else "rgb"
        ET.SubElement(mask, tag, {"name": "opacity", "value": num(v[0]) if v.size == 1 else rgb_text(v)})
    mask.append(inner)
    return mask


def area_emitter(c: CarriedInput, out: Path, prefix: str, files: AtomicFiles) -> ET.Element:
    """The carried emission as an ``area`` emitter (radiance: colour, or texture times colour)."""
    emitter = ET.Element("emitter", {"type": "area"})
    if c.texture is not None:
        emitter.append(_carried_texture(c, "radiance", 3, map_destination(out, prefix + "emission"), None, files))
    else:
        v = np.broadcast_to(np.asarray(0.0 if c.value is None else c.value, dtype=float).reshape(-1), (3,))
        ET.SubElement(emitter, "rgb", {"name": "radiance", "value": rgb_text(v)})
    return emitter


# -- probe scenes -----------------------------------------------------------------------------------


def probe_scene(bsdfs: list[ET.Element], emitters: list[ET.Element | None]) -> ET.Element:
    """A scene of the BSDFs (each with an id) on probe spheres in a row along x, seen by the probe camera
    (pulled back to see them all) under a constant white environment."""
    from matremap.core.scene import Scene

    probe = Scene()
    r = float(probe.sphere_radius)
    spacing = 2.5 * r
    half = 0.5 * spacing * (len(bsdfs) - 1) + r
    wide = half / np.tan(np.radians(probe.effective_fov) / 2.0) + r  # the whole row in view
    distance = probe.camera_distance if len(bsdfs) == 1 else max(probe.camera_distance, wide)
    scene = ET.Element("scene", {"version": "3.0.0"})
    for name, value in (("spp", "64"), ("resolution", "256"), ("max_depth", "3")):
        ET.SubElement(scene, "default", {"name": name, "value": value})
    integrator = ET.SubElement(scene, "integrator", {"type": "path"})
    ET.SubElement(integrator, "integer", {"name": "max_depth", "value": "$max_depth"})
    ET.SubElement(integrator, "boolean", {"name": "hide_emitters", "value": "true"})
    sensor = ET.SubElement(scene, "sensor", {"type": "perspective"})
    ET.SubElement(sensor, "float", {"name": "fov", "value": num(probe.effective_fov)})
    ET.SubElement(sensor, "string", {"name": "fov_axis", "value": "x"})
    tw = ET.SubElement(sensor, "transform", {"name": "to_world"})
    ET.SubElement(tw, "lookat", {"origin": f"0, 0, {num(distance)}", "target": "0, 0, 0", "up": "0, 1, 0"})
    sampler = ET.SubElement(sensor, "sampler", {"type": "independent"})
    ET.SubElement(sampler, "integer", {"name": "sample_count", "value": "$spp"})
    film = ET.SubElement(sensor, "film", {"type": "hdrfilm"})
    ET.SubElement(film, "integer", {"name": "width", "value": "$resolution"})
    ET.SubElement(film, "integer", {"name": "height", "value": "$resolution"})
    ET.SubElement(film, "string", {"name": "pixel_format", "value": "rgb"})
    ET.SubElement(film, "rfilter", {"type": "box"})
    for i, (bsdf, emitter) in enumerate(zip(bsdfs, emitters, strict=True)):
        scene.append(bsdf)
        x = spacing * (i - 0.5 * (len(bsdfs) - 1))
        shape = ET.SubElement(scene, "shape", {"type": "sphere", "id": "probe_sphere" + ("" if i == 0 else f"_{i}")})
        # Mitsuba's local sphere frame -> world so that its UVs are matremap's (renderers/mitsuba3):
        # local x -> -z, y -> -x, z (the pole) -> +y, scaled by the radius
        rows = [[0.0, -r, 0.0, x], [0.0, 0.0, r, 0.0], [-r, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
        st = ET.SubElement(shape, "transform", {"name": "to_world"})
        ET.SubElement(st, "matrix", {"value": " ".join(num(v) for row in rows for v in row)})
        ET.SubElement(shape, "ref", {"id": bsdf.get("id", "material")})
        if emitter is not None:
            shape.append(emitter)
    background = ET.SubElement(scene, "emitter", {"type": "constant"})
    ET.SubElement(background, "rgb", {"name": "radiance", "value": "1, 1, 1"})
    return scene


def document(root: ET.Element, comment: str) -> str:
    ET.indent(root, space="    ")
    return HEADER + f"<!-- {comment} -->\n" + ET.tostring(root, encoding="unicode") + "\n"


def write_probe_scene(out: Path, result: Any, source: MaterialAsset | None, force: bool) -> Path:
    """One material on the probe sphere (module doc); carried opacity and emission of ``source`` kept."""
    conv = Converted(result, out, "")
    check_output(out, force, (".xml",))
    carried = dict(source.carried) if source is not None else {}
    extra = [n for n, key in (("opacity", "opacity"), ("emission", "emission")) if key in carried]
    check_map_destinations(out, [*conv.map_names(), *extra], force)
    notes: list[str] = []
    with AtomicFiles(force) as files:
        bsdf = conv.stage(files)
        if "opacity" in carried:
            bsdf = mask_wrapper(carried["opacity"], out, "", files, bsdf)
            notes.append("the source's opacity written as a mask wrapper around the BSDF")
        bsdf.set("id", "material")
        emitter = area_emitter(carried["emission"], out, "", files) if "emission" in carried else None
        if emitter is not None:
            notes.append("the source's emission written as an area emitter on the sphere (a Mitsuba BSDF cannot emit)")
        for key in sorted(set(carried) - {"opacity", "emission"}):
            notes.append(f"the source's {key} is not written: a Mitsuba BSDF has no {key} input")
        comment = f"written by matremap: {conv.material.spec.id} on the probe sphere under a white environment"
        files.write_text(out, document(probe_scene([bsdf], [emitter]), comment))
    if source is not None:
        source.notes.extend(notes)
    return out


def unique_ids(names: list[str]) -> list[str]:
    """The names as ids, made unique (``name``, ``name_2``, ...)."""
    seen: dict[str, int] = {}
    out = []
    for n in names:
        n = n or "material"
        seen[n] = seen.get(n, 0) + 1
        out.append(n if seen[n] == 1 else f"{n}_{seen[n]}")
    return out


def write_spheres_scene(
    out: Path, results: list[tuple[str, Any]], force: bool, assets: Mapping[str, MaterialAsset] | None = None
) -> Path:
    """Every material a top-level BSDF on a probe sphere of its own (module doc), with the opacity (a
    ``mask`` wrapper) and emission (an ``area`` emitter) ``assets`` carry for it."""
    if not results:
        raise MatremapError("no materials to write")
    check_output(out, force, (".xml",))
    ids = unique_ids([n for n, _ in results])
    convs = [Converted(r, out, f"{i}_") for i, (_, r) in zip(ids, results, strict=True)]
    carried = [dict(assets[n].carried) if assets and n in assets else {} for n, _ in results]
    extra = [f"{i}_{k}" for i, c in zip(ids, carried, strict=True) for k in ("opacity", "emission") if k in c]
    check_map_destinations(out, [*(n for c in convs for n in c.map_names()), *extra], force)
    with AtomicFiles(force) as files:
        bsdfs: list[ET.Element] = []
        emitters: list[ET.Element | None] = []
        for i, conv, c in zip(ids, convs, carried, strict=True):
            bsdf = conv.stage(files)
            if "opacity" in c:
                bsdf = mask_wrapper(c["opacity"], out, f"{i}_", files, bsdf)
            bsdf.set("id", i)
            bsdfs.append(bsdf)
            emitters.append(area_emitter(c["emission"], out, f"{i}_", files) if "emission" in c else None)
        comment = f"written by matremap: {len(bsdfs)} material(s), each on a probe sphere of its own"
        files.write_text(out, document(probe_scene(bsdfs, emitters), comment))
    return out


def write_copied_scene(out: Path, results: list[tuple[str, Any]], source: Path, force: bool) -> Path:
    """The source scene with the named BSDFs replaced (:mod:`matremap.formats.mitsuba_copy`)."""
    from matremap.formats.mitsuba_copy import SceneCopy

    check_output(out, force, (".xml",))
    copy = SceneCopy(source, out)
    ids = unique_ids([n for n, _ in results])
    convs = [Converted(r, out, f"{i.replace('/', '_')}_") for i, (_, r) in zip(ids, results, strict=True)]
    check_map_destinations(out, [n for c in convs for n in c.map_names()], force)
    with AtomicFiles(force, make_folders=True) as files:
        for (name, _), conv in zip(results, convs, strict=True):
            copy.replace(name, conv.stage(files))
        for path, text in copy.documents():
            files.write_text(path, text)
    return out


__all__ = [
    "Converted",
    "area_emitter",
    "bitmap_element",
    "bsdf_element",
    "check_textured",
    "mask_wrapper",
    "num",
    "place_texture",
    "probe_scene",
    "rgb_text",
    "write_copied_scene",
    "write_probe_scene",
    "write_spheres_scene",
]
