"""USD stages (.usda, .usdc, .usdz, .usd) in and out, as UsdPreviewSurface materials.

Sources: the UsdPreviewSurface Specification 2.5 (OpenUSD ``docs/spec_usdpreviewsurface.rst``: the
``UsdPreviewSurface``, ``UsdUVTexture``, ``UsdPrimvarReader_float2`` and ``UsdTransform2d`` nodes, their inputs
and fallbacks, "Texture Coordinate Orientation in USD"), the UsdShade schemas (``UsdShadeMaterial``,
``ComputeSurfaceSource``, ``UsdShadeMaterialBindingAPI``) and the usdz specification (an uncompressed zip whose
first file is the root layer), through the ``pxr`` modules of ``usd-core`` (imported when a USD file is used).

**Reading.** Every ``UsdShade.Material`` of the composed stage is a material, named by its prim path (a
unique prim name also picks it). Its universal surface (else its ``mtlx`` one) is read:

* ``UsdPreviewSurface`` -> ``usd:preview_surface``: diffuseColor, metallic, roughness, specularColor, ior,
  clearcoat, clearcoatRoughness and the option useSpecularWorkflow; ``opacity`` / ``opacityThreshold``
  (``carried["opacity"]``, mode mask when the threshold is above 0), ``emissiveColor`` (``carried["emission"]``),
  ``occlusion`` (``carried["occlusion"]``), ``normal`` (the asset's normal map, encoded as n = 2 c - 1; any
  other scale/bias is baked into that encoding). A specular-workflow material whose specularColor is one grey
  value s and without clearcoat is the metalness workflow's dielectric with ior = (1 + sqrt s)/(1 - sqrt s)
  (both give F0 = s, F90 = 1, the same diffuse weight): it is read so, with a note; a uniform specular-workflow
  material is kept as it is, and a textured one with a coloured or textured specularColor is refused (matremap
  remaps maps in the metalness workflow).
* the MaterialX glTF PBR node (``info:id = "ND_gltf_pbr_surfaceshader"``) -> ``gltf:metal-rough``, through the
  MaterialX reader's input table (:data:`matremap.formats.materialx.SHADERS`); Standard Surface and OpenPBR
  shaders in USD are refused in one line (read them from their ``.mtlx`` document).

A ``UsdUVTexture`` gives a texture: its ``file`` (relative to the layer that authored it, confined to the
stage's folder or an allowed one by :mod:`matremap.formats.confine`; inside a ``.usdz`` the member is
extracted to matremap's private cache), ``sourceColorSpace`` (``sRGB``, ``raw``, or ``auto``: sRGB for 8-bit
images of 3 or 4 channels, as the spec says), the output used (r, g, b, a, rgb; a one-channel image repeats
its value, a two-channel one puts its second in a), ``scale`` / ``bias`` (output = texture x scale + bias),
``st`` from a ``UsdPrimvarReader_float2`` through any chain of ``UsdTransform2d`` (in x scale x rotate +
translation, rotation in degrees), baked with :mod:`matremap.formats.bake` in USD's lower-left ``st`` origin
with ``wrapS`` / ``wrapT`` (``black`` is a border of 0; ``useMetadata`` falls back to black, as the spec says).
A ``UsdUVTexture`` whose ``st`` is not connected reads its image at its ``st`` value (the spec's fallback (0, 0))
everywhere: a uniform value. A ``UsdPrimvarReader_float`` / ``_float3`` (a ``displayColor`` read into diffuseColor)
gives the primvar's value on the geometry bound to the material when it is one value there, else its ``fallback``.
A stage without materials lists its gprims whose ``displayColor`` is one colour, each read as the renderer's
fallback surface (a UsdPreviewSurface at its defaults with that diffuseColor).

The file is untrusted: before USD composes it, every layer it names (sublayers, references, payloads) is
checked recursively to lie in its folder or an allowed one and to exist there (so USD's search paths never
look elsewhere), ``://`` asset paths are refused, and a ``.usdz`` must name no member outside itself.

**Writing.** A ``usd:preview_surface`` Material or MapSet is written as a stage with a ``UsdShade.Material``
under ``/Root/Materials``, a ``UsdPreviewSurface`` shader, one ``UsdUVTexture`` per map (sRGB colour maps
tagged ``sRGB``, everything else ``raw``) fed by a ``UsdPrimvarReader_float2`` of ``st``, a normal map
(scale 2, bias -1), the source's carried opacity / emission / occlusion, bound to a UV sphere mesh with ``st``
primvars; a ``gltf:metal-rough`` one as a UsdShade shader with ``info:id = "ND_gltf_pbr_surfaceshader"`` and
the gltf_pbr inputs (maps through ``ND_image_*`` nodes). ``.usdz`` is packaged with ``UsdUtils``.
:func:`write_all` writes every converted material of a file into one stage: a flattened copy of a USD source
with those materials' surfaces replaced (every prim, mesh and binding kept: bound materials keep their prim
paths) or a fresh stage with every material under ``/Root/Materials``.
"""

from __future__ import annotations

import hashlib
import math
import os
import posixpath
import re
import tempfile
import zipfile
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from matremap.core.atomic import AtomicFiles, temp_prefix
from matremap.core.imageio import check_output
from matremap.core.material import Material
from matremap.dialects import get_model
from matremap.dialects.usd import specular_workflow
from matremap.errors import MatremapError, not_a_file
from matremap.formats.asset import CarriedInput, MaterialAsset, TextureRef
from matremap.formats.bake import (
    BAND_TEXELS,
    UVTransform,
    bake_file,
    resampled_note,
    rotate,
    scale,
    shared_size,
    texels_needed,
    translate,
)
from matremap.formats.common import ResultParts, pick_material, place_map, result_parts
from matremap.formats.confine import Confinement, resolve_reference

FORMAT = "usd"
MODEL = "usd:preview_surface"
GLTF = "gltf:metal-rough"
SUFFIXES = (".usda", ".usdc", ".usdz", ".usd")
INSTALL_HINT = "reading and writing USD needs usd-core: pip install 'matremap[usd]'"
PREVIEW = "UsdPreviewSurface"
#: MaterialX surface shader node ids -> the node category of the MaterialX reader's tables
MATERIALX_IDS = {
    "ND_gltf_pbr_surfaceshader": "gltf_pbr",
    "ND_standard_surface_surfaceshader": "standard_surface",
    "ND_open_pbr_surface_surfaceshader": "open_pbr_surface",
}
#: the UsdPreviewSurface inputs that are parameters of usd:preview_surface
PARAMS = ("diffuseColor", "metallic", "roughness", "specularColor", "ior", "clearcoat", "clearcoatRoughness")
#: the UsdPreviewSurface inputs carried unchanged, and the others the spec defines
CARRIED = ("opacity", "opacityThreshold", "emissiveColor", "occlusion", "normal", "displacement")
WRAPS = {"repeat": "repeat", "mirror": "mirror", "clamp": "clamp", "black": "border", "useMetadata": "border"}
#: the most layers a stage may compose (sublayers, references, payloads)
MAX_LAYERS = 256


def _pxr() -> Any:
    """The pxr modules matremap uses, as one namespace (imported on first use)."""
    from types import SimpleNamespace

    try:
        from pxr import Ar, Gf, Sdf, Usd, UsdGeom, UsdShade, UsdUtils, Vt  # type: ignore[import-untyped]
    except ImportError as e:
        raise MatremapError(f"{INSTALL_HINT} ({e})") from None
    return SimpleNamespace(Ar=Ar, Gf=Gf, Sdf=Sdf, Usd=Usd, UsdGeom=UsdGeom, UsdShade=UsdShade, UsdUtils=UsdUtils, Vt=Vt)


# ---------------------------------------------------------------------------------------------
# opening a stage, confined


def _open_layer(pxr: Any, path: Path, where: str) -> Any:
    try:
        layer = pxr.Sdf.Layer.FindOrOpen(str(path))
    except Exception as e:  # pxr raises Tf.ErrorException
        raise MatremapError(f"{where}: {path.name} is not a USD layer ({_first_line(e)})") from None
    if layer is None:
        raise MatremapError(f"{where}: {path.name} is not a USD layer USD can open")
    return layer


def _first_line(e: Exception) -> str:
    """The last line of a pxr error (its text may hold the file's own bytes, which need not be UTF-8: pxr's
    ``Tf.ErrorException.__str__`` then raises UnicodeDecodeError)."""
    try:
        text = str(e).strip().splitlines()
    except UnicodeError:
        return "its text is not valid UTF-8"
    return re.sub(r"^Error in '[^']*' at line \d+ in file \S+ : ", "", text[-1] if text else type(e).__name__)[:200]


def _check_layers(pxr: Any, p: Path, confinement: Confinement | None) -> None:
    """Every layer ``p`` composes, recursively: inside the stage's folder (or an allowed one) and existing
    there; a ``.usdz`` names only its own members."""
    seen: set[Path] = set()
    todo = [p.resolve()]
    while todo:
        f = todo.pop()
        if f in seen:
            continue
        seen.add(f)
        if len(seen) > MAX_LAYERS:
            raise MatremapError(f"{p}: composes more than {MAX_LAYERS} layers; flatten it first (usdcat --flatten)")
        layer = _open_layer(pxr, f, str(p))
        package = f.suffix.lower() == ".usdz"
        clips, template_folders = _clip_assets(pxr, layer)
        for folder in template_folders:  # the clips' files need not exist yet; their folder must be inside
            if package:
                _package_member(p, folder, "")
            else:
                resolve_reference(folder, f.parent, f"{p}: layer {f.name} has value clips in", confinement)
        for dep in [*layer.GetCompositionAssetDependencies(), *clips]:
            if "://" in dep or re.match(r"^[A-Za-z][A-Za-z0-9+.-]*:(?![\\/])", dep):
                raise MatremapError(f"{p}: layer {f.name} composes {dep!r}, which is not a local file")
            if package:
                _package_member(p, dep, "")
                continue
            target = resolve_reference(dep, f.parent, f"{p}: layer {f.name} composes", confinement)
            if not target.is_file():
                raise MatremapError(f"{p}: layer {f.name} composes {dep!r}, not found beside it")
            if target.suffix.lower() in SUFFIXES:
                todo.append(target)


#: the metadata of value clips naming layers (in a ``clips`` set, and the older prim metadata): USD opens
#: those layers when it reads or flattens time samples, yet they are not composition arcs
CLIP_KEYS = {"assetPaths": "clipAssetPaths", "manifestAssetPath": "clipManifestAssetPath"}
CLIP_TEMPLATE_KEYS = {"templateAssetPath": "clipTemplateAssetPath"}


def _clip_assets(pxr: Any, layer: Any) -> tuple[list[str], list[str]]:
    """The layers a layer's value clips name, and the folders its clip templates (``clip.#.usd``) stand for."""
    files: list[str] = []
    templates: list[str] = []

    def paths(value: Any) -> list[str]:
        items = [value] if isinstance(value, pxr.Sdf.AssetPath | str) else list(value or [])
        return [v.path if isinstance(v, pxr.Sdf.AssetPath) else str(v) for v in items]

    def visit(path: Any) -> None:
        spec = layer.GetObjectAtPath(path)
        if not isinstance(spec, pxr.Sdf.PrimSpec):
            return
        sets = [v for v in dict(spec.GetInfo("clips")).values() if isinstance(v, dict)] if spec.HasInfo("clips") else []
        for keys, into in ((CLIP_KEYS, files), (CLIP_TEMPLATE_KEYS, templates)):
            for key, legacy in keys.items():
                values = [c[key] for c in sets if key in c] + ([spec.GetInfo(legacy)] if spec.HasInfo(legacy) else [])
                into.extend(p for v in values for p in paths(v) if p)

    layer.Traverse(pxr.Sdf.Path.absoluteRootPath, visit)
    return files, [posixpath.dirname(t) or "." for t in templates]


def _open_stage(p: Path, confinement: Confinement | None) -> Any:
    pxr = _pxr()
    if not p.is_file():
        raise MatremapError(f"{p} not found")
    if p.suffix.lower() == ".usdz" and not zipfile.is_zipfile(p):
        raise MatremapError(f"{p} is not a usdz package (not a zip file)")
    _check_layers(pxr, p, confinement)
    try:
        stage = pxr.Usd.Stage.Open(str(p.resolve()), pxr.Usd.Stage.LoadAll)
    except Exception as e:
        raise MatremapError(f"{p} is not a USD stage USD can open ({_first_line(e)})") from None
    if stage is None:
        raise MatremapError(f"{p} is not a USD stage USD can open")
    return stage


def _package_member(p: Path, ref: str, inner_dir: str) -> str:
    """The member of usdz ``p`` that ``ref`` (relative to ``inner_dir`` inside it) names; refused outside it."""
    if ref.startswith("/") or "\\" in ref or re.match(r"^[A-Za-z]:", ref):
        raise MatremapError(f"{p}: {ref!r} is not a path inside the package; a usdz names its own files only")
    member = posixpath.normpath(posixpath.join(inner_dir, ref.removeprefix("./")))
    if member.startswith("..") or member.startswith("/"):
        raise MatremapError(f"{p}: {ref!r} points outside the package; a usdz names its own files only")
    return member


def _extract(package: Path, member: str) -> Path:
    """A member of a usdz package, extracted once to matremap's private cache (named by its digest)."""
    from matremap.core.diskcache import private_cache_dir
    from matremap.core.imageio import atomic_output

    try:
        with zipfile.ZipFile(package) as z:
            info = z.getinfo(member)
            if info.compress_type != zipfile.ZIP_STORED:
                raise MatremapError(f"{package}: member {member} is compressed; a usdz stores its files uncompressed")
            data = z.read(info)
    except KeyError:
        raise MatremapError(f"{package}: texture {member} not found in the package") from None
    except (zipfile.BadZipFile, OSError) as e:
        raise MatremapError(f"{package}: cannot read member {member} ({e})") from None
    folder = private_cache_dir("usdz-files", hashlib.sha256(package.read_bytes()).hexdigest()[:20])
    digest = hashlib.sha256(data).hexdigest()[:16]
    suffix = Path(member).suffix.lower()
    f = folder / f"{re.sub(r'[^A-Za-z0-9_-]', '_', Path(member).stem)}-{digest}{suffix}"
    if not (f.is_file() and not f.is_symlink() and hashlib.sha256(f.read_bytes()).hexdigest()[:16] == digest):
        with atomic_output(f) as tmp, open(tmp, "wb") as out:
            out.write(data)
    return f


# ---------------------------------------------------------------------------------------------
# materials of a stage


@dataclass
class UsdSource:
    """What a USD reader keeps for writers: the stage's file and the material's prim path."""

    path: Path
    prim_path: str


def _materials(pxr: Any, stage: Any) -> list[Any]:
    return [pxr.UsdShade.Material(p) for p in stage.Traverse() if p.IsA(pxr.UsdShade.Material)]


def material_names(path: str | os.PathLike) -> list[str]:
    """The prim paths of a stage's materials, in the order :func:`read` indexes them (a stage without materials:
    its gprims drawn by their displayColor, :func:`_display_colour_prims`)."""
    pxr = _pxr()
    stage = _open_stage(Path(path), None)
    found = _materials(pxr, stage)
    if not found:
        return [str(prim.GetPath()) for prim, _ in _display_colour_prims(pxr, stage)]
    return [str(m.GetPath()) for m in found]


def _display_colour_prims(pxr: Any, stage: Any) -> list[tuple[Any, list[float]]]:
    """The gprims of a stage without materials whose ``primvars:displayColor`` is one colour (``constant``, or every
    element equal), with that colour. UsdGeomGprim's ``displayColor`` is "the color to use for display ... even in
    the absence of any specified shader": renderers draw such a gprim with their fallback surface, a
    UsdPreviewSurface at its defaults whose diffuseColor is the displayColor (usdImaging's fallback material)."""
    out = []
    for prim in stage.Traverse():
        if not prim.IsA(pxr.UsdGeom.Gprim):
            continue
        pv = pxr.UsdGeom.Gprim(prim).GetDisplayColorPrimvar()
        if not pv or not pv.HasValue():
            continue
        flat = np.asarray(pv.ComputeFlattened(), dtype=np.float64).reshape(-1, 3)
        if flat.size and np.all(np.isfinite(flat)) and np.ptp(flat, axis=0).max() <= 1e-6:
            out.append((prim, [float(x) for x in flat[0]]))
    return out


def _display_colour_asset(pxr: Any, p: Path, stage: Any, material: str | int | None) -> MaterialAsset:
    """The material a renderer draws a stage without materials with (:func:`_display_colour_prims`)."""
    found = _display_colour_prims(pxr, stage)
    if not found:
        raise MatremapError(
            f"{p} holds no UsdShade Material and no gprim with a uniform displayColor; matremap reads "
            "UsdPreviewSurface materials"
        )
    names = [str(prim.GetPath()) for prim, _ in found]
    index = _pick(p, names, material)
    colour = found[index][1]
    notes = [
        f"{names[index]} has no material: read as the renderer's fallback surface, a UsdPreviewSurface at its "
        f"defaults with diffuseColor = its displayColor {[round(c, 4) for c in colour]}"
    ]
    spec = get_model(MODEL)
    constants: dict[str, Any] = {"diffuseColor": colour, "useSpecularWorkflow": "0"}
    _clamp(_Ctx(pxr, p, names[index], None, notes), spec, constants)
    asset = MaterialAsset(path=p, format=FORMAT, name=names[index], model=MODEL, constants=constants, notes=notes)
    asset.index = index  # no material prim to replace: a USD output is a new stage
    return asset


def _pick(p: Path, names: list[str], material: str | int | None) -> int:
    """A material by index, prim path or (unique) prim name."""
    if isinstance(material, str) and material not in names:
        short = [n for n in names if n.rsplit("/", 1)[-1] == material]
        if len(short) == 1:
            material = short[0]
    return pick_material(p, names, material, "material")


def _surface(pxr: Any, material: Any) -> Any:
    """The surface shader of a material (universal render context first, then mtlx), or None."""
    for context in ("", "mtlx"):
        shader, _, _ = material.ComputeSurfaceSource(context)
        if shader and shader.GetPrim().IsValid():
            return shader
    return None


def read(
    path: str | os.PathLike, material: str | int | None = None, *, confinement: Confinement | None = None
) -> MaterialAsset:
    """One material of a USD stage as a :class:`MaterialAsset` (``usd:preview_surface``, or ``gltf:metal-rough``
    for a MaterialX glTF PBR shader). ``material``: a prim path, a unique prim name or an index (the first
    by default). Files it names must lie in its folder or a folder ``confinement`` allows."""
    pxr = _pxr()
    p = Path(path)
    stage = _open_stage(p, confinement)
    found = _materials(pxr, stage)
    if not found:
        return _display_colour_asset(pxr, p, stage, material)
    names = [str(m.GetPath()) for m in found]
    index = _pick(p, names, material)
    shader = _surface(pxr, found[index])
    if shader is None:
        raise MatremapError(f"{p}: material {names[index]} has no surface shader connected to outputs:surface")
    ctx = _Ctx(pxr, p, names[index], confinement, stage=stage, material=found[index])
    shader_id = str(shader.GetIdAttr().Get() or "")
    if shader_id == PREVIEW:
        asset = _preview_asset(ctx, shader)
    elif shader_id == "ND_gltf_pbr_surfaceshader":
        asset = _gltf_pbr_asset(ctx, shader)
    elif shader_id in MATERIALX_IDS:
        raise MatremapError(
            f"{p}: material {names[index]} is a MaterialX {MATERIALX_IDS[shader_id]} shader ({shader_id}); matremap "
            f"reads UsdPreviewSurface and ND_gltf_pbr_surfaceshader from USD: convert its .mtlx document instead"
        )
    else:
        raise MatremapError(
            f"{p}: material {names[index]}'s surface is a {shader_id or 'shader without info:id'}; matremap reads "
            f"UsdPreviewSurface (and ND_gltf_pbr_surfaceshader) materials"
        )
    asset.document = UsdSource(p, names[index])
    asset.index = index
    if asset.textures and len(ctx.primvars) <= 1:  # the texels its meshes show (formats/usd_coverage.py)
        from matremap.formats.usd_coverage import material_coverage

        try:
            asset.coverage = material_coverage(pxr, stage, found[index], next(iter(ctx.primvars), "st"))
        except (RuntimeError, ValueError, TypeError):  # meshes USD cannot answer for: every texel counts
            asset.coverage = None
    return asset


@dataclass
class _Ctx:
    pxr: Any
    path: Path
    name: str
    confinement: Confinement | None
    notes: list[str] = field(default_factory=list)
    primvars: set[str] = field(default_factory=set)
    stage: Any = None
    material: Any = None

    def where(self, what: str) -> str:
        return f"{self.path}: material {self.name}: {what}"


def _value_source(ctx: _Ctx, shader: Any, name: str) -> tuple[Any, Any]:
    """(value, None) of an input's value (or None when unauthored), or (None, (shader, output name)) of the
    shader output it is connected to (through material interface inputs)."""
    inp = shader.GetInput(name)
    if not inp:
        return None, None
    attrs = inp.GetValueProducingAttributes()
    if not attrs:
        return None, None
    a = attrs[0]
    base, kind = ctx.pxr.UsdShade.Utils.GetBaseNameAndType(a.GetName())
    if kind == ctx.pxr.UsdShade.AttributeType.Output:
        return None, (ctx.pxr.UsdShade.Shader(a.GetPrim()), str(base))
    return (a.Get() if a.HasAuthoredValue() or a.Get() is not None else None), None


def _numbers(ctx: _Ctx, value: Any, name: str, size: int) -> list[float]:
    try:
        nums = [float(x) for x in (value if hasattr(value, "__len__") else [value])]
    except (TypeError, ValueError):
        raise MatremapError(ctx.where(f"input {name} = {value!r} is not a number")) from None
    if len(nums) != size and not (size == 3 and len(nums) == 1):
        raise MatremapError(ctx.where(f"input {name} has {len(nums)} component(s), not {size}"))
    if not all(math.isfinite(x) for x in nums):
        raise MatremapError(ctx.where(f"input {name} = {value!r} is not finite"))
    return nums * 3 if size == 3 and len(nums) == 1 else nums


# ---------------------------------------------------------------------------------------------
# textures


@dataclass
class _Texture:
    """A UsdUVTexture output as read: a TextureRef, or a constant (the alpha of an image without one)."""

    ref: TextureRef | None = None
    constant: list[float] | None = None
    primvar: str = "st"
    #: the map size it keeps its texels at (height, width), and the same texture baked at another size
    size: tuple[int, int] | None = None
    at_size: Callable[[tuple[int, int]], TextureRef] | None = None


def _texture_file(ctx: _Ctx, node: Any) -> tuple[Path, bool, str]:
    """(the file, whether it is matremap's extracted copy, the path as written) of a texture node's file."""
    inp = node.GetInput("file")
    attrs = inp.GetValueProducingAttributes() if inp else []
    value = attrs[0].Get() if attrs else None
    written = value.path if value is not None else ""
    if not written:
        raise MatremapError(ctx.where(f"texture {node.GetPath()} has no file; set its inputs:file"))
    stack = attrs[0].GetPropertyStack(ctx.pxr.Usd.TimeCode.Default())
    layer = stack[0].layer if stack else None
    if "://" in written:
        raise MatremapError(ctx.where(f"texture file {written!r} is not a local file"))
    if "<UDIM>" in written:
        raise MatremapError(ctx.where(f"texture {written!r} is a UDIM set; matremap reads one image per texture"))
    real = layer.realPath if layer is not None else str(ctx.path.resolve())
    package, inner = _split_package(ctx.pxr, real)
    if package is not None:
        member = _package_member(Path(package), written, posixpath.dirname(inner))
        return _extract(Path(package), member), True, written
    anchor = Path(real).parent
    f = resolve_reference(written, anchor, f"{ctx.path}: texture file", ctx.confinement)
    if not f.is_file() and f.exists():
        raise MatremapError(ctx.where(not_a_file(f, f"texture {written!r}")))
    if not f.is_file():
        raise MatremapError(ctx.where(f"texture {written!r} not found at {f}; put it beside the layer"))
    return f, False, written


def _split_package(pxr: Any, real: str) -> tuple[str | None, str]:
    """(the usdz file, the layer's path inside it) of a layer inside a package, else (None, "")."""
    if pxr.Ar.IsPackageRelativePath(real):
        outer, inner = pxr.Ar.SplitPackageRelativePathOuter(real)
        return outer, inner
    if real.lower().endswith(".usdz"):
        return real, ""
    return None, ""


def _token(ctx: _Ctx, node: Any, name: str, default: str) -> str:
    value, conn = _value_source(ctx, node, name)
    if conn is not None:
        raise MatremapError(ctx.where(f"{node.GetPath()}.{name} is connected; USD allows it a value only"))
    return str(value) if value not in (None, "") else default


def _colorspace(ctx: _Ctx, node: Any, f: Path) -> str:
    """sRGB or raw, as sourceColorSpace says (``auto``: 8-bit images of 3 or 4 channels are sRGB)."""
    from matremap.svbrdf.textures import image_info

    cs = _token(ctx, node, "sourceColorSpace", "")
    if not cs:  # the attribute before spec 2.3
        legacy = _token(ctx, node, "isSRGB", "auto").lower()
        cs = {"true": "sRGB", "1": "sRGB", "false": "raw", "0": "raw"}.get(legacy, "auto")
    if cs == "auto":
        info = image_info(f, "linear")
        return "srgb" if info.pixel_type == "uint8" and info.channels in (3, 4) else "linear"
    if cs not in ("raw", "sRGB"):
        raise MatremapError(ctx.where(f"{node.GetPath()} has sourceColorSpace {cs!r}; USD defines raw, sRGB, auto"))
    return "srgb" if cs == "sRGB" else "linear"


def _st_transform(ctx: _Ctx, node: Any) -> tuple[np.ndarray, str]:
    """The matrix from shaded st to looked-up st of a texture's ``st`` input (UsdTransform2d chain down to a
    UsdPrimvarReader_float2), and the primvar read."""
    matrix = np.eye(3)
    current, name = node, "st"
    for _ in range(32):
        value, conn = _value_source(ctx, current, name)
        if conn is None:
            raise MatremapError(
                ctx.where(f"{current.GetPath()}.{name} is not connected to a UsdPrimvarReader_float2; connect st")
            )
        up, _ = conn
        up_id = str(up.GetIdAttr().Get() or "")
        if up_id == "UsdPrimvarReader_float2":
            varname = _token(ctx, up, "varname", "st")
            return matrix, varname
        if up_id != "UsdTransform2d":
            raise MatremapError(
                ctx.where(
                    f"st comes from a {up_id or 'node'} ({up.GetPath()}); matremap reads "
                    "UsdPrimvarReader_float2 and UsdTransform2d"
                )
            )
        rot = _numbers(ctx, _value_source(ctx, up, "rotation")[0] or 0.0, "rotation", 1)[0]
        sc = _numbers(ctx, _value_source(ctx, up, "scale")[0] or (1.0, 1.0), "scale", 2)
        tr = _numbers(ctx, _value_source(ctx, up, "translation")[0] or (0.0, 0.0), "translation", 2)
        # result = in * scale * rotate + translation (spec, Transform2d): applied after the ones above it
        matrix = matrix @ translate(*tr) @ rotate(math.radians(rot)) @ scale(*sc)
        current, name = up, "in"
    raise MatremapError(ctx.where("st passes through more than 32 UsdTransform2d nodes"))


def _uv_texture(ctx: _Ctx, node: Any, output: str, param: str) -> _Texture:
    """A UsdUVTexture's output as read (see the module docstring)."""
    from matremap.svbrdf.textures import image_info

    f, extracted, written = _texture_file(ctx, node)
    try:
        header = image_info(f, "linear")
        channels = header.channels
    except MatremapError as e:
        why = str(e).split(": ", 1)[-1] if extracted else str(e)
        raise MatremapError(ctx.where(f"texture {written!r}: {why}")) from None
    colorspace = _colorspace(ctx, node, f)
    comps = {"r": [0], "g": [1], "b": [2], "a": [3], "rgb": [0, 1, 2]}.get(output)
    if comps is None:
        raise MatremapError(ctx.where(f"{param} takes output {output!r} of {node.GetPath()}; use r, g, b, a or rgb"))
    sc = np.array(_numbers(ctx, _value_source(ctx, node, "scale")[0] or (1.0,) * 4, "scale", 4))[comps]
    bias = np.array(_numbers(ctx, _value_source(ctx, node, "bias")[0] or (0.0,) * 4, "bias", 4))[comps]
    st, st_conn = _value_source(ctx, node, "st")
    if st_conn is None:
        matrix, primvar = np.eye(3), ""
    else:
        matrix, primvar = _st_transform(ctx, node)
        ctx.primvars.add(primvar)
    if output == "a" and channels not in (2, 4):  # the spec's a = 1 of images without alpha
        return _Texture(constant=[float(sc[0] + bias[0])], primvar=primvar)
    picked = tuple(c if channels >= 3 else (1 if c == 3 else 0) for c in comps)
    if channels >= 3 and output == "a":
        picked = (channels - 1,)
    wrap = tuple(WRAPS.get(_token(ctx, node, w, "useMetadata"), "") for w in ("wrapS", "wrapT"))
    if "" in wrap:
        raise MatremapError(
            ctx.where(
                f"{node.GetPath()} has a wrap mode USD does not define (black, clamp, repeat, mirror, useMetadata)"
            )
        )
    if st_conn is None:
        at = _numbers(ctx, st if st is not None else (0.0, 0.0), "st", 2)
        value = _texel_at(f, colorspace, picked, at, (wrap[0], wrap[1])) * sc + bias
        ctx.notes.append(
            f"{param}: {node.GetPath()}.st is not connected, so every point reads the texture at its st "
            f"({at[0]:g}, {at[1]:g}) (the spec's fallback (0, 0) unless authored): the uniform value "
            f"{', '.join(f'{v:.4g}' for v in value)}"
        )
        return _Texture(constant=[float(v) for v in value])
    transform = UVTransform(matrix, "bottom-left", (wrap[0], wrap[1]), 0.0)
    size = texels_needed((header.height, header.width), matrix) if not transform.identity else None
    size = size or (header.height, header.width)

    def at_size(hw: tuple[int, int]) -> TextureRef:
        return TextureRef(f, None, "linear", 1.0, extracted, _baker(f, colorspace, picked, sc, bias, transform, hw))

    if transform.identity and np.all(bias == 0.0):
        factor: float | tuple[float, ...] = float(sc[0]) if len(set(sc.tolist())) == 1 else tuple(sc.tolist())
        return _Texture(
            TextureRef(f, picked, colorspace, factor, extracted), primvar=primvar, size=size, at_size=at_size
        )
    return _Texture(at_size(size), primvar=primvar, size=size, at_size=at_size)


def _texel_at(f: Path, colorspace: str, picked: tuple[int, ...], st: list[float], wrap: tuple[str, str]) -> np.ndarray:
    """The ``picked`` channels of image ``f`` (decoded to linear) at the one texture coordinate ``st``: USD's
    ``st`` has its origin at the image's lower left, sampled bilinearly with the wrap modes (UsdUVTexture)."""
    from matremap.formats.bake import sample
    from matremap.svbrdf.textures import read_image

    image, _ = read_image(f, colorspace)
    image = np.atleast_3d(image)[..., list(picked)]
    value = sample(image, np.array([st[0]]), np.array([1.0 - st[1]]), wrap)
    return np.asarray(value, dtype=np.float64).reshape(-1)


def _baker(
    f: Path,
    colorspace: str,
    picked: tuple[int, ...],
    sc: np.ndarray,
    bias: np.ndarray,
    transform: UVTransform,
    size: tuple[int, int] | None = None,
) -> Callable[[], np.ndarray]:
    """What the renderer sees at each texel: the channels sampled through ``transform`` (bilinearly, at ``size``
    texels; the image's own size by default), x scale + bias."""

    def bake() -> np.ndarray:
        from matremap.svbrdf.textures import MapReader

        with MapReader(f, colorspace) as r:  # the file read in bands: memory is the map's, not the image's
            h, w = r.info.height, r.info.width
            if transform.identity and size in (None, (h, w)):
                image = np.empty((h, w, len(picked)), np.float32)
                rows = max(1, BAND_TEXELS // w)
                for y0 in range(0, h, rows):
                    image[y0 : y0 + rows] = r.read_rows(y0, min(h, y0 + rows))[..., list(picked)]
            else:
                image = bake_file(f, colorspace, transform, size, channels=list(picked))
        image *= sc.astype(np.float32)
        image += bias.astype(np.float32)
        return image

    return bake


def _connected_texture(ctx: _Ctx, conn: tuple[Any, str], param: str) -> _Texture:
    node, output = conn
    node_id = str(node.GetIdAttr().Get() or "")
    if node_id == "UsdUVTexture":
        return _uv_texture(ctx, node, output, param)
    if node_id in PRIMVAR_READERS:
        return _Texture(constant=_primvar_constant(ctx, node, PRIMVAR_READERS[node_id], param))
    raise MatremapError(
        ctx.where(
            f"{param} is driven by a {node_id or 'node without info:id'} ({node.GetPath()}); matremap reads "
            "UsdUVTexture textures there (bake the network into an image)"
        )
    )


#: UsdPrimvarReader node ids whose primvar is read as a uniform value -> its number of components
PRIMVAR_READERS = {"UsdPrimvarReader_float": 1, "UsdPrimvarReader_float3": 3}


def _bound_prims(ctx: _Ctx) -> list[Any]:
    """The geometry (gprims, geom subsets) whose bound material (full purpose) is the one read; a subset's
    primvars are its mesh's."""
    pxr, target = ctx.pxr, ctx.material.GetPath()
    found = []
    for prim in ctx.stage.Traverse():
        if not (prim.IsA(pxr.UsdGeom.Gprim) or prim.IsA(pxr.UsdGeom.Subset)):
            continue
        bound, _ = pxr.UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()
        if bound and bound.GetPath() == target:
            found.append(prim if prim.IsA(pxr.UsdGeom.Gprim) else prim.GetParent())
    return found


def _primvar_constant(ctx: _Ctx, node: Any, size: int, param: str) -> list[float]:
    """The value a ``UsdPrimvarReader_float`` / ``_float3`` gives ``param``: its ``varname`` primvar on the
    geometry bound to the material, when it is one value there (``constant`` interpolation, or every element
    equal: a ``displayColor`` colouring a whole mesh); its ``fallback`` input (default 0, UsdPreviewSurface
    spec, "Primvar Reader") when no bound geometry has the primvar. A primvar that varies over the surface, or
    differs between the bound meshes, is refused (bake it into a texture)."""
    varname = _token(ctx, node, "varname", "")
    if not varname:
        raise MatremapError(ctx.where(f"{node.GetPath()} has no varname; name the primvar it reads"))
    values: dict[tuple[float, ...], str] = {}
    for prim in _bound_prims(ctx):
        pv = ctx.pxr.UsdGeom.PrimvarsAPI(prim).FindPrimvarWithInheritance(varname)
        if not pv or not pv.HasValue():
            continue
        flat = np.asarray(pv.ComputeFlattened(), dtype=np.float64).reshape(-1, size)
        if flat.size == 0 or not np.all(np.isfinite(flat)):
            continue
        if np.ptp(flat, axis=0).max() > 1e-6:
            raise MatremapError(
                ctx.where(
                    f"{param} reads primvar {varname!r}, which varies over {prim.GetPath()} ({pv.GetInterpolation()} "
                    "interpolation); matremap reads a uniform one: bake it into a texture"
                )
            )
        values.setdefault(tuple(float(x) for x in flat[0]), str(prim.GetPath()))
    if len(values) > 1:
        where = ", ".join(f"{m} {list(v)}" for v, m in values.items())
        raise MatremapError(
            ctx.where(
                f"{param} reads primvar {varname!r}, which differs between the bound meshes ({where}); "
                "give each colour its own material"
            )
        )
    if values:
        ((value, mesh),) = values.items()
        ctx.notes.append(f"{param}: primvar {varname!r} of {mesh} is uniform there: read as {list(value)}")
        return list(value)
    fallback = _value_source(ctx, node, "fallback")[0]
    nums = _numbers(ctx, fallback, "fallback", size) if fallback is not None else [0.0] * size
    ctx.notes.append(f"{param}: no geometry bound to the material has primvar {varname!r}: its fallback {nums}")
    return nums


# ---------------------------------------------------------------------------------------------
# UsdPreviewSurface


def _preview_asset(ctx: _Ctx, shader: Any) -> MaterialAsset:
    spec = get_model(MODEL)
    constants: dict[str, Any] = {}
    textures: dict[str, TextureRef] = {}
    read: dict[str, _Texture] = {}
    for name in PARAMS:
        size = spec.param(name).channels
        value, conn = _value_source(ctx, shader, name)
        if conn is not None:
            tex = _connected_texture(ctx, conn, name)
            if tex.ref is not None:
                textures[name], read[name] = tex.ref, tex
            else:
                nums = tex.constant or [0.0]
                nums = nums * size if len(nums) == 1 else nums[:size]
                constants[name] = nums if size == 3 else nums[0]
        elif value is not None:
            nums = _numbers(ctx, value, name, size)
            constants[name] = nums if size == 3 else nums[0]
    textures = _at_one_size(ctx, textures, read)
    flag, conn = _value_source(ctx, shader, "useSpecularWorkflow")
    if conn is not None:
        raise MatremapError(ctx.where("useSpecularWorkflow is connected; USD allows it a value only"))
    constants["useSpecularWorkflow"] = "1" if flag is not None and int(flag) == 1 else "0"
    normal = _normal(ctx, shader)
    carried = _carried(ctx, shader)
    _note_others(ctx, shader)
    if len(ctx.primvars) > 1:
        ctx.notes.append(f"textures read from several primvars ({', '.join(sorted(ctx.primvars))}): laid on one UV set")
    specular_workflow(constants, textures, ctx.notes, f"{ctx.path}: material {ctx.name}")
    _clamp(ctx, spec, constants)
    uniform = {k: v for k, v in constants.items() if k not in textures}
    try:
        Material.create(MODEL, uniform)
    except MatremapError as e:
        raise MatremapError(ctx.where(str(e))) from None
    return MaterialAsset(
        path=ctx.path,
        format=FORMAT,
        name=ctx.name,
        model=MODEL,
        constants=constants,
        textures=textures,
        normal=normal,
        notes=ctx.notes,
        carried=carried,
    )


def _at_one_size(ctx: _Ctx, textures: dict[str, TextureRef], read: Mapping[str, _Texture]) -> dict[str, TextureRef]:
    """The textures at one size, as a map set needs them: the largest any of them keeps its texels at (a texture
    tiled 3 times asks for 3 times its size), capped at :data:`~matremap.formats.bake.MAX_SIDE` per side; one of
    another size is resampled there (bilinearly, with its transform and wrap: UsdUVTexture's default filter), with
    a note. USD gives each texture its own image (usd-wg's RoughnessTest: a 1280x1024 colour beside a 256x256
    Targa roughness)."""
    needs = [t.size for t in read.values() if t.size is not None]
    if not needs:
        return textures
    size = shared_size(needs)
    baked = any(ref.bake is not None for ref in textures.values())
    if len(set(needs)) == 1 and not (baked and size != needs[0]):  # a baked map is at most MAX_SIDE a side
        return textures
    out = dict(textures)
    resampled = []
    for name, tex in read.items():
        if tex.size != size and tex.at_size is not None:
            out[name] = tex.at_size(size)
            resampled.append(name)
    ctx.notes.append(resampled_note(resampled, size, needs))
    return out


def _clamp(ctx: _Ctx, spec: Any, constants: dict[str, Any]) -> None:
    """Clamp colours past the model's range (with a note); other values are checked by the model."""
    for k in ("diffuseColor", "specularColor"):
        if k in constants:
            lo, hi = spec.param(k).bounds
            arr = np.asarray(constants[k], dtype=float)
            if np.any(arr < lo) or np.any(arr > hi):
                constants[k] = np.clip(arr, lo, hi).tolist()
                ctx.notes.append(f"{k}={arr.tolist()} lies outside [{lo:g}, {hi:g}] and was clamped")


def _normal(ctx: _Ctx, shader: Any) -> TextureRef | None:
    """The normal map as code values c = (n + 1) / 2 of the tangent-space normal n the shader receives."""
    value, conn = _value_source(ctx, shader, "normal")
    if conn is None:
        if value is not None and np.linalg.norm(np.asarray(value, dtype=float) - (0.0, 0.0, 1.0)) > 1e-6:
            ctx.notes.append(f"a constant normal {tuple(value)} ignored")
        return None
    tex = _connected_texture(ctx, conn, "normal")
    ref = tex.ref
    if ref is None or conn[1] != "rgb":
        raise MatremapError(ctx.where("the normal input takes a texture's rgb output; connect it so"))
    if ref.bake is None and ref.colorspace == "linear" and np.allclose(ref.scale, 2.0):
        node = conn[0]
        bias = _numbers(ctx, _value_source(ctx, node, "bias")[0] or (0.0,) * 4, "bias", 4)[:3]
        if np.allclose(bias, -1.0):
            return TextureRef(ref.path, ref.channels if ref.channels != (0, 1, 2) else None, extracted=ref.extracted)
    inner = ref.bake or _baker(
        ref.path,
        ref.colorspace,
        ref.channels or (0, 1, 2),
        np.array(np.broadcast_to(ref.scale, (3,)), dtype=float),
        np.zeros(3),
        UVTransform(np.eye(3)),
    )

    def code() -> np.ndarray:
        return (0.5 * (np.asarray(inner(), dtype=np.float32) + 1.0)).astype(np.float32)

    ctx.notes.append("normal map baked from its scale/bias (or transform) into the usual 2c - 1 encoding")
    return TextureRef(ref.path, None, "linear", 1.0, ref.extracted, code)


def _carried(ctx: _Ctx, shader: Any) -> dict[str, CarriedInput]:
    """Opacity (with opacityThreshold), emission and occlusion, as :class:`CarriedInput`."""
    out: dict[str, CarriedInput] = {}
    threshold, conn = _value_source(ctx, shader, "opacityThreshold")
    cutoff = float(threshold) if threshold is not None and conn is None else 0.0
    settings = {"mode": "mask" if cutoff > 0 else "blend", "cutoff": cutoff}
    for key, name, size, neutral in (
        ("opacity", "opacity", 1, 1.0),
        ("emission", "emissiveColor", 3, 0.0),
        ("occlusion", "occlusion", 1, 1.0),
    ):
        value, conn = _value_source(ctx, shader, name)
        if conn is not None:
            tex = _connected_texture(ctx, conn, name)
            if tex.ref is not None:
                out[key] = CarriedInput(1.0 if size == 1 else (1.0,) * 3, tex.ref, settings if key == "opacity" else {})
                continue
            value = tex.constant[:size] if tex.constant else None
        if value is None:
            continue
        nums = _numbers(ctx, value, name, size)
        if any(abs(x - neutral) > 1e-9 for x in nums):
            out[key] = CarriedInput(nums[0] if size == 1 else tuple(nums), None, settings if key == "opacity" else {})
    return out


def _note_others(ctx: _Ctx, shader: Any) -> None:
    """Note displacement and the inputs the specification does not define."""
    known = set(PARAMS) | set(CARRIED) | {"useSpecularWorkflow"}
    for inp in shader.GetInputs():
        name = inp.GetBaseName()
        value, conn = _value_source(ctx, shader, name)
        if name == "displacement" and (conn is not None or (value is not None and float(value) != 0.0)):
            ctx.notes.append("displacement ignored (matremap remaps reflectance)")
        elif name not in known and (conn is not None or value is not None):
            ctx.notes.append(f"input {name} is not a UsdPreviewSurface input; ignored")


# ---------------------------------------------------------------------------------------------
# MaterialX glTF PBR in USD


def _gltf_pbr_asset(ctx: _Ctx, shader: Any) -> MaterialAsset:
    """A ``ND_gltf_pbr_surfaceshader`` as ``gltf:metal-rough``, through the MaterialX reader's input table."""
    from matremap.formats.materialx import SHADERS

    table = SHADERS["gltf_pbr"]
    spec = get_model(GLTF)
    constants: dict[str, Any] = {}
    textures: dict[str, TextureRef] = {}
    for inp in shader.GetInputs():
        name = inp.GetBaseName()
        value, conn = _value_source(ctx, shader, name)
        if name not in table:
            if name != "normal" and (conn is not None or value is not None):
                ctx.notes.append(f"gltf_pbr input {name} not remapped")
            elif conn is not None:
                ctx.notes.append("gltf_pbr normal input ignored (write the normal map through UsdPreviewSurface)")
            continue
        param = table[name]
        size = spec.param(param).channels
        if conn is not None:
            tex = _connected_texture(ctx, conn, name)
            if tex.ref is None:
                nums = tex.constant or [0.0]
                nums = nums * size if len(nums) == 1 else nums[:size]
                constants[param] = nums if size == 3 else nums[0]
                continue
            textures[param] = tex.ref
        elif value is not None:
            nums = _numbers(ctx, value, name, size)
            constants[param] = nums if size == 3 else nums[0]
    uniform = {k: v for k, v in constants.items() if k not in textures}
    try:
        Material.create(GLTF, uniform)
    except MatremapError as e:
        raise MatremapError(ctx.where(str(e))) from None
    return MaterialAsset(ctx.path, FORMAT, ctx.name, GLTF, constants, textures, None, ctx.notes)


# ---------------------------------------------------------------------------------------------
# writing


#: gltf:metal-rough parameter -> ND_gltf_pbr_surfaceshader input (the MaterialX reader's table, inverted)
def _gltf_inputs() -> dict[str, str]:
    from matremap.formats.materialx import SHADERS

    return {v: k for k, v in SHADERS["gltf_pbr"].items()}


@dataclass
class _Planned:
    """A material to author: its name, the result taken apart, the map files to copy beside the stage
    (parameter -> (source file, destination, colour space)), the normal map's, and carried inputs."""

    name: str
    parts: ResultParts
    maps: dict[str, tuple[Path, str]] = field(default_factory=dict)
    normal: str | None = None
    carried: dict[str, tuple[CarriedInput, str | None]] = field(default_factory=dict)


def _sdf_name(name: str, used: set[str]) -> str:
    """A valid, unused prim name from a material name (its last path element)."""
    base = re.sub(r"[^A-Za-z0-9_]", "_", name.rsplit("/", 1)[-1]) or "material"
    if base[0].isdigit():
        base = "_" + base
    out, i = base, 1
    while out in used:
        i += 1
        out = f"{base}_{i}"
    used.add(out)
    return out


def _plan(out: Path, name: str, result: Any, files: AtomicFiles, stem: str, source: MaterialAsset | None) -> _Planned:
    """Take a result apart and stage its maps (and the source's carried textures) beside ``out``."""
    parts = result_parts(result, "the USD writer", (MODEL, GLTF))
    plan = _Planned(name, parts)
    spec = parts.material.spec
    dest_of = out.parent
    for param, src in parts.maps.items():
        p = spec.param(param)
        cs = parts.colorspace[param]
        keep = (p.channels == 3 and p.role != "other") or cs == "linear"
        dest_stem = dest_of / f"{out.stem}_{stem}_{param}"
        dest = place_map(src, dest_stem, keep, cs, p.channels, files)
        kept = dest.suffix.lower() == src.suffix.lower() and keep
        plan.maps[param] = (dest, cs if kept else "linear")
    if parts.normal is not None:
        plan.normal = place_map(parts.normal, dest_of / f"{out.stem}_{stem}_normal", True, "linear", 3, files).name
    if source is not None and parts.material.model == MODEL:
        for key, c in source.carried.items():
            if c.texture is not None and c.texture.bake is None and c.texture.path.is_file():
                dest = dest_of / f"{out.stem}_{stem}_{key}{c.texture.path.suffix.lower()}"
                files.copy(c.texture.path, dest)
                plan.carried[key] = (c, dest.name)
            elif c.texture is None:
                plan.carried[key] = (c, None)
    return plan


def _define_texture(pxr: Any, stage: Any, mat_path: Any, name: str, file: str, cs: str, st: Any) -> Any:
    tex = pxr.UsdShade.Shader.Define(stage, mat_path.AppendChild(name))
    tex.CreateIdAttr("UsdUVTexture")
    tex.CreateInput("file", pxr.Sdf.ValueTypeNames.Asset).Set(pxr.Sdf.AssetPath("./" + file))
    tex.CreateInput("sourceColorSpace", pxr.Sdf.ValueTypeNames.Token).Set("sRGB" if cs == "srgb" else "raw")
    tex.CreateInput("wrapS", pxr.Sdf.ValueTypeNames.Token).Set("repeat")
    tex.CreateInput("wrapT", pxr.Sdf.ValueTypeNames.Token).Set("repeat")
    tex.CreateInput("st", pxr.Sdf.ValueTypeNames.Float2).ConnectToSource(st)
    return tex


def _st_reader(pxr: Any, stage: Any, mat_path: Any) -> Any:
    reader = pxr.UsdShade.Shader.Define(stage, mat_path.AppendChild("stReader"))
    reader.CreateIdAttr("UsdPrimvarReader_float2")
    reader.CreateInput("varname", pxr.Sdf.ValueTypeNames.String).Set("st")
    return reader.CreateOutput("result", pxr.Sdf.ValueTypeNames.Float2)


def _set_input(pxr: Any, shader: Any, name: str, value: np.ndarray, rgb: bool, type_name: Any = None) -> None:
    v = np.asarray(value, dtype=float).reshape(-1)
    if rgb:
        shader.CreateInput(name, type_name or pxr.Sdf.ValueTypeNames.Color3f).Set(pxr.Gf.Vec3f(*map(float, v[:3])))
    else:
        shader.CreateInput(name, type_name or pxr.Sdf.ValueTypeNames.Float).Set(float(v[0]))


def _author_preview(pxr: Any, stage: Any, material: Any, shader: Any, plan: _Planned) -> None:
    """Set a UsdPreviewSurface shader's parameters (values or UsdUVTexture networks), normal and carried inputs."""
    m = plan.parts.material
    spec = m.spec
    mat_path = material.GetPath()
    st = (
        _st_reader(pxr, stage, mat_path)
        if plan.maps or plan.normal or any(f for _, f in plan.carried.values())
        else None
    )
    for param in PARAMS:
        p = spec.param(param)
        inp_type = pxr.Sdf.ValueTypeNames.Color3f if p.channels == 3 else pxr.Sdf.ValueTypeNames.Float
        inp = shader.CreateInput(param, inp_type)
        inp.ClearSources()
        if param in plan.maps:
            dest, cs = plan.maps[param]
            tex = _define_texture(pxr, stage, mat_path, f"{param}Texture", dest.name, cs, st)
            out_name = "rgb" if p.channels == 3 else "r"
            out_type = pxr.Sdf.ValueTypeNames.Float3 if p.channels == 3 else pxr.Sdf.ValueTypeNames.Float
            inp.ConnectToSource(tex.CreateOutput(out_name, out_type))
        else:
            _set_input(pxr, shader, param, m.values[param], p.channels == 3, inp_type)
    shader.CreateInput("useSpecularWorkflow", pxr.Sdf.ValueTypeNames.Int).Set(int(m.options["useSpecularWorkflow"]))
    if plan.normal is not None:
        tex = _define_texture(pxr, stage, mat_path, "normalTexture", plan.normal, "linear", st)
        tex.CreateInput("scale", pxr.Sdf.ValueTypeNames.Float4).Set(pxr.Gf.Vec4f(2.0, 2.0, 2.0, 1.0))
        tex.CreateInput("bias", pxr.Sdf.ValueTypeNames.Float4).Set(pxr.Gf.Vec4f(-1.0, -1.0, -1.0, 0.0))
        nrm = shader.CreateInput("normal", pxr.Sdf.ValueTypeNames.Normal3f)
        nrm.ClearSources()
        nrm.ConnectToSource(tex.CreateOutput("rgb", pxr.Sdf.ValueTypeNames.Float3))
    _author_carried(pxr, stage, mat_path, shader, plan, st)


def _author_carried(pxr: Any, stage: Any, mat_path: Any, shader: Any, plan: _Planned, st: Any) -> None:
    """Write the source's carried opacity, emission and occlusion (values, or textures copied beside the stage)."""
    slots = {"opacity": ("opacity", False), "emission": ("emissiveColor", True), "occlusion": ("occlusion", False)}
    for key, (c, file) in plan.carried.items():
        name, rgb = slots[key]
        inp = shader.CreateInput(name, pxr.Sdf.ValueTypeNames.Color3f if rgb else pxr.Sdf.ValueTypeNames.Float)
        inp.ClearSources()
        if file is not None and c.texture is not None:
            ref = c.texture
            tex = _define_texture(pxr, stage, mat_path, f"{name}Texture", file, ref.colorspace, st)
            ch = ref.channels or (0, 1, 2) if rgb else (ref.channels or (0,))
            factor = np.broadcast_to(np.asarray(ref.scale, dtype=float), (len(ch),)) * np.broadcast_to(
                np.asarray(c.value if c.value is not None else 1.0, dtype=float), (len(ch),)
            )
            if rgb:
                out = tex.CreateOutput("rgb", pxr.Sdf.ValueTypeNames.Float3)
                vals = [float(x) for x in factor[:3]] + [1.0]
            else:
                out = tex.CreateOutput("rgba"[min(ch[0], 3)], pxr.Sdf.ValueTypeNames.Float)
                vals = [1.0] * 4
                vals[min(ch[0], 3)] = float(factor[0])
            tex.CreateInput("scale", pxr.Sdf.ValueTypeNames.Float4).Set(pxr.Gf.Vec4f(*vals))
            inp.ConnectToSource(out)
        elif c.value is not None:
            _set_input(pxr, shader, name, np.asarray(c.value, dtype=float), rgb)
        if key == "opacity" and c.settings.get("mode") == "mask":
            shader.CreateInput("opacityThreshold", pxr.Sdf.ValueTypeNames.Float).Set(float(c.settings["cutoff"]))


def _author_gltf_pbr(pxr: Any, stage: Any, material: Any, plan: _Planned) -> Any:
    """A ``ND_gltf_pbr_surfaceshader`` with the gltf_pbr inputs; maps through ND_image nodes."""
    m = plan.parts.material
    shader = pxr.UsdShade.Shader.Define(stage, material.GetPath().AppendChild("gltf_pbr"))
    shader.CreateIdAttr("ND_gltf_pbr_surfaceshader")
    for param, inp_name in _gltf_inputs().items():
        p = m.spec.param(param)
        if param in plan.maps:
            dest, cs = plan.maps[param]
            kind = "color3" if p.channels == 3 else "float"
            img = pxr.UsdShade.Shader.Define(stage, material.GetPath().AppendChild(f"image_{param}"))
            img.CreateIdAttr(f"ND_image_{kind}")
            f = img.CreateInput("file", pxr.Sdf.ValueTypeNames.Asset)
            f.Set(pxr.Sdf.AssetPath("./" + dest.name))
            if kind == "color3":
                f.GetAttr().SetColorSpace("srgb_texture" if cs == "srgb" else "lin_rec709")
            typ = pxr.Sdf.ValueTypeNames.Color3f if p.channels == 3 else pxr.Sdf.ValueTypeNames.Float
            shader.CreateInput(inp_name, typ).ConnectToSource(img.CreateOutput("out", typ))
        else:
            _set_input(pxr, shader, inp_name, m.values[param], p.channels == 3)
    return shader


def _author_material(pxr: Any, stage: Any, material: Any, plan: _Planned) -> None:
    """Point a material's surface at a new or updated shader for the planned result."""
    if plan.parts.material.model == MODEL:
        existing = _surface(pxr, material)
        if existing is not None and str(existing.GetIdAttr().Get() or "") == PREVIEW:
            shader = existing
        else:
            shader = pxr.UsdShade.Shader.Define(stage, material.GetPath().AppendChild("PreviewSurface"))
            shader.CreateIdAttr(PREVIEW)
        _author_preview(pxr, stage, material, shader, plan)
        out = shader.CreateOutput("surface", pxr.Sdf.ValueTypeNames.Token)
        material.CreateSurfaceOutput().ConnectToSource(out)
        mtlx = material.GetSurfaceOutput("mtlx")
        if mtlx:
            mtlx.ClearSources()
        return
    shader = _author_gltf_pbr(pxr, stage, material, plan)
    out = shader.CreateOutput("out", pxr.Sdf.ValueTypeNames.Token)
    material.CreateSurfaceOutput().ConnectToSource(out)
    material.CreateSurfaceOutput("mtlx").ConnectToSource(out)


def _uv_sphere(pxr: Any, stage: Any, path: Any, offset: float, n_lat: int = 16, n_lon: int = 32) -> Any:
    """A unit UV sphere mesh (+Y up) with ``st`` texture coordinates (USD's lower-left origin: t = 1 at the top)."""
    t = np.linspace(0.0, np.pi, n_lat + 1)[:, None]
    ph = np.linspace(0.0, 2.0 * np.pi, n_lon + 1)[None, :]
    pos = np.stack(np.broadcast_arrays(np.sin(t) * np.sin(ph) + offset, np.cos(t), np.sin(t) * np.cos(ph)), -1)
    st = np.stack(np.broadcast_arrays(ph / (2 * np.pi), 1.0 - t / np.pi), -1).reshape(-1, 2)
    counts, indices = [], []
    for i in range(n_lat):
        for j in range(n_lon):
            a, b = i * (n_lon + 1) + j, (i + 1) * (n_lon + 1) + j
            counts.append(4)
            indices += [a, b, b + 1, a + 1]
    mesh = pxr.UsdGeom.Mesh.Define(stage, path)
    mesh.CreatePointsAttr(pxr.Vt.Vec3fArray.FromNumpy(pos.reshape(-1, 3).astype(np.float32)))
    mesh.CreateFaceVertexCountsAttr(counts)
    mesh.CreateFaceVertexIndicesAttr(indices)
    mesh.CreateExtentAttr([(offset - 1.0, -1.0, -1.0), (offset + 1.0, 1.0, 1.0)])
    mesh.CreateSubdivisionSchemeAttr("none")
    pv = pxr.UsdGeom.PrimvarsAPI(mesh).CreatePrimvar(
        "st", pxr.Sdf.ValueTypeNames.TexCoord2fArray, pxr.UsdGeom.Tokens.vertex
    )
    pv.Set(pxr.Vt.Vec2fArray.FromNumpy(st.astype(np.float32)))
    return mesh


def _fresh_stage(pxr: Any) -> Any:
    stage = pxr.Usd.Stage.CreateInMemory()
    pxr.UsdGeom.SetStageUpAxis(stage, pxr.UsdGeom.Tokens.y)
    pxr.UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    root = pxr.UsdGeom.Xform.Define(stage, "/Root")
    stage.SetDefaultPrim(root.GetPrim())
    pxr.UsdGeom.Scope.Define(stage, "/Root/Materials")
    pxr.UsdGeom.Scope.Define(stage, "/Root/Geometry")
    return stage


def _bind_on_sphere(pxr: Any, stage: Any, material: Any, name: str, k: int) -> None:
    mesh = _uv_sphere(pxr, stage, f"/Root/Geometry/{name}", 2.5 * k)
    binding = pxr.UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim())
    binding.Bind(material)


def _export(layer: Any, out: Path, staged: Path) -> None:
    """Export ``layer`` to ``staged`` in the format ``out``'s suffix names (.usd: usdc)."""
    fmt = "usdc" if out.suffix.lower() in (".usd", ".usdz") else out.suffix.lower()[1:]
    if not layer.Export(str(staged), args={"format": fmt}):
        raise MatremapError(f"cannot write {out}: USD failed to export the stage")


def write(out: str | os.PathLike, result: Any, source: MaterialAsset | None = None, force: bool = False) -> Path:
    """Write ``result`` (a ``usd:preview_surface`` or ``gltf:metal-rough`` Material or MapSet) as a USD stage
    ``out`` (.usda, .usdc, .usd or .usdz). With a USD ``source``: a copy of its stage with that material's
    surface replaced; else a fresh stage with the material bound to a UV sphere. All or nothing."""
    src_path = source.document.path if source is not None and isinstance(source.document, UsdSource) else None
    name = source.name if source is not None else "material"
    return _write_stage(Path(out), [(name, result)], src_path, force, source)


def write_all(
    out: Path,
    results: list[tuple[str, Any]],
    source: Path | None,
    force: bool,
    assets: Mapping[str, MaterialAsset] | None = None,
) -> Path:
    """Every converted material of one input file into one stage: a copy of a USD ``source`` with those
    materials' surfaces replaced (everything else kept; bound materials keep their prim paths), else a fresh
    stage with every material under ``/Root/Materials``, each bound to a sphere and carrying the opacity,
    emission and occlusion of ``assets`` (the materials as read from a source of another format)."""
    return _write_stage(Path(out), results, source, force, None, assets if source is None else None)


def _write_stage(
    out: Path,
    results: list[tuple[str, Any]],
    source: Path | None,
    force: bool,
    asset: MaterialAsset | None,
    assets: Mapping[str, MaterialAsset] | None = None,
) -> Path:
    """Author ``results`` into a stage and write it as ``out`` with its maps, all or nothing; a ``.usdz`` is
    built in a hidden folder inside ``out``'s and packaged with UsdUtils (its maps go inside it)."""
    pxr = _pxr()
    if out.suffix.lower() not in SUFFIXES:
        raise MatremapError(f"cannot write {out} as USD: name it .usda, .usdc, .usd or .usdz")
    if not results:
        raise MatremapError(f"nothing to write into {out}: no converted material")
    for _, r in results:
        result_parts(r, "the USD writer", (MODEL, GLTF))
    check_output(out, force)
    if out.suffix.lower() != ".usdz":
        with AtomicFiles(force) as files:
            stage = _build(pxr, out, results, source, asset, files, assets)
            _export(stage.GetRootLayer(), out, files.stage(out))
        return out
    with tempfile.TemporaryDirectory(prefix=temp_prefix("usdz"), dir=out.parent) as tmp:  # a killed run's: removed
        inner = Path(tmp) / f"{out.stem}.usdc"
        with AtomicFiles(True) as work:
            stage = _build(pxr, inner, results, source, asset, work, assets)
            _export(stage.GetRootLayer(), inner, work.stage(inner))
        with AtomicFiles(force) as files:
            if not pxr.UsdUtils.CreateNewUsdzPackage(str(inner), str(files.stage(out))):
                raise MatremapError(f"cannot write {out}: USD failed to package the stage")
    return out


def _build(
    pxr: Any,
    out: Path,
    results: list[tuple[str, Any]],
    source: Path | None,
    asset: MaterialAsset | None,
    files: AtomicFiles,
    assets: Mapping[str, MaterialAsset] | None = None,
) -> Any:
    """The stage to write as ``out``: every result authored into its material (carrying the inputs of
    ``asset``, or of ``assets[name]``); maps staged in ``files``."""
    stage, materials = _target_stage(pxr, out, results, source, files)
    used: set[str] = set()
    for k, ((name, result), material) in enumerate(zip(results, materials, strict=True)):
        stem = _sdf_name(name, used)
        plan = _plan(out, name, result, files, stem, (assets or {}).get(name, asset))
        _author_material(pxr, stage, material, plan)
        if source is None:
            _bind_on_sphere(pxr, stage, material, f"Sphere_{stem}", k)
    return stage


def _target_stage(
    pxr: Any, out: Path, results: list[tuple[str, Any]], source: Path | None, files: AtomicFiles
) -> tuple[Any, list[Any]]:
    """The stage to author into and the material prim of each result: a flattened, in-memory copy of a USD
    ``source`` (its asset paths rebased onto ``out``'s folder), or a fresh stage."""
    if source is None:
        stage = _fresh_stage(pxr)
        used: set[str] = set()
        mats = [pxr.UsdShade.Material.Define(stage, f"/Root/Materials/{_sdf_name(name, used)}") for name, _ in results]
        return stage, mats
    flat = _open_stage(source, None).Flatten()
    _rebase_assets(pxr, flat, out, files, source)
    stage = pxr.Usd.Stage.Open(flat)
    mats = []
    for name, _ in results:
        prim = stage.GetPrimAtPath(name) if name.startswith("/") else None
        if prim is None or not prim.IsValid() or not prim.IsA(pxr.UsdShade.Material):
            raise MatremapError(f"{source}: no material at prim path {name!r} to replace")
        mats.append(pxr.UsdShade.Material(prim))
    return stage, mats


def _rebase_assets(pxr: Any, layer: Any, out: Path, files: AtomicFiles, source: Path) -> None:
    """Rewrite the (anchored, absolute) asset paths of a flattened layer as seen from ``out``'s folder; files
    inside a usdz are extracted and copied beside ``out``. Every asset path of the copy (defaults, arrays, time
    samples), not only the converted materials' textures the reader confined, must lie in ``source``'s folder
    or an allowed one (:func:`~matremap.formats.confine.resolve_reference`): a ``.usdz`` packs what they name."""
    copied: dict[str, str] = {}
    asset_types = (pxr.Sdf.ValueTypeNames.Asset, pxr.Sdf.ValueTypeNames.AssetArray)

    def visit(path: Any) -> None:
        spec = layer.GetObjectAtPath(path)
        if not isinstance(spec, pxr.Sdf.AttributeSpec) or spec.typeName not in asset_types:
            return
        values = [spec.default, *(layer.QueryTimeSample(path, t) for t in layer.ListTimeSamplesForPath(path))]
        for value in values:
            for a in [value] if isinstance(value, pxr.Sdf.AssetPath) else list(value or []):
                if a.path:
                    _confined_asset(pxr, a.path, source, f"{source}: {path}")
        value = spec.default
        if not isinstance(value, pxr.Sdf.AssetPath) or not value.path:
            return
        spec.default = pxr.Sdf.AssetPath(_rebased(pxr, value.path, out, files, copied))

    layer.Traverse(pxr.Sdf.Path.absoluteRootPath, visit)


def _confined_asset(pxr: Any, path: str, source: Path, what: str) -> None:
    """Refuse an asset path of a flattened copy of ``source`` that lies outside its folder (and the allowed
    ones); a path inside a usdz is checked by its package's file."""
    if "://" in path or re.match(r"^[A-Za-z][A-Za-z0-9+.-]*:(?![\\/])", path):
        raise MatremapError(f"{what} names {path!r}, which is not a local file")
    package, _ = _split_package(pxr, path)
    resolve_reference(package or path, source.resolve().parent, what)


def _rebased(pxr: Any, path: str, out: Path, files: AtomicFiles, copied: dict[str, str]) -> str:
    if path in copied:
        return copied[path]
    package, inner = _split_package(pxr, path)
    if package is not None and inner:
        member = _extract(Path(package), inner)
        dest = out.parent / f"{out.stem}_{re.sub(r'[^A-Za-z0-9_.-]', '_', Path(inner).name)}"
        files.copy(member, dest)
        copied[path] = "./" + dest.name
    elif os.path.isabs(path):
        copied[path] = os.path.relpath(path, out.parent).replace(os.sep, "/")
    else:
        copied[path] = path
    return copied[path]


__all__ = [
    "FORMAT",
    "MATERIALX_IDS",
    "MODEL",
    "SUFFIXES",
    "UsdSource",
    "material_names",
    "read",
    "write",
    "write_all",
]
