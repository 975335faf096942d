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

import numpy as np

from matremap.dialects.blender27 import WARD


def ward(p, opt, g):
    alpha = np.maximum(p["specular_slope"], 0.001)
    a2 = alpha * alpha
    s = g.cos_i * np.exp(-g.tan2_h / a2) / (4.0 * np.pi * a2 * np.sqrt(g.cos_o * g.cos_i))
    spec = (p["specular_intensity"] * p["specular_color"]) * s
    return spec + (p["diffuse_intensity"] * p["diffuse_color"]) * g.cos_i


#: model id -> evaluator
EVALUATORS = {WARD.id: ward}
