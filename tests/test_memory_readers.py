"""Bounded memory for every reader (SECURITY.md, "Image sizes and memory"): a texture a material file samples
through a transform, a resampling or a graph is read in bands (formats/bake.sample_file), never decoded whole;
a glTF's JSON is held once (the written copy shares its extras) and written about its own size; a JSON of more
values than :data:`~matremap.formats.gltf_container.MAX_JSON_VALUES` is refused before it is parsed.

The bound each test checks is the mechanism's, measured with tracemalloc (numpy's arrays are traced): the peak
while a 2048 x 2048 RGB texture is baked onto a 256 x 256 map stays far below the image decoded whole as float32
(48 MiB), which every reader did before (64 to 252 MiB). The peaks against image size, for each reader's whole
command, are in ``benchmarks/memory.py --readers``. No timings."""

from __future__ import annotations

import json
import tracemalloc
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from matremap.cli import main
from matremap.formats import bake
from matremap.svbrdf.textures import read_image

SIDE = 2048
#: the 2048 x 2048 RGB texture decoded whole as float32, as the readers did
WHOLE = SIDE * SIDE * 3 * 4
#: a bake onto a 256 x 256 map holds one band of the file (a million texels: its 3 MiB of codes, and OpenImageIO's
#: copy of them while it reads) and the map's lookups and values (about 100 bytes a texel, 6 MiB; a graph's float64
#: values more), measured 11 to 16 MiB: half the whole image leaves room, and no whole-image read fits under it
BOUND = WHOLE // 2
#: the alpha-free copy holds one band of RGBA codes and its RGB part (measured 6 MiB)
COPY_BOUND = WHOLE // 4


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("MATREMAP_CACHE", str(tmp_path / "cache"))


def write_png(path: Path, codes: np.ndarray) -> Path:
    import OpenImageIO as oiio

    out = oiio.ImageOutput.create(str(path))
    spec = oiio.ImageSpec(codes.shape[1], codes.shape[0], codes.shape[2], oiio.UINT8)
    spec.attribute("png:compressionLevel", 1)
    out.open(str(path), spec)
    out.write_image(np.ascontiguousarray(codes, dtype=np.uint8))
    out.close()
    return path


def texture(path: Path, channels: int = 3) -> Path:
    """A 2048 x 2048 8-bit texture of smooth gradients (compresses well: the file is small, its pixels are not)."""
    y, x = np.mgrid[0:SIDE, 0:SIDE].astype(np.uint32)
    planes = [(x * 255 // (SIDE - 1)), (y * 255 // (SIDE - 1)), ((x + y) % 256), np.full_like(x, 200)]
    return write_png(path, np.stack(planes[:channels], axis=-1).astype(np.uint8))


def traced_peak(fn: Callable[[], object]) -> tuple[object, int]:
    """``fn()`` and the peak of the memory traced while it ran (bytes above what was held before)."""
    tracemalloc.start()
    try:
        tracemalloc.reset_peak()
        before = tracemalloc.get_traced_memory()[0]
        result = fn()
        peak = tracemalloc.get_traced_memory()[1] - before
    finally:
        tracemalloc.stop()
    return result, peak


def gltf(folder: Path, image: str, info: dict) -> Path:
    doc = {
        "asset": {"version": "2.0"},
        "images": [{"uri": image}],
        "textures": [{"source": 0}],
        "materials": [{"name": "m", "pbrMetallicRoughness": {"baseColorTexture": info, "metallicFactor": 0.0}}],
    }
    (folder / "m.gltf").write_text(json.dumps(doc))
    return folder / "m.gltf"


def test_a_streamed_bake_is_the_whole_image_bake_to_the_bit(tmp_path, monkeypatch):
    """bake_file reads a file in bands; its values are bake_image's on the image read whole, for every wrap
    mode, transforms that tile, rotate and flip the origin, and bands of a few rows."""
    rng = np.random.default_rng(0)
    path = write_png(tmp_path / "a.png", rng.integers(0, 256, (37, 53, 4)))
    tile = bake.translate(0.3, -0.2) @ bake.rotate(0.7) @ bake.scale(2.5, 1.3)
    for rows in (1, 3, 64):
        monkeypatch.setattr(bake, "BAND_TEXELS", 53 * rows)
        for cs in ("srgb", "linear"):
            image = read_image(path, cs)[0]
            for wrap in (("repeat", "mirror"), ("border", "clamp")):
                for origin in ("top-left", "bottom-left"):
                    uv = bake.UVTransform(tile, origin, wrap, 0.25)
                    for size in (None, (19, 80)):
                        want = bake.bake_image(image, uv, size)
                        np.testing.assert_array_equal(bake.bake_file(path, cs, uv, size), want)
                        s, t = uv.lookup(*bake.texel_grid(size or image.shape[:2]))
                        got = bake.sample_file(path, cs, s, t, wrap, 0.25, channels=[2, 0])
                        np.testing.assert_array_equal(got, bake.sample(image[..., [2, 0]], s, t, wrap, 0.25))


def test_a_gltf_texture_transform_is_baked_from_bands(tmp_path):
    """KHR_texture_transform scale 1/8: the 2048² base colour is baked onto 256² (what it needs)."""
    from matremap.formats.gltf_read import read

    texture(tmp_path / "base.png")
    info = {"index": 0, "extensions": {"KHR_texture_transform": {"scale": [0.125, 0.125]}}}
    ref = read(gltf(tmp_path, "base.png", info)).textures["baseColor"]
    assert ref.bake is not None
    baked, peak = traced_peak(ref.bake)
    assert np.shape(baked)[:2] == (256, 256)
    assert peak < BOUND, f"baking a {SIDE}² glTF texture held {peak / 2**20:.0f} MiB"


def test_a_gltf_texture_with_alpha_is_copied_without_it_band_by_band(tmp_path):
    """A base colour with alpha is read through an alpha-free copy: made in bands, not from the whole image."""
    from matremap.formats.gltf_read import read

    texture(tmp_path / "base.png", channels=4)
    asset, peak = traced_peak(lambda: read(gltf(tmp_path, "base.png", {"index": 0})))
    ref = asset.textures["baseColor"]  # type: ignore[attr-defined]  # traced_peak returns an object
    assert ref.extracted and ref.path.name.startswith("base-rgb-")
    rgb = read_image(tmp_path / "base.png", "linear")[0][..., :3]
    np.testing.assert_array_equal(read_image(ref.path, "linear")[0], rgb)
    assert peak < COPY_BOUND, f"the alpha-free copy of a {SIDE}² texture held {peak / 2**20:.0f} MiB"


def test_a_usd_transform2d_texture_is_baked_from_bands(tmp_path):
    pytest.importorskip("pxr", reason="USD not installed")
    from pxr import Sdf, Usd, UsdShade

    from matremap.formats import read_asset

    texture(tmp_path / "t.png")
    stage = Usd.Stage.CreateNew(str(tmp_path / "m.usda"))
    mat = UsdShade.Material.Define(stage, "/M")
    surf = UsdShade.Shader.Define(stage, "/M/S")
    surf.CreateIdAttr("UsdPreviewSurface")
    tex = UsdShade.Shader.Define(stage, "/M/T")
    tex.CreateIdAttr("UsdUVTexture")
    tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set("t.png")
    xf = UsdShade.Shader.Define(stage, "/M/X")
    xf.CreateIdAttr("UsdTransform2d")
    xf.CreateInput("scale", Sdf.ValueTypeNames.Float2).Set((0.125, 0.125))
    st = UsdShade.Shader.Define(stage, "/M/P")
    st.CreateIdAttr("UsdPrimvarReader_float2")
    st.CreateInput("varname", Sdf.ValueTypeNames.Token).Set("st")
    xf.CreateInput("in", Sdf.ValueTypeNames.Float2).ConnectToSource(st.ConnectableAPI(), "result")
    tex.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(xf.ConnectableAPI(), "result")
    tex.CreateOutput("rgb", Sdf.ValueTypeNames.Float3)
    surf.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).ConnectToSource(tex.ConnectableAPI(), "rgb")
    mat.CreateSurfaceOutput().ConnectToSource(surf.ConnectableAPI(), "surface")
    stage.GetRootLayer().Save()
    ref = read_asset(tmp_path / "m.usda").textures["diffuseColor"]
    assert ref.bake is not None
    baked, peak = traced_peak(ref.bake)
    assert np.shape(baked)[:2] == (256, 256)
    assert peak < BOUND, f"baking a {SIDE}² USD texture held {peak / 2**20:.0f} MiB"


def test_a_materialx_tiled_image_is_baked_from_bands(tmp_path):
    pytest.importorskip("MaterialX", reason="MaterialX not installed")
    from matremap.formats.materialx import read

    texture(tmp_path / "t.png")
    (tmp_path / "m.mtlx").write_text(
        '<?xml version="1.0"?>\n<materialx version="1.39" colorspace="lin_rec709">\n'
        '  <tiledimage name="t" type="color3"><input name="file" type="filename" value="t.png"/>\n'
        '    <input name="uvtiling" type="vector2" value="0.125, 0.125"/></tiledimage>\n'
        '  <standard_surface name="s" type="surfaceshader"><input name="base_color" type="color3" nodename="t"/>'
        "</standard_surface>\n"
        '  <surfacematerial name="m" type="material"><input name="surfaceshader" type="surfaceshader" nodename="s"/>'
        "</surfacematerial>\n</materialx>\n"
    )
    ref = read(tmp_path / "m.mtlx").textures["base_color"]
    assert ref.bake is not None
    baked, peak = traced_peak(ref.bake)
    assert np.shape(baked)[:2] == (256, 256)
    assert peak < BOUND, f"baking a {SIDE}² MaterialX image held {peak / 2**20:.0f} MiB"


def test_a_mitsuba_bitmap_is_sampled_from_bands(tmp_path):
    """A bitmap driving a scalar (its luminance), sampled onto 256² through its to_uv."""
    from matremap.formats.mitsuba_textures import bitmap_source

    path = texture(tmp_path / "t.png")
    source = bitmap_source(path, False, True, bake.scale(0.125, 0.125), "repeat", [], "alpha")
    baked, peak = traced_peak(lambda: source.values((256, 256)))
    assert np.shape(baked) == (256, 256, 1)
    assert peak < BOUND, f"sampling a {SIDE}² Mitsuba bitmap held {peak / 2**20:.0f} MiB"


# -- a glTF's JSON ------------------------------------------------------------------------------------------


def big_extras_gltf(folder: Path, pairs: int) -> Path:
    """A uniform glTF material whose file carries ``pairs`` small arrays in its extras (written compact)."""
    doc = {
        "asset": {"version": "2.0"},
        "materials": [{"name": "m", "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.3, 0.2, 1.0]}}],
        "extras": {"points": [[i % 7, i % 3] for i in range(pairs)], "bufferView": 0, "fooTexture": {"index": 0}},
    }
    (folder / "m.gltf").write_text(json.dumps(doc, separators=(",", ":")))
    return folder / "m.gltf"


def test_a_gltf_copy_shares_its_extras_and_is_written_about_its_size(tmp_path):
    """The written copy keeps the extras as they are (not renumbered, not looked into), the reader's document is
    left as it was read, the copy takes about the source's bytes (not 3.5 times) and writing it holds little more
    than its text: no second copy of the parsed document (a deep copy of 200,000 arrays is about 20 MiB)."""
    from matremap.formats.gltf_read import read
    from matremap.formats.gltf_write import write

    src = big_extras_gltf(tmp_path, 200_000)
    asset = read(src)
    before = json.dumps(asset.document.json)
    out = tmp_path / "out" / "m.gltf"
    out.parent.mkdir()
    _, peak = traced_peak(lambda: write(out, asset.material(), source=asset))
    assert json.dumps(asset.document.json) == before
    written = json.loads(out.read_text())
    assert written["extras"] == json.loads(src.read_text())["extras"]
    assert written["materials"][0]["name"] == "m"
    size = src.stat().st_size
    assert out.stat().st_size < 1.1 * size, f"a {size:,}-byte glTF written as {out.stat().st_size:,} bytes"
    assert peak < 4 * size, f"writing a {size:,}-byte glTF held {peak / 2**20:.0f} MiB"


def test_a_gltf_json_of_too_many_values_is_refused_before_parsing(tmp_path, monkeypatch, capsys):
    from matremap.formats import gltf_container

    monkeypatch.setattr(gltf_container, "MAX_JSON_VALUES", 10_000)
    src = big_extras_gltf(tmp_path, 6_000)  # about 12,000 values
    code = main(["remap", str(src), "--to", "mitsuba06:ward", "-o", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1, err
    assert "m.gltf" in err and "10,000" in err and "values" in err
    assert not (tmp_path / "o").exists()
