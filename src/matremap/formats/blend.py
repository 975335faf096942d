"""Blender .blend output: a converted material as Cycles nodes on a sphere, written by Blender itself.

``write(out, result, source=None, force=False)`` takes a uniform :class:`~matremap.core.material.Material`
or a :class:`~matremap.svbrdf.textures.MapSet` of converted maps of ``cycles:principled``,
``cycles:glossy`` or ``cycles:diffuse`` and asks the bpy worker of
:class:`~matremap.renderers.cycles.probe.CyclesRenderer` (request ``{"op": "write_blend"}``, see
``cycles_worker.py``) to build and save the file; it needs the bpy venv (docs/cycles.md).

The file holds:

* one material, named after the asset (``source.name``; else the map set's folder; else the output
  file's stem), whose node tree is the model's own nodes, as the Cycles backend renders them:
  a Principled BSDF (``cycles:principled``, its ``distribution``), or a Glossy BSDF and a Diffuse
  BSDF (Roughness 0) joined by an Add Shader (``cycles:glossy``: Glossy "Color", "Roughness",
  ``distribution``; Diffuse "Diffuse Color"), or a Diffuse BSDF, into a Material Output. Parameters
  given as numbers (or left at the model's defaults) are the sockets' values;
* for each map, an Image Texture node (Linear interpolation, Extend, the UV map of the sphere) linked
  to its socket, the image **packed into the .blend** (the file stands alone). Its colour space is
  how matremap reads the file: "sRGB" where the map set says the file is sRGB-encoded (8/16-bit
  colour maps by default), otherwise "Non-Color" for data (scalar) maps and "Linear Rec.709" for
  colour maps stored linear (EXR). Scalar maps are linked by their Color output (grey images);
* a normal map as an Image Texture (Non-Color) into a Normal Map node (tangent space, the sphere's
  UV map; matremap's convention, x along u and y up the image, is Blender's) feeding every BSDF's
  Normal;
* the object ``sphere``: a smooth 128 x 64 UV sphere of the probe scene's radius with its pole
  along +y and matremap's UVs (as in :mod:`matremap.renderers.cycles.environment`), and the probe camera
  on +z, so that a render from the file's camera frames the sphere as matremap's renders do.

Writing is atomic (Blender saves under a temporary name beside ``out``, which then replaces it);
an existing file is only replaced with ``force``.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from matremap.core.imageio import atomic_output, check_output
from matremap.core.material import Material
from matremap.core.scene import Scene
from matremap.dialects import get_model
from matremap.errors import MatremapError

#: models this writer knows the Blender nodes of
MODELS = ("cycles:principled", "cycles:glossy", "cycles:diffuse")
#: the sphere's segments x rings
GEOMETRY = "128x64"


def _constants(spec, values: dict[str, Any]) -> dict[str, list[float]]:
    out = {}
    for p in spec.params:
        v = values.get(p.name, p.default_array)
        out[p.name] = [float(x) for x in np.atleast_1d(np.asarray(v, dtype=float)).ravel()]
    return out


def _colorspace(spec, name: str, colorspace: str) -> str:
    if colorspace == "srgb":
        return "sRGB"
    return "Linear Rec.709" if spec.param(name).channels == 3 else "Non-Color"


def write_request(out_tmp: str, result: Any, source: Any, out: Path) -> dict[str, Any]:
    """The ``write_blend`` request that has the bpy worker save ``result`` at ``out_tmp`` (which
    becomes ``out``): the model's nodes, their values and textures, the material's name, the probe
    scene. Raises for results the worker cannot write."""
    from matremap.svbrdf.textures import MapSet

    textures: dict[str, dict[str, str]] = {}
    normal: dict[str, str] | None = None
    if isinstance(result, Material):
        spec = get_model(result.model)
        consts = _constants(spec, dict(result.values))
        options = dict(result.options)
        default_name = out.stem
    elif isinstance(result, MapSet):
        spec = result.spec
        values = {k: v for k, v in result.constants.items() if k in spec.param_names}
        consts = {k: v for k, v in _constants(spec, values).items() if k not in result.maps}
        options = {o.name: o.default for o in spec.options}
        options.update(result.options)
        for name, path in result.maps.items():
            p = Path(path)
            if not p.is_file():
                raise MatremapError(f"cannot write {out}: map {p} for {name} not found")
            textures[name] = {
                "path": str(p.resolve()),
                "colorspace": _colorspace(spec, name, result.colorspace.get(name, "linear")),
            }
        if result.normal is not None:
            normal = {"path": str(Path(result.normal).resolve()), "colorspace": "Non-Color"}
        default_name = Path(result.root).name or out.stem
    else:
        raise MatremapError(f"a .blend is written from a Material or a MapSet, not {type(result).__name__}")
    if spec.id not in MODELS:
        raise MatremapError(
            f"cannot write {spec.id} to a .blend: the Blender nodes are known for "
            f"{', '.join(MODELS)}; convert to one of them first"
        )
    if isinstance(result, Material):
        options = {o.name: result.options.get(o.name, o.default) for o in spec.options}
    name = getattr(source, "name", None) or default_name
    scene = Scene()
    return {
        "op": "write_blend",
        "path": out_tmp,
        "name": str(name),
        "model": spec.id,
        "options": options,
        "consts": consts,
        "textures": textures,
        "normal": normal,
        "geometry": GEOMETRY,
        "scene": {
            "resolution": scene.resolution,
            "fov": float(scene.effective_fov),
            "camera_distance": float(scene.camera_distance),
            "sphere_radius": float(scene.sphere_radius),
        },
    }


def write(out: str | os.PathLike, result: Any, source: Any = None, force: bool = False, renderer: Any = None) -> Path:
    """Write ``result`` (a ``cycles:*`` Material or MapSet) as a .blend at ``out``; returns its path.
    ``renderer``: the :class:`~matremap.renderers.cycles.client.WorkerClient` (e.g. a
    :class:`~matremap.renderers.cycles.probe.CyclesRenderer`) whose worker writes (default: the one this
    process shares, :func:`~matremap.renderers.cycles.client.shared_client`)."""
    from matremap.renderers.cycles.client import shared_client

    p = check_output(out, force, (".blend",))
    r = shared_client(renderer)  # raises with the set-up instructions when there is no bpy venv
    with atomic_output(p) as tmp:
        request = write_request(tmp, result, source, p)
        r.call(request)
        if not os.path.getsize(tmp):
            raise MatremapError(f"Blender wrote nothing to {tmp}")
    return p


__all__ = ["GEOMETRY", "MODELS", "write", "write_request"]
