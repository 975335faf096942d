"""Mitsuba 3's BSDF plugins, as matremap fits them (drawn by the real Mitsuba 3: :mod:`matremap.renderers.mitsuba3`).

Source: Mitsuba 3.9 ``src/bsdfs/{diffuse,roughconductor,roughplastic,principled,dielectric,roughdielectric,
thindielectric}.cpp``.

=========================  ====================================================================
model                      parameters (Mitsuba 3's names; RGB unless noted)
=========================  ====================================================================
mitsuba3:diffuse           reflectance (0.5)
mitsuba3:roughconductor    distribution {beckmann*, ggx}; material {custom*, none, Au, Cu, ...};
                           alpha (scalar, 0.1); eta (0), k (1) (Mitsuba's default is a perfect
                           mirror, ``none``); specular_reflectance (1). eta and k are used
                           when material = custom, otherwise Mitsuba's named data are used.
mitsuba3:roughconductor-   Mitsuba's roughconductor with alpha_u != alpha_v: alpha_u, alpha_v
  anisotropic              (scalars, 0.1: roughness along the surface's dp/du and across it);
                           the rest as roughconductor
mitsuba3:roughplastic      distribution {beckmann*, ggx}; nonlinear {false*, true};
                           alpha (scalar, 0.1); int_ior (scalar, 1.49); ext_ior (scalar, 1.000277);
                           specular_reflectance (1); diffuse_reflectance (0.5)
mitsuba3:principled        base_color (0.5); roughness, metallic, specular (0.5), spec_tint,
                           anisotropic, sheen, sheen_tint, flatness, clearcoat,
                           clearcoat_gloss, spec_trans (scalars; those after specular held at
                           0 in fits); emulated by the embedded renderer but for anisotropic
                           and flatness (spec_trans: its reflection; what it transmits is drawn
                           by the transmission probe)
mitsuba3:dielectric        int_ior (scalar, 1.5046: bk7), ext_ior (scalar, 1.000277: air; held);
                           specular_reflectance, specular_transmittance (1; held unless freed)
mitsuba3:roughdielectric   distribution {beckmann*, ggx}; alpha (scalar, 0.1; isotropic only);
                           the rest as dielectric
mitsuba3:thindielectric    as dielectric: a thin slab (no bending), its internal reflections summed
=========================  ====================================================================

The three glasses (``dielectric.cpp``, ``roughdielectric.cpp``, ``thindielectric.cpp``): a smooth interface and a
thin slab reflect a delta lobe only (nothing under the probe's point lights); the rough one reflects
specular_reflectance F(i.h, int_ior/ext_ior) D G / (4 cos_view) with Mitsuba's exact dielectric Fresnel
(``fresnel.h``) and the separable Smith G of ``microfacet.h``. What they let through is drawn by the transmission
probe (:data:`matremap.renderers.embedded.transmission.INTERFACES`). A fit moves int_ior (the look of both
reflection and refraction) and alpha; ext_ior (the medium around) and specular_reflectance (Mitsuba: "should never
be touched" for realism) are held; specular_transmittance is held at 1 too, and freed when a transmissive source is
fitted onto the model (its tint is the only colour a glass has).
"""

from __future__ import annotations

from matremap.core.models import ModelSpec, OptionSpec, ParamSpec
from matremap.core.reflectance import Conductor, Dielectric, Metalness, SpecularLevel

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
PRINCIPLED_HELD = (
    "spec_tint",
    "anisotropic",
    "sheen",
    "sheen_tint",
    "flatness",
    "clearcoat",
    "clearcoat_gloss",
    "spec_trans",
)


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
    affine=(("reflectance", {}),),
    summary="Lambertian (Mitsuba 3 diffuse)",
    params=(_rgb("reflectance", "diffuse", 0.5, 1.0, doc="albedo"),),
    diffuse_only={},
    specular_only=None,
)

ROUGHCONDUCTOR = ModelSpec(
    id="mitsuba3:roughconductor",
    affine=(("specular_reflectance", {}),),
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

ROUGHCONDUCTOR_ANISOTROPIC = ModelSpec(
    id="mitsuba3:roughconductor-anisotropic",
    affine=(("specular_reflectance", {}),),
    summary="anisotropic rough conductor (Mitsuba 3 roughconductor with alpha_u, alpha_v)",
    params=(
        ParamSpec("alpha_u", "roughness", 0.1, (1e-4, 1.0), doc="roughness along the tangent (dp/du)"),
        ParamSpec("alpha_v", "roughness", 0.1, (1e-4, 1.0), doc="roughness along the bitangent"),
        *ROUGHCONDUCTOR.params[1:],
    ),
    options=ROUGHCONDUCTOR.options,
    diffuse_only=None,
    specular_only={},
    reflectance=Conductor("eta", "k"),
    # fitted from an isotropic source, alpha_v follows alpha_u (--free alpha_v unties it)
    isotropic=(("alpha_v", "alpha_u"),),
)

ROUGHPLASTIC = ModelSpec(
    id="mitsuba3:roughplastic",
    affine=(("specular_reflectance", {}), ("diffuse_reflectance", {"nonlinear": ("false",)})),
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
    microfacet="ggx",
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
    # a metal (metallic 1, chosen for a source without a diffuse part): base_color is its F0, the whole render
    # its specular part (without this a two-stage fit from a principled metal found its specular part black)
    specialisations=(
        (
            "metallic",
            1.0,
            {"roles": {"base_color": "specular", "specular": "other"}, "diffuse_only": None, "specular_only": {}},
        ),
    ),
    # F0: a metal's base colour, a dielectric's 0.08 specular (spec_tint held at 0); Mitsuba 3 takes specular as
    # a float, not a texture: a map set's dielectric F0 is written as one specular (svbrdf.convert)
    reflectance=Metalness("base_color", "metallic", SpecularLevel("specular", texture=False)),
)


def _glass_params() -> tuple[ParamSpec, ...]:
    """The parameters every Mitsuba 3 glass has (``dielectric.cpp``: bk7 inside, air outside by default)."""
    return (
        ParamSpec("int_ior", "fresnel", 1.5046, (1.0, 4.0), doc="interior IOR (bk7)"),
        ParamSpec("ext_ior", "other", 1.000277, (1.0, 4.0), fit=False, doc="exterior IOR (air), held"),
        _rgb("specular_reflectance", "specular", 1.0, 1.0, fit=False, doc="reflection multiplier, held at 1"),
        _rgb(
            "specular_transmittance",
            "other",
            1.0,
            1.0,
            fit=False,
            doc="transmission multiplier (per crossing), held at 1 unless a transmissive source frees it",
        ),
    )


DIELECTRIC = ModelSpec(
    id="mitsuba3:dielectric",
    summary="smooth glass, exact dielectric Fresnel (Mitsuba 3 dielectric); a mirror lobe and refraction",
    params=_glass_params(),
    diffuse_only=None,
    specular_only={},
    reflectance=Dielectric("int_ior", "ext_ior"),
)

ROUGHDIELECTRIC = ModelSpec(
    id="mitsuba3:roughdielectric",
    summary="rough glass, exact dielectric Fresnel (Mitsuba 3 roughdielectric, isotropic)",
    params=(_alpha(), *_glass_params()),
    options=(_distribution(),),
    diffuse_only=None,
    specular_only={},
    reflectance=Dielectric("int_ior", "ext_ior"),
)

THINDIELECTRIC = ModelSpec(
    id="mitsuba3:thindielectric",
    summary="thin glass slab, no refraction, internal reflections summed (Mitsuba 3 thindielectric)",
    params=_glass_params(),
    diffuse_only=None,
    specular_only={},
    reflectance=Dielectric("int_ior", "ext_ior"),
)

#: the glasses: their look is mostly what they let through (the transmission probe)
GLASSES = (DIELECTRIC, ROUGHDIELECTRIC, THINDIELECTRIC)

#: the models of this dialect, in the order they are listed
MODELS = (
    DIFFUSE,
    ROUGHCONDUCTOR,
    ROUGHCONDUCTOR_ANISOTROPIC,
    ROUGHPLASTIC,
    PRINCIPLED,
    *GLASSES,
)
#: a white Lambertian surface of albedo 1 in this renderer family (irradiance matching)
WHITE_REFERENCE = ("mitsuba3:diffuse", {"reflectance": 1.0})
