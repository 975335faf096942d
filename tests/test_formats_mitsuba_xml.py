"""Mitsuba 3 scene XML: reading BSDFs (defaults, wrappers, named IORs, bitmaps), writing scenes that
real Mitsuba 3 loads and renders, round trips and error messages. Rendering tests skip without
Mitsuba 3 (``pip install 'matremap[mitsuba]'``)."""

from __future__ import annotations

import importlib.util
import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from matremap.core.material import Material
from matremap.core.scene import Scene
from matremap.errors import MatremapError
from matremap.formats import mitsuba_xml
from matremap.formats.mitsuba_xml import IOR_TABLE, read, write
from matremap.svbrdf.textures import ImageInfo, load_map_set, read_image, write_image_like

needs_mitsuba = pytest.mark.skipif(
    importlib.util.find_spec("mitsuba") is None, reason="Mitsuba 3 not installed: pip install 'matremap[mitsuba]'"
)


def scene_xml(tmp_path: Path, body: str, name: str = "scene.xml", version: str = "3.0.0") -> Path:
    p = tmp_path / name
    p.write_text(f'<?xml version="1.0"?>\n<scene version="{version}">\n{body}\n</scene>\n')
    return p


def png(path: Path, values: np.ndarray, colorspace: str) -> Path:
    """An 8-bit PNG holding linear ``values`` encoded as ``colorspace``."""
    return write_image_like(path, values, ImageInfo("png", "uint8", values.shape[-1], 0, 0, colorspace), force=True)


def exr(path: Path, values: np.ndarray) -> Path:
    return write_image_like(path, values, ImageInfo("exr", "float", values.shape[-1], 0, 0, "linear"), force=True)


# -- reading -----------------------------------------------------------------------------------------


def test_defaults_substituted_and_twosided_unwrapped_inside_a_shape(tmp_path):
    p = scene_xml(
        tmp_path,
        """
    <default name="rough" value="0.25"/>
    <default name="dist" value="ggx"/>
    <bsdf type="diffuse" id="wall"><rgb name="reflectance" value="0.2, 0.4, 0.6"/></bsdf>
    <shape type="sphere" id="ball">
        <bsdf type="twosided" id="metal">
            <bsdf type="roughconductor">
                <string name="distribution" value="$dist"/>
                <float name="alpha" value="$rough"/>
                <rgb name="eta" value="0.2, 0.92, 1.1"/>
                <rgb name="k" value="3.9 2.45 2.14"/>
            </bsdf>
        </bsdf>
    </shape>""",
    )
    first = read(p)
    assert (first.name, first.model, first.index) == ("wall", "mitsuba3:diffuse", 0)
    assert first.constants == {"reflectance": [0.2, 0.4, 0.6]}
    for key in ("metal", 1):
        a = read(p, key)
        assert a.name == "metal" and a.model == "mitsuba3:roughconductor"
        assert a.constants == {
            "distribution": "ggx",
            "alpha": 0.25,
            "material": "custom",
            "eta": [0.2, 0.92, 1.1],
            "k": [3.9, 2.45, 2.14],
        }
        assert any("twosided" in n for n in a.notes)
        m = a.material()
        assert float(m.values["alpha"][0]) == 0.25 and m.options["distribution"] == "ggx"
    # a shape's anonymous BSDF is named after the shape; a reference to a top-level texture is followed
    p2 = scene_xml(
        tmp_path,
        """
    <texture type="bitmap" id="tex"><string name="filename" value="r.exr"/></texture>
    <shape type="cube" id="box"><bsdf type="diffuse"><ref name="reflectance" id="tex"/></bsdf></shape>""",
        "b.xml",
    )
    exr(tmp_path / "r.exr", np.full((4, 4, 3), 0.3, np.float32))
    b = read(p2)
    assert b.name == "box/bsdf" and b.textures["reflectance"].path == (tmp_path / "r.exr").resolve()


def test_conductor_defaults_and_named_material(tmp_path):
    p = scene_xml(
        tmp_path,
        """
    <bsdf type="roughconductor" id="mirror"/>
    <bsdf type="roughconductor" id="gold"><string name="material" value="Au"/>
        <float name="alpha_u" value="0.3"/><float name="alpha_v" value="0.3"/></bsdf>""",
    )
    assert read(p, "mirror").constants == {"material": "none"}  # Mitsuba's default: a perfect mirror
    gold = read(p, "gold")
    assert gold.constants == {"material": "Au", "alpha": 0.3}
    assert gold.material().options["material"] == "Au"


def test_roughplastic_named_iors_and_legacy_names(tmp_path):
    p = scene_xml(
        tmp_path,
        """
    <bsdf type="roughplastic" id="p">
        <string name="int_ior" value="bk7"/><string name="ext_ior" value="Water"/>
        <boolean name="nonlinear" value="true"/><float name="alpha" value="0.05"/>
        <rgb name="diffuse_reflectance" value="0.5"/>
    </bsdf>""",
    )
    a = read(p)
    assert a.constants["int_ior"] == 1.5046 and a.constants["ext_ior"] == 1.333
    assert a.constants["nonlinear"] == "true" and a.constants["diffuse_reflectance"] == 0.5
    assert any("bk7" in n for n in a.notes)
    m = a.material()
    assert np.allclose(m.values["diffuse_reflectance"], 0.5) and m.options["nonlinear"] == "true"
    # a Mitsuba 0.6 file: camelCase names
    old = scene_xml(
        tmp_path,
        """
    <bsdf type="roughplastic"><float name="intIOR" value="1.6"/>
        <rgb name="diffuseReflectance" value="0.1, 0.2, 0.3"/></bsdf>""",
        "old.xml",
        version="0.6.0",
    )
    o = read(old)
    assert o.constants == {"int_ior": 1.6, "diffuse_reflectance": [0.1, 0.2, 0.3]}
    assert "snake_case" in o.notes[0]


@needs_mitsuba
def test_ior_table_is_mitsubas():
    import mitsuba as mi

    if mi.variant() is None:
        mi.set_variant("scalar_rgb")
    for name, value in IOR_TABLE.items():
        props = mi.Properties()
        props["x"] = name
        assert mi.lookup_ior(props, "x", 1.0) == pytest.approx(value, abs=1e-6), name


def test_principled_eta_and_a_bare_bsdf(tmp_path):
    p = tmp_path / "bsdf.xml"
    p.write_text(
        '<bsdf version="3.0.0" type="principled" id="car"><rgb name="base_color" value="0.8, 0.1, 0.1"/>'
        '<float name="eta" value="1.5"/><float name="metallic" value="0.2"/></bsdf>'
    )
    a = read(p)
    assert a.name == "car" and a.model == "mitsuba3:principled"
    assert a.constants["specular"] == pytest.approx(0.04 / 0.08)  # F0 of 1.5 is 0.04
    assert a.material().values["metallic"][0] == 0.2


def test_bitmaps_raw_vs_srgb_normalmap_and_bumpmap(tmp_path):
    rng = np.random.default_rng(1)
    colour = rng.uniform(0.05, 0.9, (8, 8, 3)).astype(np.float32)
    png(tmp_path / "albedo.png", colour, "srgb")
    png(tmp_path / "rough.png", np.full((8, 8, 1), 0.5, np.float32), "linear")
    png(tmp_path / "rough_srgb.png", np.full((8, 8, 1), 0.5, np.float32), "linear")
    exr(tmp_path / "spec.exr", np.full((8, 8, 3), 0.7, np.float32))
    png(tmp_path / "nrm.png", np.tile(np.array([0.5, 0.5, 1.0], np.float32), (8, 8, 1)), "linear")
    sub = tmp_path / "maps"
    sub.mkdir()
    png(sub / "bump.png", np.full((8, 8, 1), 0.5, np.float32), "linear")
    p = scene_xml(
        tmp_path,
        """
    <bsdf type="bumpmap" id="bumpy">
        <texture type="bitmap" name="bumpmap"><string name="filename" value="maps/bump.png"/></texture>
        <bsdf type="normalmap">
            <texture type="bitmap" name="normalmap"><string name="filename" value="nrm.png"/>
                <boolean name="raw" value="true"/></texture>
            <bsdf type="roughconductor">
                <texture type="bitmap" name="alpha"><string name="filename" value="rough.png"/>
                    <boolean name="raw" value="true"/></texture>
                <texture type="bitmap" name="specular_reflectance"><string name="filename" value="spec.exr"/>
                </texture>
            </bsdf>
        </bsdf>
    </bsdf>
    <bsdf type="diffuse" id="painted">
        <texture type="bitmap" name="reflectance"><string name="filename" value="albedo.png"/></texture>
    </bsdf>
    <bsdf type="roughconductor" id="srgb_alpha">
        <texture type="bitmap" name="alpha"><string name="filename" value="rough_srgb.png"/></texture>
    </bsdf>""",
    )
    a = read(p, "bumpy")
    assert a.textures["alpha"].colorspace == "linear"  # raw
    assert a.textures["specular_reflectance"].colorspace == "linear"  # a float file is linear, raw or not
    # the outermost wrapper's normal is kept: the bump map baked into a normal map (flat height: a flat normal)
    assert a.normal is not None and a.normal.path == (sub / "bump.png").resolve() and a.normal.bake is not None
    assert np.allclose(a.normal.bake(), [0.5, 0.5, 1.0], atol=1e-6)
    assert any("bumpmap wrapper" in n for n in a.notes) and any(
        "second normalmap wrapper was dropped" in n for n in a.notes
    )
    assert read(p, "painted").textures["reflectance"].colorspace == "srgb"  # 8-bit, not raw: Mitsuba decodes sRGB
    assert read(p, "srgb_alpha").textures["alpha"].colorspace == "srgb"  # for scalar parameters too
    maps = load_map_set(read(p, "painted").to_map_set(tmp_path / "ms"))
    got, _ = read_image(maps.maps["reflectance"], maps.colorspace["reflectance"])
    assert np.allclose(got, colour, atol=0.01)


# -- errors ------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "text, words",
    [
        ("this is not xml <", "not valid XML"),
        ('<?xml version="1.0"?><materialx version="1.39"/>', "not a Mitsuba scene"),
        ('<scene version="3.0.0"><shape type="sphere"/></scene>', "holds no <bsdf>"),
        (
            '<scene version="3.0.0"><bsdf type="roughdielectric"><float name="alpha_u" value="0.1"/>'
            '<float name="alpha_v" value="0.3"/></bsdf></scene>',
            "anisotropic roughness (alpha_u 0.1, alpha_v 0.3) is not supported for a roughdielectric",
        ),
        (
            '<scene version="3.0.0"><bsdf type="dielectric"><texture type="bitmap" name="specular_transmittance">'
            '<string name="filename" value="t.png"/></texture></bsdf></scene>',
            "a textured glass is not converted",
        ),
        (
            '<scene version="3.0.0"><bsdf type="dielectric"><float name="int_ior" value="1.5"/>'
            '<float name="ext_ior" value="1.5"/></bsdf></scene>',
            "Mitsuba 3 refuses equal IORs",
        ),
        (
            '<scene version="3.0.0"><bsdf type="diffuse"><float name="roughness" value="0.1"/></bsdf></scene>',
            "unknown parameter(s) roughness",
        ),
        ('<scene version="3.0.0"><bsdf type="diffuse"><rgb name="reflectance" value="$c"/></bsdf></scene>', "$c"),
        (
            '<scene version="3.0.0"><bsdf type="roughconductor"><float name="alpha_u" value="0.1"/></bsdf></scene>',
            "give alpha, or alpha_u and alpha_v together",
        ),
        (
            '<scene version="3.0.0"><bsdf type="roughplastic">'
            '<string name="int_ior" value="unobtainium"/></bsdf></scene>',
            "named IORs",
        ),
        (
            '<scene version="3.0.0"><bsdf type="roughconductor"><string name="material" value="Kryptonite"/></bsdf>'
            "</scene>",
            "Mitsuba's conductors",
        ),
        (
            '<scene version="3.0.0"><bsdf type="diffuse"><texture type="bitmap" name="reflectance">'
            '<string name="filename" value="gone.png"/></texture></bsdf></scene>',
            "bitmap reflectance 'gone.png' not found",
        ),
        (
            '<scene version="3.0.0"><bsdf type="diffuse"><texture type="mesh_attribute" name="reflectance"/>'
            "</bsdf></scene>",
            "'mesh_attribute' texture; matremap reads bitmap and checkerboard textures",
        ),
        (
            '<scene version="3.0.0"><bsdf type="diffuse"><rgb name="reflectance" value="1.5"/></bsdf></scene>',
            "outside its range",
        ),
    ],
)
def test_bad_inputs_say_what_is_wrong(tmp_path, text, words):
    p = tmp_path / "bad.xml"
    p.write_text(text)
    with pytest.raises(MatremapError) as e:
        read(p)
    assert words in str(e.value) and str(p) in str(e.value)


def test_unknown_material_lists_the_names(tmp_path):
    p = scene_xml(tmp_path, '<bsdf type="diffuse" id="a"/><bsdf type="diffuse" id="b"/>')
    with pytest.raises(MatremapError, match="no BSDF named 'c'; its BSDFs are 'a', 'b'"):
        read(p, "c")
    with pytest.raises(MatremapError, match="index 5 is out of range"):
        read(p, 5)


def test_writer_refuses_and_writes_nothing(tmp_path):
    out = tmp_path / "out.xml"
    with pytest.raises(MatremapError, match="writes mitsuba3:diffuse, mitsuba3:roughconductor"):
        write(out, Material.create("gltf:metal-rough"))
    with pytest.raises(MatremapError, match="Material or a MapSet"):
        write(out, {"model": "mitsuba3:diffuse"})
    assert list(tmp_path.iterdir()) == []
    write(out, Material.create("mitsuba3:diffuse"))
    before = out.read_text()
    with pytest.raises(MatremapError, match="already exists"):
        write(out, Material.create("mitsuba3:diffuse", {"reflectance": 0.9}))
    assert out.read_text() == before
    write(out, Material.create("mitsuba3:diffuse", {"reflectance": 0.9}), force=True)
    assert read(out).constants["reflectance"] == [0.9, 0.9, 0.9]


# -- round trips -------------------------------------------------------------------------------------

MATERIALS = [
    Material.create("mitsuba3:diffuse", {"reflectance": [0.1, 0.2, 0.30000000000000004]}),
    Material.create(
        "mitsuba3:roughconductor",
        {
            "alpha": 0.123456789,
            "eta": [0.2, 0.92, 1.1],
            "k": [3.9, 2.45, 2.14],
            "distribution": "ggx",
            "specular_reflectance": [1.0, 0.9, 0.8],
        },
    ),
    Material.create("mitsuba3:roughconductor", {"material": "Cu", "alpha": 0.3}),
    Material.create(
        "mitsuba3:roughplastic",
        {"alpha": 0.07, "int_ior": 1.6, "ext_ior": 1.1, "nonlinear": "true", "diffuse_reflectance": [0.5, 0.25, 0.125]},
    ),
    Material.create(
        "mitsuba3:principled",
        {
            "base_color": [0.7, 0.3, 0.1],
            "roughness": 0.4,
            "metallic": 0.6,
            "specular": 0.3,
            "sheen": 0.1,
            "clearcoat": 0.2,
        },
    ),
]


@pytest.mark.parametrize("m", MATERIALS, ids=lambda m: m.model + "," + m.options.get("material", ""))
def test_uniform_round_trip(tmp_path, m):
    out = write(tmp_path / "m.xml", m)
    a = read(out)
    assert a.name == "material" and a.material() == m and not a.textures


def make_map_set(tmp_path: Path) -> Path:
    rng = np.random.default_rng(0)
    d = tmp_path / "maps"
    d.mkdir()
    png(d / "colour.png", rng.uniform(0.05, 0.95, (16, 16, 3)).astype(np.float32), "srgb")
    exr(d / "rough.exr", rng.uniform(0.05, 0.6, (16, 16, 1)).astype(np.float32))
    png(d / "normal.png", np.tile(np.array([0.5, 0.5, 1.0], np.float32), (16, 16, 1)), "linear")
    (d / "material.json").write_text(
        '{"model": "mitsuba3:roughconductor", "maps": {"specular_reflectance": '
        '"colour.png", "alpha": "rough.exr"}, "normal": "normal.png", '
        '"params": {"distribution": "ggx", "material": "Au"}}'
    )
    return d


def test_map_set_round_trip(tmp_path):
    ms = load_map_set(make_map_set(tmp_path))
    (tmp_path / "out").mkdir()
    out = write(tmp_path / "out" / "scene.xml", ms)
    a = read(out)
    assert a.constants == {"distribution": "ggx", "material": "Au"}
    assert set(a.textures) == {"specular_reflectance", "alpha"}
    assert a.textures["specular_reflectance"].colorspace == "srgb" and a.textures["alpha"].colorspace == "linear"
    for name in a.textures:
        assert a.textures[name].path.parent == out.parent  # copied beside the XML
        back, _ = read_image(a.textures[name].path, a.textures[name].colorspace)
        orig, _ = read_image(ms.maps[name], ms.colorspace[name])
        assert np.array_equal(back, orig)
    assert a.normal is not None and a.normal.path.read_bytes() == ms.normal.read_bytes()
    root = ET.parse(out).getroot()
    wrapper = root.find("bsdf")
    assert wrapper.get("type") == "normalmap" and wrapper.get("id") == "material"
    assert wrapper.find("texture/boolean").get("value") == "true"  # normal maps are raw
    with pytest.raises(MatremapError, match="already exists"):
        write(out, ms)


def test_writer_converts_what_mitsuba_would_misread(tmp_path):
    d = tmp_path / "maps"
    d.mkdir()
    # a linear-encoded colour PNG: Mitsuba would decode it as sRGB unless converted
    png(d / "lin.png", np.full((4, 4, 3), 0.25, np.float32), "linear")
    png(d / "grey_rgb.png", np.full((4, 4, 3), 0.4, np.float32), "linear")  # RGB file for a scalar
    (d / "material.json").write_text(
        '{"model": "mitsuba3:roughconductor", "maps": {"specular_reflectance": '
        '"lin.png", "alpha": "grey_rgb.png"}, "colorspace": {"lin.png": "linear"}}'
    )
    ms = load_map_set(d)
    out = write(tmp_path / "s.xml", ms)
    a = read(out)
    for name, value in (("specular_reflectance", 0.25), ("alpha", 0.4)):
        assert a.textures[name].path.suffix == ".exr"
        img, info = read_image(a.textures[name].path, a.textures[name].colorspace)
        assert np.allclose(img, value, atol=0.003) and info.channels == (3 if name != "alpha" else 1)
    with pytest.raises(MatremapError, match="alpha as a number"):
        (d / "material.json").write_text('{"model": "mitsuba3:roughplastic", "maps": {"alpha": "grey_rgb.png"}}')
        write(tmp_path / "p.xml", load_map_set(d))
    assert not (tmp_path / "p.xml").exists() and not list(tmp_path.glob("p_*"))


# -- real Mitsuba 3 ------------------------------------------------------------------------------------


def _mitsuba():
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    return mi


def _as_probe_scene(xml: Path, scene: Scene, out: Path) -> Path:
    """The written scene with matremap's probe lighting: one point light at the camera, the direct
    integrator with one emitter sample, one centre ray per pixel (as Mitsuba3Renderer does)."""
    tree = ET.parse(xml)
    root = tree.getroot()
    for tag in ("emitter", "integrator"):
        for el in root.findall(tag):
            root.remove(el)
    integrator = ET.SubElement(root, "integrator", {"type": "direct"})
    ET.SubElement(integrator, "integer", {"name": "emitter_samples", "value": "1"})
    ET.SubElement(integrator, "integer", {"name": "bsdf_samples", "value": "0"})
    sensor = root.find("sensor")
    sensor.remove(sensor.find("sampler"))
    sampler = ET.SubElement(sensor, "sampler", {"type": "stratified"})
    ET.SubElement(sampler, "integer", {"name": "sample_count", "value": "1"})
    ET.SubElement(sampler, "boolean", {"name": "jitter", "value": "false"})
    light = scene.lights[0]
    x, y, z = scene.light_position(light)
    emitter = ET.SubElement(root, "emitter", {"type": "point"})
    ET.SubElement(emitter, "point", {"name": "position", "x": repr(float(x)), "y": repr(float(y)), "z": repr(float(z))})
    ET.SubElement(emitter, "rgb", {"name": "intensity", "value": repr(float(scene.light_intensity(light)))})
    tree.write(out)
    return out


@needs_mitsuba
def test_written_conductor_renders_as_matremaps_mitsuba3_renderer(tmp_path):
    from matremap.renderers.mitsuba3.probe import Mitsuba3Renderer

    mi = _mitsuba()
    m = MATERIALS[1]
    xml = write(tmp_path / "m.xml", m)
    scene = Scene.probe([20.0], resolution=48)
    probe = _as_probe_scene(xml, scene, tmp_path / "probe.xml")
    img = np.asarray(mi.render(mi.load_file(str(probe), resolution=scene.resolution), spp=1, seed=0))[..., :3]
    ref = Mitsuba3Renderer().render([m], scene)[0]
    mask = scene.mask()
    assert ref[mask].mean() > 0.05
    assert np.linalg.norm(img[mask] - ref[mask]) / np.linalg.norm(ref[mask]) < 1e-4
    assert np.abs(img[~mask]).max() < 1e-6
    # a different alpha draws a different image, so the comparison above is not vacuous
    other = Mitsuba3Renderer().render([m.with_params({"alpha": 0.3})], scene)[0]
    assert np.linalg.norm(other[mask] - ref[mask]) / np.linalg.norm(ref[mask]) > 0.05


@needs_mitsuba
def test_written_scenes_render_as_they_are(tmp_path):
    mi = _mitsuba()
    means = []
    for alpha in (0.05, 0.5):
        m = Material.create("mitsuba3:roughplastic", {"alpha": alpha, "diffuse_reflectance": 0.2})
        xml = write(tmp_path / f"a{alpha}.xml", m)
        img = np.asarray(mi.render(mi.load_file(str(xml), resolution=24, spp=16), seed=0))
        assert img.shape == (24, 24, 3) and np.all(np.isfinite(img))
        means.append(float(img.mean()))
    assert means[0] > 0.02 and abs(means[0] - means[1]) > 1e-3
    # a uniform white Lambertian under the unit white environment reflects 1 (the sphere is convex)
    xml = write(tmp_path / "white.xml", Material.create("mitsuba3:diffuse", {"reflectance": 1.0}))
    img = np.asarray(mi.render(mi.load_file(str(xml), resolution=32, spp=64), seed=0))
    centre = img[12:20, 12:20]
    assert abs(float(centre.mean()) - 1.0) < 0.01 and np.allclose(centre, 1.0, atol=0.1)


@needs_mitsuba
def test_written_map_set_renders(tmp_path):
    mi = _mitsuba()
    ms = load_map_set(make_map_set(tmp_path))
    xml = write(tmp_path / "t.xml", ms)
    img = np.asarray(mi.render(mi.load_file(str(xml), resolution=24, spp=8), seed=0))
    assert np.all(np.isfinite(img)) and img.mean() > 0.02


def test_mitsuba_probe_lights_match_scene_conventions():
    # the probe light intensity the renderer test relies on
    s = Scene.probe([0.0])
    assert s.light_intensity(s.lights[0]) == pytest.approx(math.pi * 36.0)
    assert mitsuba_xml.MODELS == (
        "mitsuba3:diffuse",
        "mitsuba3:roughconductor",
        "mitsuba3:roughconductor-anisotropic",
        "mitsuba3:roughplastic",
        "mitsuba3:principled",
        "mitsuba3:dielectric",
        "mitsuba3:roughdielectric",
        "mitsuba3:thindielectric",
    )


def test_a_map_that_fails_after_another_was_placed_leaves_nothing(tmp_path):
    ms = load_map_set(make_map_set(tmp_path))
    ms.maps["alpha"].write_bytes(b"not an EXR any more")  # read after specular_reflectance is placed
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "scene.xml").write_text("old")
    with pytest.raises(MatremapError):
        write(tmp_path / "out" / "scene.xml", ms, force=True)
    assert [p.name for p in (tmp_path / "out").iterdir()] == ["scene.xml"]  # no maps, no staging folder
    assert (tmp_path / "out" / "scene.xml").read_text() == "old"
