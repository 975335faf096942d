"""The main job end to end on an example map set: sweep, learn (cached), convert, evaluate."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from matremap.cli import main
from matremap.remap import remap
from matremap.svbrdf.textures import load_map_set, read_image

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
FAST = dict(rotations="0:360:2", resolution=48, lights=16, workers=1)


@pytest.fixture()
def plastic(tmp_path):
    dst = tmp_path / "blue-plastic"
    shutil.copytree(EXAMPLES / "blue-plastic", dst)
    return dst


def test_remap_sweeps_learns_converts_and_evaluates_then_reuses_the_transform(plastic, tmp_path, monkeypatch):
    pytest.importorskip("skimage")
    cache = tmp_path / "cache"
    first = remap(
        plastic,
        "mitsuba06:ward",
        "mitsuba06:pbr",
        tmp_path / "out1",
        fix={"distribution": "as"},
        cache=cache,
        log=lambda m: None,
        library=False,  # the shipped wardclassic-as would serve these maps: sweep them here
        **FAST,
    )
    assert not first.cached and first.transform.is_file() and first.outside == 0
    assert first.report.is_file() and 0.0 <= first.mean_dssim < 0.5
    results = (first.report.parent / "results.json").read_text()
    assert ".partial-" not in results and json.loads(results)["report"] == "report.html"  # no staging paths
    result = load_map_set(first.maps)
    assert result.model == "mitsuba06:pbr" and set(result.maps) == {"alpha", "F0", "diffuseReflectance"}
    assert result.normal.read_bytes() == load_map_set(plastic).normal.read_bytes()
    # the converted F0 map is the transform applied to the source maps
    from matremap.regress.transform import Transform

    t = Transform.load(first.transform)
    src = load_map_set(plastic)
    alpha, _ = read_image(src.maps["alpha"], src.colorspace.get("alpha"))
    rho, _ = read_image(src.maps["specularReflectance"], src.colorspace.get("specularReflectance"))
    expected, _ = t.apply({"alpha": alpha[..., 0], "specularReflectance": rho[..., :3]})
    f0, _ = read_image(result.maps["F0"], result.colorspace.get("F0"))
    np.testing.assert_allclose(f0[..., :3], expected["F0"], atol=2.5 / 255)

    second = remap(
        plastic,
        None,
        "mitsuba06:pbr",
        tmp_path / "out2",
        fix={"distribution": "as"},
        cache=cache,
        log=lambda m: None,
        library=False,
        **FAST,
    )
    assert second.cached and second.transform == first.transform
    assert second.seconds["transform"] < first.seconds["transform"]
    maps1, maps2 = tmp_path / "out1" / "maps", tmp_path / "out2" / "maps"
    assert sorted(p.name for p in maps2.iterdir()) == sorted(p.name for p in maps1.iterdir())
    for p in maps1.glob("*.png"):
        assert (maps2 / p.name).read_bytes() == p.read_bytes()

    # a transform cached by a matremap whose fitting or learning gave other results is not reused
    import matremap.core.diskcache as diskcache

    monkeypatch.setattr(diskcache, "RESULTS_REVISION", diskcache.RESULTS_REVISION + 1)
    third = remap(
        plastic,
        None,
        "mitsuba06:pbr",
        tmp_path / "out3",
        fix={"distribution": "as"},
        cache=cache,
        log=lambda m: None,
        library=False,
        **FAST,
    )
    assert not third.cached and third.transform != first.transform


def test_cli_remap_convert_evaluate(plastic, tmp_path, capsys):
    pytest.importorskip("skimage")
    cache = tmp_path / "cache"
    out = tmp_path / "remapped"
    code = main(
        [
            "remap",
            str(plastic),
            "--to",
            "mitsuba06:pbr",
            "--fix",
            "distribution=as",
            "-o",
            str(out),
            "--cache",
            str(cache),
            "--rotations",
            "0:360:2",
            "--size",
            "48",
            "--env-lights",
            "16",
            "--workers",
            "1",
            "--sweep",
        ]
    )
    assert code == 0
    transform = next(cache.glob("*.json"))
    converted = tmp_path / "converted"
    assert main(["convert", str(plastic), "--transform", str(transform), "-o", str(converted), "--workers", "1"]) == 0
    assert json.loads((converted / "material.json").read_text())["model"] == "mitsuba06:pbr"
    ev = tmp_path / "eval"
    assert (
        main(
            [
                "evaluate",
                str(plastic),
                str(converted),
                "-o",
                str(ev),
                "--rotations",
                "0:360:2",
                "--size",
                "48",
                "--env-lights",
                "16",
            ]
        )
        == 0
    )
    assert (ev / "report.html").is_file() and "mean 1-SSIM" in capsys.readouterr().out


@pytest.mark.parametrize("where", ["inside", "nonempty"])
def test_remap_refuses_unsafe_outputs(plastic, tmp_path, capsys, where):
    out = plastic / "out" if where == "inside" else tmp_path / "full"
    if where == "nonempty":
        out.mkdir()
        (out / "keep.txt").write_text("mine")
    code = main(
        [
            "remap",
            str(plastic),
            "--to",
            "mitsuba06:pbr",
            "-o",
            str(out),
            "--no-evaluate",
            "--cache",
            str(tmp_path / "c"),
        ]
    )
    err = capsys.readouterr().err
    assert code == 2 and ("lies inside" in err or "matremap did not write" in err), err
    if where == "nonempty":
        assert [p.name for p in out.iterdir()] == ["keep.txt"]
    else:
        assert not out.exists()


def test_a_sweep_axis_spans_at_least_min_axis_where_a_map_hardly_varies():
    """Khronos TransmissionTest's metal stripes have a roughness map of 0 to 5e-5: swept over that range, ten fits
    differed by noise alone and the learned polynomial's coefficient reached -2.9e7 (the transform was refused). An
    axis now spans at least MIN_AXIS, inside the parameter's bounds."""
    from matremap.remap import MIN_AXIS, _range

    lo, hi = _range([0.0, 5e-5], (0.0, 1.0), floor=0.0)
    assert lo == 0.0 and hi >= MIN_AXIS / 2
    lo, hi = _range([0.5, 0.5001], (0.0, 1.0))
    assert hi - lo == pytest.approx(MIN_AXIS, abs=1e-6) and lo < 0.5 < hi
    assert _range([0.2, 0.8], (0.0, 1.0)) == (0.188, 0.812)  # a real range: padded by 2 % as before
