"""Files a material file names stay inside its folder (or a folder allowed with --allow-path), and a
named output stays inside -o (issue 19: an image from elsewhere on disk ended up in OUT/maps/)."""

from __future__ import annotations

import importlib.util
import json
import os
from pathlib import Path

import numpy as np
import pytest

from matremap.cli import main
from matremap.errors import MatremapError
from matremap.formats import allowed_paths, read_asset
from matremap.formats.confine import Confinement, output_inside, resolve_reference
from matremap.svbrdf.textures import ImageInfo, write_image_like

needs_materialx = pytest.mark.skipif(
    importlib.util.find_spec("MaterialX") is None, reason="MaterialX not installed: pip install 'matremap[materialx]'"
)
OUTSIDE = "points outside the asset folder"


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    """A cache of the test's own (extracted glTF images go there)."""
    monkeypatch.setenv("MATREMAP_CACHE", str(tmp_path / "cache"))


def png(path: Path, seed: int = 0) -> Path:
    """A small sRGB PNG whose pixels depend on ``seed``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    rgb = np.random.default_rng(seed).uniform(0.1, 0.9, (8, 8, 3)).astype(np.float32)
    return write_image_like(path, rgb, ImageInfo("png", "uint8", 3, 0, 0, "srgb"), force=True)


def gltf_image(folder: Path, ref: str) -> Path:
    """A glTF whose base colour texture is the image at uri ``ref``."""
    folder.mkdir(parents=True, exist_ok=True)
    doc = {
        "asset": {"version": "2.0"},
        "images": [{"uri": ref}],
        "textures": [{"source": 0}],
        "materials": [{"name": "m", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
    }
    (folder / "m.gltf").write_text(json.dumps(doc))
    return folder / "m.gltf"


def gltf_buffer(folder: Path, ref: str, size: int) -> Path:
    """A glTF whose base colour image is a buffer view of the buffer file at uri ``ref``."""
    folder.mkdir(parents=True, exist_ok=True)
    doc = {
        "asset": {"version": "2.0"},
        "buffers": [{"uri": ref, "byteLength": size}],
        "bufferViews": [{"buffer": 0, "byteLength": size}],
        "images": [{"bufferView": 0, "mimeType": "image/png"}],
        "textures": [{"source": 0}],
        "materials": [{"name": "m", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
    }
    (folder / "m.gltf").write_text(json.dumps(doc))
    return folder / "m.gltf"


def mitsuba(folder: Path, ref: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "s.xml").write_text(
        '<scene version="3.0.0"><bsdf type="diffuse" id="d"><texture type="bitmap" name="reflectance">'
        f'<string name="filename" value="{ref}"/></texture></bsdf></scene>'
    )
    return folder / "s.xml"


def materialx(folder: Path, ref: str, normal: bool = False) -> Path:
    """A MaterialX gltf_pbr whose base colour (or, with ``normal``, normal map) is the image file ``ref``."""
    folder.mkdir(parents=True, exist_ok=True)
    if normal:
        nodes = (
            f'  <image name="tex" type="vector3"><input name="file" type="filename" value="{ref}"/></image>\n'
            '  <normalmap name="nm" type="vector3"><input name="in" type="vector3" nodename="tex"/></normalmap>\n'
            '  <gltf_pbr name="s" type="surfaceshader"><input name="normal" type="vector3" nodename="nm"/></gltf_pbr>\n'
        )
    else:
        nodes = (
            f'  <image name="tex" type="color3"><input name="file" type="filename" value="{ref}"/></image>\n'
            '  <gltf_pbr name="s" type="surfaceshader">'
            '<input name="base_color" type="color3" nodename="tex"/></gltf_pbr>\n'
        )
    (folder / "m.mtlx").write_text(
        '<?xml version="1.0"?>\n<materialx version="1.39">\n' + nodes + '  <surfacematerial name="mat" type="material">'
        '<input name="surfaceshader" type="surfaceshader" nodename="s"/></surfacematerial>\n</materialx>\n'
    )
    return folder / "m.mtlx"


def make_gltf_image(folder: Path, ref: str, target: Path) -> Path:
    return gltf_image(folder, ref)


def make_gltf_buffer(folder: Path, ref: str, target: Path) -> Path:
    size = target.stat().st_size if target.is_file() else 100
    return gltf_buffer(folder, ref, size)


#: reader -> (build the file naming ``ref``, the file the reference names in the asset, where it shows)
READERS = {
    "gltf image": (make_gltf_image, lambda a: a.textures["baseColor"].path),
    "gltf buffer": (make_gltf_buffer, None),
    "mitsuba bitmap": (lambda f, ref, t: mitsuba(f, ref), lambda a: a.textures["reflectance"].path),
    "materialx file": (lambda f, ref, t: materialx(f, ref), lambda a: a.textures["baseColor"].path),
    "materialx normal": (lambda f, ref, t: materialx(f, ref, normal=True), lambda a: a.normal.path),
}
READER_PARAMS = [
    pytest.param(name, marks=needs_materialx) if name.startswith("materialx") else name for name in READERS
]


def reference(kind: str, tmp_path: Path, secret: Path) -> str:
    """The reference a hostile file writes to reach ``secret`` (outside ``tmp_path/asset``)."""
    if kind == "absolute":
        return str(secret)
    if kind == "parent":
        return os.path.relpath(secret, tmp_path / "asset")
    link = tmp_path / "asset" / "link.png"
    link.parent.mkdir(parents=True, exist_ok=True)
    link.symlink_to(secret)
    return "link.png"


@pytest.mark.parametrize("reader", READER_PARAMS)
@pytest.mark.parametrize("kind", ["absolute", "parent", "symlink"])
def test_a_reference_outside_the_asset_folder_is_refused_and_the_message_does_not_say_if_it_exists(
    tmp_path, reader, kind
):
    build, _ = READERS[reader]
    secret = png(tmp_path / "elsewhere" / "secret.png", seed=1)
    ref = reference(kind, tmp_path, secret)
    src = build(tmp_path / "asset", ref, secret)
    with pytest.raises(MatremapError) as exists:
        read_asset(src)
    message = str(exists.value)
    assert OUTSIDE in message and repr(ref) in message and "--allow-path" in message
    assert "\n" not in message
    secret.unlink()
    with pytest.raises(MatremapError) as missing:
        read_asset(src)
    assert str(missing.value) == message  # the same words whether the file exists or not


@pytest.mark.parametrize("reader", READER_PARAMS)
def test_a_folder_allowed_by_the_caller_is_read(tmp_path, reader):
    build, where = READERS[reader]
    secret = png(tmp_path / "elsewhere" / "secret.png", seed=1)
    src = build(tmp_path / "asset", str(secret), secret)
    asset = read_asset(src, confinement=Confinement.of([tmp_path / "elsewhere"]))
    if where is not None:
        assert where(asset) == secret.resolve()
    with allowed_paths([tmp_path / "elsewhere"]):  # what the command line's --allow-path enters
        again = read_asset(src)
    assert set(again.textures) == set(asset.textures)
    with pytest.raises(MatremapError, match=OUTSIDE):  # and only while it is in effect
        read_asset(src)
    with pytest.raises(MatremapError, match=OUTSIDE):  # another folder does not allow it
        read_asset(src, confinement=Confinement.of([tmp_path / "asset"]))


@pytest.mark.parametrize("reader", READER_PARAMS)
def test_references_inside_the_asset_folder_still_read(tmp_path, reader):
    """A subfolder, an absolute path inside the folder and a symlink within it are the asset's own."""
    build, where = READERS[reader]
    inside = png(tmp_path / "asset" / "tex" / "base.png", seed=2)
    (tmp_path / "asset" / "alias.png").symlink_to(inside)
    for ref in ("tex/base.png", str(inside), "alias.png", "tex/../tex/base.png"):
        asset = read_asset(build(tmp_path / "asset", ref, inside))
        if where is not None:
            assert where(asset) == inside.resolve()


def test_a_web_uri_is_refused_as_not_a_local_file(tmp_path):
    src = gltf_image(tmp_path / "asset", "https://example.invalid/x.png")
    with pytest.raises(MatremapError, match="is not a local file"):
        read_asset(src)


def test_resolve_reference_refuses_a_symlink_loop_and_a_nul_byte_with_the_same_line(tmp_path):
    (tmp_path / "a").symlink_to(tmp_path / "b")
    (tmp_path / "b").symlink_to(tmp_path / "a")
    for ref in ("a", "x\0.png"):
        with pytest.raises(MatremapError, match=OUTSIDE):
            resolve_reference(ref, tmp_path, "image 0 uri", Confinement())


def test_allow_path_must_name_an_existing_folder(tmp_path):
    with pytest.raises(MatremapError, match="is not a folder"):
        Confinement.of([tmp_path / "nope"])


def test_output_inside_refuses_names_that_leave_the_output_folder(tmp_path):
    out = tmp_path / "out"
    assert output_inside(out, "x.gltf") == (out / "x.gltf").resolve()
    assert output_inside(out, "sub/../x.gltf") == (out / "x.gltf").resolve()
    for name in ("../../x.gltf", "../x.gltf", str(tmp_path / "x.gltf"), ".", "sub/../../x.gltf"):
        with pytest.raises(MatremapError, match="points outside the output folder"):
            output_inside(out, name)


# -- the command line ------------------------------------------------------------------------------


def run(capsys, *argv: str) -> tuple[int, str]:
    code = main(list(argv))
    _, err = capsys.readouterr()
    return code, err


@pytest.mark.parametrize("kind", ["absolute", "parent", "symlink"])
def test_remap_refuses_an_outside_texture_with_exit_2_one_line_and_no_output(tmp_path, capsys, kind):
    secret = png(tmp_path / "elsewhere" / "secret.png", seed=1)
    src = gltf_image(tmp_path / "asset", reference(kind, tmp_path, secret))
    code, err = run(capsys, "remap", str(src), "--to", "mitsuba06:ward", "-o", str(tmp_path / "out"))
    assert code == 2 and OUTSIDE in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".out")]  # no staging folder either


def test_remap_reads_an_outside_texture_when_its_folder_is_allowed(tmp_path, capsys):
    """--allow-path reaches the reader: the remap of a glTF onto its own model copies the maps, so the
    texture from the allowed folder is in the output (and the run exits 0)."""
    secret = png(tmp_path / "elsewhere" / "secret.png", seed=1)
    src = gltf_image(tmp_path / "asset", str(secret))
    args = ["remap", str(src), "--to", "gltf:metal-rough", "-o", str(tmp_path / "out"), "--no-evaluate"]
    code, err = run(capsys, *args, "--allow-path", str(tmp_path / "elsewhere"))
    assert code == 0, err
    copied = [p for p in (tmp_path / "out").rglob("*.png") if p.read_bytes() == secret.read_bytes()]
    assert copied, "the allowed texture was not used"


def test_allow_path_must_exist(tmp_path, capsys):
    src = gltf_image(tmp_path / "asset", "base.png")
    png(tmp_path / "asset" / "base.png")
    out = tmp_path / "out"
    code, err = run(capsys, "remap", str(src), "--to", "mitsuba06:ward", "-o", str(out), "--allow-path", "/nope/x")
    assert code == 2 and "is not a folder" in err and not out.exists()


@pytest.mark.parametrize("command", ["convert", "remap", "evaluate"])
def test_a_map_set_manifest_naming_a_file_outside_its_folder_is_refused(tmp_path, capsys, command):
    """A material.json naming ../secret.png (or an absolute path) was read and its image copied into OUT."""
    png(tmp_path / "elsewhere" / "secret.png")
    maps = tmp_path / "maps"
    maps.mkdir()
    png(maps / "rough.png")
    doc = {"model": "mitsuba06:ward", "maps": {"diffuseReflectance": "../elsewhere/secret.png", "alpha": "rough.png"}}
    (maps / "material.json").write_text(json.dumps(doc))
    out = tmp_path / "out"
    args = {
        "convert": ["convert", str(maps), "--to", "mitsuba06:pbr", "--fix", "distribution=ggx", "-o", str(out)],
        "remap": ["remap", str(maps), "--to", "mitsuba06:pbr", "--fix", "distribution=ggx", "-o", str(out)],
        "evaluate": ["evaluate", str(maps), str(maps), "-o", str(out), "--rotations", "0", "--size", "16"],
    }[command]
    code, err = run(capsys, *args)
    assert code == 2 and "'../elsewhere/secret.png'" not in err or "points outside" in err
    assert code == 2 and "points outside" in err and not out.exists(), err
    (tmp_path / "elsewhere" / "secret.png").unlink()  # the same line whether or not the file exists
    assert run(capsys, *args)[1] == err
    png(tmp_path / "elsewhere" / "secret.png")
    code, err = run(capsys, *args, "--allow-path", str(tmp_path / "elsewhere"))
    assert "points outside" not in err


@pytest.mark.parametrize("name", ["../../escaped.gltf", "../escaped.gltf", "ABSOLUTE"])
def test_remap_refuses_a_write_name_outside_the_output_folder(tmp_path, capsys, name):
    work = tmp_path / "a" / "b"
    src = gltf_image(work / "asset", "base.png")
    png(work / "asset" / "base.png")
    if name == "ABSOLUTE":
        name = str(tmp_path / "escaped.gltf")
    out = work / "out"
    code, err = run(capsys, "remap", str(src), "--to", "gltf:metal-rough", "-o", str(out), "--write", name)
    assert code == 2 and "points outside the output folder" in err and "Traceback" not in err
    assert not out.exists()
    assert not list(tmp_path.rglob("escaped.gltf"))


@pytest.mark.parametrize("exists", [True, False])
@pytest.mark.parametrize("key", ["images", "buffers"])
@pytest.mark.parametrize("suffix", [".gltf", ".glb"])
def test_a_gltf_copy_refuses_a_file_outside_that_another_part_names(tmp_path, key, suffix, exists):
    """The reader confines the converted material's textures; a copy of the source also names its other
    images and buffers (a mesh's, another material's): one outside was written into the copy as
    ../secret.png, exit 0. Refused now, the same whether it exists, unless its folder is allowed."""
    from matremap.core.material import Material
    from matremap.formats import write_asset

    secret = png(tmp_path / "secret.png", seed=3) if exists else tmp_path / "secret.png"
    src = gltf_image(tmp_path / "asset", "base.png")
    png(tmp_path / "asset" / "base.png")
    doc = json.loads(src.read_text())
    if key == "images":  # a second material's texture
        doc["images"].append({"uri": "../secret.png"})
        doc["textures"].append({"source": 1})
        doc["materials"].append({"name": "other", "pbrMetallicRoughness": {"baseColorTexture": {"index": 1}}})
    else:  # a buffer no material uses (a mesh's)
        doc["buffers"] = [{"uri": "../secret.png", "byteLength": 8}]
        doc["bufferViews"] = [{"buffer": 0, "byteLength": 8}]
    src.write_text(json.dumps(doc))
    asset = read_asset(src, "m")  # the material itself is inside
    m = Material.create("gltf:metal-rough", {"baseColor": [0.5, 0.4, 0.3], "roughness": 0.5})
    (tmp_path / "out").mkdir()
    with pytest.raises(MatremapError, match=f"{key[:-1]} 1 uri|{key[:-1]} 0 uri") as e:
        write_asset(tmp_path / "out" / f"c{suffix}", m, source=asset)
    assert OUTSIDE in str(e.value) and "'../secret.png'" in str(e.value) and "\n" not in str(e.value)
    assert list((tmp_path / "out").iterdir()) == []
    if exists:
        with allowed_paths([secret.parent]):
            out = write_asset(tmp_path / "out" / f"c{suffix}", m, source=asset)
        assert out.is_file()
