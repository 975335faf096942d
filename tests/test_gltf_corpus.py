"""`matremap remap` on the glTF files added to the corpus for issue 15 (Khronos sample assets; sources and
licences in tests/data/corpus/README.md), checked outside matremap: the written file loads in its own
library (pygltflib and the validator's offline rules; Mitsuba 3's loader) and keeps the input's colour,
or the run is refused in one line that names the glTF extension. `python benchmarks/real_assets.py` runs
every glTF file of the corpus onto glTF, Mitsuba 3 rough plastic and Cycles Principled and prints the table."""

from __future__ import annotations

from pathlib import Path

import corpus_checks as cc
import gltf_validation as gv
import numpy as np
import pytest

from matremap.cli import main

CORPUS = Path(__file__).resolve().parent / "data" / "corpus"
FAST = ["--rotations", "0:360:2", "--size", "48", "--env-lights", "32"]
PLASTIC = ["mitsuba3:roughplastic", "--fix", "distribution=ggx"]

pytest.importorskip("colour", reason="the quality gate needs colour-science")


def remap(src: Path, out: Path, *args: str) -> int:
    return main(["remap", str(src), "-o", str(out), *FAST, *args])


def test_a_transmissive_material_onto_a_model_nothing_draws_it_for_is_refused(tmp_path, capsys):
    """Mitsuba 3's rough plastic: its renderer does not draw the transmission probe and the embedded renderer does
    not emulate it, so the glass's fit could not be judged (test_transmission_fit.py has the models it can be)."""
    src = CORPUS / "gltf-AttenuationTest" / "AttenuationTest.glb"
    code = remap(src, tmp_path / "o", "--material", "R2_and_R4_ThicknessFac_1.0", "--to", *PLASTIC)
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and "transmits light" in err[-1] and "mitsuba3:roughplastic" in err[-1]
    assert "Traceback" not in "\n".join(err) and not (tmp_path / "o").exists()


def test_an_emissive_material_converts_onto_mitsuba_and_keeps_its_black_base(tmp_path, capsys):
    pytest.importorskip("mitsuba")
    src = CORPUS / "gltf-EmissiveStrengthTest" / "EmissiveStrengthTest.glb"
    code = remap(src, tmp_path / "o", "--material", "Emit4", "--to", *PLASTIC)
    said = capsys.readouterr()
    assert code == 0 and "KHR_materials_emissive_strength 4" in said.out + said.err  # the carried emission noted
    f = cc.find_output_file(tmp_path / "o")
    assert f is not None and cc.mitsuba_loads(f)[0]
    assert cc.mean_luminance(cc.material_colour(f)) < 0.02  # black base colour, black diffuse


def test_a_transformed_textured_material_onto_gltf_is_the_baked_map(tmp_path):
    """TextureTransformTest 'Offset U' onto its own model: the written file is valid, the new texture has no
    transform, and it holds the stored image shifted by half its width (the transform baked)."""
    src = CORPUS / "gltf-TextureTransformTest" / "TextureTransformTest.gltf"
    code = remap(src, tmp_path / "o", "--material", "Offset U", "--to", "gltf:metal-rough")
    assert code == 0
    f = cc.find_output_file(tmp_path / "o")
    assert f is not None and gv.offline_check(f) == []
    g = gv.load(f)
    mat = next(m for m in g.materials if m.name == "Offset U")
    info = mat.pbrMetallicRoughness.baseColorTexture
    assert not (info.extensions or {}).get("KHR_texture_transform")
    assert g.textures[info.index].sampler == 0  # the clamp sampler kept
    written = cc.gltf_base_colour(f, "Offset U")
    stored = cc.read_image(src.parent / "UV.png", srgb=True)[..., :3]
    w = stored.shape[1]
    np.testing.assert_allclose(written[:, : w // 2], stored[:, w // 2 :], atol=0.01)
