"""MaterialX documents (.mtlx) in and out, as glTF metallic-roughness materials.

Sources: the MaterialX specification v1.39 (https://materialx.org/Specification.html: documents,
``surfacematerial``, node connections through ``nodename`` / ``nodegraph`` + ``output``, the
``colorspace`` attribute and its inheritance, which applies to color3/color4 data only), the glTF
PBR node of MaterialX's data library (``libraries/bxdf/gltf_pbr.mtlx``, inputs ``base_color``,
``metallic``, ``roughness``, ``ior``, ``specular``, ``specular_color``, ``normal``), the Autodesk
Standard Surface specification v1.0.1 and the OpenPBR Surface specification v1.1 (their inputs and
defaults as MaterialX 1.39's library declares them). Parsing and validation use the MaterialX
Python API (``mx.readFromXmlFile``, ``doc.validate()``); the standard library is loaded only for
the nodes' default values.

**Reading.** :func:`read` picks a ``surfacematerial`` by name or index (the first by default; a
document without materials falls back to its shader nodes) and reads its surface shader:

* ``gltf_pbr`` maps one to one onto ``gltf:metal-rough`` (base_color -> baseColor, metallic,
  roughness, ior, specular, specular_color -> specularColor);
* ``standard_surface`` (and ``open_pbr_surface``) go through matremap's hand-made translation
  of their base/specular/metalness subset: base_color x base -> baseColor, metalness -> metallic,
  specular_roughness -> roughness (both are alpha = r^2), specular_IOR -> ior, specular ->
  specular, specular_color -> specularColor (OpenPBR: base_color x base_weight, base_metalness,
  specular_roughness, specular_ior, specular_weight, specular_color). The translation is approximate
  -- Standard Surface's metal Fresnel uses specular_color as an edge tint that glTF's has no slot
  for, its dielectric lobe is energy-conserving differently -- so the asset carries a warning note
  that says so and lists every input it does not remap whose value differs from the node's
  default (coat, sheen, subsurface, transmission, emission, thin film, anisotropy, ...).

The document is untrusted: before MaterialX's own parser sees it, it is parsed with
:func:`~matremap.formats.common.parse_untrusted_xml` (entity declarations and nesting past
:data:`~matremap.formats.common.MAX_XML_DEPTH` refused), ``xi:include`` is refused (MaterialX would
read the included file from anywhere), and MaterialX then reads the very bytes that were checked.
Texture files must lie in the document's folder or a folder the user allowed
(:mod:`matremap.formats.confine`).

Texture inputs are ``image``, ``tiledimage`` and ``gltf_image`` nodes (in the document or a
nodegraph), optionally behind an ``extract`` or ``separate3`` node that picks one channel (a packed
occlusion-roughness-metallic map); ``gltf_image``'s ``factor`` becomes the texture's scale. A
texture's file is relative to the document (``fileprefix`` applied) and its colour space is the
``colorspace`` attribute in effect on the ``file`` input: ``srgb_texture`` -> sRGB,
``lin_rec709``/``lin_srgb``/``raw``/none -> linear; any other is refused. Float-typed images are
data and linear whatever the attribute says (the spec transforms colour types only). A ``normal``
input fed by a ``normalmap`` (or ``gltf_normalmap``) node gives the asset's normal map.

**Writing.** :func:`write` writes a ``gltf:metal-rough`` Material or MapSet as a document with one
``gltf_pbr`` node and a ``surfacematerial``; maps are copied beside the document as
``<stem>_<param>.png|.exr`` and read by ``image`` nodes (colour maps tagged ``srgb_texture`` or
``lin_rec709``; data maps as float images), a normal map through ``image`` -> ``normalmap``. Values
are written as Python's shortest round-tripping decimals, so reading the file back gives the very
same numbers.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from matremap.core.atomic import AtomicFiles
from matremap.core.imageio import check_output
from matremap.core.material import Material
from matremap.dialects import get_model
from matremap.errors import MatremapError
from matremap.formats.asset import MaterialAsset, TextureRef
from matremap.formats.common import (
    check_map_destinations,
    map_destination,
    parse_untrusted_xml,
    pick_material,
    place_map,
    result_parts,
)
from matremap.formats.confine import Confinement, resolve_reference

FORMAT = "mtlx"
MODEL = "gltf:metal-rough"
INSTALL_HINT = "reading and writing MaterialX needs its Python package: pip install 'matremap[materialx]'"

#: shader node category -> {its input: gltf:metal-rough parameter}; the base colour weight is applied apart
SHADERS: dict[str, dict[str, str]] = {
    "gltf_pbr": {
        "base_color": "baseColor",
        "metallic": "metallic",
        "roughness": "roughness",
        "ior": "ior",
        "specular": "specular",
        "specular_color": "specularColor",
    },
    "standard_surface": {
        "base_color": "baseColor",
        "metalness": "metallic",
        "specular_roughness": "roughness",
        "specular_IOR": "ior",
        "specular": "specular",
        "specular_color": "specularColor",
    },
    "open_pbr_surface": {
        "base_color": "baseColor",
        "base_metalness": "metallic",
        "specular_roughness": "roughness",
        "specular_ior": "ior",
        "specular_weight": "specular",
        "specular_color": "specularColor",
    },
}
#: the input that multiplies base_color
_WEIGHT = {"standard_surface": "base", "open_pbr_surface": "base_weight"}
#: inputs that are not part of the appearance on the probe (geometry and connections handled apart)
_NOT_LISTED = {"normal", "tangent", "geometry_normal", "geometry_tangent"}
_IMAGES = ("image", "tiledimage", "gltf_image")
_SRGB = ("srgb_texture",)
_LINEAR = ("", "lin_rec709", "lin_srgb", "raw", "none", "linear")


def _mx():
    try:
        import MaterialX as mx
    except ImportError as e:
        raise MatremapError(f"{INSTALL_HINT} ({e})") from None
    return mx


@lru_cache(maxsize=1)
def _library():
    """MaterialX's standard data library (node definitions and their defaults)."""
    mx = _mx()
    lib = mx.createDocument()
    mx.loadLibraries(mx.getDefaultDataLibraryFolders(), mx.getDefaultDataSearchPath(), lib)
    return lib


def _parse(text: str, where: str, channels: int) -> list[float]:
    try:
        nums = [float(x) for x in text.replace(",", " ").split()]
    except ValueError:
        raise MatremapError(f"{where}: value {text!r} is not a number") from None
    if len(nums) not in (1, channels) or not nums:
        raise MatremapError(f"{where}: value {text!r} should have {channels} component(s)")
    return nums


@dataclass
class _Ctx:
    """The document being read, the notes gathered, and where its texture files may lie."""

    path: Path
    notes: list[str]
    confinement: Confinement | None = None

    def file(self, rel: str, what: str) -> Path:
        """The file a ``file`` input names (relative to the document, or absolute), confined."""
        return resolve_reference(rel, self.path.resolve().parent, f"{self.path}: {what}", self.confinement)


def _defaults(node) -> dict[str, str]:
    """Input name -> default value string of a shader node, from its definition."""
    nd = node.getNodeDef()
    if nd is None:
        lib = _library()
        cands = [d for d in lib.getMatchingNodeDefs(node.getCategory()) if d.getType() == node.getType()]
        nd = cands[0] if cands else None
    if nd is None:
        return {}
    return {i.getName(): i.getValueString() for i in nd.getActiveInputs()}


def _texture(ctx: _Ctx, node, param: str, colour: bool) -> TextureRef:
    """A TextureRef of an image node (behind an optional channel picker)."""
    channels: tuple[int, ...] | None = None
    if node.getCategory() == "extract":
        src, idx = node.getInput("in"), node.getInput("index")
        up = src.getConnectedNode() if src is not None else None
        if up is None:
            raise MatremapError(f"{ctx.path}: extract node {node.getName()!r} for {param} is not fed by an image")
        channels = (int(float(idx.getValueString())) if idx is not None else 0,)
        node = up
    if node.getCategory() not in _IMAGES:
        raise MatremapError(
            f"{ctx.path}: {param} is driven by a {node.getCategory()!r} node; matremap reads "
            f"{', '.join(_IMAGES)} textures (bake the graph into an image)"
        )
    f = node.getInput("file")
    if f is None or not f.getResolvedValueString():
        raise MatremapError(f"{ctx.path}: image node {node.getName()!r} for {param} has no file; set its file input")
    rel = Path(f.getResolvedValueString())
    path = ctx.file(f.getResolvedValueString(), f"image node {node.getName()!r} file")
    if not path.is_file():
        raise MatremapError(
            f"{ctx.path}: texture {rel} for {param} not found at {path}; put it beside the "
            f"document or fix its file input"
        )
    cs = (f.getActiveColorSpace() or "").strip()
    if cs.lower() in _SRGB:
        colorspace = "srgb"
    elif cs.lower() in _LINEAR:
        colorspace = "linear"
    else:
        raise MatremapError(
            f"{ctx.path}: texture {rel.name} has colour space {cs!r}; matremap reads srgb_texture "
            f"and lin_rec709 (raw) textures, convert it to one of these"
        )
    if colorspace == "srgb" and (not colour or node.getType() in ("float", "vector2", "vector3")):
        ctx.notes.append(
            f"{rel.name}: {cs} ignored for {param}, a {node.getType()} texture (MaterialX transforms colour data only)"
        )
        colorspace = "linear"
    scale: float | tuple[float, ...] = 1.0
    factor = node.getInput("factor")
    if factor is not None and factor.getValueString():
        nums = _parse(factor.getValueString(), f"{ctx.path}: {node.getName()}.factor", 3)
        scale = nums[0] if len(nums) == 1 else tuple(nums)
        if channels is not None and len(nums) > 1:  # extract after the factor: the picked channel's factor
            if channels[0] >= len(nums):
                raise MatremapError(
                    f"{ctx.path}: extract index {channels[0]} for {param} is beyond the {node.getType()} image"
                )
            scale = nums[channels[0]]
    for unsupported in ("texcoord", "scale", "rotate", "offset", "uvtiling", "uvoffset"):
        i = node.getInput(unsupported)
        if (
            i is not None
            and (i.getValueString() or i.getConnectedNode() is not None)
            and not (node.getCategory() == "tiledimage" and i.getValueString() in ("1.0, 1.0", "1, 1", "0.0, 0.0"))
        ):
            ctx.notes.append(
                f"{rel.name}: {unsupported} on {node.getName()!r} ignored (maps are read on the sphere's own UVs)"
            )
    return TextureRef(path.resolve(), channels, colorspace, scale)


def _connected(ctx: _Ctx, inp, param: str, colour: bool) -> TextureRef | None:
    """The texture feeding input ``inp``, or None when it holds a value."""
    node = inp.getConnectedNode()
    if node is None:
        if inp.getNodeName() or inp.getNodeGraphString() or inp.getInterfaceName():
            raise MatremapError(
                f"{ctx.path}: input {inp.getName()} names a node or graph that does not exist; fix the connection"
            )
        return None
    channel: int | None = None
    output = inp.getConnectedOutput()
    out_name = inp.getOutputString() or (output.getOutputString() if output is not None else "")
    if node.getCategory() == "separate3":
        if out_name not in ("outr", "outg", "outb", "outx", "outy", "outz"):
            raise MatremapError(f"{ctx.path}: {param} takes separate3 output {out_name!r}; use outr, outg or outb")
        channel = "rgb".index(out_name[-1]) if out_name[-1] in "rgb" else "xyz".index(out_name[-1])
        src = node.getInput("in")
        up = src.getConnectedNode() if src is not None else None
        if up is None:
            raise MatremapError(f"{ctx.path}: separate3 node {node.getName()!r} is not fed by an image")
        ref = _texture(ctx, up, param, colour)
        return TextureRef(ref.path, (channel,), ref.colorspace, ref.scale)
    return _texture(ctx, node, param, colour)


def _shader_asset(ctx: _Ctx, shader, name: str, index: int, doc) -> MaterialAsset:
    """The asset of surface shader node ``shader`` (material ``name``, the ``index``-th of ``doc``)."""
    cat = shader.getCategory()
    if cat not in SHADERS:
        raise MatremapError(f"{ctx.path}: material {name!r} uses a {cat!r} shader; matremap reads {', '.join(SHADERS)}")
    inputs = _ShaderInputs(ctx, shader)
    constants, textures = inputs.read_all()
    inputs.apply_base_weight(constants, textures)
    normal = _normal_map(ctx, shader)
    lost = lost_look(shader)
    _note_skipped(ctx, cat, inputs.skipped())
    _clamp_colours(constants, textures, ctx.notes)
    uniform = {k: v for k, v in constants.items() if k not in textures}
    try:
        Material.create(MODEL, uniform)  # ranges, with the model's messages
    except MatremapError as e:
        raise MatremapError(f"{ctx.path}: material {name!r}: {e}") from None
    return MaterialAsset(
        path=ctx.path,
        format=FORMAT,
        name=name,
        model=MODEL,
        constants=constants,
        textures=textures,
        normal=normal,
        notes=ctx.notes,
        document=doc,
        index=index,
        lost=lost,
    )


class _ShaderInputs:
    """The inputs of one shader node in ``gltf:metal-rough`` terms (:data:`SHADERS`): values (or the
    node definition's defaults) and the textures connected to them."""

    def __init__(self, ctx: _Ctx, shader) -> None:
        self.ctx, self.shader = ctx, shader
        self.category = shader.getCategory()
        self.table = SHADERS[self.category]
        self.weight = _WEIGHT.get(self.category)
        self.defaults = _defaults(shader)
        self.spec = get_model(MODEL)

    def value_of(self, input_name: str) -> tuple[list[float] | None, TextureRef | None]:
        """(numbers, None) of a value or default, (None, texture) of a connection, (None, None) when
        neither the node nor its definition gives a value."""
        inp = self.shader.getInput(input_name)
        p = self.spec.param(self.table[input_name]) if input_name in self.table else None
        channels = 3 if p is not None and p.channels == 3 else 1
        if inp is None:
            text = self.defaults.get(input_name, "")
            return (_parse(text, f"{self.ctx.path}: {input_name}", channels) if text else None), None
        ref = _connected(self.ctx, inp, input_name, channels == 3)
        if ref is not None:
            return None, ref
        where = f"{self.ctx.path}: {self.shader.getName()}.{input_name}"
        return _parse(inp.getValueString(), where, channels), None

    def read_all(self) -> tuple[dict[str, Any], dict[str, TextureRef]]:
        """(constants, textures) of the inputs the table maps, by ``gltf:metal-rough`` parameter."""
        constants: dict[str, Any] = {}
        textures: dict[str, TextureRef] = {}
        for input_name, param in self.table.items():
            vals, ref = self.value_of(input_name)
            if ref is not None:
                textures[param] = ref
            elif vals is not None:
                scalar = self.spec.param(param).channels == 1
                constants[param] = vals[0] if scalar else (vals * 3 if len(vals) == 1 else vals)
        return constants, textures

    def apply_base_weight(self, constants: dict[str, Any], textures: dict[str, TextureRef]) -> None:
        """Multiply the base colour (its constant, or its texture's factor) by the base weight input."""
        if self.weight is None:
            return
        wvals, wref = self.value_of(self.weight)
        if wref is not None:
            raise MatremapError(
                f"{self.ctx.path}: {self.category} {self.shader.getName()!r}: a texture on {self.weight} is not "
                f"supported; multiply it into base_color's texture"
            )
        w = wvals[0] if wvals else 1.0
        if "baseColor" in textures:
            ref = textures["baseColor"]
            scale = tuple(float(x) * w for x in np.broadcast_to(ref.scale, (3,))) if w != 1.0 else ref.scale
            textures["baseColor"] = TextureRef(ref.path, ref.channels, ref.colorspace, scale)
        else:
            constants["baseColor"] = [float(x) * w for x in constants.get("baseColor", [1.0, 1.0, 1.0])]

    def skipped(self) -> list[str]:
        """The inputs not remapped that are textured or differ from their defaults, as ``name=value``."""
        out = []
        for inp in self.shader.getInputs():
            n = inp.getName()
            if n in self.table or n == self.weight or n in _NOT_LISTED:
                continue
            if inp.getConnectedNode() is not None:
                out.append(f"{n} (textured)")
                continue
            text, default = inp.getValueString(), self.defaults.get(n)
            if default is not None and _same(text, default):
                continue
            out.append(f"{n}={text}")
        return out


def _normal_map(ctx: _Ctx, shader) -> TextureRef | None:
    """The normal map fed to the shader's normal input through a ``normalmap`` (or
    ``gltf_normalmap``) node; any other node there is noted and ignored."""
    ninp = shader.getInput("normal" if shader.getCategory() != "open_pbr_surface" else "geometry_normal")
    nnode = ninp.getConnectedNode() if ninp is not None else None
    if nnode is None:
        return None
    if nnode.getCategory() not in ("normalmap", "gltf_normalmap"):
        ctx.notes.append(f"normal input fed by a {nnode.getCategory()!r} node ignored (only normalmap is read)")
        return None
    if nnode.getCategory() == "gltf_normalmap":
        img = nnode
    else:
        src = nnode.getInput("in")
        img = src.getConnectedNode() if src is not None else None
        if img is None:
            raise MatremapError(f"{ctx.path}: normalmap node {nnode.getName()!r} is not fed by an image")
    if img.getCategory() not in (*_IMAGES, "gltf_normalmap"):
        raise MatremapError(f"{ctx.path}: the normal map is a {img.getCategory()!r} node; use an image")
    f = img.getInput("file")
    rel = Path(f.getResolvedValueString()) if f is not None else None
    if rel is None or not str(rel):
        raise MatremapError(f"{ctx.path}: the normal map's image node has no file")
    npath = ctx.file(str(rel), f"normal map image node {img.getName()!r} file")
    if not npath.is_file():
        raise MatremapError(f"{ctx.path}: normal map {rel} not found at {npath}; put it beside the document")
    ctx.notes.append(f"normal map {rel.name} (through {nnode.getCategory()}) is the asset's normal map")
    return TextureRef(npath.resolve())


#: inputs that carry a material's look where gltf:metal-rough has nothing to put them: (weight input, what
#: it weights, the value past which the look is lost). A coloured coat over a white metal is Standard
#: Surface's copper; transmission is glass; sheen is velvet.
_LOOK = {
    "coat": ("coat_color", 0.05),
    "transmission": (None, 0.5),
    "transmission_weight": (None, 0.5),
    "sheen": (None, 0.5),
    "fuzz_weight": (None, 0.5),
}


def lost_look(shader: Any) -> list[str]:
    """The inputs that carry the material's look and that gltf:metal-rough has nothing for: a coloured coat
    over the base (Standard Surface's copper is a white metal under a copper coat), transmission (glass),
    sheen (velvet)."""
    lost = []
    for weight, (colour, limit) in _LOOK.items():
        w = _float_input(shader, weight)
        if w is None or w <= 0.0:
            continue
        if colour is not None:
            c = shader.getInput(colour)
            rgb = [float(x) for x in c.getValueString().split(",")] if c is not None and c.getValueString() else []
            if rgb and max(abs(x - 1.0) for x in rgb) > limit:
                lost.append(f"{weight}={w:g} with {colour}={', '.join(f'{x:.3g}' for x in rgb)}")
        elif w > limit:
            lost.append(f"{weight}={w:g}")
    return lost


def _float_input(shader: Any, name: str) -> float | None:
    inp = shader.getInput(name)
    if inp is None or inp.getConnectedNode() is not None or not inp.getValueString():
        return None
    try:
        return float(inp.getValueString())
    except ValueError:
        return None


def _note_skipped(ctx: _Ctx, category: str, skipped: list[str]) -> None:
    """Note the inputs not remapped; for a translated shader, warn first that the translation is approximate."""
    if category == "gltf_pbr":
        if skipped:
            ctx.notes.append(f"gltf_pbr inputs not remapped: {', '.join(skipped)}")
        return
    what = "Standard Surface" if category == "standard_surface" else "OpenPBR Surface"
    names = ", ".join(f"{k} -> {v}" for k, v in SHADERS[category].items())
    ctx.notes.insert(
        0,
        f"WARNING: {what} read through matremap's hand-made translation to gltf:metal-rough "
        f"(base_color x {_WEIGHT[category]} -> baseColor, {names}); it is approximate"
        + (f". Inputs NOT remapped: {', '.join(skipped)}" if skipped else "; every other input is at its default"),
    )


def _clamp_colours(constants: dict[str, Any], textures: dict[str, TextureRef], notes: list[str]) -> None:
    """Clamp uniform colours past the model's range (e.g. gold's base colour 1.059), with a note."""
    spec = get_model(MODEL)
    for k, v in list(constants.items()):
        if k in spec.param_names and k not in textures and spec.param(k).channels == 3:
            lo, hi = spec.param(k).bounds
            arr = np.asarray(v, dtype=float)
            if np.all(np.isfinite(arr)) and (np.any(arr < lo) or np.any(arr > hi)):
                clipped = np.clip(arr, lo, hi)
                constants[k] = clipped.tolist() if clipped.ndim else float(clipped)
                notes.append(f"{k}={v} lies outside [{lo:g}, {hi:g}] and was clamped to {constants[k]}")


def _same(a: str, b: str) -> bool:
    try:
        x = [float(v) for v in a.replace(",", " ").split()]
        y = [float(v) for v in b.replace(",", " ").split()]
        return len(x) == len(y) and np.allclose(x, y, rtol=0, atol=1e-9)
    except ValueError:
        return a.strip() == b.strip()


def _parse_document(mx: Any, p: Path) -> Any:
    """The MaterialX document of file ``p``: its bytes checked as untrusted XML (no entities, bounded
    nesting, no ``xi:include``), then those same bytes given to MaterialX's parser."""
    data = p.read_bytes()
    if not data[:4096].lstrip().startswith(b"<"):
        raise MatremapError(f"{p} is not a MaterialX document (not XML)")
    root = parse_untrusted_xml(p, "a MaterialX document", data)
    if root.tag != "materialx":
        raise MatremapError(f"{p} is not a MaterialX document: its root element is not <materialx>")
    if any(isinstance(el.tag, str) and el.tag.rsplit("}", 1)[-1] == "include" for el in root.iter()):
        raise MatremapError(f"{p}: xi:include is not supported; paste the included document's elements into it")
    doc = mx.createDocument()
    options = mx.XmlReadOptions()
    options.readXIncludeFunction = None  # refused above already; never let MaterialX follow one
    try:
        mx.readFromXmlString(doc, data.decode("utf-8-sig"), mx.FileSearchPath(), options)
    except UnicodeDecodeError:
        raise MatremapError(f"{p} is not a MaterialX document: it is not UTF-8 text") from None
    except Exception as e:  # MaterialX raises its own ExceptionParseError
        raise MatremapError(f"{p} is not a MaterialX document ({str(e).strip() or type(e).__name__})") from None
    return doc


def read(
    path: str | Path, material: str | int | None = None, *, confinement: Confinement | None = None
) -> MaterialAsset:
    """One material of a MaterialX document as a ``gltf:metal-rough`` :class:`MaterialAsset`.
    ``material``: a surfacematerial's name or index (the first by default). Texture files must lie
    in the document's folder or a folder ``confinement`` allows (default: the one in effect)."""
    p = Path(path)
    notes: list[str] = []
    doc, found = _materials(p, notes)
    index = pick_material(p, [n for n, _ in found], material, "material")
    name, shader = found[index]
    if shader is None:
        raise MatremapError(f"{p}: material {name!r} has no surface shader connected")
    return _shader_asset(_Ctx(p, notes, confinement), shader, name, index, doc)


def material_names(path: str | Path) -> list[str]:
    """The names of a document's materials (surfacematerials, else surface shaders), in order."""
    return [n for n, _ in _materials(Path(path), [])[1]]


def _materials(p: Path, notes: list[str]) -> tuple[Any, list[tuple[str, Any]]]:
    """The validated document and its materials as (name, surface shader or None)."""
    mx = _mx()
    if not p.is_file():
        raise MatremapError(f"{p} not found")
    doc = _parse_document(mx, p)
    ok, why = doc.validate()
    if not ok:
        raise MatremapError(f"{p} is not a valid MaterialX document: {why.strip().splitlines()[0]}")
    materials = doc.getMaterialNodes()
    found: list[tuple[str, Any]] = []
    for m in materials:
        shaders = mx.getShaderNodes(m)
        found.append((m.getName(), shaders[0] if shaders else None))
    if not found:
        found = [(n.getName(), n) for n in doc.getNodes() if n.getType() == "surfaceshader"]
        if found:
            notes.append("no surfacematerial in the document: its shader nodes are read as materials")
    if not found:
        raise MatremapError(
            f"{p} holds no surfacematerial or surface shader; matremap reads gltf_pbr, "
            f"standard_surface and open_pbr_surface materials"
        )
    return doc, found


# ---------------------------------------------------------------------------------------------
# Writing

_INPUTS = {v: k for k, v in SHADERS["gltf_pbr"].items()}  # gltf:metal-rough parameter -> gltf_pbr input


def _fmt(v: np.ndarray) -> str:
    return ", ".join(repr(float(x)) for x in np.asarray(v, dtype=float).reshape(-1))


def build_document(
    m: Material, maps: dict[str, str], colorspace: dict[str, str], normal: str | None, name: str = "material"
):
    """The MaterialX document of a gltf:metal-rough material: ``maps`` are file names (relative to
    the document) for textured parameters, ``colorspace`` their encodings (srgb/linear)."""
    mx = _mx()
    spec = m.spec
    doc = mx.createDocument()
    doc.setColorSpace("lin_rec709")
    shader = doc.addNode("gltf_pbr", f"SR_{name}", "surfaceshader")
    for param in ("baseColor", "metallic", "roughness", "ior", "specular", "specularColor"):
        p = spec.param(param)
        typ = "color3" if p.channels == 3 else "float"
        inp = shader.addInput(_INPUTS[param], typ)
        if param in maps:
            img = doc.addNode("image", f"image_{param}", typ)
            f = img.addInput("file", "filename")
            f.setValueString(maps[param])
            if typ == "color3":
                f.setColorSpace("srgb_texture" if colorspace[param] == "srgb" else "lin_rec709")
            inp.setNodeName(img.getName())
        else:
            inp.setValueString(_fmt(m.values[param]))
    if normal is not None:
        img = doc.addNode("image", "image_normal", "vector3")
        img.addInput("file", "filename").setValueString(normal)
        nm = doc.addNode("normalmap", "normalmap", "vector3")
        nm.addInput("in", "vector3").setNodeName(img.getName())
        shader.addInput("normal", "vector3").setNodeName(nm.getName())
    mat = doc.addNode("surfacematerial", name, "material")
    mat.addInput("surfaceshader", "surfaceshader").setNodeName(shader.getName())
    return doc


def write(out: str | Path, result: Any, source: MaterialAsset | None = None, force: bool = False) -> Path:
    """Write ``result`` (a ``gltf:metal-rough`` Material or MapSet) as a MaterialX document with a
    ``gltf_pbr`` shader and a ``surfacematerial``; maps are copied beside it. ``source`` names the
    material when it came from a MaterialX file. The document and its maps are written together or
    not at all."""
    mx = _mx()
    out = Path(out)
    m, maps, cs, normal = result_parts(result, "the MaterialX writer", (MODEL,))
    check_output(out, force, (".mtlx",))
    check_map_destinations(out, [*maps, *(["normal"] if normal else [])], force)
    name = "material"
    if source is not None and re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", source.name or ""):
        name = source.name
    with AtomicFiles(force) as files:
        names: dict[str, str] = {}
        spaces: dict[str, str] = {}
        for param, src in maps.items():
            names[param], spaces[param] = _place_texture(m, param, src, cs[param], out, files)
        nfile = None
        if normal is not None:
            nfile = place_map(normal, map_destination(out, "normal"), True, "linear", 3, files).name
        doc = build_document(m, names, spaces, nfile, name)
        ok, why = doc.validate()
        if not ok:  # pragma: no cover - a bug here, not the user's
            raise MatremapError(f"the MaterialX document for {out} does not validate: {why}")
        files.write_text(out, mx.writeToXmlString(doc))
    return out


def _place_texture(
    m: Material, param: str, src: Path, colorspace: str, out: Path, files: AtomicFiles
) -> tuple[str, str]:
    """Stage the map of ``param`` beside ``out``; (its file name, the colour space to declare).
    Colour maps keep any encoding (it is declared); data maps must hold linear values."""
    from matremap.svbrdf.textures import image_info

    p = m.spec.param(param)
    info = image_info(src, colorspace)
    keep = p.channels == 3 or colorspace == "linear"
    dest = place_map(src, map_destination(out, param), keep, colorspace, p.channels, files)
    kept = dest.suffix.lower() == "." + info.format and keep
    return dest.name, colorspace if kept else "linear"


__all__ = ["FORMAT", "MODEL", "SHADERS", "build_document", "read", "write"]
