"""What matremap knows of Mitsuba 3's BSDF plugins: the plugins it reads and the models they become,
the parameters each takes, Mitsuba's named IORs, and the records a read BSDF is kept in.

Sources: the Mitsuba 3.9 plugin reference (``src/bsdfs/*.cpp``) and ``include/mitsuba/core/ior.h``
(values after Hecht, *Optics*, 4th ed.). :mod:`matremap.formats.mitsuba_bsdfs` says how each plugin is read.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from matremap.formats.mitsuba_textures import TextureSource

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

#: Mitsuba plugin -> matremap model (smooth plugins read at the rough model's mirror limit)
PLUGINS = {
    "diffuse": "mitsuba3:diffuse",
    "roughconductor": "mitsuba3:roughconductor",
    "roughplastic": "mitsuba3:roughplastic",
    "principled": "mitsuba3:principled",
    "conductor": "mitsuba3:roughconductor",
    "plastic": "mitsuba3:roughplastic",
    "dielectric": "mitsuba3:dielectric",
    "roughdielectric": "mitsuba3:roughdielectric",
    "thindielectric": "mitsuba3:thindielectric",
}
MODELS = (
    "mitsuba3:diffuse",
    "mitsuba3:roughconductor",
    "mitsuba3:roughconductor-anisotropic",
    "mitsuba3:roughplastic",
    "mitsuba3:principled",
    "mitsuba3:dielectric",
    "mitsuba3:roughdielectric",
    "mitsuba3:thindielectric",
)
#: models written with another plugin than their name says
MODEL_PLUGINS = {"mitsuba3:roughconductor-anisotropic": "roughconductor"}
WRAPPERS = ("twosided", "normalmap", "bumpmap", "mask")
TRANSMISSIVE = ("dielectric", "roughdielectric", "thindielectric")
#: the alpha smooth plugins are read at: Mitsuba's microfacet floor
MIRROR_ALPHA = 1e-4

PRINCIPLED_SCALARS = (
    "roughness",
    "metallic",
    "spec_tint",
    "anisotropic",
    "sheen",
    "sheen_tint",
    "flatness",
    "clearcoat",
    "clearcoat_gloss",
    "spec_trans",
)
_CONDUCTOR = ("material", "eta", "k", "specular_reflectance")
_PLASTIC = ("int_ior", "ext_ior", "nonlinear", "specular_reflectance", "diffuse_reflectance")
_GLASS = ("int_ior", "ext_ior", "specular_reflectance", "specular_transmittance")
#: parameters each plugin accepts (Mitsuba 3 plugin reference)
ACCEPTED = {
    "diffuse": ("reflectance",),
    "roughconductor": ("distribution", "alpha", "alpha_u", "alpha_v", *_CONDUCTOR, "sample_visible"),
    "conductor": _CONDUCTOR,
    "roughplastic": ("distribution", "alpha", *_PLASTIC, "sample_visible"),
    "plastic": _PLASTIC,
    "principled": ("base_color", "specular", "eta", *PRINCIPLED_SCALARS, "sample_visible"),
    "dielectric": _GLASS,
    "roughdielectric": ("distribution", "alpha", "alpha_u", "alpha_v", *_GLASS, "sample_visible"),
    "thindielectric": _GLASS,
}
#: parameters Mitsuba 3 takes as plain numbers, not textures
CONSTANT_ONLY = {
    "roughplastic": ("alpha", "int_ior", "ext_ior"),
    "principled": ("specular", "eta"),
    **{glass: ("int_ior", "ext_ior") for glass in ("dielectric", "roughdielectric", "thindielectric")},
}
NO_EFFECT = ("sample_visible",)  # changes sampling only, not the expected image


def plugin_of(model: str) -> str:
    """The Mitsuba plugin written for a ``mitsuba3:*`` model."""
    return MODEL_PLUGINS.get(model, model.split(":", 1)[1])


@dataclass
class Prop:
    """One named property of a plugin: kind is float, rgb, spectrum, string, boolean, texture, bsdf,
    transform or other; ``value`` a number, a list, (wavelengths, values), a string or an element."""

    kind: str
    value: Any
    tag: str


@dataclass
class Parts:
    """A BSDF element read: its model, constants, texture sources, normal map, opacity and notes."""

    label: str
    model: str
    constants: dict[str, Any] = field(default_factory=dict)
    textures: dict[str, TextureSource] = field(default_factory=dict)
    normal: TextureSource | None = None
    opacity: tuple[Any, TextureSource | None] | None = None
    twosided: bool = False
    notes: list[str] = field(default_factory=list)


__all__ = [
    "ACCEPTED",
    "CONSTANT_ONLY",
    "FORMAT",
    "IOR_TABLE",
    "MIRROR_ALPHA",
    "MODELS",
    "MODEL_PLUGINS",
    "NO_EFFECT",
    "PLUGINS",
    "PRINCIPLED_SCALARS",
    "TRANSMISSIVE",
    "WRAPPERS",
    "Parts",
    "Prop",
    "plugin_of",
]
