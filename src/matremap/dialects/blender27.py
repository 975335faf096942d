"""Blender Internal 2.7x (the pre-2.80 renderer), emulated: Lambert diffuse + WardIso specular.

Source: Blender 2.7x ``source/blender/render/intern/source/shadeoutput.c`` (``WardIso_Spec``,
Lambert in ``shade_one_light``) and ``makesrna/intern/rna_material.c`` (ranges).

==================  ======================================================================
parameter           meaning (Blender's RNA names)
==================  ======================================================================
diffuse_color       RGB, default 0.8; Lambert colour
diffuse_intensity   scalar in [0, 1], default 0.8 (held at 1 when fitting)
specular_color      RGB in [0, 1], default 1
specular_intensity  scalar in [0, 1], default 0.5 (held at 1 when fitting)
specular_slope      scalar in [0, 0.4], default 0.1; the WardIso rms roughness
==================  ======================================================================

Per lamp (lamp colour and energy are the renderer's irradiance, here the scene light):

* Lambert diffuse: (n.l) diffuse_intensity diffuse_color -- note: no 1/pi, so this renderer is
  pi times brighter than a physically based one at equal lamp settings (irradiance matching
  compensates, as the paper does);
* WardIso: alpha = max(rms, 0.001), s = (n.l) exp(-tan^2(theta_h)/alpha^2) / (4 pi alpha^2 sqrt((n.v)(n.l)))
  with the normalised half vector, times specular_intensity specular_color.

Blender replaces n.l <= 0 by 0.001 in WardIso; here lamps behind the surface are shadowed (the
sphere shadows itself), so those points are black as with ray-traced shadows.
"""

from __future__ import annotations

from matremap.core.models import ModelSpec, ParamSpec
from matremap.core.reflectance import SpecularParam

WARD = ModelSpec(
    id="blender27:ward",
    affine=(("diffuse_color", {}), ("specular_color", {})),
    summary="Blender Internal Lambert + WardIso specular (shadeoutput.c)",
    params=(
        ParamSpec("diffuse_color", "diffuse", (0.8,) * 3, (0.0, 1.0), channels=3, doc="Lambert colour"),
        ParamSpec("diffuse_intensity", "diffuse", 0.8, (0.0, 1.0), fit=False, fit_value=1.0),
        ParamSpec("specular_color", "specular", (1.0,) * 3, (0.0, 1.0), channels=3),
        ParamSpec("specular_intensity", "specular", 0.5, (0.0, 1.0), fit=False, fit_value=1.0),
        ParamSpec("specular_slope", "roughness", 0.1, (0.0, 0.4), doc="WardIso rms slope"),
    ),
    diffuse_only={"specular_intensity": 0.0},
    specular_only={"diffuse_intensity": 0.0},
    reflectance=SpecularParam("specular_color"),
)

#: the models of this dialect, in the order they are listed
MODELS = (WARD,)
#: a white Lambertian surface of albedo 1 in this renderer family (irradiance matching)
WHITE_REFERENCE = ("blender27:ward", {"diffuse_color": 1.0, "diffuse_intensity": 1.0, "specular_intensity": 0.0})
