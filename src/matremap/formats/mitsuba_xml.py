"""Mitsuba 3 scene XML in and out.

Sources: the Mitsuba 3 documentation, "Scene format"
(https://mitsuba.readthedocs.io/en/stable/src/key_topics/scene_format.html: ``<default>`` and
``$name`` substitution, ``<ref>``, ``<rgb>``/``<float>``/``<string>``/``<boolean>``), and its plugin
reference (https://mitsuba.readthedocs.io/en/stable/src/generated/plugins_bsdfs.html and
``plugins_textures.html``): ``diffuse``, ``roughconductor``, ``roughplastic``, ``principled``, the
wrappers ``twosided``, ``normalmap``, ``bumpmap`` and ``mask``, and the ``bitmap`` texture.

**Reading.** :func:`read` accepts a ``<scene>`` or a bare ``<bsdf>`` document. The materials of a
scene are its top-level ``<bsdf>`` elements, then the ``<bsdf>`` elements written inside ``<shape>``
elements, in document order; ``material`` picks one by ``id`` (or ``shape id/bsdf`` for an
anonymous one inside a shape) or by index. ``twosided`` is unwrapped (matremap's probe sees the
front side); a ``normalmap`` wrapper's bitmap becomes the asset's normal map; ``bumpmap`` and
``mask`` are dropped with a note. The core BSDF maps to matremap's ``mitsuba3:*`` model of the same
name, with Mitsuba's parameter names. Values Mitsuba accepts are read as Mitsuba reads them:

* ``int_ior`` / ``ext_ior`` given by name use Mitsuba's table (:data:`IOR_TABLE`, copied from
  Mitsuba 3.9's ``include/mitsuba/core/ior.h``, whose values come from Hecht, *Optics*, 4th ed.);
* a ``roughconductor`` without ``eta``/``k``/``material`` is Mitsuba's default perfect mirror
  (``material=none``); with ``eta``/``k`` it is ``material=custom``;
* ``alpha_u`` = ``alpha_v`` is the isotropic ``alpha`` (anisotropy is refused);
* ``principled``'s ``eta`` becomes ``specular = ((eta - 1)/(eta + 1))^2 / 0.08``, the relation
  Mitsuba's plugin documents between the two;
* a ``bitmap`` texture's file is relative to the XML file, and must lie in the XML file's folder or a
  folder the user allowed (:mod:`matremap.formats.confine`). With ``raw="true"`` its values are used
  as they are (linear); without, Mitsuba decodes 8/16-bit files from sRGB -- for every parameter,
  scalar ones included (checked with Mitsuba 3.9.1: a grey 128 PNG gives alpha 0.216 unless
  raw) -- and float files (EXR) are linear either way. The :class:`TextureRef` says the same.
* documents older than version 2 (Mitsuba 0.6) have their camelCase parameter names turned into
  snake_case, as Mitsuba 3's own upgrade does (``intIOR`` -> ``int_ior``).

The XML is parsed with defusedxml: entity declarations (entity expansion, external entities) are
refused whatever the expat version, as are documents nested deeper than
:data:`~matremap.formats.common.MAX_XML_DEPTH` elements.

Anything else -- another BSDF or texture plugin, spectra given as wavelength lists, an unknown
parameter -- raises a :class:`MatremapError` naming it; parameters without an effect on the
image (``sample_visible``, a texture's filter and wrap mode) are noted.

**Writing.** :func:`write` writes a scene (version 3.0.0) holding the material as the top-level
BSDF ``material`` (inside a ``normalmap`` wrapper when the map set has a normal map), its maps
copied beside the XML as ``bitmap`` textures (``raw`` for data maps; files converted to linear
EXR where their encoding is not what Mitsuba would assume), and the probe sphere of
:mod:`matremap.core.scene` (radius 2, turned so that Mitsuba's UVs are matremap's) under a constant
white environment, seen by the probe camera; ``$spp``, ``$resolution`` and ``$max_depth`` are
``<default>`` parameters, so ``mitsuba file.xml`` or ``mi.load_file(file)`` renders it as it is.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass
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

FORMAT = "mitsuba-xml"

#: Mitsuba 3's named indices of refraction (include/mitsuba/core/ior.h, after Hecht, Optics, 4th ed.;
#: measured between 0 and 20 C at about 589 nm)
IOR_TABLE: dict[str, float] = {
    "vacuum": 1.0,
    "helium": 1.000036,
    "hydrogen": 1.000132,
    "air": 1.000277,
    "carbon dioxide": 1.00045,
    "water": 1.3330,
    "acetone": 1.36,
    "ethanol": 1.361,
    "carbon tetrachloride": 1.461,
    "glycerol": 1.4729,
    "benzene": 1.501,
    "silicone oil": 1.52045,
    "bromine": 1.661,
    "water ice": 1.31,
    "fused quartz": 1.458,
    "pyrex": 1.470,
    "acrylic glass": 1.49,
    "polypropylene": 1.49,
    "bk7": 1.5046,
    "sodium chloride": 1.544,
    "amber": 1.55,
    "pet": 1.5750,
    "diamond": 2.419,
}

#: Mitsuba plugin -> matremap model
PLUGINS = {
    "diffuse": "mitsuba3:diffuse",
    "roughconductor": "mitsuba3:roughconductor",
    "roughplastic": "mitsuba3:roughplastic",
    "principled": "mitsuba3:principled",
}
MODELS = tuple(PLUGINS.values())
WRAPPERS = ("twosided", "normalmap", "bumpmap", "mask")

_PRINCIPLED_SCALARS = (
    "roughness",
    "metallic",
    "spec_tint",
    "anisotropic",
    "sheen",
    "sheen_tint",
    "clearcoat",
    "clearcoat_gloss",
    "spec_trans",
)
#: parameters each plugin accepts (Mitsuba 3 plugin reference)
_ACCEPTED = {
    "diffuse": ("reflectance",),
    "roughconductor": (
        "distribution",
        "alpha",
        "alpha_u",
        "alpha_v",
        "material",
        "eta",
        "k",
        "specular_reflectance",
        "sample_visible",
    ),
    "roughplastic": (
        "distribution",
        "alpha",
        "int_ior",
        "ext_ior",
        "nonlinear",
        "specular_reflectance",
        "diffuse_reflectance",
        "sample_visible",
    ),
    "principled": ("base_color", "specular", "eta", *_PRINCIPLED_SCALARS, "sample_visible"),
}
#: parameters Mitsuba 3 takes as plain numbers, not textures
_CONSTANT_ONLY = {"roughplastic": ("alpha", "int_ior", "ext_ior"), "principled": ("specular", "eta")}
_NO_EFFECT = ("sample_visible",)  # changes sampling only, not the expected image


# ---------------------------------------------------------------------------------------------
# Reading


@dataclass
class _Prop:
    """One named property of a plugin: kind is float, rgb, string, boolean, texture, bsdf or other."""

    kind: str
    value: Any
    tag: str


class _Reader:
    def __init__(self, path: Path, root: ET.Element, confinement: Confinement | None = None) -> None:
        self.path = path
        self.root = root
        self.confinement = confinement
        self.ids: dict[str, ET.Element] = {}
        for el in root.iter():
            if el.get("id") is not None and el.tag in ("bsdf", "texture"):
                self.ids[el.get("id")] = el  # type: ignore[index]
        version = root.get("version")
        self.legacy = False
        if version is not None:
            try:
                self.legacy = int(version.split(".")[0]) < 2
            except ValueError:
                raise MatremapError(f"{path}: version {version!r} is not a version number like 3.0.0") from None

    def fail(self, msg: str) -> MatremapError:
        return MatremapError(f"{self.path}: {msg}")

    def name_of(self, el: ET.Element) -> str:
        name = el.get("name")
        if name is not None and self.legacy:
            name = re.sub(r"(?<=[a-z0-9])(?=[A-Z])", "_", name).lower()
        return name or ""

    def props(self, el: ET.Element, what: str) -> dict[str, _Prop]:
        """The named properties of plugin element ``el`` (nested BSDFs are named by position)."""
        out: dict[str, _Prop] = {}
        nested = 0
        for child in el:
            tag = child.tag
            if not isinstance(tag, str):  # comments
                continue
            name = self.name_of(child)
            if tag == "ref":
                target = self.ids.get(child.get("id", ""))
                if target is None:
                    raise self.fail(
                        f"{what} refers to id {child.get('id')!r}, which no top-level <bsdf> or "
                        f"<texture> has; define it or fix the id"
                    )
                tag, child = target.tag, target
            if tag == "bsdf":
                key = name or f"#bsdf{nested}"
                nested += 1
                out[key] = _Prop("bsdf", child, tag)
                continue
            if not name:
                raise self.fail(f"<{tag}> inside {what} has no name attribute")
            if name in out:
                raise self.fail(f"{what} sets {name} twice; keep one")
            value = child.get("value")
            if tag in ("float", "integer"):
                out[name] = _Prop("float", self.number(value, name, what), tag)
            elif tag in ("rgb", "spectrum", "color"):
                nums = self.numbers(value, name, what, tag)
                out[name] = _Prop("rgb" if len(nums) == 3 else "float", nums if len(nums) == 3 else nums[0], tag)
            elif tag == "string":
                out[name] = _Prop("string", value or "", tag)
            elif tag == "boolean":
                if (value or "").lower() not in ("true", "false"):
                    raise self.fail(f"{what}: boolean {name} must be true or false, not {value!r}")
                out[name] = _Prop("boolean", value.lower() == "true", tag)  # type: ignore[union-attr]
            elif tag == "texture":
                out[name] = _Prop("texture", child, tag)
            else:
                out[name] = _Prop("other", child, tag)
        return out

    def number(self, value: str | None, name: str, what: str) -> float:
        try:
            return float(value)  # type: ignore[arg-type]
        except (TypeError, ValueError):
            raise self.fail(f"{what}: {name}={value!r} is not a number") from None

    def numbers(self, value: str | None, name: str, what: str, tag: str) -> list[float]:
        parts = (value or "").replace(",", " ").split()
        if tag == "spectrum" and any(":" in p for p in parts):
            raise self.fail(
                f"{what}: {name} is a spectrum given as wavelength:value pairs; matremap reads RGB "
                f'materials, give it as <rgb name="{name}" value="r, g, b"/>'
            )
        try:
            nums = [float(p) for p in parts]
        except ValueError:
            raise self.fail(f"{what}: <{tag}> {name}={value!r} is not one or three numbers") from None
        if len(nums) not in (1, 3):
            raise self.fail(f"{what}: <{tag}> {name} has {len(nums)} values; give one or three")
        return nums

    # -- materials ------------------------------------------------------------------------------
    def candidates(self) -> list[tuple[str, ET.Element]]:
        if self.root.tag == "bsdf":
            return [(self.root.get("id") or self.root.get("type") or "bsdf", self.root)]
        out: list[tuple[str, ET.Element]] = []
        for el in self.root:
            if el.tag == "bsdf":
                out.append((el.get("id") or f"bsdf {len(out)}", el))
        for i, shape in enumerate(el for el in self.root.iter("shape")):
            for child in shape:
                if child.tag == "bsdf":
                    label = shape.get("id") or f"shape {i} ({shape.get('type')})"
                    out.append((child.get("id") or f"{label}/bsdf", child))
        return out

    def unwrap(self, el: ET.Element, notes: list[str]) -> tuple[ET.Element, TextureRef | None]:
        normal: TextureRef | None = None
        while el.get("type") in WRAPPERS:
            kind = el.get("type")
            what = f'<bsdf type="{kind}">'
            props = self.props(el, what)
            inner = [p.value for p in props.values() if p.kind == "bsdf"]
            if not inner:
                raise self.fail(f"{what} wraps no <bsdf>; put the material inside it")
            if kind == "twosided":
                if len(inner) > 1:
                    notes.append("twosided with a different back-side BSDF: only the front side is read")
                notes.append("twosided unwrapped: the probe sees the front side only")
            elif kind == "normalmap":
                tex = props.get("normalmap")
                if tex is None or tex.kind != "texture":
                    raise self.fail(f'{what} has no <texture name="normalmap">; add the normal map\'s bitmap')
                ref = self.texture(tex.value, "normal map", colour=False)
                if normal is None:
                    if ref.colorspace != "linear":
                        notes.append(
                            "the normal map's bitmap is not raw: Mitsuba decodes it from sRGB, "
                            'which bends the normals; matremap reads it as linear (set raw="true")'
                        )
                    normal = TextureRef(ref.path)
                    notes.append(f"normalmap wrapper: its bitmap {ref.path.name} is the asset's normal map")
                else:
                    notes.append("a second normalmap wrapper was dropped (only the outermost is kept)")
            elif kind == "bumpmap":
                notes.append("bumpmap wrapper dropped: matremap's maps carry no bump (height) map")
            else:
                notes.append("mask wrapper dropped: opacity is not remapped")
            el = inner[0]
        return el, normal

    def texture(self, el: ET.Element, param: str, colour: bool) -> TextureRef:
        from matremap.svbrdf.textures import image_info

        kind = el.get("type")
        what = f"texture for {param}"
        if kind != "bitmap":
            raise self.fail(
                f"{what} is a {kind!r} texture; matremap reads bitmap textures only (bake it into an image)"
            )
        props = self.props(el, what)
        unknown = set(props) - {"filename", "raw", "filter_type", "wrap_mode", "to_uv", "format", "accel"}
        if unknown:
            raise self.fail(f"{what}: unknown bitmap parameter(s) {', '.join(sorted(unknown))}")
        fname = props.get("filename")
        if fname is None or fname.kind != "string" or not fname.value:
            raise self.fail(f'{what}: the bitmap has no <string name="filename">; add the image\'s file name')
        path = resolve_reference(
            fname.value, self.path.resolve().parent, f"{self.path}: bitmap filename for {param}", self.confinement
        )
        if not path.is_file():
            raise self.fail(
                f"bitmap {fname.value} for {param} not found at {path}; put it beside the XML or fix its filename"
            )
        raw = props.get("raw")
        if raw is not None and raw.kind != "boolean":
            raise self.fail(f"{what}: raw must be a <boolean>")
        info = image_info(path, colour=colour)
        colorspace = "linear" if (raw is not None and raw.value) or not info.integer else "srgb"
        return TextureRef(path.resolve(), None, colorspace)

    def material(self, label: str, el: ET.Element, index: int) -> MaterialAsset:
        """The asset of BSDF element ``el`` (named ``label``, the ``index``-th of the file): its
        wrappers unwrapped, its core plugin's parameters read as a ``mitsuba3:*`` material."""
        notes: list[str] = []
        core, normal = self.unwrap(el, notes)
        plugin = core.get("type")
        if plugin not in PLUGINS:
            raise self.fail(
                f"material {label!r} is a {plugin!r} BSDF; matremap reads {', '.join(PLUGINS)} "
                f"(inside {', '.join(WRAPPERS)} wrappers)"
            )
        what = f'<bsdf type="{plugin}"> {label!r}'
        props = self.props(core, what)
        extra = sorted(set(props) - set(_ACCEPTED[plugin]))
        if extra:
            raise self.fail(
                f"{what}: unknown parameter(s) {', '.join(extra)}; {plugin} takes {', '.join(_ACCEPTED[plugin])}"
            )
        values = _BsdfValues(self, plugin, what, props, notes)
        values.read()
        model = PLUGINS[plugin]
        uniform = {k: v for k, v in values.constants.items() if k not in values.textures}
        try:
            Material.create(model, uniform)  # names, ranges and options, with the model's own messages
        except MatremapError as e:
            raise self.fail(f"material {label!r}: {e}") from None
        if normal is not None and not values.textures:
            notes.append("the material is uniform apart from its normal map")
        return MaterialAsset(
            path=self.path,
            format=FORMAT,
            name=label,
            model=model,
            constants=values.constants,
            textures=values.textures,
            normal=normal,
            notes=notes,
            document=self.root,
            index=index,
        )


class _BsdfValues:
    """The parameters of one core BSDF element read as a ``mitsuba3:*`` model's constants (model
    units and options) and textures, the way Mitsuba 3 reads them (see the module doc)."""

    def __init__(self, reader: _Reader, plugin: str, what: str, props: dict[str, _Prop], notes: list[str]) -> None:
        self.reader, self.plugin, self.what, self.props, self.notes = reader, plugin, what, props, notes
        self.spec = get_model(PLUGINS[plugin])
        self.constants: dict[str, Any] = {}
        self.textures: dict[str, TextureRef] = {}

    def fail(self, msg: str) -> MatremapError:
        return self.reader.fail(f"{self.what}: {msg}")

    def read(self) -> None:
        """Read the options every plugin shares, then the plugin's own parameters."""
        if "distribution" in self.props:
            dist = self.string("distribution")
            choices = self.spec.option("distribution").choices
            if dist not in choices:
                raise self.fail(f"distribution {dist!r} is not one of {', '.join(choices)}")
            self.constants["distribution"] = dist
        for name in _NO_EFFECT:
            if name in self.props:
                self.notes.append(f"{name} ignored: it changes how Mitsuba samples the BSDF, not the image")
        {
            "diffuse": self.diffuse,
            "roughconductor": self.roughconductor,
            "roughplastic": self.roughplastic,
            "principled": self.principled,
        }[self.plugin]()

    # -- one parameter -------------------------------------------------------------------------
    def take(self, name: str, target: str | None = None) -> None:
        """Read parameter ``name`` (if given) as a number, an RGB colour or a texture of ``target``."""
        prop = self.props.get(name)
        if prop is None:
            return
        target = target or name
        p = self.spec.param(target)
        if prop.kind == "texture":
            if name in _CONSTANT_ONLY.get(self.plugin, ()):
                raise self.fail(f"Mitsuba 3 takes {name} as a number, not a texture")
            colour = p.channels == 3 and p.role != "roughness"
            self.textures[target] = self.reader.texture(prop.value, name, colour=colour)
        elif prop.kind == "float":
            self.constants[target] = float(prop.value)
        elif prop.kind == "rgb" and p.channels == 3:
            self.constants[target] = [float(x) for x in prop.value]
        else:
            kind = "an RGB colour, a number or a texture" if p.channels == 3 else "a number or a texture"
            raise self.fail(f"{name} must be {kind}, not <{prop.tag}>")

    def string(self, name: str) -> str | None:
        """The value of ``<string name=...>``, or None when it is not given."""
        prop = self.props.get(name)
        if prop is None:
            return None
        if prop.kind != "string":
            raise self.fail(f"{name} must be a <string>, not <{prop.tag}>")
        return prop.value

    # -- the plugins ---------------------------------------------------------------------------
    def diffuse(self) -> None:
        self.take("reflectance")

    def roughconductor(self) -> None:
        """alpha, specular_reflectance and the conductor: a named ``material``, or ``eta``/``k``
        (``material=custom``), or neither (Mitsuba's perfect mirror, ``material=none``)."""
        self.isotropic_alpha()
        self.take("alpha")
        self.take("specular_reflectance")
        material = self.string("material")
        has_ior = "eta" in self.props or "k" in self.props
        if has_ior and material not in (None, "none"):
            raise self.fail("give either material or eta/k, not both (Mitsuba refuses both)")
        if has_ior:
            self.constants["material"] = "custom"
            self.constants.setdefault("eta", 0.0)  # Mitsuba's defaults when only one of them is given
            self.constants.setdefault("k", 1.0)
            self.take("eta")
            self.take("k")
            for name in ("eta", "k"):
                if name in self.textures:
                    self.constants.pop(name, None)
            return
        material = material or "none"
        choices = self.spec.option("material").choices
        if material not in choices:
            raise self.fail(
                f"material {material!r} is not one of Mitsuba's conductors "
                f"({', '.join(c for c in choices if c != 'custom')})"
            )
        self.constants["material"] = material

    def isotropic_alpha(self) -> None:
        """``alpha_u`` = ``alpha_v`` given together become ``alpha``; anisotropy is refused."""
        props = self.props
        if "alpha_u" not in props and "alpha_v" not in props:
            return
        au, av = props.get("alpha_u"), props.get("alpha_v")
        if "alpha" in props or au is None or av is None:
            raise self.fail("give alpha, or alpha_u and alpha_v together")
        if au.kind != "float" or av.kind != "float" or au.value != av.value:
            raise self.fail(
                "anisotropic roughness (alpha_u != alpha_v) is not supported; matremap's "
                "roughconductor is isotropic, give one alpha"
            )
        props["alpha"] = au
        del props["alpha_u"], props["alpha_v"]

    def roughplastic(self) -> None:
        """alpha, the two IORs (numbers or names of Mitsuba's table), nonlinear, the reflectances."""
        self.take("alpha")
        for name in ("int_ior", "ext_ior"):
            self.ior(name)
        if "nonlinear" in self.props:
            if self.props["nonlinear"].kind != "boolean":
                raise self.fail("nonlinear must be a <boolean>")
            self.constants["nonlinear"] = "true" if self.props["nonlinear"].value else "false"
        self.take("specular_reflectance")
        self.take("diffuse_reflectance")

    def ior(self, name: str) -> None:
        """An index of refraction given as a number or by name (:data:`IOR_TABLE`)."""
        prop = self.props.get(name)
        if prop is None:
            return
        if prop.kind != "string":
            self.take(name)
            return
        key = prop.value.strip().lower()
        if key not in IOR_TABLE:
            raise self.fail(
                f"{name}={prop.value!r} is not one of Mitsuba's named IORs ({', '.join(IOR_TABLE)}); give a number"
            )
        self.constants[name] = IOR_TABLE[key]
        self.notes.append(f"{name} {prop.value!r} = {IOR_TABLE[key]:g} (Mitsuba's IOR table)")

    def principled(self) -> None:
        """base_color, the scalar lobes, and specular (given as such or as ``eta``)."""
        self.take("base_color")
        for name in _PRINCIPLED_SCALARS:
            self.take(name)
        if "eta" in self.props and "specular" in self.props:
            raise self.fail("give either eta or specular, not both")
        if "eta" not in self.props:
            self.take("specular")
            return
        prop = self.props["eta"]
        if prop.kind != "float" or not prop.value > 1.0:
            raise self.fail(f"eta must be a number above 1, not {prop.value!r}")
        f0 = ((prop.value - 1.0) / (prop.value + 1.0)) ** 2
        spec_value = f0 / 0.08
        if spec_value > 1.0:
            raise self.fail(
                f"eta={prop.value:g} is beyond specular = 1 (eta 1.8); matremap's "
                f"principled model takes specular in [0, 1]"
            )
        self.constants["specular"] = spec_value
        self.notes.append(f"eta {prop.value:g} read as specular {spec_value:.6g} (F0 = 0.08 specular)")


def _substitute(root: ET.Element, path: Path) -> None:
    """Apply ``<default name value>`` to ``$name`` in every attribute, as Mitsuba does."""
    defaults: dict[str, str] = {}
    for el in list(root):
        if el.tag == "default":
            name, value = el.get("name"), el.get("value")
            if name is None or value is None:
                raise MatremapError(f"{path}: a <default> needs name and value attributes")
            defaults[name] = value
    pattern = re.compile(r"\$(\w+)")

    def repl(m: re.Match) -> str:
        if m.group(1) not in defaults:
            raise MatremapError(
                f'{path}: ${m.group(1)} is used but no <default name="{m.group(1)}" value=...> '
                f"gives it a value; add one"
            )
        return defaults[m.group(1)]

    for el in root.iter():
        if el.tag == "default":
            continue
        for k, v in el.attrib.items():
            if "$" in v:
                el.set(k, pattern.sub(repl, v))


def material_names(path: str | Path) -> list[str]:
    """The names of a scene's BSDFs (their ids, or the names the module doc gives unnamed ones), in order."""
    return [n for n, _ in _materials(Path(path), None)[2]]


def _materials(p: Path, confinement: Confinement | None) -> tuple[Any, _Reader, list[tuple[str, Any]]]:
    """The parsed scene, its reader and its BSDFs as (name, element)."""
    if not p.is_file():
        raise MatremapError(f"{p} not found")
    root = parse_untrusted_xml(p, "a Mitsuba 3 scene file")
    if root.tag not in ("scene", "bsdf"):
        raise MatremapError(f"{p} is not a Mitsuba scene: its root element is <{root.tag}>, not <scene> or <bsdf>")
    for el in root.iter():
        if el.tag == "include":
            raise MatremapError(f"{p}: <include> is not supported; paste the included file's BSDFs into the scene")
    _substitute(root, p)
    reader = _Reader(p, root, confinement)
    found = reader.candidates()
    if not found:
        raise MatremapError(f"{p} holds no <bsdf>; matremap reads a scene's BSDFs (top-level or inside shapes)")
    return root, reader, found


def read(
    path: str | Path, material: str | int | None = None, *, confinement: Confinement | None = None
) -> MaterialAsset:
    """One material of a Mitsuba 3 scene (or bare ``<bsdf>``) XML file as a :class:`MaterialAsset`
    of a ``mitsuba3:*`` model. ``material``: a BSDF id (see the module doc for names) or an index;
    the first by default. Bitmaps must lie in the file's folder or a folder ``confinement`` allows
    (default: the one in effect, :mod:`matremap.formats.confine`)."""
    p = Path(path)
    root, reader, found = _materials(p, confinement)
    index = pick_material(p, [n for n, _ in found], material, "BSDF")
    asset = reader.material(*found[index], index)
    if reader.legacy:
        asset.notes.insert(
            0, f"version {root.get('version')} file: camelCase parameter names read as Mitsuba 3's snake_case names"
        )
    return asset


# ---------------------------------------------------------------------------------------------
# Writing


def _num(x: float) -> str:
    return repr(float(x))


def _rgb(v: np.ndarray) -> str:
    return ", ".join(_num(x) for x in np.asarray(v, dtype=float).reshape(-1))


def _bsdf_xml(m: Material, textures: Mapping[str, ET.Element]) -> ET.Element:
    spec = m.spec
    plugin = next(k for k, v in PLUGINS.items() if v == spec.id)
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
        for name in ("base_color", *_PRINCIPLED_SCALARS, "specular"):
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
    plugin = next(k for k, v in PLUGINS.items() if v == m.spec.id)
    for name in maps:
        if name in _CONSTANT_ONLY.get(plugin, ()):
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
