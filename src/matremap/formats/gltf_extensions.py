"""glTF material extensions read, validated and reported: what drives the model, what only a glTF keeps.

Each extension's fields, defaults and ranges are those of its Khronos README and JSON schema (glTF 2.0
extension registry, ratified versions):

* KHR_materials_ior: ``ior`` >= 1, or 0 ("full specular"), default 1.5;
* KHR_materials_specular: ``specularFactor`` in [0, 1] (default 1) x alpha of ``specularTexture``,
  ``specularColorFactor`` >= 0 (default 1) x sRGB RGB of ``specularColorTexture``;
* KHR_materials_emissive_strength: ``emissiveStrength`` >= 0 (default 1) multiplies ``emissiveFactor``;
* KHR_materials_clearcoat: ``clearcoatFactor`` (R of ``clearcoatTexture``), ``clearcoatRoughnessFactor``
  (G of ``clearcoatRoughnessTexture``), both in [0, 1], default 0; ``clearcoatNormalTexture``;
* KHR_materials_sheen: ``sheenColorFactor`` RGB in [0, 1] (default 0) x ``sheenColorTexture`` (sRGB),
  ``sheenRoughnessFactor`` in [0, 1] (default 0) x alpha of ``sheenRoughnessTexture``;
* KHR_materials_transmission: ``transmissionFactor`` in [0, 1] (default 0) x R of ``transmissionTexture``;
* KHR_materials_volume: ``thicknessFactor`` >= 0 (default 0) x G of ``thicknessTexture``,
  ``attenuationDistance`` > 0 (default infinity), ``attenuationColor`` RGB in [0, 1] (default 1).

* KHR_materials_pbrSpecularGlossiness (archived, ratified; its README): ``diffuseFactor`` RGBA in [0, 1] (default 1)
  x ``diffuseTexture`` (sRGB RGB, linear alpha), ``specularFactor`` RGB in [0, 1] (default 1) x sRGB RGB of
  ``specularGlossinessTexture``, ``glossinessFactor`` in [0, 1] (default 1) x its linear alpha; converted to
  metallic-roughness by :func:`spec_gloss_values`.

``ior`` and ``specular`` drive ``gltf:metal-rough``; emissive strength goes into the carried emission
(:mod:`matremap.formats.gltf_read`). The layers: a glTF written over its source keeps them as they are (the
copy leaves them alone). A material without textures whose look a layer carries (a clear coat above 0.5, a
coloured sheen, any transmission) is read into ``gltf:pbr`` and its layers fitted (:func:`layer_values`; a
transmission on the transmission probe); so is a textured material whose coat or sheen is uniform (no texture of
its own values: the layer is fitted once and held while the sweep fits the base maps under it) or whose transmission
is (converted at levels of its roughness map, :func:`~matremap.svbrdf.mixed.through_levels`); a faint layer is
noted; a layer with textures of its own is listed in ``asset.lost`` and refused for other targets, except a coat's
or a transmission's weight texture (``clearcoatTexture``, ``transmissionTexture``: read as the ``clearcoat`` or
``transmission`` map, the material blended per texel with the layer and without it), a coat's roughness and a
sheen's colour and roughness textures (converted at levels of them). A coat's own normal map
(``clearcoatNormalTexture``) is noted: the target's coat follows the base's normal map.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from matremap.errors import MatremapError
from matremap.formats.gltf_container import is_index
from matremap.formats.gltf_textures import TRANSFORM, as_dict, finite_numbers, transform_matrix

IOR = "KHR_materials_ior"
SPECULAR = "KHR_materials_specular"
EMISSIVE_STRENGTH = "KHR_materials_emissive_strength"
CLEARCOAT = "KHR_materials_clearcoat"
SHEEN = "KHR_materials_sheen"
TRANSMISSION = "KHR_materials_transmission"
VOLUME = "KHR_materials_volume"
SPEC_GLOSS = "KHR_materials_pbrSpecularGlossiness"


@dataclass(frozen=True)
class Field:
    """One field of an extension: ``kind`` is ``unit`` ([0, 1]), ``nonneg`` (>= 0), ``positive`` (> 0),
    ``ior`` (>= 1 or 0), ``rgb_unit``, ``rgb_nonneg`` or ``texture`` (a textureInfo)."""

    kind: str
    default: Any = None


TEXTURE = Field("texture")
SCHEMAS: dict[str, dict[str, Field]] = {
    IOR: {"ior": Field("ior", 1.5)},
    SPECULAR: {
        "specularFactor": Field("unit", 1.0),
        "specularTexture": TEXTURE,
        "specularColorFactor": Field("rgb_nonneg", [1.0, 1.0, 1.0]),
        "specularColorTexture": TEXTURE,
    },
    EMISSIVE_STRENGTH: {"emissiveStrength": Field("nonneg", 1.0)},
    CLEARCOAT: {
        "clearcoatFactor": Field("unit", 0.0),
        "clearcoatTexture": TEXTURE,
        "clearcoatRoughnessFactor": Field("unit", 0.0),
        "clearcoatRoughnessTexture": TEXTURE,
        "clearcoatNormalTexture": TEXTURE,
    },
    SHEEN: {
        "sheenColorFactor": Field("rgb_unit", [0.0, 0.0, 0.0]),
        "sheenColorTexture": TEXTURE,
        "sheenRoughnessFactor": Field("unit", 0.0),
        "sheenRoughnessTexture": TEXTURE,
    },
    TRANSMISSION: {"transmissionFactor": Field("unit", 0.0), "transmissionTexture": TEXTURE},
    VOLUME: {
        "thicknessFactor": Field("nonneg", 0.0),
        "thicknessTexture": TEXTURE,
        "attenuationDistance": Field("positive", math.inf),
        "attenuationColor": Field("rgb_unit", [1.0, 1.0, 1.0]),
    },
    SPEC_GLOSS: {
        "diffuseFactor": Field("rgba_unit", [1.0, 1.0, 1.0, 1.0]),
        "diffuseTexture": TEXTURE,
        "specularFactor": Field("rgb_unit", [1.0, 1.0, 1.0]),
        "glossinessFactor": Field("unit", 1.0),
        "specularGlossinessTexture": TEXTURE,
    },
}
_RANGES = {
    "unit": "a number in [0, 1]",
    "nonneg": "a number >= 0",
    "positive": "a number > 0",
    "ior": "a number >= 1 (or 0)",
    "rgb_unit": "3 numbers in [0, 1]",
    "rgba_unit": "4 numbers in [0, 1]",
    "rgb_nonneg": "3 numbers >= 0",
}


def _valid(kind: str, value: Any) -> Any:
    """``value`` as a float (or 3 floats) when it fits ``kind``, else None."""
    vals = finite_numbers(value, 4 if kind.startswith("rgba") else 3 if kind.startswith("rgb") else 1)
    if vals is None:
        return None
    low_ok = {
        "unit": lambda v: 0.0 <= v <= 1.0,
        "rgb_unit": lambda v: 0.0 <= v <= 1.0,
        "rgba_unit": lambda v: 0.0 <= v <= 1.0,
        "nonneg": lambda v: v >= 0.0,
        "rgb_nonneg": lambda v: v >= 0.0,
        "positive": lambda v: v > 0.0,
        "ior": lambda v: v >= 1.0 or v == 0.0,
    }[kind]
    if not all(low_ok(v) for v in vals):
        return None
    return vals if kind.startswith("rgb") else vals[0]


def check_texture_info(path: Path, where: str, info: Any, n_textures: int) -> dict[str, Any]:
    """A textureInfo (``index``, ``texCoord``, KHR_texture_transform) checked for its types and that its
    index names one of the file's ``n_textures`` textures."""
    if not isinstance(info, dict) or not is_index(info.get("index")):
        raise MatremapError(f"{path}: {where} is not a textureInfo with an index; fix the file")
    if info["index"] >= n_textures:
        raise MatremapError(
            f"{path}: {where} refers to textures[{info['index']}], but the file has {n_textures}; fix the file"
        )
    if not is_index(info.get("texCoord", 0)):
        raise MatremapError(f"{path}: {where}.texCoord must be a UV set index, got {info['texCoord']!r}; fix the file")
    for key in ("scale", "strength"):
        if key in info and finite_numbers(info[key], 1) is None:
            raise MatremapError(f"{path}: {where}.{key} must be a number, got {info[key]!r}; fix the file")
    if TRANSFORM in as_dict(info.get("extensions")):
        transform_matrix(path, where, info["extensions"][TRANSFORM])
    return info


def read_extensions(path: Path, where: str, ext: dict[str, Any], n_textures: int) -> dict[str, dict[str, Any]]:
    """The material's known extensions (:data:`SCHEMAS`), each field checked and defaults filled in
    (textures as their textureInfo); a malformed value is refused in one line naming the material
    (``where``), the extension and the field."""
    found: dict[str, dict[str, Any]] = {}
    for name, schema in SCHEMAS.items():
        if name not in ext:
            continue
        obj = ext[name]
        if obj is None:
            obj = {}
        if not isinstance(obj, dict):
            raise MatremapError(f"{path}: {where}: {name} is not an object; fix the file")
        values: dict[str, Any] = {}
        for key, f in schema.items():
            if f.kind == "texture":
                if key in obj:
                    values[key] = check_texture_info(path, f"{where} {name}.{key}", obj[key], n_textures)
                continue
            value = _valid(f.kind, obj[key]) if key in obj else f.default
            if value is None:
                raise MatremapError(
                    f"{path}: {where}: {name}.{key} must be {_RANGES[f.kind]}, got {obj[key]!r}; fix the file"
                )
            values[key] = value
        found[name] = values
    return found


def _g(v: float) -> str:
    return f"{v:.3g}"


def _rgb(v: list[float]) -> str:
    return "[" + ", ".join(_g(x) for x in v) + "]"


def _textures(values: dict[str, Any]) -> str:
    names = [k for k in values if k.endswith("Texture")]
    return f" with {', '.join(names)}" if names else ""


def _value_textures(values: dict[str, Any]) -> list[str]:
    """The textures that vary a layer's values (not its own normal map, which a coat may have)."""
    return [k for k in values if k.endswith("Texture") and not k.endswith("NormalTexture")]


LEFT_BEHIND = "a glTF output keeps it as it is; other targets leave it out"

#: the dielectric F0 of gltf:metal-rough's default ior 1.5, ((1.5 - 1) / (1.5 + 1))^2
F0_IOR_15 = 0.04


def spec_gloss_values(sg: dict[str, Any]) -> dict[str, Any]:
    """The ``gltf:metal-rough`` values of a KHR_materials_pbrSpecularGlossiness material's factors.

    The extension's README ("Specular - Glossiness") gives the BRDF inputs c_diff = diffuse.rgb (1 -
    max(specular)), F0 = specular, alpha = (1 - glossiness)^2. gltf:metal-rough's dielectric (metallic 0) with
    KHR_materials_specular has c_diff = baseColor (1 - specular max(F0)), F0 = min(((ior - 1)/(ior + 1))^2
    specularColor, 1) specular and alpha = roughness^2, so: baseColor = diffuse, roughness = 1 - glossiness,
    metallic 0, specular 1, ior 1.5 and specularColor = specular / 0.04 (the extension's F0 exactly, within
    specularColor's range [0, 25]). glTF-Transform's ``metalRough`` converts the same way (diffuse -> base colour,
    metallic 0, roughness = 1 - glossiness, the specular colour into KHR_materials_specular's
    specularColorFactor), with a large ior in place of the factor 25 that gltf:metal-rough's ior range
    [1, 5] does not allow. Textures convert per texel the same way (:mod:`matremap.formats.gltf_read`).

    A material without textures whose c_diff is 0 (a diffuse of 0, or a specular reaching 1 in a channel, which
    leaves no light to the diffuse: the extension's gold example) is the metal of baseColor = specular instead:
    gltf:metal-rough's metal_brdf F(baseColor, 1) D V is then the same BRDF, and other models see the metal."""
    out = {
        "baseColor": list(sg["diffuseFactor"][:3]),
        "metallic": 0.0,
        "roughness": 1.0 - sg["glossinessFactor"],
        "ior": 1.5,
        "specular": 1.0,
        "specularColor": [v / F0_IOR_15 for v in sg["specularFactor"]],
    }
    no_diffuse = max(sg["diffuseFactor"][:3]) <= 0.0 or max(sg["specularFactor"]) >= 1.0
    if no_diffuse and not any(k.endswith("Texture") for k in sg):
        out |= {"baseColor": list(sg["specularFactor"]), "metallic": 1.0, "specularColor": [1.0, 1.0, 1.0]}
    return out


def lost_look(found: dict[str, dict[str, Any]]) -> list[str]:
    """The extensions that carry the material's look: any transmission (its share of the base goes through: a
    glass, or a part of one), a sheen (above :data:`SHEEN_LOOK`, or textured: velvet) or a clear coat above
    :data:`COAT_LOOK` with textures of its own values. :func:`layer_values` reads the uniform ones into
    ``gltf:pbr``; the others are lost (refused for other models)."""
    lost = []
    tr = found.get(TRANSMISSION)
    if tr and tr["transmissionFactor"] > 0:
        lost.append(f"{TRANSMISSION} (transmissionFactor {_g(tr['transmissionFactor'])}{_textures(tr)})")
    sh = found.get(SHEEN)
    if sh and (
        max(sh["sheenColorFactor"]) > SHEEN_LOOK or ("sheenColorTexture" in sh and max(sh["sheenColorFactor"]) > 0)
    ):
        lost.append(f"{SHEEN} (a coloured sheen: sheenColorFactor {_rgb(sh['sheenColorFactor'])}{_textures(sh)})")
    cc = found.get(CLEARCOAT)
    if cc and cc["clearcoatFactor"] > COAT_LOOK and _coat_textures(cc):
        lost.append(f"{CLEARCOAT} (clearcoatFactor {_g(cc['clearcoatFactor'])} with {', '.join(_coat_textures(cc))})")
    return lost


@dataclass(frozen=True)
class CoatMap:
    """A KHR_materials_clearcoat texture read as a ``gltf:pbr`` map: its slot, the channel the value is in and
    the factor it multiplies (its weight's R, its roughness's G; a coat's normal map is noted, not read)."""

    slot: str
    channel: int
    factor: str


#: gltf:pbr's coat maps (each blended per texel: svbrdf/mixed.py) -> their KHR_materials_clearcoat texture
COAT_MAPS = {
    "clearcoat": CoatMap("clearcoatTexture", 0, "clearcoatFactor"),
    "clearcoatRoughness": CoatMap("clearcoatRoughnessTexture", 1, "clearcoatRoughnessFactor"),
}
_COAT_SLOTS = {m.slot for m in COAT_MAPS.values()}


#: gltf:pbr's transmission weight map: R of KHR_materials_transmission's transmissionTexture times its factor (the
#: material converted with the transmission and without it, blended per texel: svbrdf/mixed.py)
TRANSMISSION_MAP = "transmissionTexture"

#: gltf:pbr's sheen maps -> their KHR_materials_sheen texture (the colour in its sRGB RGB, the roughness in its alpha;
#: converted at levels of them: :func:`~matremap.svbrdf.mixed.layer_levels`)
SHEEN_MAPS = {"sheenColor": "sheenColorTexture", "sheenRoughness": "sheenRoughnessTexture"}


def _coat_textures(cc: dict[str, Any]) -> list[str]:
    """A coat's textures that matremap does not convert (none of the ratified extension's: see :data:`COAT_MAPS`)."""
    return [k for k in _value_textures(cc) if k not in _COAT_SLOTS]


#: the model a glTF material is read into when a layer carries its look (:func:`layer_values`)
LAYERED_MODEL = "gltf:pbr"
#: a clear coat's factor past which it carries the look (a second, sharp highlight over the base)
COAT_LOOK = 0.5
#: a sheen colour's brightest channel past which the sheen carries the look: a velvet's colour is its sheen over a
#: near-black base (Khronos GlamVelvetSofa's navy fabric: base 0.01, sheen [0.05, 0.17, 0.5]; its black one, sheen
#: 0.13; SheenChair's peacock velvet, sheen [0.013, 0.284, 0.298] over a 0.1 base), which a cut at 0.5 read as faint
#: and left out
SHEEN_LOOK = 0.1


def layer_values(found: dict[str, dict[str, Any]], textured: bool = False) -> dict[str, Any]:
    """The ``gltf:pbr`` layer parameters of a material whose clear coat (clearcoatFactor above
    :data:`COAT_LOOK`), coloured sheen or transmission (as :func:`lost_look` says) carries its look, when those
    layers' values have no texture: the material is then read into ``gltf:pbr`` and its layers are fitted (a
    transmission on the transmission probe), not left out. ``textured``: the base has maps; a uniform coat or
    sheen is read (held over the maps' sweep), and a uniform transmission (converted at levels of a roughness map,
    each fitted on the transmission probe; other maps that vary are refused then:
    :func:`~matremap.svbrdf.mixed.through_levels`). Empty otherwise (the material is read as
    ``gltf:metal-rough``)."""
    cc, sh, tr = found.get(CLEARCOAT), found.get(SHEEN), found.get(TRANSMISSION)
    coat = cc is not None and cc["clearcoatFactor"] > COAT_LOOK and not _coat_textures(cc)
    sheen = sh is not None and SHEEN in " ".join(lost_look(found))
    through = tr is not None and TRANSMISSION in " ".join(lost_look(found))
    vol = found.get(VOLUME)
    if not (coat or sheen or through):
        return {}
    out: dict[str, Any] = {}
    if through and tr is not None:
        out["transmission"] = tr["transmissionFactor"]
        if vol is not None:
            distance = vol["attenuationDistance"]
            out |= {
                "thickness": vol["thicknessFactor"],
                "attenuationColor": list(vol["attenuationColor"]),
                "attenuationDistance": 0.0 if not math.isfinite(distance) else distance,
            }
    if cc is not None and not _coat_textures(cc):
        out |= {"clearcoat": cc["clearcoatFactor"], "clearcoatRoughness": cc["clearcoatRoughnessFactor"]}
    if sh is not None and (sheen or not _value_textures(sh)):  # its textures are read as maps by the factors
        out |= {"sheenColor": list(sh["sheenColorFactor"]), "sheenRoughness": sh["sheenRoughnessFactor"]}
    return out


def extension_notes(found: dict[str, dict[str, Any]], textured: bool = False) -> list[str]:
    """One note per layer extension that does not make the material lost: its values, and what becomes
    of it (kept in a glTF output, left out elsewhere; fitted in gltf:pbr when :func:`layer_values` reads it,
    for a material without textures)."""
    notes = []
    lost = " ".join(lost_look(found))
    layers = layer_values(found, textured)
    if layers:
        what = ", ".join(f"{k} {_g(v) if isinstance(v, float) else _rgb(v)}" for k, v in layers.items())
        uniform = textured and not (CLEARCOAT in found and _COAT_SLOTS & set(found[CLEARCOAT]))
        held = " (uniform over the maps: fitted once, held while the sweep fits the maps)" if uniform else ""
        if textured and "transmission" in layers:
            held = " (over maps: converted at levels of its roughness map, each fitted on the transmission probe)"
        sheen_maps = [k for k in SHEEN_MAPS.values() if k in (found.get(SHEEN) or {})]
        if "sheenColor" in layers and sheen_maps:
            held = (
                f" ({' and '.join(sheen_maps)} vary the sheen: converted at a few levels of it, the base maps swept "
                "under each, and interpolated per texel)"
            )
        exts = [
            e
            for e, k in ((CLEARCOAT, "clearcoat"), (SHEEN, "sheenColor"), (TRANSMISSION, "transmission"))
            if k in layers
        ]
        notes.append(
            f"read into {LAYERED_MODEL} ({what}; {', '.join(exts)}): its layers are fitted, not left out{held}"
        )
    cc = found.get(CLEARCOAT)
    if cc is not None and "clearcoat" in layers and "clearcoatTexture" in cc:
        notes.append(
            f"{CLEARCOAT}.clearcoatTexture masks the coat: the material is converted with the coat and without it, "
            "and the two blended per texel by the mask"
        )
    if cc is not None and "clearcoat" in layers and "clearcoatRoughnessTexture" in cc:
        notes.append(
            f"{CLEARCOAT}.clearcoatRoughnessTexture varies the coat's roughness: the material is converted at a few "
            "levels of it and interpolated per texel"
        )
    if cc is not None and "clearcoat" in layers and "clearcoatNormalTexture" in cc:
        notes.append(
            f"{CLEARCOAT}.clearcoatNormalTexture, the coat's own normal map, is not converted: the target's coat "
            "follows the base's normal map (a glTF copy of the file keeps it)"
        )
    if cc is not None and "clearcoat" not in layers and CLEARCOAT not in lost:
        if cc["clearcoatFactor"] == 0:
            notes.append(f"{CLEARCOAT} has clearcoatFactor 0: no coat")
        else:
            notes.append(
                f"{CLEARCOAT} factor {_g(cc['clearcoatFactor'])}, roughness {_g(cc['clearcoatRoughnessFactor'])}"
                f"{_textures(cc)}: a faint coat (at most {COAT_LOOK}) the fit does not see; {LEFT_BEHIND}"
            )
    sh = found.get(SHEEN)
    if sh is not None and SHEEN not in lost and "sheenColor" not in layers:
        notes.append(
            f"{SHEEN} colour {_rgb(sh['sheenColorFactor'])}, roughness {_g(sh['sheenRoughnessFactor'])}"
            f"{_textures(sh)}: a faint sheen the fit does not see; {LEFT_BEHIND}"
        )
    return notes + _through_notes(found, layers, lost)


def _through_notes(found: dict[str, dict[str, Any]], layers: dict[str, Any], lost: str) -> list[str]:
    """The notes of KHR_materials_transmission and _volume (``layers``: what :func:`layer_values` read)."""
    notes = []
    tr, vol = found.get(TRANSMISSION), found.get(VOLUME)
    if tr is not None and "transmission" in layers and TRANSMISSION_MAP in tr:
        notes.append(
            f"{TRANSMISSION}.{TRANSMISSION_MAP} varies how much light goes through: the material is converted with its "
            "transmission and without it, and the two blended per texel by the map"
        )
    if "transmission" in layers and vol is not None and "thicknessTexture" in vol:
        notes.append(
            f"{VOLUME}.thicknessTexture is a rasteriser's stand-in for the length of the path through the object (the "
            'extension\'s "Thickness Texture": path tracers derive it from the geometry and ignore the texture): not '
            "converted; the volume's length comes from the geometry (thicknessFactor "
            f"{_g(vol['thicknessFactor'])} > 0: a volume, not a thin wall); a glTF copy keeps it"
        )
    if "transmission" not in layers and tr is not None and TRANSMISSION not in lost:
        notes.append(f"{TRANSMISSION} factor 0: nothing goes through")
    if vol is not None and "transmission" not in layers:
        notes.append(
            f"{VOLUME} thickness {_g(vol['thicknessFactor'])}, attenuation colour {_rgb(vol['attenuationColor'])} "
            f"over {_g(vol['attenuationDistance'])}{_textures(vol)}: the volume under a transmissive surface; "
            f"{LEFT_BEHIND}"
        )
    return notes


__all__ = [
    "CLEARCOAT",
    "COAT_MAPS",
    "SHEEN_LOOK",
    "SHEEN_MAPS",
    "SPEC_GLOSS",
    "EMISSIVE_STRENGTH",
    "IOR",
    "LAYERED_MODEL",
    "SCHEMAS",
    "SHEEN",
    "SPECULAR",
    "TRANSMISSION",
    "TRANSMISSION_MAP",
    "VOLUME",
    "check_texture_info",
    "extension_notes",
    "layer_values",
    "lost_look",
    "read_extensions",
    "spec_gloss_values",
]
