"""UsdPreviewSurface, emulated as its specification defines it and Storm settles what it leaves open.

Sources: the "UsdPreviewSurface Specification", version 2.5 (Pixar, OpenUSD ``docs/spec_usdpreviewsurface.rst``;
"Preview Surface" inputs and their fallbacks), and for what the specification leaves open, its reference
implementation in USD's rasteriser Storm (OpenUSD ``pxr/usdImaging/plugin/usdShaders/shaders/previewSurface.glslfx``,
``evaluateLight`` / ``evaluateDirectSpecular``). In the notation of both (E view, L light, H half vector, dot
products clamped to [0, 1]), with R = (1 - ior) / (1 + ior):

* **metalness workflow** (``useSpecularWorkflow = 0``; spec, input ``metallic``): "if metallic is 1, both F0
  and edge F90 reflectivity will simply be the Albedo; if metallic is 0, F0 is derived from ior via
  ((1 - ior)/(1 + ior))^2 and F90 is white. In between, we interpolate." The interpolation is Storm's:
  specColor = mix(1, diffuseColor, metallic), F0 = mix(R^2 specColor, specColor, metallic),
  F90 = specColor; the diffuse term is scaled by (1 - metallic) ("pure metals have no diffuse");
* **specular workflow** (``useSpecularWorkflow = 1``; spec, input ``specularColor``): "the color at 0
  incidence. Edge color is assumed white. Transition between the two colors according to Schlick fresnel
  approximation": F0 = specularColor, F90 = 1; ``metallic`` is ignored (and ``ior`` only sets the clearcoat);
* Fresnel: Schlick, F = mix(F0, F90, (1 - E.H)^5) (spec, ``specularColor``; Storm ``SchlickFresnel``);
* **roughness -> alpha**: alpha = roughness^2 ("usually squared before use with a GGX or Beckmann lobe"),
  with Storm's GGX (Trowbridge-Reitz) distribution D = alpha^2 / (pi ((N.H)^2 (alpha^2 - 1) + 1)^2);
* masking-shadowing (left open by the spec): Storm's separable Smith-Schlick form G = G1(E) G1(L),
  G1(x) = N.x / (N.x (1 - k) + k) with k = alpha / 2; the lobe is F D G / (4 N.L N.E);
* **diffuse/specular split** (left open by the spec): Storm's ``d *= 1 - mix(F0, F90, fresnel)``, per
  channel: diffuse = diffuseColor / pi (1 - metallic) (1 - F), added to the specular lobe;
* **clearcoat** (spec: "second specular lobe amount. The color is white"; ``ior`` is used "including the
  clearcoat if clearcoat > 0"): clearcoat times a second GGX lobe of the same form with alpha =
  clearcoatRoughness^2, F0 = R^2 and F90 = 1 (Storm: ``R * R * clearcoatColor``, ``clearcoatColor``, white),
  added without attenuating the layers under it, as Storm does.

Choices where Storm is a rasteriser rather than a definition (written down here, tested in
``tests/test_usd_dialect.py``): Storm's numerical guards are not kept -- it adds 0.001 to alpha^2 in D's
numerator and to the 4 N.L N.E denominator, takes pi = 3.1415 and clamps roughness to at least 0.001; they
would brighten a smooth highlight by tens of per cent (alpha^2 + 0.001 against alpha^2 = 0.0016 at
roughness 0.2). Here a lobe whose alpha^2 is at most 1e-14 (roughness below 3.2e-4) is a mirror a point
light never reaches, as in :mod:`.gltf`. ``opacity``, ``opacityThreshold``, ``emissiveColor``,
``occlusion``, ``normal`` and ``displacement`` are not reflectance: readers carry them
(:class:`~matremap.formats.asset.MaterialAsset` ``carried``, normal maps), and Storm multiplies direct light by
``occlusion``, which this model leaves at 1.

The metalness workflow is the one matremap remaps (its F0 and albedo are the reflectance below); the
specular workflow is drawn exactly and fitted with ``--fix useSpecularWorkflow=1 --free specularColor``.
Parameter names are the UsdPreviewSurface input names, defaults its fallbacks.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, MutableMapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from matremap.core.models import ModelSpec, OptionSpec, ParamSpec
from matremap.core.optics import f0_from_ior, ior_from_f0
from matremap.core.reflectance import Channels, Reflectance, as_floats, as_rgb
from matremap.errors import MatremapError


def metalness_f0_f90(diffuse: Any, metallic: Any, ior: Any) -> tuple[np.ndarray, np.ndarray]:
    """F0 and F90 of the metalness workflow (Storm's interpolation, see the module docstring): arrays
    broadcast from ``diffuse`` [..., 3] (or [N, 3, ...]) with ``metallic`` and ``ior``."""
    spec_color = 1.0 + (diffuse - 1.0) * metallic  # mix(1, diffuseColor, metallic)
    r2 = f0_from_ior(ior)
    return r2 * spec_color + (spec_color - r2 * spec_color) * metallic, spec_color


@dataclass(frozen=True)
class PreviewSurfaceMetalness(Reflectance):
    """F0 of UsdPreviewSurface's metalness workflow: mix(R^2 s, s, metallic) with s = mix(1, diffuseColor,
    metallic) and R = (1 - ior)/(1 + ior) (spec 2.5 ``metallic``, Storm's interpolation); the diffuse colour is
    albedo in proportion to 1 - metallic. Written back like glTF's metallic-roughness: a metal
    (metallic >= 0.5) takes F0 as its diffuse colour (at metallic 1, F0 = diffuseColor), a dielectric the
    albedo as diffuse colour and F0 through ior = (1 + sqrt F0)/(1 - sqrt F0) of the channel mean (the
    workflow has no tinted dielectric F0), written only where it differs from the template's."""

    diffuse_color: str
    metallic: str
    ior: str

    writes_albedo: ClassVar[bool] = True

    @property
    def params(self) -> tuple[str, ...]:
        return (self.diffuse_color, self.metallic, self.ior)

    @property
    def map_params(self) -> tuple[str, ...]:
        return (self.diffuse_color, self.metallic)

    def driven_param(self, metal: bool = True) -> str:
        """A metal's diffuse colour, or a dielectric's ior."""
        return self.diffuse_color if metal else self.ior

    def f0(self, values: Mapping[str, Any], channels: Channels) -> np.ndarray:
        m = as_floats(values[self.metallic])[..., None]
        ior = as_floats(values[self.ior])[..., None]
        f0, _ = metalness_f0_f90(as_rgb(values[self.diffuse_color], 3), m, ior)
        return f0

    def albedo(self, diffuse: np.ndarray, values: Mapping[str, Any]) -> np.ndarray:
        """A metal's diffuse colour is no albedo: diffuse (1 - metallic)."""
        return diffuse * (1.0 - as_floats(values[self.metallic])[..., None])

    def write_f0(
        self, f0: np.ndarray, out: MutableMapping[str, Any], channels: Channels, diffuse: np.ndarray | None = None
    ) -> list[str]:
        metal = (np.asarray(out[self.metallic]) >= 0.5)[..., None]
        albedo = np.asarray(out[self.diffuse_color]) if diffuse is None else as_floats(diffuse)
        out[self.diffuse_color] = np.where(metal, f0, albedo)
        driven = [self.diffuse_color]
        if not np.all(metal):
            current = np.asarray(out[self.ior], dtype=float)
            wanted = ior_from_f0(np.mean(f0, axis=-1))
            want = np.where(metal[..., 0], current, wanted)
            if np.max(np.abs(f0_from_ior(want) - f0_from_ior(current))) > 1e-4 * max(float(np.max(f0)), 1e-12):
                out[self.ior] = want
                driven.append(self.ior)
        return driven


PREVIEW_SURFACE = ModelSpec(
    id="usd:preview_surface",
    microfacet="ggx",
    summary="UsdPreviewSurface 2.5 (metalness or specular workflow, GGX, Schlick, clearcoat), as Storm draws it",
    params=(
        ParamSpec(
            "diffuseColor",
            "diffuse",
            (0.18,) * 3,
            (0.0, 1.0),
            channels=3,
            doc="albedo; at metallic 1 (metalness workflow) F0 and F90",
        ),
        ParamSpec(
            "metallic",
            "other",
            0.0,
            (0.0, 1.0),
            fit=False,
            doc="metalness workflow: 0 dielectric, 1 metal (held in fits: fix it to 0 or 1)",
        ),
        ParamSpec("roughness", "roughness", 0.5, (0.0, 1.0), doc="specular lobe roughness, alpha = roughness^2"),
        ParamSpec(
            "specularColor",
            "specular",
            (0.0,) * 3,
            (0.0, 1.0),
            channels=3,
            fit=False,
            fit_value=0.04,
            doc="specular workflow: F0 (F90 is white; held at 0.04 in fits, --free it); unused by the metalness one",
        ),
        ParamSpec(
            "ior",
            "fresnel",
            1.5,
            (1.0, 5.0),
            doc="metalness workflow: dielectric F0 = ((1 - ior)/(1 + ior))^2; both workflows: the clearcoat's F0",
        ),
        ParamSpec("clearcoat", "other", 0.0, (0.0, 1.0), fit=False, doc="weight of the second (white) GGX lobe"),
        ParamSpec(
            "clearcoatRoughness",
            "other",
            0.01,
            (0.0, 1.0),
            fit=False,
            doc="roughness of the clearcoat lobe, alpha = clearcoatRoughness^2",
        ),
    ),
    options=(
        OptionSpec(
            "useSpecularWorkflow",
            ("0", "1"),
            "0",
            "0: metalness workflow (metallic, ior); 1: specular workflow (specularColor is F0)",
        ),
    ),
    # the diffuse part keeps its Fresnel weight (1 - F): roughness 0 switches the lobe off, clearcoat 0 the coat
    diffuse_only={"metallic": 0.0, "roughness": 0.0, "clearcoat": 0.0},
    specular_only={"diffuseColor": 0.0},
    specialisations=(
        (
            "metallic",
            1.0,
            {"roles": {"diffuseColor": "specular", "ior": "other"}, "diffuse_only": None, "specular_only": {}},
        ),
    ),
    reflectance=PreviewSurfaceMetalness("diffuseColor", "metallic", "ior"),
)

#: the models of this dialect, in the order they are listed
MODELS = (PREVIEW_SURFACE,)
#: UsdPreviewSurface has no exact Lambertian (its diffuse term always carries 1 - F); the family's irradiance
#: units are the embedded renderer's, which draws glTF's white Lambertian in the same units
WHITE_REFERENCE = ("gltf:metal-rough", {"baseColor": 1.0, "metallic": 0.0, "specular": 0.0})


def specular_workflow(
    constants: dict[str, Any], textures: MutableMapping[str, Any], notes: list[str], where: str
) -> None:
    """Read a specular-workflow UsdPreviewSurface as the metalness workflow where both give the same (see the
    module docstring of :mod:`matremap.formats.usd`); refuse a textured one that cannot be; keep a uniform one.
    ``textures`` maps the parameters a file textures to anything; ``where`` starts a refusal (the file and
    material). The USD and MaterialX readers share this rule."""
    if constants["useSpecularWorkflow"] != "1":
        return
    textures.pop("metallic", None)  # the specular workflow ignores metallic
    s = np.asarray(constants.get("specularColor", [0.0] * 3), dtype=float)
    coat = constants.get("clearcoat", 0.0)
    grey = "specularColor" not in textures and float(np.ptp(s)) <= 1e-6 and "clearcoat" not in textures
    ior = float(ior_from_f0(float(s[0]))) if grey and s[0] < 0.999 else math.inf
    if grey and coat == 0.0 and ior <= PREVIEW_SURFACE.param("ior").bounds[1]:
        constants.update({"useSpecularWorkflow": "0", "metallic": 0.0, "ior": ior})
        notes.append(
            f"useSpecularWorkflow=1 with grey specularColor {s[0]:.6g} is the metalness workflow's dielectric "
            f"with ior {ior:.6g} (same F0, F90 and diffuse weight): read so"
        )
        return
    if textures:
        raise MatremapError(
            f"{where}: uses the specular workflow with a coloured or textured specularColor (or a clearcoat); "
            "matremap remaps textured materials in the metalness workflow (useSpecularWorkflow=0) only"
        )
    constants["metallic"] = 0.0
