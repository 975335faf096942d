"""Writing MaterialX: documents that MaterialX itself validates with its standard libraries loaded, the
carried inputs (emission, opacity, occlusion) written into gltf_pbr and read back, and write_all -- a fresh
document holding every material, or a copy of a MaterialX source (the public Open Chess Set, 15 materials
and a look) with the converted materials' shaders replaced and everything else kept -- each material
reading back to the converted values; and read -> write -> read round trips of the public corpus."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

mx = pytest.importorskip("MaterialX", reason="MaterialX not installed: pip install 'matremap[materialx]'")

from matremap.core.material import Material  # noqa: E402
from matremap.errors import MatremapError  # noqa: E402
from matremap.formats import write_all as formats_write_all  # noqa: E402
from matremap.formats.asset import MaterialAsset  # noqa: E402
from matremap.formats.confine import Confinement  # noqa: E402
from matremap.formats.materialx import material_names, read, write, write_all  # noqa: E402
from matremap.svbrdf.textures import ImageInfo, load_map_set, read_image, write_image_like  # noqa: E402

CORPUS = Path(__file__).resolve().parent / "data" / "corpus"
ALLOW = Confinement.of([CORPUS])
CHESS = CORPUS / "mtlx-standard_surface_chess_set" / "standard_surface_chess_set.mtlx"


def validates(path: Path) -> None:
    """MaterialX's own validation with its standard data libraries (not matremap's code path)."""
    d = mx.createDocument()
    mx.readFromXmlFile(d, str(path))
    lib = mx.createDocument()
    mx.loadLibraries(mx.getDefaultDataLibraryFolders(), mx.getDefaultDataSearchPath(), lib)
    d.importLibrary(lib)
    ok, why = d.validate()
    assert ok, why
    assert d.getVersionString() == "1.39"


def exr(path: Path, values: np.ndarray) -> Path:
    v = np.asarray(values, dtype=np.float32)
    return write_image_like(path, v, ImageInfo("exr", "float", v.shape[-1], 0, 0, "linear"), force=True)


def doc(tmp_path: Path, body: str, name: str = "src.mtlx") -> Path:
    p = tmp_path / name
    p.write_text(f'<?xml version="1.0"?>\n<materialx version="1.39" colorspace="lin_rec709">\n{body}\n</materialx>\n')
    return p


def texture_values(ref) -> np.ndarray:
    """A carried texture's values as a writer sees them (bake, or the file with its channels), times its scale."""
    if ref.bake is not None:
        v = np.atleast_3d(ref.bake())
    else:
        v = np.atleast_3d(read_image(ref.path, ref.colorspace)[0])
    if ref.channels is not None:
        v = v[..., list(ref.channels)]
    return v * np.asarray(ref.scale, dtype=np.float32).reshape(-1)[: v.shape[-1]]


GLTF = Material.create(
    "gltf:metal-rough",
    {"baseColor": [0.2, 0.4, 0.6], "metallic": 0.0, "roughness": 0.3, "ior": 1.45, "specular": 0.8},
)


def test_write_carries_emission_opacity_and_occlusion(tmp_path):
    orm = np.random.default_rng(3).uniform(0.1, 0.9, (4, 4, 3)).astype(np.float32)
    exr(tmp_path / "orm.exr", orm)
    src = doc(
        tmp_path,
        """<gltf_image name="orm" type="vector3"><input name="file" type="filename" value="orm.exr"/></gltf_image>
  <separate3 name="ch" type="multioutput"><input name="in" type="vector3" nodename="orm"/></separate3>
  <gltf_pbr name="SR" type="surfaceshader"><input name="base_color" type="color3" value="0.2, 0.4, 0.6"/>
    <input name="emissive" type="color3" value="1, 0.5, 0.25"/><input name="emissive_strength" type="float" value="4"/>
    <input name="alpha" type="float" value="0.4"/><input name="alpha_mode" type="integer" value="1"/>
    <input name="alpha_cutoff" type="float" value="0.3"/>
    <input name="occlusion" type="float" nodename="ch" output="outx"/></gltf_pbr>
  <surfacematerial name="Lamp" type="material"><input name="surfaceshader" type="surfaceshader" nodename="SR"/>
  </surfacematerial>""",
    )
    a = read(src)
    assert a.carried["emission"].value == pytest.approx((4.0, 2.0, 1.0))
    assert a.carried["opacity"].value == pytest.approx(0.4)
    assert dict(a.carried["opacity"].settings) == {"mode": "mask", "cutoff": 0.3}
    (tmp_path / "out").mkdir()
    out = write(tmp_path / "out" / "lamp.mtlx", a.material(), source=a)
    validates(out)
    text = out.read_text()
    # a copy of the source document: its shader's name and carried inputs as they were, the ORM image copied
    assert (
        '<gltf_pbr name="SR" type="surfaceshader">' in text
        and 'name="emissive_strength" type="float" value="4"' in text
    )
    assert (tmp_path / "out" / "lamp_files" / "orm.exr").is_file()
    b = read(out)
    assert b.name == "Lamp" and b.material() == a.material()
    assert b.carried["emission"].value == pytest.approx((4.0, 2.0, 1.0))
    assert b.carried["opacity"].value == pytest.approx(0.4) and b.carried["opacity"].settings["cutoff"] == 0.3
    np.testing.assert_allclose(texture_values(b.carried["occlusion"].texture), orm[..., :1], atol=1e-6)


def test_write_carries_a_textured_standard_surface_emission(tmp_path):
    glow = np.random.default_rng(4).uniform(0.0, 1.0, (4, 4, 3)).astype(np.float32)
    exr(tmp_path / "glow.exr", glow)
    src = doc(
        tmp_path,
        """<image name="g" type="color3"><input name="file" type="filename" value="glow.exr"/></image>
  <standard_surface name="SS" type="surfaceshader"><input name="emission" type="float" value="2"/>
    <input name="emission_color" type="color3" nodename="g"/><input name="opacity" type="color3" value="0.5, 0.5, 0.5"/>
  </standard_surface>
  <surfacematerial name="Sign" type="material"><input name="surfaceshader" type="surfaceshader" nodename="SS"/>
  </surfacematerial>""",
    )
    a = read(src)
    em = a.carried["emission"]
    np.testing.assert_allclose(texture_values(em.texture) * np.asarray(em.value), glow * 2, atol=1e-6)
    assert a.carried["opacity"].value == pytest.approx(0.5) and a.carried["opacity"].settings["mode"] == "blend"
    (tmp_path / "out").mkdir()
    out = write(tmp_path / "out" / "sign.mtlx", a.material(), source=a)
    validates(out)
    b = read(out)
    em2 = b.carried["emission"]
    np.testing.assert_allclose(texture_values(em2.texture) * np.asarray(em2.value), glow * 2, atol=1e-6)
    assert b.carried["opacity"].value == pytest.approx(0.5) and b.carried["opacity"].settings["mode"] == "blend"


def test_write_all_fresh_document_holds_every_material(tmp_path):
    rough = np.linspace(0.1, 0.9, 16, dtype=np.float32).reshape(4, 4, 1)
    d = tmp_path / "ms"
    d.mkdir()
    exr(d / "rough.exr", rough)
    (d / "material.json").write_text(
        json.dumps({"model": "gltf:metal-rough", "maps": {"roughness": "rough.exr"}, "params": {"metallic": 1}})
    )
    results = [("red paint", GLTF), ("Worn Metal", load_map_set(d)), ("red_paint", GLTF.with_params({"ior": 1.6}))]
    (tmp_path / "out").mkdir()
    out = formats_write_all(tmp_path / "out" / "all.mtlx", results, tmp_path / "scene.gltf", force=False)
    validates(out)
    names = material_names(out)
    assert names == ["red_paint", "Worn_Metal", "red_paint2"]  # valid MaterialX names, kept apart
    assert read(out, "red_paint").material() == GLTF
    assert read(out, "red_paint2").material() == GLTF.with_params({"ior": 1.6})
    metal = read(out, "Worn_Metal")
    assert metal.constants["metallic"] == 1.0
    back, _ = read_image(metal.textures["roughness"].path, "linear")
    np.testing.assert_array_equal(back, rough)


def chess_results(tmp_path: Path) -> list[tuple[str, object]]:
    """Converted results for three of the chess set's materials: two uniform, one map set."""
    bishop = read(CHESS, "M_Bishop_B", confinement=ALLOW)
    ms = load_map_set(bishop.to_map_set(tmp_path / "bishop"))
    return [
        ("M_Chessboard", GLTF),
        ("M_Bishop_B", ms),
        ("M_Pawn_Top_W", GLTF.with_params({"metallic": 1.0, "roughness": 0.1})),
    ]


def test_write_all_copies_a_materialx_source_keeping_looks_and_names(tmp_path):
    results = chess_results(tmp_path)
    (tmp_path / "out").mkdir()
    out = write_all(tmp_path / "out" / "chess.mtlx", results, CHESS)
    validates(out)
    d = mx.createDocument()
    mx.readFromXmlFile(d, str(out))
    src = mx.createDocument()
    mx.readFromXmlFile(src, str(CHESS))
    # every material, in order, and the look with its 15 assignments, as they were
    assert [m.getName() for m in d.getMaterialNodes()] == [m.getName() for m in src.getMaterialNodes()]
    look = d.getLook("L_ChessSet")
    assert look is not None and len(look.getMaterialAssigns()) == 15
    # the converted materials' shaders are nodes of their models (gltf_pbr; the bishop's maps, read into Standard
    # Surface itself, a standard_surface) under the source's shader names
    for name, result in results:
        old = mx.getShaderNodes(src.getNode(name))[0].getName()
        new = mx.getShaderNodes(d.getNode(name))
        category = "standard_surface" if result.model == "mtlx:standard_surface" else "gltf_pbr"
        assert [n.getName() for n in new] == [old] and new[0].getCategory() == category
    assert d.getNodeGraph("NG_BishopBlack") is None  # only the replaced shader used it
    assert d.getNodeGraph("NG_KingWhite") is not None and d.getNode("King_W").getCategory() == "standard_surface"
    # each converted material reads back to its converted values
    assert read(out, "M_Chessboard").material() == GLTF
    assert read(out, "M_Pawn_Top_W").material() == results[2][1]
    bishop = read(out, "M_Bishop_B")
    ms = results[1][1]
    for param, f in ms.maps.items():
        want, _ = read_image(f, ms.colorspace.get(param))
        got, _ = read_image(bishop.textures[param].path, bishop.textures[param].colorspace)
        np.testing.assert_allclose(got[..., : want.shape[-1]], want, atol=1e-6, err_msg=param)
    # an unconverted material still finds its textures: copied beside the new document, byte for byte
    king = read(out, "M_King_W")
    src_king = read(CHESS, "M_King_W", confinement=ALLOW)
    assert set(king.textures) == set(src_king.textures)
    for k, ref in king.textures.items():
        assert ref.path.parent == (out.parent / "chess_files").resolve()
        assert ref.path.read_bytes() == src_king.textures[k].path.read_bytes()
    # only the textures the kept materials use are copied (the bishop's own are not)
    assert not (out.parent / "chess_files" / "bishop_black_base_color.jpg").exists()


def test_write_all_carries_emission_connections_in_a_copy(tmp_path):
    glow = np.random.default_rng(5).uniform(0.0, 1.0, (4, 4, 3)).astype(np.float32)
    exr(tmp_path / "glow.exr", glow)
    src = doc(
        tmp_path,
        """<nodegraph name="NG"><image name="g" type="color3"><input name="file" type="filename" value="glow.exr"/>
    </image><output name="out" type="color3" nodename="g"/></nodegraph>
  <standard_surface name="SS" type="surfaceshader"><input name="emission" type="float" value="3"/>
    <input name="emission_color" type="color3" nodegraph="NG" output="out"/></standard_surface>
  <surfacematerial name="Sign" type="material"><input name="surfaceshader" type="surfaceshader" nodename="SS"/>
  </surfacematerial>""",
    )
    (tmp_path / "out").mkdir()
    out = write_all(tmp_path / "out" / "sign.mtlx", [("Sign", GLTF)], src)
    validates(out)
    b = read(out)
    assert b.material() == GLTF
    em = b.carried["emission"]
    np.testing.assert_allclose(texture_values(em.texture) * np.asarray(em.value), glow * 3, atol=1e-6)
    assert 'nodegraph="NG"' in out.read_text()  # the same graph, kept, now feeding emissive


def test_write_all_refuses_a_material_the_source_does_not_have_and_writes_nothing(tmp_path):
    (tmp_path / "out").mkdir()
    with pytest.raises(MatremapError, match="no surfacematerial 'M_Rook'"):
        write_all(tmp_path / "out" / "chess.mtlx", [("M_Rook", GLTF)], CHESS)
    assert list((tmp_path / "out").iterdir()) == []


ROUND_TRIP = [
    ("mtlx-gltf_pbr_boombox/gltf_pbr_boombox.mtlx", None),
    (
        "mtlx-standard_surface_wood_tiled/resources/Materials/Examples/StandardSurface/standard_surface_wood_tiled.mtlx",
        None,
    ),
    (
        "mtlx-standard_surface_brick_procedural/resources/Materials/Examples/StandardSurface/"
        "standard_surface_brick_procedural.mtlx",
        None,
    ),
    ("mtlx-standard_surface_chess_set/standard_surface_chess_set.mtlx", "M_Queen_W"),
    ("mtlx-open_pbr_lightbulb/open_pbr_lightbulb.mtlx", None),
    ("mtlx-standard_surface_jade/standard_surface_jade.mtlx", None),
    ("mtlx-standard_surface_velvet/standard_surface_velvet.mtlx", None),
    ("mtlx-gltf_pbr_gold/gltf_pbr_gold.mtlx", None),
]


@pytest.mark.parametrize("rel, material", ROUND_TRIP, ids=[r.split("/")[0] for r, _ in ROUND_TRIP])
def test_corpus_round_trip_read_write_read(tmp_path, rel, material):
    """read -> write (gltf_pbr) -> read gives the same parameters, maps, normal map and carried inputs."""
    a = read(CORPUS / rel, material, confinement=ALLOW)
    result = load_map_set(a.to_map_set(tmp_path / "a")) if a.textured else a.material()
    (tmp_path / "out").mkdir()
    out = write(tmp_path / "out" / "rt.mtlx", result, source=a)
    validates(out)
    b = read(out, a.name)  # a copy of the source document: its other materials are kept
    assert b.name == a.name.replace(" ", "_")
    assert b.material() == a.material() or a.textured
    assert {k: v for k, v in b.constants.items() if k not in b.textures} == {
        k: v for k, v in a.constants.items() if k not in a.textures
    }
    assert set(b.textures) == set(a.textures)
    if a.textured:
        left = load_map_set(b.to_map_set(tmp_path / "b"))
        for param in a.textures:
            x, _ = read_image(result.maps[param], result.colorspace.get(param))
            y, _ = read_image(left.maps[param], left.colorspace.get(param))
            np.testing.assert_allclose(y, x, atol=2e-6, err_msg=param)
    assert (a.normal is None) == (b.normal is None)
    if a.normal is not None:
        np.testing.assert_allclose(texture_values(b.normal), texture_values(a.normal), atol=2e-6)
    assert set(b.carried) == set(a.carried)
    for key, c in a.carried.items():
        d = b.carried[key]
        if c.texture is None:
            assert d.texture is None and np.allclose(d.value, c.value)
        else:
            np.testing.assert_allclose(
                texture_values(d.texture) * np.asarray(d.value),
                texture_values(c.texture) * np.asarray(c.value),
                atol=2e-6,
            )


def test_write_refuses_other_models_and_writes_nothing(tmp_path):
    asset = MaterialAsset(path=tmp_path / "x.gltf", format="gltf", name="x", model="gltf:metal-rough")
    with pytest.raises(MatremapError, match="not mitsuba3:diffuse"):
        write(tmp_path / "x.mtlx", Material.create("mitsuba3:diffuse"), source=asset)
    with pytest.raises(MatremapError, match="not mitsuba3:diffuse"):
        write_all(tmp_path / "y.mtlx", [("a", Material.create("mitsuba3:diffuse"))], None)
    assert list(tmp_path.iterdir()) == []


def test_standard_surface_transmission_is_written_and_read_back(tmp_path):
    """transmission, transmission_color, transmission_depth and the boolean thin_walled go into the document,
    which MaterialX validates, and come back into mtlx:standard_surface (the transmission is read, not lost: it
    is fitted on the transmission probe)."""
    values = {"coat": 1.0, "transmission": 0.9, "transmission_color": [0.9, 0.6, 0.3], "transmission_depth": 2.0}
    m = Material.create("mtlx:standard_surface", {**values, "thin_walled": 1.0})
    out = write(tmp_path / "glass.mtlx", m)
    validates(out)
    assert '<input name="thin_walled" type="boolean" value="true" />' in out.read_text()
    asset = read(out)
    assert asset.model == "mtlx:standard_surface" and asset.lost == []
    for k, v in {**values, "thin_walled": 1.0}.items():
        assert asset.constants[k] == v, k
