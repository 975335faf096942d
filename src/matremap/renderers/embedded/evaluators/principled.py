"""The embedded renderer's evaluator of ``cycles:principled``: Blender 5.0 Cycles' Principled BSDF
restricted to the sockets the dialect exposes (Base Color, Metallic, Roughness, IOR, Specular IOR
Level, Specular Tint; distribution multi_ggx or ggx), as f * cos(theta_light) on [N, C, L, P] arrays.

Written from Cycles' source (blender/blender, ``intern/cycles``), not copied from it:

* ``kernel/svm/closure.h``, ``svm_node_closure_bsdf``, case ``CLOSURE_BSDF_PRINCIPLED_ID``: the
  layering. With weight w = 1: a metal GGX lobe of weight Metallic (F82-tint Fresnel, F0 = Base
  Color clamped to [0, 1], F82 tint = min(Specular Tint, 1)), then w *= 1 - Metallic; the IOR
  adjustment (F0 = ((IOR - 1)/(IOR + 1))^2, and when Specular IOR Level != 0.5: F0 *= 2 Level,
  eta = ior_from_F0(F0) with F0 clamped to 0.99 there); a dielectric GGX lobe of weight w when
  eta != 1 (so Level 0 removes it) whose Fresnel is the "generalized Schlick" with a negative
  exponent: the real dielectric Fresnel of eta remapped from [F0(eta), 1] to
  [min(F0 Specular Tint, 1), 1]; then ``closure_layering_weight`` w *= clamp(1 - max over RGB of
  the lobe's albedo / w, 0, 1); last a Lambertian (Diffuse Roughness 0) of weight Base Color w.
* ``kernel/closure/bsdf_microfacet.h``: ``bsdf_microfacet_eval`` (D G2 / (4 cos_view) with the
  height-correlated Smith G, zero for a near-mirror), ``microfacet_fresnel`` (the F82_TINT and
  GENERALIZED_SCHLICK branches), ``bsdf_microfacet_setup_fresnel_generalized_schlick`` /
  ``..._f82_tint`` (the average Fresnel Fss handed to the energy compensation),
  ``microfacet_ggx_preserve_energy`` (Multiscatter GGX: the lobe times 1 + Fms (1 - E)/E, with
  E, E_avg the white GGX albedo tables of :mod:`.cycles`; the closure's weight carries the part
  (1 + Fms (1 - E)/E) E, which the layering sees) and ``bsdf_microfacet_estimate_albedo`` (the
  dielectric lobe's albedo for the layering: mix(F0 tint, 1, s) with s read from the table
  ``ggx_gen_schlick_ior_s`` at (Roughness, cos_view, sqrt((eta - 1)/(eta + 1)))).
* ``kernel/closure/bsdf_util.h``: ``fresnel_dielectric``, ``F0_from_ior``, ``ior_from_F0``,
  ``fresnel_f82``, ``fresnel_f82tint_B``, ``fresnel_f82_Fss``, ``fresnel_dielectric_Fss`` (Kulla and
  Conty's fit of the average dielectric Fresnel), ``closure_layering_weight``; ``kernel/closure/bsdf.h``
  ``bsdf_albedo`` (the closure's weight times the estimate above).
* ``app/cycles_precompute.cpp`` (term ``ggx_gen_schlick_ior_s``) and ``kernel/util/lookup_table.h``:
  the 16 x 16 x 16 table holds, for Roughness r = i/15 (clamped to [1e-4, 1]), cos_view mu = j/15
  (clamped to [1e-4, 1]) and z = k/15 (clamped to [1e-4, 0.99], eta = ior_from_F0(z^4)), the mean of
  s(o.m) = clamp((F(o.m, eta) - F0(eta))/(1 - F0(eta)), 0, 1) over GGX visible normals m sampled
  from the view direction, a sample whose reflection falls below the horizon counting as 0; read
  trilinearly (linear in r, then mu, then z). Cycles estimates it by Monte Carlo; here it is
  integrated numerically (:func:`visible_normal_mean`) on the same nodes and read the same way.

Where the renderer differs from the Principled BSDF's published description, this follows the
renderer: the diffuse base is weighted by 1 - (the specular lobe's directional albedo from the
table above, an average over visible normals rather than the lobe's exact albedo), the reduction
takes the largest RGB channel (a tinted specular darkens the diffuse equally in all channels),
and under Multiscatter GGX the albedo includes the multiple-scattering gain but not the 1/E.
A Base Color above 1 would still feed the diffuse unclamped (the dialect caps it at 1).

The two layers over that base, in ``CLOSURE_BSDF_PRINCIPLED_ID``'s order (the weight w starts at 1 and each
layer leaves w clamp(1 - max over RGB of (its albedo / w), 0, 1) to what lies below: ``closure_layering_weight``):

* sheen, first, when Sheen Weight > 1e-5 (``CLOSURE_WEIGHT_CUTOFF``): a closure of weight Sheen Weight Sheen
  Tint w evaluated by ``kernel/closure/bsdf_sheen.h``: Zeltner, Burley and Chiang's LTC sheen, R(mu_o, r)
  D_LTC(light) in the frame of the view's azimuth, roughness clamped to [1e-3, 1], with A, B and R read from
  Cycles' 32 x 32 table ``sheen_ltc`` (:mod:`..cycles_sheen_ltc`, the paper's published fit) bilinearly as
  ``lookup_table_read_2D`` does; skipped (no lobe, no layering) where |A| or R is below 1e-5; its albedo
  Sheen Weight Sheen Tint R(mu_o, r). (The analytic fits of the same table, which MaterialX uses for
  OpenPBR's fuzz, differ from it by 1 to 30 % of a sheen's image below roughness 0.5.)
* coat, second, when Coat Weight > 1e-5: a GGX closure of weight Coat Weight w, alpha = Coat Roughness^2, the
  real dielectric Fresnel of Coat IOR (``bsdf_microfacet_setup_fresnel_dielectric``), which always applies
  ``microfacet_ggx_preserve_energy`` with Fss = ``fresnel_dielectric_Fss``(Coat IOR): the lobe times
  1 + Fms (1 - E)/E whatever the node's distribution; its albedo Coat Weight (1 + Fms (1 - E)/E) E
  mix(F0(Coat IOR), 1, s), s the ``ggx_gen_schlick_ior_s`` table as for the dielectric lobe (0 at Coat IOR 1);
  then, if Coat Tint is not white, w *= mix(1, Coat Tint^(1/cos theta_t), Coat Weight), theta_t the view
  refracted into the coat.

Both default to off (weights 0), where w stays exactly 1 and the result is the base's bit for bit.

Transmission (``CLOSURE_BSDF_PRINCIPLED_ID``, "Transmission component", after the metal): when Transmission
Weight t > 1e-5 a GGX glass closure (``bsdf_microfacet_ggx_glass_setup``) of weight t w, alpha = Roughness^2,
relative IOR the socket's IOR (not adjusted by Specular IOR Level) and the generalized Schlick Fresnel with a
negative exponent (the real dielectric Fresnel remapped to [min(F0(IOR) Specular Tint, 1), 1]), transmission
tint sqrt(min(Base Color, 1)); then w *= 1 - t (no albedo layering). Its reflection is the GGX lobe times that
Fresnel (``bsdf_microfacet_eval``); under Multiscatter GGX ``microfacet_ggx_preserve_energy`` on the glass
multiplies it by 1 + F_ms (1 - E)/E with Fss = the transmission tint and E, E_avg Cycles' glass albedo tables
(:mod:`..cycles_glass`). The probe's lights are in front of the sphere, so a light below a pixel's horizon is
behind the sphere itself (its shadow ray is blocked), and only this reflection is seen on the opaque probe;
what goes through is drawn by the transmission probe (``..transmission.cycles_principled_interface``).

Left out, as the dialect does not expose them: subsurface, emission, thin film, anisotropy,
alpha, Coat Normal, Diffuse Roughness (Oren-Nayar) and normal maps on other lobes.
"""

from __future__ import annotations

import functools
import hashlib
import json
from pathlib import Path

import numpy as np

from matremap.core.diskcache import cache_dir, load_tables, save_tables
from matremap.core.optics import f0_from_ior, fresnel_dielectric, ior_from_f0
from matremap.dialects.cycles import PRINCIPLED
from matremap.renderers.embedded import layering as ly
from matremap.renderers.embedded import microfacet as mf
from matremap.renderers.embedded import quadrature
from matremap.renderers.embedded.cycles_glass import glass_multiscatter_scale
from matremap.renderers.embedded.cycles_sheen_ltc import sheen_ltc_table
from matremap.renderers.embedded.evaluators.cycles import ggx_albedo, multiscatter_scale

#: nodes per axis of Cycles' ``ggx_gen_schlick_ior_s`` table (roughness, cos_view, z)
SCHLICK_NODES = 16
#: Cycles' ``BSDF_ROUGHNESS_SQ_THRESH`` as the glossy emulation uses it: alpha^2 at or below is a mirror
MIRROR_ALPHA2 = 2e-10
#: Cycles' ``CLOSURE_WEIGHT_CUTOFF``: a layer of this weight or less is not created
CLOSURE_WEIGHT_CUTOFF = 1e-5

_TABLE_FORMAT = 1
_TABLE_QUAD = (48, 48)


def cycles_ior_from_f0(f0) -> np.ndarray:
    """Cycles' ``ior_from_F0``: (1 + sqrt F0)/(1 - sqrt F0) with F0 clamped to [0, 0.99]."""
    return ior_from_f0(np.clip(np.asarray(f0, dtype=float), 0.0, 0.99))


def visible_normal_mean(mu, rough, weight, quad: tuple[int, int] | None = None) -> np.ndarray:
    """The mean of ``weight(o.m)`` over GGX visible normals m seen from a viewer at cos theta = mu
    (alpha = rough^2), where a normal whose mirror reflection of the viewer lies below the surface
    counts as 0: what Cycles' precompute gets from its VNDF sampler (a sample going below the horizon
    returns a zero pdf).

    The visible-normal density is G1(o) (o.m) D(m) / mu; with u = tan^2 / (alpha^2 + tan^2) of theta_m
    (uniform under D cos theta_m dm) the mean is 1/pi integral G1(o) (o.m) / (mu cos theta_m)
    weight(o.m) du dphi over phi in [0, pi], the azimuths where the reflection stays above the
    surface. That region is all azimuths while tan theta_m < (1 - sin theta_o)/mu, none beyond
    (1 + sin theta_o)/mu, and |phi| < arccos(mu (t^2 - 1) / (2 sin theta_o t)) between; the u integral
    is split there so each panel is smooth. ``mu`` and ``rough`` broadcast (1-d results)."""
    n_u, n_phi = quad or _TABLE_QUAD
    mu, rough = np.broadcast_arrays(np.asarray(mu, dtype=float), np.asarray(rough, dtype=float))
    shape = mu.shape
    mu = np.clip(mu.reshape(-1, 1, 1), 1e-7, 1.0 - 1e-9)
    a2 = np.maximum(np.clip(rough.reshape(-1, 1, 1), 0.0, 1.0) ** 4, 1e-30)
    sin_o = np.sqrt(1.0 - mu * mu)
    t_all, t_none = (1.0 - sin_o) / mu, (1.0 + sin_o) / mu
    u1, u2 = t_all**2 / (a2 + t_all**2), t_none**2 / (a2 + t_none**2)
    xs, ws = quadrature.smoothstep(n_u)
    u = np.concatenate([u1 * xs[:, None], u1 + (u2 - u1) * xs[:, None]], axis=-2)
    wu = np.concatenate([u1 * ws[:, None], (u2 - u1) * ws[:, None]], axis=-2)
    tan2 = a2 * u / np.maximum(1.0 - u, 1e-300)
    t = np.sqrt(tan2)
    cos_m = 1.0 / np.sqrt(1.0 + tan2)
    with np.errstate(divide="ignore", invalid="ignore"):
        edge = np.where(t > 0.0, mu * (tan2 - 1.0) / (2.0 * sin_o * t), -1.0)
    phi_max = np.arccos(np.clip(edge, -1.0, 1.0))
    px, pw = quadrature.smoothstep(n_phi)
    o_m = sin_o * t * cos_m * np.cos(phi_max * px) + mu * cos_m
    lam_o = 0.5 * (np.sqrt(1.0 + a2 * (1.0 - mu * mu) / (mu * mu)) - 1.0)
    ok = o_m > 0.0
    f = np.where(ok, o_m / (cos_m * mu * (1.0 + lam_o)) * weight(np.where(ok, o_m, 1.0)), 0.0)
    mean = np.sum(f * pw * phi_max * wu, axis=(-2, -1)) / np.pi
    return mean.reshape(shape)


def dielectric_s(cos_theta, eta) -> np.ndarray:
    """Where the real dielectric Fresnel of ``eta`` lies between its F0 and 1:
    clamp((F(cos, eta) - F0(eta)) / (1 - F0(eta)), 0, 1) (``microfacet_fresnel``, exponent < 0)."""
    eta = np.asarray(eta, dtype=float)
    f0 = f0_from_ior(eta)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (fresnel_dielectric(cos_theta, eta) - f0) / (1.0 - f0)
    return np.clip(np.nan_to_num(s), 0.0, 1.0)


def _table_spec() -> str:
    return json.dumps({"format": _TABLE_FORMAT, "nodes": SCHLICK_NODES, "quad": _TABLE_QUAD}, sort_keys=True)


def _table_path() -> Path:
    digest = hashlib.sha256(_table_spec().encode()).hexdigest()[:12]
    return cache_dir() / f"cycles_gen_schlick_ior_s_{digest}.npz"


def _build_ior_s_table() -> np.ndarray:
    """The table [z, mu, r] on Cycles' nodes (see the module docstring)."""
    n = SCHLICK_NODES
    nodes = np.arange(n) / (n - 1)
    rough = np.clip(nodes, 1e-4, 1.0)
    mus = np.clip(nodes, 1e-4, 1.0)
    etas = cycles_ior_from_f0(np.clip(nodes, 1e-4, 0.99) ** 4)
    table = np.zeros((n, n, n))
    mu_grid, r_grid = np.meshgrid(mus, rough, indexing="ij")  # [mu, r]
    for k, eta in enumerate(etas):
        if np.float32(eta) == 1.0:  # Cycles works in float32: this IOR is 1, where s is 0
            continue
        table[k] = visible_normal_mean(mu_grid, r_grid, lambda c, eta=eta: dielectric_s(c, eta))
        mirror = rough**4 <= MIRROR_ALPHA2  # a mirror reflects about n itself: s at the view angle
        table[k][:, mirror] = dielectric_s(mus, eta)[:, None]
    return np.clip(table, 0.0, 1.0)


def _load_table(path: Path) -> np.ndarray | None:
    n = SCHLICK_NODES
    data = load_tables(path, _table_spec(), {"s": (n, n, n)})
    return None if data is None else data["s"]


@functools.cache
def ior_s_table() -> np.ndarray:
    """Cycles' ``ggx_gen_schlick_ior_s`` as [z node, mu node, roughness node], from the cache or built."""
    path = _table_path()
    table = _load_table(path)
    if table is None:
        table = _build_ior_s_table()
        save_tables(path, "cycles_gen_schlick_ior_s_*.npz", spec=np.array(_table_spec()), s=table)
    table.flags.writeable = False
    return table


def _lerp(x, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``lookup_table_read``'s coordinate: clamp(x, 0, 1) (n - 1); node below, node above, fraction."""
    x = np.clip(np.asarray(x, dtype=float), 0.0, 1.0) * (n - 1)
    i = np.minimum(np.floor(x).astype(np.intp), n - 1)
    return i, np.minimum(i + 1, n - 1), x - i


def specular_albedo_s(rough, mu, eta) -> np.ndarray:
    """s of the dielectric lobe's albedo estimate: the table read at (rough, mu, sqrt((eta-1)/(eta+1)))
    trilinearly, as ``lookup_table_read_3D`` does. Arguments broadcast."""
    table = ior_s_table()
    n = SCHLICK_NODES
    eta = np.asarray(eta, dtype=float)
    z = np.sqrt(np.abs((eta - 1.0) / (eta + 1.0)))
    r0, r1, tr = _lerp(rough, n)
    m0, m1, tm = _lerp(mu, n)
    z0, z1, tz = _lerp(z, n)

    def plane(k):
        def row(m):
            return (1.0 - tr) * table[k, m, r0] + tr * table[k, m, r1]

        return (1.0 - tm) * row(m0) + tm * row(m1)

    return (1.0 - tz) * plane(z0) + tz * plane(z1)


def f82_tint_fresnel(cos_theta, f0, tint) -> np.ndarray:
    """Cycles' F82-tint metal Fresnel: clamp(Schlick(F0) - B cos (1 - cos)^6, 0, 1) with B chosen so
    that at cos = 1/7 the value is Schlick's times ``tint`` (``fresnel_f82`` with ``fresnel_f82tint_B``)."""
    f0 = np.asarray(f0, dtype=float)
    m = np.clip(1.0 - np.asarray(cos_theta, dtype=float), 0.0, 1.0)
    m5 = m**5
    return np.clip(f0 + (1.0 - f0) * m5 - f82_b(f0, tint) * (1.0 - m) * m5 * m, 0.0, 1.0)


def f82_b(f0, tint) -> np.ndarray:
    """``fresnel_f82tint_B``: Schlick(F0) at cos = 1/7 times 7 / (6/7)^6 times (1 - tint)."""
    f = 6.0 / 7.0
    f0 = np.asarray(f0, dtype=float)
    return (f0 + (1.0 - f0) * f**5) * (7.0 / f**6) * (1.0 - np.asarray(tint, dtype=float))


def ggx_lobe(rough, g) -> np.ndarray:
    """The white single-scatter GGX lobe times cos(theta_light): D G2 / (4 cos_view), zero for a
    near-mirror (alpha = rough^2) under point lights, a lobe of ``g.mirror_alpha`` where the renderer samples the
    mirror direction (:func:`~matremap.renderers.embedded.microfacet.drawn_alpha`)."""
    alpha = mf.drawn_alpha(rough * rough, g)
    d = mf.d_ggx(g.cos_h, g.tan2_h, alpha)
    g2 = mf.g_height_correlated(mf.lambda_ggx(g.tan_i, alpha), mf.lambda_ggx(g.tan_o, alpha))
    return np.where(alpha * alpha <= MIRROR_ALPHA2, 0.0, d * g2 / (4.0 * g.cos_o))


def layering_weight(ratio, w) -> np.ndarray:
    """``closure_layering_weight``: w clamp(1 - max over RGB of albedo / w, 0, 1), with the layer's albedo
    given as ``ratio`` = albedo / w (channels where w is 0 count as 0, as ``safe_divide_color`` makes them)."""
    ratio = np.where(w > 0.0, np.broadcast_to(ratio, np.broadcast(ratio, w).shape), 0.0)
    return w * np.clip(1.0 - np.max(ratio, axis=1, keepdims=True), 0.0, 1.0)


def sheen_ltc(mu, rough) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(A, B, R) of Cycles' sheen at cos_view ``mu`` and roughness: ``lookup_table_read_2D`` of
    :func:`~matremap.renderers.embedded.cycles_sheen_ltc.sheen_ltc_table`, linear in cos_view within the two
    roughness rows around it, then in roughness."""
    table = sheen_ltc_table()
    n = table.shape[-1]
    m0, m1, tm = _lerp(mu, n)
    r0, r1, tr = _lerp(rough, n)

    def read(plane):
        def row(r):
            return (1.0 - tm) * table[plane, r, m0] + tm * table[plane, r, m1]

        return (1.0 - tr) * row(r0) + tr * row(r1)

    return read(0), read(1), read(2)


def sheen_layer(p, g) -> tuple[np.ndarray, np.ndarray]:
    """The sheen closure's f cos(theta_light) for w = 1, and its albedo (see the module docstring)."""
    weight = np.maximum(p["Sheen Weight"], 0.0)
    colour = weight * np.maximum(p["Sheen Tint"], 0.0)
    rough = np.clip(p["Sheen Roughness"], 1e-3, 1.0)
    a, b, albedo = sheen_ltc(g.cos_o, rough)
    on = (weight > CLOSURE_WEIGHT_CUTOFF) & (np.abs(a) >= 1e-5) & (albedo >= 1e-5)
    fcos = np.where(on, colour * albedo * ly.ltc_cosine(np.where(on, a, 1.0), b, g), 0.0)
    return fcos, np.where(on, colour * albedo, 0.0)


def coat_layer(p, g) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The coat closure's f cos(theta_light) and albedo for w = 1, and the tint its absorption leaves on w."""
    weight = np.maximum(p["Coat Weight"], 0.0)
    rough = np.clip(p["Coat Roughness"], 0.0, 1.0)
    ior = np.maximum(p["Coat IOR"], 1.0)
    on = weight > CLOSURE_WEIGHT_CUTOFF
    f0 = f0_from_ior(ior)
    gain = multiscatter_scale(dielectric_average_fresnel(ior), rough, g.cos_o)
    fcos = weight * gain * fresnel_dielectric(g.i_dot_h, ior) * ggx_lobe(rough, g)
    estimate = np.where(ior > 1.0, f0 + (1.0 - f0) * specular_albedo_s(rough, g.cos_o, ior), 0.0)
    albedo = weight * gain * ggx_albedo(rough, g.cos_o) * estimate
    cos_t = np.sqrt(np.maximum(1.0 - (1.0 - g.cos_o**2) / ior**2, 0.0))
    tint = np.maximum(p["Coat Tint"], 0.0) ** (1.0 / np.maximum(cos_t, 1e-12))
    absorbed = (1.0 - weight) + weight * tint
    return np.where(on, fcos, 0.0), np.where(on, albedo, 0.0), np.where(on, absorbed, 1.0)


def principled(p, opt, g):
    """f * cos(theta_light) of the Principled BSDF: the sheen over the coat over the base (the base alone
    when no material of the batch has a layer)."""
    base = principled_base(p, opt, g)
    if not any(np.any(np.asarray(p.get(k, 0.0)) > CLOSURE_WEIGHT_CUTOFF) for k in ("Sheen Weight", "Coat Weight")):
        return base
    sheen, sheen_albedo = sheen_layer(p, g)
    w = layering_weight(sheen_albedo, np.ones_like(np.asarray(sheen_albedo, dtype=float)))
    coat, coat_albedo, absorbed = coat_layer(p, g)
    coat = w * coat
    w = layering_weight(coat_albedo, w) * absorbed
    return sheen + coat + w * base


def principled_base(p, opt, g):
    """f * cos(theta_light) of the Principled BSDF without its layers (see the module docstring for each step)."""
    multi = opt["distribution"] == "multi_ggx"
    base = np.maximum(p["Base Color"], 0.0)
    f0_metal = np.minimum(base, 1.0)
    metallic = np.clip(p["Metallic"], 0.0, 1.0)
    rough = np.clip(p["Roughness"], 0.0, 1.0)
    ior = np.maximum(p["IOR"], 1e-5)
    level = np.maximum(p["Specular IOR Level"], 0.0)
    tint = np.maximum(p["Specular Tint"], 0.0)
    lobe = ggx_lobe(rough, g)
    cos_h = g.i_dot_h

    # metal: F82-tint Fresnel, weight Metallic
    b = f82_b(f0_metal, np.minimum(tint, 1.0))
    metal = f82_tint_fresnel(cos_h, f0_metal, np.minimum(tint, 1.0)) * lobe
    if multi:
        fss_metal = f0_metal + (1.0 - f0_metal) / 21.0 - b / 126.0
        metal = metal * multiscatter_scale(fss_metal, rough, g.cos_o)
    weight = np.where(metallic > 1e-5, 1.0 - metallic, 1.0)
    metal = np.where(metallic > 1e-5, metallic * metal, 0.0)
    glass, weight = transmission_layer(p, g, weight, lobe, multi)

    # dielectric specular: the IOR adjusted by Specular IOR Level, the real Fresnel remapped to the tint
    f0 = f0_from_ior(ior)
    adjusted = level != 0.5
    f0 = np.where(adjusted, f0 * 2.0 * level, f0)
    eta = np.where(adjusted, cycles_ior_from_f0(f0), ior)
    eta = np.where(adjusted & (ior < 1.0), 1.0 / eta, eta)
    has_spec = eta != 1.0
    f0_tint = np.clip(f0 * tint, 0.0, 1.0)
    s = dielectric_s(cos_h, eta)
    spec = (f0_tint + (1.0 - f0_tint) * s) * lobe
    keep = 1.0  # what the layering sees of the closure's weight besides w: Multiscatter's darkening
    if multi:
        s_avg = np.clip((dielectric_average_fresnel(eta) - f0_from_ior(eta)) / (1.0 - f0_from_ior(eta)), 0.0, 1.0)
        fss = f0_tint + (1.0 - f0_tint) * s_avg
        gain = multiscatter_scale(fss, rough, g.cos_o)
        spec = spec * gain
        keep = gain * ggx_albedo(rough, g.cos_o)
    spec = np.where(has_spec, weight * spec, 0.0)

    # diffuse under the specular layer: w (1 - max over RGB of the lobe's estimated albedo)
    s_est = specular_albedo_s(rough, g.cos_o, eta)
    albedo = keep * (f0_tint + (1.0 - f0_tint) * s_est)
    cover = np.clip(1.0 - np.max(albedo, axis=1, keepdims=True), 0.0, 1.0)
    diffuse_weight = np.where(has_spec, weight * cover, weight)
    return metal + glass + spec + base * diffuse_weight * g.lambert


def transmission_layer(p, g, weight, lobe, multi: bool) -> tuple[np.ndarray | float, np.ndarray]:
    """The glass closure's reflection f cos(theta_light) at weight Transmission Weight ``weight``, and the weight
    it leaves below ((1 - t) ``weight``); nothing and ``weight`` itself when no material has t > 1e-5."""
    t = np.clip(p.get("Transmission Weight", 0.0), 0.0, 1.0)
    on = t > CLOSURE_WEIGHT_CUTOFF
    if not np.any(on):
        return 0.0, weight
    ior = np.maximum(p["IOR"], 1e-5)
    f0 = np.clip(f0_from_ior(ior) * np.maximum(p["Specular Tint"], 0.0), 0.0, 1.0)
    reflection = (f0 + (1.0 - f0) * dielectric_s(g.i_dot_h, ior)) * lobe
    if multi:
        fss = np.sqrt(np.clip(p["Base Color"], 0.0, 1.0))
        reflection = reflection * glass_multiscatter_scale(fss, np.clip(p["Roughness"], 0.0, 1.0), g.cos_o, ior)
    return np.where(on, t * weight * reflection, 0.0), np.where(on, (1.0 - t) * weight, weight)


def dielectric_average_fresnel(eta) -> np.ndarray:
    """Cycles' ``fresnel_dielectric_Fss`` for eta >= 1: Kulla and Conty's fit (eta - 1)/(4.08567 + 1.00071 eta)
    of the cosine-weighted mean dielectric Fresnel; their cubic for eta < 1."""
    eta = np.asarray(eta, dtype=float)
    below = 0.997118 + eta * (0.1014 - eta * (0.965241 + eta * 0.130607))
    return np.where(eta < 1.0, below, (eta - 1.0) / (4.08567 + 1.00071 * eta))


#: model id -> evaluator
EVALUATORS = {PRINCIPLED.id: principled}
