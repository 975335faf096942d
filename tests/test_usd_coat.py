"""UsdPreviewSurface's clearcoat is a layer like glTF's (a second white GGX lobe weighted by ``clearcoat``, its
roughness ``clearcoatRoughness``; UsdPreviewSurface 2.5 specification): a coated source keeps a coat there,
fitted with the target's own layer, instead of being absorbed into the base and written with clearcoat 0."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from matremap.core.material import Material
from matremap.core.scene import parse_probe
from matremap.dialects.mtlx import LAYER_PARAMS, LAYERS, layers_on
from matremap.remap import remap_file
from matremap.renderers import get_renderer


def coated_gltf(folder: Path) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    material = {
        "name": "paint",
        "pbrMetallicRoughness": {
            "baseColorFactor": [0.5, 0.05, 0.02, 1.0],
            "metallicFactor": 0.0,
            "roughnessFactor": 0.45,
        },
        "extensions": {"KHR_materials_clearcoat": {"clearcoatFactor": 1.0, "clearcoatRoughnessFactor": 0.1}},
    }
    doc = {"asset": {"version": "2.0"}, "extensionsUsed": ["KHR_materials_clearcoat"], "materials": [material]}
    (folder / "paint.gltf").write_text(json.dumps(doc))
    return folder / "paint.gltf"


def test_usd_preview_surface_names_its_coat_as_a_layer():
    assert LAYERS["usd:preview_surface"]["coat"] == "clearcoat"
    assert LAYER_PARAMS["usd:preview_surface"]["coat"].roughness == "clearcoatRoughness"
    assert layers_on("usd:preview_surface", {"clearcoat": 0.5}) == ["coat"]


def test_a_clear_coated_gltf_keeps_its_coat_on_usd_preview_surface(tmp_path, monkeypatch):
    monkeypatch.setenv("MATREMAP_CACHE", str(tmp_path / "cache"))
    lines: list[str] = []
    res = remap_file(
        coated_gltf(tmp_path / "in"), "usd:preview_surface", tmp_path / "out", log=lines.append, evaluate=False
    )
    fitted = json.loads((tmp_path / "out" / "material.json").read_text())["params"]
    assert fitted["clearcoat"] > 0.3 and fitted["clearcoatRoughness"] < 0.3, fitted
    assert not any("absorbed" in line for line in lines), lines
    # under the environment the coat carries the look: the same fit with the coat off is far from the source
    scene = parse_probe("env").views()[0]
    source = Material.create(
        "gltf:pbr",
        {
            "baseColor": [0.5, 0.05, 0.02],
            "metallic": 0.0,
            "roughness": 0.45,
            "clearcoat": 1.0,
            "clearcoatRoughness": 0.1,
        },
    )
    target = Material.create("usd:preview_surface", fitted)
    bare = Material.create("usd:preview_surface", {**fitted, "clearcoat": 0.0})
    ref, got, lost = get_renderer("embedded").render([source, target, bare], scene)
    mask = scene.mask()

    def off(img: np.ndarray) -> float:
        return float(np.linalg.norm(img[mask] - ref[mask]) / np.linalg.norm(ref[mask]))

    assert off(got) < 0.5 * off(lost), (off(got), off(lost))
    assert res.verdict.passed, res.verdict.line()
