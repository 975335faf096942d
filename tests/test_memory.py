"""Bounded memory (issue 19, finding 4 and must-have 5): ``remap`` reads maps in bands; the statistics it
takes from them (ranges, medians, samples, the renders' downsampled maps, the metallic counts) are those
of the whole maps; a map beyond ``--max-texels`` is refused from its header before any texel is decoded.

The peak-memory figures against map size are in ``benchmarks/memory.py``; the test here is one bound a
whole-map implementation cannot meet: a 4096 x 4096 remap in its own process. No timings."""

from __future__ import annotations

import json
import os
import shutil
import struct
import subprocess
import sys
import zlib
from pathlib import Path

import numpy as np
import pytest

import matremap
from matremap.cli import main
from matremap.svbrdf.quality import sample
from matremap.svbrdf.textures import load_map_set, map_values, read_image

ROOT = Path(__file__).resolve().parents[1]
#: the matremap the tests import: the child processes run the same one
SRC = str(Path(matremap.__file__).resolve().parents[1])
BRONZE = ROOT / "examples" / "bronze"


def write_png(path: Path, codes: np.ndarray) -> None:
    import OpenImageIO as oiio

    a = np.atleast_3d(codes).astype(np.uint8)
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(a.shape[1], a.shape[0], a.shape[2], oiio.UINT8))
    out.write_image(a)
    out.close()


def whole(ms, name: str) -> np.ndarray:
    """A map of ``ms`` read whole, as the parameter's array."""
    path = ms.maps[name]
    return map_values(ms.spec, name, read_image(path, ms.colorspace.get(name))[0], path, 0)


def gltf_map_set(folder: Path, h: int, w: int, seed: int = 1) -> Path:
    """A gltf:metal-rough map set of odd size with random 8-bit codes: sRGB base colour, a metallic map
    mixing 0, 1 and values between, a roughness map."""
    rng = np.random.default_rng(seed)
    folder.mkdir(parents=True)
    write_png(folder / "m_basecolor.png", rng.integers(0, 256, (h, w, 3)))
    metal = rng.choice([0, 0, 255, 255, 128, 1], size=(h, w))
    write_png(folder / "m_metallic.png", metal)
    write_png(folder / "m_roughness.png", rng.integers(20, 240, (h, w)))
    write_png(folder / "m_normal.png", rng.integers(0, 256, (h, w, 3)))
    doc = {
        "model": "gltf:metal-rough",
        "maps": {"baseColor": "m_basecolor.png", "metallic": "m_metallic.png", "roughness": "m_roughness.png"},
        "normal": "m_normal.png",
        "colorspace": {"m_basecolor.png": "srgb", "m_metallic.png": "linear", "m_roughness.png": "linear"},
    }
    (folder / "material.json").write_text(json.dumps(doc))
    return folder


def block_means(a: np.ndarray, k: int) -> np.ndarray:
    """The mean of each k x k block, a smaller block at the right and bottom edges (by loops: the reference)."""
    h, w = a.shape[:2]
    out = np.zeros((-(-h // k), -(-w // k), *a.shape[2:]))
    for i in range(out.shape[0]):
        for j in range(out.shape[1]):
            out[i, j] = a[i * k : (i + 1) * k, j * k : (j + 1) * k].astype(float).mean(axis=(0, 1))
    return out


def test_streamed_statistics_are_those_of_the_whole_maps(tmp_path):
    from matremap.svbrdf.mapstats import summarise, with_medians

    ms = load_map_set(gltf_map_set(tmp_path / "maps", 301, 257))
    summary = with_medians(ms, summarise(ms, limits=(64, 100), render_side=60))
    for name in ms.maps:
        a = whole(ms, name)
        stats = summary.stats[name]
        assert (stats.lo, stats.hi) == (a.min(), a.max())
        assert stats.mean == pytest.approx(a.astype(float).mean(), rel=1e-12)
        # 8-bit maps: the histogram's median is numpy's, to the bit (an even count: the two middle values' mean)
        expected = np.median(a.reshape(-1, a.shape[-1]) if a.ndim == 3 else a.reshape(-1), axis=0)
        np.testing.assert_allclose(stats.median, expected, rtol=1e-6, atol=0)
        for limit in (64, 100):
            np.testing.assert_array_equal(summary.sample(limit)[name], sample(a, limit))
        # the renders' maps: means of 6 x 6 blocks (301 x 257 to at most 60 a side), ragged at the edges
        np.testing.assert_allclose(summary.render[name], block_means(a, 6), rtol=1e-5, atol=1e-6)
    normal = read_image(ms.normal, "linear", colour=False)[0]
    np.testing.assert_allclose(summary.render_normal, 2 * block_means(normal, 6) - 1, atol=1e-5)
    metal = whole(ms, "metallic")
    counts = summary.stats["metallic"].specialisation
    assert counts.texels == metal.size
    assert counts.at_value == np.count_nonzero(np.abs(metal - 1.0) <= 0.5 / 255)
    assert counts.some_value == np.count_nonzero(metal > 0.5 / 255)
    assert counts.some_other == np.count_nonzero(metal < 1 - 0.5 / 255)
    assert counts.between == np.count_nonzero((metal > 0.5 / 255) & (metal < 1 - 0.5 / 255))


def test_the_median_of_a_float_map_is_within_a_half_float_bin(tmp_path):
    import OpenImageIO as oiio

    from matremap.svbrdf.mapstats import summarise, with_medians

    rng = np.random.default_rng(3)
    folder = tmp_path / "maps"
    folder.mkdir()
    a = rng.lognormal(-1.0, 1.0, (200, 150)).astype(np.float32)  # roughness-like, many distinct values
    out = oiio.ImageOutput.create(str(folder / "r_roughness.exr"))
    out.open(str(folder / "r_roughness.exr"), oiio.ImageSpec(150, 200, 1, oiio.FLOAT))
    out.write_image(a[..., None])
    out.close()
    ms = load_map_set(folder, "mitsuba06:ward")
    name = next(iter(ms.maps))
    median = with_medians(ms, summarise(ms)).stats[name].median
    assert abs(median - float(np.median(whole(ms, name)))) <= 2**-10 * abs(median)


def tiled(folder: Path, size: int) -> Path:
    """``examples/bronze`` tiled to ``size`` x ``size`` (written band by band)."""
    import OpenImageIO as oiio

    shutil.copytree(BRONZE, folder, ignore=shutil.ignore_patterns("*.png"))
    for f in sorted(BRONZE.glob("*.png")):
        tile = read_codes(f)
        reps = size // tile.shape[0]
        out = oiio.ImageOutput.create(str(folder / f.name))
        out.open(str(folder / f.name), oiio.ImageSpec(size, size, tile.shape[2], oiio.UINT8))
        row = np.tile(tile, (1, reps, 1))
        for y0 in range(0, size, tile.shape[0]):
            out.write_scanlines(y0, y0 + tile.shape[0], 0, np.ascontiguousarray(row))
        out.close()
    return folder


def read_codes(path: Path) -> np.ndarray:
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    spec = inp.spec()
    a = inp.read_image(0, 0, 0, spec.nchannels, oiio.UINT8)
    inp.close()
    return np.asarray(a).reshape(spec.height, spec.width, spec.nchannels)


#: runs a command and prints its peak resident set last on stderr. A small process of its own forks it: the
#: peak Linux keeps for a process survives exec, so a command forked straight from this test process (large
#: after many tests) would start from the test process's size
MEASURED = """
import os, subprocess, sys
child = subprocess.Popen(sys.argv[1:])
_, status, usage = os.wait4(child.pid, 0)
print(f"peak-rss-kb {usage.ru_maxrss}", file=sys.stderr)
sys.exit(os.waitstatus_to_exitcode(status))
"""


def run_measured(args: list[str], cwd: Path) -> tuple[int, str, float]:
    """``python -m matremap ARGS`` in its own process: exit code, stderr and its peak resident set (MB)."""
    env = {**os.environ, "MATREMAP_CACHE": str(cwd / "cache"), "PYTHONPATH": SRC}
    cmd = [sys.executable, "-c", MEASURED, sys.executable, "-m", "matremap", *args]
    p = subprocess.run(cmd, cwd=cwd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    *lines, last = p.stderr.rstrip("\n").split("\n")
    assert last.startswith("peak-rss-kb "), p.stderr
    return p.returncode, "\n".join(lines), int(last.split()[1]) / 1024  # kB on Linux


@pytest.mark.slow
def test_a_4096_remap_stays_far_below_its_maps_as_float64(tmp_path):
    """The 4096 x 4096 bronze set (two RGB maps, a grey one and a normal map) held once as float64 is
    1.34 GB; the whole-map remap of before peaked at 3.6 GB. Streamed, one process (--workers 1) stays
    under 1 GB (measured: about 0.4 GB), evaluation included. The result is the texel-by-texel remap: its
    maps are the 256 x 256 example's result, tiled."""
    big = tiled(tmp_path / "big", 4096)
    job = ["--to", "mitsuba06:pbr", "--fix", "distribution=as", "--rotations", "0:360:2"]
    code, err, peak_mb = run_measured(["remap", str(big), *job, "--workers", "1", "-o", "out-big"], tmp_path)
    assert code == 0, err
    assert peak_mb < 1024, f"remap of 4096 x 4096 maps peaked at {peak_mb:.0f} MB; its log:\n{err[-2000:]}"
    assert main(["remap", str(BRONZE), *job, "-o", str(tmp_path / "out-small")]) == 0
    small = load_map_set(tmp_path / "out-small" / "maps")
    large = load_map_set(tmp_path / "out-big" / "maps")
    assert set(small.maps) == set(large.maps) and large.size == (4096, 4096)
    for name, path in small.maps.items():
        tile = read_codes(path)
        got = read_codes(large.maps[name])
        np.testing.assert_array_equal(got[:256, :256], tile, err_msg=name)
        np.testing.assert_array_equal(got[-256:, -256:], tile, err_msg=name)
    verdict = json.loads((tmp_path / "out-big" / "verdict.json").read_text())
    assert verdict["passed"] and "box-filtered to 1024 x 1024" in err


def png_header(path: Path, width: int, height: int) -> Path:
    """A PNG whose header declares ``width`` x ``height`` grey texels and whose pixel data is 1 MB of noise,
    not a deflate stream: any attempt to decode it fails, so a refusal naming its size came from the header
    alone. (1 MB: OpenImageIO itself refuses a header claiming thousands of times the file's size; a
    389 KB PNG of 20000 x 20000 passes it, as the issue found.)"""

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    idat = np.random.default_rng(0).integers(0, 256, 1 << 20, dtype=np.uint8).tobytes()
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", idat) + chunk(b"IEND", b""))
    return path


def test_an_absurd_map_is_refused_from_its_header_in_one_line(tmp_path, capsys):
    folder = tmp_path / "maps"
    folder.mkdir()
    png_header(folder / "huge_roughness.png", 50_000, 50_000)
    code = main(["remap", str(folder), "--from", "mitsuba06:ward", "--to", "mitsuba06:pbr", "-o", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1, err
    assert "huge_roughness.png" in err and "50000 x 50000" in err and "--max-texels" in err
    assert not (tmp_path / "o").exists()


def test_a_material_file_naming_an_absurd_texture_is_refused_before_decoding(tmp_path, capsys):
    asset = tmp_path / "asset"
    asset.mkdir()
    png_header(asset / "huge.png", 40_000, 40_000)
    doc = {
        "asset": {"version": "2.0"},
        "images": [{"uri": "huge.png"}],
        "textures": [{"source": 0}],
        "materials": [{"name": "m", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
    }
    (asset / "m.gltf").write_text(json.dumps(doc))
    code = main(["remap", str(asset / "m.gltf"), "--to", "mitsuba06:ward", "-o", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "huge.png" in err and "40000 x 40000" in err, err
    assert not (tmp_path / "o").exists()


def test_max_texels_sets_the_limit(tmp_path, capsys):
    job = [str(BRONZE), "--to", "mitsuba06:pbr", "--fix", "distribution=as"]
    assert main(["convert", *job, "-o", str(tmp_path / "a"), "--max-texels", "65535"]) == 2
    err = capsys.readouterr().err.strip()
    assert "256 x 256 = 65,536 texels" in err and "--max-texels 65536" in err and len(err.splitlines()) == 1
    assert not (tmp_path / "a").exists()
    assert main(["convert", *job, "-o", str(tmp_path / "b"), "--max-texels", "65536"]) == 0
    assert (tmp_path / "b" / "material.json").is_file()
