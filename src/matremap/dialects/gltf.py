"""glTF 2.0 metallic-roughness material, emulated as its specification defines it.

Source: the glTF 2.0 specification, Appendix B "BRDF Implementation" (Khronos, 2021), and the
extensions KHR_materials_ior and KHR_materials_specular. In the spec's notation (V view, L light,
H half vector, all dot products clamped to [0, 1]):

* alpha = roughness^2;
* D = alpha^2 / (pi ((N.H)^2 (alpha^2 - 1) + 1)^2)  (Trowbridge-Reitz / GGX);
* the visibility term V = G / (4 |N.L| |N.V|) with Smith's GGX masking-shadowing, by default in
  its height-correlated form, G = 1 / (1 + Lambda(L) + Lambda(V)) (what the Khronos sample viewer
  and most engines evaluate; option ``visibility=separable`` gives the product G1(L) G1(V) the
  appendix writes out);
* Schlick's Fresnel F(f0, f90) = f0 + (f90 - f0) (1 - |V.H|)^5;
* metal_brdf = F(baseColor, 1) D V;
* dielectric_brdf = (1 - specular max_c(fr)) baseColor / pi + specular fr D V, where
  fr = F(min(((ior - 1)/(ior + 1))^2 specularColor, 1), 1) per channel: KHR_materials_ior and
  the ratified KHR_materials_specular (its ``fresnel_mix``: the diffuse base is weighted by one
  number, the largest channel of fr). Without the extensions ior = 1.5 gives f0 = 0.04 and
  specular = specularColor = 1, the core spec's mix(diffuse, specular, F(0.04, 1));
* material = mix(dielectric_brdf, metal_brdf, metallic).

The parameter names are the glTF JSON property names without ``Factor``.

gltf:pbr -- the same material with two more of Khronos' ratified layer extensions (the set MaterialX 1.39's
``gltf_pbr`` node carries), each off at its default, where the model is gltf:metal-rough exactly:

* KHR_materials_sheen (ratified README, "Sheen" and the non-normative "Implementation Notes", which
  fill in what the normative text leaves open): ``sheenColor`` (default 0: off) and ``sheenRoughness``;
  f_sheen = sheenColor D V with Estevez and Kulla's "Charlie" D = (2 + 1/a)
  sin^(1/a)(theta_h) / (2 pi), a = sheenRoughness^2 (clamped below at 1e-6 squared, as the Khronos sample
  viewer does), and their visibility V = 1 / ((1 + Lambda(N.V) + Lambda(N.L)) 4 N.V N.L) with the fitted
  Lambda of the README; layered by albedo scaling:
  f = f_sheen + material min(1 - max(sheenColor) E(N.V), 1 - max(sheenColor) E(N.L)),
  E the sheen lobe's directional albedo (integrated numerically, ``renderers/embedded/layering.py``);
* KHR_materials_clearcoat (ratified README, "Clearcoat" and "Implementation"): ``clearcoat`` (default 0:
  off) and ``clearcoatRoughness``; the spec's ``fresnel_coat`` with F0 0.04 (ior 1.5) and Schlick's Fresnel
  of N.V (not V.H, as the README's "Discussion" says): Fc = 0.04 + 0.96 (1 - N.V)^5,
  f = material (1 - clearcoat Fc) + clearcoat Fc D V, D V the core specular lobe (GGX, the same
  visibility option) with alpha = clearcoatRoughness^2. Clear coat sits on top of sheen;
* KHR_materials_transmission (ratified README, "Transmission" and "Implementation"): ``transmission`` (default 0)
  replaces that share of the dielectric base's diffuse by the specular BTDF tinted by baseColor:
  dielectric_brdf = fresnel_mix(ior, base = mix(diffuse_brdf, specular_btdf baseColor, transmission), layer =
  specular_brdf); the BTDF reflects nothing, so in reflection the diffuse is (1 - transmission) of itself. What
  goes through is drawn by the transmission probe (``renderers/embedded/transmission.py``), with
  KHR_materials_volume (ratified README): ``thickness`` (0: thin-walled, no refraction), ``attenuationColor`` and
  ``attenuationDistance`` (Beer-Lambert, sigma = -ln(attenuationColor) / attenuationDistance; 0 here stands for
  the default +infinity, as glTF forbids 0 itself).

It is a model of its own rather than more parameters of gltf:metal-rough so that a material file writer
that stores gltf:metal-rough refuses a result with these layers (one line naming the model) instead of
dropping them: a writer must know the layers to hold them.
"""

from __future__ import annotations

from matremap.core.models import ModelSpec, OptionSpec, ParamSpec
from matremap.core.reflectance import MetalRough

METAL_ROUGH = ModelSpec(
    id="gltf:metal-rough",
    microfacet="ggx",
    summary="glTF 2.0 metallic-roughness PBR (GGX, Schlick), with KHR_materials_ior/specular",
    params=(
        ParamSpec(
            "baseColor",
            "diffuse",
            (1.0,) * 3,
            (0.0, 1.0),
            channels=3,
            doc="albedo of a dielectric, F0 of a metal (baseColorFactor x texture)",
        ),
        ParamSpec(
            "metallic",
            "other",
            1.0,
            (0.0, 1.0),
            fit=False,
            doc="0 dielectric, 1 metal (held in fits: fix it to 0 or 1)",
        ),
        ParamSpec("roughness", "roughness", 1.0, (0.0, 1.0), doc="perceptual roughness, alpha = roughness^2"),
        ParamSpec("ior", "fresnel", 1.5, (1.0, 5.0), doc="KHR_materials_ior: sets a dielectric's F0"),
        ParamSpec(
            "specular",
            "other",
            1.0,
            (0.0, 1.0),
            fit=False,
            doc="KHR_materials_specular specularFactor: scales the dielectric F0 and F90",
        ),
        ParamSpec(
            "specularColor",
            "fresnel",
            (1.0,) * 3,
            (0.0, 25.0),
            channels=3,
            fit=False,
            linear=True,
            doc="KHR_materials_specular specularColorFactor: tints the dielectric F0 (clamped to 1)",
        ),
    ),
    options=(
        OptionSpec(
            "visibility",
            ("height-correlated", "separable"),
            "height-correlated",
            "Smith GGX visibility: height-correlated (sample viewer) or separable (spec appendix)",
        ),
    ),
    # the diffuse part keeps its Fresnel weight (1 - specular max F): roughness 0 switches the lobe off
    diffuse_only={"metallic": 0.0, "roughness": 0.0},
    specular_only={"baseColor": 0.0},
    specialisations=(
        (
            "metallic",
            1.0,
            {"roles": {"baseColor": "specular", "ior": "other"}, "diffuse_only": None, "specular_only": {}},
        ),
    ),
    reflectance=MetalRough("baseColor", "metallic", "ior", "specular", "specularColor"),
)

PBR = ModelSpec(
    id="gltf:pbr",
    microfacet="ggx",
    summary="glTF 2.0 metallic-roughness with KHR_materials_ior/specular/sheen/clearcoat/transmission/volume",
    params=(
        *METAL_ROUGH.params,
        ParamSpec(
            "sheenColor",
            "diffuse",
            (0.0,) * 3,
            (0.0, 1.0),
            channels=3,
            fit=False,
            doc="KHR_materials_sheen sheenColorFactor: the sheen layer's colour (0: no sheen; --free sheenColor)",
        ),
        ParamSpec(
            "sheenRoughness",
            "diffuse",
            0.0,
            (0.0, 1.0),
            fit=False,
            linear=False,
            doc="KHR_materials_sheen sheenRoughnessFactor: Charlie sheen, alpha = sheenRoughness^2",
        ),
        ParamSpec(
            "clearcoat",
            "specular",
            0.0,
            (0.0, 1.0),
            fit=False,
            doc="KHR_materials_clearcoat clearcoatFactor: the coat's intensity (0: no coat; --free clearcoat)",
        ),
        ParamSpec(
            "clearcoatRoughness",
            "roughness",
            0.0,
            (0.0, 1.0),
            fit=False,
            doc="KHR_materials_clearcoat clearcoatRoughnessFactor: alpha = clearcoatRoughness^2",
        ),
        ParamSpec(
            "transmission",
            "other",
            0.0,
            (0.0, 1.0),
            fit=False,
            doc="KHR_materials_transmission transmissionFactor: share of the dielectric base that refracts",
        ),
        ParamSpec(
            "thickness",
            "other",
            0.0,
            (0.0, 1000.0),
            fit=False,
            doc="KHR_materials_volume thicknessFactor: 0 thin-walled, > 0 a volume (the probe traces the real one)",
        ),
        ParamSpec(
            "attenuationDistance",
            "other",
            0.0,
            (0.0, 1e6),
            fit=False,
            doc="KHR_materials_volume attenuationDistance (scene units); 0 stands for glTF's default, infinity",
        ),
        ParamSpec(
            "attenuationColor",
            "other",
            (1.0,) * 3,
            (0.0, 1.0),
            channels=3,
            fit=False,
            doc="KHR_materials_volume attenuationColor: what is left of white light after attenuationDistance",
        ),
    ),
    options=METAL_ROUGH.options,
    # the diffuse part keeps the sheen (a diffuse absorbs it) and the coat's Fresnel weight (a mirror coat:
    # no lobe under point lights); the specular part is every lobe over a black base, without the sheen.
    # So a two-stage fit that frees the layers fits the sheen with the diffuse part (roles "diffuse") and
    # the coat with the specular part (roles "specular" and "roughness"; the first roughness stays the base's)
    diffuse_only={"metallic": 0.0, "roughness": 0.0, "clearcoatRoughness": 0.0},
    specular_only={"baseColor": 0.0, "sheenColor": 0.0},
    specialisations=METAL_ROUGH.specialisations,
    reflectance=METAL_ROUGH.reflectance,
)

#: the models of this dialect, in the order they are listed
MODELS = (METAL_ROUGH, PBR)
#: a white Lambertian surface of albedo 1 in this renderer family (irradiance matching)
WHITE_REFERENCE = ("gltf:metal-rough", {"baseColor": 1.0, "metallic": 0.0, "specular": 0.0})
