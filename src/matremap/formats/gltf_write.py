"""glTF 2.0 materials written: one converted material into a copy of its source, or onto a UV sphere.

References: glTF 2.0 (Khronos, 2.0.1) §3.9.2 (baseColorFactor x sRGB baseColorTexture, its alpha the
coverage; metallicFactor / roughnessFactor x B / G of one linear metallicRoughnessTexture), §3.9.3
(normalTexture, occlusionTexture R x strength, emissiveFactor x sRGB emissiveTexture), §3.9.4 (alphaMode,
alphaCutoff), §3.8 (images, textures, samplers), §4.4 (GLB); KHR_materials_ior, KHR_materials_specular
(alpha of specularTexture, sRGB RGB of specularColorTexture) and KHR_materials_emissive_strength.

The maps a writer receives are on the map set's one UV set with no transform (the reader baked any
KHR_texture_transform), so a new texture keeps the sampler of the texture it replaces but never its
transform, and it is looked up with the UV set the source material's maps used.

What the material carries besides the model (``source.carried``: emission, occlusion, opacity, see
:class:`~matremap.formats.asset.CarriedInput`) is written from any source format; a copy of a glTF source
keeps its own emission and occlusion as they are and gives a new base colour texture the source's alpha.
:mod:`matremap.formats.gltf_edit` holds the file-level steps shared with ``write_all``.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any
from urllib.parse import quote

import numpy as np

from matremap.core.atomic import AtomicFiles
from matremap.core.imageio import check_output, linear_to_srgb
from matremap.core.material import Material
from matremap.dialects import get_model
from matremap.errors import MatremapError
from matremap.formats.asset import CarriedInput, MaterialAsset, TextureRef
from matremap.formats.bake import UVTransform, bake_image
from matremap.formats.gltf_container import GltfDocument
from matremap.formats.gltf_edit import (
    NewImage,
    Replacement,
    Target,
    add_bin_buffer,
    add_images,
    check_writable_source,
    confine_uris,
    drop_unused,
    glb_bytes,
    json_bytes,
    material_textures,
    rebase_uris,
    refuse_overwrites,
    update_extension_lists,
)
from matremap.formats.gltf_extensions import (
    CLEARCOAT,
    COAT_MAPS,
    EMISSIVE_STRENGTH,
    IOR,
    LAYERED_MODEL,
    SHEEN,
    SHEEN_MAPS,
    SPEC_GLOSS,
    SPECULAR,
    TRANSMISSION,
    TRANSMISSION_MAP,
    VOLUME,
)
from matremap.formats.gltf_read import DEFAULT_IOR, MODEL
from matremap.formats.gltf_textures import linear_values


def result_values(result: Any) -> tuple[dict[str, Any], dict[str, np.ndarray], Path | None, list[Path]]:
    """(constants, maps as linear float arrays, normal map file, input files) of a Material or MapSet."""
    from matremap.regress.quantities import material_values
    from matremap.svbrdf.textures import MapSet, read_image

    if not isinstance(result, Material | MapSet):
        raise MatremapError(f"cannot write {type(result).__name__} as glTF; give a material or a map set")
    spec = get_model(result.model)
    if spec.id not in (MODEL, LAYERED_MODEL):
        raise MatremapError(
            f"glTF stores {MODEL} and {LAYERED_MODEL} materials, and this result is {result.model}; remap it onto "
            f"one of them first (e.g. matremap remap ... --to {MODEL})"
        )
    if isinstance(result, Material):
        return dict(material_values(result)), {}, None, []
    consts: dict[str, Any] = {p.name: p.default_array if p.channels == 3 else p.default for p in spec.params}
    consts.update({k: v for k, v in result.constants.items() if k in spec.param_names})
    maps: dict[str, np.ndarray] = {}
    for name, f in result.maps.items():
        pspec = spec.param(name)
        if name == "ior":
            raise MatremapError(
                f"{f}: {IOR} has no texture, so a map of ior cannot be written to glTF; use a uniform ior"
            )
        if name in CONSTANT_ONLY:
            raise MatremapError(
                f"{f}: a map of {name} (a layer extension's texture) is not written to glTF yet; use a uniform {name}"
            )
        img, _ = read_image(f, result.colorspace.get(name), colour=pspec.channels == 3 and pspec.role != "other")
        if pspec.channels == 3:
            img = np.repeat(img[..., :1], 3, axis=-1) if img.shape[-1] == 1 else img[..., :3]
        else:
            img = img[..., 0]
        maps[name] = np.clip(img, *pspec.bounds)
    if len({a.shape[:2] for a in maps.values()}) > 1:
        raise MatremapError("the maps differ in size; resample them to one size before writing glTF")
    return consts, maps, result.normal, list(result.files)


def code(values: np.ndarray, srgb: bool) -> np.ndarray:
    """8-bit code values of linear ``values`` (clipped to [0, 1]), sRGB-encoded when ``srgb``."""
    v = np.clip(np.asarray(values, dtype=np.float64), 0.0, 1.0)
    if srgb:
        v = linear_to_srgb(v)
    return np.round(v * 255.0).astype(np.uint8)


def png(array: np.ndarray) -> bytes:
    """8-bit PNG bytes of a uint8 array [H, W, C]."""
    from matremap.core.imageio import png_bytes

    return png_bytes(array)


def split_factor(a: np.ndarray) -> tuple[np.ndarray, list[float]]:
    """A map [H, W, 3] as (texture in [0, 1], per-channel factor): the factor is 1 unless the map exceeds 1."""
    factor = np.maximum(a.reshape(-1, 3).max(axis=0), 1.0)
    return a / factor, [float(x) for x in factor]


def texture_values(ref: TextureRef, size: tuple[int, int] | None = None) -> np.ndarray:
    """A TextureRef's linear values [H, W, C] (baked when it says so, channels picked, factor applied),
    resampled to ``size`` (height, width) when given."""
    if ref.bake is not None:
        image = np.atleast_3d(np.asarray(ref.bake(), dtype=np.float32))
    else:
        if not ref.path.is_file():
            raise MatremapError(f"texture {ref.path} not found; put it beside its file or fix the reference")
        image = linear_values(ref.path, ref.colorspace == "srgb")
    if ref.channels is not None:
        if max(ref.channels) >= image.shape[-1]:
            raise MatremapError(f"{ref.path}: has {image.shape[-1]} channel(s), channel {max(ref.channels)} is needed")
        image = image[..., list(ref.channels)]
    image = image * np.asarray(ref.scale, dtype=np.float32).reshape(-1)[: image.shape[-1]]
    if size is not None and image.shape[:2] != tuple(size):
        image = bake_image(image, UVTransform(np.eye(3), wrap=("clamp", "clamp")), size)
    return image.astype(np.float32)


def base_colour_image(
    pbr: dict[str, Any], consts: dict[str, Any], maps: dict[str, np.ndarray], opacity: CarriedInput | None
) -> NewImage | None:
    """Set baseColorFactor (its alpha the carried opacity's, else the source's); the sRGB texture of a base
    colour map, with the carried opacity texture as its alpha (a texture of white with that alpha when the
    base colour is uniform)."""
    old = pbr.pop("baseColorTexture", None)
    alpha = float((pbr.get("baseColorFactor") or [1, 1, 1, 1])[3])
    if opacity is not None and opacity.value is not None:
        alpha = float(np.clip(np.asarray(opacity.value, dtype=float).reshape(-1)[0], 0.0, 1.0))
    alpha_tex = opacity.texture if opacity is not None else None
    if "baseColor" not in maps and alpha_tex is None:
        pbr["baseColorFactor"] = [*(float(x) for x in np.broadcast_to(consts["baseColor"], (3,))), alpha]
        return None
    if "baseColor" in maps:
        tex, factor = split_factor(maps["baseColor"])
        size: tuple[int, int] | None = tex.shape[:2]
    else:
        factor = [float(x) for x in np.broadcast_to(consts["baseColor"], (3,))]
        tex, size = None, None
    a = texture_values(alpha_tex, size)[..., 0] if alpha_tex is not None else None
    rgb = code(tex, True) if tex is not None else np.full((*a.shape[:2], 3), 255, np.uint8)  # type: ignore[union-attr]
    pixels = rgb if a is None else np.concatenate([rgb, code(a, False)[..., None]], axis=-1)
    pbr["baseColorFactor"] = [*factor, alpha]
    return NewImage("baseColor", png(pixels), "image/png", old)


def metallic_roughness_image(
    pbr: dict[str, Any], consts: dict[str, Any], maps: dict[str, np.ndarray]
) -> NewImage | None:
    """Set roughnessFactor and metallicFactor (1 where a map carries the values); roughness and
    metallic maps packed into the G and B channels of one linear texture (§3.9.2), if any."""
    old = pbr.pop("metallicRoughnessTexture", None)
    image = None
    if "roughness" in maps or "metallic" in maps:
        shape = next(a.shape[:2] for k, a in maps.items() if k in ("roughness", "metallic"))
        packed = np.ones((*shape, 3))
        for k, c in (("roughness", 1), ("metallic", 2)):
            if k in maps:
                packed[..., c] = maps[k]
        image = NewImage("metallicRoughness", png(code(packed, False)), "image/png", old)
    for k in ("roughness", "metallic"):
        pbr[f"{k}Factor"] = 1.0 if k in maps else float(np.asarray(consts[k]).reshape(-1)[0])
    return image


def specular_image(
    consts: dict[str, Any], maps: dict[str, np.ndarray], old: dict[str, Any]
) -> tuple[dict[str, Any], NewImage | None]:
    """KHR_materials_specular's factors ({} when they and the maps are at the defaults) and one
    texture holding specularColor (sRGB RGB) and specular (alpha), if either is a map. ``old``: the
    source's extension object."""
    spec_f = 1.0 if "specular" in maps else float(np.asarray(consts["specular"]).reshape(-1)[0])
    tint_tex: np.ndarray | None = None
    if "specularColor" in maps:
        tint_tex, tint_f = split_factor(maps["specularColor"])
    else:
        tint_f = [float(x) for x in np.broadcast_to(consts["specularColor"], (3,))]
    image = None
    if "specular" in maps or tint_tex is not None:
        shape = next(a.shape[:2] for k, a in maps.items() if k in ("specular", "specularColor"))
        rgba = np.full((*shape, 4), 255, dtype=np.uint8)
        if tint_tex is not None:
            rgba[..., :3] = code(tint_tex, True)
        if "specular" in maps:
            rgba[..., 3] = code(maps["specular"], False)
        else:
            rgba = rgba[..., :3]
        copy_from = old.get("specularColorTexture") or old.get("specularTexture")
        image = NewImage("specular", png(rgba), "image/png", copy_from)
    if spec_f != 1.0 or any(v != 1.0 for v in tint_f) or "specular" in maps or tint_tex is not None:
        return {"specularFactor": spec_f, "specularColorFactor": tint_f}, image
    return {}, image


def coat_image(maps: dict[str, np.ndarray], exts: dict[str, Any], name: str) -> NewImage | None:
    """A ``clearcoat`` or ``clearcoatRoughness`` map as KHR_materials_clearcoat's texture (its R or G channel of
    a linear PNG; the factor is then 1), replacing the copied extension's own (``exts``)."""
    if name not in maps:
        return None
    coat = COAT_MAPS[name]
    return channel_image(name, maps[name], coat.channel, (exts.get(CLEARCOAT) or {}).get(coat.slot))


def channel_image(name: str, values: np.ndarray, channel: int, old: Any) -> NewImage:
    """A scalar map as one channel of a linear RGB PNG (the others 0), the texture of a layer extension whose value
    it reads from that channel, replacing the copied extension's own ``old`` textureInfo."""
    pixels = np.zeros((*values.shape[:2], 3))
    pixels[..., channel] = values
    return NewImage(name, png(code(pixels, False)), "image/png", old)


def sheen_image(maps: dict[str, np.ndarray], exts: dict[str, Any]) -> NewImage | None:
    """``sheenColor`` and ``sheenRoughness`` maps as KHR_materials_sheen's textures, in one PNG as the extension
    reads them: the colour in its sRGB RGB, the roughness in its alpha (the factors are then 1), replacing the
    copied extension's own (``exts``)."""
    if "sheenColor" not in maps and "sheenRoughness" not in maps:
        return None
    shape = next(maps[k].shape[:2] for k in ("sheenColor", "sheenRoughness") if k in maps)
    rgba = np.full((*shape, 4), 255, dtype=np.uint8)
    if "sheenColor" in maps:
        rgba[..., :3] = code(maps["sheenColor"], True)
    if "sheenRoughness" in maps:
        rgba[..., 3] = code(maps["sheenRoughness"], False)
    else:
        rgba = rgba[..., :3]
    old = (exts.get(SHEEN) or {}).get("sheenColorTexture") or (exts.get(SHEEN) or {}).get("sheenRoughnessTexture")
    return NewImage("sheen", png(rgba), "image/png", old)


def transmission_image(maps: dict[str, np.ndarray], exts: dict[str, Any]) -> NewImage | None:
    """A ``transmission`` map as KHR_materials_transmission's ``transmissionTexture`` (its R channel of a linear
    PNG; the factor is then 1), replacing the copied extension's own (``exts``)."""
    if "transmission" not in maps:
        return None
    return channel_image("transmission", maps["transmission"], 0, (exts.get(TRANSMISSION) or {}).get(TRANSMISSION_MAP))


def normal_image(mat: dict[str, Any], normal: Path | None, source_normal: TextureRef | None) -> NewImage | None:
    """The result's normal map as a texture (a PNG or JPEG file as it is, anything else encoded as
    PNG), unless it is the source's own file used as stored (which the copy keeps)."""
    if normal is None:
        return None
    if source_normal is not None and source_normal.bake is None:
        if Path(normal).resolve() == source_normal.path.resolve():
            return None
    old = mat.pop("normalTexture", None)
    suffix = Path(normal).suffix.lower()
    if suffix in (".png", ".jpg", ".jpeg"):
        return NewImage("normal", Path(normal).read_bytes(), "image/png" if suffix == ".png" else "image/jpeg", old)
    from matremap.svbrdf.textures import read_image

    image, _ = read_image(normal, "linear", colour=False)
    return NewImage("normal", png(code(image[..., :3], False)), "image/png", old)


def carried_images(mat: dict[str, Any], carried: dict[str, CarriedInput]) -> list[NewImage]:
    """Write a non-glTF source's emission and occlusion into the material (factors now, textures returned):
    emission above 1 as emissiveFactor / its maximum x KHR_materials_emissive_strength."""
    images: list[NewImage] = []
    emission = carried.get("emission")
    if emission is not None:
        value = np.broadcast_to(np.asarray(emission.value if emission.value is not None else 1.0, float), (3,))
        if emission.texture is not None:
            tex, tex_f = split_factor(_rgb(texture_values(emission.texture)))
            value = value * np.asarray(tex_f)
            images.append(NewImage("emissive", png(code(tex, True)), "image/png", None))
        peak = float(value.max())
        if peak > 1.0:
            mat.setdefault("extensions", {})[EMISSIVE_STRENGTH] = {"emissiveStrength": peak}
            value = value / peak
        mat["emissiveFactor"] = [float(v) for v in value]
    occlusion = carried.get("occlusion")
    if occlusion is not None and occlusion.texture is not None:
        strength = float(np.asarray(occlusion.value if occlusion.value is not None else 1.0).reshape(-1)[0])
        occ = texture_values(occlusion.texture)[..., :1]
        images.append(NewImage("occlusion", png(code(occ, False)), "image/png", {"strength": min(max(strength, 0), 1)}))
    return images


def _rgb(a: np.ndarray) -> np.ndarray:
    return np.repeat(a[..., :1], 3, axis=-1) if a.shape[-1] < 3 else a[..., :3]


def write(out: str | os.PathLike, result: Any, source: MaterialAsset | None = None, force: bool = False) -> Path:
    """Write ``result`` (a ``gltf:metal-rough`` Material or MapSet) as ``out`` (.gltf or .glb).

    With a glTF ``source``: a copy of the source file (as ``out``'s kind) with its material replaced.
    Factors carry the uniform values; maps become new textures (PNG files beside a .gltf, buffer views
    in the BIN chunk of a .glb): baseColor (sRGB, alpha the carried opacity), roughness and metallic
    packed into one metallicRoughnessTexture (G and B, §3.9.2), specular (alpha) and specularColor (sRGB
    RGB) of KHR_materials_specular. KHR_materials_ior / KHR_materials_specular are written only where they
    differ from their defaults. The source's normal, occlusion and emissive textures are kept unless
    the result brings a normal map; textures the replaced material alone used are dropped. Without a glTF
    source, the material is written on a UV sphere with the carried inputs of ``source`` (any format).

    The file and the files beside it (textures, ``.bin``) are written together or not at all;
    existing files are replaced only with ``force``, and input files never.
    """
    out = Path(out)
    if out.suffix.lower() not in (".gltf", ".glb"):
        raise MatremapError(f"cannot write {out} as glTF: name it .gltf or .glb")
    consts, maps, normal, inputs = result_values(result)
    check_output(out, force)
    gdoc = source.document if source is not None and isinstance(source.document, GltfDocument) else None
    if source is not None and gdoc is not None:
        target = Target.copy_of(source.path, gdoc, [t.path for t in source.textures.values()])
        index, uv_set = source.index, gdoc.uv_set
    else:
        target = Target.spheres([source.name if source is not None else ""])
        index, uv_set = 0, 0
    rep = Replacement(
        index,
        consts,
        maps,
        normal,
        dict(source.carried) if source is not None else {},
        copied=gdoc is not None,
        source_normal=source.normal if source is not None else None,
        uv_set=uv_set,
        source_layered=gdoc is not None and source is not None and source.model == LAYERED_MODEL,
    )
    return commit(out, target, [rep], inputs, force)


def commit(out: Path, target: Target, reps: list[Replacement], inputs: list[Path], force: bool) -> Path:
    """Replace the materials ``reps`` in ``target`` and write it as ``out`` (.gltf with its new textures
    and .bin beside it, or .glb), all files or none; ``inputs`` (and the target's) are never overwritten."""
    kind, doc = out.suffix.lower(), target.json
    if target.base is not None:
        check_writable_source(target.inputs[0], doc, [r.index for r in reps])
    else:
        check_writable_source(out, doc, [r.index for r in reps])
    before = set().union(*(material_textures(doc["materials"][r.index]) for r in reps))
    images: list[NewImage] = []
    for rep in reps:
        for im in plan_material(doc, rep):
            im.material, im.stem = rep.index, (f"_{rep.index}" if len(reps) > 1 else "")
            images.append(im)
    bin_file = out.parent / f"{out.stem}.bin"
    planned = [out]
    if kind == ".gltf":
        planned += [out.parent / im.file_name(out) for im in images]
        planned += [bin_file] if target.bin is not None else []
    refuse_overwrites(out, planned, [*inputs, *target.inputs], force)
    if target.base is not None:
        confine_uris(doc, target.base, target.inputs[0])
    if target.base is not None and target.base.resolve() != out.parent.resolve():
        rebase_uris(doc, target.base, out.parent)
    if kind == ".glb" and images and target.bin is None:
        target.bin = add_bin_buffer(doc)
    blob: bytearray | None = bytearray(target.bin or b"")
    with AtomicFiles(force) as files:
        infos = add_images(doc, images, out, blob if kind == ".glb" else None, files, {r.index: r.uv_set for r in reps})
        for rep in reps:
            finish_material(doc, rep, infos.get(rep.index, {}))
        blob = drop_unused(doc, before, blob if target.bin is not None else None)
        if target.bin is not None and blob is not None:
            doc["buffers"][0]["byteLength"] = len(blob)
            if kind == ".gltf":
                doc["buffers"][0]["uri"] = quote(bin_file.name)
                files.write_bytes(bin_file, bytes(blob))
            else:
                doc["buffers"][0].pop("uri", None)
        update_extension_lists(doc)
        if kind == ".glb":
            files.write_bytes(out, glb_bytes(doc, bytes(blob) if target.bin is not None and blob is not None else None))
        else:
            files.write_bytes(out, json_bytes(doc))
    return out


def plan_material(doc: dict[str, Any], rep: Replacement) -> list[NewImage]:
    """Set the factors of material ``rep.index`` and drop the textures it replaces; returns the new
    textures, each for a slot (their textureInfos are set by :func:`finish_material`)."""
    mat = doc["materials"][rep.index]
    pbr = mat.setdefault("pbrMetallicRoughness", {})
    rep.old_spec = dict(mat.setdefault("extensions", {}).get(SPECULAR) or {})
    opacity = rep.carried.get("opacity")
    images = [
        base_colour_image(pbr, rep.consts, rep.maps, opacity),
        metallic_roughness_image(pbr, rep.consts, rep.maps),
    ]
    rep.spec_ext, spec_image = specular_image(rep.consts, rep.maps, rep.old_spec)
    images += [spec_image, normal_image(mat, rep.normal, rep.source_normal if rep.copied else None)]
    images += [coat_image(rep.maps, mat.get("extensions") or {}, slot) for slot in COAT_MAPS]
    images.append(sheen_image(rep.maps, mat.get("extensions") or {}))
    images.append(transmission_image(rep.maps, mat.get("extensions") or {}))
    if opacity is not None and not rep.copied:
        mat["alphaMode"] = "MASK" if opacity.settings.get("mode") == "mask" else "BLEND"
        if "cutoff" in opacity.settings:
            mat["alphaCutoff"] = float(opacity.settings["cutoff"])
    if not rep.copied:
        images += carried_images(mat, rep.carried)
    return [im for im in images if im is not None]


def finish_material(doc: dict[str, Any], rep: Replacement, infos: dict[str, dict[str, Any]]) -> None:
    """Point material ``rep.index`` at its new textures and set (or drop, at their defaults) its extensions."""
    mat = doc["materials"][rep.index]
    pbr, exts = mat["pbrMetallicRoughness"], mat["extensions"]
    if "baseColor" in infos:
        pbr["baseColorTexture"] = infos["baseColor"]
    if "metallicRoughness" in infos:
        pbr["metallicRoughnessTexture"] = {k: v for k, v in infos["metallicRoughness"].items() if k != "strength"}
    if "normal" in infos:
        mat["normalTexture"] = infos["normal"]
    if "emissive" in infos:
        mat["emissiveTexture"] = infos["emissive"]
    if "occlusion" in infos:
        mat["occlusionTexture"] = infos["occlusion"]
    ior = float(np.asarray(rep.consts["ior"]).reshape(-1)[0])
    if abs(ior - DEFAULT_IOR) > 1e-6:
        exts[IOR] = {"ior": ior}
    else:
        exts.pop(IOR, None)
    if rep.spec_ext:
        if "specular" in infos:
            slot = {k: v for k, v in infos["specular"].items() if k not in ("scale", "strength")}
            if "specular" in rep.maps:
                rep.spec_ext["specularTexture"] = dict(slot)
            if "specularColor" in rep.maps:
                rep.spec_ext["specularColorTexture"] = dict(slot)
        exts[SPECULAR] = rep.spec_ext
    else:
        exts.pop(SPECULAR, None)
    if "clearcoat" in rep.consts:
        slots = {COAT_MAPS[n].slot: infos[n] for n in COAT_MAPS if n in infos}
        if "sheen" in infos:  # one texture: the colour in its RGB, the roughness in its alpha
            slots |= {SHEEN_MAPS[n]: dict(infos["sheen"]) for n in SHEEN_MAPS if n in rep.maps}
        if "transmission" in infos:
            slots[TRANSMISSION_MAP] = infos["transmission"]
        layer_extensions(exts, rep.consts, keep_unread=rep.copied, layer_textures=slots)
    elif rep.source_layered:
        for name in (CLEARCOAT, SHEEN):
            exts.pop(name, None)
    exts.pop(SPEC_GLOSS, None)  # the result is its metallic-roughness conversion (formats/gltf_read.py)
    if not exts:
        mat.pop("extensions")
    if not pbr:
        mat.pop("pbrMetallicRoughness")


#: gltf:pbr's layer parameters, each written into the extension named (KHR_materials_*)
LAYER_EXTENSIONS = {
    "clearcoat": CLEARCOAT,
    "clearcoatRoughness": CLEARCOAT,
    "sheenColor": SHEEN,
    "sheenRoughness": SHEEN,
    "transmission": TRANSMISSION,
    "thickness": VOLUME,
    "attenuationDistance": VOLUME,
    "attenuationColor": VOLUME,
}


#: gltf:pbr's layer parameters the writer takes as maps (each into its extension's texture)
LAYER_MAPS = ("clearcoat", "clearcoatRoughness", *SHEEN_MAPS, "transmission")
#: the textures of a layer extension that hold none of its values: a copy of the source keeps them
KEPT_TEXTURES = {CLEARCOAT: "clearcoatNormalTexture", VOLUME: "thicknessTexture"}
#: the parameters this writer takes as numbers only: KHR_materials_ior has no texture, and the layer extensions'
#: textures are not written yet (but the coat's, :data:`LAYER_MAPS`)
CONSTANT_ONLY = ("ior", *(n for n in LAYER_EXTENSIONS if n not in LAYER_MAPS))


def layer_extensions(
    exts: dict[str, Any],
    consts: dict[str, Any],
    keep_unread: bool = False,
    layer_textures: dict[str, dict[str, Any]] | None = None,
) -> None:
    """Set (or drop, where the layer is off) the layer extensions of a ``gltf:pbr`` result's uniform values:
    KHR_materials_clearcoat (clearcoatFactor > 0), _sheen (a sheen colour not black), _transmission
    (transmissionFactor > 0) and _volume (thicknessFactor > 0; attenuationDistance 0 is glTF's default,
    infinity, so it is left out). The ratified READMEs' property names; a replaced extension loses the textures
    of its values (the result's values are uniform), not those of :data:`KEPT_TEXTURES`. ``keep_unread``: in a copy of a
    glTF source, a transmission or volume the result has off is the source's, which the reader does not read into
    gltf:pbr (only its coat and sheen): kept. ``layer_textures``: the textureInfos of the layer maps by slot
    (``clearcoatTexture``, ``clearcoatRoughnessTexture``, ``sheenColorTexture``, ``sheenRoughnessTexture``,
    ``transmissionTexture``; their factors are then 1)."""

    def one(name: str) -> float:
        return float(np.asarray(consts[name], dtype=float).reshape(-1)[0])

    def rgb(name: str) -> list[float]:
        return [float(x) for x in np.broadcast_to(np.asarray(consts[name], dtype=float), (3,))]

    given = layer_textures or {}
    factors = {m.slot: m.factor for m in COAT_MAPS.values()}
    coat = {**{factors[k]: 1.0 for k in given if k in factors}, **{k: v for k, v in given.items() if k in factors}}
    sheen_tex = {k: v for k, v in given.items() if k in SHEEN_MAPS.values()}
    sheen_factors = {
        **({"sheenColorFactor": [1.0, 1.0, 1.0]} if "sheenColorTexture" in sheen_tex else {}),
        **({"sheenRoughnessFactor": 1.0} if "sheenRoughnessTexture" in sheen_tex else {}),
    }
    through: dict[str, Any] | None = {"transmissionFactor": one("transmission")} if one("transmission") > 0 else None
    if TRANSMISSION_MAP in given:  # a weight map: its values in the texture, the factor 1
        through = {"transmissionFactor": 1.0, TRANSMISSION_MAP: given[TRANSMISSION_MAP]}
    values: dict[str, dict[str, Any] | None] = {
        CLEARCOAT: {
            "clearcoatFactor": one("clearcoat"),
            "clearcoatRoughnessFactor": one("clearcoatRoughness"),
            **(coat or {}),
        }
        if one("clearcoat") > 0 or "clearcoatTexture" in (coat or {})
        else None,
        SHEEN: {
            "sheenColorFactor": rgb("sheenColor"),
            "sheenRoughnessFactor": one("sheenRoughness"),
            **sheen_factors,
            **sheen_tex,
        }
        if max(rgb("sheenColor")) > 0 or "sheenColorTexture" in sheen_tex
        else None,
        TRANSMISSION: through,
        VOLUME: {
            "thicknessFactor": one("thickness"),
            "attenuationColor": rgb("attenuationColor"),
            **({"attenuationDistance": one("attenuationDistance")} if one("attenuationDistance") > 0 else {}),
        }
        if one("thickness") > 0
        else None,
    }
    for name, ext in values.items():
        if ext is not None:
            # no values of the layer, so a copy keeps them: the coat's own normal map (matremap's coats use the
            # base's), a volume's thickness texture (a rasteriser's stand-in for the path length the geometry gives)
            slot = KEPT_TEXTURES.get(name)
            own = (exts.get(name) or {}).get(slot) if slot is not None else None
            exts[name] = ext if own is None else {**ext, str(slot): own}
        elif not (keep_unread and name in (TRANSMISSION, VOLUME)):
            exts.pop(name, None)


__all__ = [
    "CONSTANT_ONLY",
    "commit",
    "finish_material",
    "layer_extensions",
    "plan_material",
    "result_values",
    "texture_values",
    "write",
]
