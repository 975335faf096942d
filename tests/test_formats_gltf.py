"""glTF 2.0 reader and writer (matremap.formats.gltf).

Every test builds its glTF / GLB files here, in tmp_path (JSON written with json, PNGs with
OpenImageIO, GLB containers packed with struct), and the written files are checked by a structural
validator written from the spec (§3 and §4 of glTF 2.0), independent of the module under test.
"""

from __future__ import annotations

import base64
import json
import os
import struct
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest

from matremap.core.imageio import linear_to_srgb, srgb_to_linear
from matremap.core.material import Material
from matremap.errors import MatremapError
from matremap.formats import read_asset, write_asset
from matremap.formats.confine import Confinement
from matremap.formats.gltf import read, write
from matremap.svbrdf.textures import load_map_set, read_image

MR = "gltf:metal-rough"


# ------------------------------------------------------------------------------------------------
# building files


def png_bytes(tmp_path: Path, a: np.ndarray) -> bytes:
    a = np.ascontiguousarray(a, dtype=np.uint8)
    if a.ndim == 2:
        a = a[..., None]
    f = tmp_path / f".enc{np.random.default_rng().integers(1 << 30)}.png"
    spec = oiio.ImageSpec(a.shape[1], a.shape[0], a.shape[2], oiio.UINT8)
    spec.attribute("oiio:UnassociatedAlpha", 1)  # PNG stores unassociated alpha: keep the values as given
    out = oiio.ImageOutput.create(str(f))
    assert out.open(str(f), spec)
    assert out.write_image(a)
    out.close()
    data = f.read_bytes()
    f.unlink()
    return data


def glb_bytes(doc: dict, bin_data: bytes | None) -> bytes:
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    body = struct.pack("<II", len(text), 0x4E4F534A) + text
    if bin_data is not None:
        b = bin_data + b"\0" * (-len(bin_data) % 4)
        body += struct.pack("<II", len(b), 0x004E4942) + b
    return struct.pack("<III", 0x46546C67, 2, 12 + len(body)) + body


def make_file(
    folder: Path,
    name: str,
    materials: list[dict],
    images: dict[str, np.ndarray] | None = None,
    store: str = "file",
    extra: dict | None = None,
) -> Path:
    """A glTF (.gltf or .glb by ``name``) with ``materials``; ``images`` name -> uint8 array become
    textures in order (texture i = image i), stored as files ("file"), data: URIs ("data") or buffer
    views ("bufferView"; in the BIN chunk of a .glb, else in a data: URI buffer)."""
    folder.mkdir(parents=True, exist_ok=True)
    doc: dict = {"asset": {"version": "2.0"}, "materials": materials}
    doc.update(extra or {})
    blob = bytearray()
    if images:
        doc["images"], doc["textures"] = [], []
        for i, (iname, a) in enumerate(images.items()):
            data = png_bytes(folder, a)
            if store == "file":
                (folder / f"{iname}.png").write_bytes(data)
                doc["images"].append({"uri": f"{iname}.png"})
            elif store == "data":
                doc["images"].append({"uri": "data:image/png;base64," + base64.b64encode(data).decode()})
            else:
                blob += b"\0" * (-len(blob) % 4)
                doc.setdefault("bufferViews", []).append(
                    {"buffer": 0, "byteOffset": len(blob), "byteLength": len(data)}
                )
                blob += data
                doc["images"].append({"bufferView": len(doc["bufferViews"]) - 1, "mimeType": "image/png"})
            doc["textures"].append({"source": i})
    path = folder / name
    if blob:
        doc["buffers"] = [{"byteLength": len(blob)}]
    if path.suffix == ".glb":
        path.write_bytes(glb_bytes(doc, bytes(blob) if blob else None))
    else:
        if blob:
            doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(blob).decode()
        path.write_text(json.dumps(doc))
    return path


def ramp(h: int = 8, w: int = 8, seed: int = 0, channels: int = 3) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.integers(0, 256, size=(h, w, channels), dtype=np.uint8)


# ------------------------------------------------------------------------------------------------
# an independent structural validator (glTF 2.0 §3, §4.4)


def load_written(path: Path) -> tuple[dict, bytes | None]:
    data = path.read_bytes()
    if path.suffix == ".glb":
        magic, version, length = struct.unpack_from("<III", data, 0)
        assert (magic, version, length) == (0x46546C67, 2, len(data))
        clen, ctype = struct.unpack_from("<II", data, 12)
        assert ctype == 0x4E4F534A and clen % 4 == 0
        doc = json.loads(data[20 : 20 + clen])
        pos = 20 + clen
        binc = None
        if pos < len(data):
            blen, btype = struct.unpack_from("<II", data, pos)
            assert btype == 0x004E4942 and blen % 4 == 0 and pos + 8 + blen == len(data)
            binc = data[pos + 8 : pos + 8 + blen]
        return doc, binc
    assert data[:1] == b"{"
    return json.loads(data), None


def validate(path: Path) -> dict:
    """Assert that ``path`` is a structurally valid glTF 2.0 whose every reference resolves; returns the JSON."""
    doc, binc = load_written(path)
    assert doc["asset"]["version"] == "2.0"

    def count(key):
        return len(doc.get(key, []))

    def ok(key, i):
        assert isinstance(i, int) and 0 <= i < count(key), (key, i, count(key))

    for key in (
        "scenes",
        "nodes",
        "meshes",
        "accessors",
        "bufferViews",
        "buffers",
        "images",
        "textures",
        "materials",
        "samplers",
    ):
        if key in doc:
            assert isinstance(doc[key], list) and doc[key], f"{key} must be a non-empty array when present"
    if "scene" in doc:
        ok("scenes", doc["scene"])
    for s in doc.get("scenes", []):
        for n in s.get("nodes", []):
            ok("nodes", n)
    for n in doc.get("nodes", []):
        if "mesh" in n:
            ok("meshes", n["mesh"])
        for c in n.get("children", []):
            ok("nodes", c)
    for m in doc.get("meshes", []):
        for prim in m["primitives"]:
            for a in prim["attributes"].values():
                ok("accessors", a)
            if "indices" in prim:
                ok("accessors", prim["indices"])
            if "material" in prim:
                ok("materials", prim["material"])
    sizes = {5120: 1, 5121: 1, 5122: 2, 5123: 2, 5125: 4, 5126: 4}
    comps = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}
    for a in doc.get("accessors", []):
        ok("bufferViews", a["bufferView"])
        bv = doc["bufferViews"][a["bufferView"]]
        n = a["count"] * sizes[a["componentType"]] * comps[a["type"]]
        assert a.get("byteOffset", 0) + n <= bv["byteLength"]
    lengths = []
    for i, b in enumerate(doc.get("buffers", [])):
        if "uri" not in b:
            assert i == 0 and path.suffix == ".glb" and binc is not None
            assert b["byteLength"] <= len(binc) <= b["byteLength"] + 3
            lengths.append(len(binc))
        elif b["uri"].startswith("data:"):
            lengths.append(len(base64.b64decode(b["uri"].split(",", 1)[1])))
        else:
            f = path.parent / b["uri"]
            assert f.is_file(), f"buffer {b['uri']} missing"
            lengths.append(f.stat().st_size)
        assert lengths[-1] >= b["byteLength"]
    for bv in doc.get("bufferViews", []):
        ok("buffers", bv["buffer"])
        assert bv.get("byteOffset", 0) + bv["byteLength"] <= doc["buffers"][bv["buffer"]]["byteLength"]
    for im in doc.get("images", []):
        assert ("uri" in im) != ("bufferView" in im)
        if "bufferView" in im:
            ok("bufferViews", im["bufferView"])
            assert im["mimeType"] in ("image/png", "image/jpeg")
        elif not im["uri"].startswith("data:"):
            assert (path.parent / im["uri"]).is_file(), f"image {im['uri']} missing"
    for t in doc.get("textures", []):
        if "source" in t:
            ok("images", t["source"])
        if "sampler" in t:
            ok("samplers", t["sampler"])
    used = set(doc.get("extensionsUsed", []))
    assert set(doc.get("extensionsRequired", [])) <= used
    for m in doc.get("materials", []):
        pbr = m.get("pbrMetallicRoughness", {})
        infos = [
            pbr.get("baseColorTexture"),
            pbr.get("metallicRoughnessTexture"),
            m.get("normalTexture"),
            m.get("occlusionTexture"),
            m.get("emissiveTexture"),
        ]
        for name, e in (m.get("extensions") or {}).items():
            assert name in used, f"{name} used but not in extensionsUsed"
            infos += [v for v in e.values() if isinstance(v, dict) and "index" in v]
        for info in infos:
            if info is not None:
                ok("textures", info["index"])
        for v in [*pbr.get("baseColorFactor", []), pbr.get("metallicFactor", 0), pbr.get("roughnessFactor", 0)]:
            assert 0.0 <= v <= 1.0
    return doc


def listing(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")}


# ------------------------------------------------------------------------------------------------
# reading


def test_factors_and_khr_extensions_are_read(tmp_path):
    mat = {
        "name": "paint",
        "pbrMetallicRoughness": {
            "baseColorFactor": [0.8, 0.4, 0.2, 1.0],
            "metallicFactor": 0.25,
            "roughnessFactor": 0.6,
        },
        "extensions": {
            "KHR_materials_ior": {"ior": 1.4},
            "KHR_materials_specular": {"specularFactor": 0.7, "specularColorFactor": [1.0, 0.9, 0.8]},
        },
    }
    f = make_file(tmp_path, "a.gltf", [mat], extra={"extensionsUsed": ["KHR_materials_ior", "KHR_materials_specular"]})
    asset = read_asset(f)
    assert asset.format == "gltf" and asset.model == MR and asset.name == "paint" and not asset.textured
    m = asset.material()
    np.testing.assert_allclose(m.values["baseColor"], [0.8, 0.4, 0.2])
    np.testing.assert_allclose(
        [m.values[k][0] for k in ("metallic", "roughness", "ior", "specular")], [0.25, 0.6, 1.4, 0.7]
    )
    np.testing.assert_allclose(m.values["specularColor"], [1.0, 0.9, 0.8])
    assert asset.notes == []


def test_missing_properties_take_the_spec_defaults(tmp_path):
    asset = read(make_file(tmp_path, "a.glb", [{}]))
    m = asset.material()
    assert m == Material.create(
        MR, {"baseColor": 1.0, "metallic": 1.0, "roughness": 1.0, "ior": 1.5, "specular": 1.0, "specularColor": 1.0}
    )
    assert asset.name == "material 0"


@pytest.mark.parametrize(
    "store, name", [("file", "a.gltf"), ("bufferView", "a.glb"), ("data", "a.gltf"), ("bufferView", "a.gltf")]
)
def test_packed_metallic_roughness_texture_gives_green_roughness_and_blue_metallic(tmp_path, store, name):
    mr = ramp(seed=1)
    mat = {
        "pbrMetallicRoughness": {
            "metallicFactor": 0.5,
            "roughnessFactor": 0.8,
            "metallicRoughnessTexture": {"index": 0},
        }
    }
    f = make_file(tmp_path / "in", name, [mat], {"mr": mr}, store=store)
    asset = read(f)
    assert set(asset.textures) == {"roughness", "metallic"}
    assert asset.textures["roughness"].channels == (1,) and asset.textures["metallic"].channels == (2,)
    assert all(t.path.is_file() for t in asset.textures.values())
    ms = load_map_set(asset.to_map_set(tmp_path / "maps"))
    rough, _ = read_image(ms.maps["roughness"], ms.colorspace["roughness"], colour=False)
    metal, _ = read_image(ms.maps["metallic"], ms.colorspace["metallic"], colour=False)
    np.testing.assert_allclose(rough[..., 0], mr[..., 1] / 255.0 * 0.8, atol=1e-6)
    np.testing.assert_allclose(metal[..., 0], mr[..., 2] / 255.0 * 0.5, atol=1e-6)
    assert ms.constants["baseColor"] == [1.0, 1.0, 1.0]


def read_image_bytes_ok(path: Path) -> bool:
    import hashlib

    return hashlib.sha256(path.read_bytes()).hexdigest()[:16] in path.stem


def test_embedded_images_are_extracted_to_a_cache_folder_named_by_the_file(tmp_path):
    f = make_file(
        tmp_path,
        "a.glb",
        [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
        {"base": ramp(seed=2)},
        store="bufferView",
    )
    from matremap.core.diskcache import cache_dir

    p1 = read(f).textures["baseColor"].path
    assert p1.suffix == ".png" and p1.is_relative_to(cache_dir() / "gltf-images")  # the documented cache
    assert read(f).textures["baseColor"].path == p1  # cached, same file
    p1.write_bytes(p1.read_bytes()[:-10])  # a damaged cache file is not trusted: written again
    assert read(f).textures["baseColor"].path == p1 and read_image_bytes_ok(p1)
    g = make_file(
        tmp_path / "b",
        "a.glb",
        [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
        {"base": ramp(seed=3)},
        store="bufferView",
    )
    assert read(g).textures["baseColor"].path != p1  # another file, another folder


def test_base_color_texture_is_decoded_from_srgb_and_multiplied_by_the_factor(tmp_path):
    codes = np.array([[[0, 10, 128], [200, 255, 64]]], dtype=np.uint8)
    mat = {"pbrMetallicRoughness": {"baseColorFactor": [0.5, 1.0, 0.25, 1.0], "baseColorTexture": {"index": 0}}}
    asset = read(make_file(tmp_path, "a.gltf", [mat], {"base": codes}))
    ref = asset.textures["baseColor"]
    assert ref.colorspace == "srgb" and ref.channels == (0, 1, 2) and ref.scale == (0.5, 1.0, 0.25)
    ms = load_map_set(asset.to_map_set(tmp_path / "maps"))
    base, _ = read_image(ms.maps["baseColor"], ms.colorspace["baseColor"])
    expect = srgb_to_linear(codes / 255.0) * np.array([0.5, 1.0, 0.25])
    np.testing.assert_allclose(base, expect, atol=1e-6)
    assert abs(float(base[0, 0, 2]) / 0.25 - 0.2158605) < 1e-5  # sRGB 128 is linear 0.21586


def test_a_base_colour_texture_with_alpha_keeps_its_stored_colour(tmp_path):
    """PNG colour is unassociated with alpha: alpha 64 must not darken the base colour."""
    rgba = ramp(seed=8, channels=4)
    rgba[..., 3] = 64
    asset = read(
        make_file(tmp_path, "a.gltf", [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}], {"b": rgba})
    )
    assert asset.carried == {}  # alphaMode OPAQUE: alpha is ignored (glTF §3.9.4)
    ms = load_map_set(asset.to_map_set(tmp_path / "maps"))
    base, _ = read_image(ms.maps["baseColor"], ms.colorspace["baseColor"])
    np.testing.assert_allclose(base, srgb_to_linear(rgba[..., :3] / 255.0), atol=1e-6)


def test_specular_textures_use_alpha_and_srgb_colour(tmp_path):
    rgba = ramp(seed=4, channels=4)
    mat = {
        "extensions": {
            "KHR_materials_specular": {
                "specularFactor": 0.5,
                "specularTexture": {"index": 0},
                "specularColorFactor": [2.0, 1.0, 1.0],
                "specularColorTexture": {"index": 0},
            }
        }
    }
    asset = read(make_file(tmp_path, "a.gltf", [mat], {"spec": rgba}))
    assert asset.textures["specular"].channels == (3,) and asset.textures["specular"].colorspace == "linear"
    assert asset.textures["specularColor"].colorspace == "srgb"
    ms = load_map_set(asset.to_map_set(tmp_path / "maps"))
    s, _ = read_image(ms.maps["specular"], ms.colorspace["specular"], colour=False)
    c, _ = read_image(ms.maps["specularColor"], ms.colorspace["specularColor"])
    np.testing.assert_allclose(s[..., 0], rgba[..., 3] / 255.0 * 0.5, atol=1e-6)
    np.testing.assert_allclose(c, srgb_to_linear(rgba[..., :3] / 255.0) * [2.0, 1.0, 1.0], atol=1e-5)


def test_normal_texture_is_kept_as_the_normal_map(tmp_path):
    mat = {"normalTexture": {"index": 0, "scale": 0.5}, "pbrMetallicRoughness": {"baseColorTexture": {"index": 1}}}
    f = make_file(tmp_path, "a.gltf", [mat], {"n": ramp(seed=5), "b": ramp(seed=6)})
    asset = read(f)
    assert asset.normal.path == tmp_path / "n.png"
    assert any("normalTexture scale 0.5" in n for n in asset.notes)
    ms = load_map_set(asset.to_map_set(tmp_path / "maps"))
    assert ms.normal.resolve() == (tmp_path / "n.png").resolve()


def test_inputs_matremap_does_not_remap_are_noted(tmp_path):
    mat = {
        "name": "fancy",
        "alphaMode": "BLEND",
        "emissiveFactor": [1, 0, 0],
        "occlusionTexture": {"index": 0},
        "pbrMetallicRoughness": {
            "baseColorFactor": [1, 1, 1, 0.5],
            "baseColorTexture": {"index": 0, "texCoord": 1},
            "metallicRoughnessTexture": {
                "index": 0,
                "extensions": {"KHR_texture_transform": {"scale": [2, 2], "texCoord": 1}},
            },
        },
        "extensions": {"KHR_materials_clearcoat": {"clearcoatFactor": 1}, "KHR_materials_sheen": {}},
    }
    f = make_file(tmp_path, "a.gltf", [mat, {"name": "other"}], {"t": ramp(seed=7)})
    notes = " | ".join(read(f).notes)
    for word in (
        "2 materials",
        "BLEND",
        "emissi",
        "occlusion",
        "alpha 0.5",
        "TEXCOORD_1",
        "KHR_texture_transform",
        "KHR_materials_clearcoat",
        "KHR_materials_sheen",
    ):
        assert word in notes, word
    assert read(f, "other").notes == []


def test_materials_are_chosen_by_name_or_index(tmp_path):
    mats = [
        {"name": "a", "pbrMetallicRoughness": {"roughnessFactor": 0.1}},
        {"name": "b", "pbrMetallicRoughness": {"roughnessFactor": 0.2}},
    ]
    f = make_file(tmp_path, "m.glb", mats)
    assert read(f).name == "a"
    assert read(f, "b").material().values["roughness"][0] == 0.2
    assert read(f, 1).index == 1 and read(f, "1").name == "b"
    with pytest.raises(MatremapError, match=r"no material 'c'.*0: 'a', 1: 'b'"):
        read(f, "c")
    with pytest.raises(MatremapError, match="no material 2"):
        read(f, 2)


@pytest.mark.parametrize(
    "name, content, message",
    [
        ("a.glb", b'{"asset": {"version": "2.0"}}', "JSON text, not a binary glTF; rename it to .gltf"),
        ("a.glb", b"hello, not a model", "does not start with the 'glTF' magic"),
        ("a.gltf", glb_bytes({"asset": {"version": "2.0"}, "materials": [{}]}, None), "binary glTF.*rename it to .glb"),
        ("a.gltf", b"\x00\xff\xfe binary", "not UTF-8"),
        ("a.gltf", b'{"asset": {"version": "2.0"}, "materials": [', "not valid glTF JSON"),
        ("a.gltf", b'{"asset": {"version": "1.0"}, "materials": [{}]}', "glTF 1.0; matremap reads glTF 2.0"),
        ("a.gltf", b'{"asset": {"version": "2.0"}}', "has no materials"),
        ("a.glb", glb_bytes({"asset": {"version": "2.0"}, "materials": [{}]}, None)[:-4], "truncated"),
        (
            "a.gltf",
            b'{"asset": {"version": "2.0"}, "materials": [{"pbrMetallicRoughness": {"roughnessFactor": 2}}]}',
            "roughness=2 is outside",
        ),
    ],
)
def test_files_that_are_not_what_they_say_raise_clear_errors(tmp_path, name, content, message):
    (tmp_path / name).write_bytes(content)
    before = listing(tmp_path)
    with pytest.raises(MatremapError, match=message):
        read_asset(tmp_path / name)
    assert listing(tmp_path) == before


def test_a_missing_external_texture_raises_naming_it(tmp_path):
    f = make_file(tmp_path, "a.gltf", [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}], {"gone": ramp()})
    (tmp_path / "gone.png").unlink()
    with pytest.raises(MatremapError, match=r"image 'gone.png' \(material 'material 0' baseColorTexture\) not found"):
        read(f)


def test_a_texture_index_out_of_range_raises(tmp_path):
    f = make_file(tmp_path, "a.gltf", [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 3}}}])
    with pytest.raises(MatremapError, match=r"textures\[3\], but the file has 0"):
        read(f)


# ------------------------------------------------------------------------------------------------
# writing


def mr_map_set(folder: Path, size: int = 8, with_specular: bool = True) -> Path:
    """A gltf:metal-rough map set: baseColor and specularColor 8-bit sRGB PNGs, roughness, metallic and
    specular 8-bit linear PNGs, ior as a constant."""
    folder.mkdir(parents=True, exist_ok=True)
    maps = {
        "baseColor": ramp(size, size, 10),
        "roughness": ramp(size, size, 11, 1),
        "metallic": ramp(size, size, 12, 1),
    }
    if with_specular:
        maps.update(specular=ramp(size, size, 13, 1), specularColor=ramp(size, size, 14))
    for k, a in maps.items():
        (folder / f"{k}.png").write_bytes(png_bytes(folder, a))
    manifest = {
        "model": MR,
        "maps": {k: f"{k}.png" for k in maps},
        "params": {"ior": 1.45},
        "colorspace": {
            "baseColor": "srgb",
            "specularColor": "srgb",
            "roughness": "linear",
            "metallic": "linear",
            "specular": "linear",
        },
    }
    (folder / "material.json").write_text(json.dumps(manifest))
    return folder


def map_values(ms) -> dict[str, np.ndarray]:
    out = {}
    for k, f in ms.maps.items():
        img, _ = read_image(f, ms.colorspace[k], colour=k in ("baseColor", "specularColor"))
        out[k] = img[..., :3] if k in ("baseColor", "specularColor") else img[..., 0]
    return out


@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
def test_map_set_round_trip_within_8_bit_quantisation(tmp_path, suffix):
    ms = load_map_set(mr_map_set(tmp_path / "maps"))
    out = write(tmp_path / f"out{suffix}", ms)
    doc = validate(out)
    assert doc["extensionsUsed"] == ["KHR_materials_ior", "KHR_materials_specular"]
    assert len(doc["meshes"]) == 1  # the material on a UV sphere
    mat = doc["materials"][0]
    tex = mat["extensions"]["KHR_materials_specular"]
    assert tex["specularTexture"]["index"] == tex["specularColorTexture"]["index"]  # one RGBA image
    back = read(out)
    assert back.constants["ior"] == pytest.approx(1.45)
    assert set(back.textures) == {"baseColor", "roughness", "metallic", "specular", "specularColor"}
    assert back.textures["roughness"].path == back.textures["metallic"].path  # packed into one image
    got = map_values(load_map_set(back.to_map_set(tmp_path / "back")))
    want = map_values(ms)
    for k in ("roughness", "metallic", "specular"):
        np.testing.assert_allclose(got[k], want[k], atol=0.5 / 255 + 1e-6, err_msg=k)
    for k in ("baseColor", "specularColor"):  # compare in the sRGB code domain
        np.testing.assert_allclose(linear_to_srgb(got[k]), linear_to_srgb(want[k]), atol=0.5 / 255 + 1e-5, err_msg=k)


def test_uniform_material_without_source_writes_factors_and_only_needed_extensions(tmp_path):
    m = Material.create(MR, {"baseColor": [0.9, 0.5, 0.1], "metallic": 0.0, "roughness": 0.3})
    doc = validate(write(tmp_path / "u.gltf", m))
    mat = doc["materials"][0]
    assert mat["pbrMetallicRoughness"] == {
        "baseColorFactor": [0.9, 0.5, 0.1, 1.0],
        "metallicFactor": 0.0,
        "roughnessFactor": 0.3,
    }
    assert "extensions" not in mat and "extensionsUsed" not in doc and "images" not in doc
    assert (tmp_path / "u.bin").is_file()
    assert read(tmp_path / "u.gltf").material() == m
    m2 = m.with_params({"ior": 1.33, "specularColor": [1.0, 0.5, 0.5]})
    doc = validate(write(tmp_path / "u2.glb", m2))
    assert doc["extensionsUsed"] == ["KHR_materials_ior", "KHR_materials_specular"]
    assert doc["materials"][0]["extensions"]["KHR_materials_ior"] == {"ior": 1.33}
    back = read(tmp_path / "u2.glb").material()
    for k, v in m2.values.items():
        np.testing.assert_allclose(back.values[k], v, err_msg=k)


def make_source_scene(folder: Path) -> Path:
    """A .gltf with two materials, a mesh in an external .bin, an occlusion texture, a sampler and the
    specular extension on the material that will be replaced."""
    folder.mkdir(parents=True)
    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=np.float32)
    (folder / "mesh.bin").write_bytes(pos.tobytes())
    (folder / "ao.png").write_bytes(png_bytes(folder, ramp(seed=20)))
    (folder / "nrm.png").write_bytes(png_bytes(folder, ramp(seed=21)))
    doc = {
        "asset": {"version": "2.0", "generator": "test"},
        "extensionsUsed": ["KHR_materials_specular", "KHR_materials_clearcoat"],
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "material": 1}]}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}
        ],
        "bufferViews": [{"buffer": 0, "byteLength": 36}],
        "buffers": [{"uri": "mesh.bin", "byteLength": 36}],
        "samplers": [{"wrapS": 33071, "wrapT": 33071}],
        "images": [{"uri": "ao.png"}, {"uri": "nrm.png"}],
        "textures": [{"source": 0, "sampler": 0}, {"source": 1}],
        "materials": [
            {"name": "keep", "extensions": {"KHR_materials_clearcoat": {"clearcoatFactor": 1.0}}},
            {
                "name": "car",
                "occlusionTexture": {"index": 0},
                "normalTexture": {"index": 1},
                "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}, "metallicRoughnessTexture": {"index": 0}},
                "extensions": {"KHR_materials_specular": {"specularFactor": 0.5}},
            },
        ],
    }
    (folder / "scene.gltf").write_text(json.dumps(doc))
    return folder / "scene.gltf"


@pytest.mark.parametrize("suffix", [".gltf", ".glb"])
def test_writing_over_a_source_copies_the_file_with_the_material_replaced(tmp_path, suffix):
    src = make_source_scene(tmp_path / "src")
    asset = read(src, "car")
    ms = load_map_set(mr_map_set(tmp_path / "maps", with_specular=False))
    (tmp_path / "out").mkdir()
    out = write_asset(tmp_path / "out" / f"car{suffix}", ms, source=asset)
    doc = validate(out)
    keep, car = doc["materials"]
    assert keep == {"name": "keep", "extensions": {"KHR_materials_clearcoat": {"clearcoatFactor": 1.0}}}
    assert car["occlusionTexture"] == {"index": 0} and car["normalTexture"] == {"index": 1}  # kept
    assert doc["meshes"][0]["primitives"][0]["material"] == 1
    # specular is back at its default: the extension leaves the material and extensionsUsed
    assert doc["extensionsUsed"] == ["KHR_materials_clearcoat", "KHR_materials_ior"]
    assert "KHR_materials_specular" not in car["extensions"]
    bc = doc["textures"][car["pbrMetallicRoughness"]["baseColorTexture"]["index"]]
    assert bc["sampler"] == 0  # the replaced texture's sampler
    # the kept normal map is the source's own file, referenced where it lies: outside the copy's folder,
    # so reading the copy back needs the source's folder allowed
    back = read(out, "car", confinement=Confinement.of([tmp_path / "src"]))
    assert back.normal is not None and back.constants["specular"] == 1.0
    got = map_values(load_map_set(back.to_map_set(tmp_path / "back")))
    want = map_values(ms)
    np.testing.assert_allclose(got["roughness"], want["roughness"], atol=0.5 / 255 + 1e-6)
    np.testing.assert_allclose(got["metallic"], want["metallic"], atol=0.5 / 255 + 1e-6)
    # the mesh still loads: its buffer is referenced from the new folder (or carried in the BIN chunk)
    b = doc["buffers"][doc["bufferViews"][0]["buffer"]]
    data = (out.parent / b["uri"]).read_bytes()
    assert np.frombuffer(data[:36], dtype=np.float32).reshape(3, 3)[1, 0] == 1.0
    assert (tmp_path / "src" / "scene.gltf").read_text() == src.read_text()


def test_glb_source_to_glb_and_gltf_keeps_embedded_images(tmp_path):
    mats = [{"name": "a", "normalTexture": {"index": 0}, "pbrMetallicRoughness": {"roughnessFactor": 0.2}}]
    src = make_file(tmp_path / "src", "s.glb", mats, {"n": ramp(seed=30)}, store="bufferView")
    asset = read(src)
    m = Material.create(MR, {"baseColor": 0.5, "metallic": 1.0, "roughness": 0.7})
    for name in ("o.glb", "o.gltf"):
        out = write(tmp_path / name, m, source=asset)
        doc = validate(out)
        assert doc["materials"][0]["pbrMetallicRoughness"]["roughnessFactor"] == 0.7
        back = read(out)
        assert back.material() == m.with_params({"baseColor": 0.5})
        n1, _ = read_image(back.normal.path, "linear", colour=False)
        n0, _ = read_image(asset.normal.path, "linear", colour=False)
        np.testing.assert_array_equal(n1, n0)
    assert (tmp_path / "o.bin").is_file()


def test_writer_refuses_other_models_existing_files_and_inputs(tmp_path):
    ward = Material.create("mitsuba06:ward", {"variant": "ward"})
    with pytest.raises(
        MatremapError, match="glTF stores gltf:metal-rough and gltf:pbr materials, and this result is mitsuba06:ward"
    ):
        write(tmp_path / "w.glb", ward)
    m = Material.create(MR, {"roughness": 0.5})
    with pytest.raises(MatremapError, match="name it .gltf or .glb"):
        write(tmp_path / "w.obj", m)
    write(tmp_path / "w.glb", m)
    with pytest.raises(MatremapError, match="already exists; pass --force"):
        write(tmp_path / "w.glb", m)
    write(tmp_path / "w.glb", m.with_params({"roughness": 0.25}), force=True)
    assert read(tmp_path / "w.glb").material().values["roughness"][0] == 0.25
    src = make_source_scene(tmp_path / "src")
    before = src.read_bytes()
    with pytest.raises(MatremapError, match="would overwrite the input"):
        write(src, m, source=read(src, "car"), force=True)
    (tmp_path / "src" / "x.gltf").write_text("{}")
    with pytest.raises(MatremapError, match="already exists"):  # x.bin, x.gltf: nothing half written
        write(tmp_path / "src" / "x.gltf", m, force=False)
    assert src.read_bytes() == before
    assert not list(tmp_path.rglob(".*"))  # no temporary files left behind


def test_a_failure_at_the_last_file_takes_back_the_textures_and_bin(tmp_path, monkeypatch):
    ms = load_map_set(mr_map_set(tmp_path / "maps"))
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "o_baseColor.png").write_bytes(b"old")
    real = os.replace

    def replace(src, dst):  # the .gltf is moved into place last, after its textures and .bin
        if Path(dst).name == "o.gltf":
            raise OSError("disk full")
        real(src, dst)

    monkeypatch.setattr(os, "replace", replace)
    with pytest.raises(OSError, match="disk full"):
        write(tmp_path / "out" / "o.gltf", ms, force=True)
    assert listing(tmp_path / "out") == {"o_baseColor.png"}  # no o.bin, no new textures, no staging folder
    assert (tmp_path / "out" / "o_baseColor.png").read_bytes() == b"old"
