"""MaterialX documents: gltf_pbr, standard_surface and open_pbr_surface read as gltf:metal-rough,
textures and their colour spaces, the hand-made translation's warning, written documents that
MaterialX validates, round trips and error messages."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

mx = pytest.importorskip("MaterialX", reason="MaterialX not installed: pip install 'matremap[materialx]'")

from matremap.core.material import Material  # noqa: E402
from matremap.errors import MatremapError  # noqa: E402
from matremap.formats.materialx import read, write  # noqa: E402
from matremap.svbrdf.textures import ImageInfo, load_map_set, read_image, write_image_like  # noqa: E402


def doc(tmp_path: Path, body: str, name: str = "m.mtlx") -> Path:
    p = tmp_path / name
    p.write_text(f'<?xml version="1.0"?>\n<materialx version="1.39" colorspace="lin_rec709">\n{body}\n</materialx>\n')
    return p


def png(path: Path, values: np.ndarray, colorspace: str) -> Path:
    return write_image_like(path, values, ImageInfo("png", "uint8", values.shape[-1], 0, 0, colorspace), force=True)


def validates(path: Path) -> bool:
    d = mx.createDocument()
    mx.readFromXmlFile(d, str(path))
    lib = mx.createDocument()
    mx.loadLibraries(mx.getDefaultDataLibraryFolders(), mx.getDefaultDataSearchPath(), lib)
    d.importLibrary(lib)
    ok, why = d.validate()
    assert ok, why
    return ok


# -- reading -----------------------------------------------------------------------------------------


def test_gltf_pbr_values_textures_and_normal(tmp_path):
    rng = np.random.default_rng(0)
    png(tmp_path / "base.png", rng.uniform(0.05, 0.95, (8, 8, 3)).astype(np.float32), "srgb")
    png(tmp_path / "orm.png", rng.uniform(0.05, 0.95, (8, 8, 3)).astype(np.float32), "linear")
    png(tmp_path / "n.png", np.tile(np.array([0.5, 0.5, 1.0], np.float32), (8, 8, 1)), "linear")
    p = doc(
        tmp_path,
        """
  <image name="base" type="color3"><input name="file" type="filename" value="base.png" colorspace="srgb_texture"/>
  </image>
  <gltf_image name="orm" type="color3"><input name="file" type="filename" value="orm.png"/>
    <input name="factor" type="color3" value="1, 0.5, 1"/></gltf_image>
  <extract name="rough" type="float"><input name="in" type="color3" nodename="orm"/>
    <input name="index" type="integer" value="1"/></extract>
  <nodegraph name="NG">
    <image name="nimg" type="vector3"><input name="file" type="filename" value="n.png"/></image>
    <normalmap name="nmap" type="vector3"><input name="in" type="vector3" nodename="nimg"/></normalmap>
    <output name="out" type="vector3" nodename="nmap"/>
  </nodegraph>
  <gltf_pbr name="SR" type="surfaceshader">
    <input name="base_color" type="color3" nodename="base"/>
    <input name="roughness" type="float" nodename="rough"/>
    <input name="metallic" type="float" value="0"/>
    <input name="ior" type="float" value="1.45"/>
    <input name="specular_color" type="color3" value="1, 0.9, 0.8"/>
    <input name="normal" type="vector3" nodegraph="NG" output="out"/>
    <input name="clearcoat" type="float" value="0.3"/>
  </gltf_pbr>
  <surfacematerial name="Painted" type="material"><input name="surfaceshader" type="surfaceshader" nodename="SR"/>
  </surfacematerial>""",
    )
    a = read(p)
    assert (a.name, a.model, a.format) == ("Painted", "gltf:metal-rough", "mtlx")
    assert a.constants["metallic"] == 0.0 and a.constants["ior"] == 1.45 and a.constants["specular"] == 1.0
    assert a.constants["specularColor"] == [1.0, 0.9, 0.8]
    base, rough = a.textures["baseColor"], a.textures["roughness"]
    assert base.path == (tmp_path / "base.png").resolve() and base.colorspace == "srgb" and base.plain
    assert rough.path == (tmp_path / "orm.png").resolve() and rough.channels == (1,)
    assert rough.colorspace == "linear" and rough.scale == 0.5  # the factor of the channel taken
    assert a.normal is not None and a.normal.path == (tmp_path / "n.png").resolve()
    assert any("clearcoat=0.3" in n for n in a.notes)
    assert not any("WARNING" in n for n in a.notes)  # gltf_pbr maps one to one
    # the map set applies the channel and the factor
    ms = load_map_set(a.to_map_set(tmp_path / "ms"))
    got, _ = read_image(ms.maps["roughness"], ms.colorspace["roughness"])
    orm, _ = read_image(tmp_path / "orm.png", "linear")
    assert np.allclose(got[..., 0], orm[..., 1] * 0.5, atol=1e-6)


def test_colour_spaces(tmp_path):
    png(tmp_path / "c.png", np.full((4, 4, 3), 0.5, np.float32), "srgb")
    body = """
  <image name="img" type="color3"><input name="file" type="filename" value="c.png" {cs}/></image>
  <gltf_pbr name="SR" type="surfaceshader"><input name="base_color" type="color3" nodename="img"/></gltf_pbr>
  <surfacematerial name="M" type="material"><input name="surfaceshader" type="surfaceshader" nodename="SR"/>
  </surfacematerial>"""
    expect = {
        'colorspace="srgb_texture"': "srgb",
        'colorspace="lin_rec709"': "linear",
        'colorspace="raw"': "linear",
        "": "linear",
    }  # no attribute: the document's lin_rec709
    for cs, want in expect.items():
        assert read(doc(tmp_path, body.format(cs=cs))).textures["baseColor"].colorspace == want, cs
    with pytest.raises(MatremapError, match="colour space 'acescg'"):
        read(doc(tmp_path, body.format(cs='colorspace="acescg"')))


def test_standard_surface_is_read_into_its_own_model_with_what_it_does_not_model_listed(tmp_path):
    """Standard Surface is read by name into mtlx:standard_surface (before: a hand-made translation onto glTF's
    parameters, which no measure could check); the inputs it does not model are named in a note."""
    p = doc(
        tmp_path,
        """
  <standard_surface name="SS" type="surfaceshader">
    <input name="base" type="float" value="0.5"/>
    <input name="base_color" type="color3" value="0.8, 0.6, 0.4"/>
    <input name="metalness" type="float" value="1"/>
    <input name="specular_roughness" type="float" value="0.35"/>
    <input name="specular_IOR" type="float" value="1.6"/>
    <input name="coat" type="float" value="0.5"/>
    <input name="sheen" type="float" value="0"/>
    <input name="emission" type="float" value="0.2"/>
    <input name="specular_anisotropy" type="float" value="0.4"/>
  </standard_surface>
  <surfacematerial name="Brass" type="material">
    <input name="surfaceshader" type="surfaceshader" nodename="SS"/></surfacematerial>""",
    )
    a = read(p)
    assert a.model == "mtlx:standard_surface" and not any("translation" in n for n in a.notes)
    assert a.constants["base"] == 0.5 and a.constants["base_color"] == pytest.approx([0.8, 0.6, 0.4])
    assert a.constants["metalness"] == 1.0 and a.constants["specular_roughness"] == 0.35
    assert a.constants["specular_IOR"] == 1.6 and a.constants["coat"] == 0.5
    first = a.notes[0]
    assert first.startswith("standard_surface read into mtlx:standard_surface") and "specular_anisotropy=0.4" in first
    assert "sheen" not in first  # modelled, and at its default
    # emission is not remapped but carried to the writer: emission_color (default white) x emission
    assert a.carried["emission"].value == pytest.approx((0.2, 0.2, 0.2)) and a.carried["emission"].texture is None
    assert any(n.startswith("carried unchanged") and "emission (0.2" in n for n in a.notes)


#: an OpenPBR dielectric whose diffuse is EON at roughness 1 (glTF has no diffuse roughness)
ROUGH_DIFFUSE = """
  <open_pbr_surface name="OP" type="surfaceshader">
    <input name="base_weight" type="float" value="1"/>
    <input name="base_color" type="color3" value="0.7, 0.5, 0.3"/>
    <input name="base_diffuse_roughness" type="float" value="1"/>
    <input name="specular_roughness" type="float" value="0.4"/>
  </open_pbr_surface>
  <surfacematerial name="M" type="material"><input name="surfaceshader" type="surfaceshader" nodename="OP"/>
  </surfacematerial>"""


def test_open_pbr_surface_is_read_into_its_own_model(tmp_path):
    a = read(doc(tmp_path, ROUGH_DIFFUSE))
    assert a.model == "mtlx:open_pbr_surface"
    assert a.constants["base_weight"] == 1.0 and a.constants["base_color"] == pytest.approx([0.7, 0.5, 0.3])
    # a diffuse roughness glTF has no slot for (EON): modelled, so a fit onto glTF sees it (it was dropped)
    assert a.constants["base_diffuse_roughness"] == 1.0 and a.constants["specular_roughness"] == 0.4


def test_an_open_pbr_diffuse_roughness_onto_gltf_is_fitted_not_copied(tmp_path, capsys):
    """Before, the hand-made translation read this material as a glTF one, and the remap onto glTF was an identity
    copy (exit 0) that dropped the diffuse roughness; now it is fitted, and glTF's Lambertian cannot flatten the
    diffuse as EON does at roughness 1: the gate says so."""
    pytest.importorskip("colour", reason="the quality gate needs colour-science")
    from matremap.cli import main

    p = doc(tmp_path, ROUGH_DIFFUSE)
    code = main(["remap", str(p), "--to", "gltf:metal-rough", "-o", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 3 and "identity" not in err and "FAILED: fit_error" in err.strip().splitlines()[-1]


def test_material_selection(tmp_path):
    p = doc(
        tmp_path,
        """
  <gltf_pbr name="A" type="surfaceshader"><input name="roughness" type="float" value="0.1"/></gltf_pbr>
  <gltf_pbr name="B" type="surfaceshader"><input name="roughness" type="float" value="0.2"/></gltf_pbr>
  <surfacematerial name="first" type="material"><input name="surfaceshader" type="surfaceshader" nodename="A"/>
  </surfacematerial>
  <surfacematerial name="second" type="material"><input name="surfaceshader" type="surfaceshader" nodename="B"/>
  </surfacematerial>""",
    )
    assert read(p).constants["roughness"] == 0.1
    assert read(p, "second").constants["roughness"] == 0.2 and read(p, 1).index == 1
    with pytest.raises(MatremapError, match="no material named 'third'; its materials are 'first', 'second'"):
        read(p, "third")
    with pytest.raises(MatremapError, match="index 2 is out of range"):
        read(p, 2)


@pytest.mark.parametrize(
    "text, words",
    [
        ("not xml at all", "not a MaterialX document"),
        ('<?xml version="1.0"?><scene version="3.0.0"><bsdf type="diffuse"/></scene>', "not a MaterialX document"),
        (
            '<?xml version="1.0"?><materialx version="1.39"><image name="i" type="color3">'
            '<input name="file" type="filename" value="missing.png"/></image><gltf_pbr name="S" type="surfaceshader">'
            '<input name="base_color" type="color3" nodename="i"/></gltf_pbr><surfacematerial name="M" type="material">'
            '<input name="surfaceshader" type="surfaceshader" nodename="S"/></surfacematerial></materialx>',
            "texture missing.png for base_color not found",
        ),
        (
            '<?xml version="1.0"?><materialx version="1.39"><nodedef name="ND_x" node="x"/></materialx>',
            "holds no surfacematerial",
        ),
        (
            '<?xml version="1.0"?><materialx version="1.39"><gltf_pbr name="S" type="surfaceshader">'
            '<input name="roughness" type="float" value="2"/></gltf_pbr></materialx>',
            "outside its range",
        ),
    ],
)
def test_bad_inputs_say_what_is_wrong(tmp_path, text, words):
    p = tmp_path / "bad.mtlx"
    p.write_text(text)
    with pytest.raises(MatremapError) as e:
        read(p)
    assert words in str(e.value) and str(p) in str(e.value)


# -- writing -----------------------------------------------------------------------------------------


def test_uniform_round_trip_and_validation(tmp_path):
    m = Material.create(
        "gltf:metal-rough",
        {
            "baseColor": [0.1, 0.2, 0.30000000000000004],
            "metallic": 0.25,
            "roughness": 0.123456789,
            "ior": 1.45,
            "specular": 0.7,
            "specularColor": [1.0, 0.9, 0.8],
        },
    )
    out = write(tmp_path / "m.mtlx", m)
    assert validates(out)
    a = read(out)
    assert a.material() == m and not a.textures and a.notes == []
    with pytest.raises(MatremapError, match="already exists"):
        write(out, m.with_params({"roughness": 0.5}))
    assert read(out).material() == m
    write(out, m.with_params({"roughness": 0.5}), force=True)
    assert read(out).constants["roughness"] == 0.5


def test_map_set_round_trip(tmp_path):
    rng = np.random.default_rng(2)
    d = tmp_path / "maps"
    d.mkdir()
    png(d / "base.png", rng.uniform(0.05, 0.95, (8, 8, 3)).astype(np.float32), "srgb")
    png(d / "lin_base.png", rng.uniform(0.05, 0.95, (8, 8, 3)).astype(np.float32), "linear")
    png(d / "rough.png", rng.uniform(0.1, 0.9, (8, 8, 1)).astype(np.float32), "linear")
    png(d / "normal.png", np.tile(np.array([0.5, 0.5, 1.0], np.float32), (8, 8, 1)), "linear")
    (d / "material.json").write_text(
        '{"model": "gltf:metal-rough", "maps": {"baseColor": "base.png", '
        '"roughness": "rough.png"}, "normal": "normal.png", '
        '"params": {"metallic": 0, "ior": 1.4}}'
    )
    ms = load_map_set(d)
    (tmp_path / "out").mkdir()
    out = write(tmp_path / "out" / "mat.mtlx", ms)
    assert validates(out)
    text = out.read_text()
    assert 'colorspace="srgb_texture"' in text and 'value="mat_baseColor.png"' in text  # relative file names
    a = read(out)
    assert a.constants["metallic"] == 0.0 and a.constants["ior"] == 1.4
    assert a.textures["baseColor"].colorspace == "srgb" and a.textures["roughness"].colorspace == "linear"
    for name in ("baseColor", "roughness"):
        ref = a.textures[name]
        assert ref.path.parent == out.parent
        back, _ = read_image(ref.path, ref.colorspace)
        orig, _ = read_image(ms.maps[name], ms.colorspace[name])
        assert np.array_equal(back, orig)
    assert a.normal is not None and a.normal.path.read_bytes() == (d / "normal.png").read_bytes()
    # a linear colour PNG is declared lin_rec709
    (d / "material.json").write_text(
        '{"model": "gltf:metal-rough", "maps": {"baseColor": "lin_base.png"}, "colorspace": {"lin_base.png": "linear"}}'
    )
    out2 = write(tmp_path / "lin.mtlx", load_map_set(d))
    assert 'colorspace="lin_rec709"' in out2.read_text() and read(out2).textures["baseColor"].colorspace == "linear"


def test_writer_refuses_other_models_and_writes_nothing(tmp_path):
    with pytest.raises(MatremapError, match="writes gltf:metal-rough, gltf:pbr, .* materials, not mitsuba3:diffuse"):
        write(tmp_path / "x.mtlx", Material.create("mitsuba3:diffuse"))
    with pytest.raises(MatremapError, match="unknown file type"):
        write(tmp_path / "x.xml", Material.create("gltf:metal-rough"))
    assert list(tmp_path.iterdir()) == []


def test_a_colour_just_above_one_is_clamped_with_a_note(tmp_path):
    p = doc(
        tmp_path,
        '<gltf_pbr name="S" type="surfaceshader">'
        '<input name="base_color" type="color3" value="1.059, 0.773, 0.307"/></gltf_pbr>'
        '<surfacematerial name="Gold" type="material">'
        '<input name="surfaceshader" type="surfaceshader" nodename="S"/></surfacematerial>',
    )
    asset = read(p)
    np.testing.assert_allclose(asset.constants["baseColor"], [1.0, 0.773, 0.307])
    assert any("clamped" in n for n in asset.notes)


def test_a_map_that_fails_after_another_was_placed_leaves_nothing(tmp_path):
    d = tmp_path / "maps"
    d.mkdir()
    png(d / "base.png", np.full((8, 8, 3), 0.5, np.float32), "srgb")
    png(d / "rough.png", np.full((8, 8, 1), 0.5, np.float32), "linear")
    (d / "material.json").write_text(
        '{"model": "gltf:metal-rough", "maps": {"baseColor": "base.png", "roughness": "rough.png"}}'
    )
    ms = load_map_set(d)
    (d / "rough.png").write_bytes(b"not a PNG any more")  # read after the base colour is placed
    (tmp_path / "out").mkdir()
    with pytest.raises(MatremapError):
        write(tmp_path / "out" / "mat.mtlx", ms)
    assert list((tmp_path / "out").iterdir()) == []


def _preview_doc(tmp_path, inputs: str, nodes: str = "") -> Path:
    from matremap.svbrdf.textures import ImageInfo, write_image_like

    img = np.zeros((4, 4, 3), dtype=np.float32)
    img[:, :2] = [0.8, 0.1, 0.1]
    img[:, 2:] = [0.1, 0.1, 0.8]
    write_image_like(tmp_path / "tex.png", img, ImageInfo("png", "uint8", 3, 4, 4, "srgb"), force=True)
    p = tmp_path / "preview.mtlx"
    p.write_text(
        '<?xml version="1.0"?><materialx version="1.39" colorspace="lin_rec709">'
        f'<UsdPreviewSurface name="U" type="surfaceshader">{inputs}</UsdPreviewSurface>{nodes}'
        '<surfacematerial name="M" type="material"><input name="surfaceshader" type="surfaceshader" nodename="U"/>'
        "</surfacematerial></materialx>"
    )
    return p


_TEX = (
    '<image name="t" type="color3"><input name="file" type="filename" value="tex.png" colorspace="srgb_texture"/>'
    "</image>"
)


def test_a_usd_preview_surface_is_read_into_its_own_model_with_textures_and_a_mask(tmp_path):
    p = _preview_doc(
        tmp_path,
        '<input name="diffuseColor" type="color3" nodename="t"/><input name="roughness" type="float" value="0.4"/>'
        '<input name="clearcoat" type="float" value="0.5"/><input name="opacity" type="float" value="0.5"/>'
        '<input name="opacityThreshold" type="float" value="0.25"/>'
        '<input name="emissiveColor" type="color3" value="0.1, 0.2, 0.3"/>',
        _TEX,
    )
    a = read(p)
    assert a.model == "usd:preview_surface" and set(a.textures) == {"diffuseColor"}
    assert a.textures["diffuseColor"].path.name == "tex.png" and a.textures["diffuseColor"].colorspace == "srgb"
    assert a.constants["roughness"] == pytest.approx(0.4) and a.constants["clearcoat"] == pytest.approx(0.5)
    assert a.constants["useSpecularWorkflow"] == "0"
    assert a.carried["opacity"].value == pytest.approx(0.5)
    assert a.carried["opacity"].settings == {"mode": "mask", "cutoff": 0.25}
    assert a.carried["emission"].value == pytest.approx((0.1, 0.2, 0.3))


def test_a_textured_coloured_specular_workflow_is_refused_and_a_grey_one_read_as_metalness(tmp_path):
    p = _preview_doc(
        tmp_path,
        '<input name="useSpecularWorkflow" type="integer" value="1"/><input name="specularColor" type="color3" '
        'nodename="t"/><input name="diffuseColor" type="color3" nodename="t"/>',
        _TEX,
    )
    with pytest.raises(MatremapError, match="specular workflow with a coloured or textured specularColor"):
        read(p)
    grey = _preview_doc(
        tmp_path,
        '<input name="useSpecularWorkflow" type="integer" value="1"/>'
        '<input name="specularColor" type="color3" value="0.04, 0.04, 0.04"/>'
        '<input name="diffuseColor" type="color3" nodename="t"/>',
        _TEX,
    )
    a = read(grey)
    assert a.constants["useSpecularWorkflow"] == "0" and a.constants["ior"] == pytest.approx(1.5)
