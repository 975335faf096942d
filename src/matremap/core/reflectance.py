"""How a model's parameters give its specular reflectance at normal incidence, F0.

Each :class:`~matremap.core.models.ModelSpec` that has a specular part names one of these in its
``reflectance`` field. The class knows which of the model's parameters it reads, how they give F0
per channel (:meth:`Reflectance.f0`), how F0 is written back into them (:meth:`Reflectance.write_f0`)
and which parameter a map of F0 drives. A new way of expressing F0 (a layered model, say) is a new
subclass; no caller looks inside.

Formulas: F0 of a (complex) IOR is eq. (1) of Sztrajman et al. 2019, the glTF dielectric F0 is
KHR_materials_ior / KHR_materials_specular, and the metal-roughness blend is the glTF 2.0
specification's appendix B (``F0 = mix(dielectric F0, baseColor, metallic)``); see
:mod:`matremap.core.optics`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping, MutableMapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from matremap.core.optics import dielectric_f0, f0_from_ior, ior_from_f0

#: parameter name -> number of channels (1 or 3), as the model's ``ParamSpec`` says
Channels = Mapping[str, int]


def as_floats(v: Any) -> np.ndarray:
    """An array of floats, keeping float32 (texture maps) as float32."""
    a = np.asarray(v)
    return a if a.dtype in (np.float32, np.float64) else a.astype(float)


def as_rgb(v: Any, channels: int) -> np.ndarray:
    """Floats with a trailing RGB axis: a one-channel value [...] is repeated to [..., 3]."""
    v = as_floats(v)
    return np.repeat(v[..., None], 3, axis=-1) if channels == 1 else v


@dataclass(frozen=True)
class Reflectance(ABC):
    """Base of the ways a model expresses F0. Subclasses name the model's parameters as fields."""

    #: whether :meth:`write_f0` also writes the diffuse albedo (then the diffuse quantity must not
    #: be written to the model's diffuse parameter on its own)
    writes_albedo: ClassVar[bool] = False

    @property
    @abstractmethod
    def params(self) -> tuple[str, ...]:
        """Every parameter F0 is computed from."""

    @property
    @abstractmethod
    def map_params(self) -> tuple[str, ...]:
        """The parameters a map set carries F0 in (the others are expected to be constants)."""

    @abstractmethod
    def driven_param(self, metal: bool = True) -> str:
        """The parameter a map of F0 drives; ``metal``: whether the material is held metallic."""

    @property
    def specular_map_param(self) -> str | None:
        """The parameter a ``*_specular`` map file binds by naming convention (None: no such file)."""
        return None

    def constant_param(self, metal: bool = True) -> str | None:
        """The parameter a map of F0 drives when the renderer takes it as one number only, not a texture
        (None: it may be a map). :meth:`write_f0` still writes it per texel; the map writer writes one
        value (:mod:`matremap.svbrdf.convert`)."""
        return None

    @abstractmethod
    def f0(self, values: Mapping[str, Any], channels: Channels) -> np.ndarray:
        """F0 per channel [..., 3] from parameter arrays (scalars [...], RGB [..., 3])."""

    @abstractmethod
    def write_f0(
        self, f0: np.ndarray, out: MutableMapping[str, Any], channels: Channels, diffuse: np.ndarray | None = None
    ) -> list[str]:
        """Set the parameters in ``out`` that give ``f0`` [..., 3] (others in ``out`` held); return their names.
        ``diffuse``: the albedo to write too, used only where :attr:`writes_albedo`."""

    def albedo(self, diffuse: np.ndarray, values: Mapping[str, Any]) -> np.ndarray:
        """The diffuse albedo [..., 3] given the diffuse parameter's value (here: that value)."""
        return diffuse


@dataclass(frozen=True)
class SpecularParam(Reflectance):
    """The parameter *is* F0: Ward's ``specularReflectance``, pbr's ``F0``, Cycles Glossy ``Color``."""

    param: str

    @property
    def params(self) -> tuple[str, ...]:
        return (self.param,)

    @property
    def map_params(self) -> tuple[str, ...]:
        return (self.param,)

    def driven_param(self, metal: bool = True) -> str:
        return self.param

    @property
    def specular_map_param(self) -> str | None:
        return self.param

    def f0(self, values: Mapping[str, Any], channels: Channels) -> np.ndarray:
        return as_rgb(values[self.param], channels[self.param])

    def write_f0(
        self, f0: np.ndarray, out: MutableMapping[str, Any], channels: Channels, diffuse: np.ndarray | None = None
    ) -> list[str]:
        out[self.param] = f0 if channels[self.param] == 3 else f0.mean(axis=-1)
        return [self.param]


@dataclass(frozen=True)
class Dielectric(Reflectance):
    """A real interior IOR (scalar), optionally over an exterior IOR: F0 = ((n - 1)/(n + 1))^2 with
    n = ior / ext_ior (Sztrajman et al. 2019 eq. 1, k = 0); written back as n = (1 + sqrt F0)/(1 - sqrt F0)
    of the channel mean."""

    ior: str
    ext_ior: str | None = None

    @property
    def params(self) -> tuple[str, ...]:
        return (self.ior,) if self.ext_ior is None else (self.ior, self.ext_ior)

    @property
    def map_params(self) -> tuple[str, ...]:
        return (self.ior,)

    def driven_param(self, metal: bool = True) -> str:
        return self.ior

    def f0(self, values: Mapping[str, Any], channels: Channels) -> np.ndarray:
        eta = as_floats(values[self.ior]) / (as_floats(values[self.ext_ior]) if self.ext_ior is not None else 1.0)
        return as_rgb(f0_from_ior(eta), 1)

    def write_f0(
        self, f0: np.ndarray, out: MutableMapping[str, Any], channels: Channels, diffuse: np.ndarray | None = None
    ) -> list[str]:
        out[self.ior] = ior_from_f0(f0.mean(axis=-1)) * (out[self.ext_ior] if self.ext_ior is not None else 1.0)
        return [self.ior]


@dataclass(frozen=True)
class Conductor(Reflectance):
    """A complex IOR eta + i k (RGB or scalar each), optionally over a scalar exterior IOR:
    F0 = ((eta - 1)^2 + k^2) / ((eta + 1)^2 + k^2) of the relative IOR (Sztrajman et al. 2019 eq. 1).
    F0 is written into k with eta held: k = sqrt((F0 (eta + 1)^2 - (eta - 1)^2) / (1 - F0))."""

    eta: str
    k: str
    ext_eta: str | None = None

    @property
    def params(self) -> tuple[str, ...]:
        return (self.eta, self.k) if self.ext_eta is None else (self.eta, self.k, self.ext_eta)

    @property
    def map_params(self) -> tuple[str, ...]:
        return (self.eta, self.k)

    def driven_param(self, metal: bool = True) -> str:
        return self.k

    def f0(self, values: Mapping[str, Any], channels: Channels) -> np.ndarray:
        ext = as_floats(values[self.ext_eta])[..., None] if self.ext_eta is not None else 1.0
        eta = as_rgb(values[self.eta], channels[self.eta]) / ext
        k = as_rgb(values[self.k], channels[self.k]) / ext
        return f0_from_ior(eta, k)

    def write_f0(
        self, f0: np.ndarray, out: MutableMapping[str, Any], channels: Channels, diffuse: np.ndarray | None = None
    ) -> list[str]:
        ext = out[self.ext_eta][..., None] if self.ext_eta is not None else 1.0
        eta = as_rgb(out[self.eta], channels[self.eta]) / ext
        k2 = (f0 * (eta + 1) ** 2 - (eta - 1) ** 2) / (1.0 - f0)
        out[self.k] = np.sqrt(np.maximum(k2, 0.0)) * ext
        return [self.k]


def metal_blend_colour(
    f0: np.ndarray, albedo: np.ndarray, metallic: np.ndarray, f0_dielectric: Callable[[], np.ndarray]
) -> tuple[np.ndarray, np.ndarray]:
    """The base colour, and the dielectric part's F0, with which F0 = mix(F0_d, colour, m) and albedo =
    colour (1 - m) read back (Burley 2012 §5.3 "metallic"; glTF 2.0 appendix B), per texel of ``metallic`` m:
    a metal (m >= 0.5) keeps F0 exactly, colour (F0 - F0_d (1 - m)) / m with the held ``f0_dielectric``; a
    dielectric keeps the albedo, colour albedo / (1 - m) and F0_d (F0 - m colour) / (1 - m). At m = 1 and m = 0
    these are F0 and the albedo themselves; ``f0_dielectric`` (per texel) is only asked for a partial metal."""
    m = metallic
    metal = m >= 0.5
    if not bool(np.any((m > 0.0) & (m < 1.0))):
        return np.where(metal, f0, albedo), f0
    colour = np.where(
        metal, (f0 - f0_dielectric() * (1.0 - m)) / np.maximum(m, 1e-12), albedo / np.maximum(1.0 - m, 1e-12)
    )
    return colour, np.clip((f0 - colour * m) / np.maximum(1.0 - m, 1e-12), 0.0, 1.0)


@dataclass(frozen=True)
class MetalRough(Reflectance):
    """glTF metallic-roughness with KHR_materials_ior / KHR_materials_specular:
    F0 = mix(min(((ior - 1)/(ior + 1))^2 specularColor, 1) specular, baseColor, metallic) (glTF 2.0
    appendix B); the base colour is albedo only in proportion to 1 - metallic."""

    base_color: str
    metallic: str
    ior: str
    specular: str
    specular_color: str

    writes_albedo: ClassVar[bool] = True

    @property
    def params(self) -> tuple[str, ...]:
        return (self.base_color, self.metallic, self.ior, self.specular, self.specular_color)

    @property
    def map_params(self) -> tuple[str, ...]:
        return (self.base_color, self.metallic)

    def driven_param(self, metal: bool = True) -> str:
        """A metal's base colour, or a dielectric's specular colour."""
        return self.base_color if metal else self.specular_color

    def f0(self, values: Mapping[str, Any], channels: Channels) -> np.ndarray:
        m = as_floats(values[self.metallic])[..., None]
        f0_d = dielectric_f0(
            as_floats(values[self.ior])[..., None],
            as_floats(values[self.specular])[..., None],
            as_rgb(values[self.specular_color], 3),
        )
        return f0_d * (1.0 - m) + as_rgb(values[self.base_color], 3) * m

    def albedo(self, diffuse: np.ndarray, values: Mapping[str, Any]) -> np.ndarray:
        """A metal's base colour is no albedo: diffuse (1 - metallic)."""
        return diffuse * (1.0 - as_floats(values[self.metallic])[..., None])

    def write_f0(
        self, f0: np.ndarray, out: MutableMapping[str, Any], channels: Channels, diffuse: np.ndarray | None = None
    ) -> list[str]:
        """glTF metallic-roughness from F0 and albedo, the template's metallic deciding per texel:
        a metal (metallic >= 0.5) takes F0 as base colour; a dielectric takes the albedo as base colour
        and F0 through specularColor = F0 / f0(ior) / specular (KHR_materials_specular), written only
        where it differs from the template's; a partial metal as :func:`metal_blend_colour` says."""
        m = as_floats(out[self.metallic])[..., None]
        metal = m >= 0.5
        albedo = np.asarray(out[self.base_color]) if diffuse is None else as_floats(diffuse)
        colour, f0 = metal_blend_colour(f0, albedo, m, lambda: self.f0({**out, self.metallic: 0.0}, channels))
        out[self.base_color] = colour
        driven = [self.base_color]
        if not np.all(metal):
            ior = np.asarray(out[self.ior])[..., None]
            specular = np.asarray(out[self.specular])[..., None]
            scale = np.maximum(specular * dielectric_f0(ior, 1.0, 1.0), 1e-12)
            current = dielectric_f0(ior, specular, np.asarray(out[self.specular_color]))
            if np.max(np.abs(np.where(metal, current, f0) - current)) > 1e-4 * max(float(np.max(current)), 1e-12):
                out[self.specular_color] = np.where(metal, np.asarray(out[self.specular_color]), f0 / scale)
                driven.append(self.specular_color)
        return driven


@dataclass(frozen=True)
class SpecularLevel(Reflectance):
    """A grey dielectric F0 given as a level: F0 = ``scale`` x the parameter (Burley 2012, "Physically-based
    shading at Disney", §5.3: ``specular`` in [0, 1] maps to F0 in [0, 0.08]; Mitsuba 3's ``principled`` takes
    eta = 2 / (1 - sqrt(0.08 specular)) - 1, the same F0). Written back as the channel mean / ``scale``.
    ``texture=False``: the renderer takes the level as one number (Mitsuba 3's ``principled.cpp`` reads
    ``props.get<float>("specular", 0.5f)``), see :meth:`Reflectance.constant_param`."""

    param: str
    scale: float = 0.08
    texture: bool = True

    @property
    def params(self) -> tuple[str, ...]:
        return (self.param,)

    @property
    def map_params(self) -> tuple[str, ...]:
        return (self.param,)

    def driven_param(self, metal: bool = True) -> str:
        return self.param

    def constant_param(self, metal: bool = True) -> str | None:
        return None if self.texture else self.param

    def f0(self, values: Mapping[str, Any], channels: Channels) -> np.ndarray:
        return as_rgb(self.scale * as_floats(values[self.param]), 1)

    def write_f0(
        self, f0: np.ndarray, out: MutableMapping[str, Any], channels: Channels, diffuse: np.ndarray | None = None
    ) -> list[str]:
        out[self.param] = np.clip(f0.mean(axis=-1) / self.scale, 0.0, 1.0)
        return [self.param]


@dataclass(frozen=True)
class Metalness(Reflectance):
    """A principled BSDF's metallic blend: F0 = mix(F0 of the dielectric part, base colour, metallic) (Burley
    2012 §5.3, "metallic"; Blender's Principled BSDF and Mitsuba 3's ``principled`` take a metal's F0 from its
    base colour, and scale the diffuse by 1 - metallic). Written back per texel as glTF's metal-roughness is:
    a metal (the template's metallic >= 0.5) takes F0 as its base colour, a dielectric takes its albedo as
    base colour and F0 through the dielectric part (an IOR, a specular level), written only where it is not
    metal; a partial metal as :func:`metal_blend_colour` says."""

    base_color: str
    metallic: str
    dielectric: Reflectance

    writes_albedo: ClassVar[bool] = True

    @property
    def params(self) -> tuple[str, ...]:
        return (self.base_color, self.metallic, *self.dielectric.params)

    @property
    def map_params(self) -> tuple[str, ...]:
        return (self.base_color, self.metallic)

    def driven_param(self, metal: bool = True) -> str:
        """A metal's base colour, or the dielectric part's parameter."""
        return self.base_color if metal else self.dielectric.driven_param(False)

    def constant_param(self, metal: bool = True) -> str | None:
        """None for a metal (its base colour takes a map), else the dielectric part's."""
        return None if metal else self.dielectric.constant_param(False)

    def f0(self, values: Mapping[str, Any], channels: Channels) -> np.ndarray:
        m = as_floats(values[self.metallic])[..., None]
        return self.dielectric.f0(values, channels) * (1.0 - m) + as_rgb(values[self.base_color], 3) * m

    def albedo(self, diffuse: np.ndarray, values: Mapping[str, Any]) -> np.ndarray:
        """A metal's base colour is no albedo: diffuse (1 - metallic)."""
        return diffuse * (1.0 - as_floats(values[self.metallic])[..., None])

    def write_f0(
        self, f0: np.ndarray, out: MutableMapping[str, Any], channels: Channels, diffuse: np.ndarray | None = None
    ) -> list[str]:
        m = as_floats(out[self.metallic])[..., None]
        metal = m >= 0.5
        albedo = np.asarray(out[self.base_color]) if diffuse is None else as_floats(diffuse)
        colour, part = metal_blend_colour(f0, albedo, m, lambda: self.dielectric.f0(out, channels))
        out[self.base_color] = colour
        driven = [self.base_color]
        if not np.all(metal):
            name = self.dielectric.driven_param(False)
            held = np.asarray(out[name], dtype=float)
            self.dielectric.write_f0(part, out, channels)
            out[name] = np.where(metal[..., 0] if held.ndim < metal.ndim else metal, held, np.asarray(out[name]))
            driven.append(name)
        return driven
