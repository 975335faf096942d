"""Blender Cycles (Blender >= 2.80) BSDF nodes, emulated: Glossy BSDF (+ a Diffuse BSDF added).

Source: Cycles ``intern/cycles/kernel/closure/bsdf_microfacet.h`` and
``bsdf_ashikhmin_shirley.h``; ``kernel/svm/closure.h`` for alpha = Roughness^2; for Multiscatter
GGX also ``intern/cycles/app/cycles_precompute.cpp`` (how the albedo tables are made) and
``kernel/util/lookup_table.h`` (how they are read).

cycles:glossy -- Blender's Glossy BSDF node plus a Diffuse BSDF node joined by an Add Shader:

==============  ===============================================================================
parameter       meaning (node socket names)
==============  ===============================================================================
distribution    ggx*, beckmann, ashikhmin_shirley, multi_ggx (Multiscatter GGX, see below)
Color           RGB in [0, 1], default 0.8; no Fresnel: the lobe is multiplied by it
Roughness       scalar in [0, 1], default 0.5; alpha = Roughness^2
Diffuse Color   RGB in [0, 1], default 0 (no diffuse node); Lambertian Color/pi
==============  ===============================================================================

* GGX / Beckmann: f = Color D G / (4 cos_i cos_o) with the height-correlated Smith
  G = 1/(1 + Lambda(i) + Lambda(o)) used since Blender 3.5; zero when alpha^2 <= 2e-10.
* Ashikhmin-Shirley: alpha clamped to [1e-4, 1] (zero at or below 1e-4), n = 2/alpha^2 - 2,
  f cos_i = cos_i (n+1)/(8 pi) (n.h)^n / max(1e-6, (h.o) max(cos_i, cos_o)), cosines floored at 1e-6.

* Multiscatter GGX (Blender >= 4.0; 5.0 unchanged): not a random walk any more but the single-scatter
  GGX lobe above scaled up by energy compensation (``microfacet_ggx_preserve_energy`` in
  ``bsdf_microfacet.h``, reached from the Glossy node through ``bsdf_microfacet_setup_fresnel_constant``
  with the node's Color as the single-scatter "Fresnel"):

      f_ms = f_ss * (1 + F_ms (1 - E) / E),   F_ms = c E_avg / (1 - c (1 - E_avg)),   c = max(Color, 0)

  where E(mu, r) is the directional albedo of the white single-scatter lobe seen from the viewer
  (mu = cos theta_view, r = sqrt(alpha) = Roughness) and E_avg(r) = integral of E 2 mu dmu its
  cosine-weighted average. With a white Color F_ms = 1 and the lobe is simply divided by E. Cycles
  reads E from a 32 x 32 table on the nodes r = k/31, mu = j/31 (both clamped below at 1e-4;
  r -> 0 is a mirror, E = 1) and E_avg from 32 nodes in r, interpolated linearly (bilinearly), with
  inputs clamped to [0, 1]. The tables here hold the same quantities, computed by numerical
  integration of this module's single-scatter GGX (:func:`ggx_directional_albedo`) instead of
  Cycles' quasi-Monte Carlo, on the same nodes and read the same way, so the emulation inherits
  Cycles' interpolation. They take about a second to build and are cached in memory and in
  matremap's private cache folder (``$MATREMAP_CACHE``, default ``~/.cache/matremap``;
  skipped silently if not writable or not private).

cycles:diffuse -- the Diffuse BSDF node with Roughness 0 (Lambert): Color/pi.

cycles:principled -- the Principled BSDF node of Blender 5.0 with the sockets below (the others at
their defaults: no subsurface, emission, thin film, Diffuse Roughness 0).
Emulated by the embedded renderer (``renderers/embedded/evaluators/principled.py``, which follows
``kernel/svm/closure.h`` ``CLOSURE_BSDF_PRINCIPLED_ID`` and says where Cycles departs from the
published model) and drawn by real Cycles with ``--target-renderer cycles``:

  a metal GGX lobe of weight Metallic with the F82-tint Fresnel (F0 = Base Color, tint = Specular
  Tint); over the rest (1 - Metallic) a dielectric GGX lobe whose Fresnel is that of the IOR with F0
  scaled by 2 Specular IOR Level and remapped to F0 Specular Tint, over a Lambertian of Base Color
  weighted by 1 - the dielectric lobe's estimated directional albedo (the largest RGB channel);
  Multiscatter GGX scales each lobe by Cycles' energy compensation. Over all of it, as layers weighing
  what lies below by 1 - their estimated albedo (largest RGB channel): a sheen (Sheen Weight, Sheen Tint,
  Sheen Roughness: Zeltner et al.'s LTC sheen) and over that a coat (Coat Weight, Coat Roughness, Coat IOR:
  a GGX lobe with the real dielectric Fresnel and energy compensation whatever the distribution), whose
  Coat Tint absorbs along the refracted view (tint^(1/cos theta_t)). Both off by default (weights 0).
  Transmission Weight t (default 0): below the metal, a GGX glass closure of weight t (Roughness, the IOR
  itself -- not adjusted by Specular IOR Level --, F0 tinted by Specular Tint; what it transmits is tinted by
  sqrt(Base Color) at each crossing) takes the share t of the dielectric: the specular lobe and the diffuse
  under it keep 1 - t. In reflection the glass shows its GGX reflection (the transmission probe draws the rest).
"""

from __future__ import annotations

from matremap.core.models import ModelSpec, OptionSpec, ParamSpec
from matremap.core.reflectance import Dielectric, Metalness, SpecularParam

GLOSSY = ModelSpec(
    id="cycles:glossy",
    affine=(("Color", {"distribution": ("ggx", "beckmann", "ashikhmin_shirley")}), ("Diffuse Color", {})),
    summary="Glossy BSDF (+ Diffuse BSDF), alpha = Roughness^2",
    params=(
        ParamSpec("Color", "specular", (0.8,) * 3, (0.0, 1.0), channels=3),
        ParamSpec("Roughness", "roughness", 0.5, (0.0, 1.0), doc="alpha = Roughness^2"),
        ParamSpec("Diffuse Color", "diffuse", (0.0,) * 3, (0.0, 1.0), channels=3),
    ),
    options=(OptionSpec("distribution", ("ggx", "beckmann", "ashikhmin_shirley", "multi_ggx"), "ggx"),),
    diffuse_only={"Color": 0.0},
    specular_only={"Diffuse Color": 0.0},
    reflectance=SpecularParam("Color"),
    normal_mapping="cycles",
)

DIFFUSE = ModelSpec(
    id="cycles:diffuse",
    affine=(("Color", {}),),
    summary="Diffuse BSDF (Lambert)",
    params=(ParamSpec("Color", "diffuse", (0.8,) * 3, (0.0, 1.0), channels=3),),
    diffuse_only={},
    specular_only=None,
    normal_mapping="cycles",
)

PRINCIPLED = ModelSpec(
    id="cycles:principled",
    summary="Principled BSDF (Blender 5.0 Cycles; multiscatter GGX, F82-tint metals)",
    params=(
        ParamSpec(
            "Base Color",
            "diffuse",
            (0.8,) * 3,
            (0.0, 1.0),
            channels=3,
            doc="diffuse albedo; metal reflectance at normal incidence",
        ),
        ParamSpec("Metallic", "specular", 0.0, (0.0, 1.0), fit=False, doc="metallicity (held at 0 in fits)"),
        ParamSpec("Roughness", "roughness", 0.5, (0.0, 1.0), doc="alpha = Roughness^2"),
        ParamSpec("IOR", "fresnel", 1.5, (1.0, 4.0), doc="dielectric IOR (fitted: sets the specular level)"),
        ParamSpec(
            "Specular IOR Level",
            "specular",
            0.5,
            (0.0, 1.0),
            fit=False,
            doc="scales the dielectric F0 (0.5 = the IOR's own; 0 = no specular); held at 0.5 in "
            "fits, where IOR sets the level",
        ),
        ParamSpec(
            "Specular Tint",
            "other",
            (1.0,) * 3,
            (0.0, 1.0),
            channels=3,
            fit=False,
            doc="dielectric specular colour (held at white in fits)",
        ),
        ParamSpec(
            "Coat Weight",
            "specular",
            0.0,
            (0.0, 1.0),
            fit=False,
            linear=False,
            doc="coverage of the coat layer (0: none; held in fits: --free 'Coat Weight')",
        ),
        ParamSpec("Coat Roughness", "roughness", 0.03, (0.0, 1.0), fit=False, doc="coat GGX, alpha = roughness^2"),
        ParamSpec("Coat IOR", "other", 1.5, (1.0, 4.0), fit=False, doc="IOR of the coat (its real Fresnel)"),
        ParamSpec(
            "Coat Tint",
            "other",
            (1.0,) * 3,
            (0.0, 1.0),
            channels=3,
            fit=False,
            doc="colour of the coat's absorption at normal incidence (Beer's law along the refracted view)",
        ),
        ParamSpec(
            "Sheen Weight",
            "diffuse",
            0.0,
            (0.0, 1.0),
            fit=False,
            linear=False,
            doc="weight of the sheen layer (0: none; held in fits: --free 'Sheen Weight')",
        ),
        ParamSpec(
            "Sheen Roughness", "diffuse", 0.5, (0.0, 1.0), fit=False, linear=False, doc="Zeltner et al. LTC sheen"
        ),
        ParamSpec(
            "Sheen Tint", "diffuse", (1.0,) * 3, (0.0, 1.0), channels=3, fit=False, doc="colour of the sheen layer"
        ),
        ParamSpec(
            "Transmission Weight",
            "other",
            0.0,
            (0.0, 1.0),
            fit=False,
            linear=False,
            doc="share of the dielectric that is glass (refracts; held in fits: --free 'Transmission Weight')",
        ),
    ),
    options=(OptionSpec("distribution", ("multi_ggx", "ggx"), "multi_ggx", "microfacet distribution"),),
    # the diffuse part keeps the sheen (a diffuse absorbs it) and the coat's tint (Coat IOR 1: no coat reflection)
    diffuse_only={"Metallic": 0.0, "Specular IOR Level": 0.0, "Coat IOR": 1.0},
    # with Metallic = 0 (held in fits) a black base leaves the dielectric specular lobe (and the coat) alone;
    # a metal's lobe takes Base Color's colour, so this isolates nothing when Metallic > 0
    specular_only={"Base Color": 0.0, "Sheen Weight": 0.0},
    # a metal (Metallic 1, chosen for a source without a diffuse part): Base Color is its F0, no diffuse part
    specialisations=(
        (
            "Metallic",
            1.0,
            {"roles": {"Base Color": "specular", "IOR": "other"}, "diffuse_only": None, "specular_only": {}},
        ),
    ),
    # F0: a metal's Base Color (F82-tint: Base Color is F0); a dielectric's F0 of the IOR, with Specular IOR
    # Level held at 0.5 (where Cycles leaves F0 as the IOR gives it)
    reflectance=Metalness("Base Color", "Metallic", Dielectric("IOR")),
    channel_separable=False,
    normal_mapping="cycles",
)

#: the models of this dialect, in the order they are listed
MODELS = (
    GLOSSY,
    DIFFUSE,
    PRINCIPLED,
)
#: a white Lambertian surface of albedo 1 in this renderer family (irradiance matching)
WHITE_REFERENCE = ("cycles:diffuse", {"Color": 1.0})
