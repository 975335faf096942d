"""Blender .blend files: a converted material written as Cycles nodes on a sphere by Blender itself, and the
uniform Principled BSDF materials of a .blend read (through the same bpy worker).

``read(path, material=None)`` takes one material whose surface is a single Principled BSDF (Blender 5.0's
sockets, the names ``cycles:principled`` uses) with none of its modelled sockets linked (a textured .blend
material is refused in one line): Base Color, Metallic, Roughness, IOR, Specular IOR Level, Specular Tint,
Coat Weight / Roughness / IOR / Tint, Sheen Weight / Roughness / Tint, Transmission Weight and the node's
distribution become a ``cycles:principled`` asset; Emission Color x Emission Strength and Alpha are carried (as
emission and a blended opacity). What the model has no parameter for is noted where it is not at its off value
(Subsurface, Anisotropic, Thin Film, Diffuse Roughness). A Transmission Weight is read like the rest: a glass is
fitted on the transmission probe (``matremap.transmissive``).

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
from matremap.formats.asset import CarriedInput, MaterialAsset
from matremap.formats.common import pick_material

#: models this writer knows the Blender nodes of
MODELS = ("cycles:principled", "cycles:glossy", "cycles:diffuse")
#: Principled BSDF sockets no cycles:principled parameter stands for, and the value at which each is off
UNMODELLED = {
    "Subsurface Weight": 0.0,
    "Anisotropic": 0.0,
    "Thin Film Thickness": 0.0,
    "Diffuse Roughness": 0.0,
}
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


def _inspect(path: Path) -> dict[str, Any]:
    """What the bpy worker sees in the .blend ``path`` (its ``inspect_blend`` request)."""
    from matremap.renderers.cycles.client import shared_client

    if not path.is_file():
        raise MatremapError(f"{path} not found")
    info: dict[str, Any] = shared_client().call({"op": "inspect_blend", "path": str(path.resolve())})
    return info


def material_names(path: str | os.PathLike) -> list[str]:
    """The names of the node materials of a .blend, in Blender's order."""
    return list(_inspect(Path(path))["materials"])


def read(path: str | os.PathLike, material: str | int | None = None, *, confinement: Any = None) -> MaterialAsset:
    """One uniform Principled BSDF material of a .blend as a ``cycles:principled``
    :class:`~matremap.formats.asset.MaterialAsset` (see the module docstring)."""
    p = Path(path)
    materials = _inspect(p)["materials"]
    if not materials:
        raise MatremapError(f"{p} holds no node material; matremap reads Principled BSDF materials of a .blend")
    names = list(materials)
    name = names[pick_material(p, names, material, "material")]
    where = f"{p}: material {name!r}"
    node = _surface_principled(materials[name], where)
    spec = get_model("cycles:principled")
    inputs, linked = node["inputs"], [s for s in spec.param_names if s not in node["inputs"]]
    if linked:
        raise MatremapError(
            f"{where}: {', '.join(linked)} linked to other nodes (a textured material); matremap reads uniform "
            f".blend materials only: bake the textures or give the sockets values"
        )
    constants: dict[str, Any] = {n: _socket_value(inputs[n], spec.param(n).channels) for n in spec.param_names}
    constants["distribution"] = str(node.get("distribution", "MULTI_GGX")).lower()
    unmodelled = [
        f"{k}={_socket_value(inputs[k], 1):g}"
        for k, off in UNMODELLED.items()
        if k in inputs and _socket_value(inputs[k], 1) != off
    ]
    notes = [f"{d}: cycles:principled has no such parameter; left out" for d in unmodelled]
    lost: list[str] = []
    carried = {}
    strength = _socket_value(inputs.get("Emission Strength", 0.0), 1)
    colour = np.asarray(_socket_value(inputs.get("Emission Color", [1.0, 1.0, 1.0]), 3), dtype=float)
    if strength > 0 and np.any(colour > 0):
        carried["emission"] = CarriedInput(tuple(float(x) for x in colour * strength))
    alpha = _socket_value(inputs.get("Alpha", 1.0), 1)
    if alpha < 1.0:
        carried["opacity"] = CarriedInput(float(alpha), None, {"mode": "blend"})
    try:
        Material.create(spec.id, constants)
    except MatremapError as e:
        raise MatremapError(f"{where}: {e}") from None
    return MaterialAsset(
        path=p,
        format="blend",
        name=name,
        model=spec.id,
        constants=constants,
        notes=notes,
        lost=lost,
        carried=carried,
        dropped=dropped_sockets(inputs),
    )


#: the sockets of :data:`UNMODELLED` that change the look (the gate's ``dropped`` check) -> the socket they need
#: above 0 to show (None: none); a Diffuse Roughness (Oren-Nayar) is left out with a note only
DROPPED = {"Subsurface Weight": None, "Anisotropic": "Roughness", "Thin Film Thickness": None}


def dropped_sockets(inputs: dict[str, Any]) -> list[str]:
    """The Principled BSDF's sockets of :data:`DROPPED` that are on (above 0, and their roughness too), as
    ``name=value``."""
    out = []
    for k, needs in DROPPED.items():
        if k in inputs and _socket_value(inputs[k], 1) > UNMODELLED[k]:
            if needs is None or _socket_value(inputs.get(needs, 0.5), 1) > 0.0:
                out.append(f"{k}={_socket_value(inputs[k], 1):g}")
    return out


def _surface_principled(mat: dict[str, Any], where: str) -> dict[str, Any]:
    """The Principled BSDF node linked into a Material Output's Surface (refused otherwise)."""
    nodes, links = mat["nodes"], mat["links"]
    into = [lk for lk in links if nodes.get(lk[2], {}).get("type") == "ShaderNodeOutputMaterial" and lk[3] == "Surface"]
    if not into:
        raise MatremapError(f"{where} has no surface shader linked into its Material Output")
    node = nodes[into[0][0]]
    if node.get("type") != "ShaderNodeBsdfPrincipled":
        raise MatremapError(
            f"{where}: its surface is a {node.get('type')}; matremap reads .blend materials whose surface is one "
            f"Principled BSDF"
        )
    return dict(node)


def _socket_value(v: Any, channels: int) -> Any:
    """A socket's value as a parameter value: a float, or RGB (a colour socket's alpha dropped)."""
    a = np.atleast_1d(np.asarray(v, dtype=float))
    if channels == 3:
        return [float(x) for x in (a[:3] if a.size >= 3 else np.repeat(a[:1], 3))]
    return float(a[0])


__all__ = ["GEOMETRY", "MODELS", "material_names", "read", "write", "write_request"]
