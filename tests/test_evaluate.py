"""SSIM evaluation over environment rotations and its self-contained HTML report."""

from __future__ import annotations

import json
import math
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("skimage", reason="scikit-image is needed by matremap evaluate: pip install scikit-image")

from matremap.core import envmap
from matremap.core.material import SVMaterial
from matremap.errors import MatremapError
from matremap.renderers.base import EnvironmentLight
from matremap.svbrdf.evaluate import evaluate, irradiance_scale_under, parse_rotations, ssim_map

CHROMIUM = Path("/usr/bin/chromium")
KW = dict(resolution=32, lights=48)


@pytest.fixture(scope="module")
def studio():
    return envmap.builtin(32, 64)


def _ward(alpha: float):
    rng = np.random.default_rng(7)
    diffuse = 0.1 + 0.4 * rng.random((8, 16, 3))
    return ("mitsuba06:ward", {"alpha": alpha, "specularReflectance": 0.15, "diffuseReflectance": diffuse}, {}, None)


@pytest.fixture(scope="module")
def report(tmp_path_factory, studio):
    out = tmp_path_factory.mktemp("eval") / "report-dir"
    normal = np.broadcast_to([0.1, 0.0, 0.995], (4, 8, 3))
    target = (
        "cycles:glossy",
        {"Roughness": 0.4, "Color": 0.15, "Diffuse Color": _ward(0.1)[1]["diffuseReflectance"]},
        {"distribution": "beckmann"},
        normal,
    )
    result = evaluate(_ward(0.15), target, studio, parse_rotations("0:360:3"), out, **KW)
    return result


def test_parse_rotations():
    assert parse_rotations("0:360:12") == [30.0 * k for k in range(12)]
    assert parse_rotations("90:180:2") == [90.0, 135.0]
    assert parse_rotations("0, 45,90") == [0.0, 45.0, 90.0]
    assert parse_rotations("30") == [30.0]
    for bad, msg in [
        ("0:360", "START:STOP:COUNT"),
        ("a:360:4", "START and STOP"),
        ("0:360:x", "COUNT"),
        ("0:360:0", "at least 1"),
        ("10:10:3", "the same"),
        ("0,north", "not an angle"),
        ("", "empty"),
    ]:
        with pytest.raises(MatremapError, match=msg):
            parse_rotations(bad)


def test_ssim_of_identical_images_is_one():
    img = np.random.default_rng(0).random((32, 32, 3)).astype(np.float32) * 4.0
    mssim, smap = ssim_map(img, img)
    assert mssim == pytest.approx(1.0)
    assert smap.shape == (32, 32) and np.allclose(smap, 1.0)
    black = np.zeros((16, 16, 3))
    assert ssim_map(black, black)[0] == pytest.approx(1.0)


def test_dssim_is_zero_for_the_same_material_and_grows_with_a_change(tmp_path, studio):
    rot = [0.0, 120.0]
    same = evaluate(_ward(0.2), _ward(0.2), studio, rot, tmp_path / "same", **KW)
    assert max(same.dssim_full + same.dssim_specular) < 1e-9
    assert same.irradiance_scale == 1.0
    near = evaluate(_ward(0.2), _ward(0.25), studio, rot, tmp_path / "near", **KW)
    far = evaluate(_ward(0.2), _ward(0.5), studio, rot, tmp_path / "far", **KW)
    assert 0.0 < near.mean_full < far.mean_full
    assert 0.0 < near.mean_specular < far.mean_specular
    # the specular-only comparison is the more sensitive one to a roughness change
    assert far.mean_specular > far.mean_full


def test_irradiance_matching_across_families(studio):
    blender = SVMaterial("blender27:ward", {})
    mitsuba = SVMaterial("mitsuba06:ward", {})
    light = EnvironmentLight(studio, 32)
    assert irradiance_scale_under(light, blender.model, mitsuba.model) == pytest.approx(1.0 / math.pi, rel=1e-6)
    assert irradiance_scale_under(light, mitsuba.model, "cycles:glossy") == pytest.approx(1.0, rel=1e-6)


def test_report_files_and_numbers(report):
    out = report.out_dir
    assert report.report == out / "report.html" and report.report.is_file()
    assert len(report.rotations) == 3 and len(report.dssim_full) == 3 and len(report.dssim_specular) == 3
    assert all(0.0 < v < 2.0 for v in report.dssim_full + report.dssim_specular)
    data = json.loads((out / "results.json").read_text())
    assert data["rotations"] == [0.0, 120.0, 240.0]
    assert data["mean_dssim_full"] == pytest.approx(np.mean(report.dssim_full))
    pngs = sorted(p.name for p in (out / "images").glob("*.png"))
    assert "dssim_vs_rotation.png" in pngs
    assert {"r002_full_source.png", "r002_full_target.png", "r002_full_dssim.png", "r002_specular_dssim.png"} <= set(
        pngs
    )
    for p in (out / "images").glob("*.png"):
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_report_is_self_contained(report):
    text = report.report.read_text(encoding="utf-8")
    srcs = re.findall(r"""\bsrc\s*=\s*["']([^"']*)""", text)
    assert len(srcs) == 3 * 6 + 2  # six per rotation, the plot and the colour bar
    assert all(s.startswith("data:image/png;base64,") for s in srcs)
    assert not re.search(r"""\bhref\s*=""", text)
    assert not re.search(r"url\(|@import|https?://", text)
    for v in report.dssim_full:
        assert f"{v:.5f}" in text
    assert f"{report.mean_full:.5f}" in text and f"{report.mean_specular:.5f}" in text


def test_report_is_not_overwritten_without_force(report, studio):
    before = report.report.read_bytes()
    with pytest.raises(MatremapError, match="already exists"):
        evaluate(_ward(0.15), _ward(0.3), studio, [0.0], report.out_dir, **KW)
    assert report.report.read_bytes() == before


def test_overwrite_with_force_and_bad_output(tmp_path, studio):
    out = tmp_path / "r"
    evaluate(_ward(0.2), _ward(0.3), studio, [0.0], out, **KW)
    again = evaluate(_ward(0.2), _ward(0.2), studio, [0.0], out, force=True, **KW)
    assert again.mean_full < 1e-9
    with pytest.raises(MatremapError, match="does not exist"):
        evaluate(_ward(0.2), _ward(0.2), studio, [0.0], tmp_path / "no" / "such" / "dir", **KW)
    with pytest.raises(MatremapError, match="no parameter"):
        evaluate(_ward(0.2), ("mitsuba06:ward", {"roughness": 1}), studio, [0.0], tmp_path / "bad", **KW)
    assert not (tmp_path / "bad").exists()  # nothing written for a bad material


def test_report_shows_its_images_in_headless_chromium(report, tmp_path):
    if not CHROMIUM.exists():
        pytest.skip("Debian chromium not installed: apt-get install chromium")
    cmd = [
        str(CHROMIUM),
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        f"--user-data-dir={tmp_path / 'profile'}",
        "--virtual-time-budget=10000",
        "--dump-dom",
        report.report.resolve().as_uri(),
    ]
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=90)
    except subprocess.TimeoutExpired:
        pytest.fail("headless chromium did not finish within 90 s")
    assert proc.returncode == 0, proc.stderr[-2000:]
    n_images = len(re.findall(r"<img\b", report.report.read_text(encoding="utf-8")))
    m = re.search(r'data-images-loaded="(\d+)/(\d+)"', proc.stdout)
    assert m, "the report's script did not run (no data-images-loaded on <body>):\n" + proc.stdout[:500]
    loaded, total = int(m.group(1)), int(m.group(2))
    assert total == n_images > 0
    assert loaded == total, f"only {loaded} of {total} images decoded in chromium"
    shutil.rmtree(tmp_path / "profile", ignore_errors=True)


def test_mitsuba3_materials_are_drawn_by_mitsuba3_and_compare_with_their_emulation(tmp_path):
    pytest.importorskip("mitsuba", reason="Mitsuba 3 not installed: pip install 'matremap[mitsuba]'")
    from matremap.core import envmap as envmap_module

    rng = np.random.default_rng(0)
    alpha = rng.uniform(0.2, 0.4, (16, 32))
    k = np.stack([np.full((16, 32), v) for v in (3.0, 2.0, 1.0)], axis=-1)
    real = (
        "mitsuba3:roughconductor",
        {"alpha": alpha, "eta": 1.0, "k": k},
        {"distribution": "ggx", "material": "custom"},
    )
    emulated = (
        "mitsuba06:roughconductor",
        {"alpha": alpha, "eta": 1.0 * 1.000277, "k": k * 1.000277},
        {"distribution": "ggx"},
    )
    env = envmap_module.builtin()
    result = evaluate(real, emulated, env, [0.0], tmp_path / "ev", resolution=48, lights=256)
    assert result.irradiance_scale == pytest.approx(1.0, abs=0.02)
    assert result.mean_full < 0.05  # same BSDF; what differs is Mitsuba's sampling vs discrete lights (~0.016)
    rougher = (emulated[0], {**emulated[1], "alpha": 2 * alpha}, emulated[2])
    assert evaluate(real, rougher, env, [0.0], tmp_path / "ev2", resolution=48, lights=256).mean_full > 0.1
