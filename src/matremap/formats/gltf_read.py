"""One glTF 2.0 material read as a ``gltf:metal-rough`` asset: factors, textures, extensions, carried inputs.

References are to the glTF 2.0 specification (Khronos, version 2.0.1, 2021):

* §3.9.2 "Metallic-Roughness Material": ``baseColorFactor`` (linear RGBA, default 1) times the
  ``baseColorTexture`` (sRGB-encoded); ``metallicFactor`` / ``roughnessFactor`` (default 1) times
  the blue / green channels of the linear ``metallicRoughnessTexture`` (red and alpha unused);
* §3.9.3 "Additional Textures": ``normalTexture`` (tangent space), ``occlusionTexture`` (R channel,
  ``strength`` in [0, 1], default 1), ``emissiveTexture`` (sRGB) times ``emissiveFactor`` (default 0);
* §3.9.4 "Alpha Coverage": ``alphaMode`` OPAQUE (alpha ignored, the default), MASK (``alphaCutoff``,
  default 0.5) or BLEND; alpha is ``baseColorFactor[3]`` times the base colour texture's alpha;
* the material extensions of :mod:`matremap.formats.gltf_extensions` (ior and specular drive the model,
  emissive strength multiplies the emission, the layers are recorded and reported; a
  KHR_materials_pbrSpecularGlossiness material is converted to metallic-roughness by the extension's formulas,
  :func:`~matremap.formats.gltf_extensions.spec_gloss_values`, its textures per texel, and read in place of the
  metallic-roughness fallback beside it, which its README says a client supporting it does not draw).

Textures are resolved by :mod:`matremap.formats.gltf_textures` (samplers, KHR_texture_transform, UV sets):
a transformed texture is baked onto the map set's UVs. A map set has one UV set, so the remapped textures
(base colour, metallic-roughness, specular, normal) must share one; a material whose remapped textures
use two sets is refused, one whose textures all use another set than TEXCOORD_0 is read on that set with
a note (every written file lays the maps on the UVs the material's own meshes use for them).

Emission, occlusion and opacity are *carried* (:class:`~matremap.formats.asset.CarriedInput`): passed to
the writer unchanged, which writes them where its format has a slot.
"""

from __future__ import annotations

import os
import tempfile
from glob import escape as glob_escape
from pathlib import Path
from typing import Any

import numpy as np

from matremap.core.atomic import temp_prefix
from matremap.core.imageio import oiio_name
from matremap.core.material import Material
from matremap.errors import MatremapError
from matremap.formats.asset import CarriedInput, MaterialAsset, TextureRef
from matremap.formats.bake import resampled_note, shared_size
from matremap.formats.confine import Confinement
from matremap.formats.gltf_container import (
    FileReader,
    GltfDocument,
    cache_dir,
    digest_matches,
    file_digest,
    parse_container,
)
from matremap.formats.gltf_coverage import material_coverage
from matremap.formats.gltf_extensions import (
    CLEARCOAT,
    COAT_MAPS,
    EMISSIVE_STRENGTH,
    IOR,
    LAYERED_MODEL,
    SCHEMAS,
    SHEEN,
    SHEEN_MAPS,
    SPEC_GLOSS,
    SPECULAR,
    TRANSMISSION,
    TRANSMISSION_MAP,
    check_texture_info,
    extension_notes,
    layer_values,
    lost_look,
    read_extensions,
    spec_gloss_values,
)
from matremap.formats.gltf_textures import (
    TRANSFORM,
    SlotTexture,
    as_dict,
    baked,
    baked_normal,
    finite_numbers,
    sampler_wrap,
    transform_matrix,
)

MODEL = "gltf:metal-rough"
DEFAULT_IOR = 1.5


def without_alpha(path: Path) -> Path:
    """A copy of an image with alpha, without it, in the cache folder.

    PNG stores colour unassociated with alpha (§3.8.2 images are PNG or JPEG); OpenImageIO
    premultiplies colour by alpha on read unless told otherwise, which would darken base colours
    and packed channels wherever alpha < 1. The copy keeps the stored colour values; it is made band by
    band (memory does not grow with the image). It lives in the folder of the image's own content and
    carries its digest in its name, checked when reused."""
    import OpenImageIO as oiio

    folder = cache_dir(path)
    for f in sorted(folder.glob(f"{glob_escape(path.stem)}-rgb-*.png")):
        if digest_matches(f, f.stem.rsplit("-", 1)[-1]):
            return f
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    inp = oiio.ImageInput.open(oiio_name(path), config)
    if inp is None:
        raise MatremapError(f"cannot read {path}: {oiio.geterror().strip()}; re-export it as PNG or JPEG")
    try:
        tmp = _colour_copy(path, inp, folder)
    finally:
        inp.close()
    try:
        final = folder / f"{path.stem}-rgb-{file_digest(tmp)[:16]}.png"
        if not digest_matches(final, final.stem.rsplit("-", 1)[-1]):
            os.replace(tmp, final)
    finally:
        if tmp.exists():
            tmp.unlink()
    return final


def _colour_copy(path: Path, inp: Any, folder: Path) -> Path:
    """The colour channels of the open image ``inp`` (of ``path``) written as a PNG under a marked temporary
    name in ``folder`` (see clean_stale), rows in bands of about a million texels."""
    import OpenImageIO as oiio

    spec = inp.spec()
    fmt = oiio.UINT16 if str(spec.format) == "uint16" else oiio.UINT8
    keep = 3 if spec.nchannels == 4 else 1
    fd, name = tempfile.mkstemp(prefix=temp_prefix("tmp", "rgb"), suffix=".png", dir=folder)
    os.close(fd)
    tmp = Path(name)
    try:
        out = oiio.ImageOutput.create(oiio_name(name))
        if out is None or not out.open(oiio_name(name), oiio.ImageSpec(spec.width, spec.height, keep, fmt)):
            raise MatremapError(f"cannot write an alpha-free copy of {path} in {folder}: {oiio.geterror().strip()}")
        rows = max(1, (1 << 20) // max(spec.width, 1))
        try:
            for y0 in range(0, spec.height, rows):
                y1 = min(spec.height, y0 + rows)
                pixels = inp.read_scanlines(0, 0, y0, y1, 0, 0, keep, fmt)
                if pixels is None or not isinstance(pixels, np.ndarray):
                    raise MatremapError(f"cannot read {path}: the image is corrupt; re-export it")
                out.write_scanlines(y0, y1, 0, np.ascontiguousarray(pixels.reshape(y1 - y0, spec.width, keep)))
        finally:
            out.close()
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return tmp


def select(path: Path, materials: list[Any], material: str | int | None) -> int:
    """The index of the material named or numbered ``material`` (the first when None)."""
    names = [m.get("name") if isinstance(m, dict) else None for m in materials]
    if material is None:
        return 0
    if isinstance(material, str) and material in names:
        return names.index(material)
    idx: int | None = None
    if isinstance(material, int) and not isinstance(material, bool):
        idx = material
    elif isinstance(material, str) and material.strip().lstrip("-").isdigit():
        idx = int(material)
    if idx is not None and 0 <= idx < len(materials):
        return idx
    listing = ", ".join(f"{i}: {n!r}" if n else f"{i}: (unnamed)" for i, n in enumerate(names))
    raise MatremapError(f"{path} has no material {material!r}; its materials are {listing} (pick one by name or index)")


def number(path: Path, where: str, value: Any, default: Any, size: int = 1) -> Any:
    """``value`` as a float (or ``size`` floats), ``default`` when None; anything else is refused."""
    if value is None:
        return default
    vals = finite_numbers(value, size)
    if vals is None:
        raise MatremapError(
            f"{path}: {where} must be {'a number' if size == 1 else f'{size} numbers'}, got {value!r}; fix the file"
        )
    return vals if size > 1 else vals[0]


def read_materials(p: Path) -> tuple[bytes, dict[str, Any], bytes | None, list[Any]]:
    """The file's bytes, its JSON, its binary chunk and its (non-empty) material list."""
    if not p.is_file():
        raise MatremapError(f"{p} not found")
    data = p.read_bytes()
    obj, bin_chunk = parse_container(p, data)
    mats = obj.get("materials")
    if not isinstance(mats, list) or not mats:
        raise MatremapError(f"{p} has no materials; export it with its materials")
    return data, obj, bin_chunk, mats


def material_names(path: str | os.PathLike) -> list[str]:
    """The names of a file's materials, in order ("material N" for an unnamed one)."""
    mats = read_materials(Path(path))[3]
    names = [m.get("name") if isinstance(m, dict) else None for m in mats]
    return [n if isinstance(n, str) and n else f"material {i}" for i, n in enumerate(names)]


def read(
    path: str | os.PathLike, material: str | int | None = None, *, confinement: Confinement | None = None
) -> MaterialAsset:
    """Read one material of a ``.gltf`` / ``.glb`` file as a ``gltf:metal-rough`` asset.

    ``material``: a name or an index (the first material by default). Textures become
    :class:`TextureRef`: base colour (sRGB, RGB, times baseColorFactor), roughness and metallic
    (green and blue of the metallicRoughnessTexture, §3.9.2), specular (alpha of specularTexture) and
    specularColor (sRGB RGB of specularColorTexture) of KHR_materials_specular; the normal map as
    ``asset.normal``; transformed ones baked. Emission, occlusion and opacity go into ``asset.carried``;
    the layer extensions into ``asset.document.extensions``, ``asset.notes`` and ``asset.lost``. External
    images and buffers must lie in the file's folder or a folder ``confinement`` allows.
    """
    p = Path(path)
    data, obj, bin_chunk, mats = read_materials(p)
    doc = GltfDocument(obj, bin_chunk, p.suffix.lower() == ".glb", p.parent)
    idx = select(p, mats, material)
    m = mats[idx]
    if not isinstance(m, dict):
        raise MatremapError(f"{p}: materials[{idx}] is not an object; the file is broken, re-export it")
    given = m.get("name")
    name = given if isinstance(given, str) and given else f"material {idx}"
    notes: list[str] = []
    if material is None and len(mats) > 1:
        notes.append(f"{p.name} has {len(mats)} materials; using the first, {name!r} (choose another by name or index)")
    where = f"material {name!r}"
    pbr, ext = m.get("pbrMetallicRoughness") or {}, m.get("extensions") or {}
    if not isinstance(pbr, dict) or not isinstance(ext, dict):
        raise MatremapError(f"{p}: {where} has a malformed pbrMetallicRoughness or extensions; re-export the file")
    n_textures = len(obj["textures"]) if isinstance(obj.get("textures"), list) else 0
    found = read_extensions(p, where, ext, n_textures)
    doc.extensions = found
    pbr, constants = base_values(p, where, pbr, found, notes)
    reader = FileReader(p, doc, data, confinement)
    textures = MaterialTextures(reader, where, notes)
    layers = layer_values(found)
    maps = textures.read_base_maps(pbr, found, constants)
    maps |= textures.read_layer_maps(found, layers)
    normal = textures.read_normal(m)
    maps, normal = textures.at_one_size(maps, normal)
    doc.uv_set = textures.uv_set
    if normal is not None and not maps:
        notes.append(
            "normalTexture on a material with no other texture: it is converted as a uniform material, so only a "
            "glTF output keeps the normal map"
        )
    coverage = material_coverage(reader, idx, textures.uv_set) if maps else None
    carried = textures.read_carried(m, pbr, found)
    notes += extension_notes(found, textured=bool(maps))
    note_unknown(ext, obj, notes)
    # a coat or sheen carrying the look: read into gltf:pbr, where it is fitted (over textured maps: fitted once
    # and held through the sweep); a layer with textures of its own stays in asset.lost
    layers, lost = layer_values(found, textured=bool(maps)), lost_look(found)
    if layers:
        constants |= layers
        lost = [w for w in lost if not w.startswith(SHEEN)]
        lost = [w for w in lost if "transmission" not in layers or not w.startswith(TRANSMISSION)]
    lost += [f"{workflow} ({why})" for workflow, why in WORKFLOWS.items() if workflow in ext]
    return MaterialAsset(
        path=p,
        format="gltf",
        name=name,
        model=LAYERED_MODEL if layers else MODEL,
        constants=constants,
        textures=maps,
        normal=normal,
        notes=notes,
        document=doc,
        index=idx,
        lost=lost,
        carried=carried,
        dropped=dropped_extensions(ext),
        coverage=coverage,
    )


#: material extensions that replace the lit metallic-roughness workflow -> what that means for a conversion (the
#: material is lost: copied onto its own model, refused for others)
WORKFLOWS = {
    "KHR_materials_unlit": "an unlit material: no lit model draws it; use its base colour as an emission instead",
}


def base_values(
    path: Path, where: str, pbr: dict[str, Any], found: dict[str, dict[str, Any]], notes: list[str]
) -> tuple[dict[str, Any], dict[str, Any]]:
    """The material's pbrMetallicRoughness (its base colour and alpha) and uniform values: a
    KHR_materials_pbrSpecularGlossiness material's conversion (the extension's material is the one drawn; the
    fallback beside it is not read), else :func:`read_factors`."""
    sg = found.get(SPEC_GLOSS)
    if sg is None:
        return pbr, read_factors(path, where, pbr, found)
    base = {"baseColorFactor": sg["diffuseFactor"]}
    if "diffuseTexture" in sg:
        base["baseColorTexture"] = sg["diffuseTexture"]
    notes.append(spec_gloss_note(sg, found))
    return base, read_factors(path, where, {}, {}) | spec_gloss_values(sg)


def spec_gloss_note(sg: dict[str, Any], found: dict[str, dict[str, Any]]) -> str:
    """The note of a KHR_materials_pbrSpecularGlossiness material converted to metallic-roughness."""
    v = spec_gloss_values(sg)
    tex = [k for k in ("diffuseTexture", "specularGlossinessTexture") if k in sg]
    replaced = [e for e in (IOR, SPECULAR) if e in found]
    if v["metallic"] == 1.0:
        return (
            f"{SPEC_GLOSS} converted by its README's formulas: no light reaches its diffuse (c_diff = diffuse (1 - "
            f"max specular) = 0), so it is the metal of baseColor = specular {[round(x, 4) for x in v['baseColor']]}, "
            f"roughness = 1 - glossiness = {v['roughness']:.4g}; a glTF output gets the metallic-roughness material "
            "without the extension"
        )
    return (
        f"{SPEC_GLOSS} converted by its README's formulas: diffuse -> baseColor "
        f"{[round(x, 4) for x in v['baseColor']]}, "
        f"specular {[round(x, 4) for x in sg['specularFactor']]} -> F0 (metallic 0, ior 1.5, specularColor = "
        f"specular / 0.04), roughness = 1 - glossiness = {v['roughness']:.4g}"
        + (f"; {' and '.join(tex)} converted per texel" if tex else "")
        + (f"; {', '.join(replaced)} beside it replaced" if replaced else "")
        + "; a glTF output gets the metallic-roughness material without the extension"
    )


#: the material extensions that change the look and that no model here converts -> the property that turns each on
#: (default 0 in each ratified README) and what it draws; a dispersion shows only through a refracting transmission
LOOKS = {
    "KHR_materials_anisotropy": ("anisotropyStrength", "an anisotropic highlight"),
    "KHR_materials_iridescence": ("iridescenceFactor", "a thin-film iridescence"),
    "KHR_materials_diffuse_transmission": ("diffuseTransmissionFactor", "light diffused through a thin surface"),
    "KHR_materials_dispersion": ("dispersion", "a glass's colour fringes"),
}

#: the extensions of :data:`LOOKS` the gate's ``dropped`` check counts (on: their factor above 0). Not a dispersion
#: (OpenPBR's transmission_dispersion_*): colour fringes at a glass's edges, noted, as OpenPBR's glass example's
#: Abbe 64 is
DROPPED = {name: factor for name, (factor, _) in LOOKS.items() if name != "KHR_materials_dispersion"}


def dropped_extensions(ext: dict[str, Any]) -> list[str]:
    """The extensions of :data:`DROPPED` a material has on (their factor above 0), as ``extension factor``: a glTF copy
    keeps them (the copy leaves them alone), any other target loses them."""
    out = []
    for name, factor in DROPPED.items():
        e = ext.get(name)
        if not isinstance(e, dict):
            continue
        v = e.get(factor, 0.0)
        if isinstance(v, (int, float)) and not isinstance(v, bool) and v > 0:
            out.append(f"{name} {factor} {v:g}")
    return out


def read_factors(path: Path, where: str, pbr: dict[str, Any], found: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """The material's uniform values: the pbrMetallicRoughness factors, KHR_materials_ior's ior and
    KHR_materials_specular's factors (each at its default when absent), checked against the model."""
    base = number(path, f"{where} baseColorFactor", pbr.get("baseColorFactor"), [1.0] * 4, 4)
    constants: dict[str, Any] = {
        "baseColor": base[:3],
        "metallic": number(path, f"{where} metallicFactor", pbr.get("metallicFactor"), 1.0),
        "roughness": number(path, f"{where} roughnessFactor", pbr.get("roughnessFactor"), 1.0),
    }
    constants["ior"] = found.get(IOR, {}).get("ior", DEFAULT_IOR)
    if constants["ior"] == 0.0:
        raise MatremapError(
            f"{path}: {where} has {IOR} ior 0 (full specular), which gltf:metal-rough cannot express; "
            f"give it an ior in [1, 5]"
        )
    spec = found.get(SPECULAR, {})
    constants["specular"] = spec.get("specularFactor", 1.0)
    constants["specularColor"] = spec.get("specularColorFactor", [1.0] * 3)
    try:
        Material.create(MODEL, constants)
    except MatremapError as e:
        raise MatremapError(f"{path}: {where}: {e}; fix the value in the file") from None
    return constants


def channel(c: int, nch: int) -> int:
    """File channel of glTF colour channel c (0 R, 1 G, 2 B) in a file of ``nch`` channels: grey files replicate."""
    return c if nch >= 3 else 0


def alpha_channel(nch: int) -> int | None:
    """File channel of glTF's alpha in a file of ``nch`` channels; None when it has no alpha."""
    return {4: 3, 2: 1}.get(nch)


class MaterialTextures:
    """Reads the textures of one material (``where`` names it in messages) into TextureRefs, baking
    transformed ones; keeps the UV set the remapped textures use (:attr:`uv_set`)."""

    def __init__(self, reader: FileReader, where: str, notes: list[str]) -> None:
        self.reader, self.where, self.notes = reader, where, notes
        self.uv_sets: dict[str, int] = {}
        #: the textures each TextureRef made here was read from, with whether it was decoded from sRGB
        self.sources: list[tuple[TextureRef, SlotTexture, bool]] = []
        #: the roughness maps read from a glossiness (id of the TextureRef -> its glossinessFactor)
        self.glossiness: dict[int, float] = {}

    @property
    def uv_set(self) -> int:
        """The UV set of the remapped textures (0 when there are none)."""
        return next(iter(self.uv_sets.values()), 0)

    def file(self, info: Any, slot: str) -> SlotTexture:
        """The image, sampler, UV set and transform of a textureInfo."""
        r, p, where = self.reader, self.reader.path, self.where
        n_textures = len(r.doc.json["textures"]) if isinstance(r.doc.json.get("textures"), list) else 0
        info = check_texture_info(p, f"{where} {slot}", info, n_textures)
        tex = r.item("textures", info["index"], f"{where} {slot}")
        src = tex.get("source")
        if src is None:  # an extension may give the only source (EXT_texture_webp, KHR_texture_basisu)
            src = next((e["source"] for e in as_dict(tex.get("extensions")).values() if "source" in as_dict(e)), None)
        if src is None:
            raise MatremapError(
                f"{p}: {where} {slot} uses textures[{info['index']}], which has no image source; re-export the file"
            )
        f = r.image(src, f"{where} {slot}")
        matrix, uv_override = None, None
        if TRANSFORM in as_dict(info.get("extensions")):
            matrix, uv_override = transform_matrix(p, f"{where} {slot}", info["extensions"][TRANSFORM])
        wrap = sampler_wrap(p, r.doc.json, tex, f"{where} {slot}")
        uv = uv_override if uv_override is not None else info.get("texCoord", 0)
        from matremap.svbrdf.textures import image_info

        info = image_info(f, "linear", colour=False)
        return SlotTexture(slot, f, info.channels, uv, wrap, matrix, f in r.extracted, (info.height, info.width))

    def remapped(self, info: Any, slot: str) -> SlotTexture:
        """:meth:`file` of a texture the model is remapped from: its UV set must be the others'."""
        tex = self.file(info, slot)
        for other, uv in self.uv_sets.items():
            if uv != tex.uv_set:
                raise MatremapError(
                    f"{self.reader.path}: {self.where}: {other} uses TEXCOORD_{uv} and {slot} TEXCOORD_{tex.uv_set}; "
                    f"a map set has one UV set, so these textures cannot be converted together (re-export them on "
                    f"one UV set)"
                )
        self.uv_sets[slot] = tex.uv_set
        return tex

    def ref(self, tex: SlotTexture, channels: tuple[int, ...], srgb: bool, scale: Any) -> TextureRef:
        """A parameter's TextureRef: the file as it is, an alpha-free copy for colour channels of an
        image with alpha, or a bake when a transform moves the lookup."""
        colorspace = "srgb" if srgb else "linear"
        if tex.transform is not None:
            self.note_baked(tex)
            ref = TextureRef(tex.path, channels, colorspace, scale, tex.extracted, bake=baked(tex, srgb))
        else:
            f, extracted = tex.path, tex.extracted
            if tex.channels in (2, 4) and max(channels) < tex.channels - 1:
                f, extracted = without_alpha(tex.path), True
            ref = TextureRef(f, channels, colorspace, scale, extracted)
        self.sources.append((ref, tex, srgb))
        return ref

    def read_maps(
        self, pbr: dict[str, Any], spec_ext: dict[str, Any], constants: dict[str, Any]
    ) -> dict[str, TextureRef]:
        """The parameters' textures, each scaled by its factor in ``constants``: base colour,
        roughness and metallic (one packed texture), specular and specularColor."""
        textures: dict[str, TextureRef] = {}
        if "baseColorTexture" in pbr:
            tex = self.remapped(pbr["baseColorTexture"], "baseColorTexture")
            rgb = tuple(channel(c, tex.channels) for c in range(3))
            textures["baseColor"] = self.ref(tex, rgb, True, tuple(constants["baseColor"]))
        if "metallicRoughnessTexture" in pbr:
            tex = self.remapped(pbr["metallicRoughnessTexture"], "metallicRoughnessTexture")
            textures["roughness"] = self.ref(tex, (channel(1, tex.channels),), False, constants["roughness"])
            textures["metallic"] = self.ref(tex, (channel(2, tex.channels),), False, constants["metallic"])
        if "specularTexture" in spec_ext:
            tex = self.remapped(spec_ext["specularTexture"], "specularTexture")
            a = alpha_channel(tex.channels)
            if a is None:
                self.notes.append(
                    "specularTexture has no alpha channel, so it is 1 everywhere; using specularFactor alone"
                )
            else:
                textures["specular"] = self.ref(tex, (a,), False, constants["specular"])
        if "specularColorTexture" in spec_ext:
            tex = self.remapped(spec_ext["specularColorTexture"], "specularColorTexture")
            rgb = tuple(channel(c, tex.channels) for c in range(3))
            textures["specularColor"] = self.ref(tex, rgb, True, tuple(constants["specularColor"]))
        if self.uv_set != 0:
            self.notes.append(
                f"the textures use TEXCOORD_{self.uv_set}: the maps are laid on that UV set (a glTF output keeps it)"
            )
        return textures

    def read_base_maps(
        self, pbr: dict[str, Any], found: dict[str, dict[str, Any]], constants: dict[str, Any]
    ) -> dict[str, TextureRef]:
        """The base's maps: :meth:`read_spec_gloss_maps` of a KHR_materials_pbrSpecularGlossiness material, else
        :meth:`read_maps`."""
        if SPEC_GLOSS in found:
            return self.read_spec_gloss_maps(found[SPEC_GLOSS], constants)
        return self.read_maps(pbr, found.get(SPECULAR, {}), constants)

    def read_spec_gloss_maps(self, sg: dict[str, Any], constants: dict[str, Any]) -> dict[str, TextureRef]:
        """KHR_materials_pbrSpecularGlossiness's textures as gltf:metal-rough maps, per texel as
        :func:`~matremap.formats.gltf_extensions.spec_gloss_values` converts its factors: ``baseColor`` the sRGB RGB
        of diffuseTexture times diffuseFactor, ``specularColor`` the sRGB RGB of specularGlossinessTexture times
        specularFactor / 0.04, ``roughness`` 1 - glossinessFactor times its linear alpha (an image without alpha
        has glossiness 1 there: the factor alone, noted)."""
        maps: dict[str, TextureRef] = {}
        if "diffuseTexture" in sg:
            tex = self.remapped(sg["diffuseTexture"], f"{SPEC_GLOSS}.diffuseTexture")
            rgb = tuple(channel(c, tex.channels) for c in range(3))
            maps["baseColor"] = self.ref(tex, rgb, True, tuple(constants["baseColor"]))
        if "specularGlossinessTexture" in sg:
            slot = f"{SPEC_GLOSS}.specularGlossinessTexture"
            tex = self.remapped(sg["specularGlossinessTexture"], slot)
            rgb = tuple(channel(c, tex.channels) for c in range(3))
            maps["specularColor"] = self.ref(tex, rgb, True, tuple(constants["specularColor"]))
            a = alpha_channel(tex.channels)
            if a is None:
                self.notes.append(
                    "specularGlossinessTexture has no alpha channel, so its glossiness is 1 everywhere; using "
                    "glossinessFactor alone"
                )
            else:
                gloss = float(sg["glossinessFactor"])
                ref = TextureRef(
                    tex.path, (a,), "linear", 1.0, tex.extracted, bake=roughness_from_glossiness(tex, gloss)
                )
                self.sources.append((ref, tex, False))
                self.glossiness[id(ref)] = gloss
                maps["roughness"] = ref
        return maps

    def read_layer_map(self, info: dict[str, Any], slot: str, c: int, factor: float) -> TextureRef:
        """A layer extension's texture (KHR_materials_clearcoat: ``clearcoatTexture`` R, the coat's weight;
        ``clearcoatRoughnessTexture`` G, its roughness), channel ``c`` times its factor."""
        tex = self.remapped(info, slot)
        return self.ref(tex, (channel(c, tex.channels),), False, factor)

    def read_layer_maps(self, found: dict[str, dict[str, Any]], layers: dict[str, Any]) -> dict[str, TextureRef]:
        """The maps of the layers read into gltf:pbr (``layers``): a coat mask (R of clearcoatTexture) and a coat
        roughness map (G of its texture); a sheen's colour and roughness maps (:meth:`read_sheen_maps`); a
        transmission weight map (R of transmissionTexture)."""
        maps: dict[str, TextureRef] = {}
        if "clearcoat" in layers:
            for name, coat in COAT_MAPS.items():
                if coat.slot in found[CLEARCOAT]:
                    maps[name] = self.read_layer_map(found[CLEARCOAT][coat.slot], coat.slot, coat.channel, layers[name])
        if "sheenColor" in layers:
            maps |= self.read_sheen_maps(found[SHEEN])
        if "transmission" in layers and TRANSMISSION_MAP in found[TRANSMISSION]:
            info = found[TRANSMISSION][TRANSMISSION_MAP]
            maps["transmission"] = self.read_layer_map(info, TRANSMISSION_MAP, 0, layers["transmission"])
        return maps

    def read_sheen_maps(self, sheen: dict[str, Any]) -> dict[str, TextureRef]:
        """KHR_materials_sheen's textures as maps: ``sheenColor`` the sRGB RGB of sheenColorTexture times
        sheenColorFactor, ``sheenRoughness`` the alpha of sheenRoughnessTexture times sheenRoughnessFactor (an
        image without alpha is 1 there: the factor alone, noted)."""
        maps: dict[str, TextureRef] = {}
        for name, slot in SHEEN_MAPS.items():
            if slot not in sheen:
                continue
            tex = self.remapped(sheen[slot], f"{SHEEN}.{slot}")
            if name == "sheenColor":
                rgb = tuple(channel(c, tex.channels) for c in range(3))
                maps[name] = self.ref(tex, rgb, True, tuple(sheen["sheenColorFactor"]))
                continue
            a = alpha_channel(tex.channels)
            if a is None:
                self.notes.append(f"{slot} has no alpha channel, so it is 1 everywhere; using sheenRoughnessFactor")
            else:
                maps[name] = self.ref(tex, (a,), False, sheen["sheenRoughnessFactor"])
        return maps

    def read_normal(self, m: dict[str, Any]) -> TextureRef | None:
        """The normal map (its scale is noted, not applied); a transformed one is baked and turned."""
        if "normalTexture" not in m:
            return None
        tex = self.remapped(m["normalTexture"], "normalTexture")
        scale = number(self.reader.path, f"{self.where} normalTexture.scale", m["normalTexture"].get("scale"), 1.0)
        if scale != 1:
            self.notes.append(f"normalTexture scale {scale:g} ignored; the normal map is used as stored (scale 1)")
        if tex.transform is not None:
            self.note_baked(tex)
            ref = TextureRef(tex.path, None, "linear", 1.0, tex.extracted, bake=baked_normal(tex))
        else:
            ref = TextureRef(tex.path, None, "linear", 1.0, tex.extracted)
        self.sources.append((ref, tex, False))
        return ref

    def at_one_size(
        self, maps: dict[str, TextureRef], normal: TextureRef | None
    ) -> tuple[dict[str, TextureRef], TextureRef | None]:
        """The remapped textures and the normal map at one size, as a map set needs them: the largest any of
        them needs to keep its texels (a texture tiled 7 times asks for 7 times its size; :attr:`SlotTexture.need`),
        capped at :data:`~matremap.formats.bake.MAX_SIDE` per side; one of another size is resampled there
        (bilinearly, glTF's linear filter, its transform and wrap applied), with a note. glTF gives each
        texture its own size and transform (§3.8.4; KHR_texture_transform), so a material's textures often
        differ (Khronos SheenChair: a 512² fabric albedo tiled 7 times beside a 1024² normal map tiled twice)."""
        used = [r for r in (*maps.values(), normal) if r is not None]
        slots = {id(ref): (tex, srgb) for ref, tex, srgb in self.sources if any(ref is u for u in used)}
        if not slots:
            return maps, normal
        need = [tex.need for tex, _ in slots.values()]
        size = shared_size(need)
        if all(tex.size == size for tex, _ in slots.values()):
            return maps, normal

        def sized(ref: TextureRef) -> TextureRef:
            tex, srgb = slots[id(ref)]
            if tex.size == size:
                return ref
            if id(ref) in self.glossiness:
                bake = roughness_from_glossiness(tex, self.glossiness[id(ref)], size)
            else:
                bake = baked_normal(tex, size) if ref is normal else baked(tex, srgb, size)
            return TextureRef(tex.path, ref.channels, ref.colorspace, ref.scale, tex.extracted, bake=bake)

        resampled = sorted({tex.slot for tex, _ in slots.values() if tex.size != size})
        if resampled:
            self.notes.append(resampled_note(resampled, size, need))
        return {k: sized(r) for k, r in maps.items()}, sized(normal) if normal is not None else None

    def note_baked(self, tex: SlotTexture) -> None:
        """Note (once per slot) that a transformed texture is baked onto the maps' UVs."""
        note = f"{tex.slot}: {TRANSFORM} and the sampler's wrap ({'/'.join(tex.wrap)}) baked into the map"
        if tex.slot.startswith("normal"):
            note += " (its tangent-space x, y turned with the transform)"
        if note not in self.notes:
            self.notes.append(note)

    def carried_texture(self, info: Any, slot: str, channels: tuple[int, ...] | None, srgb: bool) -> TextureRef | None:
        """A carried input's texture on the maps' UV set (None, with a note, when it uses another set);
        ``channels`` None: the texture's colour, its RGB (a grey or grey-alpha image's grey three times, as PNG
        decoders and glTF viewers expand it; an alpha channel is not colour)."""
        tex = self.file(info, slot)
        if tex.uv_set != self.uv_set:
            self.notes.append(
                f"{slot} uses TEXCOORD_{tex.uv_set} and the maps TEXCOORD_{self.uv_set}: a glTF output keeps it as "
                f"it is; other formats get its factor without the texture (a map set has one UV set)"
            )
            return None
        colour = (0, 1, 2) if tex.channels >= 3 else (0, 0, 0)
        return self.ref(tex, channels or colour, srgb, 1.0)

    def read_carried(
        self, m: dict[str, Any], pbr: dict[str, Any], found: dict[str, dict[str, Any]]
    ) -> dict[str, CarriedInput]:
        """Emission, occlusion and opacity (§3.9.3, §3.9.4), each with a note."""
        p, where = self.reader.path, self.where
        carried: dict[str, CarriedInput] = {}
        factor = number(p, f"{where} emissiveFactor", m.get("emissiveFactor"), [0.0] * 3, 3)
        strength = found.get(EMISSIVE_STRENGTH, {}).get("emissiveStrength", 1.0)
        if min(factor) < 0:
            raise MatremapError(f"{p}: {where} emissiveFactor must be 3 numbers >= 0, got {factor}; fix the file")
        if max(factor) > 0 and strength > 0:
            value = tuple(float(f * strength) for f in factor)
            texture = None
            if "emissiveTexture" in m:
                texture = self.carried_texture(m["emissiveTexture"], "emissiveTexture", None, True)
            carried["emission"] = CarriedInput(value, texture, {"factor": factor, "strength": strength})
            self.notes.append(
                f"emission: emissiveFactor {factor}"
                + (f" x {EMISSIVE_STRENGTH} {strength:g}" if strength != 1 else "")
                + (" x emissiveTexture" if texture is not None else "")
                + " is carried over as it is (not remapped)"
            )
        if "occlusionTexture" in m:
            info = m["occlusionTexture"]
            occ_strength = number(p, f"{where} occlusionTexture.strength", as_dict(info).get("strength"), 1.0)
            if not 0 <= occ_strength <= 1:
                raise MatremapError(f"{p}: {where} occlusionTexture.strength must be in [0, 1]; fix the file")
            texture = self.carried_texture(info, "occlusionTexture", (0,), False)
            if texture is not None:
                carried["occlusion"] = CarriedInput(occ_strength, texture)
                self.notes.append(f"occlusion: occlusionTexture (strength {occ_strength:g}) is carried over as it is")
        opacity = self.read_opacity(m, pbr)
        if opacity is not None:
            carried["opacity"] = opacity
        return carried

    def read_opacity(self, m: dict[str, Any], pbr: dict[str, Any]) -> CarriedInput | None:
        """Alpha coverage (§3.9.4): None for OPAQUE (alpha ignored); else the alpha factor, the base colour
        texture's alpha and the mode (and cutoff for MASK)."""
        p, where = self.reader.path, self.where
        mode = m.get("alphaMode", "OPAQUE")
        if mode not in ("OPAQUE", "MASK", "BLEND"):
            raise MatremapError(f"{p}: {where} alphaMode is {mode!r}, not OPAQUE, MASK or BLEND; fix the file")
        alpha = number(p, f"{where} baseColorFactor", pbr.get("baseColorFactor"), [1.0] * 4, 4)[3]
        cutoff = number(p, f"{where} alphaCutoff", m.get("alphaCutoff"), 0.5)
        if cutoff < 0 or not 0 <= alpha <= 1:
            raise MatremapError(f"{p}: {where} alphaCutoff must be >= 0 and alpha in [0, 1]; fix the file")
        if mode == "OPAQUE":
            if alpha < 1:
                self.notes.append(f"baseColorFactor alpha {alpha:g} ignored: alphaMode is OPAQUE (glTF §3.9.4)")
            return None
        texture = None
        if "baseColorTexture" in pbr:
            tex = self.file(pbr["baseColorTexture"], "baseColorTexture")
            a = alpha_channel(tex.channels)
            if a is not None:
                texture = self.ref(tex, (a,), False, 1.0)
        settings: dict[str, Any] = {"mode": mode.lower()}
        if mode == "MASK":
            settings["cutoff"] = cutoff
        self.notes.append(
            f"opacity: alphaMode {mode}{f' (cutoff {cutoff:g})' if mode == 'MASK' else ''}, alpha {alpha:g}"
            + (" x baseColorTexture alpha" if texture is not None else "")
            + " is carried over as it is (matremap remaps the reflectance as opaque)"
        )
        return CarriedInput(alpha, texture, settings)


def roughness_from_glossiness(tex: SlotTexture, gloss: float, size: tuple[int, int] | None = None) -> Any:
    """A bake callable: 1 - ``gloss`` x the texture's linear values as its transform and sampler show them (the
    roughness of a specularGlossinessTexture, whose alpha is the glossiness)."""
    inner = baked(tex, False, size)

    def bake() -> np.ndarray:
        return (1.0 - gloss * np.asarray(inner(), dtype=np.float32)).astype(np.float32)

    return bake


def note_unknown(ext: dict[str, Any], obj: dict[str, Any], notes: list[str]) -> None:
    """Note the material extensions matremap does not read (a written copy keeps them) and the
    extensions the file requires. The ones of :data:`LOOKS` are named together in one note, with the value that
    turns each on."""
    looks = []
    for name, (factor, what) in LOOKS.items():
        e = ext.get(name)
        if isinstance(e, dict):
            v = e.get(factor, 0.0)
            value = f"{v:g}" if isinstance(v, (int, float)) and not isinstance(v, bool) else repr(v)
            looks.append(f"{name} ({what}; {factor} {value})")
    if looks:
        notes.append(
            f"not converted, no model here has them: {'; '.join(looks)}; a glTF output keeps them, other targets "
            "leave them out"
        )
    for name in sorted(set(ext) - set(SCHEMAS) - set(LOOKS)):
        notes.append(
            f"{name} is not remapped (matremap fits the base metallic-roughness layer); a written copy keeps it"
        )
    listed = obj.get("extensionsRequired")
    required = {e for e in (listed if isinstance(listed, list) else []) if isinstance(e, str)}
    required -= {IOR, SPECULAR, TRANSFORM, SPEC_GLOSS}
    if required:
        notes.append(f"the file requires {', '.join(sorted(required))}; matremap ignores them")


__all__ = ["DEFAULT_IOR", "MODEL", "MaterialTextures", "material_names", "read", "read_materials", "select"]
