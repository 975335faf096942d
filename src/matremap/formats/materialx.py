"""MaterialX documents (.mtlx) in and out, as glTF metallic-roughness materials.

Sources: the MaterialX specification v1.39 (https://materialx.org/Specification.html: documents,
``surfacematerial``, node connections through ``nodename`` / ``nodegraph`` + ``output`` /
``interfacename``, ``fileprefix``, the ``colorspace`` attribute and its inheritance, which applies to
color3/color4 data only), the glTF PBR node of MaterialX's data library (``libraries/bxdf/gltf_pbr.mtlx``),
the Autodesk Standard Surface specification v1.0.1 and the OpenPBR Surface specification v1.1 (their
inputs and defaults as MaterialX 1.39's library declares them). Documents are opened and validated
with MaterialX's standard data libraries (:mod:`matremap.formats.mtlx_document`); node graphs are
evaluated by :mod:`matremap.formats.mtlx_graph`; writing is :mod:`matremap.formats.mtlx_write`.

**Reading.** :func:`read` picks a ``surfacematerial`` by name or index (the first by default; a
document without materials falls back to its shader nodes) and reads its surface shader:

* ``gltf_pbr`` maps one to one onto ``gltf:metal-rough`` (base_color -> baseColor, metallic,
  roughness, ior, specular, specular_color -> specularColor);
* ``standard_surface`` and ``open_pbr_surface`` are read into their own models (``mtlx:standard_surface``,
  ``mtlx:open_pbr_surface``: Standard Surface 1.0.1 and OpenPBR 1.1 as their specifications draw them), every
  input they model by name (OpenPBR's boolean ``geometry_thin_walled`` as 0 / 1), whatever the material: a
  translation onto glTF's parameters would be a hand-made formula no measure can see (before, a layer-less one was
  so translated, and an OpenPBR ``base_diffuse_roughness`` of 1 went onto glTF as an identity copy, exit 0); the
  fit carries each input onto the target's, or fails the gate where the target cannot draw it. The inputs they do
  not model are listed in a note (those that change the look also fail the gate's ``dropped`` check);
* ``gltf_pbr`` is read into ``gltf:pbr`` instead where a layer carries the look -- its clearcoat above 0.5 or a
  sheen_color above 0.1 (:func:`lost_look`) -- so that a fit carries the layer onto the target's instead of
  dropping it (gltf_pbr's ``attenuation_distance`` default of "infinity" as gltf:pbr's 0). Any transmission is read
  the same way where the shader's model transmits in the transmission probe
  (``renderers/embedded/transmission.py`` ``INTERFACES``), and fitted there; elsewhere it stays lost;
* ``UsdPreviewSurface`` (MaterialX's ``ND_UsdPreviewSurface_surfaceshader``) maps one to one onto
  ``usd:preview_surface``, whose parameters are its input names; ``useSpecularWorkflow`` becomes the
  model's option, and a specular-workflow material is read by the same rule as in a USD file
  (:func:`matremap.dialects.usd.specular_workflow`); ``emissiveColor``, ``opacity`` (a mask where
  ``opacityThreshold`` > 0) and ``occlusion`` are carried.

An IOR below 1 (the velvet example's ``specular_IOR = 0``) means, in MaterialX's dielectric Fresnel
(``libraries/pbrlib/genglsl/lib/mx_microfacet_specular.glsl``, ``mx_fresnel_dielectric``: total
reflection whenever ior^2 + cos^2 - 1 < 0), a Fresnel of 1 at every angle: a mirror. Where the
specular lobe is off anyway (specular weight 0, a black specular colour, or a full metal) it has no
effect and ``ior`` is read as the default 1.5 with a note; otherwise the material is refused, since
glTF's dielectric cannot express it.

Every input of a shader may be driven by a node graph: a plain image (``image``, ``tiledimage``,
``gltf_image`` at UV0 with no transform, optionally behind ``extract``/``separate`` picking a channel;
``gltf_image``'s ``factor`` becomes the texture's scale) is used as the file it is; anything else the
evaluator handles is baked onto a map at the size the graph asks for (see
:mod:`matremap.formats.mtlx_graph`: tiling, place2d, arithmetic, mixing, channels, colour
conversions); the textures of one material are brought to one size. A ``normal`` input (OpenPBR:
``geometry_normal``) fed by ``normalmap`` / ``gltf_normalmap`` gives the asset's normal map.

``carried`` (inputs passed to the writer unchanged): ``emission`` = the emission colour x its weight
(``emission_color x emission``, ``emissive x emissive_strength``, OpenPBR's ``emission_color x
emission_luminance``), in the units MaterialX's own library gives its ``uniform_edf`` (the product as
it is: linear radiance in the scene's units, OpenPBR's nits entering 1:1); ``opacity`` = ``alpha``
(gltf_pbr, when ``alpha_mode`` is not opaque, with its mode and cutoff), ``opacity`` (Standard Surface,
a colour: the mean of its channels, noted when they differ) or ``geometry_opacity`` (OpenPBR), mode
blend; ``occlusion`` = gltf_pbr's ``occlusion``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from matremap.core.material import Material
from matremap.dialects import get_model
from matremap.errors import MatremapError, not_a_file
from matremap.formats.asset import CarriedInput, MaterialAsset, TextureRef
from matremap.formats.common import pick_material
from matremap.formats.confine import Confinement, resolve_reference
from matremap.formats.gltf_extensions import SHEEN_LOOK
from matremap.formats.mtlx_document import EMISSION, FORMAT, MODEL, OPACITY, valid_document
from matremap.formats.mtlx_document import mx as materialx_module
from matremap.formats.mtlx_graph import Analysis, GraphEvaluator, PlainImage, parse_value
from matremap.formats.mtlx_write import build_document, write, write_all

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
}
SHADERS["UsdPreviewSurface"] = {
    n: n for n in ("diffuseColor", "metallic", "roughness", "specularColor", "ior", "clearcoat", "clearcoatRoughness")
}
#: shader node category -> the matremap model its inputs are read into (gltf:metal-rough unless named here)
MODELS = {"UsdPreviewSurface": "usd:preview_surface"}
#: shader node category -> the layered model that draws it as its specification does, used for a material whose
#: look a layer carries (see :func:`lost_look`): its coat and sheen are then fitted, not dropped
LAYERED = {
    "standard_surface": "mtlx:standard_surface",
    "open_pbr_surface": "mtlx:open_pbr_surface",
    "gltf_pbr": "gltf:pbr",
}
#: shaders read into their own model whatever their inputs (LAYERED): their models are not glTF's, and the
#: embedded renderer draws them as their specifications do, so the fit sees every difference
OWN_MODEL = ("standard_surface", "open_pbr_surface")
#: gltf_pbr input -> gltf:pbr parameter (MaterialX 1.39 ``libraries/bxdf/gltf_pbr.mtlx``); the MaterialX models'
#: parameters are their input names
GLTF_PBR_LAYERED = {
    **SHADERS["gltf_pbr"],
    "clearcoat": "clearcoat",
    "clearcoat_roughness": "clearcoatRoughness",
    "sheen_color": "sheenColor",
    "sheen_roughness": "sheenRoughness",
    "transmission": "transmission",
    "thickness": "thickness",
    "attenuation_distance": "attenuationDistance",
    "attenuation_color": "attenuationColor",
}
#: inputs of MaterialX type boolean, read as 0 / 1 (OpenPBR's thin-walled switch)
BOOLEAN_INPUTS = frozenset({"geometry_thin_walled", "thin_walled"})
#: inputs that name the dielectric Fresnel and what switches the lobe off, per model read into:
#: (ior, specular weight, specular colour, metalness)
_IOR_INPUTS = {
    "gltf:metal-rough": ("ior", "specular", "specularColor", "metallic"),
    "gltf:pbr": ("ior", "specular", "specularColor", "metallic"),
    "mtlx:standard_surface": ("specular_IOR", "specular", "specular_color", "metalness"),
    "mtlx:open_pbr_surface": ("specular_ior", "specular_weight", "specular_color", "base_metalness"),
}


def layered_inputs(category: str) -> dict[str, str]:
    """Shader input -> parameter of the layered model :data:`LAYERED` reads ``category`` into."""
    if category == "gltf_pbr":
        return dict(GLTF_PBR_LAYERED)
    return {p.name: p.name for p in get_model(LAYERED[category]).params}


#: the shader input carrying the (tangent-space, through normalmap) normal
NORMAL = {
    "gltf_pbr": "normal",
    "standard_surface": "normal",
    "open_pbr_surface": "geometry_normal",
    "UsdPreviewSurface": "normal",
}
#: UsdPreviewSurface's carried inputs: (emission colour, opacity, its mask threshold, occlusion)
_PREVIEW_CARRIED = ("emissiveColor", "opacity", "opacityThreshold", "occlusion")
#: inputs that are not part of the appearance on the probe, or are read apart (normal, carried inputs)
_NOT_LISTED = {
    "normal",
    "tangent",
    "geometry_normal",
    "geometry_tangent",
    "occlusion",
    "alpha_mode",
    "alpha_cutoff",
    "useSpecularWorkflow",
    *_PREVIEW_CARRIED,
    *(n for pair in EMISSION.values() for n in pair),
    *OPACITY.values(),
}


@dataclass
class _Ctx:
    """The document being read, the notes gathered, and where its texture files may lie."""

    path: Path
    notes: list[str]
    confinement: Confinement | None = None

    def file(self, rel: str, what: str) -> Path:
        """The file a ``file`` input names (relative to the document, or absolute), confined."""
        return resolve_reference(rel, self.path.resolve().parent, f"{self.path}: {what}", self.confinement)


@dataclass
class _Field:
    """One shader input (or a product of inputs) as read: a uniform ``value``, or a texture -- ``root``
    evaluates it in the evaluator's pass, ``analysis`` is what the probe found, ``plain`` the image file
    when it is used as it is -- times a uniform ``scale``."""

    name: str
    value: np.ndarray | None = None
    root: Any = None
    analysis: Analysis | None = None
    plain: PlainImage | None = None
    scale: np.ndarray = field(default_factory=lambda: np.ones(1))

    @property
    def textured(self) -> bool:
        return self.value is None

    @property
    def size(self) -> tuple[int, int]:
        if self.plain is not None:
            return self.plain.size
        return self.analysis.size if self.analysis is not None else (1, 1)

    def evaluate(self) -> np.ndarray:
        """Its values in the evaluator's current pass (uniform [C] or [H, W, C]), scale included."""
        return (self.value if self.value is not None else np.asarray(self.root())) * self.scale

    def times(self, other: _Field) -> _Field:
        """The product of two inputs (base_color x base, emission_color x emission)."""
        if other.value is not None and self.value is not None:
            return _Field(self.name, self.value * other.value)
        if other.value is not None or self.value is not None:
            tex, uni = (self, other) if other.value is not None else (other, self)
            assert uni.value is not None
            return _Field(tex.name, None, tex.root, tex.analysis, tex.plain, tex.scale * uni.value)
        a, b = self.analysis, other.analysis
        assert a is not None and b is not None
        size = (max(a.size[0], b.size[0]), max(a.size[1], b.size[1]))
        joint = Analysis(None, [*a.images, *b.images], size, a.capped or b.capped)
        return _Field(f"{self.name} x {other.name}", None, lambda: self.evaluate() * other.evaluate(), joint)


class _ShaderReader:
    """The inputs of one shader node: values (or the node definition's defaults) and the graphs
    feeding them, as :class:`_Field` s, and the textures they become."""

    def __init__(self, ctx: _Ctx, shader: Any, doc: Any, layered: bool = False) -> None:
        self.ctx, self.shader = ctx, shader
        self.category = shader.getCategory()
        self.layered = layered
        if layered:
            self.model, self.table = LAYERED[self.category], layered_inputs(self.category)
        else:
            self.model, self.table = MODELS.get(self.category, MODEL), SHADERS[self.category]
        self.ev = GraphEvaluator(doc, ctx.path, ctx.file, ctx.notes)

    def field(self, name: str, typ: str) -> _Field:
        """Input ``name`` of the shader, of MaterialX type ``typ``."""
        inp = self.shader.getInput(name)
        where = f"{self.ctx.path}: {self.shader.getName()}.{name}"
        if inp is None or not (inp.getAttribute("nodename") or inp.getAttribute("nodegraph")):
            if inp is not None and inp.getAttribute("interfacename"):
                raise MatremapError(f"{where} names an interface input outside a node graph; connect it to a node")
            text = inp.getValueString() if inp is not None and inp.getValueString() else self._default(name)
            return _Field(name, np.asarray(parse_value(text, typ, where), dtype=np.float64) if text else np.zeros(1))
        analysis = self.ev.analyse(lambda: self.ev.port(inp, typ, self.ev.doc_scope), name)
        if analysis.constant is not None:
            self.ctx.notes.append(f"{name}: its node graph is the same everywhere; read as its value")
            return _Field(name, analysis.constant)
        plain = self.ev.plain_image(inp, name)
        return _Field(name, None, lambda: self.ev.port(inp, typ, self.ev.doc_scope), analysis, plain)

    def _default(self, name: str) -> str:
        nd = self.shader.getNodeDef()
        ndi = nd.getActiveInput(name) if nd is not None else None
        return ndi.getValueString() if ndi is not None else ""

    def params(self) -> dict[str, _Field]:
        """Model parameter -> its field."""
        spec = get_model(self.model)
        out = {}
        for input_name, param in self.table.items():
            typ = (
                "boolean" if input_name in BOOLEAN_INPUTS else "color3" if spec.param(param).channels == 3 else "float"
            )
            out[param] = self.field(input_name, typ)
        return out

    def textures(self, fields: dict[str, _Field]) -> dict[str, TextureRef]:
        """The textured fields as TextureRefs of one size (the largest any of them asks for)."""
        textured = {k: f for k, f in fields.items() if f.textured}
        if not textured:
            return {}
        size = (max(f.size[0] for f in textured.values()), max(f.size[1] for f in textured.values()))
        return {k: self.texture(f, size) for k, f in textured.items()}

    def texture(self, f: _Field, size: tuple[int, int]) -> TextureRef:
        """A TextureRef of a textured field at ``size``: its image file when it is used as it is at that
        size, else a baked graph (with a note saying what was evaluated and at what size)."""
        scale = tuple(float(x) for x in f.scale) if f.scale.size > 1 else float(f.scale[0])
        if f.plain is not None and f.plain.size == size:
            factor = np.asarray(f.plain.factor, dtype=np.float64) * f.scale
            fs = tuple(float(x) for x in factor) if factor.size > 1 else float(factor.reshape(-1)[0])
            return TextureRef(f.plain.file.path.resolve(), f.plain.channels, f.plain.colorspace, fs)
        a = f.analysis
        assert a is not None
        self.ctx.notes.append(_bake_note(f, size))
        path = a.images[0].path.resolve() if a.images else self.ctx.path.resolve()
        return TextureRef(path, None, "linear", scale, bake=partial(self.ev.bake, f.root, f.name, size))

    def normal(self) -> TextureRef | None:
        """The normal map fed to the shader's normal input through ``normalmap`` / ``gltf_normalmap``."""
        inp = self.shader.getInput(NORMAL[self.category])
        if inp is None:
            return None
        found = self.ev.normal_map(inp, inp.getName())
        if found is None:
            return None
        root, plain = found
        if plain is not None and plain.channels is None:
            self.ctx.notes.append(
                f"normal map {plain.file.path.name} (through a normalmap node) is the asset's normal map"
            )
            return TextureRef(plain.file.path.resolve())
        a = self.ev.analyse(root, inp.getName())
        if a.constant is not None:
            self.ctx.notes.append(f"{inp.getName()}: a uniform normal map ignored")
            return None
        f = _Field(inp.getName(), None, root, a)
        self.ctx.notes.append(_bake_note(f, a.size))
        path = a.images[0].path.resolve() if a.images else self.ctx.path.resolve()
        return TextureRef(path, bake=partial(self.ev.bake, root, inp.getName(), a.size))

    def carried(self) -> dict[str, CarriedInput]:
        """Emission, opacity and occlusion, for writers to carry over (see the module docstring)."""
        out: dict[str, CarriedInput] = {}
        if self.category == "UsdPreviewSurface":
            return self._preview_carried()
        colour, weight = EMISSION[self.category]
        emission = self.field(colour, "color3").times(self.field(weight, "float"))
        if emission.textured or np.any(emission.value != 0):
            out["emission"] = self._carried(emission, 3)
        opacity = self._opacity()
        if opacity is not None:
            out["opacity"] = opacity
        if self.category == "gltf_pbr":
            occ = self.field("occlusion", "float")
            if occ.textured:
                out["occlusion"] = self._carried(occ, 1)
        if out:
            what = ", ".join(f"{k} ({_carried_words(c)})" for k, c in out.items())
            self.ctx.notes.append(f"carried unchanged to the written file (not remapped): {what}")
        return out

    def _preview_carried(self) -> dict[str, CarriedInput]:
        """UsdPreviewSurface's emissiveColor, opacity (a mask where opacityThreshold > 0; UsdPreviewSurface
        2.5, ``opacityThreshold``) and occlusion."""
        emissive, opacity, threshold, occlusion = _PREVIEW_CARRIED
        out: dict[str, CarriedInput] = {}
        emission = self.field(emissive, "color3")
        if emission.textured or np.any(emission.value != 0):
            out["emission"] = self._carried(emission, 3)
        alpha = self.field(opacity, "float")
        if alpha.textured or float(np.asarray(alpha.value).reshape(-1)[0]) < 1.0:
            cutoff = float(np.asarray(self.field(threshold, "float").value).reshape(-1)[0])
            mode = {"mode": "mask", "cutoff": cutoff} if cutoff > 0.0 else {"mode": "blend"}
            out["opacity"] = self._carried(alpha, 1, mode)
        occ = self.field(occlusion, "float")
        if occ.textured:
            out["occlusion"] = self._carried(occ, 1)
        if out:
            what = ", ".join(f"{k} ({_carried_words(c)})" for k, c in out.items())
            self.ctx.notes.append(f"carried unchanged to the written file (not remapped): {what}")
        return out

    def _opacity(self) -> CarriedInput | None:
        name = OPACITY[self.category]
        mode = "blend"
        settings: dict[str, Any] = {"mode": mode}
        if self.category == "gltf_pbr":
            alpha_mode = int(self.field("alpha_mode", "integer").value[0])  # type: ignore[index]
            if alpha_mode == 0:
                return None  # OPAQUE: alpha is ignored (glTF 2.0 §3.9.4)
            if alpha_mode == 1:
                cutoff = float(self.field("alpha_cutoff", "float").value[0])  # type: ignore[index]
                settings = {"mode": "mask", "cutoff": cutoff}
        typ = "color3" if self.category == "standard_surface" else "float"
        f = self.field(name, typ)
        if typ == "color3":
            if f.value is not None and np.ptp(f.value) > 1e-6:
                self.ctx.notes.append(f"{name}={f.value.tolist()} is coloured; its mean is carried as the opacity")
            f = _mean_channels(f)
        if not f.textured and float(np.asarray(f.value).reshape(-1)[0]) >= 1.0:
            return None
        return self._carried(f, 1, settings)

    def _carried(self, f: _Field, channels: int, settings: dict[str, Any] | None = None) -> CarriedInput:
        settings = settings or {}
        if not f.textured:
            v = np.broadcast_to(np.asarray(f.value, dtype=np.float64), (channels,))
            return CarriedInput(tuple(float(x) for x in v) if channels > 1 else float(v[0]), None, settings)
        value = np.broadcast_to(f.scale, (channels,))
        bare = _Field(f.name, None, f.root, f.analysis, f.plain)
        ref = self.texture(bare, bare.size)
        return CarriedInput(tuple(float(x) for x in value) if channels > 1 else float(value[0]), ref, settings)

    def skipped(self) -> list[str]:
        """The inputs not remapped that are textured or differ from their defaults, as ``name=value``."""
        out = []
        for inp in self.shader.getInputs():
            n = inp.getName()
            if n in self.table or n in _NOT_LISTED:
                continue
            if inp.getAttribute("nodename") or inp.getAttribute("nodegraph"):
                out.append(f"{n} (textured)")
                continue
            text, default = inp.getValueString(), self._default(n)
            if default and _same(text, default):
                continue
            out.append(f"{n}={text}")
        return out


def _carried_words(c: CarriedInput) -> str:
    v = c.value
    text = f"{v:.4g}" if isinstance(v, float) else ", ".join(f"{x:.4g}" for x in (v or ()))
    return f"texture {c.texture.path.name} x {text}" if c.texture is not None else text


def _mean_channels(f: _Field) -> _Field:
    """A colour field as the mean of its channels."""
    if f.value is not None:
        return _Field(f.name, np.array([float(np.mean(f.value * f.scale))]))
    return _Field(f.name, None, lambda: np.mean(f.evaluate(), axis=-1, keepdims=True), f.analysis)


def _bake_note(f: _Field, size: tuple[int, int]) -> str:
    """What was evaluated for a baked input, from which images, and at what size (and why)."""
    a = f.analysis
    h, w = size
    parts = []
    for u in a.images if a is not None else []:
        tiled = "" if u.need == u.size else f", sampled at {u.need[1]}x{u.need[0]} texels (tiling)"
        parts.append(f"{u.path.name} {u.size[1]}x{u.size[0]}{tiled}")
    text = f"{f.name}: node graph evaluated onto a {w}x{h} map"
    if parts:
        text += f" from {'; '.join(parts)}"
    elif a is not None:
        text += " (it reads no image: a procedural size)"
    if a is not None and a.capped:
        text += f"; capped at {max(h, w)} texels per side"
    return text


def _same(a: str, b: str) -> bool:
    try:
        x = [float(v) for v in a.replace(",", " ").split()]
        y = [float(v) for v in b.replace(",", " ").split()]
        return len(x) == len(y) and np.allclose(x, y, rtol=0, atol=1e-9)
    except ValueError:
        return a.strip() == b.strip()


def _shader_asset(ctx: _Ctx, shader: Any, name: str, index: int, doc: Any) -> MaterialAsset:
    """The asset of surface shader node ``shader`` (material ``name``, the ``index``-th of ``doc``)."""
    cat = shader.getCategory()
    if cat not in SHADERS and cat not in LAYERED:
        readable = ", ".join(dict.fromkeys([*SHADERS, *LAYERED]))
        raise MatremapError(f"{ctx.path}: material {name!r} uses a {cat!r} shader; matremap reads {readable}")
    lost = lost_look(shader)
    # Standard Surface and OpenPBR always into their own models: a translation to glTF's would be a hand-made formula
    # the gate cannot see (an OpenPBR base_diffuse_roughness of 1 went onto glTF as an identity copy, exit 0)
    layered = cat in LAYERED and (
        cat in OWN_MODEL or any(not _is_transmission(w) or _transmits(LAYERED[cat]) for w in lost)
    )
    reader = _ShaderReader(ctx, shader, doc, layered)
    fields = reader.params()
    if reader.model in _IOR_INPUTS:
        _check_ior(ctx, shader, fields, _IOR_INPUTS[reader.model])
    if layered:
        _distance_default(fields, shader)
        lost = [w for w in lost if _is_transmission(w) and not _transmits(reader.model)]
    constants = {k: _constant(f) for k, f in fields.items() if not f.textured}
    textures = reader.textures(fields)
    normal = reader.normal()
    carried = reader.carried()
    _note_skipped(ctx, cat, reader.skipped(), reader.model if layered else None)
    if cat == "UsdPreviewSurface":
        from matremap.dialects.usd import specular_workflow

        flag = int(np.asarray(reader.field("useSpecularWorkflow", "integer").value).reshape(-1)[0])
        constants["useSpecularWorkflow"] = "1" if flag == 1 else "0"
        specular_workflow(constants, textures, ctx.notes, f"{ctx.path}: material {name!r}")
    _clamp_colours(constants, ctx.notes, reader.model)
    try:
        Material.create(reader.model, {k: v for k, v in constants.items() if k not in textures})
    except MatremapError as e:
        raise MatremapError(f"{ctx.path}: material {name!r}: {e}") from None
    return MaterialAsset(
        path=ctx.path,
        format=FORMAT,
        name=name,
        model=reader.model,
        constants=constants,
        textures=textures,
        normal=normal,
        notes=ctx.notes,
        document=doc,
        index=index,
        lost=lost,
        carried=carried,
        dropped=dropped_look(shader),
    )


#: shader inputs that change the look and that no model here converts -> (the weights of the lobes they belong to,
#: any of which carrying the look is enough, and the least such a weight is -- as a coat above 0.5 does, COAT_LOOK;
#: with no weight, the least the input itself is --, the roughness they need to show; None: none): anisotropies of a
#: lobe that carries the look, subsurface scattering above a tenth, thin films, volume scattering under a
#: transmission
_DROPPED: dict[str, dict[str, tuple[tuple[str, ...], float, str | None]]] = {
    "standard_surface": {
        # the specular roughness is a metal's too: its anisotropy shows whether the specular weight or the
        # metalness carries that lobe (Standard Surface's specular weight scales the dielectric's alone)
        "specular_anisotropy": (("specular", "metalness"), 0.5, "specular_roughness"),
        "coat_anisotropy": (("coat",), 0.5, "coat_roughness"),
        # what a coat that carries the look does to the base under it: saturates its colour, roughens it
        "coat_affect_color": (("coat",), 0.5, None),
        "coat_affect_roughness": (("coat",), 0.5, None),
        "subsurface": ((), 0.1, None),
        "thin_film_thickness": ((), 0.0, None),
        "transmission_scatter": (("transmission",), 0.0, None),
        "transmission_extra_roughness": (("transmission",), 0.0, None),
    },
    "open_pbr_surface": {
        "specular_roughness_anisotropy": (("specular_weight", "base_metalness"), 0.5, "specular_roughness"),
        "coat_roughness_anisotropy": (("coat_weight",), 0.5, "coat_roughness"),
        "subsurface_weight": ((), 0.1, None),
        "thin_film_weight": ((), 0.0, None),
        "transmission_scatter": (("transmission_weight",), 0.0, None),
    },
    "gltf_pbr": {
        "iridescence": ((), 0.0, None),
        "anisotropy_strength": ((), 0.0, "roughness"),
    },
}
#: the documented defaults of the weights :data:`_DROPPED` names (Standard Surface 1.0.1, OpenPBR 1.1)
_WEIGHT_DEFAULTS = {
    "specular": 1.0,
    "specular_weight": 1.0,
    "coat": 0.0,
    "coat_weight": 0.0,
    "metalness": 0.0,
    "base_metalness": 0.0,
    "transmission_weight": 0.0,
    "transmission": 0.0,
}


def dropped_look(shader: Any) -> list[str]:
    """The inputs of ``shader`` (:data:`_DROPPED`) that are on and carry the look (textured, or above their least
    where the lobe they belong to carries the look and is not a mirror), as ``name=value``: Standard Surface 1.0.1
    and OpenPBR 1.1 name them so. OpenPBR's brushed aluminium (anisotropy 0.9), its ketchup (subsurface 1), the
    Standard Surface jade (subsurface 0.4, anisotropy 0.5) and the chess set's kings and queens (a subsurface
    texture over 73-88 % of their texels) were converted with a note and exit 0."""
    out = []
    for name, (weights, least, roughness) in _DROPPED.get(shader.getCategory(), {}).items():
        inp = shader.getInput(name)
        if inp is None:
            continue
        if inp.getAttribute("nodename") or inp.getAttribute("nodegraph"):
            out.append(f"{name} (textured)")
            continue
        text = inp.getValueString()
        try:
            values = [float(x) for x in text.replace(",", " ").split()]
        except ValueError:
            continue
        if not values or max(values) <= (0.0 if weights else least):
            continue
        if weights and all(_level(shader, w) < max(least, 1e-9) for w in weights):
            continue  # no lobe it belongs to carries the look
        if roughness is not None and _level(shader, roughness) <= 0.0:
            continue
        out.append(f"{name}={text}")
    return out


def _level(shader: Any, name: str) -> float:
    """Input ``name`` of ``shader`` as a number: its value, its documented default where absent, 1 where it is
    connected (a texture: taken as on)."""
    inp = shader.getInput(name)
    if inp is None:
        return _WEIGHT_DEFAULTS.get(name, 0.5)
    if inp.getAttribute("nodename") or inp.getAttribute("nodegraph"):
        return 1.0
    v = _float_input(shader, name)
    return 1.0 if v is None else v


def _constant(f: _Field) -> Any:
    v = np.asarray(f.evaluate(), dtype=np.float64).reshape(-1)
    return float(v[0]) if v.size == 1 else [float(x) for x in v]


def _check_ior(ctx: _Ctx, shader: Any, fields: dict[str, _Field], names: tuple[str, str, str, str]) -> None:
    """An IOR below 1 (see the module docstring): read as the default where the specular lobe is off,
    else refused. ``names``: the model's (ior, specular weight, specular colour, metalness) parameters."""
    ior_name, weight, colour, metalness = names
    f = fields[ior_name]
    if f.textured:
        return
    ior = float(np.asarray(f.evaluate()).reshape(-1)[0])
    if ior >= 1.0:
        return
    input_name = f.name
    off = {"specular": fields[weight], "specularColor": fields[colour], "metallic": fields[metalness]}
    reason = ""
    if not off["specular"].textured and float(_constant(off["specular"])) == 0.0:
        reason = "the specular weight is 0"
    elif not off["specularColor"].textured and not any(_constant(off["specularColor"])):
        reason = "the specular colour is black"
    elif not off["metallic"].textured and float(_constant(off["metallic"])) == 1.0:
        reason = "the material is a full metal"
    if not reason:
        raise MatremapError(
            f"{ctx.path}: {shader.getName()}.{input_name}={ior:g}: an IOR below 1 gives a Fresnel of 1 at "
            f"every angle in MaterialX's dielectric (total reflection), a mirror that matremap's dielectric "
            f"cannot express; set {input_name} to 1 or more (1.5 is its default)"
        )
    fields[ior_name] = _Field(input_name, np.array([1.5]))
    ctx.notes.append(f"{input_name}={ior:g} has no effect since {reason}; ior read as the default 1.5")


#: inputs that carry a material's look where gltf:metal-rough has nothing to put them: (weight input, what
#: it weights, the value past which the look is lost). A coloured coat over a white metal is Standard
#: Surface's copper; any transmission lets part of the base through (glass); sheen is velvet.
_LOOK = {
    "coat": ("coat_color", 0.05),
    "coat_weight": ("coat_color", 0.05),
    "clearcoat": (None, 0.5),
    "transmission": (None, 0.0),
    "transmission_weight": (None, 0.0),
    "sheen": (None, SHEEN_LOOK),
    "fuzz_weight": (None, SHEEN_LOOK),
}
#: a coat weight past which even a white coat carries the look (a second, sharp highlight over the base)
_WHITE_COAT = 0.5


def lost_look(shader: Any) -> list[str]:
    """The inputs that carry the material's look and that gltf:metal-rough has nothing for: a coloured coat
    over the base (Standard Surface's copper is a white metal under a copper coat; a textured coat colour,
    the tiled brass), transmission (glass), sheen (velvet), and any of these weights fed by a texture (before,
    read as no layer at all: a coat masked by an image was dropped with exit 0)."""
    lost = []
    for weight, (colour, limit) in _LOOK.items():
        inp = shader.getInput(weight)
        if inp is not None and (inp.getAttribute("nodename") or inp.getAttribute("nodegraph")):
            lost.append(f"{weight} textured")  # a layer over part of the surface (read into its model, refused)
            continue
        w = _float_input(shader, weight)
        if w is None or w <= 0.0:
            continue
        if colour is not None:
            c = shader.getInput(colour)
            if c is not None and (c.getAttribute("nodename") or c.getAttribute("nodegraph")):
                lost.append(f"{weight}={w:g} with {colour} textured")
                continue
            rgb = [float(x) for x in c.getValueString().split(",")] if c is not None and c.getValueString() else []
            if rgb and max(abs(x - 1.0) for x in rgb) > limit:
                lost.append(f"{weight}={w:g} with {colour}={', '.join(f'{x:.3g}' for x in rgb)}")
            elif w > _WHITE_COAT:
                lost.append(f"{weight}={w:g}")
        elif w > limit:
            lost.append(f"{weight}={w:g}")
    sheen = shader.getInput("sheen_color") if shader.getCategory() == "gltf_pbr" else None
    if (
        sheen is not None
        and sheen.getValueString()
        and not (sheen.getAttribute("nodename") or sheen.getAttribute("nodegraph"))
    ):
        rgb = [float(x) for x in sheen.getValueString().split(",")]
        if max(rgb) > SHEEN_LOOK:  # a sheen: velvet (glTF's rule, formats/gltf_extensions.lost_look)
            lost.append(f"sheen_color={', '.join(f'{x:.3g}' for x in rgb)}")
    return lost


def _is_transmission(lost: str) -> bool:
    """Whether an entry of :func:`lost_look` is a transmission."""
    return lost.startswith("transmission")


def _transmits(model: str) -> bool:
    """Whether the model's transmission is drawn by the transmission probe (and so fitted, not lost)."""
    from matremap.renderers.embedded.transmission import INTERFACES

    return model in INTERFACES


def _distance_default(fields: dict[str, _Field], shader: Any) -> None:
    """gltf_pbr's attenuation_distance of 'infinity' (MaterialX declares a large default) is gltf:pbr's 0."""
    f = fields.get("attenuationDistance")
    if shader.getCategory() == "gltf_pbr" and f is not None and f.value is not None and float(f.value[0]) >= 1e6:
        fields["attenuationDistance"] = _Field(f.name, np.zeros(1))


def _float_input(shader: Any, name: str) -> float | None:
    inp = shader.getInput(name)
    if inp is None or inp.getAttribute("nodename") or inp.getAttribute("nodegraph") or not inp.getValueString():
        return None
    try:
        return float(inp.getValueString())
    except ValueError:
        return None


def _note_skipped(ctx: _Ctx, category: str, skipped: list[str], layered: str | None = None) -> None:
    """Note the inputs not remapped; a shader read into its own model (``layered``) says so first."""
    if layered is not None:
        ctx.notes.insert(
            0,
            f"{category} read into {layered} (every input it models, fitted onto the target)"
            + (f"; inputs not modelled: {', '.join(skipped)}" if skipped else ""),
        )
        return
    if skipped:
        ctx.notes.append(f"{category} inputs not remapped: {', '.join(skipped)}")


def _clamp_colours(constants: dict[str, Any], notes: list[str], model: str = MODEL) -> None:
    """Clamp uniform colours past the model's range (e.g. gold's base colour 1.059), with a note."""
    spec = get_model(model)
    for k, v in list(constants.items()):
        if k in spec.param_names and spec.param(k).channels == 3:
            lo, hi = spec.param(k).bounds
            arr = np.asarray(v, dtype=float)
            if np.all(np.isfinite(arr)) and (np.any(arr < lo) or np.any(arr > hi)):
                clipped = np.clip(arr, lo, hi)
                constants[k] = clipped.tolist() if clipped.ndim else float(clipped)
                notes.append(f"{k}={v} lies outside [{lo:g}, {hi:g}] and was clamped to {constants[k]}")


def read(
    path: str | Path, material: str | int | None = None, *, confinement: Confinement | None = None
) -> MaterialAsset:
    """One material of a MaterialX document as a :class:`MaterialAsset` (``gltf:metal-rough``; its own layered
    model where a layer carries the look; ``usd:preview_surface``; see the module docstring).
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
    if not p.is_file():
        raise MatremapError(not_a_file(p, "MaterialX document"))
    doc = valid_document(p)
    mx = materialx_module()
    found: list[tuple[str, Any]] = []
    for m in doc.getMaterialNodes():
        shaders = mx.getShaderNodes(m)
        found.append((m.getName(), shaders[0] if shaders else None))
    if not found:
        found = [(n.getName(), n) for n in doc.getNodes() if n.getType() == "surfaceshader"]
        if found:
            notes.append("no surfacematerial in the document: its shader nodes are read as materials")
    if not found:
        raise MatremapError(
            f"{p} holds no surfacematerial or surface shader; matremap reads gltf_pbr, "
            f"standard_surface, open_pbr_surface and UsdPreviewSurface materials"
        )
    return doc, found


__all__ = [
    "FORMAT",
    "MODEL",
    "MODELS",
    "NORMAL",
    "SHADERS",
    "build_document",
    "lost_look",
    "material_names",
    "read",
    "write",
    "write_all",
]
