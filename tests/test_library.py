"""The shipped transform library: its files, routes through it, and that a sample still reproduces."""

from __future__ import annotations

import json

import numpy as np
import pytest

from matremap.cli import main
from matremap.dialects import get_model
from matremap.regress import library
from matremap.regress.library import PAIRS, build_pair, entries, find_route, max_prediction_difference, node_key, route
from matremap.regress.transform import Transform


def test_every_pair_is_shipped_in_both_directions_with_provenance():
    names = {e.name for e in entries()}
    for pair in PAIRS:
        assert pair.name in names, f"{pair.name} missing: run tools/make_transform_library.py {pair.name}"
        if pair.reverse:
            assert library.reverse_name(pair.name) in names
    for e in entries():
        t = e.transform
        get_model(t.source), get_model(t.target)  # ids that exist
        assert t.provenance["library"]["pair"] in {p.name for p in PAIRS}
        assert t.domain and all(lo <= hi for lo, hi in t.domain.values())
        assert e.error < 0.02, f"{e.name}: held-out RMSE {e.error}"


def test_a_direct_route_is_preferred_and_options_must_match():
    direct = find_route("mitsuba06:ward", {}, "mitsuba06:pbr", {"distribution": "as"})
    assert [e.name for e in direct.steps] == ["ward-as"]
    ggx = find_route("mitsuba06:ward", {}, "mitsuba06:pbr", {"distribution": "ggx"})
    assert [e.name for e in ggx.steps] == ["ward-ggx"]
    # the library's Ward is the balanced variant: another variant has no route
    assert find_route("mitsuba06:ward", {"variant": "ward-duer"}, "mitsuba06:pbr", {"distribution": "as"}) is None


def test_a_chain_is_found_when_no_direct_transform_exists():
    found = find_route("blender27:ward", {}, "gltf:metal-rough", {"metallic": 1.0})
    assert [e.name for e in found.steps] == ["blender27ward-ward", "ward-gltf-metal"]
    assert found.error == pytest.approx(np.hypot(*(e.error for e in found.steps)))
    t = found.transform
    assert t.method == "chain" and t.source == "blender27:ward" and t.target == "gltf:metal-rough"
    out, outside = t.apply(
        {
            "specular_slope": np.array([0.1, 0.2]),
            "specular_color": np.array([0.1, 0.3]),
            "specular_intensity": np.array([1.0, 1.0]),
            "diffuse_color": np.zeros((2, 3)),
        }
    )
    assert not outside.any() and np.all(out["metallic"] == 1.0)
    assert "blender27:ward -> mitsuba06:ward -> gltf:metal-rough" in found.describe()


def test_held_values_pick_the_metal_or_the_dielectric_entry():
    metal = find_route("mitsuba06:ward", {}, "gltf:metal-rough", {"metallic": 1.0})
    dielectric = find_route("mitsuba06:ward", {}, "gltf:metal-rough", {"metallic": 0.0})
    assert metal.steps[0].name == "ward-gltf-metal" and dielectric.steps[0].name == "ward-gltf-dielectric"
    # and back: a glTF dielectric reaches Ward by the dielectric entry's reverse, not the metal one's
    back = route(node_key("gltf:metal-rough", {}, {"metallic": 0.0}), node_key("mitsuba06:ward", {}))
    assert [e.name for e in back.steps] == ["gltf-dielectric-ward"]
    # a model the library does not know has no route at all
    assert route(node_key("mitsuba06:phong", {}), node_key("mitsuba06:ward", {})) is None


def test_no_route_is_none_and_the_cli_says_so(capsys):
    assert find_route("mitsuba06:phong", {}, "cycles:glossy", {}) is None
    assert main(["transforms", "--route", "mitsuba06:phong", "cycles:glossy"]) == 2
    assert "no route" in capsys.readouterr().err


def test_cli_lists_the_library(capsys):
    assert main(["transforms"]) == 0
    text = capsys.readouterr().out
    assert "ward-as" in text and "trained on roughness" in text
    assert main(["transforms", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert {r["name"] for r in rows} == {e.name for e in entries()}
    assert main(["transforms", "--route", "blender27:ward", "cycles:glossy", "--fix", "distribution=ggx"]) == 0
    assert "blender27ward-ward, ward-cycles" in capsys.readouterr().out


@pytest.mark.slow
def test_a_shipped_transform_still_reproduces(tmp_path):
    """Regenerate one library pair and compare its predictions with the shipped file's: a change
    in a dialect, the fitter or the learner that moves the library fails here."""
    pair = next(p for p in PAIRS if p.name == "ward-as")
    written = build_pair(pair, tmp_path, workers=1, log=lambda m: None)
    fresh = Transform.load(written[0])
    shipped = next(e.transform for e in entries() if e.name == "ward-as")
    diff = max_prediction_difference(shipped, fresh)
    assert diff["roughness"] < 2e-3 and diff["reflectance"] < 2e-3, diff


def _ward_maps(folder, variant: str):
    from matremap.svbrdf.textures import ImageInfo, write_image_like

    folder.mkdir()
    y, x = np.mgrid[0:8, 0:8] / 7.0
    write_image_like(
        folder / "w_roughness.exr",
        (0.1 + 0.4 * x)[..., None].astype(np.float32),
        ImageInfo("exr", "float", 1, 0, 0, "linear"),
    )
    write_image_like(
        folder / "w_specular.exr",
        np.stack([0.05 + 0.2 * y] * 3, -1).astype(np.float32),
        ImageInfo("exr", "float", 3, 0, 0, "linear"),
    )
    (folder / "material.json").write_text(
        json.dumps(
            {
                "model": "mitsuba06:ward",
                "params": {"variant": variant, "diffuseReflectance": 0.0},
                "maps": {"alpha": "w_roughness.exr", "specularReflectance": "w_specular.exr"},
            }
        )
    )
    return x, y


def test_convert_to_a_model_takes_the_library_route(tmp_path, capsys):
    from matremap.svbrdf.textures import read_image

    x, y = _ward_maps(tmp_path / "in", "balanced")
    out = tmp_path / "out"
    assert (
        main(["convert", str(tmp_path / "in"), "--to", "mitsuba06:pbr", "--fix", "distribution=as", "-o", str(out)])
        == 0
    )
    assert "route mitsuba06:ward -> mitsuba06:pbr" in capsys.readouterr().err
    shipped = next(e.transform for e in entries() if e.name == "ward-as")
    expected, _ = shipped.apply(
        {"alpha": 0.1 + 0.4 * x, "specularReflectance": np.stack([0.05 + 0.2 * y] * 3, -1), "diffuseReflectance": 0.0}
    )
    alpha, _ = read_image(out / "w_roughness.exr")
    np.testing.assert_allclose(alpha[..., 0], expected["alpha"], rtol=1e-5)


def test_convert_to_a_model_without_a_route_fails_cleanly(tmp_path, capsys):
    _ward_maps(tmp_path / "in", "ward-duer")  # the library's Ward transforms are the ward and balanced variants
    out = tmp_path / "out"
    assert (
        main(["convert", str(tmp_path / "in"), "--to", "mitsuba06:pbr", "--fix", "distribution=as", "-o", str(out)])
        == 2
    )
    assert "no route" in capsys.readouterr().err and not out.exists()


def test_no_route_names_the_nearest_transforms_with_every_option(capsys):
    """The README's Ward example swept every time without saying why: its Ward is variant=ward, the
    library's Ward transforms variant=balanced. The message now shows both sides' options."""
    from matremap.cli import main
    from matremap.regress.library import nearest_routes

    near = nearest_routes("mitsuba06:ward", {"variant": "ward-duer"}, "mitsuba06:pbr", {"distribution": "ggx"})
    assert near and near[0].split(":")[0] in ("ward-ggx", "ward-as", "wardclassic-ggx", "wardclassic-as")
    assert all("variant=" in n for n in near[:2]) and "mitsuba06:pbr (distribution=" in near[0]
    code = main(
        ["transforms", "--route", "mitsuba06:ward", "mitsuba06:pbr", "--fix", "distribution=ggx"]
        + ["--source-option", "variant=ward-duer"]
    )
    err = capsys.readouterr().err
    assert code == 2 and "nearest: ward" in err and "variant=balanced" in err
    assert main(["transforms"]) == 0
    listing = capsys.readouterr().out
    assert "mitsuba06:ward (variant=balanced) -> mitsuba06:pbr (distribution=as)" in listing  # defaults shown


def test_a_textured_gltf_dielectric_goes_onto_openpbr_through_the_library(tmp_path, capsys):
    """Khronos BoxTextured (a textured dielectric) onto OpenPBR takes the shipped gltf-dielectric-openpbr route
    (before it, a sweep), and the written base colour map is the source's texture: OpenPBR's base layer draws a
    glTF dielectric's diffuse the same (checked on the files, decoded by OpenImageIO, not by matremap's score)."""
    pytest.importorskip("colour", reason="the quality gate needs colour-science")
    from pathlib import Path

    oiio = pytest.importorskip("OpenImageIO")

    def read_image(path):  # the stored (sRGB-encoded) values, as OpenImageIO decodes the PNG
        f = oiio.ImageInput.open(str(path))
        try:
            return f.read_image(format="float")
        finally:
            f.close()

    corpus = Path(__file__).parent / "data" / "corpus" / "gltf-BoxTextured"
    out = tmp_path / "out"
    code = main(["remap", str(corpus / "BoxTextured.gltf"), "--to", "mtlx:open_pbr_surface", "-o", str(out)])
    err = capsys.readouterr().err
    assert code == 0, err[-600:]
    assert "gltf-dielectric-openpbr" in err and "sweeping" not in err
    written = read_image(out / "BoxTextured_base_color.png")[..., :3]
    source = read_image(corpus / "CesiumLogoFlat.png")[..., :3]
    assert written.shape[:2] == source.shape[:2]
    assert np.mean(np.abs(written - source)) < 0.02


def test_a_textured_gltf_metal_goes_onto_openpbr_through_the_library(tmp_path, capsys):
    """The examples' textured glTF brass (metallic 1) onto OpenPBR takes the shipped gltf-metal-openpbr route (a
    metal's F0 read from OpenPBR's base colour: before, its sweep gave no F0 axis), and the written base colour map
    follows the source's, channel by channel (decoded by OpenImageIO, not by matremap's score)."""
    pytest.importorskip("colour", reason="the quality gate needs colour-science")
    from pathlib import Path

    oiio = pytest.importorskip("OpenImageIO")

    def read_image(path):
        f = oiio.ImageInput.open(str(path))
        try:
            return np.asarray(f.read_image(format="float"))[..., :3]
        finally:
            f.close()

    example = Path(__file__).parents[1] / "examples" / "brass-gltf"
    out = tmp_path / "out"
    code = main(["remap", str(example / "brass.gltf"), "--to", "mtlx:open_pbr_surface", "-o", str(out)])
    err = capsys.readouterr().err
    assert code == 0, err[-600:]
    assert "gltf-metal-openpbr" in err and "sweeping" not in err
    written = next(out.glob("*base_color*"))
    w, s = read_image(written), read_image(example / "brass_basecolor.png")
    assert w.shape == s.shape
    for c in range(3):  # the texture's pattern (F0 times k(roughness) per texel: 0.966 measured)
        assert np.corrcoef(w[..., c].ravel(), s[..., c].ravel())[0, 1] > 0.95
    ratio = linear(w).reshape(-1, 3).mean(axis=0) / linear(s).reshape(-1, 3).mean(axis=0)
    assert 0.8 < ratio.mean() < 1.1 and np.ptp(ratio) < 0.03  # the brass's hue (0.92 on every channel measured)


def linear(srgb: np.ndarray) -> np.ndarray:
    """sRGB-encoded values to linear (IEC 61966-2-1)."""
    return np.where(srgb <= 0.04045, srgb / 12.92, ((srgb + 0.055) / 1.055) ** 2.4)


def test_a_kind_of_a_blended_map_set_needs_a_route_only_where_it_is_used(tmp_path):
    """One kind of a map set blended per texel (a glTF metallic map's metal texels) is converted over every texel,
    but only those where it has weight reach the result: the library's coverage is judged there. Judged over all
    texels, the shipped glTF metal -> Cycles Principled route was refused for BoomBox (45 % covered)."""
    from matremap.remap import library_transform
    from matremap.svbrdf.textures import MapSet

    rough = np.full((8, 8), 0.5)
    rough[:, :4] = 0.0  # below the library's grid (roughness from 0.05): where the dielectric texels are
    params = {"roughness": rough, "baseColor": np.full((8, 8, 3), 0.6), "metallic": 1.0}
    fix = {"Metallic": 1.0, "distribution": "multi_ggx"}
    ms = MapSet("gltf:metal-rough", {}, tmp_path)
    logs: list[str] = []
    assert library_transform(ms, params, "cycles:principled", fix, logs.append) is None
    used = np.zeros((8, 8), dtype=bool)
    used[:, 4:] = True
    found = library_transform(ms, params, "cycles:principled", fix, logs.append, within=used)
    assert found is not None and "gltf-metal-cyclesprincipled" in logs[-1]


def test_prediction_differences_read_a_source_template_older_than_its_model():
    """A shipped transform learned before its source model gained parameters (Cycles' Principled coat and sheen):
    comparing it with another transform takes the model's defaults for them (it raised KeyError 'Coat Weight')."""
    entry = next(e for e in entries() if e.name == "cyclesprincipled-ward")
    assert "Coat Weight" not in entry.transform.source_template
    d = max_prediction_difference(entry.transform, entry.transform)
    assert set(d) >= {"roughness", "reflectance"} and max(d.values()) == 0.0
