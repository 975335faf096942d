"""glTF writing checked independently (tests/gltf_validation.py: pygltflib, the validator's offline rules,
the Khronos glTF Validator when node can load it): a map set written with no source, and ``write_all``
over public multi-material files (tests/data/corpus, licences in its README) -- every material index
still resolves, the geometry reads the same bytes, and each converted material reads back to its values."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import gltf_validation as gv
import numpy as np
import pytest
from test_formats_gltf import mr_map_set

from matremap.core.material import Material
from matremap.errors import MatremapError
from matremap.formats import write_all as formats_write_all
from matremap.formats import write_asset
from matremap.formats.gltf import material_names, read, write_all
from matremap.svbrdf.textures import MapSet, load_map_set, read_image

CORPUS = Path(__file__).resolve().parent / "data" / "corpus"
MR = "gltf:metal-rough"
KEPT = ("scene", "scenes", "nodes", "meshes", "animations", "skins", "cameras", "samplers", "asset")


def code_values(path: Path, channel: int) -> np.ndarray:
    import OpenImageIO as oiio

    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    inp = oiio.ImageInput.open(str(path), config)
    spec = inp.spec()
    a = np.asarray(inp.read_image(0, 0, 0, spec.nchannels, oiio.FLOAT)).reshape(spec.height, spec.width, -1)
    inp.close()
    return a[..., channel]


@pytest.mark.parametrize("suffix", [".gltf", ".glb"])
def test_a_map_set_without_source_is_a_valid_file_with_packed_textures(tmp_path, suffix):
    ms = load_map_set(mr_map_set(tmp_path / "maps", with_specular=True))
    (tmp_path / "out").mkdir()
    out = write_asset(tmp_path / "out" / f"m{suffix}", ms)
    assert gv.offline_check(out) == []
    g = gv.load(out)
    mat = g.materials[0]
    assert len(g.meshes) == 1 and g.meshes[0].primitives[0].material == 0
    doc = json.loads(g.to_json())
    pbr = doc["materials"][0]["pbrMetallicRoughness"]
    mr_tex = g.textures[pbr["metallicRoughnessTexture"]["index"]].source
    base_tex = g.textures[pbr["baseColorTexture"]["index"]].source
    back = read(out)
    # roughness in G, metallic in B of one texture; base colour sRGB-encoded
    assert back.textures["roughness"].path == back.textures["metallic"].path
    assert back.textures["roughness"].channels == (1,) and back.textures["metallic"].channels == (2,)
    assert mr_tex != base_tex and back.textures["baseColor"].colorspace == "srgb"
    for name, channel in (("roughness", 1), ("metallic", 2)):
        want, _ = read_image(ms.maps[name], ms.colorspace[name], colour=False)
        got = code_values(back.textures[name].path, channel)
        np.testing.assert_allclose(got, want[..., 0], atol=0.5 / 255 + 1e-6)
    ext = mat.extensions or {}
    assert "KHR_materials_specular" in ext and "KHR_materials_specular" in (g.extensionsUsed or [])
    report = gv.khronos_validator(out)
    if report is not None:
        assert report["numErrors"] == 0, report["messages"]


def test_the_khronos_validator_finds_no_error_in_written_files(tmp_path):
    """Skipped without node's gltf-validator (install: see gltf_validation.INSTALL)."""
    m = Material.create(MR, {"baseColor": [0.8, 0.2, 0.1], "metallic": 0.0, "roughness": 0.3, "ior": 1.4})
    out = write_asset(tmp_path / "u.glb", m)
    report = gv.khronos_validator(out)
    if report is None:
        pytest.skip(f"the Khronos glTF Validator is not available: {gv.INSTALL}")
    assert report["numErrors"] == 0 and report["numWarnings"] == 0, report["messages"]


# ------------------------------------------------------------------------------------------------
# write_all


def converted(material: Material, i: int) -> Material:
    """A 'converted' uniform material: the values moved so that a kept original would be caught."""
    r = float(np.asarray(material.values["roughness"]).reshape(-1)[0])
    base = np.asarray(material.values["baseColor"], dtype=float)
    return material.with_params({"roughness": 0.05 + 0.9 * (1 - r), "baseColor": 0.1 + 0.8 * base[::-1]})


def results_of(src: Path, tmp_path: Path) -> tuple[list[tuple[str, Any]], dict[str, Any]]:
    """Each material of ``src`` that reads and unpacks, as the batch would hand it to write_all: a map set
    for a textured one (as read), a moved uniform material otherwise."""
    results, want = [], {}
    for i, name in enumerate(material_names(src)):
        try:
            asset = read(src, i)
            if asset.lost:
                continue
            result: Any = (
                load_map_set(asset.to_map_set(tmp_path / f"ms{i}"))
                if asset.textured
                else converted(asset.material(), i)
            )
        except MatremapError:
            continue  # a material the batch would refuse (textures of two sizes, ...): not in the results
        results.append((name, result))
        want[name] = result
    return results, want


def texture_free_json(path: Path) -> dict[str, Any]:
    return json.loads(gv.load(path).to_json())


@pytest.mark.parametrize(
    "pattern",
    [
        "gltf-TextureCoordinateTest/*.glb",
        "gltf-MetalRoughSpheresNoTextures/*.glb",
        "gltf-ClearCoatTest/*.glb",
        "gltf-TextureTransformTest/*.gltf",
    ],
)
@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
def test_write_all_replaces_every_material_in_place(tmp_path, pattern, suffix):
    src = sorted(CORPUS.glob(pattern))[0]
    results, want = results_of(src, tmp_path)
    assert len(results) >= 3
    (tmp_path / "out").mkdir()
    out = write_all(tmp_path / "out" / f"{src.stem}{suffix}", results, src)
    assert gv.offline_check(out) == []
    # geometry, primitives' materials and the scene graph as they were
    assert gv.primitive_materials(out) == gv.primitive_materials(src)
    assert gv.accessor_digest(out) == gv.accessor_digest(src)
    a, b = texture_free_json(src), texture_free_json(out)
    for key in KEPT:
        assert a.get(key) == b.get(key), key
    assert [m.get("name") for m in a["materials"]] == [m.get("name") for m in b["materials"]]
    # each converted material reads back to the converted values; the others are untouched
    names = material_names(out)
    for i, name in enumerate(names):
        before = a["materials"][i]
        after = b["materials"][i]
        kept_ext = {k: v for k, v in (before.get("extensions") or {}).items() if "ior" not in k and "specular" not in k}
        after_ext = {k: v for k, v in (after.get("extensions") or {}).items() if k in kept_ext}
        coat_maps = {"clearcoat": "clearcoatTexture", "clearcoatRoughness": "clearcoatRoughnessTexture"}
        written = [t for k, t in coat_maps.items() if isinstance(want.get(name), MapSet) and k in want[name].maps]
        factors = [t.replace("Texture", "Factor") for t in written]
        if written:  # a coat mask or roughness map: a new texture, its factor 1 (the pixels: test_held_layers.py)
            kept_ext, after_ext = (
                {k: {f: x for f, x in v.items() if f not in written + factors} for k, v in e.items()}
                for e in (kept_ext, after_ext)
            )
            assert set(written) <= set(after["extensions"]["KHR_materials_clearcoat"])
        assert gv.resolved(out, after_ext) == gv.resolved(src, kept_ext)
        if name not in want:
            assert gv.resolved(out, after) == gv.resolved(src, before)
            continue
        back = read(out, i)
        if isinstance(want[name], Material):
            for k, v in want[name].values.items():
                np.testing.assert_allclose(np.asarray(back.material().values[k]), np.asarray(v), atol=1e-6)
        else:
            ms: MapSet = want[name]
            got = load_map_set(back.to_map_set(tmp_path / f"back{i}"))
            for k, f in ms.maps.items():
                w, _ = read_image(f, ms.colorspace[k], colour=k == "baseColor")
                g, _ = read_image(got.maps[k], got.colorspace[k], colour=k == "baseColor")
                np.testing.assert_allclose(
                    g[..., : w.shape[-1]], w, atol=0.01 if k == "baseColor" else 0.5 / 255 + 1e-6
                )

    # no image left that nothing uses, unless the input had it so
    def unused_images(doc: dict[str, Any]) -> int:
        return len(doc.get("images", [])) - len({t.get("source") for t in doc.get("textures", [])})

    assert unused_images(b) <= unused_images(a)
    report = gv.khronos_validator(out)
    if report is not None:
        errors = lambda r: {m["code"] for m in r["messages"] if m["severity"] == 0}  # noqa: E731
        assert errors(report) <= errors(gv.khronos_validator(src)), report["messages"]


@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
def test_write_all_without_a_gltf_source_puts_each_material_on_its_own_sphere(tmp_path, suffix):
    results = [
        ("red", Material.create(MR, {"baseColor": [0.8, 0.1, 0.1], "metallic": 0.0, "roughness": 0.4})),
        ("gold", Material.create(MR, {"baseColor": [1.0, 0.78, 0.34], "metallic": 1.0, "roughness": 0.2})),
        ("tex", load_map_set(mr_map_set(tmp_path / "maps"))),
    ]
    (tmp_path / "out").mkdir()
    out = formats_write_all(tmp_path / "out" / f"all{suffix}", results, None)
    assert gv.offline_check(out) == []
    g = gv.load(out)
    assert material_names(out) == ["red", "gold", "tex"]
    assert gv.primitive_materials(out) == [0, 1, 2]
    assert sorted(n.translation[0] for n in g.nodes) == [0.0, 2.0, 4.0]
    np.testing.assert_allclose(read(out, "gold").material().values["baseColor"], [1.0, 0.78, 0.34], atol=1e-6)
    assert read(out, "tex").textured and not read(out, "red").textured


def test_write_all_refuses_names_the_source_does_not_have(tmp_path):
    src = CORPUS / "gltf-MetalRoughSpheresNoTextures" / "MetalRoughSpheresNoTextures.glb"
    m = Material.create(MR, {"roughness": 0.5})
    with pytest.raises(MatremapError, match="has no material 'nope' left to replace"):
        write_all(tmp_path / "x.glb", [("nope", m)], src)
    assert not (tmp_path / "x.glb").exists()


def test_a_malformed_extensions_used_list_keeps_its_names_and_drops_the_rest():
    """A source whose extensionsUsed holds a non-string (a list) made the writer raise TypeError."""
    from matremap.formats.gltf_edit import update_extension_lists

    doc = {"extensionsUsed": ["KHR_materials_sheen", ["x"], 3], "materials": [{"extensions": {"KHR_x": {}}}]}
    update_extension_lists(doc)
    assert doc["extensionsUsed"] == ["KHR_materials_sheen", "KHR_x"]
    doc = {"extensionsUsed": {"not": "a list"}, "materials": []}
    update_extension_lists(doc)
    assert "extensionsUsed" not in doc
