"""Mitsuba 3 itself, apart from any scene: finding and importing it, choosing its variant, the BSDF plugin
dictionary of a ``mitsuba3:*`` material, errors turned into one line, and the probe camera. The probe
(:mod:`.probe`) and environment (:mod:`.environment`) renders build on these."""

from __future__ import annotations

import glob
import os
import subprocess
import sys
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

from matremap.core.material import Material
from matremap.core.scene import Scene
from matremap.dialects import mitsuba3 as mitsuba3_dialect
from matremap.dialects.mitsuba3 import (
    PRINCIPLED_HELD,
)
from matremap.errors import MatremapError, RendererUnavailable

INSTALL_HINT = (
    "Mitsuba 3 is not installed; install it with `pip install 'matremap[mitsuba]'` "
    "(or `pip install mitsuba`, which brings drjit)"
)


@dataclass(frozen=True)
class Binding:
    """A model parameter and the key of ``mi.traverse(scene)`` it writes (prefixed by ``sphere.bsdf.``)."""

    param: str
    key: str
    rgb: bool


def bsdf_dict(model: str, options: dict[str, str], m: Material) -> tuple[dict[str, Any], list[Binding]]:
    """The BSDF's plugin dictionary for material ``m`` and the parameters to update per material."""

    def rgb(name: str) -> dict[str, Any]:
        return {"type": "rgb", "value": [float(x) for x in m.values[name]]}

    def scalar(name: str) -> float:
        return float(m.values[name][0])

    if model == "mitsuba3:diffuse":
        return {"type": "diffuse", "reflectance": rgb("reflectance")}, [
            Binding("reflectance", "reflectance.value", True)
        ]
    if model in ("mitsuba3:roughconductor", "mitsuba3:roughconductor-anisotropic"):
        alphas = ("alpha",) if model == "mitsuba3:roughconductor" else ("alpha_u", "alpha_v")
        d: dict[str, Any] = {
            "type": "roughconductor",
            "distribution": options["distribution"],
            **{a: scalar(a) for a in alphas},
            "specular_reflectance": rgb("specular_reflectance"),
        }
        b = [
            *(Binding(a, f"{a}.value", False) for a in alphas),
            Binding("specular_reflectance", "specular_reflectance.value", True),
        ]
        if options["material"] == "custom":
            d.update(eta=rgb("eta"), k=rgb("k"))
            b += [Binding("eta", "eta.value", True), Binding("k", "k.value", True)]
        else:
            d["material"] = options["material"]
        return d, b
    if model == "mitsuba3:roughplastic":
        d = {
            "type": "roughplastic",
            "distribution": options["distribution"],
            "alpha": scalar("alpha"),
            "int_ior": scalar("int_ior"),
            "ext_ior": scalar("ext_ior"),
            "nonlinear": options["nonlinear"] == "true",
            "specular_reflectance": rgb("specular_reflectance"),
            "diffuse_reflectance": rgb("diffuse_reflectance"),
        }
        # eta (= int_ior / ext_ior) is handled separately in _Loaded.set
        b = [
            Binding("alpha", "alpha", False),
            Binding("specular_reflectance", "specular_reflectance.value", True),
            Binding("diffuse_reflectance", "diffuse_reflectance.value", True),
        ]
        return d, b
    if model == "mitsuba3:principled":
        d = {"type": "principled", "base_color": rgb("base_color")}
        b = [Binding("base_color", "base_color.value", True), Binding("specular", "specular", False)]
        d["specular"] = scalar("specular")
        for name in ("roughness", "metallic", *PRINCIPLED_HELD):
            d[name] = scalar(name)
            b.append(Binding(name, f"{name}.value", False))
        return d, b
    if model in GLASS_PLUGINS:
        return glass_dict(model, options, m)
    raise MatremapError(f"renderer 'mitsuba3' cannot render model {model}")  # pragma: no cover


#: the glass models and their plugins (dielectric.cpp, roughdielectric.cpp, thindielectric.cpp)
GLASS_PLUGINS = {
    "mitsuba3:dielectric": "dielectric",
    "mitsuba3:roughdielectric": "roughdielectric",
    "mitsuba3:thindielectric": "thindielectric",
}


def glass_dict(model: str, options: dict[str, str], m: Material) -> tuple[dict[str, Any], list[Binding]]:
    """A glass's plugin dictionary. Its IORs are constructor arguments (Mitsuba keeps only ``eta``, which
    ``mi.traverse`` exposes): the probe writes ``eta`` = int_ior / ext_ior per material (``probe.ETA_MODELS``)."""
    d: dict[str, Any] = {
        "type": GLASS_PLUGINS[model],
        "int_ior": float(m.values["int_ior"][0]),
        "ext_ior": float(m.values["ext_ior"][0]),
        "specular_reflectance": {"type": "rgb", "value": [float(x) for x in m.values["specular_reflectance"]]},
        "specular_transmittance": {"type": "rgb", "value": [float(x) for x in m.values["specular_transmittance"]]},
    }
    b = [
        Binding("specular_reflectance", "specular_reflectance.value", True),
        Binding("specular_transmittance", "specular_transmittance.value", True),
    ]
    if model == "mitsuba3:roughdielectric":
        d.update(distribution=options["distribution"], alpha=float(m.values["alpha"][0]))
        b.append(Binding("alpha", "alpha.value", False))
    return d, b


#: the models Mitsuba 3 draws: those of its dialect
MODELS = tuple(spec.id for spec in mitsuba3_dialect.MODELS)


def mitsuba_installed() -> bool:
    """Whether the ``mitsuba`` package can be found (without importing it)."""
    import importlib.util

    return importlib.util.find_spec("mitsuba") is not None


def import_mitsuba():
    """``import mitsuba``, or a MatremapError saying how to install it."""
    try:
        import mitsuba
    except ImportError as e:  # also covers a broken drjit
        raise RendererUnavailable(f"{INSTALL_HINT} ({e})") from None
    return mitsuba


def llvm_usable() -> bool:
    """Whether a libLLVM that Mitsuba's llvm variants work with (>= 17) is on the system."""
    for path in glob.glob("/usr/lib/*/libLLVM*.so*") + glob.glob("/usr/lib/llvm-*/lib/libLLVM*.so*"):
        digits = "".join(c if c.isdigit() else " " for c in os.path.basename(path)).split()
        if digits and 17 <= int(digits[0]) < 100:
            return True
    return False


_LLVM_CHECK = """
import mitsuba as mi
mi.set_variant("llvm_ad_rgb")
scene = mi.load_dict({"type": "scene", "integrator": {"type": "direct"},
                      "sensor": {"type": "perspective", "film": {"type": "hdrfilm", "width": 4, "height": 4}},
                      "s": {"type": "sphere", "center": [0, 0, -3]}, "e": {"type": "constant"}})
img = mi.render(scene, spp=1, seed=0)
print("ok", float(img.numpy().mean()))
"""


@lru_cache(maxsize=1)
def llvm_renders() -> bool:
    """Whether ``llvm_ad_rgb`` renders here: a libLLVM >= 17 is found (:func:`llvm_usable`) and a tiny
    render in a child process succeeds (LLVM 15/16 abort the process, so this is never tried in
    this one). Cached per process; costs about 2 s the first time."""
    if not llvm_usable():
        return False
    try:
        done = subprocess.run([sys.executable, "-c", _LLVM_CHECK], capture_output=True, text=True, timeout=120)
    except (OSError, subprocess.SubprocessError):
        return False
    return done.returncode == 0 and done.stdout.startswith("ok")


def choose_variant(mi, variant: str | None) -> str:
    """``variant``, else ``$MATREMAP_MITSUBA_VARIANT``, else ``scalar_rgb``; ``auto`` is
    ``llvm_ad_rgb`` when this build has it and it renders (:func:`llvm_renders`), else ``scalar_rgb``."""
    variant = variant or os.environ.get("MATREMAP_MITSUBA_VARIANT") or "scalar_rgb"
    if variant == "auto":
        variant = "llvm_ad_rgb" if "llvm_ad_rgb" in mi.variants() and llvm_renders() else "scalar_rgb"
    if not variant.endswith("_rgb"):
        raise MatremapError(f"Mitsuba variant {variant!r}: matremap needs an RGB variant (scalar_rgb, llvm_ad_rgb)")
    if variant not in mi.variants():
        raise MatremapError(f"Mitsuba variant {variant!r} is not available; this build has {', '.join(mi.variants())}")
    return variant


def mitsuba_call(mi, what: str, fn, *args, **kwargs):
    """``fn(*args, **kwargs)``, with Mitsuba's own errors turned into one MatremapError naming ``what``."""
    try:
        return fn(*args, **kwargs)
    except (RuntimeError, ValueError, TypeError) as e:
        raise RendererUnavailable(f"Mitsuba 3 failed to {what}: {e}") from e


def probe_sensor(mi, scene: Scene, sampler: dict[str, Any]) -> dict[str, Any]:
    """The probe scene's camera as a Mitsuba sensor: at (0, 0, camera_distance) looking at the
    origin, +y up, the scene's field of view along x, a square box-filtered HDR film."""
    res = scene.resolution
    return {
        "type": "perspective",
        "fov": float(scene.effective_fov),
        "fov_axis": "x",
        "near_clip": 1e-3,
        "far_clip": 10.0 * (scene.camera_distance + scene.sphere_radius),
        "to_world": mi.ScalarTransform4f().look_at(
            origin=[0.0, 0.0, float(scene.camera_distance)], target=[0.0, 0.0, 0.0], up=[0.0, 1.0, 0.0]
        ),
        "sampler": sampler,
        "film": {"type": "hdrfilm", "width": res, "height": res, "pixel_format": "rgb", "rfilter": {"type": "box"}},
    }
