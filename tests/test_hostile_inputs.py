"""Malformed and hostile material files end in one clean MatremapError (issue 19), never a traceback, a
hang or a read of another file; the glTF image cache is private and checked."""

from __future__ import annotations

import base64
import importlib.util
import json
import os
import stat
import struct
from pathlib import Path

import numpy as np
import pytest

from matremap.cli import main
from matremap.core.diskcache import cache_dir, ensure_private, private_cache_dir, save_tables
from matremap.errors import MatremapError
from matremap.formats import read_asset
from matremap.formats.common import MAX_XML_DEPTH
from matremap.formats.gltf import MAX_JSON_DEPTH
from matremap.svbrdf.textures import load_map_set

needs_materialx = pytest.mark.skipif(
    importlib.util.find_spec("MaterialX") is None, reason="MaterialX not installed: pip install 'matremap[materialx]'"
)


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    """A cache of the test's own, named by the documented variable."""
    monkeypatch.setenv("MATREMAP_CACHE", str(tmp_path / "cache"))
    monkeypatch.delenv("MATREMAP_CACHE_DIR", raising=False)
    return tmp_path / "cache"


def png_bytes(seed: int = 0, channels: int = 3) -> bytes:
    from matremap.core.imageio import png_bytes as encode

    rgb = np.random.default_rng(seed).integers(0, 256, (8, 8, channels), dtype=np.uint8)
    return encode(rgb)


MATERIAL = {"name": "m", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}


def glb(json_obj: dict | bytes, bin_chunk: bytes | None = None, version: int = 2, length: int | None = None) -> bytes:
    """GLB bytes (header, JSON chunk, optional BIN chunk); ``length`` overrides the header's."""
    text = json_obj if isinstance(json_obj, bytes) else json.dumps(json_obj).encode()
    text += b" " * (-len(text) % 4)
    body = struct.pack("<II", len(text), 0x4E4F534A) + text
    if bin_chunk is not None:
        b = bin_chunk + b"\0" * (-len(bin_chunk) % 4)
        body += struct.pack("<II", len(b), 0x004E4942) + b
    return b"glTF" + struct.pack("<II", version, 12 + len(body) if length is None else length) + body


def chunks(body: bytes) -> bytes:
    """A GLB header of the right length before the chunk bytes ``body``."""
    return b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body


def glb_with_image(data: bytes, view: dict | None = None, buffer: dict | None = None) -> dict:
    """The JSON of a GLB whose base colour image is buffer view 0 of the BIN chunk ``data``."""
    return {
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": len(data), **(buffer or {})}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": len(data), **(view or {})}],
        "images": [{"bufferView": 0, "mimeType": "image/png"}],
        "textures": [{"source": 0}],
        "materials": [MATERIAL],
    }


def refused(path: Path, match: str) -> str:
    """The one-line MatremapError reading ``path`` gives (it must match ``match``)."""
    with pytest.raises(MatremapError, match=match) as e:
        read_asset(path)
    assert "\n" not in str(e.value)
    return str(e.value)


# -- GLB header and chunks ---------------------------------------------------------------------------

GOOD_JSON = {"asset": {"version": "2.0"}, "materials": [{"name": "m"}]}


@pytest.mark.parametrize(
    "data, match",
    [
        (b"glTF\x02\x00", "truncated"),
        (b"GLTF" + glb(GOOD_JSON)[4:], "'glTF' magic"),
        (glb(GOOD_JSON, version=1), "GLB version 1"),
        (glb(GOOD_JSON, length=10_000), "its header says 10000 bytes"),
        (chunks(struct.pack("<II", 2**32 - 8, 0x4E4F534A) + b"{}  "), "runs past the end"),
        (chunks(struct.pack("<II", 4, 0x004E4942) + b"\0\0\0\0"), "first GLB chunk is not JSON"),
        (glb(b"\xff\xfe{}"), "not UTF-8"),
        (glb(b"[1, 2]"), "JSON object"),
    ],
    ids=["short", "magic", "version", "length-beyond-file", "chunk-length-wraps", "first-chunk-bin", "utf8", "array"],
)
def test_a_broken_glb_header_or_chunk_is_refused(tmp_path, data, match):
    (tmp_path / "m.glb").write_bytes(data)
    refused(tmp_path / "m.glb", match)


@pytest.mark.parametrize(
    "view, buffer, match",
    [
        ({"byteOffset": -4}, None, "byteOffset is -4, not a non-negative integer"),
        ({"byteOffset": "0"}, None, "byteOffset is '0'"),
        ({"byteOffset": 1.5}, None, "byteOffset is 1.5"),
        ({"byteLength": True}, None, "byteLength is True"),
        ({"byteLength": -1}, None, "byteLength is -1"),
        ({"byteLength": None}, None, "byteLength is None"),
        ({"byteOffset": 8, "byteLength": 10**6}, None, "runs past the end of its buffer"),
        ({"buffer": [0]}, None, r"refers to buffers\[\[0\]\]"),
        ({"buffer": 3}, None, r"refers to buffers\[3\], but the file has 1"),
        (None, {"byteLength": "big"}, "byteLength is 'big', not a byte count"),
        (None, {"byteLength": 10**9}, "the file is truncated"),
        (None, {"uri": 7}, r"buffers\[0\].uri is not a string"),
    ],
)
def test_wrong_typed_or_out_of_range_buffer_views_are_refused(tmp_path, view, buffer, match):
    data = png_bytes()
    (tmp_path / "m.glb").write_bytes(glb(glb_with_image(data, view, buffer), data))
    refused(tmp_path / "m.glb", match)


def test_a_good_glb_of_the_same_shape_reads(tmp_path):
    data = png_bytes()
    (tmp_path / "m.glb").write_bytes(glb(glb_with_image(data), data))
    asset = read_asset(tmp_path / "m.glb")
    assert asset.textures["baseColor"].path.read_bytes() == data


@pytest.mark.parametrize(
    "change, match",
    [
        ({"images": [[0]]}, r"images\[0\] is not an object"),
        ({"images": [{"uri": ["a.png"]}]}, r"images\[0\].uri is not a string"),
        ({"textures": [{"source": [0]}]}, r"refers to images\[\[0\]\]"),
        ({"images": [{"bufferView": 0, "mimeType": ["image/png"]}]}, None),  # sniffed from the bytes instead
    ],
)
def test_wrong_typed_image_entries_are_refused_or_read(tmp_path, change, match):
    data = png_bytes()
    (tmp_path / "m.glb").write_bytes(glb({**glb_with_image(data), **change}, data))
    if match is None:
        assert read_asset(tmp_path / "m.glb").textures["baseColor"].path.suffix == ".png"
    else:
        refused(tmp_path / "m.glb", match)


@pytest.mark.parametrize(
    "material, match",
    [
        ({"normalTexture": {"index": 0, "scale": "x"}}, "normalTexture.scale must be a number"),
        ({"extensions": {"KHR_materials_transmission": {"transmissionFactor": "x"}}}, "transmissionFactor must be"),
        ({"extensions": {"KHR_materials_sheen": {"sheenColorFactor": 5}}}, "sheenColorFactor must be 3 numbers"),
        ({"extensions": {"KHR_materials_ior": [1.5]}}, "KHR_materials_ior is not an object"),
    ],
)
def test_wrong_typed_material_members_are_refused(tmp_path, material, match):
    data = png_bytes()
    doc = glb_with_image(data)
    doc["materials"] = [{**MATERIAL, **material}]
    (tmp_path / "m.glb").write_bytes(glb(doc, data))
    refused(tmp_path / "m.glb", match)


def test_a_source_whose_other_parts_are_broken_is_refused_when_written_back(tmp_path):
    """The reader looks at one material; the writer edits the rest of the document, so checks it."""
    from matremap.core.material import Material
    from matremap.formats import write_asset

    data = png_bytes()
    doc = {**glb_with_image(data), "extensionsUsed": 5}
    (tmp_path / "m.glb").write_bytes(glb(doc, data))
    asset = read_asset(tmp_path / "m.glb")
    m = Material.create("gltf:metal-rough", {"roughness": 0.3})
    with pytest.raises(MatremapError, match="extensionsUsed is not an array"):
        write_asset(tmp_path / "o.glb", m, source=asset)
    doc = glb_with_image(data)
    doc["materials"] = [{**MATERIAL, "extensions": None}]
    doc["extensionsRequired"] = None
    (tmp_path / "n.glb").write_bytes(glb(doc, data))
    out = write_asset(tmp_path / "o.glb", m, source=read_asset(tmp_path / "n.glb"))
    assert read_asset(out).constants["roughness"] == pytest.approx(0.3)


# -- data: URIs ----------------------------------------------------------------------------------------


def gltf_text(tmp_path: Path, doc: dict | str) -> Path:
    f = tmp_path / "m.gltf"
    f.write_text(doc if isinstance(doc, str) else json.dumps(doc))
    return f


@pytest.mark.parametrize("payload", ["@@@not-base64@@@", "QUJD=QUJD", "QUJDR", "é"])
def test_a_data_uri_with_bad_base64_is_refused(tmp_path, payload):
    doc = {"asset": {"version": "2.0"}, "images": [{"uri": f"data:image/png;base64,{payload}"}]}
    doc |= {"textures": [{"source": 0}], "materials": [MATERIAL]}
    refused(gltf_text(tmp_path, doc), "not valid base64")
    doc = {"asset": {"version": "2.0"}, "buffers": [{"uri": f"data:;base64,{payload}", "byteLength": 3}]}
    doc |= {"bufferViews": [{"buffer": 0, "byteLength": 3}], "images": [{"bufferView": 0}]}
    doc |= {"textures": [{"source": 0}], "materials": [MATERIAL]}
    refused(gltf_text(tmp_path, doc), r"buffers\[0\] is a data: URI whose base64 payload is not valid")


def test_a_data_uri_with_line_breaks_in_its_base64_still_reads(tmp_path):
    data = png_bytes(seed=4)
    text = base64.b64encode(data).decode()
    wrapped = "\n".join(text[i : i + 60] for i in range(0, len(text), 60))
    doc = {"asset": {"version": "2.0"}, "images": [{"uri": f"data:image/png;base64,{wrapped}"}]}
    doc |= {"textures": [{"source": 0}], "materials": [MATERIAL]}
    assert read_asset(gltf_text(tmp_path, doc)).textures["baseColor"].path.read_bytes() == data


# -- JSON nesting and numbers --------------------------------------------------------------------------


@pytest.mark.parametrize("depth", [100_000, 2_000, MAX_JSON_DEPTH + 1])
def test_json_nested_too_deep_is_refused(tmp_path, depth):
    text = '{"asset": {"version": "2.0"}, "materials": [{}], "extras": ' + "[" * depth + "]" * depth + "}"
    refused(gltf_text(tmp_path, text), f"nests deeper than {MAX_JSON_DEPTH} levels")


def test_json_nested_within_the_limit_reads_and_writes_back(tmp_path):
    from matremap.core.material import Material
    from matremap.formats import write_asset

    depth = MAX_JSON_DEPTH - 3  # asset, materials, extras and the arrays
    text = '{"asset": {"version": "2.0"}, "materials": [{"extras": ' + "[" * depth + "]" * depth + "}]}"
    asset = read_asset(gltf_text(tmp_path, text))
    m = Material.create("gltf:metal-rough", {"roughness": 0.3})
    assert write_asset(tmp_path / "o.gltf", m, source=asset).is_file()


def test_an_integer_of_too_many_digits_is_refused(tmp_path):
    refused(gltf_text(tmp_path, '{"asset": {"version": "2.0"}, "x": ' + "9" * 5000 + "}"), "not valid glTF JSON")


# -- XML ---------------------------------------------------------------------------------------------------

LAUGHS = '<!ENTITY a0 "ha">' + "".join(f'<!ENTITY a{i} "{("&a" + str(i - 1) + ";") * 10}">' for i in range(1, 10))


def mitsuba_attack(tmp_path: Path, attack: str) -> Path:
    (tmp_path / "secret.txt").write_text("0.5, 0.5, 0.5")
    body = '<bsdf type="diffuse" id="d"><rgb name="reflectance" value="{value}"/></bsdf>'
    if attack == "billion-laughs":
        text = f'<?xml version="1.0"?><!DOCTYPE scene [{LAUGHS}]><scene version="3.0.0">'
        text += body.format(value="&a9;") + "</scene>"
    elif attack == "external-entity":
        text = f'<?xml version="1.0"?><!DOCTYPE scene [<!ENTITY x SYSTEM "file://{tmp_path / "secret.txt"}">]>'
        text += '<scene version="3.0.0">' + body.format(value="&x;") + "</scene>"
    else:
        depth = 100_000 if attack == "deep-nesting" else MAX_XML_DEPTH + 1
        text = '<scene version="3.0.0">' + body.format(value="0.5") + "<a>" * depth + "</a>" * depth + "</scene>"
    (tmp_path / "s.xml").write_text(text)
    return tmp_path / "s.xml"


def materialx_attack(tmp_path: Path, attack: str) -> Path:
    (tmp_path / "secret.txt").write_text("0.5, 0.5, 0.5")
    shader = (
        '<gltf_pbr name="s" type="surfaceshader"><input name="base_color" type="color3" value="{value}"/></gltf_pbr>'
        '<surfacematerial name="mat" type="material">'
        '<input name="surfaceshader" type="surfaceshader" nodename="s"/></surfacematerial>'
    )
    if attack == "billion-laughs":
        text = f'<?xml version="1.0"?><!DOCTYPE materialx [{LAUGHS}]><materialx version="1.39">'
        text += shader.format(value="&a9;") + "</materialx>"
    elif attack == "external-entity":
        text = f'<?xml version="1.0"?><!DOCTYPE materialx [<!ENTITY x SYSTEM "file://{tmp_path / "secret.txt"}">]>'
        text += '<materialx version="1.39">' + shader.format(value="&x;") + "</materialx>"
    elif attack == "xinclude":
        text = '<?xml version="1.0"?><materialx version="1.39" xmlns:xi="http://www.w3.org/2001/XInclude">'
        text += f'<xi:include href="{tmp_path / "other.mtlx"}"/>' + shader.format(value="0.5, 0.5, 0.5")
        text += "</materialx>"
        (tmp_path / "other.mtlx").write_text('<?xml version="1.0"?><materialx version="1.39"/>')
    else:
        depth = 100_000 if attack == "deep-nesting" else MAX_XML_DEPTH + 1
        nest = "<nodegraph>" * depth + "</nodegraph>" * depth
        text = '<materialx version="1.39">' + shader.format(value="0.5, 0.5, 0.5") + nest + "</materialx>"
    (tmp_path / "m.mtlx").write_text(text)
    return tmp_path / "m.mtlx"


ATTACKS = {
    "billion-laughs": "declares entities",
    "external-entity": "declares entities",
    "deep-nesting": f"deeper than {MAX_XML_DEPTH} levels",
    "just-too-deep": f"deeper than {MAX_XML_DEPTH} levels",
}


@pytest.mark.parametrize("attack", list(ATTACKS))
def test_the_mitsuba_reader_refuses_xml_attacks(tmp_path, attack):
    refused(mitsuba_attack(tmp_path, attack), ATTACKS[attack])


@needs_materialx
@pytest.mark.parametrize("attack", [*ATTACKS, "xinclude"])
def test_the_materialx_reader_refuses_xml_attacks(tmp_path, attack):
    refused(materialx_attack(tmp_path, attack), ATTACKS.get(attack, "xi:include is not supported"))


@pytest.mark.parametrize("attack", ["billion-laughs", "external-entity"])
def test_the_command_line_refuses_an_xml_attack_with_exit_2_and_no_output(tmp_path, capsys, attack):
    src = mitsuba_attack(tmp_path, attack)
    code = main(["remap", str(src), "--to", "mitsuba06:diffuse", "-o", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and "declares entities" in err and "Traceback" not in err
    assert not (tmp_path / "out").exists()


def test_a_plain_doctype_without_entities_still_reads(tmp_path):
    (tmp_path / "s.xml").write_text(
        '<?xml version="1.0"?><!DOCTYPE scene><scene version="3.0.0">'
        '<bsdf type="diffuse" id="d"><rgb name="reflectance" value="0.2, 0.3, 0.4"/></bsdf></scene>'
    )
    assert read_asset(tmp_path / "s.xml").constants["reflectance"] == [0.2, 0.3, 0.4]


# -- the cache ---------------------------------------------------------------------------------------------


def test_the_cache_folder_honours_both_variables_then_xdg(tmp_path, monkeypatch):
    monkeypatch.setenv("MATREMAP_CACHE_DIR", str(tmp_path / "old"))
    assert cache_dir() == tmp_path / "cache"  # MATREMAP_CACHE first
    monkeypatch.delenv("MATREMAP_CACHE")
    assert cache_dir() == tmp_path / "old"
    monkeypatch.delenv("MATREMAP_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache_dir() == tmp_path / "xdg" / "matremap"
    monkeypatch.setenv("XDG_CACHE_HOME", "relative")  # the spec says to ignore a relative one
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert cache_dir() == tmp_path / "home" / ".cache" / "matremap"


def test_the_cache_is_created_private(private_cache):
    os.umask(old := os.umask(0o022))
    try:
        folder = private_cache_dir("gltf-images", "abc")
    finally:
        os.umask(old)
    for f in (private_cache, private_cache / "gltf-images", folder):
        assert stat.S_IMODE(f.stat().st_mode) == 0o700


def test_a_cache_folder_writable_by_others_is_refused(private_cache):
    private_cache.mkdir()
    os.chmod(private_cache, 0o777)
    with pytest.raises(MatremapError, match="writable by other users"):
        private_cache_dir("gltf-images")
    os.chmod(private_cache, 0o720)
    with pytest.raises(MatremapError, match="writable by other users"):
        ensure_private(private_cache)
    os.chmod(private_cache, 0o755)  # readable by others, as older versions made it: still usable
    assert ensure_private(private_cache) == private_cache


def test_a_cache_folder_of_another_user_is_refused(private_cache, monkeypatch):
    private_cache.mkdir(mode=0o700)
    if os.getuid() == 0:
        os.chown(private_cache, 12345, 12345)
    else:  # only root can give a folder away: pretend to be someone else instead
        monkeypatch.setattr(os, "getuid", lambda: os.stat(private_cache).st_uid + 1)
    with pytest.raises(MatremapError, match="owned by another user"):
        private_cache_dir()


def test_an_unsafe_cache_refuses_extraction_but_tables_are_skipped_silently(tmp_path, private_cache):
    private_cache.mkdir()
    os.chmod(private_cache, 0o777)
    data = png_bytes()
    (tmp_path / "m.glb").write_bytes(glb(glb_with_image(data), data))
    refused(tmp_path / "m.glb", "writable by other users")
    save_tables(private_cache / "t.npz", "t*.npz", a=np.zeros(3))  # an optional table: no error, not written
    assert not (private_cache / "t.npz").exists()
    os.chmod(private_cache, 0o700)
    save_tables(private_cache / "t.npz", "t*.npz", a=np.zeros(3))
    assert (private_cache / "t.npz").is_file()


def test_a_cached_image_is_reused_only_when_its_content_matches_its_digest(tmp_path):
    data = png_bytes(seed=7)
    (tmp_path / "m.glb").write_bytes(glb(glb_with_image(data), data))
    first = read_asset(tmp_path / "m.glb").textures["baseColor"].path
    assert first.read_bytes() == data
    forged = png_bytes(seed=8)[: len(data)].ljust(len(data), b"\0")  # same size, other content
    first.write_bytes(forged)
    again = read_asset(tmp_path / "m.glb").textures["baseColor"].path
    assert again == first and again.read_bytes() == data  # rewritten, not trusted by its size


def test_an_alpha_free_copy_is_reused_only_when_its_content_matches_its_digest(tmp_path):
    data = png_bytes(seed=9, channels=4)
    (tmp_path / "m.glb").write_bytes(glb(glb_with_image(data), data))
    copy = read_asset(tmp_path / "m.glb").textures["baseColor"].path
    good = copy.read_bytes()
    assert copy.name.endswith(".png") and "-rgb-" in copy.name
    copy.write_bytes(good[:-10] + b"\0" * 10)
    again = read_asset(tmp_path / "m.glb").textures["baseColor"].path
    assert again.read_bytes() == good


def test_a_map_set_never_points_into_the_cache(tmp_path, private_cache):
    """An image extracted from a .glb is copied into the map set's folder, which names it relatively."""
    data = png_bytes(seed=5)
    normal = png_bytes(seed=6)
    doc = glb_with_image(data + normal)
    doc["bufferViews"] = [
        {"buffer": 0, "byteOffset": 0, "byteLength": len(data)},
        {"buffer": 0, "byteOffset": len(data), "byteLength": len(normal)},
    ]
    doc["images"].append({"bufferView": 1, "mimeType": "image/png"})
    doc["textures"].append({"source": 1})
    doc["materials"] = [{**MATERIAL, "normalTexture": {"index": 1}}]
    (tmp_path / "m.glb").write_bytes(glb(doc, data + normal))
    asset = read_asset(tmp_path / "m.glb")
    assert asset.textures["baseColor"].extracted and asset.normal is not None and asset.normal.extracted
    out = asset.to_map_set(tmp_path / "maps")
    manifest = (out / "material.json").read_text()
    assert str(private_cache) not in manifest
    ms = load_map_set(out)
    assert ms.maps["baseColor"].parent == out and Path(ms.maps["baseColor"]).read_bytes() == data
    assert Path(ms.normal).parent == out and Path(ms.normal).read_bytes() == normal


def test_a_table_planted_in_a_shared_cache_folder_is_not_read(tmp_path):
    """Numerically integrated tables are read back only from a private folder: a world-writable cache
    folder holding a poisoned table (right name, spec and shape) gets the table rebuilt, not trusted."""
    import subprocess
    import sys

    code = (
        "import numpy as np; from matremap.renderers.embedded.evaluators.cycles import albedo_tables; "
        "print(float(albedo_tables()[1].mean()))"
    )

    def mean_albedo(cache: Path) -> float:
        env = {**os.environ, "MATREMAP_CACHE": str(cache)}
        out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
        return float(out.stdout.strip().splitlines()[-1])

    private = tmp_path / "private"
    honest = mean_albedo(private)
    (table,) = private.glob("cycles_ggx_albedo_*.npz")
    shared = tmp_path / "shared"
    shared.mkdir()
    os.chmod(shared, 0o777)
    with np.load(table, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["E_avg"] = np.full_like(arrays["E_avg"], 0.123)
    np.savez(shared / table.name, **arrays)
    assert mean_albedo(shared) == pytest.approx(honest, rel=1e-9)
    os.chmod(shared, 0o700)  # the same file in a private folder is read: the check is what stopped it
    assert mean_albedo(shared) == pytest.approx(0.123)


@pytest.mark.parametrize("where", [0.1, 0.5, 0.95])
def test_a_damaged_cached_table_is_rebuilt_with_a_note(tmp_path, capsys, where):
    """A cached table's arrays carry their CRC-32 (.npz is a zip): a flipped byte made np.load raise
    BadZipFile, which reached the command line as an internal error (exit 70). Now: a note, and rebuilt."""
    from matremap.core.diskcache import load_tables, private_cache_dir

    path = private_cache_dir() / "t_1.npz"
    save_tables(path, "t_*.npz", spec=np.array("s"), a=np.linspace(0.0, 1.0, 4096))
    good = load_tables(path, "s", {"a": (4096,)})
    assert good is not None and good["a"][-1] == 1.0
    data = bytearray(path.read_bytes())
    data[int(where * len(data))] ^= 0xFF
    path.write_bytes(bytes(data))
    assert load_tables(path, "s", {"a": (4096,)}) is None  # rebuilt by its caller
    err = capsys.readouterr().err
    assert "damaged" in err and "rebuilding it" in err and err.count("\n") == 1
    path.unlink()
    assert load_tables(path, "s", {"a": (4096,)}) is None and capsys.readouterr().err == ""  # missing: silent
