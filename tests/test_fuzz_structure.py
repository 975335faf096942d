"""Fuzzing the XML readers' structure, not only their values: how deep MaterialX node graphs nest (inside
nodegraphs or not), how Mitsuba ``<default>``\\ s build on one another and ``<include>``\\ s fan out, the
names of nodes, files and folders (odd Unicode, bytes that are not UTF-8), byte order marks and declared
encodings, and sizes. Every document is read as ``remap`` reads it; each must give a material or raise a
MatremapError whose message is one short line, never another exception. Budgets are fixed and
derandomized (the same examples every run; about 30 s in all)."""

from __future__ import annotations

import importlib.util
import os
import tempfile
from pathlib import Path
from typing import Any
from unittest import mock
from xml.sax.saxutils import quoteattr

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from matremap.errors import MatremapError
from matremap.formats import material_names, read_asset
from matremap.formats.mitsuba_scene import MAX_INCLUDES
from matremap.formats.mtlx_graph import MAX_DEPTH

STRUCTURE = settings(
    max_examples=150, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck), database=None
)
#: the longest message a refusal may carry (paths of the test's folders included)
MAX_MESSAGE = 1500
needs_materialx = pytest.mark.skipif(
    importlib.util.find_spec("MaterialX") is None, reason="MaterialX not installed: pip install 'matremap[materialx]'"
)

#: names: plain, odd Unicode (combining marks, right-to-left, emoji, the BOM character, NUL-free controls)
odd_text = st.text(
    alphabet=st.characters(blacklist_categories=("Cs",), blacklist_characters="\x00/"), min_size=1, max_size=10
)
names = st.sampled_from(["n", "node_1", "a.b", "é", "\u202eevil", "\u0301x", "\ufeffbom", "x" * 300]) | odd_text
#: file and folder names as bytes: anything but "/" and NUL, including bytes that are not UTF-8
name_bytes = st.binary(min_size=1, max_size=10).filter(lambda b: b"/" not in b and b"\0" not in b) | st.sampled_from(
    [b"plain", b"caf\xe9", b"\xff\xfe", b"sp ace", b"\xc3\xa9t\xc3\xa9"]
)
#: (codec, the encoding an XML declaration names, or None for no declaration)
encodings = st.sampled_from(
    [
        ("utf-8", None),
        ("utf-8", "UTF-8"),
        ("utf-8-sig", None),
        ("utf-8-sig", "UTF-8"),
        ("utf-16", "UTF-16"),
        ("utf-16-le", "UTF-16"),
        ("utf-16-be", "UTF-16"),
        ("utf-32", "UTF-32"),
        ("latin-1", "ISO-8859-1"),
        ("latin-1", None),  # bytes that are not the UTF-8 the missing declaration means
        ("utf-8", "x-unknown"),
    ]
)


def encoded(body: str, codec: str, declared: str | None) -> bytes:
    head = f'<?xml version="1.0" encoding="{declared}"?>\n' if declared else '<?xml version="1.0"?>\n'
    return (head + body).encode(codec, "xmlcharrefreplace")


def placed(root: Path, folder: bytes, stem: bytes, suffix: str) -> Path:
    """A file path in folder ``folder`` (bytes, made) under ``root``, named ``stem`` + ``suffix``."""
    if folder in (b".", b".."):
        folder = b"_" + folder
    if stem in (b".", b".."):
        stem = b"_" + stem
    where = os.fsencode(root) + b"/" + folder
    os.makedirs(where, exist_ok=True)
    return Path(os.fsdecode(where + b"/" + stem + suffix.encode()))


def outcome(read: Any) -> Any:
    """``read()``'s result, or None for a refusal, which must be a MatremapError of one short line."""
    try:
        return read()
    except MatremapError as e:
        message = str(e)
        assert len(message) <= MAX_MESSAGE, message[:300]
        return None


def read_all(path: Path) -> None:
    """Every material of ``path`` as ``remap`` reads it: its textures baked, or its uniform values."""

    def read() -> None:
        for name in material_names(path)[:3]:
            asset = read_asset(path, name)
            for ref in [*asset.textures.values(), asset.normal]:
                if ref is not None and ref.bake is not None:
                    ref.bake()
            if not asset.textured:
                asset.material()

    outcome(read)


# -- MaterialX: graphs of any depth, in nodegraphs, odd names, encodings, sizes -----------------------

#: node categories a chain may hold: (category, the input the chain continues through, other inputs)
LINKS = [
    ("add", "in1", '<input name="in2" type="color3" value="0.01, 0.01, 0.01"/>'),
    ("multiply", "in1", '<input name="in2" type="color3" value="0.9, 0.9, 0.9"/>'),
    ("max", "in2", '<input name="in1" type="color3" value="0, 0, 0"/>'),
    ("clamp", "in", ""),
    ("dot", "in", ""),
    ("mix", "fg", '<input name="bg" type="color3" value="0.5, 0.5, 0.5"/><input name="mix" type="float" value="0.5"/>'),
    ("switch", "in1", '<input name="which" type="float" value="0"/>'),
    ("hsvtorgb", "in", ""),
    ("no_such_node", "in", ""),
]
leaves = st.sampled_from(["constant", "texcoord", "image", "missing image", "fifo image", "folder image"])


@st.composite
def materialx_documents(draw: Any) -> tuple[str, str]:
    """(document text, leaf kind): a chain of nodes of any depth under a shader input, maybe in a nodegraph."""
    depth = draw(st.integers(1, 30) | st.sampled_from([MAX_DEPTH - 3, MAX_DEPTH + 2]))
    kinds = draw(st.lists(st.sampled_from(range(len(LINKS))), min_size=1, max_size=4))
    leaf = draw(leaves)
    weird = draw(st.booleans())
    label = [draw(names) if weird else f"n{i}" for i in range(min(depth, 5))]

    def name(i: int) -> str:
        return label[i] + (str(i) if i >= len(label) else "") if i < len(label) else f"n{i}"

    value = draw(st.sampled_from(["0.2, 0.3, 0.4", "1e400, 0, 0", "0.5", "x" * draw(st.integers(0, 100_000))]))
    if leaf == "constant":
        nodes = [
            f'<constant name={quoteattr(name(0))} type="color3"><input name="value" type="color3" value="{value}"/>'
        ]
        nodes[0] += "</constant>"
    elif leaf == "texcoord":
        nodes = [
            f'<texcoord name="uv" type="vector2"/><convert name={quoteattr(name(0))} type="color3">'
            '<input name="in" type="vector2" nodename="uv"/></convert>'
        ]
    else:
        nodes = [
            f'<image name={quoteattr(name(0))} type="color3"><input name="file" type="filename" value="tex.png"/>'
            "</image>"
        ]
    for i in range(1, depth):
        category, through, other = LINKS[kinds[i % len(kinds)]]
        typ = ' type="color3"'
        nodes.append(
            f"<{category} name={quoteattr(name(i))}{typ}><input name={quoteattr(through)} type="
            f'"color3" nodename={quoteattr(name(i - 1))}/>{other}</{category}>'
        )
    last = quoteattr(name(depth - 1))
    if draw(st.booleans()):  # the chain inside a nodegraph, the shader connected to its output
        graph = draw(st.sampled_from(["g", "graph é", "\ufeffg"]))
        body = (
            f"<nodegraph name={quoteattr(graph)}>{''.join(nodes)}"
            f'<output name="out" type="color3" nodename={last}/></nodegraph>'
        )
        connection = f'nodegraph={quoteattr(graph)} output="out"'
    else:
        body, connection = "".join(nodes), f"nodename={last}"
    text = (
        f'<materialx version="1.39">{body}<standard_surface name="s" type="surfaceshader">'
        f'<input name="base_color" type="color3" {connection}/></standard_surface>'
        '<surfacematerial name="mat" type="material"><input name="surfaceshader" type="surfaceshader" nodename="s"/>'
        "</surfacematerial></materialx>\n"
    )
    return text, leaf


@needs_materialx
@STRUCTURE
@given(materialx_documents(), encodings, name_bytes, name_bytes)
def test_fuzz_materialx_structure(document, encoding, folder, stem):
    import numpy as np

    from matremap.core.imageio import png_bytes

    text, leaf = document
    # a graph varying without images is baked at a small side here: the structure is fuzzed, not the size
    with tempfile.TemporaryDirectory() as d, mock.patch("matremap.formats.mtlx_graph.PROCEDURAL_SIDE", 32):
        path = placed(Path(d), folder, stem, ".mtlx")
        path.write_bytes(encoded(text, *encoding))
        texture = path.parent / "tex.png"
        if leaf == "image":
            texture.write_bytes(png_bytes(np.full((2, 3, 3), 128, np.uint8)))
        elif leaf == "fifo image":
            os.mkfifo(texture)
        elif leaf == "folder image":
            texture.mkdir()
        read_all(path)


# -- Mitsuba XML: defaults built on defaults, includes fanning out, odd names, encodings ----------------


@st.composite
def mitsuba_scenes(draw: Any) -> dict[str, Any]:
    """A scene: ``levels`` defaults each repeating the one before ``fan`` times, used ``uses`` times; a chain
    of ``depth`` included files each including the next ``spread`` times (maybe back to the first: a cycle);
    a bitmap that is a file, missing, a FIFO or a folder; names of odd Unicode."""
    return {
        "levels": draw(st.integers(0, 30)),
        "fan": draw(st.integers(1, 3)),
        "base": draw(st.sampled_from(["0.5", "0.5 ", "\\$x", "$", "x" * 1000])),
        "uses": draw(st.integers(0, 40)),
        "depth": draw(st.integers(0, 7)),
        "spread": draw(st.integers(1, 8)),
        "cycle": draw(st.booleans()),
        "include_name": draw(names).replace("/", "_").replace("\x00", "_").lstrip(".") or "i",
        "bitmap": draw(st.sampled_from(["file", "missing", "fifo", "folder", "none"])),
    }


@STRUCTURE
@given(mitsuba_scenes(), encodings, name_bytes)
def test_fuzz_mitsuba_structure(scene, encoding, folder):
    import numpy as np

    from matremap.core.imageio import png_bytes

    with tempfile.TemporaryDirectory() as d:
        main = placed(Path(d), folder, b"scene", ".xml")
        where = main.parent
        defaults = f'<default name="d0" value={quoteattr(scene["base"])}/>' + "".join(
            f'<default name="d{i}" value="{f"$d{i - 1}" * scene["fan"]}"/>' for i in range(1, scene["levels"] + 1)
        )
        top = f"$d{scene['levels']}"
        uses = "".join(f'<string name="s{i}" value="{top}"/>' for i in range(scene["uses"]))
        bitmap = ""
        if scene["bitmap"] != "none":
            bitmap = '<texture type="bitmap" name="reflectance"><string name="filename" value="tex.png"/></texture>'
            tex = where / "tex.png"
            if scene["bitmap"] == "file":
                tex.write_bytes(png_bytes(np.full((2, 2, 3), 100, np.uint8)))
            elif scene["bitmap"] == "fifo":
                os.mkfifo(tex)
            elif scene["bitmap"] == "folder":
                tex.mkdir()
        include = ""
        if scene["depth"]:
            stem = scene["include_name"][:40]
            files = [f"{stem}{i}.xml" for i in range(scene["depth"])]
            for i, name in enumerate(files):
                following = files[i + 1] if i + 1 < len(files) else (files[0] if scene["cycle"] else None)
                inner = (
                    f"<include filename={quoteattr(following)}/>" * scene["spread"]
                    if following
                    else '<bsdf type="diffuse" id="inc"/>'
                )
                (where / name).write_bytes(encoded(f'<scene version="3.0.0">{inner}</scene>', *encoding))
            include = f"<include filename={quoteattr(files[0])}/>"
        body = (
            f'<scene version="3.0.0">{defaults}{include}<bsdf type="diffuse" id="main">{bitmap}{uses}</bsdf>'
            f'<bsdf type="roughconductor"><float name="alpha" value="{top}"/></bsdf></scene>'
        )
        main.write_bytes(encoded(body, *encoding))
        read_all(main)


def test_the_bounds_the_fuzzing_reaches():
    """The strategies above reach past the bounds they test (so the bounds are fuzzed, not only below them)."""
    assert 2 * 8**6 > MAX_INCLUDES  # spread 8 over 7 files
    assert len("0.5 ") * 3**30 > 1 << 24  # 30 levels of fan 3
