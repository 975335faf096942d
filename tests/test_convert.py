import json
import warnings

import numpy as np
import pytest

from matremap.core.material import Material
from matremap.core.scene import Scene
from matremap.errors import MatremapError
from matremap.regress.transform import Transform, learn_transform
from matremap.svbrdf.convert import MASK_NAME, convert
from matremap.svbrdf.textures import ImageInfo, load_map_set, read_image, write_image_like
from matremap.sweep.executors import InlineExecutor
from matremap.sweep.grid import parse_grid
from matremap.sweep.run import SweepConfig, run_sweep

H, W = 23, 17


@pytest.fixture(scope="module")
def ward_db(tmp_path_factory):
    source = Material.create("mitsuba06:ward", {"variant": "ward", "diffuseReflectance": 0.0})
    config = SweepConfig(source=source, target="mitsuba06:pbr", fix={"distribution": "as"}, scene=Scene(resolution=48))
    path = tmp_path_factory.mktemp("db") / "w2as.sqlite"
    run_sweep(
        config,
        parse_grid("alpha=0.03:0.99:5,specularReflectance=0.02:0.232:4", source.spec),
        str(path),
        InlineExecutor(),
    )
    return path


@pytest.fixture(scope="module")
def ward_to_as(ward_db):
    return learn_transform(ward_db)


def fields(seed=0):
    rng = np.random.default_rng(seed)
    alpha = rng.uniform(0.05, 0.9, (H, W)).astype(np.float32)
    rho = rng.uniform(0.03, 0.2, (H, W, 3)).astype(np.float32)
    rho[3, 4] = [0.3, 0.1, 0.1]  # beyond the training domain (rho_s <= 0.232)
    alpha[7, 9] = 0.015  # smoother than the smoothest trained alpha (0.03)
    normal = rng.uniform(0, 1, (H, W, 3)).astype(np.float32)
    return alpha, rho, normal


PNG8_GREY = ImageInfo("png", "uint8", 1, 0, 0, "linear")
PNG16_SRGB = ImageInfo("png", "uint16", 3, 0, 0, "srgb")


def make_set(folder, alpha, rho, normal, rough_info=PNG8_GREY, spec_info=PNG16_SRGB):
    folder.mkdir(parents=True, exist_ok=True)
    write_image_like(folder / f"w_roughness.{rough_info.format}", alpha, rough_info)
    write_image_like(folder / f"w_specular.{spec_info.format}", rho, spec_info)
    write_image_like(folder / "w_normal.png", normal, ImageInfo("png", "uint8", 3, 0, 0, "linear"))
    (folder / "material.json").write_text(
        json.dumps(
            {
                "model": "mitsuba06:ward",
                "normal": "w_normal.png",
                "maps": {
                    "alpha": f"w_roughness.{rough_info.format}",
                    "specularReflectance": f"w_specular.{spec_info.format}",
                },
                "params": {"variant": "ward", "diffuseReflectance": 0},
            }
        )
    )
    return load_map_set(folder)


def quiet_convert(*args, **kwargs):
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        report = convert(*args, **kwargs)
    return report, [str(x.message) for x in w]


def test_convert_matches_transform_apply(tmp_path, ward_to_as):
    ms = make_set(tmp_path / "in", *fields())
    report, warned = quiet_convert(ms, [ward_to_as], tmp_path / "out", tile_rows=5, workers=1)
    # what the converter read, through the transform, directly
    alpha, _ = read_image(ms.maps["alpha"], "linear")
    rho, _ = read_image(ms.maps["specularReflectance"], "srgb")
    expected, outside = ward_to_as.apply(
        {"alpha": alpha[..., 0], "specularReflectance": rho, "diffuseReflectance": 0.0}
    )
    doc = json.loads((tmp_path / "out" / "material.json").read_text())
    assert doc["model"] == "mitsuba06:pbr" and doc["maps"] == {"alpha": "w_roughness.png", "F0": "w_specular.png"}
    assert doc["params"]["distribution"] == "as" and doc["params"]["specularReflectance"] == [1.0, 1.0, 1.0]
    out_alpha, ai = read_image(tmp_path / "out" / "w_roughness.png", "linear")
    out_f0, fi = read_image(tmp_path / "out" / "w_specular.png", "srgb")
    assert (ai.pixel_type, ai.channels, fi.pixel_type, fi.channels) == ("uint8", 1, "uint16", 3)
    assert np.abs(out_alpha[..., 0] - expected["alpha"]).max() <= 0.5 / 255 + 1e-6  # 8-bit linear
    assert np.abs(out_f0 - expected["F0"]).max() <= 2e-5  # 16-bit sRGB
    mask, _ = read_image(tmp_path / "out" / MASK_NAME, colour=False)
    np.testing.assert_array_equal(mask[..., 0] == 1, outside)
    assert report.outside == int(outside.sum()) == 2 and outside[3, 4] and outside[7, 9]
    assert any("2 of 391 texels" in m for m in warned)
    assert (tmp_path / "out" / "w_normal.png").read_bytes() == (tmp_path / "in" / "w_normal.png").read_bytes()
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == sorted(
        ["material.json", MASK_NAME, "w_normal.png", "w_roughness.png", "w_specular.png"]
    )
    # the output is itself a map set
    again = load_map_set(tmp_path / "out")
    assert again.model == "mitsuba06:pbr" and again.colorspace == {"alpha": "linear", "F0": "srgb"}


def test_float_maps_stay_float_and_two_workers_agree(tmp_path, ward_to_as, monkeypatch):
    import matremap.svbrdf.convert

    monkeypatch.setattr(matremap.svbrdf.convert, "PARALLEL_MIN_TEXELS", 0)  # a pool even for small maps
    alpha, rho, normal = fields(1)
    ms = make_set(
        tmp_path / "in",
        alpha,
        rho,
        normal,
        ImageInfo("exr", "float", 1, 0, 0, "linear"),
        ImageInfo("exr", "float", 3, 0, 0, "linear"),
    )
    quiet_convert(ms, ward_to_as, tmp_path / "one", tile_rows=4, workers=1)
    quiet_convert(ms, ward_to_as, tmp_path / "two", tile_rows=6, workers=2)
    expected, _ = ward_to_as.apply({"alpha": alpha, "specularReflectance": rho, "diffuseReflectance": 0.0})
    for d in ("one", "two"):
        a, info = read_image(tmp_path / d / "w_roughness.exr")
        assert info.pixel_type == "float"
        np.testing.assert_allclose(a[..., 0], expected["alpha"], rtol=1e-6)
        np.testing.assert_allclose(read_image(tmp_path / d / "w_specular.exr")[0], expected["F0"], rtol=1e-6)
    assert (tmp_path / "one" / MASK_NAME).read_bytes() == (tmp_path / "two" / MASK_NAME).read_bytes()


def test_a_chain_is_applied_per_texel(tmp_path, ward_db, ward_to_as):
    back = learn_transform(ward_db, reverse=True)
    alpha, rho, normal = fields(2)
    ms = make_set(
        tmp_path / "in",
        alpha,
        rho,
        normal,
        ImageInfo("exr", "float", 1, 0, 0, "linear"),
        ImageInfo("exr", "float", 3, 0, 0, "linear"),
    )
    report, _ = quiet_convert(ms, [ward_to_as, back], tmp_path / "out", workers=1)
    assert report.model == "mitsuba06:ward"
    doc = json.loads((tmp_path / "out" / "material.json").read_text())
    assert doc["params"]["variant"] == "ward"
    expected, _ = Transform.chain([ward_to_as, back]).apply(
        {"alpha": alpha, "specularReflectance": rho, "diffuseReflectance": 0.0}
    )
    np.testing.assert_allclose(
        read_image(tmp_path / "out" / "w_roughness.exr")[0][..., 0], expected["alpha"], rtol=1e-6
    )
    np.testing.assert_allclose(alpha, expected["alpha"], atol=0.02)  # and it is nearly a round trip


def test_nan_in_the_last_band_leaves_nothing_behind(tmp_path, ward_to_as, monkeypatch):
    import matremap.svbrdf.convert

    monkeypatch.setattr(matremap.svbrdf.convert, "PARALLEL_MIN_TEXELS", 0)  # a pool even for small maps
    alpha, rho, normal = fields()
    alpha[H - 1, 3] = np.nan
    ms = make_set(tmp_path / "in", alpha, rho, normal, ImageInfo("exr", "float", 1, 0, 0, "linear"))
    with pytest.raises(MatremapError, match=f"w_roughness.exr holds NaN or infinite texels \\(first in row {H - 1}\\)"):
        convert(ms, ward_to_as, tmp_path / "out", tile_rows=4, workers=1)
    assert not (tmp_path / "out").exists()  # created by the call, so removed again
    (tmp_path / "kept").mkdir()
    with pytest.raises(MatremapError, match="NaN"):
        convert(ms, ward_to_as, tmp_path / "kept", tile_rows=4, workers=2)
    assert list((tmp_path / "kept").iterdir()) == []


def test_truncated_input_fails_cleanly(tmp_path, ward_to_as):
    alpha, rho, normal = fields()
    ms = make_set(tmp_path / "in", alpha, rho, normal)
    data = ms.maps["specularReflectance"].read_bytes()
    ms.maps["specularReflectance"].write_bytes(data[: len(data) // 2])
    (tmp_path / "out").mkdir()
    with pytest.raises(MatremapError, match="w_specular.png: the file is corrupt or truncated"):
        convert(ms, ward_to_as, tmp_path / "out", tile_rows=4, workers=1)
    assert list((tmp_path / "out").iterdir()) == []


def test_outputs_are_not_overwritten_without_force_and_inputs_never(tmp_path, ward_to_as):
    ms = make_set(tmp_path / "in", *fields())
    quiet_convert(ms, ward_to_as, tmp_path / "out", workers=1)
    before = (tmp_path / "out" / "w_specular.png").read_bytes()
    with pytest.raises(MatremapError, match="already exists.*--force"):
        convert(ms, ward_to_as, tmp_path / "out", workers=1)
    assert (tmp_path / "out" / "w_specular.png").read_bytes() == before
    quiet_convert(ms, ward_to_as, tmp_path / "out", workers=1, force=True)
    with pytest.raises(MatremapError, match="is the input folder"):
        convert(ms, ward_to_as, tmp_path / "in", workers=1, force=True)
    with pytest.raises(MatremapError, match="contains the input"):
        convert(ms, ward_to_as, tmp_path, workers=1, force=True)


def test_mismatched_transforms_and_missing_maps(tmp_path, ward_db, ward_to_as):
    alpha, rho, normal = fields()
    ms = make_set(tmp_path / "in", alpha, rho, normal)
    back = learn_transform(ward_db, reverse=True)
    with pytest.raises(MatremapError, match="maps are for mitsuba06:ward.*learned from mitsuba06:ward"):
        convert(ms, back, tmp_path / "out")
    (tmp_path / "in" / "material.json").write_text(
        json.dumps({"model": "mitsuba06:ward", "maps": {"alpha": "w_roughness.png"}, "params": {"variant": "ward"}})
    )
    with pytest.raises(MatremapError, match="no map or value for specularReflectance"):
        convert(load_map_set(tmp_path / "in"), ward_to_as, tmp_path / "out")
    (tmp_path / "in" / "material.json").write_text(
        json.dumps(
            {
                "model": "mitsuba06:ward",
                "maps": {"alpha": "w_roughness.png", "specularReflectance": "w_specular.png"},
                "params": {"variant": "balanced"},
            }
        )
    )
    with pytest.raises(MatremapError, match="variant=balanced but the transform was trained on variant=ward"):
        convert(load_map_set(tmp_path / "in"), ward_to_as, tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_a_diffuse_map_the_transform_never_saw_is_flagged(tmp_path, ward_to_as):
    alpha, rho, normal = fields()
    make_set(tmp_path / "in", alpha, rho, normal)
    d = np.zeros((H, W, 3), np.float32)
    d[:2] = 0.5
    write_image_like(tmp_path / "in" / "w_diffuse.png", d, ImageInfo("png", "uint8", 3, 0, 0, "srgb"))
    doc = json.loads((tmp_path / "in" / "material.json").read_text())
    doc["maps"]["diffuseReflectance"] = "w_diffuse.png"
    del doc["params"]["diffuseReflectance"]
    (tmp_path / "in" / "material.json").write_text(json.dumps(doc))
    report, _ = quiet_convert(load_map_set(tmp_path / "in"), ward_to_as, tmp_path / "out", workers=1)
    assert report.outside == 2 * W + 2  # two rows of non-zero diffuse plus the two texels of fields()
    assert any("diffuse held at 0" in n for n in report.notes)


def test_maps_of_one_value_each_stay_maps_when_all_are_uniform(tmp_path, ward_to_as):
    """A target parameter the same at every texel becomes a constant, but a map set needs a map: when every
    map is uniform (a glTF base colour texture of one colour) they all stay maps. All were dropped, and the
    remap failed after converting ('material.json binds no map')."""
    alpha, rho, normal = fields()
    flat = make_set(tmp_path / "flat", np.full_like(alpha, 0.3), np.full_like(rho, 0.1), normal)
    report, _ = quiet_convert(flat, ward_to_as, tmp_path / "flat-out", workers=1)
    out = load_map_set(tmp_path / "flat-out")
    assert set(out.maps) == {"alpha", "F0"} and not any("same at every" in n for n in report.notes)
    values = read_image(out.maps["alpha"])[0]
    assert np.ptp(values) == 0  # one value, written as a map
    mixed = make_set(tmp_path / "mixed", np.full_like(alpha, 0.3), rho, normal)  # one uniform: a constant
    report, _ = quiet_convert(mixed, ward_to_as, tmp_path / "mixed-out", workers=1)
    out = load_map_set(tmp_path / "mixed-out")
    assert set(out.maps) == {"F0"} and "alpha" in out.constants
    assert any(n.startswith("alpha is the same at every texel") for n in report.notes)
