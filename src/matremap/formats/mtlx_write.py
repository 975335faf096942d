"""MaterialX documents written from gltf:metal-rough, gltf:pbr, mtlx:open_pbr_surface and mtlx:standard_surface
materials: one material, or every material of a file.

A ``gltf:*`` result becomes a ``gltf_pbr`` node (gltf:pbr's layers in its ``clearcoat``, ``sheen_*``,
``transmission``, ``thickness`` and ``attenuation_*`` inputs), an ``mtlx:*`` result the ``open_pbr_surface`` or
``standard_surface`` node whose inputs its parameters are named after (Standard Surface v1.0.1, OpenPBR Surface
v1.1 as MaterialX 1.39 declares them).

Sources: the MaterialX specification v1.39 (documents, ``surfacematerial``, ``nodename`` connections,
``colorspace`` on ``file`` inputs) and the ``gltf_pbr`` node of its data library
(``libraries/bxdf/gltf_pbr.mtlx``: ``base_color``, ``metallic``, ``roughness``, ``ior``, ``specular``,
``specular_color``, ``normal``, ``emissive`` x ``emissive_strength``, ``alpha`` with ``alpha_mode``
0 opaque / 1 mask / 2 blend and ``alpha_cutoff``, ``occlusion``). Every document is checked with
MaterialX's ``validate`` with the standard libraries loaded before it is written.

:func:`write` writes one ``gltf:metal-rough`` Material or MapSet as a document in MaterialX 1.39 with
one ``gltf_pbr`` node and a ``surfacematerial``; maps are copied beside the document as
``<stem>_<param>.png|.exr`` and read by ``image`` nodes (colour maps tagged ``srgb_texture`` or
``lin_rec709``; data maps as float images), a normal map through ``image`` -> ``normalmap``. The
source asset's carried inputs (:attr:`~matremap.formats.asset.MaterialAsset.carried`) go where
``gltf_pbr`` has them: emission into ``emissive`` (x ``emissive_strength`` when it exceeds 1),
opacity into ``alpha`` (with its mode), occlusion into ``occlusion`` (its strength applied to the
map). Values are written as Python's shortest round-tripping decimals, so reading the file back gives
the very same numbers.

:func:`write_all` writes every converted material of one input file into one document: a copy of the
source document when it is MaterialX -- each converted material's shader replaced by a ``gltf_pbr``
node of the same name, its emission and opacity connections carried onto it, the nodes and graphs
only the old shaders used removed, looks, material names, other materials and node names kept, and
every remaining ``file`` reference rewritten relative to the new document (``fileprefix`` folded in) --
else a fresh document holding all of them.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from matremap.core.atomic import AtomicFiles
from matremap.core.imageio import check_output
from matremap.core.material import Material
from matremap.errors import MatremapError
from matremap.formats.asset import CarriedInput, MaterialAsset, TextureRef
from matremap.formats.common import check_map_destinations, map_destination, place_map, result_parts
from matremap.formats.mtlx_document import EMISSION, FORMAT, MODEL, OPACITY, mx, parse_document, validate

#: gltf:metal-rough parameter -> gltf_pbr input
INPUTS = {
    "baseColor": "base_color",
    "metallic": "metallic",
    "roughness": "roughness",
    "ior": "ior",
    "specular": "specular",
    "specularColor": "specular_color",
}
#: gltf:pbr's layer parameters -> gltf_pbr inputs (MaterialX 1.39 ``libraries/bxdf/gltf_pbr.mtlx``)
LAYER_INPUTS = {
    "clearcoat": "clearcoat",
    "clearcoatRoughness": "clearcoat_roughness",
    "sheenColor": "sheen_color",
    "sheenRoughness": "sheen_roughness",
    "transmission": "transmission",
    "thickness": "thickness",
    "attenuationDistance": "attenuation_distance",
    "attenuationColor": "attenuation_color",
}
#: model -> (the shader node written for it, its parameter -> input); the MaterialX models' parameters are
#: their inputs' names (dialects/mtlx.py)
NODES: dict[str, tuple[str, dict[str, str] | None]] = {
    MODEL: ("gltf_pbr", INPUTS),
    "gltf:pbr": ("gltf_pbr", {**INPUTS, **LAYER_INPUTS}),
    "mtlx:open_pbr_surface": ("open_pbr_surface", None),
    "mtlx:standard_surface": ("standard_surface", None),
}
#: inputs of MaterialX type boolean (written true / false)
BOOLEAN_INPUTS = frozenset({"geometry_thin_walled", "thin_walled"})
#: the input of each written shader that takes a normal map
NORMAL_INPUT = {"gltf_pbr": "normal", "standard_surface": "normal", "open_pbr_surface": "geometry_normal"}
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def _fmt(v: Any) -> str:
    return ", ".join(repr(float(x)) for x in np.asarray(v, dtype=float).reshape(-1))


def _name(text: str | None, fallback: str = "material") -> str:
    """A valid MaterialX element name from ``text`` (letters, digits, underscores; not starting with a digit)."""
    name = re.sub(r"[^A-Za-z0-9_]", "_", text or "")
    return name if _NAME.fullmatch(name) else (f"M_{name}" if name else fallback)


def _image(doc: Any, name: str, typ: str, file: str, colorspace: str | None) -> Any:
    img = doc.addNode("image", doc.createValidChildName(name), typ)
    f = img.addInput("file", "filename")
    f.setValueString(file)
    if colorspace is not None and typ.startswith("color"):
        f.setColorSpace("srgb_texture" if colorspace == "srgb" else "lin_rec709")
    return img


def add_material(
    doc: Any,
    m: Material,
    maps: dict[str, str],
    colorspace: dict[str, str],
    normal: str | None,
    name: str,
    shader_name: str | None = None,
) -> Any:
    """Add the shader of ``m``'s model (:data:`NODES`: ``gltf_pbr``, ``open_pbr_surface`` or
    ``standard_surface``; named ``shader_name``, else ``SR_<name>``) to ``doc``: ``maps`` are file names
    (relative to the document) for textured parameters, ``colorspace`` their encodings (srgb/linear),
    ``normal`` the normal map's file. glTF's attenuationDistance 0 (infinity) is left at the node's default.
    Returns the shader node."""
    category, table = NODES[m.model]
    table = table if table is not None else {p.name: p.name for p in m.spec.params}
    shader = doc.addNode(category, shader_name or doc.createValidChildName(f"SR_{name}"), "surfaceshader")
    for param, input_name in table.items():
        if param == "attenuationDistance" and param not in maps and float(m.values[param][0]) == 0.0:
            continue
        if input_name in BOOLEAN_INPUTS:  # OpenPBR's thin-walled switch: a boolean, not a map
            shader.addInput(input_name, "boolean").setValueString("true" if m.values[param][0] >= 0.5 else "false")
            continue
        typ = "color3" if m.spec.param(param).channels == 3 else "float"
        inp = shader.addInput(input_name, typ)
        if param in maps:
            inp.setNodeName(_image(doc, f"image_{name}_{param}", typ, maps[param], colorspace[param]).getName())
        else:
            inp.setValueString(_fmt(m.values[param]))
    if normal is not None:
        img = _image(doc, f"image_{name}_normal", "vector3", normal, None)
        nm = doc.addNode("normalmap", doc.createValidChildName(f"normalmap_{name}"), "vector3")
        nm.addInput("in", "vector3").setNodeName(img.getName())
        shader.addInput(NORMAL_INPUT[category], "vector3").setNodeName(nm.getName())
    return shader


def build_document(
    m: Material, maps: dict[str, str], colorspace: dict[str, str], normal: str | None, name: str = "material"
) -> Any:
    """A MaterialX 1.39 document holding one gltf:metal-rough material (see :func:`add_material`)."""
    doc = mx().createDocument()
    doc.setColorSpace("lin_rec709")
    shader = add_material(doc, m, maps, colorspace, normal, name)
    mat = doc.addNode("surfacematerial", name, "material")
    mat.addInput("surfaceshader", "surfaceshader").setNodeName(shader.getName())
    return doc


def _serialise(doc: Any, out: Path) -> str:
    ok, why = validate(doc)
    if not ok:  # pragma: no cover - a bug here, not the user's
        raise MatremapError(f"the MaterialX document for {out} does not validate: {why}")
    text: str = mx().writeToXmlString(doc)
    return text


def _place_maps(result: Any, out: Path, prefix: str, files: AtomicFiles) -> tuple[Material, dict, dict, str | None]:
    """Stage the maps of a result beside ``out`` as ``<stem>_<prefix><param>``; (material, file names,
    colour spaces, normal map file)."""
    m, maps, cs, normal = result_parts(result, "the MaterialX writer", tuple(NODES))
    names: dict[str, str] = {}
    spaces: dict[str, str] = {}
    for param, src in maps.items():
        names[param], spaces[param] = _place_texture(m, param, src, cs[param], out, prefix, files)
    nfile = None
    if normal is not None:
        nfile = place_map(normal, map_destination(out, f"{prefix}normal"), True, "linear", 3, files).name
    return m, names, spaces, nfile


def _place_texture(
    m: Material, param: str, src: Path, colorspace: str, out: Path, prefix: str, files: AtomicFiles
) -> tuple[str, str]:
    """Stage the map of ``param`` beside ``out``; (its file name, the colour space to declare).
    Colour maps keep any encoding (it is declared); data maps must hold linear values."""
    from matremap.svbrdf.textures import image_info

    p = m.spec.param(param)
    info = image_info(src, colorspace)
    keep = p.channels == 3 or colorspace == "linear"
    dest = place_map(src, map_destination(out, f"{prefix}{param}"), keep, colorspace, p.channels, files)
    kept = dest.suffix.lower() == "." + info.format and keep
    return dest.name, colorspace if kept else "linear"


def write(out: str | Path, result: Any, source: MaterialAsset | None = None, force: bool = False) -> Path:
    """Write ``result`` (a ``gltf:metal-rough`` Material or MapSet) as a MaterialX document with a
    ``gltf_pbr`` shader and a ``surfacematerial`` named as the source material (when the name is a valid
    MaterialX name); maps are copied beside it and the source's carried inputs written into the
    shader. With a MaterialX ``source``: a copy of its document with that material's shader replaced (its
    looks, node names and other materials kept, as :func:`write_all` copies one; the glTF and USD writers
    copy their sources the same way). The document and its files are written together or not at all."""
    out = Path(out)
    result_parts(result, "the MaterialX writer", tuple(NODES))
    if source is not None and source.format == FORMAT and Path(source.path).suffix.lower() == ".mtlx":
        return write_all(out, [(source.name, result)], Path(source.path), force)
    check_output(out, force, (".mtlx",))
    carried = dict(source.carried) if source is not None else {}
    names = [*getattr(result, "maps", {}), *(["normal"] if getattr(result, "normal", None) else [])]
    check_map_destinations(out, [*names, *(k for k, c in carried.items() if c.texture is not None)], force)
    name = _name(source.name) if source is not None and source.name else "material"
    with AtomicFiles(force) as files:
        m, maps, spaces, nfile = _place_maps(result, out, "", files)
        doc = build_document(m, maps, spaces, nfile, name)
        shader = doc.getNode(doc.getNode(name).getInput("surfaceshader").getNodeName())
        add_carried(doc, shader, carried, out, name, "", files, source.notes if source is not None else None)
        files.write_text(out, _serialise(doc, out))
    return out


# ---------------------------------------------------------------------------------------------
# Carried inputs (emission, opacity, occlusion)


def add_carried(
    doc: Any,
    shader: Any,
    carried: dict[str, CarriedInput],
    out: Path,
    name: str,
    prefix: str,
    files: AtomicFiles,
    notes: list[str] | None = None,
) -> None:
    """Write a source's carried inputs into shader ``shader`` of material ``name`` (see the module docstring);
    texture files are staged beside ``out`` as ``<stem>_<prefix><key>.exr``. An ``open_pbr_surface`` or
    ``standard_surface`` node takes the emission colour (weight 1) and the opacity in its own inputs
    (:data:`~matremap.formats.mtlx_document.EMISSION`, ``OPACITY``); it has no occlusion, which is then left
    out with a note in ``notes``."""
    category = shader.getCategory()
    if category != "gltf_pbr":
        _add_carried_surface(doc, shader, carried, out, name, prefix, files, notes)
        return
    emission = carried.get("emission")
    if emission is not None:
        v = np.broadcast_to(np.asarray(emission.value if emission.value is not None else 1.0, float), (3,))
        _set(doc, shader, "emissive", "color3", v, emission.texture, out, f"{prefix}emission", name, files)
    opacity = carried.get("opacity")
    if opacity is not None:
        v = np.asarray(opacity.value if opacity.value is not None else 1.0, float).reshape(-1)[:1]
        _set(doc, shader, "alpha", "float", v, opacity.texture, out, f"{prefix}opacity", name, files)
        mode = 1 if opacity.settings.get("mode") == "mask" else 2
        shader.addInput("alpha_mode", "integer").setValueString(str(mode))
        if mode == 1:
            shader.addInput("alpha_cutoff", "float").setValueString(repr(float(opacity.settings.get("cutoff", 0.5))))
    occlusion = carried.get("occlusion")
    if occlusion is not None and occlusion.texture is not None:
        strength = float(np.asarray(occlusion.value if occlusion.value is not None else 1.0).reshape(-1)[0])
        dest = _texture_file(
            occlusion.texture, 1, out, f"{prefix}occlusion", files, lambda a: 1.0 + strength * (a - 1.0)
        )
        img = _image(doc, f"image_{name}_occlusion", "float", dest, None)
        shader.addInput("occlusion", "float").setNodeName(img.getName())


def _add_carried_surface(
    doc: Any,
    shader: Any,
    carried: dict[str, CarriedInput],
    out: Path,
    name: str,
    prefix: str,
    files: AtomicFiles,
    notes: list[str] | None,
) -> None:
    """:func:`add_carried` for an ``open_pbr_surface`` / ``standard_surface`` node."""
    category = shader.getCategory()
    colour, weight = EMISSION[category]
    emission = carried.get("emission")
    if emission is not None:
        v = np.broadcast_to(np.asarray(emission.value if emission.value is not None else 1.0, float), (3,))
        _set(doc, shader, colour, "color3", v, emission.texture, out, f"{prefix}emission", name, files)
        shader.addInput(weight, "float").setValueString("1.0")
    opacity = carried.get("opacity")
    if opacity is not None:
        v = np.asarray(opacity.value if opacity.value is not None else 1.0, float).reshape(-1)[:1]
        typ, channels = ("color3", 3) if category == "standard_surface" else ("float", 1)
        _set(
            doc,
            shader,
            OPACITY[category],
            typ,
            np.repeat(v, channels),
            opacity.texture,
            out,
            f"{prefix}opacity",
            name,
            files,
        )
        if opacity.settings.get("mode") == "mask" and notes is not None:
            notes.append(f"the source's opacity mask is written as {category}'s plain opacity (no cutoff there)")
    if carried.get("occlusion") is not None and notes is not None:
        notes.append(f"the source's occlusion is not written: {category} has no occlusion input")


def _set(
    doc: Any,
    shader: Any,
    input_name: str,
    typ: str,
    value: np.ndarray,
    texture: TextureRef | None,
    out: Path,
    key: str,
    name: str,
    files: AtomicFiles,
) -> None:
    """Set ``input_name`` to ``value`` (x a texture when there is one); an emissive colour past 1 is
    written as a colour in [0, 1] x ``emissive_strength``."""
    inp = shader.addInput(input_name, typ)
    if texture is None:
        peak = float(np.max(value))
        if input_name == "emissive" and peak > 1.0:
            inp.setValueString(_fmt(value / peak))
            shader.addInput("emissive_strength", "float").setValueString(repr(peak))
        else:
            inp.setValueString(_fmt(value))
        return
    channels = 3 if typ == "color3" else 1
    dest = _texture_file(texture, channels, out, key, files, lambda a: a * value.astype(np.float32))
    img = _image(doc, f"image_{name}_{input_name}", typ, dest, "linear")
    inp.setNodeName(img.getName())


def _texture_file(
    ref: TextureRef, channels: int, out: Path, key: str, files: AtomicFiles, transform: Any = None
) -> str:
    """Stage the values of texture ``ref`` (channels picked, its scale and ``transform`` applied) beside
    ``out`` as a linear float EXR ``<stem>_<key>.exr``; its file name."""
    from matremap.svbrdf.textures import ImageInfo, read_image, write_image_like

    if ref.bake is not None:
        image = np.atleast_3d(np.asarray(ref.bake(), dtype=np.float32))
    else:
        image = np.atleast_3d(read_image(ref.path, ref.colorspace, colour=True)[0]).astype(np.float32)
    if ref.channels is not None:
        image = image[..., list(ref.channels)]
    image = image[..., :channels] if image.shape[-1] >= channels else np.repeat(image[..., :1], channels, axis=-1)
    image = image * np.asarray(ref.scale, dtype=np.float32).reshape(-1)[: image.shape[-1]]
    if transform is not None:
        image = np.asarray(transform(image), dtype=np.float32)
    if not np.all(np.isfinite(image)):
        raise MatremapError(f"{ref.path}: the carried texture {key} has non-finite values")
    dest = map_destination(out, key).with_suffix(".exr")
    h, w, c = image.shape
    write_image_like(files.stage(dest), image, ImageInfo("exr", "float", c, w, h, "linear"), force=True)
    return dest.name


# ---------------------------------------------------------------------------------------------
# Every material of a file in one document


def write_all(
    out: Path,
    results: list[tuple[str, Any]],
    source: Path | None,
    force: bool = False,
    assets: Mapping[str, MaterialAsset] | None = None,
) -> Path:
    """Write every ``(material name, gltf:metal-rough result)`` into one MaterialX document ``out``: a copy
    of MaterialX document ``source`` with those materials' shaders replaced, else a fresh document
    holding all of them (see the module docstring). Maps go beside it as ``<stem>_<material>_<param>``;
    the files the copy still references (the other materials' textures) are copied into ``<stem>_files/``.
    A fresh document carries the emission, opacity and occlusion of ``assets`` (the materials as read from a
    source of another format)."""
    out = Path(out)
    check_output(out, force, (".mtlx",))
    if not results:
        raise MatremapError(f"{out}: no material to write")
    with AtomicFiles(force, make_folders=True) as files:
        if source is None:
            doc = mx().createDocument()
            doc.setColorSpace("lin_rec709")
            for name, result in results:
                mname = doc.createValidChildName(_name(name))
                m, maps, spaces, nfile = _place_maps(result, out, f"{mname}_", files)
                shader = add_material(doc, m, maps, spaces, nfile, mname)
                if assets and name in assets:
                    add_carried(doc, shader, dict(assets[name].carried), out, mname, f"{mname}_", files)
                mat = doc.addNode("surfacematerial", mname, "material")
                mat.addInput("surfaceshader", "surfaceshader").setNodeName(shader.getName())
        else:
            doc = parse_document(source)
            refs = _file_references(doc, source)
            _replace_shaders(doc, results, out, source, files)
            _copy_references(doc, refs, source, out, files)
        files.write_text(out, _serialise(doc, out))
    return out


def _file_references(doc: Any, source: Path) -> dict[str, str]:
    """Name path -> the text of every ``file`` input of the source document, ``fileprefix`` applied (the
    attribute is then removed: the copy's references are rewritten relative to its own folder)."""
    refs = {
        el.getNamePath(): el.getResolvedValueString()
        for el in doc.traverseTree()
        if el.getCategory() == "input" and el.getType() == "filename" and el.getValueString()
    }
    for el in doc.traverseTree():
        if el.hasAttribute("fileprefix"):
            el.removeAttribute("fileprefix")
    return refs


def _copy_references(doc: Any, refs: dict[str, str], source: Path, out: Path, files: AtomicFiles) -> None:
    """Copy the files the copied document still references (confined to the source's folder and the
    allowed ones) into ``<stem>_files/`` beside ``out`` and point the references there."""
    from matremap.formats.confine import resolve_reference

    folder = f"{out.stem}_files"
    placed: dict[Path, str] = {}
    for el in doc.traverseTree():
        text = refs.get(el.getNamePath()) if el.getCategory() == "input" else None
        if not text or el.getValueString() == "" or el.getType() != "filename":
            continue
        src = resolve_reference(text, source.resolve().parent, f"{source}: {el.getParent().getName()!r} file")
        if src not in placed:
            if not src.is_file():
                raise MatremapError(f"{source}: texture {text} of {el.getParent().getName()!r} not found at {src}")
            stem, n = src.stem, 1
            name = src.name
            while name in placed.values():
                n += 1
                name = f"{stem}_{n}{src.suffix}"
            placed[src] = name
            files.copy(src, out.parent / folder / name)
        el.setValueString(f"{folder}/{placed[src]}")


def _replace_shaders(doc: Any, results: list[tuple[str, Any]], out: Path, source: Path, files: AtomicFiles) -> None:
    """Replace the shader of each named material of ``doc`` by a ``gltf_pbr`` node of its result."""
    m_x = mx()
    replaced: list[Any] = []
    for name, result in results:
        mat = doc.getNode(name)
        if mat is None or mat.getCategory() != "surfacematerial":
            raise MatremapError(f"{source} has no surfacematerial {name!r}; the converted materials do not match it")
        shaders = m_x.getShaderNodes(mat)
        if not shaders or shaders[0].getNamePath() != shaders[0].getName():
            raise MatremapError(f"{source}: material {name!r} has no surface shader node to replace")
        old = shaders[0]
        m, maps, spaces, nfile = _place_maps(result, out, f"{_name(name)}_", files)
        shared = any(
            other.getName() != name and any(s.getName() == old.getName() for s in m_x.getShaderNodes(other))
            for other in doc.getMaterialNodes()
        )
        new = add_material(doc, m, maps, spaces, nfile, _name(name), doc.createValidChildName(f"SR_{_name(name)}"))
        _carry_connections(doc, old, new)
        mat.getInput("surfaceshader").setNodeName(new.getName())
        if not shared:
            old_name = old.getName()
            replaced.append(old)
            doc.removeNode(old_name)
            new.setName(old_name)  # the node names of the source are kept
            mat.getInput("surfaceshader").setNodeName(old_name)
    _prune(doc, replaced)


def _carry_connections(doc: Any, old: Any, new: Any) -> None:
    """Give ``gltf_pbr`` node ``new`` the emission and opacity of shader ``old`` -- its values, or the same
    connections (a ``multiply`` where both colour and weight are connected)."""
    cat = old.getCategory()
    if cat == new.getCategory():
        names = ("emissive", "emissive_strength", "alpha", "alpha_mode", "alpha_cutoff", "occlusion")
        for n in names if cat == "gltf_pbr" else (*EMISSION.get(cat, ()), OPACITY.get(cat, "")):
            if n and old.getInput(n) is not None:
                new.addInput(n, old.getInput(n).getType()).copyContentFrom(old.getInput(n))
        return
    if new.getCategory() != "gltf_pbr":
        carried = [n for n in (*EMISSION.get(cat, ()), OPACITY.get(cat, "")) if n and old.getInput(n) is not None]
        if carried:
            raise MatremapError(
                f"{old.getName()}: its {', '.join(carried)} cannot be carried from a {cat} node into a "
                f"{new.getCategory()} one yet; write the material into a new file (not a copy of the source)"
            )
        return
    if cat in EMISSION:
        _carry_emission(doc, old, new, *EMISSION[cat])
    if cat in OPACITY:
        _carry_opacity(doc, old, new, OPACITY[cat])


def _connected(inp: Any) -> bool:
    return inp is not None and bool(inp.getAttribute("nodename") or inp.getAttribute("nodegraph"))


def _link(src: Any, dst: Any) -> None:
    for attr in ("nodename", "nodegraph", "output"):
        if src.getAttribute(attr):
            dst.setAttribute(attr, src.getAttribute(attr))


def _value(node: Any, name: str, default: float | tuple[float, ...]) -> np.ndarray:
    inp = node.getInput(name)
    text = inp.getValueString() if inp is not None else ""
    if not text:
        nd = node.getNodeDef()
        ndi = nd.getActiveInput(name) if nd is not None else None
        text = ndi.getValueString() if ndi is not None else ""
    try:
        return np.asarray([float(x) for x in text.replace(",", " ").split()] or default, dtype=float)
    except ValueError:
        return np.asarray(default, dtype=float)


def _carry_emission(doc: Any, old: Any, new: Any, colour: str, weight: str) -> None:
    c_in, w_in = old.getInput(colour), old.getInput(weight)
    c, w = _value(old, colour, (1.0, 1.0, 1.0)), float(_value(old, weight, 0.0)[0])
    if not _connected(c_in) and not _connected(w_in):
        v = np.broadcast_to(c, (3,)) * w
        if np.any(v != 0):
            peak = float(np.max(v))
            new.addInput("emissive", "color3").setValueString(_fmt(v / peak if peak > 1 else v))
            if peak > 1:
                new.addInput("emissive_strength", "float").setValueString(repr(peak))
        return
    if _connected(w_in):
        mul = doc.addNode("multiply", doc.createValidChildName(f"{new.getName()}_emission"), "color3")
        a, b = mul.addInput("in1", "color3"), mul.addInput("in2", "float")
        _link(c_in, a) if _connected(c_in) else a.setValueString(_fmt(c))
        _link(w_in, b)
        new.addInput("emissive", "color3").setNodeName(mul.getName())
        return
    if w == 0.0:
        return
    _link(c_in, new.addInput("emissive", "color3"))
    new.addInput("emissive_strength", "float").setValueString(repr(w))


def _carry_opacity(doc: Any, old: Any, new: Any, name: str) -> None:
    inp = old.getInput(name)
    colour = old.getCategory() == "standard_surface"
    if not _connected(inp):
        a = float(np.mean(_value(old, name, 1.0)))
        if a < 1.0:
            new.addInput("alpha", "float").setValueString(repr(a))
            new.addInput("alpha_mode", "integer").setValueString("2")
        return
    alpha = new.addInput("alpha", "float")
    if colour:  # a colour opacity: the mean of its channels, as the reader carries it
        conv = doc.addNode("convert", doc.createValidChildName(f"{new.getName()}_opacity_vector"), "vector3")
        _link(inp, conv.addInput("in", "color3"))
        dot = doc.addNode("dotproduct", doc.createValidChildName(f"{new.getName()}_opacity"), "float")
        dot.addInput("in1", "vector3").setNodeName(conv.getName())
        dot.addInput("in2", "vector3").setValueString(_fmt([1 / 3, 1 / 3, 1 / 3]))
        alpha.setNodeName(dot.getName())
    else:
        _link(inp, alpha)
    new.addInput("alpha_mode", "integer").setValueString("2")


def _prune(doc: Any, removed: list[Any]) -> None:
    """Remove the document-level nodes and nodegraphs that only the removed shaders used."""
    candidates: set[str] = set()
    for old in removed:
        for inp in old.getInputs():
            candidates.update(x for x in (inp.getAttribute("nodename"), inp.getAttribute("nodegraph")) if x)
    while candidates:
        used = _referenced(doc)
        gone = {c for c in candidates if c not in used}
        if not gone:
            return
        for c in gone:
            el = doc.getChild(c)
            if el is None:
                continue
            for inp in el.getInputs():
                candidates.update(x for x in (inp.getAttribute("nodename"), inp.getAttribute("nodegraph")) if x)
            doc.removeChild(c)
        candidates -= gone


def _referenced(doc: Any) -> set[str]:
    """The names of document-level nodes and nodegraphs that some element of ``doc`` connects to."""
    used: set[str] = set()
    ports = [p for el in [*doc.getNodes(), *doc.getNodeGraphs()] for p in el.getInputs()] + list(doc.getOutputs())
    for p in ports:
        used.update(x for x in (p.getAttribute("nodegraph"), p.getAttribute("nodename")) if x)
    return used
