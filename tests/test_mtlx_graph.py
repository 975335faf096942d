"""MaterialX node graphs evaluated onto maps (formats/mtlx_graph.py), node by node, against values computed
by hand on tiny images written here: UV convention (lower-left origin), tiling, place2d in both operation
orders, gltf_image's top-left pivot, address modes, filter types, arithmetic, channels, conversions, HSV,
normal maps, interface inputs, colour-space inheritance, the map size a graph asks for, and the clean
refusal of nodes it cannot evaluate."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

mx = pytest.importorskip("MaterialX", reason="MaterialX not installed: pip install 'matremap[materialx]'")

from matremap.errors import MatremapError  # noqa: E402
from matremap.formats.materialx import read  # noqa: E402
from matremap.formats.mtlx_document import parse_document  # noqa: E402
from matremap.formats.mtlx_graph import MAX_SIDE, GraphEvaluator, hsv_to_rgb, rgb_to_hsv  # noqa: E402
from matremap.svbrdf.textures import ImageInfo, read_image, write_image_like  # noqa: E402


def exr(path: Path, values: np.ndarray) -> Path:
    v = np.asarray(values, dtype=np.float32)
    v = v[..., None] if v.ndim == 2 else v
    return write_image_like(path, v, ImageInfo("exr", "float", v.shape[-1], 0, 0, "linear"), force=True)


def document(tmp_path: Path, body: str, version: str = "1.39") -> Path:
    p = tmp_path / "g.mtlx"
    p.write_text(
        f'<?xml version="1.0"?>\n<materialx version="{version}" colorspace="lin_rec709">\n{body}\n</materialx>\n'
    )
    return p


def shader_doc(tmp_path: Path, graph: str, base: str = "out", rough: str | None = None) -> Path:
    """A document whose standard_surface takes base_color (and specular_roughness) from nodegraph NG."""
    rough_in = (
        f'<input name="specular_roughness" type="float" nodegraph="NG" output="{rough}"/>' if rough is not None else ""
    )
    return document(
        tmp_path,
        f"""<nodegraph name="NG">{graph}</nodegraph>
  <standard_surface name="SS" type="surfaceshader">
    <input name="base_color" type="color3" nodegraph="NG" output="{base}"/>{rough_in}
  </standard_surface>
  <surfacematerial name="M" type="material"><input name="surfaceshader" type="surfaceshader" nodename="SS"/>
  </surfacematerial>""",
    )


def evaluate(path: Path, input_name: str = "base_color", typ: str = "color3", size: tuple[int, int] | None = None):
    """(analysis, baked values) of a shader input of the document, evaluated directly."""
    doc = parse_document(path)
    shader = doc.getNode("SS")
    ev = GraphEvaluator(doc, path, lambda text, what: (path.parent / text).resolve(), [])
    inp = shader.getInput(input_name)

    def root():
        return ev.port(inp, typ, ev.doc_scope)

    analysis = ev.analyse(root, input_name)
    if analysis.constant is not None:
        return analysis, analysis.constant
    return analysis, ev.bake(root, input_name, size or analysis.size)


IMG = np.array(
    [[[0.1, 0.2, 0.3], [0.4, 0.5, 0.6]], [[0.7, 0.8, 0.9], [0.15, 0.25, 0.35]]], dtype=np.float32
)  # 2x2, row 0 on top


def test_texcoord_has_its_origin_at_the_lower_left(tmp_path):
    """MaterialX 1.39 §image: "the lower-left corner of an image mapping to the (0,0) UV coordinate"."""
    exr(tmp_path / "a.exr", IMG)  # gives the graph a size: 2x2
    p = shader_doc(
        tmp_path,
        """<image name="i" type="color3"><input name="file" type="filename" value="a.exr"/></image>
    <texcoord name="uv" type="vector2"/>
    <combine3 name="c" type="color3"><input name="in1" type="float" nodename="sep" output="outx"/>
      <input name="in2" type="float" nodename="sep" output="outy"/>
      <input name="in3" type="float" nodename="ext" /></combine3>
    <separate2 name="sep" type="multioutput"><input name="in" type="vector2" nodename="uv"/></separate2>
    <extract name="ext" type="float"><input name="in" type="color3" nodename="i"/>
      <input name="index" type="integer" value="2"/></extract>
    <output name="out" type="color3" nodename="c"/>""",
    )
    a, v = evaluate(p, size=(2, 2))
    assert a.size == (2, 2)
    np.testing.assert_allclose(v[..., 0], [[0.25, 0.75], [0.25, 0.75]])  # u grows to the right
    np.testing.assert_allclose(v[..., 1], [[0.75, 0.75], [0.25, 0.25]])  # v grows upwards: row 0 is the top
    np.testing.assert_allclose(v[..., 2], IMG[..., 2], atol=1e-6)  # the image itself, unflipped


def test_tiledimage_tiles_from_the_lower_left_with_its_offset(tmp_path):
    img = np.arange(4 * 4 * 3, dtype=np.float32).reshape(4, 4, 3) / 48.0
    exr(tmp_path / "t.exr", img)
    p = shader_doc(
        tmp_path,
        """<tiledimage name="t" type="color3"><input name="file" type="filename" value="t.exr"/>
      <input name="uvtiling" type="vector2" value="2, 3"/><input name="uvoffset" type="vector2" value="0.25, 0"/>
    </tiledimage><output name="out" type="color3" nodename="t"/>""",
    )
    a, v = evaluate(p)
    assert a.size == (12, 8)  # 4 texels x 3 tiles high, x 2 tiles wide: every texel kept
    # u' = 2u - 0.25 lands on texel centres one texel to the left: a roll by one; v' = 3v tiles rows exactly
    np.testing.assert_allclose(v, np.tile(np.roll(img, 1, axis=1), (3, 2, 1)), atol=1e-6)


def test_gltf_image_scales_about_the_top_left_and_tiledimage_about_the_bottom_left(tmp_path):
    rows = np.array([[[0.2]], [[0.8]]], dtype=np.float32)  # 2 rows, 1 column
    exr(tmp_path / "r.exr", rows)
    for node, inputs, want in [
        ("gltf_image", '<input name="scale" type="vector2" value="1, 1.5"/>', [0.2, 0.8, 0.2]),
        ("tiledimage", '<input name="uvtiling" type="vector2" value="1, 1.5"/>', [0.8, 0.2, 0.8]),
    ]:
        p = shader_doc(
            tmp_path,
            f"""<{node} name="t" type="float"><input name="file" type="filename" value="r.exr"/>{inputs}</{node}>
    <output name="r" type="float" nodename="t"/><constant name="k" type="color3"/><output name="out" type="color3"
     nodename="k"/>""",
            rough="r",
        )
        a, v = evaluate(p, "specular_roughness", "float")
        assert a.size == (3, 1), node
        np.testing.assert_allclose(v[:, 0, 0], want, atol=1e-6, err_msg=node)


def place2d_doc(tmp_path: Path, inputs: str) -> Path:
    return shader_doc(
        tmp_path,
        f"""<texcoord name="uv" type="vector2"/>
    <place2d name="p" type="vector2"><input name="texcoord" type="vector2" nodename="uv"/>{inputs}</place2d>
    <convert name="c" type="color3"><input name="in" type="vector2" nodename="p"/></convert>
    <image name="i" type="color3"><input name="file" type="filename" value="a.exr"/></image>
    <output name="out" type="color3" nodename="c"/><output name="img" type="color3" nodename="i"/>""",
    )


@pytest.mark.parametrize(
    "inputs, formula",
    [
        # stdlib_ng.mtlx NG_place2d_vector2, SRT: ((uv - pivot) / scale) rotated, - offset, + pivot
        (
            '<input name="pivot" type="vector2" value="0.5, 0.5"/><input name="scale" type="vector2" value="2, 4"/>'
            '<input name="offset" type="vector2" value="0.1, 0.2"/>',
            lambda u, v: ((u - 0.5) / 2 - 0.1 + 0.5, (v - 0.5) / 4 - 0.2 + 0.5),
        ),
        # TRS: rotate2d(uv - pivot - offset) / scale + pivot
        (
            '<input name="pivot" type="vector2" value="0.5, 0.5"/><input name="scale" type="vector2" value="2, 4"/>'
            '<input name="offset" type="vector2" value="0.1, 0.2"/><input name="operationorder" type="integer" '
            'value="1"/>',
            lambda u, v: ((u - 0.5 - 0.1) / 2 + 0.5, (v - 0.5 - 0.2) / 4 + 0.5),
        ),
        # rotate2d by 90 degrees as MaterialX's library code does it: (x, y) -> (c x + s y, -s x + c y) = (y, -x)
        ('<input name="rotate" type="float" value="90"/>', lambda u, v: (v, -u)),
    ],
)
def test_place2d_follows_the_library_definition(tmp_path, inputs, formula):
    exr(tmp_path / "a.exr", IMG)
    p = place2d_doc(tmp_path, inputs)
    _, v = evaluate(p, size=(4, 4))
    s, t = np.meshgrid((np.arange(4) + 0.5) / 4, (np.arange(4) + 0.5) / 4)
    u_want, v_want = formula(s, 1.0 - t)
    np.testing.assert_allclose(v[..., 0], u_want, atol=1e-12)
    np.testing.assert_allclose(v[..., 1], v_want, atol=1e-12)
    np.testing.assert_allclose(v[..., 2], 0.0)  # convert vector2 -> color3 pads with 0


@pytest.mark.parametrize(
    "mode, want",
    [
        ("periodic", [0.1, 0.9, 0.1, 0.9]),
        ("clamp", [0.1, 0.9, 0.9, 0.9]),
        ("mirror", [0.1, 0.9, 0.9, 0.1]),
        ("constant", [0.1, 0.9, 0.5, 0.5]),  # the node's default outside [0, 1]
    ],
)
def test_address_modes(tmp_path, mode, want):
    exr(tmp_path / "x.exr", np.array([[[0.1], [0.9]]], dtype=np.float32))  # 1 row, 2 columns
    p = shader_doc(
        tmp_path,
        f"""<texcoord name="uv" type="vector2"/>
    <place2d name="p" type="vector2"><input name="texcoord" type="vector2" nodename="uv"/>
      <input name="scale" type="vector2" value="0.5, 1"/></place2d>
    <image name="i" type="float"><input name="file" type="filename" value="x.exr"/>
      <input name="texcoord" type="vector2" nodename="p"/><input name="default" type="float" value="0.5"/>
      <input name="uaddressmode" type="string" value="{mode}"/></image>
    <output name="r" type="float" nodename="i"/><constant name="k" type="color3"/>
    <output name="out" type="color3" nodename="k"/>""",
        rough="r",
    )
    a, v = evaluate(p, "specular_roughness", "float")
    assert a.size == (1, 4)  # u' = 2u: the image is sampled twice across
    np.testing.assert_allclose(v[0, :, 0], want, atol=1e-6)


def test_filter_types(tmp_path):
    exr(tmp_path / "x.exr", np.array([[[0.0], [1.0]]], dtype=np.float32))
    body = """<image name="i" type="float"><input name="file" type="filename" value="x.exr"/>{f}</image>
    <output name="r" type="float" nodename="i"/><constant name="k" type="color3"/>
    <output name="out" type="color3" nodename="k"/>"""
    # 3 output texels over a 2-texel image: lookups at u = 1/6, 1/2, 5/6, periodic
    _, linear = evaluate(shader_doc(tmp_path, body.format(f=""), rough="r"), "specular_roughness", "float", (1, 3))
    np.testing.assert_allclose(linear[0, :, 0], [1 / 6, 0.5, 5 / 6], atol=1e-6)
    closest = '<input name="filtertype" type="string" value="closest"/>'
    _, near = evaluate(shader_doc(tmp_path, body.format(f=closest), rough="r"), "specular_roughness", "float", (1, 3))
    np.testing.assert_allclose(near[0, :, 0], [0.0, 1.0, 1.0])


def arithmetic_doc(tmp_path: Path, node: str) -> Path:
    exr(tmp_path / "a.exr", IMG)
    exr(tmp_path / "b.exr", np.array([[0.5, 2.0], [0.25, 0.0]], dtype=np.float32))
    return shader_doc(
        tmp_path,
        f"""<image name="A" type="color3"><input name="file" type="filename" value="a.exr"/></image>
    <image name="B" type="float"><input name="file" type="filename" value="b.exr"/></image>
    {node}<output name="out" type="color3" nodename="n"/>""",
    )


B = np.array([[0.5, 2.0], [0.25, 0.0]])[..., None]
A = IMG.astype(np.float64)


@pytest.mark.parametrize(
    "node, want",
    [
        (
            '<add name="n" type="color3"><input name="in1" type="color3" nodename="A"/>'
            '<input name="in2" type="color3" value="0.1, 0.2, 0.3"/></add>',
            A + [0.1, 0.2, 0.3],
        ),
        (
            '<subtract name="n" type="color3"><input name="in1" type="color3" nodename="A"/>'
            '<input name="in2" type="float" nodename="B"/></subtract>',
            A - B,
        ),
        (
            '<multiply name="n" type="color3"><input name="in1" type="color3" nodename="A"/>'
            '<input name="in2" type="float" nodename="B"/></multiply>',
            A * B,
        ),
        (
            '<divide name="n" type="color3"><input name="in1" type="color3" nodename="A"/>'
            '<input name="in2" type="float" value="4"/></divide>',
            A / 4,
        ),
        (
            '<max name="n" type="color3"><input name="in1" type="color3" nodename="A"/>'
            '<input name="in2" type="float" value="0.5"/></max>',
            np.maximum(A, 0.5),
        ),
        (
            '<min name="n" type="color3"><input name="in1" type="color3" nodename="A"/>'
            '<input name="in2" type="float" value="0.5"/></min>',
            np.minimum(A, 0.5),
        ),
        (
            '<mix name="n" type="color3"><input name="fg" type="color3" value="1, 0, 0"/>'
            '<input name="bg" type="color3" nodename="A"/><input name="mix" type="float" nodename="B"/></mix>',
            [1, 0, 0] * B + A * (1 - B),
        ),  # "Fm + B(1-m)"
        (
            '<clamp name="n" type="color3"><input name="in" type="color3" nodename="m"/>'
            '<input name="low" type="float" value="0.1"/><input name="high" type="float" value="0.6"/></clamp>'
            '<multiply name="m" type="color3"><input name="in1" type="color3" nodename="A"/>'
            '<input name="in2" type="float" nodename="B"/></multiply>',
            np.clip(A * B, 0.1, 0.6),
        ),
        ('<dot name="n" type="color3"><input name="in" type="color3" nodename="A"/></dot>', A),
        (
            '<convert name="n" type="color3"><input name="in" type="float" nodename="B"/></convert>',
            np.repeat(B, 3, axis=-1),
        ),  # a scalar fills every channel
        (
            '<combine3 name="n" type="color3"><input name="in1" type="float" nodename="B"/>'
            '<input name="in2" type="float" nodename="s" output="outb"/><input name="in3" type="float" value="0.3"/>'
            '</combine3><separate3 name="s" type="multioutput"><input name="in" type="color3" nodename="A"/>'
            "</separate3>",
            np.concatenate([B, A[..., 2:3], np.full_like(B, 0.3)], axis=-1),
        ),
        (
            '<convert name="n" type="color3"><input name="in" type="color4" nodename="c4"/></convert>'
            '<combine2 name="c4" type="color4"><input name="in1" type="color3" nodename="A"/>'
            '<input name="in2" type="float" nodename="B"/></combine2>',
            A,
        ),  # color4 -> color3 drops alpha
        (
            '<convert name="n" type="color3"><input name="in" type="vector4" nodename="c4"/></convert>'
            '<combine4 name="c4" type="vector4"><input name="in1" type="float" nodename="B"/>'
            '<input name="in2" type="float" nodename="e"/><input name="in3" type="float" value="0.5"/>'
            '<input name="in4" type="float" value="0.9"/></combine4><extract name="e" type="float">'
            '<input name="in" type="color3" nodename="A"/><input name="index" type="integer" value="1"/></extract>',
            np.concatenate([B, A[..., 1:2], np.full_like(B, 0.5)], axis=-1),
        ),
        (
            '<convert name="n" type="color3"><input name="in" type="vector3" nodename="d"/></convert>'
            '<dotproduct name="dp" type="float"><input name="in1" type="vector3" nodename="v"/>'
            '<input name="in2" type="vector3" value="1, 2, 3"/></dotproduct><convert name="v" type="vector3">'
            '<input name="in" type="color3" nodename="A"/></convert><convert name="d" type="vector3">'
            '<input name="in" type="float" nodename="dp"/></convert>',
            np.repeat((A * [1, 2, 3]).sum(-1, keepdims=True), 3, axis=-1),
        ),
        (
            '<switch name="n" type="color3"><input name="in1" type="color3" value="1, 1, 1"/>'
            '<input name="in2" type="color3" nodename="A"/><input name="which" type="float" value="1.7"/></switch>',
            A,
        ),
    ],
)
def test_arithmetic_and_channel_nodes(tmp_path, node, want):
    a, v = evaluate(arithmetic_doc(tmp_path, node))
    assert a.size == (2, 2) and a.constant is None
    np.testing.assert_allclose(v, np.broadcast_to(want, v.shape), atol=1e-6)


def test_hsv_conversions_by_hand():
    rgb = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 0.5], [0.5, 0.5, 0.5], [1, 0.5, 0]], dtype=float)
    hsv = np.array([[0, 1, 1], [1 / 3, 1, 1], [2 / 3, 1, 0.5], [0, 0, 0.5], [1 / 12, 1, 1]], dtype=float)
    np.testing.assert_allclose(rgb_to_hsv(rgb), hsv, atol=1e-12)
    np.testing.assert_allclose(hsv_to_rgb(hsv), rgb, atol=1e-12)
    np.testing.assert_allclose(hsv_to_rgb(np.array([[1.25, 1, 1]])), [[0.5, 1, 0]], atol=1e-12)  # hue wraps


def test_a_graph_of_constants_folds_into_a_value(tmp_path):
    p = shader_doc(
        tmp_path,
        """<constant name="k" type="color3"><input name="value" type="color3" value="1, 0.5, 0"/></constant>
    <rgbtohsv name="h" type="color3"><input name="in" type="color3" nodename="k"/></rgbtohsv>
    <add name="a" type="color3"><input name="in1" type="color3" nodename="h"/>
      <input name="in2" type="color3" value="0.5, 0, -0.5"/></add>
    <hsvtorgb name="n" type="color3"><input name="in" type="color3" nodename="a"/></hsvtorgb>
    <output name="out" type="color3" nodename="n"/>""",
    )
    a = read(p)
    assert "base_color" not in a.textures
    # hue 1/12 + 0.5 = 7/12 (azure), value 1 - 0.5: (0, 0.25, 0.5) (read into the shader's own model, base weight apart)
    np.testing.assert_allclose(a.constants["base_color"], [0.0, 0.25, 0.5], atol=1e-12)
    assert any("same everywhere" in n for n in a.notes)


def test_interface_inputs_fileprefix_and_colorspace_inheritance(tmp_path):
    (tmp_path / "tex").mkdir()
    from matremap.svbrdf.textures import ImageInfo as Info

    code = np.array([[[0.5, 0.25, 1.0]]], dtype=np.float32)
    write_image_like(tmp_path / "tex" / "c.png", code, Info("png", "uint8", 3, 0, 0, "srgb"), force=True)
    p = document(
        tmp_path,
        """<nodegraph name="NG" fileprefix="tex/" colorspace="srgb_texture">
    <input name="tint" type="color3" value="0.5, 1, 2"/>
    <image name="i" type="color3"><input name="file" type="filename" value="c.png"/></image>
    <multiply name="m" type="color3"><input name="in1" type="color3" nodename="i"/>
      <input name="in2" type="color3" interfacename="tint"/></multiply>
    <output name="out" type="color3" nodename="m"/></nodegraph>
  <standard_surface name="SS" type="surfaceshader"><input name="base_color" type="color3" nodegraph="NG" output="out"/>
    <input name="base" type="float" value="0.5"/></standard_surface>
  <surfacematerial name="M" type="material"><input name="surfaceshader" type="surfaceshader" nodename="SS"/>
  </surfacematerial>""",
    )
    a = read(p)
    ref = a.textures["base_color"]
    decoded, _ = read_image(tmp_path / "tex" / "c.png", "srgb")  # the graph's colorspace, inherited
    np.testing.assert_allclose(ref.bake()[0, 0] * np.asarray(ref.scale), decoded[0, 0] * [0.5, 1, 2], atol=1e-6)
    assert a.constants["base"] == 0.5  # the base weight is Standard Surface's own parameter


def test_normalmap_scale_and_a_plain_normal_map(tmp_path):
    enc = np.array([[[0.75, 0.5, 0.9]]], dtype=np.float32)
    exr(tmp_path / "n.exr", enc)
    body = """<image name="img" type="vector3"><input name="file" type="filename" value="n.exr"/></image>
  <normalmap name="nm" type="vector3"><input name="in" type="vector3" nodename="img"/>{scale}</normalmap>
  <standard_surface name="SS" type="surfaceshader"><input name="normal" type="vector3" nodename="nm"/>
  </standard_surface>
  <surfacematerial name="M" type="material"><input name="surfaceshader" type="surfaceshader" nodename="SS"/>
  </surfacematerial>"""
    plain = read(document(tmp_path, body.format(scale="")))
    assert (
        plain.normal is not None and plain.normal.bake is None and plain.normal.path == (tmp_path / "n.exr").resolve()
    )
    scaled = read(document(tmp_path, body.format(scale='<input name="scale" type="float" value="0.5"/>')))
    n = enc[0, 0] * 2 - 1
    n = np.array([n[0] * 0.5, n[1] * 0.5, n[2]])
    want = n / np.linalg.norm(n) * 0.5 + 0.5  # Standard Nodes 1.39 §normalmap: scale multiplies x and y
    assert scaled.normal is not None
    np.testing.assert_allclose(scaled.normal.bake()[0, 0], want, atol=1e-6)


def test_a_swizzle_of_an_older_document_is_read_through_its_upgrade(tmp_path):
    exr(tmp_path / "orm.exr", IMG)
    p = document(
        tmp_path,
        """<image name="orm" type="color3"><input name="file" type="filename" value="orm.exr"/></image>
  <swizzle name="g" type="float"><input name="in" type="color3" nodename="orm"/>
    <input name="channels" type="string" value="g"/></swizzle>
  <swizzle name="bgr" type="color3"><input name="in" type="color3" nodename="orm"/>
    <input name="channels" type="string" value="bgr"/></swizzle>
  <standard_surface name="SS" type="surfaceshader"><input name="specular_roughness" type="float" nodename="g"/>
    <input name="base_color" type="color3" nodename="bgr"/><input name="base" type="float" value="1"/>
  </standard_surface>
  <surfacematerial name="M" type="material"><input name="surfaceshader" type="surfaceshader" nodename="SS"/>
  </surfacematerial>""",
        version="1.38",
    )
    a = read(p)
    rough = a.textures["specular_roughness"]
    assert rough.channels == (1,) and rough.bake is None  # the file as it is
    np.testing.assert_allclose(a.textures["base_color"].bake(), IMG[..., ::-1], atol=1e-6)


def test_maps_of_one_material_are_brought_to_one_size(tmp_path):
    exr(tmp_path / "small.exr", IMG)
    exr(tmp_path / "big.exr", np.full((4, 4, 1), 0.4, np.float32))
    p = document(
        tmp_path,
        """<image name="s" type="color3"><input name="file" type="filename" value="small.exr"/></image>
  <image name="b" type="float"><input name="file" type="filename" value="big.exr"/></image>
  <standard_surface name="SS" type="surfaceshader"><input name="base_color" type="color3" nodename="s"/>
    <input name="specular_roughness" type="float" nodename="b"/><input name="base" type="float" value="1"/>
  </standard_surface>
  <surfacematerial name="M" type="material"><input name="surfaceshader" type="surfaceshader" nodename="SS"/>
  </surfacematerial>""",
    )
    a = read(p)
    assert a.textures["specular_roughness"].bake is None  # already the largest: used as it is
    base = a.textures["base_color"].bake()
    assert base.shape == (4, 4, 3)
    # resampled bilinearly with periodic wrap: each source texel weighs the same, so the mean is kept
    np.testing.assert_allclose(base.mean(axis=(0, 1)), IMG.mean(axis=(0, 1)), atol=1e-6)
    assert base.min() >= IMG.min() - 1e-6 and base.max() <= IMG.max() + 1e-6
    a.to_map_set(tmp_path / "ms")  # one size: no "different sizes" refusal


def test_a_tiling_past_the_cap_is_capped_and_said(tmp_path):
    exr(tmp_path / "a.exr", IMG)
    p = shader_doc(
        tmp_path,
        """<tiledimage name="t" type="color3"><input name="file" type="filename" value="a.exr"/>
      <input name="uvtiling" type="vector2" value="5000, 3"/></tiledimage><output name="out" type="color3"
      nodename="t"/>""",
    )
    a, _ = evaluate(p, size=(1, 1))
    assert a.size == (6, MAX_SIDE) and a.capped
    notes = read(p).notes
    assert any(f"onto a {MAX_SIDE}x6 map" in n and "10000x6 texels (tiling)" in n and "capped" in n for n in notes)


@pytest.mark.parametrize(
    "graph, words",
    [
        (
            '<noise2d name="nz" type="color3"/><output name="out" type="color3" nodename="nz"/>',
            "base_color is fed by a 'noise2d' node ('nz' in nodegraph 'NG'",
        ),
        (
            '<position name="pos" type="vector3"/><convert name="c" type="color3"><input name="in" type="vector3" '
            'nodename="pos"/></convert><output name="out" type="color3" nodename="c"/>',
            "base_color is fed by a 'position' node ('pos' in nodegraph 'NG')",
        ),
        (
            '<texcoord name="uv1" type="vector2"><input name="index" type="integer" value="1"/></texcoord>'
            '<convert name="c" type="color3"><input name="in" type="vector2" nodename="uv1"/></convert>'
            '<output name="out" type="color3" nodename="c"/>',
            "UV set 1",
        ),
    ],
)
def test_other_nodes_are_refused_naming_the_node_and_the_input(tmp_path, graph, words):
    p = shader_doc(tmp_path, graph)
    with pytest.raises(MatremapError) as e:
        read(p)
    assert words in str(e.value) and "cannot evaluate" in str(e.value) and str(p) in str(e.value)
