"""Every public Mitsuba scene of tests/data/corpus (mitsuba-blender's test scenes, BSD-3-Clause) remapped
with the command line, as a user would: it converts -- the written file loads in its own library -- or is
refused with one line naming the feature (exit 2), or is fitted, written and failed by the quality gate (exit 3:
a glass onto a target that cannot transmit), never a traceback. Textured diffuse and roughplastic
scenes (no public licensed one exists; written here) convert and pass the quality gate."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import corpus_checks as cc
import numpy as np
import pytest

from matremap.cli import main
from matremap.svbrdf.textures import ImageInfo, write_image_like

CORPUS = Path(__file__).resolve().parent / "data" / "corpus"
FAST = ["--rotations", "0:360:2", "--size", "48", "--env-lights", "32"]

#: fitted and written, failed by the quality gate (exit 3)
GATE = "FAILED: fit_error"
#: the corpus's glasses: water inside a medium of IOR 1.6789 (relative IOR 0.79), tinted; gltf:metal-rough has no
#: transmission, so the closest look it has is far (fit error 0.6-0.93 on the transmission probe)
GLASS = GATE

#: corpus folder -> None (converts onto glTF), GATE, or the words its one-line refusal must hold
EXPECTED = {
    "mitsuba-blendbsdf": "blends only two BSDFs of one model",  # a diffuse and a dielectric
    "mitsuba-bumpmap": "Texture::eval_1_grad",
    "mitsuba-conductor": None,
    "mitsuba-dielectric": GLASS,
    "mitsuba-diffuse": None,
    "mitsuba-mask": None,
    "mitsuba-normalmap": None,
    "mitsuba-plastic": None,
    "mitsuba-principled": "principled anisotropic 0.6 (anisotropy)",  # its clearcoat 0.8 alone would be fitted
    "mitsuba-roughconductor_anisotropic": None,  # alpha_u 0.4 / alpha_v 0.2: fit error 0.2455, passes
    "mitsuba-roughconductor_isotropic": None,
    "mitsuba-roughdielectric_isotropic": GLASS,
    "mitsuba-roughplastic": None,
    "mitsuba-test1": None,
    "mitsuba-thindielectric": GLASS,
    "mitsuba-twosided_1": None,
    "mitsuba-twosided_2": "Mitsuba 3 refuses too",  # a dielectric back side: Mitsuba fails to load it
}

pytest.importorskip("colour", reason="the quality gate needs colour-science")


def test_every_mitsuba_corpus_scene_is_listed():
    assert sorted(p.name for p in CORPUS.glob("mitsuba-*")) == sorted(EXPECTED)


@pytest.mark.parametrize("folder", sorted(EXPECTED))
def test_corpus_scene_onto_gltf_converts_or_is_refused_in_one_line(tmp_path, capsys, folder):
    src = next((CORPUS / folder).glob("*.xml"))
    code = main(["remap", str(src), "--to", "gltf:metal-rough", "-o", str(tmp_path / "out"), *FAST])
    err = capsys.readouterr().err
    assert "Traceback" not in err
    why = EXPECTED[folder]
    if why == GATE:
        last = err.strip().splitlines()[-1]
        assert code == 3 and GATE in last, last
        out = cc.find_output_file(tmp_path / "out")
        assert out is not None and out.suffix == ".gltf" and cc.file_loads(out)[0]
        return
    if why is not None:
        last = err.strip().splitlines()[-1]
        assert code == 2 and why in last and str(src) in last, last
        assert not (tmp_path / "out").exists()
        return
    assert code == 0, err
    out = cc.find_output_file(tmp_path / "out")
    assert out is not None and out.suffix == ".gltf" and cc.file_loads(out)[0]


def textured_scene(tmp_path: Path, plugin: str) -> Path:
    y, x = np.mgrid[0:64, 0:64] / 64.0
    albedo = np.stack([0.2 + 0.6 * x, 0.3 + 0.3 * y, 0.1 + 0.2 * np.sin(6 * x) ** 2], -1).astype(np.float32)
    write_image_like(tmp_path / "albedo.png", albedo, ImageInfo("png", "uint8", 3, 0, 0, "srgb"), force=True)
    tex = '<texture type="bitmap" name="{}"><string name="filename" value="albedo.png"/></texture>'
    body = {
        "diffuse": f'<bsdf type="diffuse" id="wood">{tex.format("reflectance")}</bsdf>',
        "roughplastic": '<bsdf type="roughplastic" id="toy"><string name="distribution" value="ggx"/>'
        f'<float name="alpha" value="0.15"/>{tex.format("diffuse_reflectance")}</bsdf>',
    }[plugin]
    p = tmp_path / f"{plugin}.xml"
    ref = "wood" if plugin == "diffuse" else "toy"
    p.write_text(f'<scene version="3.0.0">{body}<shape type="sphere"><ref id="{ref}"/></shape></scene>')
    return p


@pytest.mark.parametrize("plugin", ["diffuse", "roughplastic"])
def test_textured_diffuse_and_roughplastic_scenes_convert(tmp_path, capsys, plugin):
    """They ended in '2 usable points: too few to learn'; then a diffuse-only sweep from 0 (black, refused) left
    the darkest 16 % of texels outside the learned domain."""
    src = textured_scene(tmp_path, plugin)
    code = main(["remap", str(src), "--to", "gltf:metal-rough", "-o", str(tmp_path / "out"), *FAST])
    err = capsys.readouterr().err
    assert code == 0, err
    out = cc.find_output_file(tmp_path / "out")
    assert out is not None and cc.file_loads(out)[0]
    cin, cout = cc.read_image(tmp_path / "albedo.png", srgb=True), cc.gltf_base_colour(out)
    assert cc.hue_difference(cc.mean_hue(cin), cc.mean_hue(cout)) < 10
    assert 0.7 < cc.mean_luminance(cout) / cc.mean_luminance(cin) < 1.3


@pytest.mark.skipif(
    not (Path(__file__).resolve().parents[1] / ".venv-bpy" / "bin" / "python").exists()
    and importlib.util.find_spec("bpy") is None,
    reason="Blender's bpy not installed: see docs/cycles.md (a .venv-bpy with pip install bpy)",
)
@pytest.mark.parametrize("folder", ["mitsuba-conductor", "mitsuba-twosided_1"])
def test_corpus_scene_onto_cycles_principled_writes_a_blend_bpy_opens(tmp_path, capsys, folder):
    src = next((CORPUS / folder).glob("*.xml"))
    code = main(["remap", str(src), "--to", "cycles:principled", "-o", str(tmp_path / "out"), *FAST])
    err = capsys.readouterr().err
    assert code == 0 and "Traceback" not in err, err
    out = cc.find_output_file(tmp_path / "out")
    assert out is not None and out.suffix == ".blend"
    _, loads, message = cc.blend_colour(out, Path(__file__).resolve().parents[1] / ".venv-bpy" / "bin" / "python")
    assert loads, message


def test_smooth_silver_onto_gltf_keeps_its_colour(tmp_path, capsys):
    """The mirror is read as GGX at alpha 1e-4: its widened fit keeps F0 (read as Beckmann it came out white)."""
    pytest.importorskip("mitsuba")
    src = CORPUS / "mitsuba-conductor" / "conductor.xml"
    assert main(["remap", str(src), "--to", "gltf:metal-rough", "-o", str(tmp_path / "out"), *FAST]) == 0
    out = cc.find_output_file(tmp_path / "out")
    ratio = cc.mean_luminance(cc.gltf_base_colour(out)) / cc.mean_luminance(cc.material_colour(src))
    assert 0.95 < ratio < 1.05, ratio
