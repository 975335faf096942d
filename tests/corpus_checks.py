"""Independent checks of a remap's output, for the real-asset corpus (tests/data/corpus).

Nothing here uses matremap: the input and output files are read with their own libraries (json / a
small glTF reader, MaterialX, Mitsuba 3, bpy in the Cycles worker venv) and OpenImageIO, so a check
cannot share a bug with the code it checks. `benchmarks/real_assets.py` uses these; tests may too.

A *colour* below is the linear RGB array (H, W, 3) that carries a material's look: glTF / gltf_pbr
base colour (factor x texture), Standard Surface / OpenPBR ``base x base_color`` tinted by the coat
colour, Mitsuba's ``reflectance`` / ``diffuse_reflectance`` / ``base_color``, or a conductor's normal
incidence Fresnel F0 from ``eta`` and ``k`` (times ``specular_reflectance``). Uniform values are
(1, 1, 3) arrays.
"""

from __future__ import annotations

import base64
import json
import os
import struct
import subprocess
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np

REC709_Y = np.array([0.2126, 0.7152, 0.0722])


# --------------------------------------------------------------------------- images and statistics


def srgb_to_linear(a: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 sRGB decoding of values in [0, 1]."""
    a = np.asarray(a, dtype=np.float64)
    return np.where(a <= 0.04045, a / 12.92, ((a + 0.055) / 1.055) ** 2.4)


def read_image(path: str | os.PathLike, srgb: bool | None = None) -> np.ndarray:
    """An image file as a float array (H, W, C) with OpenImageIO, without alpha premultiplication.

    ``srgb`` True decodes from sRGB, False keeps the stored values, None decodes integer formats
    (PNG/JPEG) and keeps float formats (EXR) as they are.
    """
    import OpenImageIO as oiio

    cfg = oiio.ImageSpec()
    cfg.attribute("oiio:UnassociatedAlpha", 1)
    buf = oiio.ImageBuf(str(path), 0, 0, cfg)
    if buf.has_error:
        raise OSError(f"{path}: {buf.geterror()}")
    is_float = buf.spec().format.basetype in (oiio.HALF, oiio.FLOAT, oiio.DOUBLE)
    a = np.asarray(buf.get_pixels(oiio.FLOAT), dtype=np.float64)
    if a.ndim == 2:
        a = a[..., None]
    if srgb is None:
        srgb = not is_float
    if srgb:
        a = a.copy()
        n = min(a.shape[2], 3)
        a[..., :n] = srgb_to_linear(np.clip(a[..., :n], 0, 1))
    return a


def rgb(a: np.ndarray) -> np.ndarray:
    """The first three channels of an (H, W, C) array (grey repeated when C is 1 or 2)."""
    a = np.asarray(a, dtype=np.float64)
    if a.ndim == 1:
        a = a[None, None, :]
    if a.shape[-1] >= 3:
        return a[..., :3]
    return np.repeat(a[..., :1], 3, axis=-1)


def mean_luminance(a: np.ndarray) -> float:
    """Mean Rec. 709 luminance of a linear RGB array."""
    return float((rgb(a) @ REC709_Y).mean())


def saturated_mask(a: np.ndarray, min_sat: float = 0.2, min_value: float = 0.01) -> np.ndarray:
    """Texels whose HSV saturation (on linear values) is at least ``min_sat`` and not near-black."""
    c = rgb(a)
    mx, mn = c.max(-1), c.min(-1)
    sat = np.where(mx > 0, (mx - mn) / np.maximum(mx, 1e-12), 0.0)
    return (sat >= min_sat) & (mx >= min_value)


def hue_degrees(a: np.ndarray) -> np.ndarray:
    """HSV hue in degrees [0, 360) of each texel of a linear RGB array."""
    c = rgb(a)
    r, g, b = c[..., 0], c[..., 1], c[..., 2]
    mx, mn = c.max(-1), c.min(-1)
    d = np.maximum(mx - mn, 1e-12)
    h = np.where(mx == r, ((g - b) / d) % 6, np.where(mx == g, (b - r) / d + 2, (r - g) / d + 4))
    return (h * 60.0) % 360.0


def mean_hue(a: np.ndarray, min_sat: float = 0.2, min_fraction: float = 0.05) -> float | None:
    """Circular mean hue (degrees) of the saturated texels; None when fewer than ``min_fraction`` are."""
    m = saturated_mask(a, min_sat)
    if m.mean() < min_fraction:
        return None
    h = np.radians(hue_degrees(a)[m])
    return float(np.degrees(np.arctan2(np.sin(h).mean(), np.cos(h).mean())) % 360.0)


def hue_difference(h1: float, h2: float) -> float:
    """Smallest angle between two hues, degrees."""
    d = abs(h1 - h2) % 360.0
    return min(d, 360.0 - d)


def varies(a: np.ndarray, tol: float = 0.01) -> bool:
    """Whether an array's luminance has a standard deviation above ``tol`` (a map, not a constant)."""
    return float((rgb(a) @ REC709_Y).std()) > tol


def is_all_zero(a: np.ndarray, tol: float = 1e-4) -> bool:
    """Whether every value is within ``tol`` of zero."""
    return bool(np.all(np.abs(rgb(a)) <= tol))


def max_abs_diff(a: np.ndarray, b: np.ndarray) -> float | None:
    """Max |a - b| over texels; None when the shapes differ (and neither is uniform)."""
    a, b = rgb(a), rgb(b)
    if a.shape != b.shape:
        if a.shape[:2] == (1, 1) or b.shape[:2] == (1, 1):
            return float(np.abs(a - b).max())
        return None
    return float(np.abs(a - b).max())


def conductor_f0(eta: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Normal-incidence Fresnel reflectance of a conductor, ((eta-1)^2 + k^2) / ((eta+1)^2 + k^2)."""
    eta, k = np.asarray(eta, dtype=np.float64), np.asarray(k, dtype=np.float64)
    return ((eta - 1) ** 2 + k**2) / ((eta + 1) ** 2 + k**2)


def summary(a: np.ndarray | None) -> dict[str, Any]:
    """Luminance, hue, variation and zero flags of a colour array, for tables and JSON."""
    if a is None:
        return {"lum": None, "hue": None, "varies": None, "zero": None, "shape": None}
    return {
        "lum": mean_luminance(a),
        "hue": mean_hue(a),
        "varies": varies(a),
        "zero": is_all_zero(a),
        "shape": list(np.shape(a)),
    }


# --------------------------------------------------------------------------- glTF


def gltf_load(path: str | os.PathLike) -> tuple[dict[str, Any], bytes | None]:
    """(JSON document, GLB binary chunk or None) of a .gltf or .glb file (glTF 2.0 §4.4)."""
    data = Path(path).read_bytes()
    if data[:4] != b"glTF":
        return json.loads(data.decode("utf-8")), None
    _, _, length = struct.unpack_from("<III", data, 0)
    pos, doc, binary = 12, None, None
    while pos < min(length, len(data)):
        clen, ctype = struct.unpack_from("<II", data, pos)
        chunk = data[pos + 8 : pos + 8 + clen]
        if ctype == 0x4E4F534A:
            doc = json.loads(chunk.decode("utf-8"))
        elif ctype == 0x004E4942:
            binary = chunk
        pos += 8 + clen
    if doc is None:
        raise ValueError(f"{path}: GLB without a JSON chunk")
    return doc, binary


def _gltf_buffer(path: Path, doc: dict[str, Any], binary: bytes | None, index: int) -> bytes:
    buf = doc["buffers"][index]
    uri = buf.get("uri")
    if uri is None:
        if binary is None:
            raise ValueError(f"{path}: buffer {index} has no uri and there is no GLB chunk")
        return binary
    if uri.startswith("data:"):
        return base64.b64decode(uri.split(",", 1)[1])
    from urllib.parse import unquote

    return (path.parent / unquote(uri)).read_bytes()


def gltf_image_bytes(path: str | os.PathLike, doc: dict[str, Any], binary: bytes | None, index: int) -> bytes:
    """The encoded bytes of ``images[index]`` (file uri, data uri or buffer view)."""
    path = Path(path)
    im = doc["images"][index]
    if "uri" in im:
        uri = im["uri"]
        if uri.startswith("data:"):
            return base64.b64decode(uri.split(",", 1)[1])
        from urllib.parse import unquote

        return (path.parent / unquote(uri)).read_bytes()
    view = doc["bufferViews"][im["bufferView"]]
    data = _gltf_buffer(path, doc, binary, view["buffer"])
    off = view.get("byteOffset", 0)
    return data[off : off + view["byteLength"]]


def _image_from_bytes(data: bytes, srgb: bool) -> np.ndarray:
    suffix = ".png" if data[:4] == b"\x89PNG" else ".jpg" if data[:2] == b"\xff\xd8" else ".img"
    with tempfile.TemporaryDirectory() as tmp:
        f = Path(tmp) / ("image" + suffix)
        f.write_bytes(data)
        return read_image(f, srgb=srgb)


_GLTF_DTYPES = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}


def _gltf_accessor(path: Path, doc: dict[str, Any], binary: bytes | None, index: int) -> np.ndarray:
    """An accessor's elements as floats [count, components] (glTF 2.0 §3.6.2; normalised integers divided by their
    maximum; no sparse accessors)."""
    acc = doc["accessors"][index]
    view = doc["bufferViews"][acc["bufferView"]]
    data = _gltf_buffer(path, doc, binary, view["buffer"])
    dtype = np.dtype(_GLTF_DTYPES[acc["componentType"]])
    n = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[acc["type"]]
    stride = view.get("byteStride") or dtype.itemsize * n
    start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    rows = [np.frombuffer(data, dtype, n, start + i * stride) for i in range(acc["count"])]
    out = np.array(rows, dtype=np.float64).reshape(acc["count"], n)
    return out / np.iinfo(dtype).max if acc.get("normalized") and dtype.kind in "iu" else out


def gltf_shown(path: str | os.PathLike, material: str | int | None, shape: tuple[int, int]) -> np.ndarray | None:
    """The texels of a map of ``shape`` (H, W) that the triangles drawn with a glTF material show through
    TEXCOORD_0 (mode 4 only; glTF §3.8.3: UV (0, 0) is the image's top-left), drawn with PIL's polygon filler;
    None when no triangle uses the material or a UV leaves [0, 1] (a tiled texture: every texel counts)."""
    from PIL import Image, ImageDraw

    path = Path(path)
    doc, binary = gltf_load(path)
    idx = gltf_material_index(doc, material)
    h, w = shape
    canvas = Image.new("L", (w, h), 0)
    draw = ImageDraw.Draw(canvas)
    drawn = False
    for mesh in doc.get("meshes", []):
        for prim in mesh.get("primitives", []):
            variants = prim.get("extensions", {}).get("KHR_materials_variants", {}).get("mappings", [])
            if idx != prim.get("material") and idx not in [m.get("material") for m in variants]:
                continue
            if prim.get("mode", 4) != 4 or "TEXCOORD_0" not in prim["attributes"]:
                return None
            uv = _gltf_accessor(path, doc, binary, prim["attributes"]["TEXCOORD_0"])
            if uv.size and (uv.min() < -1e-6 or uv.max() > 1 + 1e-6):
                return None
            if "indices" in prim:
                tris = _gltf_accessor(path, doc, binary, prim["indices"]).astype(np.int64).reshape(-1, 3)
            else:
                tris = np.arange(len(uv)).reshape(-1, 3)
            for t in tris:
                draw.polygon([(float(uv[k, 0] * w), float(uv[k, 1] * h)) for k in t], fill=255)
            drawn = True
    if not drawn:
        return None
    return np.asarray(canvas) > 0


def gltf_material_index(doc: dict[str, Any], material: str | int | None) -> int:
    """Index of a material given by name or index (default 0)."""
    if material is None:
        return 0
    if isinstance(material, int) or str(material).isdigit():
        return int(material)
    for i, m in enumerate(doc.get("materials", [])):
        if m.get("name") == material:
            return i
    raise KeyError(material)


def gltf_base_colour(path: str | os.PathLike, material: str | int | None = None) -> np.ndarray:
    """Linear base colour (factor x sRGB-decoded texture) of a glTF material."""
    doc, binary = gltf_load(path)
    m = doc["materials"][gltf_material_index(doc, material)]
    pbr = m.get("pbrMetallicRoughness", {})
    factor = np.array(pbr.get("baseColorFactor", [1, 1, 1, 1])[:3], dtype=np.float64)
    tex = pbr.get("baseColorTexture")
    if tex is None:
        return factor[None, None, :]
    src = doc["textures"][tex["index"]]["source"]
    img = rgb(_image_from_bytes(gltf_image_bytes(path, doc, binary, src), srgb=True))
    return img * factor


def gltf_metallic(path: str | os.PathLike, material: str | int | None = None) -> np.ndarray:
    """Metallic (factor x blue channel of the metallic-roughness texture) of a glTF material."""
    doc, binary = gltf_load(path)
    m = doc["materials"][gltf_material_index(doc, material)]
    pbr = m.get("pbrMetallicRoughness", {})
    factor = float(pbr.get("metallicFactor", 1.0))
    tex = pbr.get("metallicRoughnessTexture")
    if tex is None:
        return np.full((1, 1), factor)
    src = doc["textures"][tex["index"]]["source"]
    img = _image_from_bytes(gltf_image_bytes(path, doc, binary, src), srgb=False)
    return img[..., 2] * factor


def gltf_loads(path: str | os.PathLike) -> tuple[bool, str]:
    """Whether a glTF file parses (pygltflib when installed, else json) and every buffer, image and
    index it refers to exists; (ok, message)."""
    path = Path(path)
    try:
        try:
            import pygltflib  # type: ignore[import-not-found]

            pygltflib.GLTF2().load(str(path))
        except ImportError:
            pass
        doc, binary = gltf_load(path)
        for i, b in enumerate(doc.get("buffers", [])):
            if len(_gltf_buffer(path, doc, binary, i)) < b["byteLength"]:
                return False, f"buffer {i} shorter than byteLength"
        for i, v in enumerate(doc.get("bufferViews", [])):
            if v["buffer"] >= len(doc.get("buffers", [])):
                return False, f"bufferView {i} -> missing buffer"
        for i in range(len(doc.get("images", []))):
            if not gltf_image_bytes(path, doc, binary, i):
                return False, f"image {i} empty"
        n_img = len(doc.get("images", []))
        for i, t in enumerate(doc.get("textures", [])):
            if t.get("source", 0) >= n_img:
                return False, f"texture {i} -> missing image"
        n_tex = len(doc.get("textures", []))
        for i, m in enumerate(doc.get("materials", [])):
            for key, val in _texture_refs(m):
                if val >= n_tex:
                    return False, f"material {i} {key} -> missing texture"
        return True, "ok"
    except Exception as e:  # noqa: BLE001 - any failure to read is the answer
        return False, f"{type(e).__name__}: {e}"


def _texture_refs(obj: Any, key: str = "") -> list[tuple[str, int]]:
    out: list[tuple[str, int]] = []
    if isinstance(obj, dict):
        for k, v in obj.items():
            if k.endswith("Texture") and isinstance(v, dict) and "index" in v:
                out.append((k, int(v["index"])))
            out += _texture_refs(v, k)
    return out


# --------------------------------------------------------------------------- MaterialX

_SHADERS = ("gltf_pbr", "standard_surface", "open_pbr_surface", "UsdPreviewSurface")


def _mx_document(path: str | os.PathLike) -> Any:
    import MaterialX as mx

    doc = mx.createDocument()
    mx.readFromXmlFile(doc, str(path))
    return doc


def mtlx_loads(path: str | os.PathLike) -> tuple[bool, str]:
    """Whether a MaterialX document reads and validates against the standard data libraries."""
    try:
        import MaterialX as mx

        doc = _mx_document(path)
        lib = mx.createDocument()
        mx.loadLibraries(mx.getDefaultDataLibraryFolders(), mx.getDefaultDataSearchPath(), lib)
        doc.importLibrary(lib)
        ok, msg = doc.validate()
        return bool(ok), "ok" if ok else msg.strip().splitlines()[0]
    except Exception as e:  # noqa: BLE001
        return False, f"{type(e).__name__}: {e}"


def _mx_shader(doc: Any, material: str | int | None) -> Any:
    mats = doc.getMaterialNodes()
    shaders = []
    for m in mats:
        inp = m.getInput("surfaceshader")
        node = inp.getConnectedNode() if inp is not None else None
        if node is not None:
            shaders.append((m.getName(), node))
    if not shaders:
        shaders = [(n.getName(), n) for n in doc.getNodes() if n.getCategory() in _SHADERS]
    if not shaders:
        raise ValueError("no surface shader")
    if material is None:
        return shaders[0][1]
    if isinstance(material, int) or str(material).isdigit():
        return shaders[int(material)][1]
    for name, node in shaders:
        if name == material or node.getName() == material:
            return node
    raise KeyError(material)


def _mx_input(doc: Any, base: Path, shader: Any, name: str) -> np.ndarray | float | None:
    """Value of a shader input: a uniform (value) or an image (through a node graph or node)."""
    inp = shader.getInput(name)
    if inp is None:
        return None
    if inp.hasValueString() and not (inp.getNodeGraphString() or inp.getNodeName()):
        v = inp.getValue()
        try:
            return np.array(v.asTuple(), dtype=np.float64)
        except AttributeError:
            return float(v)
    node = inp.getConnectedNode()
    if node is None and inp.getNodeGraphString():
        ng = doc.getNodeGraph(inp.getNodeGraphString())
        out = ng.getOutput(inp.getOutputString()) if inp.getOutputString() else ng.getOutputs()[0]
        node = out.getConnectedNode()
    if node is None:
        return None
    f = node.getInput("file")
    if f is None:
        raise ValueError(f"{name}: connected to a {node.getCategory()} node (not an image)")
    rel = f.getResolvedValueString()
    cs = f.getColorSpace() or ""
    img = read_image(base / rel, srgb="srgb" in cs.lower())
    coords = node.getInput("texcoord")
    place = coords.getConnectedNode() if coords is not None else None
    if place is not None and place.getCategory() == "place2d":
        img = _placed(img, place, node)
    return img


def _mx_number(node: Any, name: str, default: Any) -> np.ndarray:
    inp = node.getInput(name)
    if inp is None or not inp.hasValueString():
        return np.asarray(default, dtype=np.float64)
    v = inp.getValue()
    try:
        return np.array(v.asTuple(), dtype=np.float64)
    except AttributeError:
        return np.asarray(float(v), dtype=np.float64)


def _placed(img: np.ndarray, place: Any, image: Any, n: int = 64) -> np.ndarray:
    """What an image node shows over the surface's [0, 1]^2 when its texcoord comes through a ``place2d``, sampled on
    an n x n grid (nearest texel): MaterialX 1.39 ``NG_place2d_vector2``, operation order SRT, uv' = rotate((uv -
    pivot) / scale, degrees) - offset + pivot; the image's address modes (clamp, periodic, mirror) outside [0, 1];
    UV (0, 0) at the image's lower left. Written here from the standard library's node graph, apart from matremap's
    own evaluator."""
    pivot, scale = _mx_number(place, "pivot", [0.0, 0.0]), _mx_number(place, "scale", [1.0, 1.0])
    offset, angle = _mx_number(place, "offset", [0.0, 0.0]), float(_mx_number(place, "rotate", 0.0))
    t = (np.arange(n) + 0.5) / n
    uv = np.stack(np.meshgrid(t, 1.0 - t), axis=-1)  # rows from the top: v from 1 down
    q = (uv - pivot) / scale
    c, s_ = np.cos(np.radians(angle)), np.sin(np.radians(angle))
    q = np.stack([c * q[..., 0] - s_ * q[..., 1], s_ * q[..., 0] + c * q[..., 1]], axis=-1) - offset + pivot

    def address(x: np.ndarray, mode: str) -> np.ndarray:
        if mode == "periodic":
            return x % 1.0
        if mode == "mirror":
            return 1.0 - np.abs((x % 2.0) - 1.0)
        return np.clip(x, 0.0, 1.0)  # clamp (constant borders are not drawn here)

    modes = [str(image.getInputValue(k) or "periodic") for k in ("uaddressmode", "vaddressmode")]
    u, v = address(q[..., 0], modes[0]), address(q[..., 1], modes[1])
    h, w = img.shape[:2]
    cols = np.clip((u * w).astype(int), 0, w - 1)
    rows = np.clip(((1.0 - v) * h).astype(int), 0, h - 1)
    return img[rows, cols]


def mtlx_colour(path: str | os.PathLike, material: str | int | None = None) -> np.ndarray:
    """Linear colour carrying the look of a MaterialX material (see the module docstring)."""
    path = Path(path)
    doc = _mx_document(path)
    sh = _mx_shader(doc, material)
    cat = sh.getCategory()

    def get(name: str, default: Any) -> Any:
        v = _mx_input(doc, path.parent, sh, name)
        return default if v is None else v

    def arr(v: Any) -> np.ndarray:
        v = np.asarray(v, dtype=np.float64)
        if v.ndim == 0:
            v = np.full(3, float(v))
        return rgb(v if v.ndim == 3 else v[None, None, :])

    if cat == "gltf_pbr":
        return arr(get("base_color", [1, 1, 1]))
    if cat == "UsdPreviewSurface":
        return arr(get("diffuseColor", [0.18, 0.18, 0.18]))
    if cat == "standard_surface":
        c = arr(get("base_color", [0.8, 0.8, 0.8])) * float(np.mean(get("base", 1.0)))
        coat, coat_colour = get("coat", 0.0), get("coat_color", [1, 1, 1])
    else:  # open_pbr_surface
        c = arr(get("base_color", [0.8, 0.8, 0.8])) * float(np.mean(get("base_weight", 1.0)))
        coat, coat_colour = get("coat_weight", 0.0), get("coat_color", [1, 1, 1])
    coat = float(np.mean(coat))
    if coat > 0:
        c = c * (1 - coat + coat * arr(coat_colour))
    return c


# --------------------------------------------------------------------------- Mitsuba 3

_MI_COLOUR_KEYS = ("base_color", "diffuse_reflectance", "reflectance")


def _mitsuba() -> Any:
    import mitsuba as mi

    if mi.variant() is None:
        mi.set_variant("scalar_rgb")
    return mi


def mitsuba_loads(path: str | os.PathLike) -> tuple[bool, str]:
    """Whether Mitsuba 3 loads the scene file (``mitsuba.load_file``)."""
    try:
        _mitsuba().load_file(str(path))
        return True, "ok"
    except Exception as e:  # noqa: BLE001
        return False, f"{type(e).__name__}: {str(e).strip().splitlines()[-1][:160]}"


def _mi_value(v: Any) -> np.ndarray:
    a = np.array(v, dtype=np.float64)
    if a.ndim == 2 and a.shape[1] == 1:  # a JIT variant's Color3f of width 1 is [3, 1]
        a = a[:, 0]
    if a.ndim == 0:
        a = np.full(3, float(a))
    if a.ndim == 1:
        a = a[None, None, :]
    return rgb(a)


def _mi_texels(params: Any, key: str) -> Any:
    """A parameter's value; a bitmap's data as linear floats. Mitsuba 3.9 keeps an 8-bit bitmap's texels as
    they are stored (``TensorXu8``): the sRGB-encoded bytes unless the bitmap is ``raw`` (the texture's
    description says ``raw = 1``), decoded here as its lookups decode them."""
    value = params[key]
    a = np.asarray(value)
    if a.dtype != np.uint8:
        return value
    node = params.properties[key][2] if hasattr(params, "properties") else None
    raw = node is not None and "raw = 1" in str(node)
    a = a.astype(np.float64) / 255.0
    if not raw:
        a = a.copy()
        n = min(a.shape[-1], 3)
        a[..., :n] = srgb_to_linear(a[..., :n])
    return a


def mitsuba_colour(path: str | os.PathLike, material: str | None = None) -> np.ndarray:
    """Linear colour of the first BSDF (or the one with id ``material``) of a Mitsuba 3 scene, read
    from the loaded scene's parameters (``mitsuba.traverse``): Mitsuba resolves ``$`` defaults,
    named IORs, sRGB bitmaps and ``twosided`` itself."""
    mi = _mitsuba()
    scene = mi.load_file(str(path))
    params = mi.traverse(scene)
    keys = list(params.keys())
    bsdf_ids = [s.bsdf().id() for s in scene.shapes()] if scene.shapes() else []
    prefixes = []
    if material:
        prefixes.append(material)
    prefixes += [b for b in bsdf_ids if b]
    prefixes.append("")

    def find(name: str) -> Any:
        for p in prefixes:
            for k in keys:
                if (not p or k.startswith(p)) and (k.endswith(f".{name}.value") or k.endswith(f".{name}.data")):
                    return _mi_texels(params, k)
        return None

    for name in _MI_COLOUR_KEYS:
        v = find(name)
        if v is not None:
            return _mi_value(v)
    eta, k = find("eta"), find("k")
    if k is not None:
        eta_a = _mi_value(eta) if eta is not None else np.zeros((1, 1, 3))
        f0 = conductor_f0(eta_a, _mi_value(k))
        spec = find("specular_reflectance")
        return f0 * (_mi_value(spec) if spec is not None else 1.0)
    raise ValueError(f"{path}: no colour parameter among {keys[:12]}")


# --------------------------------------------------------------------------- Blender .blend (Cycles)

_BPY_SCRIPT = r"""
import bpy, json, sys
import numpy as np
bpy.ops.wm.open_mainfile(filepath=sys.argv[-2])
out = {}
for mat in bpy.data.materials:
    if not mat.use_nodes:
        continue
    for node in mat.node_tree.nodes:
        if node.type not in ("BSDF_PRINCIPLED", "BSDF_DIFFUSE", "BSDF_GLOSSY"):
            continue
        sock = node.inputs.get("Base Color") or node.inputs.get("Color")
        if sock.is_linked:
            src = sock.links[0].from_node
            if src.type == "TEX_IMAGE" and src.image is not None:
                im = src.image
                px = np.array(im.pixels[:], dtype=np.float32).reshape(im.size[1], im.size[0], im.channels)
                np.save(sys.argv[-1], px)
                out = {"material": mat.name, "node": node.type, "image": im.name,
                       "colorspace": im.colorspace_settings.name, "is_float": im.is_float}
            else:
                out = {"material": mat.name, "node": node.type, "linked": src.type}
        else:
            out = {"material": mat.name, "node": node.type, "value": list(sock.default_value)[:3]}
        break
    if out:
        break
print("JSON:" + json.dumps(out))
"""


def blend_colour(path: str | os.PathLike, python: str | os.PathLike) -> tuple[np.ndarray | None, bool, str]:
    """(colour, loads, message) of a .blend: opened by bpy in ``python`` (the Cycles worker venv),
    the Base Color (Principled) or Color (Diffuse/Glossy) of the first such node."""
    with tempfile.TemporaryDirectory() as tmp:
        script = Path(tmp) / "probe.py"
        script.write_text(_BPY_SCRIPT)
        npy = Path(tmp) / "px.npy"
        try:
            r = subprocess.run(
                [str(python), str(script), str(path), str(npy)], capture_output=True, text=True, timeout=180
            )
        except Exception as e:  # noqa: BLE001
            return None, False, f"{type(e).__name__}: {e}"
        line = next((x for x in r.stdout.splitlines() if x.startswith("JSON:")), None)
        if r.returncode != 0 or line is None:
            tail = (r.stderr.strip().splitlines() or ["no output"])[-1]
            return None, False, tail[:160]
        info = json.loads(line[5:])
        if not info:
            return None, True, "no BSDF node"
        if "value" in info:
            return _mi_value(info["value"]), True, "ok"
        if "image" in info:
            px = np.load(npy)[::-1].astype(np.float64)
            c = rgb(px)
            if not info["is_float"] and info["colorspace"] == "sRGB":
                c = srgb_to_linear(np.clip(c, 0, 1))
            return c, True, "ok"
        return None, True, f"Base Color linked to {info.get('linked')}"


# --------------------------------------------------------------------------- dispatch


def file_kind(path: str | os.PathLike) -> str:
    """'gltf', 'mtlx', 'mitsuba' or 'blend' by suffix (and root element for .xml)."""
    s = Path(path).suffix.lower()
    if s in (".gltf", ".glb"):
        return "gltf"
    if s == ".mtlx":
        return "mtlx"
    if s == ".blend":
        return "blend"
    if s == ".xml":
        root = ET.parse(path).getroot()
        return "mtlx" if root.tag == "materialx" else "mitsuba"
    return "unknown"


def material_colour(path: str | os.PathLike, material: str | int | None = None) -> np.ndarray:
    """The colour (see the module docstring) of a material file of any supported kind but .blend."""
    kind = file_kind(path)
    if kind == "gltf":
        return gltf_base_colour(path, material)
    if kind == "mtlx":
        return mtlx_colour(path, material)
    if kind == "mitsuba":
        return mitsuba_colour(path, None if material is None else str(material))
    raise ValueError(f"{path}: no colour reader for {kind}")


def file_loads(path: str | os.PathLike) -> tuple[bool, str]:
    """Whether a written file loads in its own library (glTF, MaterialX or Mitsuba 3)."""
    kind = file_kind(path)
    if kind == "gltf":
        return gltf_loads(path)
    if kind == "mtlx":
        return mtlx_loads(path)
    if kind == "mitsuba":
        return mitsuba_loads(path)
    return False, f"no loader for {kind}"


def find_output_file(out: str | os.PathLike) -> Path | None:
    """The target file a remap wrote into ``out`` (top level: .gltf/.glb/.mtlx/.xml/.blend)."""
    out = Path(out)
    if not out.is_dir():
        return None
    for suffix in (".gltf", ".glb", ".mtlx", ".blend", ".xml"):
        found = sorted(p for p in out.glob(f"*{suffix}") if p.is_file())
        if found:
            return found[0]
    return None


def verdict(
    exit_code: int | None,
    stderr: str,
    loads: bool | None,
    lum_in: float | None,
    lum_out: float | None,
    hue_in: float | None,
    hue_out: float | None,
    in_varies: bool | None,
    out_varies: bool | None,
    out_zero: bool | None,
    identity_diff: float | None = None,
    identity: bool = False,
    max_lum_ratio: float = 2.0,
    max_hue_shift: float = 30.0,
    identity_tol: float = 2.0 / 255.0,
) -> tuple[str, list[str]]:
    """OK / WRONG / REFUSED / CRASH and the reasons, from a run's exit code and stderr and the
    independent measures. WRONG: exit 0 but the output does not load, has no readable colour, is
    all zero or constant where the input varies, lost the input's hue (> ``max_hue_shift`` degrees
    or no saturated texels left), is off in mean luminance by more than ``max_lum_ratio``, or (for
    an identity case) differs from the input's colour by more than ``identity_tol``."""
    if exit_code is None:
        return "CRASH", ["timeout"]
    if exit_code != 0:
        return ("CRASH" if "Traceback (most recent call last)" in stderr else "REFUSED"), []
    why: list[str] = []
    if loads is False:
        why.append("does not load")
    if lum_out is None:
        why.append("no output colour found")
    else:
        if out_zero and not (lum_in is not None and lum_in < 1e-4):
            why.append("output colour all zero")
        elif in_varies and out_varies is False:
            why.append("constant output where input varies")
        if lum_in is not None and lum_in > 5e-3:
            ratio = lum_out / lum_in if lum_in > 0 else float("inf")
            if ratio > max_lum_ratio or ratio < 1.0 / max_lum_ratio:
                why.append(f"luminance x{ratio:.2f}")
        if hue_in is not None:
            if hue_out is None:
                why.append("hue lost (grey output)")
            elif hue_difference(hue_in, hue_out) > max_hue_shift:
                why.append(f"hue moved {hue_difference(hue_in, hue_out):.0f} deg")
    if identity:
        if identity_diff is None:
            why.append("identity: map size changed")
        elif identity_diff > identity_tol:
            why.append(f"identity: max diff {identity_diff:.3g}")
    return ("WRONG" if why else "OK"), why
