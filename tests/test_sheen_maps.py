"""A sheen whose colour and roughness are maps (KHR_materials_sheen's sheenColorTexture and sheenRoughnessTexture,
an OpenPBR fuzz_color image): converted at levels of each (an additive grid,
:func:`matremap.svbrdf.mixed.layer_levels`), the colour at grey levels of its brightest channel with each texel's
hue given back to the target's layer colour.

Checked by what the written files hold, independently of matremap's score: the target's sheen (fuzz) colour keeps
the source's hue where there is a sheen, its weight follows the sheen's brightness, its roughness the source's
roughness map; a glTF written with sheen maps loads in pygltflib with both textures. Khronos SheenCloth (CC0,
fetched on demand: ``python tools/fetch_assets.py gltf-SheenCloth``) is the real file.
"""

from __future__ import annotations

import colorsys
import json
from pathlib import Path

import numpy as np
import pytest

from matremap.cli import main
from matremap.formats import read_asset
from matremap.svbrdf.mixed import chroma
from matremap.svbrdf.textures import load_map_set, read_image

pytest.importorskip("colour", reason="the quality gate needs colour-science")
#: a quick evaluation: the gate still renders source and result under the environment
QUICK = ["--size", "64", "--rotations", "0:360:2", "--env-lights", "64"]
SIDE = 16


def remap(capsys, src: Path, target: str, out: Path, *extra: str) -> tuple[int, str]:
    code = main(["remap", str(src), "--to", target, "-o", str(out), *QUICK, *extra])
    captured = capsys.readouterr()
    return code, captured.out + captured.err


def sheen_texture() -> np.ndarray:
    """16 x 16 RGBA codes: a warm sheen on the left half, a cool one on the right, each brightening along x; no sheen
    in the first column; alpha (the roughness) rising along y."""
    y, x = np.mgrid[0:SIDE, 0:SIDE] / (SIDE - 1)
    hue = np.where(x[..., None] < 0.5, np.array([0.9, 0.35, 0.1]), np.array([0.15, 0.4, 0.95]))
    colour = hue * (0.2 + 0.8 * x)[..., None]
    colour[:, 0] = 0.0
    rgba = np.concatenate([colour, (0.25 + 0.65 * y)[..., None]], axis=-1)
    return np.round(rgba * 255).astype(np.uint8)


def sheen_gltf(folder: Path) -> Path:
    """A grey dielectric (roughness 0.6) under a sheen whose colour and roughness are one RGBA texture, as Khronos
    SheenCloth stores them (colour in RGB, roughness in alpha)."""
    from test_formats_gltf import png_bytes

    folder.mkdir(parents=True, exist_ok=True)
    (folder / "sheen.png").write_bytes(png_bytes(folder, sheen_texture()))
    sheen = {
        "sheenColorFactor": [1.0, 1.0, 1.0],
        "sheenColorTexture": {"index": 0},
        "sheenRoughnessFactor": 1.0,
        "sheenRoughnessTexture": {"index": 0},
    }
    doc = {
        "asset": {"version": "2.0"},
        "extensionsUsed": ["KHR_materials_sheen"],
        "images": [{"uri": "sheen.png"}],
        "textures": [{"source": 0}],
        "materials": [
            {
                "name": "cloth",
                "pbrMetallicRoughness": {
                    "baseColorFactor": [0.3, 0.3, 0.3, 1],
                    "metallicFactor": 0,
                    "roughnessFactor": 0.6,
                },
                "extensions": {"KHR_materials_sheen": sheen},
            }
        ],
    }
    (folder / "cloth.gltf").write_text(json.dumps(doc))
    return folder / "cloth.gltf"


def written(out: Path, name: str) -> np.ndarray:
    ms = load_map_set(out / "maps")
    p = ms.spec.param(name)
    if name not in ms.maps:
        return np.broadcast_to(np.asarray(ms.constants[name], dtype=float), (*ms.size, p.channels)).squeeze()
    a, _ = read_image(ms.maps[name], ms.colorspace.get(name), colour=p.channels == 3)
    return a[..., :3] if p.channels == 3 else a[..., 0]


def hue(rgb: np.ndarray) -> np.ndarray:
    return np.array([colorsys.rgb_to_hsv(*c)[0] for c in rgb.reshape(-1, 3)]).reshape(rgb.shape[:-1])


def test_sheen_textures_are_read_as_maps(tmp_path):
    """Refused before ("a coloured sheen ... with sheenColorTexture: a layer on a textured material")."""
    asset = read_asset(sheen_gltf(tmp_path))
    assert asset.model == "gltf:pbr" and not asset.lost
    assert set(asset.textures) == {"sheenColor", "sheenRoughness"}
    assert asset.textures["sheenColor"].colorspace == "srgb" and asset.textures["sheenRoughness"].channels == (3,)


def test_a_sheen_colour_and_roughness_map_onto_openpbr(tmp_path, capsys):
    src = sheen_gltf(tmp_path / "in")
    out = tmp_path / "out"
    code, log = remap(capsys, src, "mtlx:open_pbr_surface", out)
    assert code == 0 and "PASSED" in log, log[-1500:]
    assert "sheenColor (by its brightest channel, its hue kept)" in log
    source = load_map_set(read_asset(src).to_map_set(tmp_path / "src"))
    colour, _ = read_image(source.maps["sheenColor"], source.colorspace["sheenColor"], colour=True)
    rough, _ = read_image(source.maps["sheenRoughness"], source.colorspace.get("sheenRoughness"), colour=False)
    fuzz_colour, fuzz_weight = written(out, "fuzz_color"), written(out, "fuzz_weight")
    lit = colour.max(axis=-1) > 0.1
    # the hue of each texel's sheen, and its brightness as the fuzz's weight (OpenPBR dims the base by the weight)
    np.testing.assert_allclose(chroma(fuzz_colour)[lit], chroma(colour)[lit], atol=0.03)
    assert np.abs(hue(fuzz_colour[lit]) - hue(colour[lit])).max() < 0.02
    assert np.corrcoef(fuzz_weight[lit], colour.max(axis=-1)[lit])[0, 1] > 0.98
    # no sheen where the source has none (to first order: the roughness axis moves the weight by up to 0.024 there)
    assert fuzz_weight[:, 0].max() < 0.05 and fuzz_weight[:, 0].max() < 0.1 * fuzz_weight.max()
    # the fuzz follows the sheen's roughness map (not linearly: OpenPBR's fuzz 0.51 to 0.74 for glTF's 0.25 to 0.9)
    fuzz_rough, r = written(out, "fuzz_roughness")[lit], rough[..., 0][lit]
    assert fuzz_rough[r > np.quantile(r, 0.75)].mean() > fuzz_rough[r < np.quantile(r, 0.25)].mean() + 0.1


def test_sheen_maps_are_written_to_gltf_as_one_texture_with_both(tmp_path):
    """A gltf:pbr map set with sheen maps written to glTF: KHR_materials_sheen's two textures, the colour in the RGB
    and the roughness in the alpha of one PNG, factors 1 (refused before: "not written to glTF yet"); read back by
    matremap and pygltflib, the maps are the ones written."""
    from matremap.formats import write_asset

    asset = read_asset(sheen_gltf(tmp_path / "in"))
    ms = load_map_set(asset.to_map_set(tmp_path / "ms"))
    (tmp_path / "out").mkdir()
    out = write_asset(tmp_path / "out" / "back.gltf", ms)
    import pygltflib

    g = pygltflib.GLTF2().load(str(out))
    sheen = g.materials[0].extensions["KHR_materials_sheen"]
    assert sheen["sheenColorFactor"] == [1.0, 1.0, 1.0] and sheen["sheenRoughnessFactor"] == 1.0
    assert sheen["sheenColorTexture"]["index"] == sheen["sheenRoughnessTexture"]["index"]
    back = load_map_set(read_asset(out).to_map_set(tmp_path / "read"))
    for name in ("sheenColor", "sheenRoughness"):
        colour = name == "sheenColor"
        got, _ = read_image(back.maps[name], back.colorspace.get(name), colour=colour)
        want, _ = read_image(ms.maps[name], ms.colorspace.get(name), colour=colour)
        np.testing.assert_allclose(got[..., : want.shape[-1]], want, atol=0.01)


def test_a_sheen_map_to_openpbr_and_back_to_gltf(tmp_path, capsys):
    """glTF's sheen maps onto OpenPBR (a fuzz weight, colour and roughness map) and that file back onto glTF: its fuzz
    weight map blends a sheened and a bare kind, each with OpenPBR's fuzz colour and roughness maps at levels inside,
    and glTF's ior, a number only, held at the bare base's fit (before: the kinds' iors made a map the glTF writer
    refused, exit 2; earlier still, a degenerate reflectance mapping stopped the learning)."""
    first = tmp_path / "opbr"
    code, log = remap(capsys, sheen_gltf(tmp_path / "in"), "mtlx:open_pbr_surface", first)
    assert code == 0, log[-800:]
    out = tmp_path / "back"
    code, log = remap(capsys, next(first.glob("*.mtlx")), "gltf:pbr", out, "--write", "back.gltf")
    assert code == 0 and "PASSED" in log, log[-1500:]
    import pygltflib

    material = pygltflib.GLTF2().load(str(out / "back.gltf")).materials[0]
    assert "sheenColorTexture" in material.extensions["KHR_materials_sheen"]
    back = load_map_set(read_asset(out / "back.gltf").to_map_set(tmp_path / "read"))
    colour, _ = read_image(back.maps["sheenColor"], back.colorspace["sheenColor"], colour=True)
    original = load_map_set(read_asset(tmp_path / "in" / "cloth.gltf").to_map_set(tmp_path / "orig"))
    want, _ = read_image(original.maps["sheenColor"], original.colorspace["sheenColor"], colour=True)
    lit = want.max(axis=-1) > 0.2
    assert np.median(np.abs(hue(colour[lit]) - hue(want[lit]))) < 0.03  # the round trip keeps the sheen's hue


def test_khronos_sheencloth_onto_openpbr(tmp_path, capsys):
    """The real file: a fabric whose sheen colour and roughness are one tiled RGBA texture over base colour and
    roughness maps (fetched on demand)."""
    from large_assets import large_asset

    src = large_asset("gltf-SheenCloth") / "SheenCloth.gltf"
    out = tmp_path / "out"
    code, log = remap(capsys, src, "mtlx:open_pbr_surface", out)
    assert code == 0 and "PASSED" in log, log[-1500:]
    asset = read_asset(src)
    source = load_map_set(asset.to_map_set(tmp_path / "src"))
    colour, _ = read_image(source.maps["sheenColor"], source.colorspace["sheenColor"], colour=True)
    fuzz = written(out, "fuzz_color") * written(out, "fuzz_weight")[..., None]
    lit = colour.max(axis=-1) > 0.2
    assert lit.mean() > 0.1
    # the fuzz (weight x colour) keeps the sheen's hue, and its brightness follows the sheen's
    assert np.median(np.abs(hue(fuzz[lit][::97]) - hue(colour[lit][::97]))) < 0.03
    assert np.corrcoef(fuzz.max(axis=-1)[lit], colour.max(axis=-1)[lit])[0, 1] > 0.9
