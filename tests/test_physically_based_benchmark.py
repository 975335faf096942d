"""benchmarks/physically_based.py on the PhysicallyBased data of the ``materialxmaterials`` package (Anton
Palmqvist's database, CC0, with Bernard Kwok's MaterialX translations; skipped without the package): both
translations it reads (OpenPBR, Standard Surface) give the 110 materials, 33 of them transmissive, each naming a
material of its file; and a transmissive one goes the way ``matremap remap FILE --material NAME --to gltf:pbr``
takes it (the transmission-probe fit: a glTF volume that lets light through, the gate passed), closer to the
OpenPBR render than the hand-made glTF, which is thin-walled (measured, 96 px: Water 0.042 against 0.85)."""

from __future__ import annotations

import sys
from collections import Counter
from pathlib import Path

import pytest

pytest.importorskip("MaterialX")
pytest.importorskip("materialxMaterials")

from matremap.formats.materialx import material_names  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import physically_based as pb  # noqa: E402

GLTF_FILE = "PhysicallyBasedMaterialX_GLTF.mtlx"


def entries(source: str) -> list[pb.Entry]:
    src = pb.SOURCES[source]
    data = pb.data_dir()
    defs = pb.shader_inputs(data / src.file, src.category)
    hand = pb.shader_inputs(data / GLTF_FILE, "gltf_pbr")
    return [pb.classify(src, name, "", material, values, hand[name][1]) for name, (material, values) in defs.items()]


@pytest.mark.parametrize("source", sorted(pb.SOURCES))
def test_each_translation_reads_the_110_materials(source):
    found = entries(source)
    assert len(found) == 110
    assert Counter(e.kind for e in found) == {"opaque": 77, "transmissive": 33}
    names = set(material_names(pb.data_dir() / pb.SOURCES[source].file))
    assert {e.material for e in found} <= names  # what remap_file is asked for exists in the file
    assert all(e.source is not None and e.source.model == pb.SOURCES[source].model for e in found)


def test_a_transmissive_material_is_remapped_as_the_cli_does(tmp_path):
    water = next(e for e in entries("open_pbr") if e.name == "Water")
    pb.run_transmissive(water, pb.data_dir() / pb.SOURCES["open_pbr"].file, 32, "builtin", tmp_path)
    assert water.passed, water.verdict
    fitted = water.fitted.values
    assert fitted["transmission"][0] > 0.9 and fitted["thickness"][0] > 0.0  # a volume, refracting
    assert water.hand.values["thickness"][0] == 0.0  # the hand-made glTF is thin-walled
    assert water.err["b"]["rmse"] < 0.1 < water.err["a"]["rmse"]
    assert water.err["c"]["rmse"] < 0.1  # the read-across formula, reported beside the fit
