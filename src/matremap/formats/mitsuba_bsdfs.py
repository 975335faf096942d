"""Mitsuba 3 BSDF elements read as matremap materials (``mitsuba3:*`` models, Mitsuba's parameter names).

Sources: the Mitsuba 3.9 plugin reference (``src/bsdfs/*.cpp``: ``diffuse``, ``conductor``,
``roughconductor``, ``plastic``, ``roughplastic``, ``principled``, ``dielectric``, ``roughdielectric``,
``thindielectric``, ``twosided``, ``normalmap``, ``bumpmap``, ``mask``, ``blendbsdf``) and
``include/mitsuba/core/ior.h``. What each plugin becomes:

* ``diffuse``, ``roughconductor``, ``roughplastic``, ``principled``: the model of the same name.
* ``conductor`` and ``plastic`` (smooth): ``roughconductor`` / ``roughplastic`` at the mirror limit,
  alpha = 1e-4, the floor Mitsuba's microfacet distribution clamps every alpha to
  (``MicrofacetDistribution``: ``max(alpha, 1e-4)``) and the lower bound of matremap's alpha, with the
  GGX distribution (a mirror has none; GGX is what most targets draw). A fit
  from such a source widens the highlight until the probe resolves it and carries the target's
  roughness back to the mirror limit (``core/fit.py``, "Every roughness, including 0").
* ``roughconductor`` with ``alpha_u`` = ``alpha_v`` is isotropic ``alpha``; ``alpha_u`` != ``alpha_v``
  (numbers) is ``mitsuba3:roughconductor-anisotropic``, in the tangent frame of the surface (dp/du);
  anisotropic roughness maps are refused.
* ``dielectric``, ``roughdielectric``, ``thindielectric``: the model of the same name (uniform only: a texture
  is refused; roughdielectric isotropic only, ``alpha_u`` = ``alpha_v`` read as ``alpha``); a fit from one is made
  on the transmission probe (:mod:`matremap.transmissive`).
* ``int_ior`` / ``ext_ior`` given by name use :data:`IOR_TABLE` (Mitsuba 3.9 ``ior.h``, after Hecht,
  *Optics*, 4th ed.); a ``roughconductor`` without ``eta``/``k``/``material`` is Mitsuba's perfect
  mirror (``material=none``), with ``eta``/``k`` it is ``material=custom``; ``principled``'s ``eta``
  becomes ``specular = ((eta - 1)/(eta + 1))^2 / 0.08`` (the plugin's documented relation).
* Colours given as spectra (``wavelength:value`` lists or ``.spd`` files) are converted to RGB as
  Mitsuba's RGB variants do (:mod:`matremap.formats.spectra`; bounded for reflectances, unbounded for
  ``eta``/``k``).
* Wrappers: ``twosided`` is unwrapped (the probe sees the front side; writers that copy the scene
  keep it); ``normalmap``'s texture is the asset's normal map, ``bumpmap``'s height texture becomes
  one (:mod:`matremap.formats.mitsuba_textures`); ``mask``'s opacity is carried
  (``MaterialAsset.carried["opacity"]``, mode ``blend``); ``blendbsdf`` of two BSDFs of the same
  model and options becomes one material whose parameters are blended by the weight, texel by texel
  (exact for the parameters the BSDF is linear in, reflectances; an approximation for the others, noted).
* Documents older than version 2 (Mitsuba 0.6) have camelCase names read as snake_case
  (``intIOR`` -> ``int_ior``), as Mitsuba 3's upgrade does.

Anything else -- another plugin, an unknown parameter -- raises a :class:`MatremapError` naming it.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from typing import Any

import numpy as np

from matremap.core.material import Material
from matremap.errors import MatremapError
from matremap.formats.asset import CarriedInput, MaterialAsset
from matremap.formats.bake import MAX_SIDE
from matremap.formats.mitsuba_blend import blend_parts
from matremap.formats.mitsuba_params import BsdfValues
from matremap.formats.mitsuba_plugins import (
    ACCEPTED,
    FORMAT,
    PLUGINS,
    TRANSMISSIVE,
    WRAPPERS,
    Parts,
    Prop,
)
from matremap.formats.mitsuba_scene import MitsubaScene
from matremap.formats.mitsuba_textures import (
    DEFAULT_BAKE_SIZE,
    WRAP,
    TextureSource,
    bitmap_source,
    bump_normal_source,
    checkerboard_source,
    uv_matrix,
)
from matremap.formats.spectra import parse_pairs, parse_spd, spectrum_to_srgb

_BITMAP_PARAMS = {"filename", "raw", "filter_type", "wrap_mode", "to_uv", "format", "accel"}


class BsdfReader:
    """Reads the BSDFs of a :class:`~matremap.formats.mitsuba_scene.MitsubaScene`."""

    def __init__(self, scene: MitsubaScene) -> None:
        self.scene = scene

    def fail(self, msg: str, el: ET.Element | None = None) -> MatremapError:
        return self.scene.fail(el, msg)

    def name_of(self, el: ET.Element) -> str:
        name = el.get("name")
        if name is not None and self.scene.file_of(el).legacy:
            name = re.sub(r"(?<=[a-z0-9])(?=[A-Z])", "_", name).lower()
        return name or ""

    # -- properties --------------------------------------------------------------------------------
    def props(self, el: ET.Element, what: str) -> dict[str, Prop]:
        """The named properties of plugin element ``el`` (nested BSDFs are named by position)."""
        out: dict[str, Prop] = {}
        nested = 0
        for child in el:
            tag = child.tag
            if not isinstance(tag, str):  # comments
                continue
            name = self.name_of(child)
            if tag == "ref":
                target = self.scene.ids.get(child.get("id", ""))
                if target is None or target.tag not in ("bsdf", "texture", "spectrum"):
                    raise self.fail(
                        f"{what} refers to id {child.get('id')!r}, which no <bsdf> or <texture> of the scene "
                        f"(or its included files) has; define it or fix the id",
                        child,
                    )
                tag, child = target.tag, target
            if tag == "bsdf" or (tag == "texture" and not name):  # nested objects may go unnamed
                key = name or f"#{tag}{nested}"
                nested += 1
                out[key] = Prop("bsdf" if tag == "bsdf" else "texture", child, tag)
                continue
            if not name:
                raise self.fail(f"<{tag}> inside {what} has no name attribute", child)
            if name in out:
                raise self.fail(f"{what} sets {name} twice; keep one", child)
            out[name] = self.prop(child, tag, name, what)
        return out

    def prop(self, child: ET.Element, tag: str, name: str, what: str) -> Prop:
        value = child.get("value")
        if tag in ("float", "integer"):
            return Prop("float", self.number(value, name, what, child), tag)
        if tag == "spectrum" and child.get("type") is None:
            return self.spectrum(child, name, what)
        if tag in ("rgb", "color"):
            nums = self.numbers(value, name, what, tag, child)
            return Prop("rgb" if len(nums) == 3 else "float", nums if len(nums) == 3 else nums[0], tag)
        if tag == "string":
            return Prop("string", value or "", tag)
        if tag == "boolean":
            if (value or "").lower() not in ("true", "false"):
                raise self.fail(f"{what}: boolean {name} must be true or false, not {value!r}", child)
            return Prop("boolean", (value or "").lower() == "true", tag)
        if tag in ("texture", "spectrum"):
            return Prop("texture", child, tag)
        if tag == "transform":
            return Prop("transform", child, tag)
        return Prop("other", child, tag)

    def spectrum(self, child: ET.Element, name: str, what: str) -> Prop:
        """A ``<spectrum>``: one or three numbers, wavelength:value pairs, or a spectrum file."""
        value, filename = child.get("value"), child.get("filename")
        if (value is None) == (filename is None):
            raise self.fail(f"{what}: <spectrum> {name} needs a value or a filename attribute (not both)", child)
        try:
            if filename is not None:
                path = self.scene.resolve(filename, f"{self.scene.file_of(child).path}: spectrum file for {name}")
                return Prop("spectrum", parse_spd(path.read_text(errors="replace")), "spectrum")
            pairs = parse_pairs(value or "")
        except MatremapError as e:
            raise self.fail(f"{what}: {name}: {e}", child) from None
        if pairs is not None:
            return Prop("spectrum", pairs, "spectrum")
        nums = self.numbers(value, name, what, "spectrum", child)
        return Prop("rgb" if len(nums) == 3 else "float", nums if len(nums) == 3 else nums[0], "spectrum")

    def number(self, value: str | None, name: str, what: str, el: ET.Element) -> float:
        try:
            x = float(value)  # type: ignore[arg-type]
        except (TypeError, ValueError):
            raise self.fail(f"{what}: {name}={value!r} is not a number", el) from None
        if not np.isfinite(x):
            raise self.fail(f"{what}: {name}={value!r} is not a finite number", el)
        return x

    def numbers(self, value: str | None, name: str, what: str, tag: str, el: ET.Element) -> list[float]:
        parts = (value or "").replace(",", " ").split()
        try:
            nums = [float(p) for p in parts]
        except ValueError:
            raise self.fail(f"{what}: <{tag}> {name}={value!r} is not one or three numbers", el) from None
        if len(nums) not in (1, 3) or not all(np.isfinite(nums)):
            raise self.fail(f"{what}: <{tag}> {name} has {len(nums)} values; give one or three finite numbers", el)
        return nums

    # -- materials -----------------------------------------------------------------------------------
    def candidates(self) -> list[tuple[str, ET.Element]]:
        """The scene's BSDFs: top-level ones, then those written inside shapes, in document order."""
        root = self.scene.root
        if root.tag == "bsdf":
            return [(root.get("id") or root.get("type") or "bsdf", root)]
        out: list[tuple[str, ET.Element]] = []
        for el in root:
            if el.tag == "bsdf":
                out.append((el.get("id") or f"bsdf {len(out)}", el))
        for i, shape in enumerate(root.iter("shape")):
            for child in shape:
                if child.tag == "bsdf":
                    label = shape.get("id") or f"shape {i} ({shape.get('type')})"
                    out.append((child.get("id") or f"{label}/bsdf", child))
        return out

    def asset(self, label: str, el: ET.Element, index: int) -> MaterialAsset:
        """The :class:`MaterialAsset` of BSDF element ``el``, the ``index``-th of the scene."""
        parts = self.parts(label, el)
        return finish(self.scene, parts, index)

    def parts(self, label: str, el: ET.Element) -> Parts:
        """BSDF ``el`` read: wrappers unwrapped, a blend blended, the core plugin's parameters read."""
        parts = Parts(label, "")
        core = self.unwrap(el, parts)
        plugin = core.get("type", "")
        if plugin == "blendbsdf":
            return self.blend(core, parts)
        self.core(core, plugin, parts)
        return parts

    def blend(self, el: ET.Element, outer: Parts) -> Parts:
        """``blendbsdf``: its weight and two BSDFs (:mod:`matremap.formats.mitsuba_blend`), inside the
        wrappers already read into ``outer``."""
        what = f'<bsdf type="blendbsdf"> {outer.label!r}'
        props = self.props(el, what)
        children = [p.value for p in props.values() if p.kind == "bsdf"]
        unknown = set(props) - {"weight"} - {k for k, p in props.items() if p.kind == "bsdf"}
        if len(children) != 2 or unknown:
            raise self.fail(f"{what} needs a weight and exactly two BSDFs", el)
        w = props.get("weight")
        weight: tuple[float, TextureSource | None]
        if w is None:
            raise self.fail(f'{what} has no weight; add <float name="weight">', el)
        if w.kind == "texture":
            weight = (0.0, self.texture(w.value, "weight", scalar=True, notes=outer.notes))
        elif w.kind in ("float", "rgb") and 0.0 <= mean_of(w.value) <= 1.0:
            weight = (mean_of(w.value), None)
        else:
            raise self.fail(f"{what}: weight must be a number in [0, 1] or a texture", el)
        first, second = (self.parts(f"{outer.label}/{i}", child) for i, child in enumerate(children))
        try:
            blended = blend_parts(first, second, weight, outer.label, self.scene.path)
        except MatremapError as e:
            raise self.fail(str(e), el) from None
        blended.notes[:0] = outer.notes
        blended.normal, blended.opacity, blended.twosided = outer.normal, outer.opacity, outer.twosided
        return blended

    def core(self, core: ET.Element, plugin: str, parts: Parts) -> None:
        """Read core BSDF ``core`` (plugin ``plugin``) into ``parts``."""
        label = parts.label
        if plugin not in PLUGINS:
            raise self.fail(
                f"material {label!r} is a {plugin!r} BSDF; matremap reads {', '.join(PLUGINS)} "
                f"(inside {', '.join(WRAPPERS)} wrappers, or two of them in a blendbsdf)",
                core,
            )
        what = f'<bsdf type="{plugin}"> {label!r}'
        props = self.props(core, what)
        extra = sorted(set(props) - set(ACCEPTED[plugin]))
        if extra:
            raise self.fail(
                f"{what}: unknown parameter(s) {', '.join(extra)}; {plugin} takes {', '.join(ACCEPTED[plugin])}", core
            )
        values = BsdfValues(self, plugin, what, props, parts.notes, core)
        values.read()
        parts.model = values.model
        parts.constants.update(values.constants)
        parts.textures.update(values.textures)
        uniform = {k: v for k, v in values.constants.items() if k not in values.textures}
        try:
            Material.create(parts.model, uniform)  # names, ranges and options, with the model's own messages
        except MatremapError as e:
            raise self.fail(f"material {label!r}: {e}", core) from None

    def unwrap(self, el: ET.Element, parts: Parts) -> ET.Element:
        """The core BSDF inside ``el``'s wrappers; what each wrapper keeps goes into ``parts``."""
        notes = parts.notes
        while el.get("type") in WRAPPERS:
            kind = el.get("type", "")
            what = f'<bsdf type="{kind}">'
            props = self.props(el, what)
            inner = [p.value for p in props.values() if p.kind == "bsdf"]
            if not inner:
                raise self.fail(f"{what} wraps no <bsdf>; put the material inside it", el)
            if kind == "twosided":
                glass = [b.get("type") for b in inner if b.get("type") in TRANSMISSIVE]
                if glass:
                    raise self.fail(
                        f"{what} {parts.label!r} holds a {glass[0]} BSDF, which Mitsuba 3 refuses too (twosided takes "
                        "only BSDFs without transmission); fix the scene",
                        el,
                    )
                if len(inner) > 1:
                    notes.append("twosided with a different back-side BSDF: only the front side is read")
                notes.append("twosided unwrapped: the probe sees the front side (a copied scene keeps the wrapper)")
                parts.twosided = True
            elif kind in ("normalmap", "bumpmap"):
                self.normal_wrapper(kind, props, parts, el)
            else:
                self.mask(props, parts, el)
            el = inner[0]
        return el

    def normal_wrapper(self, kind: str, props: dict[str, Prop], parts: Parts, el: ET.Element) -> None:
        what = f'<bsdf type="{kind}">'
        textures = [p for p in props.values() if p.kind == "texture"]
        if kind == "normalmap":
            tex = props.get("normalmap") or (textures[0] if len(textures) == 1 else None)
        else:
            tex = textures[0] if len(textures) == 1 else None
        if tex is None:
            raise self.fail(f"{what} needs exactly one <texture> (the {kind}'s image)", el)
        if parts.normal is not None:
            parts.notes.append(f"a second {kind} wrapper was dropped (only the outermost normal perturbation is kept)")
            return
        if kind == "normalmap":
            src = self.texture(tex.value, "normal map", scalar=False, notes=parts.notes)
            parts.normal = TextureSource(src.path, src.size, src.sample, src.plain if _is_raw(src) else None)
            parts.notes.append(f"normalmap wrapper: {src.path.name} is the asset's normal map")
            return
        if tex.value.get("type") != "bitmap":
            raise self.fail(
                f"{what} over a {tex.value.get('type')!r} texture: Mitsuba 3 cannot render it (only bitmap textures "
                "have the height gradient bumpmap needs, Texture::eval_1_grad); give the height as a bitmap",
                el,
            )
        scale = props.get("scale")
        if scale is not None and scale.kind != "float":
            raise self.fail(f"{what}: scale must be a <float>", el)
        height = self.texture(tex.value, "bump map", scalar=True, notes=parts.notes)
        factor = float(scale.value) if scale is not None else 1.0
        parts.normal = bump_normal_source(height, factor)
        parts.notes.append(
            f"bumpmap wrapper: {height.path.name} (scale {factor:g}) baked into a tangent-space normal map as "
            "Mitsuba's bumpmap bends the shading normal, on a surface one unit across per unit of UV (Mitsuba's bumps "
            "scale with 1/|dp/du| on the real mesh)"
        )
        for name in ("flip_invalid_normals", "use_shadowing_function"):
            if name in props:
                parts.notes.append(f"bumpmap {name} ignored: it is not a property of the normal map")

    def mask(self, props: dict[str, Prop], parts: Parts, el: ET.Element) -> None:
        """``mask``: opacity (default 0.5) carried as it is, to be written back by writers that can."""
        op = props.get("opacity")
        if parts.opacity is not None:
            parts.notes.append("a second mask wrapper was dropped (only the outermost opacity is kept)")
            return
        if op is None:
            parts.opacity = (0.5, None)
        elif op.kind == "texture":
            parts.opacity = (1.0, self.texture(op.value, "opacity", scalar=True, notes=parts.notes))
        elif op.kind in ("float", "rgb"):
            v = op.value
            parts.opacity = (float(v) if op.kind == "float" else tuple(float(x) for x in v), None)
        elif op.kind == "spectrum":
            parts.opacity = (tuple(float(x) for x in spectrum_to_srgb(*op.value)), None)
        else:
            raise self.fail('<bsdf type="mask">: opacity must be a number, a colour or a texture', el)
        parts.notes.append("mask wrapper: its opacity is carried (blend mode) to formats with an opacity slot")

    # -- textures ------------------------------------------------------------------------------------
    def texture(self, el: ET.Element, param: str, scalar: bool, notes: list[str]) -> TextureSource:
        """A ``bitmap`` or ``checkerboard`` texture driving ``param``; other plugins are refused."""
        kind = el.get("type")
        what = f"texture for {param}"
        if kind == "checkerboard":
            return self.checkerboard(el, param, scalar)
        if kind != "bitmap":
            raise self.fail(
                f"{what} is a {kind!r} texture; matremap reads bitmap and checkerboard textures "
                "(bake it into an image)",
                el,
            )
        props = self.props(el, what)
        unknown = set(props) - _BITMAP_PARAMS
        if unknown:
            raise self.fail(f"{what}: unknown bitmap parameter(s) {', '.join(sorted(unknown))}", el)
        fname = props.get("filename")
        if fname is None or fname.kind != "string" or not fname.value:
            raise self.fail(f'{what}: the bitmap has no <string name="filename">; add the image\'s file name', el)
        path = self.scene.resolve(fname.value, f"{self.scene.file_of(el).path}: bitmap {param}")
        raw = props.get("raw")
        if raw is not None and raw.kind != "boolean":
            raise self.fail(f"{what}: raw must be a <boolean>", el)
        wrap = self.choice(props, "wrap_mode", WRAP, "repeat", what, el)
        if self.choice(props, "filter_type", ("bilinear", "nearest"), "bilinear", what, el) == "nearest":
            notes.append(f"{path.name} for {param}: filter_type nearest is read as bilinear")
        matrix = self.uv(props, what)
        return bitmap_source(path, bool(raw and raw.value), scalar, matrix, wrap, notes, param)

    def choice(self, props: dict[str, Prop], name: str, choices: tuple[str, ...], default: str, what: str, el) -> str:
        p = props.get(name)
        if p is None:
            return default
        if p.kind != "string" or p.value not in choices:
            raise self.fail(f"{what}: {name} must be one of {', '.join(choices)}, not {p.value!r}", el)
        return str(p.value)

    def uv(self, props: dict[str, Prop], what: str) -> np.ndarray | None:
        p = props.get("to_uv")
        if p is None:
            return None
        if p.kind != "transform":
            raise self.fail(f"{what}: to_uv must be a <transform>")
        return uv_matrix(p.value, f"{self.scene.file_of(p.value).path}: {what}: to_uv")

    def checkerboard(self, el: ET.Element, param: str, scalar: bool) -> TextureSource:
        what = f"checkerboard texture for {param}"
        props = self.props(el, what)
        unknown = set(props) - {"color0", "color1", "to_uv"}
        if unknown:
            raise self.fail(f"{what}: unknown parameter(s) {', '.join(sorted(unknown))}", el)
        colours = []
        for name, default in (("color0", 0.4), ("color1", 0.2)):
            p = props.get(name)
            if p is None:
                colours.append(np.array([default]))
            elif p.kind in ("float", "rgb"):
                colours.append(np.atleast_1d(np.asarray(p.value, dtype=float)))
            elif p.kind == "spectrum":
                colours.append(spectrum_to_srgb(*p.value))
            else:
                raise self.fail(f"{what}: {name} must be a number or a colour (a nested texture is not baked)", el)
        return checkerboard_source(self.scene.file_of(el).path, colours[0], colours[1], scalar, self.uv(props, what))


def _is_raw(src: TextureSource) -> bool:
    """Whether a texture's plain file holds the values as they are (not sRGB-decoded)."""
    return src.plain is not None and src.plain.colorspace == "linear"


def bake_size(parts: Parts) -> tuple[tuple[int, int], bool]:
    """The size every map of a material is made at: the largest of its images (by texel count), capped at
    :data:`~matremap.formats.bake.MAX_SIDE` per side when one of them is baked (a baked map is held whole), or
    :data:`DEFAULT_BAKE_SIZE` when only procedural textures drive it; and whether that default was used."""
    sources = [*parts.textures.values(), parts.normal, parts.opacity[1] if parts.opacity else None]
    sizes = [s.size for s in sources if s is not None and s.size is not None]
    if not sizes:
        return DEFAULT_BAKE_SIZE, True
    h, w = max(sizes, key=lambda hw: (hw[0] * hw[1], hw))
    if any(s is not None and s.plain is None for s in sources):
        return (min(h, MAX_SIDE), min(w, MAX_SIDE)), False
    return (h, w), False


def finish(scene: MitsubaScene, parts: Parts, index: int) -> MaterialAsset:
    """The asset of ``parts``: every texture made a map of one size (resampled bilinearly, as the
    renderer samples it, where sizes differ), opacity carried."""
    size, default = bake_size(parts)
    sources = [s for s in (*parts.textures.values(), parts.normal) if s is not None]
    if default and sources:
        parts.notes.append(f"procedural textures baked at {size[1]}x{size[0]} texels")
    elif any(s.size not in (None, size) for s in sources):
        parts.notes.append(f"textures of other sizes resampled to {size[1]}x{size[0]} (bilinear, as Mitsuba samples)")
    carried: dict[str, CarriedInput] = {}
    if parts.opacity is not None:
        value, tex = parts.opacity
        carried["opacity"] = CarriedInput(value, tex.ref(size) if tex else None, {"mode": "blend"})
    if parts.normal is not None and not parts.textures:
        parts.notes.append("the material is uniform apart from its normal map")
    return MaterialAsset(
        lost=lost_layers(parts),
        path=scene.path,
        format=FORMAT,
        name=parts.label,
        model=parts.model,
        constants=parts.constants,
        textures={k: v.ref(size) for k, v in parts.textures.items()},
        normal=parts.normal.ref(size) if parts.normal else None,
        notes=parts.notes,
        document=scene,
        index=index,
        carried=carried,
    )


#: principled lobes the embedded renderer does not draw, and what they are (its clearcoat and sheen it draws, and
#: fits carry them onto the other layered models' coat and sheen; a uniform spec_trans is fitted on the transmission
#: probe, a textured one blended per texel with and without it: svbrdf/mixed.py ``transmission_parameter``)
LAYERS = {"anisotropic": "anisotropy"}


def lost_layers(parts: Parts) -> list[str]:
    """The look a ``principled`` material carries in lobes no fit can draw (anisotropic): kept onto itself, refused
    onto other models."""
    if parts.model != "mitsuba3:principled":
        return []
    lost = []
    for name, what in LAYERS.items():
        value = parts.constants.get(name, 0.0)
        if name in parts.textures or (name in LAYERS and float(np.max(value)) > 0.0):
            lost.append(
                f"principled {name} {'(a texture)' if name in parts.textures else f'{float(np.max(value)):g}'} ({what})"
            )
    return lost


def mean_of(value: Any) -> float:
    """A number or colour as Mitsuba's constant texture answers ``eval_1``: the mean of its channels."""
    return float(np.mean(np.asarray(value, dtype=float)))


__all__ = ["BsdfReader", "bake_size", "finish", "mean_of"]
