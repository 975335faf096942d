"""The parameters of one Mitsuba 3 core BSDF read as a ``mitsuba3:*`` model's constants and textures.

Sources: Mitsuba 3.9 ``src/bsdfs/{diffuse,conductor,roughconductor,plastic,roughplastic,principled,dielectric,
roughdielectric,thindielectric}.cpp``
and ``include/mitsuba/render/microfacet.h`` (alpha is clamped to >= 1e-4). The rules are listed in
:mod:`matremap.formats.mitsuba_bsdfs`; this module applies them to one element's properties.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from typing import Any, Protocol

import numpy as np

from matremap.dialects import get_model
from matremap.errors import MatremapError
from matremap.formats.mitsuba_plugins import (
    CONSTANT_ONLY,
    IOR_TABLE,
    MIRROR_ALPHA,
    NO_EFFECT,
    PLUGINS,
    PRINCIPLED_SCALARS,
    Prop,
)
from matremap.formats.mitsuba_textures import TextureSource
from matremap.formats.spectra import spectrum_to_srgb

ANISOTROPIC = "mitsuba3:roughconductor-anisotropic"


class TextureReader(Protocol):
    """What :class:`BsdfValues` needs of the scene's reader."""

    def fail(self, msg: str, el: ET.Element | None = None) -> MatremapError: ...

    def texture(self, el: ET.Element, param: str, scalar: bool, notes: list[str]) -> TextureSource: ...


class BsdfValues:
    """The parameters of one core BSDF element (``props``) in model units, options and textures."""

    def __init__(
        self, reader: TextureReader, plugin: str, what: str, props: dict[str, Prop], notes: list[str], el: ET.Element
    ) -> None:
        self.reader, self.plugin, self.what, self.props, self.notes, self.el = reader, plugin, what, props, notes, el
        self.model = PLUGINS[plugin]
        self.spec = get_model(self.model)
        self.constants: dict[str, Any] = {}
        self.textures: dict[str, TextureSource] = {}

    def fail(self, msg: str) -> MatremapError:
        return self.reader.fail(f"{self.what}: {msg}", self.el)

    def read(self) -> None:
        """Read the options every plugin shares, then the plugin's own parameters."""
        if "distribution" in self.props:
            dist = self.string("distribution")
            choices = self.spec.option("distribution").choices
            if dist not in choices:
                raise self.fail(f"distribution {dist!r} is not one of {', '.join(choices)}")
            self.constants["distribution"] = dist
        for name in NO_EFFECT:
            if name in self.props:
                self.notes.append(f"{name} ignored: it changes how Mitsuba samples the BSDF, not the image")
        {
            "diffuse": self.diffuse,
            "roughconductor": self.roughconductor,
            "conductor": self.conductor,
            "roughplastic": self.roughplastic,
            "plastic": self.plastic,
            "principled": self.principled,
            "dielectric": self.glass,
            "roughdielectric": self.glass,
            "thindielectric": self.glass,
        }[self.plugin]()

    # -- one parameter -------------------------------------------------------------------------
    def take(self, name: str, target: str | None = None) -> None:
        """Read parameter ``name`` (if given) as a number, an RGB colour, a spectrum or a texture of ``target``."""
        prop = self.props.get(name)
        if prop is None:
            return
        target = target or name
        p = self.spec.param(target)
        if prop.kind == "texture":
            if name in CONSTANT_ONLY.get(PLUGINS[self.plugin].split(":")[1], ()):
                raise self.fail(f"Mitsuba 3 takes {name} as a number, not a texture")
            scalar = p.channels == 1 or p.role == "roughness"
            self.textures[target] = self.reader.texture(prop.value, name, scalar=scalar, notes=self.notes)
        elif prop.kind == "float":
            self.constants[target] = float(prop.value)
        elif prop.kind == "rgb" and p.channels == 3:
            self.constants[target] = [float(x) for x in prop.value]
        elif prop.kind == "spectrum":
            self.constants[target] = self.spectrum(name, prop, p.channels, p.bounds[1] <= 1.0)
        else:
            kind = "an RGB colour, a number or a texture" if p.channels == 3 else "a number or a texture"
            raise self.fail(f"{name} must be {kind}, not <{prop.tag}>")

    def spectrum(self, name: str, prop: Prop, channels: int, bounded: bool) -> Any:
        """A wavelength:value spectrum as Mitsuba's RGB variants see it (:mod:`matremap.formats.spectra`)."""
        wavelengths, values = prop.value
        rgb = spectrum_to_srgb(wavelengths, values, bounded=bounded, d65=True)
        self.notes.append(
            f"{name}: spectrum of {len(prop.value[0])} samples converted to RGB {np.round(rgb, 4).tolist()} "
            "(CIE 1931 under D65, as Mitsuba's RGB variants do)"
        )
        if channels == 3:
            return [float(x) for x in rgb]
        return float(rgb @ np.array([0.212671, 0.715160, 0.072169]))

    def string(self, name: str) -> str | None:
        """The value of ``<string name=...>``, or None when it is not given."""
        prop = self.props.get(name)
        if prop is None:
            return None
        if prop.kind != "string":
            raise self.fail(f"{name} must be a <string>, not <{prop.tag}>")
        return str(prop.value)

    # -- the plugins ---------------------------------------------------------------------------
    def diffuse(self) -> None:
        self.take("reflectance")

    def conductor(self) -> None:
        """Smooth ``conductor``: ``roughconductor`` at the mirror limit (alpha 1e-4)."""
        self.mirror("conductor", "roughconductor")
        self.fresnel()

    def mirror(self, plugin: str, rough: str) -> None:
        """A smooth plugin as its rough twin at the mirror limit: alpha 1e-4 (Mitsuba's floor), GGX (a mirror
        has no microfacet distribution; GGX is what glTF and Cycles targets draw, so the fit at the widest
        resolvable lobe keeps F0: a smooth Ag conductor onto glTF gives base colour 0.86 at 3e-4 error with
        GGX, white at 0.155 with Beckmann)."""
        self.constants["alpha"] = MIRROR_ALPHA
        self.constants["distribution"] = "ggx"
        self.notes.append(
            f"smooth {plugin} read as {rough} at the mirror limit: alpha {MIRROR_ALPHA:g} (Mitsuba clamps every "
            "microfacet alpha to it), GGX"
        )

    def roughconductor(self) -> None:
        """alpha (isotropic), specular_reflectance and the conductor's Fresnel."""
        self.isotropic_alpha()
        for name in ("alpha", "alpha_u", "alpha_v"):
            self.take(name)
        self.fresnel()

    def fresnel(self) -> None:
        """specular_reflectance and the conductor: a named ``material``, or ``eta``/``k``
        (``material=custom``), or neither (Mitsuba's perfect mirror, ``material=none``)."""
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
        """``alpha_u`` = ``alpha_v`` given together become ``alpha``; different numbers make the material
        ``mitsuba3:roughconductor-anisotropic``; different textures are refused."""
        props = self.props
        if "alpha_u" not in props and "alpha_v" not in props:
            return
        au, av = props.get("alpha_u"), props.get("alpha_v")
        if "alpha" in props or au is None or av is None:
            raise self.fail("give alpha, or alpha_u and alpha_v together")
        same = au.kind == av.kind == "float" and au.value == av.value
        if same or (au.kind == av.kind == "texture" and au.value is av.value):
            props["alpha"] = au
            del props["alpha_u"], props["alpha_v"]
            return
        if au.kind != "float" or av.kind != "float":
            raise self.fail(
                "anisotropic roughness given by textures (alpha_u, alpha_v maps) is not supported: a map's texels "
                "would be remapped through one roughness; give alpha_u and alpha_v as numbers"
            )
        self.model = ANISOTROPIC
        self.spec = get_model(ANISOTROPIC)
        self.notes.append(
            f"anisotropic roughconductor: alpha_u {au.value:g} along the surface's dp/du, alpha_v {av.value:g} across"
        )

    def roughplastic(self) -> None:
        """alpha, the two IORs (numbers or names of Mitsuba's table), nonlinear, the reflectances."""
        self.take("alpha")
        self.plastic_layers()

    def plastic(self) -> None:
        """Smooth ``plastic``: ``roughplastic`` at the mirror limit (alpha 1e-4)."""
        self.mirror("plastic", "roughplastic")
        self.plastic_layers()

    def plastic_layers(self) -> None:
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

    def glass(self) -> None:
        """``dielectric``, ``roughdielectric`` (isotropic), ``thindielectric`` (Mitsuba 3.9 ``src/bsdfs/``): the
        IORs (numbers or names), the two multipliers and roughdielectric's alpha, all uniform (a glass is fitted on
        the transmission probe, which draws uniform materials: a texture is refused). Mitsuba refuses equal IORs
        for a dielectric and roughdielectric, and so does this; an interior IOR below the exterior one (eta < 1,
        e.g. water inside a denser medium) is read as it is, with a note."""
        textured = sorted(name for name, p in self.props.items() if p.kind == "texture")
        if textured:
            raise self.fail(
                f"{', '.join(textured)} given by a texture: a textured glass is not converted (the transmission probe "
                "draws uniform materials); give it as a number or colour"
            )
        if self.plugin == "roughdielectric":
            au, av = self.props.get("alpha_u"), self.props.get("alpha_v")
            if au is not None and av is not None and au.value != av.value:
                raise self.fail(
                    f"anisotropic roughness (alpha_u {au.value}, alpha_v {av.value}) is not supported for a "
                    "roughdielectric; give one alpha"
                )
            self.isotropic_alpha()
            self.take("alpha")
        for name in ("int_ior", "ext_ior"):
            self.ior(name)
        for name in ("specular_reflectance", "specular_transmittance"):
            self.take(name)
        spec = self.spec
        int_ior = float(self.constants.get("int_ior", spec.param("int_ior").default))
        ext_ior = float(self.constants.get("ext_ior", spec.param("ext_ior").default))
        if int_ior == ext_ior and self.plugin != "thindielectric":
            raise self.fail(f"int_ior and ext_ior are both {int_ior:g}; Mitsuba 3 refuses equal IORs, so does this")
        if int_ior < ext_ior:
            self.notes.append(
                f"int_ior {int_ior:g} below ext_ior {ext_ior:g}: relative IOR {int_ior / ext_ior:.4g} < 1 (a medium "
                "less dense than the one around); a target that assumes air outside takes the closest look it has"
            )

    def principled(self) -> None:
        """base_color, the scalar lobes, and specular (given as such or as ``eta``)."""
        self.take("base_color")
        for name in PRINCIPLED_SCALARS:
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


__all__ = ["BsdfValues", "TextureReader"]
