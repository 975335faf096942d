"""The Khronos sample assets with KHR_materials_sheen that are too large for the corpus (SheenChair, SheenCloth,
GlamVelvetSofa; fetched on demand, tests/data/corpus/README.md "Larger assets, fetched on demand") read with
:mod:`matremap.formats`: every material by name, in the file's order, and each sheen's factors as the file gives
them (read beside the file with :mod:`json`), with the reader saying what becomes of the sheen. Reading only; the
conversions are tested elsewhere. Skipped when an asset has not been fetched."""

from __future__ import annotations

import json

import pytest
from large_assets import large_asset

from matremap import formats

SHEEN = "KHR_materials_sheen"
#: asset -> (its .gltf, how many of its materials have a sheen), so a file without one cannot pass unnoticed
FILES = {
    "gltf-SheenChair": ("SheenChair.gltf", 2),
    "gltf-SheenCloth": ("SheenCloth.gltf", 1),
    "gltf-GlamVelvetSofa": ("GlamVelvetSofa.gltf", 5),
}


@pytest.mark.parametrize("name", list(FILES))
def test_every_material_reads_with_its_sheen(name):
    file, n_sheen = FILES[name]
    path = large_asset(name) / file
    materials = json.loads(path.read_text(encoding="utf-8"))["materials"]
    assert formats.material_names(path) == [m["name"] for m in materials]
    sheens = 0
    for index, m in enumerate(materials):
        asset = formats.read_asset(path, m["name"])
        assert (asset.name, asset.index, asset.format) == (m["name"], index, "gltf")
        given = m.get("extensions", {}).get(SHEEN)
        said = [line for line in asset.notes + asset.lost if SHEEN in line]
        if given is None:
            assert "sheenColor" not in asset.constants and not said, m["name"]
            continue
        sheens += 1
        colour, roughness = given.get("sheenColorFactor", [0.0] * 3), given.get("sheenRoughnessFactor", 0.0)
        read = asset.document.extensions[SHEEN]
        assert (read["sheenColorFactor"], read["sheenRoughnessFactor"]) == (colour, roughness), m["name"]
        if "sheenColor" in asset.constants:  # read into gltf:pbr, where the sheen is fitted
            assert asset.model == "gltf:pbr", m["name"]
            assert asset.constants["sheenColor"] == colour and asset.constants["sheenRoughness"] == roughness
        else:  # kept on a glTF copy, refused or left out elsewhere: the reader says so
            assert said, m["name"]
    assert sheens == n_sheen
