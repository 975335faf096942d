"""The real Mitsuba 3 renderer (PyPI ``mitsuba``), behind the same protocol as the embedded one.

Install with ``pip install 'matremap[mitsuba]'`` (or ``pip install mitsuba``). Importing this module
does not import Mitsuba: the models below are plain data and are listed without it; the renderer
imports Mitsuba when it is created and says how to install it when that fails.

The probe scene is built exactly as the embedded renderer sees it (see :mod:`matremap.core.scene`):

* a ``sphere`` of the scene's radius at the origin carrying the material's BSDF;
* a ``perspective`` sensor at (0, 0, d) looking at the origin, +y up, ``fov`` = the scene's full
  field of view along x, an ``hdrfilm`` of the scene's resolution with a ``box`` reconstruction filter;
* the ``direct`` integrator (one emitter sample, no BSDF samples: a point light cannot be hit by
  BSDF sampling) with a ``stratified`` sampler, ``jitter=false`` and 1 sample per pixel: the one
  camera ray of each pixel goes through the pixel centre, so a render is deterministic and
  noise-free, and equal to the embedded renderer's geometry to float32 precision;
* one scene per point light, summed: Mitsuba's emitter sampling picks *one* light per sample,
  which would make multi-light renders noisy; with one light per scene the point light is
  sampled deterministically. Each point light has ``intensity`` = the scene's radiant intensity.

A loaded scene is cached per (scene, light, model, options); a batch of materials is a loop that
changes the BSDF's parameters with ``mi.traverse`` and renders again (``spp`` and ``seed`` are
always passed to ``mi.render``: Mitsuba otherwise keeps the last call's sample count).

Variants: ``scalar_rgb`` by default (works from the wheel alone). Any ``*_rgb`` variant may be
chosen with ``Mitsuba3Renderer(variant=...)`` or the environment variable
``MATREMAP_MITSUBA_VARIANT``; ``llvm_ad_rgb`` needs a libLLVM >= 17 (Debian ``libllvm19``, which
Mitsuba finds without any environment variable even next to LLVM 14/15; LLVM 15 and 16 crash
inside Mitsuba on the first render, which cannot be caught), so ``variant="auto"`` picks it only
when such a library is found and a tiny render in a child process succeeds (:func:`llvm_renders`).
It agrees with ``scalar_rgb`` to 2e-6 and renders ~2x faster here (centre rays; 8x at 256 spp).

=========================  ====================================================================
model                      parameters (Mitsuba 3's names; RGB unless noted)
=========================  ====================================================================
mitsuba3:diffuse           reflectance (0.5)
mitsuba3:roughconductor    distribution {beckmann*, ggx}; material {custom*, none, Au, Cu, ...};
                           alpha (scalar, 0.1); eta (0), k (1) (Mitsuba's default is a perfect
                           mirror, ``none``); specular_reflectance (1). eta and k are used
                           when material = custom, otherwise Mitsuba's named data are used.
mitsuba3:roughplastic      distribution {beckmann*, ggx}; nonlinear {false*, true};
                           alpha (scalar, 0.1); int_ior (scalar, 1.49); ext_ior (scalar, 1.000277);
                           specular_reflectance (1); diffuse_reflectance (0.5)
mitsuba3:principled        base_color (0.5); roughness, metallic, specular (0.5), spec_tint,
                           anisotropic, sheen, sheen_tint, clearcoat, clearcoat_gloss,
                           spec_trans (scalars; those after specular held at 0 in fits)
=========================  ====================================================================
"""

from __future__ import annotations

from matremap.core.models import ModelSpec, OptionSpec, ParamSpec
from matremap.core.reflectance import Conductor, Dielectric

CONDUCTORS = (
    "none",
    "a-C",
    "Ag",
    "Al",
    "AlAs",
    "AlAs_palik",
    "AlSb",
    "AlSb_palik",
    "Au",
    "Be",
    "Be_palik",
    "Cr",
    "CsI",
    "CsI_palik",
    "Cu",
    "Cu_palik",
    "Cu2O",
    "Cu2O_palik",
    "CuO",
    "CuO_palik",
    "d-C",
    "d-C_palik",
    "Hg",
    "Hg_palik",
    "HgTe",
    "HgTe_palik",
    "Ir",
    "Ir_palik",
    "K",
    "K_palik",
    "Li",
    "Li_palik",
    "MgO",
    "MgO_palik",
    "Mo",
    "Mo_palik",
    "Na_palik",
    "Nb",
    "Nb_palik",
    "Ni_palik",
    "Rh",
    "Rh_palik",
    "Se",
    "Se_palik",
    "Se-e",
    "Se-e_palik",
    "SiC",
    "SiC_palik",
    "SnTe",
    "SnTe_palik",
    "Ta",
    "Ta_palik",
    "Te",
    "Te_palik",
    "Te-e",
    "Te-e_palik",
    "ThF4",
    "ThF4_palik",
    "TiC",
    "TiC_palik",
    "TiN",
    "TiN_palik",
    "TiO2",
    "TiO2_palik",
    "TiO2-e",
    "TiO2-e_palik",
    "VC",
    "VC_palik",
    "V_palik",
    "VN",
    "VN_palik",
    "W",
)

DISTRIBUTIONS = ("beckmann", "ggx")

#: principled parameters matremap holds at 0 in fits (they stay settable)
PRINCIPLED_HELD = ("spec_tint", "anisotropic", "sheen", "sheen_tint", "clearcoat", "clearcoat_gloss", "spec_trans")


def _rgb(
    name: str, role: str, default: float, hi: float, fit: bool = True, fit_value: float | None = None, doc: str = ""
) -> ParamSpec:
    return ParamSpec(name, role, (default,) * 3, (0.0, hi), channels=3, fit=fit, fit_value=fit_value, doc=doc)


def _alpha() -> ParamSpec:
    return ParamSpec("alpha", "roughness", 0.1, (1e-4, 1.0), doc="microfacet roughness (RMS slope)")


def _distribution() -> OptionSpec:
    return OptionSpec("distribution", DISTRIBUTIONS, "beckmann", "microfacet normal distribution")


DIFFUSE = ModelSpec(
    id="mitsuba3:diffuse",
    summary="Lambertian (Mitsuba 3 diffuse)",
    params=(_rgb("reflectance", "diffuse", 0.5, 1.0, doc="albedo"),),
    diffuse_only={},
    specular_only=None,
)

ROUGHCONDUCTOR = ModelSpec(
    id="mitsuba3:roughconductor",
    summary="rough conductor, exact conductor Fresnel (Mitsuba 3 roughconductor)",
    params=(
        _alpha(),
        _rgb(
            "eta",
            "fresnel",
            0.0,
            100.0,
            fit=False,
            fit_value=1.0,
            doc="real part of the IOR (material=custom); held at 1 in fits so that F0 = k^2/(4 + k^2)",
        ),
        _rgb("k", "fresnel", 1.0, 100.0, doc="absorption coefficient (material=custom)"),
        _rgb(
            "specular_reflectance",
            "specular",
            1.0,
            1.0,
            fit=False,
            doc="multiplier that should not be touched for realism",
        ),
    ),
    options=(
        _distribution(),
        OptionSpec(
            "material",
            ("custom", *CONDUCTORS),
            "custom",
            "named conductor (Mitsuba's spectral data); custom uses eta and k",
        ),
    ),
    diffuse_only=None,
    specular_only={},
    # F0 of eta + i k (no exterior IOR in Mitsuba 3); with a named `material` eta/k are unused
    reflectance=Conductor("eta", "k"),
)

ROUGHPLASTIC = ModelSpec(
    id="mitsuba3:roughplastic",
    summary="rough dielectric coating over a Lambertian base (Mitsuba 3 roughplastic)",
    params=(
        _alpha(),
        ParamSpec("int_ior", "fresnel", 1.49, (1.0001, 4.0), doc="interior IOR (polypropylene)"),
        ParamSpec("ext_ior", "other", 1.000277, (1.0, 4.0), fit=False, doc="exterior IOR (air)"),
        _rgb("specular_reflectance", "specular", 1.0, 1.0, fit=False, doc="multiplier, held at 1"),
        _rgb("diffuse_reflectance", "diffuse", 0.5, 1.0, doc="albedo of the base under the coating"),
    ),
    options=(
        OptionSpec("distribution", DISTRIBUTIONS, "beckmann", "microfacet normal distribution"),
        OptionSpec("nonlinear", ("false", "true"), "false", "account for internal scattering nonlinearly"),
    ),
    diffuse_only={"specular_reflectance": 0.0},
    specular_only={"diffuse_reflectance": 0.0},
    reflectance=Dielectric("int_ior", "ext_ior"),
)

PRINCIPLED = ModelSpec(
    id="mitsuba3:principled",
    summary="Disney principled BSDF (Mitsuba 3 principled); fit it with --strategy simple",
    params=(
        _rgb("base_color", "diffuse", 0.5, 1.0, doc="base colour (diffuse albedo; metal reflectance)"),
        ParamSpec("roughness", "roughness", 0.5, (1e-3, 1.0), doc="roughness (alpha = roughness^2)"),
        ParamSpec("metallic", "specular", 0.0, (0.0, 1.0), doc="metallicity"),
        ParamSpec(
            "specular",
            "specular",
            0.5,
            (0.0, 1.0),
            linear=True,
            doc="dielectric specular amount (eta = 2/(1 - sqrt(0.08 specular)) - 1)",
        ),
        *(ParamSpec(n, "other", 0.0, (0.0, 1.0), fit=False, doc="held at 0 in fits") for n in PRINCIPLED_HELD),
    ),
    diffuse_only={"metallic": 0.0, "specular": 0.0, "clearcoat": 0.0, "spec_trans": 0.0},
    # the metallic lobe takes base_color's colour: no parameter override isolates the specular part
    specular_only=None,
    channel_separable=False,  # tints use the luminance of base_color
    # a metal (metallic 1, chosen for a source without a diffuse part): base_color is its F0
    specialisations=(
        ("metallic", 1.0, {"roles": {"base_color": "specular", "specular": "other"}, "diffuse_only": None}),
    ),
)

#: the models of this dialect, in the order they are listed
MODELS = (
    DIFFUSE,
    ROUGHCONDUCTOR,
    ROUGHPLASTIC,
    PRINCIPLED,
)
#: a white Lambertian surface of albedo 1 in this renderer family (irradiance matching)
WHITE_REFERENCE = ("mitsuba3:diffuse", {"reflectance": 1.0})
