import json

import numpy as np
import OpenImageIO as oiio
import pytest

from matremap.errors import MatremapError
from matremap.svbrdf.textures import (
    ImageInfo,
    MapReader,
    load_map_set,
    map_values,
    output_info,
    read_image,
    read_region,
    save_manifest,
    srgb_to_linear,
    write_image_like,
)


def smooth(h=40, w=56, c=3, seed=0):
    y, x = np.mgrid[0:h, 0:w] / np.array([h, w])[:, None, None]
    rng = np.random.default_rng(seed)
    phase = rng.uniform(0, 6, c)
    return (0.5 + 0.45 * np.sin(3 * x[..., None] + 2 * y[..., None] + phase)).astype(np.float32)


def raw_write(path, data, fmt):
    h, w, c = data.shape
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), oiio.ImageSpec(w, h, c, fmt))
    assert out.write_image(data)
    out.close()


FORMATS = [  # out format, extension, pixel type, max error in linear values
    ("png8", "png", "uint8", 0.0045),
    ("png16", "png", "uint16", 2e-5),
    ("jpg", "jpg", "uint8", 0.06),
    ("tif8", "tif", "uint8", 0.0045),
    ("tif16", "tif", "uint16", 2e-5),
    ("tif32", "tif", "float", 0.0),
    ("exr", "exr", "float", 0.0),
    ("exr16", "exr", "half", 5e-4),
]


@pytest.mark.parametrize("fmt,ext,pixel_type,tol", FORMATS)
@pytest.mark.parametrize("colorspace", ["srgb", "linear"])
def test_round_trip_per_format(tmp_path, fmt, ext, pixel_type, tol, colorspace):
    a = smooth()
    info = output_info(ImageInfo("png", "uint8", 3, 1, 1, colorspace), fmt)
    p = write_image_like(tmp_path / f"m.{ext}", a, info)
    b, got = read_image(p, colorspace=info.colorspace)
    assert (got.format, got.pixel_type, got.channels, got.width, got.height) == (ext, pixel_type, 3, 56, 40)
    assert b.dtype == np.float32 and b.shape == a.shape
    # linear 8-bit steps are 1/255 wide, sRGB ones at most ~0.0086 (near white)
    limit = tol if colorspace == "srgb" or pixel_type != "uint8" else max(tol, 0.5 / 255 + 1e-6)
    assert np.abs(b - a).max() <= limit + 1e-7
    if pixel_type in ("uint8", "uint16") and fmt != "jpg":  # re-encoding is lossless
        p2 = write_image_like(tmp_path / f"again.{ext}", b, got)
        c, _ = read_image(p2, colorspace=info.colorspace)
        np.testing.assert_array_equal(c, b)


def test_colour_maps_are_decoded_from_srgb_and_data_maps_are_linear(tmp_path):
    codes = np.arange(256, dtype=np.uint8).reshape(16, 16, 1).repeat(3, axis=2)
    raw_write(tmp_path / "c.png", codes, oiio.UINT8)
    colour, info = read_image(tmp_path / "c.png")
    assert info.colorspace == "srgb"
    np.testing.assert_allclose(colour, srgb_to_linear(codes / 255.0), atol=1e-7)
    data, info = read_image(tmp_path / "c.png", colour=False)
    assert info.colorspace == "linear"
    np.testing.assert_allclose(data, codes / 255.0, atol=1e-7)
    codes16 = (np.arange(256, dtype=np.uint16) * 257).reshape(16, 16, 1)
    raw_write(tmp_path / "c16.png", codes16, oiio.UINT16)
    colour16, info = read_image(tmp_path / "c16.png")
    assert info.pixel_type == "uint16"
    np.testing.assert_allclose(colour16[..., 0], srgb_to_linear(codes16[..., 0] / 65535.0), atol=1e-7)
    f = np.full((4, 4, 3), 0.25, np.float32)
    raw_write(tmp_path / "f.exr", f, oiio.FLOAT)
    np.testing.assert_array_equal(read_image(tmp_path / "f.exr")[0], f)  # float files are linear as stored


def test_bands_read_in_order_match_the_whole_image(tmp_path):
    a = smooth(37, 20)
    p = write_image_like(tmp_path / "m.png", a, ImageInfo("png", "uint16", 3, 0, 0, "srgb"))
    whole, _ = read_image(p)
    with MapReader(p) as r:
        bands = [r.read_rows(y, min(y + 8, 37)) for y in range(0, 37, 8)]
    np.testing.assert_array_equal(np.concatenate(bands), whole)
    region, _ = read_region(p, 10, 20)
    np.testing.assert_array_equal(region, whole[10:20])


def make_set(
    folder, size=(12, 16), names=("ward_diffuse.png", "ward_specular.png", "ward_roughness.png", "ward_normal.png")
):
    folder.mkdir(parents=True, exist_ok=True)
    h, w = size
    for n in names:
        role = n.rsplit("_", 1)[1].split(".")[0]
        c = 1 if role == "roughness" else 3
        a = smooth(h, w, c) * (0.2 if role == "specular" else 1.0)
        write_image_like(folder / n, a, ImageInfo("png", "uint8", c, 0, 0, "linear" if c == 1 else "srgb"))
    return folder


MANIFEST = {
    "model": "mitsuba06:ward",
    "maps": {
        "specularReflectance": "ward_specular.png",
        "alpha": "ward_roughness.png",
        "diffuseReflectance": "ward_diffuse.png",
    },
    "normal": "ward_normal.png",
    "params": {"variant": "ward"},
    "colorspace": {"ward_specular.png": "srgb"},
}


def test_manifest_json_and_toml(tmp_path):
    root = make_set(tmp_path / "set")
    (root / "material.json").write_text(json.dumps(MANIFEST))
    ms = load_map_set(root)
    assert ms.model == "mitsuba06:ward" and ms.size == (12, 16)
    assert ms.maps["alpha"].name == "ward_roughness.png" and ms.normal.name == "ward_normal.png"
    assert ms.colorspace == {"specularReflectance": "srgb", "alpha": "linear", "diffuseReflectance": "srgb"}
    assert ms.constants == {"variant": "ward"}
    (root / "material.json").unlink()
    (root / "material.toml").write_text(
        'model = "mitsuba06:ward"\nnormal = "ward_normal.png"\n[maps]\nalpha = "ward_roughness.png"\n'
        'specularReflectance = "ward_specular.png"\n[params]\nvariant = "ward"\ndiffuseReflectance = 0.1\n'
        '[colorspace]\n"ward_specular.png" = "linear"\n'
    )
    ms = load_map_set(root / "material.toml")
    assert set(ms.maps) == {"alpha", "specularReflectance"} and ms.constants["diffuseReflectance"] == 0.1
    assert ms.colorspace["specularReflectance"] == "linear"
    out = tmp_path / "copy"
    out.mkdir()
    doc = json.loads(save_manifest(out, ms).read_text())
    assert doc["model"] == "mitsuba06:ward" and doc["params"]["variant"] == "ward"


def test_file_name_conventions(tmp_path):
    root = make_set(tmp_path / "set")
    ms = load_map_set(root, model="mitsuba06:ward")
    assert {k: v.name for k, v in ms.maps.items()} == {
        "diffuseReflectance": "ward_diffuse.png",
        "specularReflectance": "ward_specular.png",
        "alpha": "ward_roughness.png",
    }
    assert ms.normal.name == "ward_normal.png"
    assert ms.colorspace["alpha"] == "linear" and ms.colorspace["specularReflectance"] == "srgb"
    pbr = load_map_set(root, model="mitsuba06:pbr")  # *_specular binds the model's reflectance parameter
    assert "F0" in pbr.maps and "specularReflectance" not in pbr.maps
    with pytest.raises(MatremapError, match="name the maps' model"):
        load_map_set(root)


def test_a_grey_rgb_file_feeds_a_scalar_and_a_coloured_one_does_not(tmp_path):
    root = make_set(tmp_path / "set", names=("ward_specular.png",))
    grey = np.repeat(smooth(12, 16, 1), 3, axis=2)
    write_image_like(root / "ward_roughness.png", grey, ImageInfo("png", "uint8", 3, 0, 0, "linear"))
    ms = load_map_set(root, model="mitsuba06:ward")
    assert any("first channel" in n for n in ms.notes)
    band = MapReader(ms.maps["alpha"], "linear").read_rows(0, 12)
    np.testing.assert_array_equal(map_values(ms.spec, "alpha", band, ms.maps["alpha"], 0), band[..., 0])
    band[5, 3, 1] += 0.3
    with pytest.raises(MatremapError, match="row 5"):
        map_values(ms.spec, "alpha", band, ms.maps["alpha"], 0)


def test_bad_map_sets(tmp_path):
    def fresh(name, **manifest):
        root = make_set(tmp_path / name)
        (root / "material.json").write_text(json.dumps({**MANIFEST, **manifest}))
        return root

    root = fresh("sizes")
    write_image_like(
        root / "ward_roughness.png", smooth(12, 15, 1), ImageInfo("png", "uint8", 1, 0, 0, "linear"), force=True
    )
    with pytest.raises(MatremapError, match="differ in size.*resample"):
        load_map_set(root)
    root = fresh("missing")
    (root / "ward_specular.png").unlink()
    with pytest.raises(MatremapError, match="ward_specular.png not found"):
        load_map_set(root)
    root = fresh("channels")
    write_image_like(
        root / "ward_roughness.png", smooth(12, 16, 2), ImageInfo("png", "uint8", 2, 0, 0, "linear"), force=True
    )
    with pytest.raises(MatremapError, match="2 channels but alpha is a scalar"):
        load_map_set(root)
    root = fresh("normal")
    write_image_like(
        root / "ward_normal.png", smooth(12, 16, 1), ImageInfo("png", "uint8", 1, 0, 0, "linear"), force=True
    )
    with pytest.raises(MatremapError, match="normal map.*needs 3"):
        load_map_set(root)
    root = fresh("corrupt")
    (root / "ward_diffuse.png").write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(range(200)))
    with pytest.raises(MatremapError, match="ward_diffuse.png: it is not a readable image"):
        load_map_set(root)
    root = fresh("colorspace", colorspace={"ward_specular.png": "acescg"})
    with pytest.raises(MatremapError, match="unknown colour space 'acescg'; use one of srgb, linear"):
        load_map_set(root)
    root = fresh("param", maps={"roughness": "ward_roughness.png"})
    with pytest.raises(MatremapError, match="no parameter 'roughness'"):
        load_map_set(root)
    root = fresh("range", maps={"alpha": "ward_roughness.png"}, params={"variant": "ward", "diffuseReflectance": 3})
    with pytest.raises(MatremapError, match="outside its range"):
        load_map_set(root)
    (tmp_path / "empty").mkdir()
    with pytest.raises(MatremapError, match="holds no maps"):
        load_map_set(tmp_path / "empty", model="mitsuba06:ward")


def test_truncated_and_non_finite_files_fail_when_read(tmp_path):
    a = smooth(64, 64)
    p = write_image_like(
        tmp_path / "t.png",
        a + 0.01 * np.random.default_rng(0).normal(size=a.shape),
        ImageInfo("png", "uint8", 3, 0, 0, "srgb"),
    )
    data = p.read_bytes()
    (tmp_path / "cut.png").write_bytes(data[: len(data) // 2])
    with pytest.raises(MatremapError, match="cut.png.*corrupt or truncated"), MapReader(tmp_path / "cut.png") as r:
        for y in range(0, 64, 16):
            r.read_rows(y, y + 16)
    a[50, 7, 1] = np.inf
    p = write_image_like(tmp_path / "inf.exr", a, ImageInfo("exr", "float", 3, 0, 0, "linear"))
    with pytest.raises(MatremapError, match=r"inf.exr holds NaN or infinite texels \(first in row 50\)"):
        read_image(p)


def test_rgba_colour_is_not_multiplied_by_alpha(tmp_path):
    """An RGBA PNG's colour comes back as stored (OpenImageIO would premultiply it by alpha)."""
    import OpenImageIO as oiio

    from matremap.svbrdf.textures import read_image

    path = str(tmp_path / "rgba.png")
    pixels = np.zeros((4, 4, 4), np.uint8)
    pixels[..., :3] = (200, 100, 50)
    pixels[..., 3] = 64
    out = oiio.ImageOutput.create(path)
    spec = oiio.ImageSpec(4, 4, 4, oiio.UINT8)
    spec.attribute("oiio:UnassociatedAlpha", 1)
    assert out.open(path, spec) and out.write_image(pixels)
    out.close()
    image, _ = read_image(path, "linear")
    np.testing.assert_allclose(image[0, 0] * 255, [200, 100, 50, 64], atol=1e-3)


@pytest.mark.parametrize("channels", [1, 2, 3, 4])
def test_png_bytes_decode_to_the_array_and_use_no_temporary_folder(tmp_path, monkeypatch, channels):
    """png_bytes encodes in memory (it went through a folder in the system's temporary folder, which a killed
    run left); PIL and OpenImageIO read back exactly the array, colour under a zero alpha included."""
    import io
    import tempfile

    import OpenImageIO as oiio
    from PIL import Image

    from matremap.core.imageio import png_bytes

    def no_folder(*args, **kwargs):
        raise AssertionError("png_bytes made a temporary folder")

    monkeypatch.setattr(tempfile, "mkdtemp", no_folder)  # TemporaryDirectory calls it
    a = np.random.default_rng(channels).integers(0, 256, (5, 7, channels), dtype=np.uint8)
    if channels in (2, 4):
        a[0, 0, -1] = 0  # colour kept where alpha is 0 (unassociated)
    data = png_bytes(a)
    pil = np.asarray(Image.open(io.BytesIO(data)))
    np.testing.assert_array_equal(pil.reshape(a.shape), a)
    (tmp_path / "t.png").write_bytes(data)
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)  # as matremap reads textures
    np.testing.assert_array_equal(oiio.ImageBuf(str(tmp_path / "t.png"), 0, 0, config).get_pixels(oiio.UINT8), a)
