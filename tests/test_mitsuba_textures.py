"""Mitsuba 3 textures and plugins read as the renderer sees them, each compared with Mitsuba 3 itself where
installed: bitmaps with to_uv / wrap_mode / raw, an RGB image driving a scalar (luminance), the procedural
checkerboard (and its eval/eval_1 swap), spectra as wavelength:value lists, smooth conductor and plastic at
the mirror limit, bumpmap baked into a normal map, mask opacity carried, blendbsdf blended texel by texel."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from matremap.errors import MatremapError
from matremap.formats import read_asset
from matremap.formats.bake import texel_grid
from matremap.formats.spectra import spectrum_to_srgb
from matremap.svbrdf.textures import ImageInfo, write_image_like

needs_mitsuba = pytest.mark.skipif(
    importlib.util.find_spec("mitsuba") is None, reason="Mitsuba 3 not installed: pip install 'matremap[mitsuba]'"
)


def mi_scalar():
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    return mi


def scene(tmp_path: Path, body: str, name: str = "s.xml") -> Path:
    p = tmp_path / name
    p.write_text(f'<scene version="3.0.0">{body}</scene>')
    return p


def image(path: Path, values: np.ndarray, kind: str = "exr", colorspace: str = "linear") -> Path:
    info = ImageInfo(kind, "float" if kind == "exr" else "uint8", values.shape[-1], 0, 0, colorspace)
    return write_image_like(path, values.astype(np.float32), info, force=True)


def mitsuba_texture_at(texture_xml: str, size: tuple[int, int], scalar: bool) -> np.ndarray:
    """Mitsuba's own texture evaluated at the texel centres of a map of ``size`` (uv origin: top left)."""
    mi = mi_scalar()
    tex = mi.load_string(texture_xml.replace("<texture ", '<texture version="3.0.0" ', 1))
    s, t = texel_grid(size)
    si = mi.SurfaceInteraction3f()
    out = np.zeros((*size, 1 if scalar else 3))
    for j in range(size[0]):
        for i in range(size[1]):
            si.uv = mi.Point2f(float(s[j, i]), float(t[j, i]))
            out[j, i] = tex.eval_1(si) if scalar else np.asarray(tex.eval(si)).reshape(-1)
    return out


TO_UV = """<transform name="to_uv"><scale x="2.5" y="1.5"/><rotate z="1" angle="30"/>
    <translate x="0.2" y="-0.35"/></transform>"""


@needs_mitsuba
@pytest.mark.parametrize("wrap", ["repeat", "mirror", "clamp"])
def test_bitmap_to_uv_and_wrap_baked_as_mitsuba_samples_it(tmp_path, wrap):
    rng = np.random.default_rng(3)
    img = image(tmp_path / "c.exr", rng.uniform(0.0, 1.0, (6, 5, 3)))
    tex = (
        f'<texture type="bitmap" name="reflectance"><string name="filename" value="{img}"/>'
        f'<string name="wrap_mode" value="{wrap}"/>{TO_UV}</texture>'
    )
    a = read_asset(scene(tmp_path, f'<bsdf type="diffuse">{tex}</bsdf>'))
    ref = a.textures["reflectance"]
    assert ref.bake is not None and any("to_uv" in n for n in a.notes)
    ours = ref.bake()
    assert ours.shape == (6, 5, 3)
    theirs = mitsuba_texture_at(tex, (6, 5), scalar=False)
    assert np.abs(ours - theirs).max() < 1e-5
    assert (
        np.abs(ours - np.asarray(__import__("matremap.svbrdf.textures", fromlist=["x"]).read_image(img)[0])).max() > 0.1
    )


@needs_mitsuba
def test_a_4x4_matrix_and_a_scalar_parameter_read_luminance(tmp_path):
    rng = np.random.default_rng(4)
    img = image(tmp_path / "c.png", rng.uniform(0.0, 1.0, (8, 8, 3)), "png", "srgb")
    to_uv = '<transform name="to_uv"><matrix value="1 0.5 0 0.25  0 2 0 0.1  0 0 1 0  0 0 0 1"/></transform>'
    tex = f'<texture type="bitmap" name="alpha"><string name="filename" value="{img}"/>{to_uv}</texture>'
    a = read_asset(scene(tmp_path, f'<bsdf type="roughconductor">{tex}</bsdf>'))
    ours = a.textures["alpha"].bake()
    theirs = mitsuba_texture_at(tex, (8, 8), scalar=True)
    assert ours.shape == (8, 8, 1) and np.abs(ours - theirs).max() < 1e-5
    assert any("luminance" in n for n in a.notes)
    # raw: the code values as they are, no sRGB decoding
    raw = tex.replace("</texture>", '<boolean name="raw" value="true"/></texture>')
    b = read_asset(scene(tmp_path, f'<bsdf type="roughconductor">{raw}</bsdf>', "raw.xml"))
    assert np.abs(b.textures["alpha"].bake() - mitsuba_texture_at(raw, (8, 8), scalar=True)).max() < 1e-5


@needs_mitsuba
def test_checkerboard_baked_with_mitsubas_colour_and_scalar_patterns(tmp_path):
    tex = (
        '<texture type="checkerboard" name="{name}"><rgb name="color0" value="0.9, 0.2, 0.1"/>'
        '<float name="color1" value="0.05"/><transform name="to_uv"><scale value="3"/></transform></texture>'
    )
    a = read_asset(
        scene(
            tmp_path,
            f'<bsdf type="roughconductor">{tex.format(name="specular_reflectance")}{tex.format(name="alpha")}</bsdf>',
        )
    )
    assert any("procedural textures baked at 512x512" in n for n in a.notes)
    colour, scalar = a.textures["specular_reflectance"].bake(), a.textures["alpha"].bake()
    assert colour.shape == (512, 512, 3) and scalar.shape == (512, 512, 1)
    step = 16  # compare Mitsuba on a sub-grid of texel centres
    s, t = texel_grid((512, 512))
    mi = mi_scalar()
    for name, ours, is_scalar in (("specular_reflectance", colour, False), ("alpha", scalar, True)):
        m = mi.load_string(tex.format(name=name).replace("<texture ", '<texture version="3.0.0" ', 1))
        si = mi.SurfaceInteraction3f()
        for j in range(0, 512, step):
            for i in range(0, 512, step):
                si.uv = mi.Point2f(float(s[j, i]), float(t[j, i]))
                want = m.eval_1(si) if is_scalar else np.asarray(m.eval(si)).reshape(-1)
                assert np.allclose(ours[j, i], want, atol=1e-6), (name, j, i)
    # Mitsuba's eval_1 takes the other colour where eval takes color0: the patterns are swapped
    assert np.isclose(colour[0, 0, 0], 0.9) and np.isclose(scalar[0, 0, 0], 0.05)


def test_other_procedurals_are_refused_naming_them(tmp_path):
    p = scene(tmp_path, '<bsdf type="diffuse"><texture type="volume" name="reflectance"/></bsdf>')
    with pytest.raises(MatremapError, match="'volume' texture; matremap reads bitmap and checkerboard"):
        read_asset(p)


@needs_mitsuba
@pytest.mark.parametrize("variant", ["scalar_rgb", "llvm_ad_rgb"])
def test_spectra_become_the_rgb_mitsuba_makes_of_them(tmp_path, variant):
    import mitsuba as mi

    try:
        mi.set_variant(variant)
    except Exception as e:  # noqa: BLE001 - llvm may be missing
        pytest.skip(f"{variant} unavailable: {e}")
    pairs = "400:0.1, 450:0.3, 500:0.6, 550:0.5, 600:0.4, 650:0.8, 700:0.2"
    eta_pairs = "380:0.6, 500:3.3, 620:0.9, 780:0.45"
    body = (
        f'<bsdf type="diffuse" id="d"><spectrum name="reflectance" value="{pairs}"/></bsdf>'
        f'<bsdf type="roughconductor" id="c"><spectrum name="eta" value="{eta_pairs}"/>'
        '<spectrum name="k" value="3.0"/></bsdf><shape type="sphere"><ref id="d"/></shape>'
        '<shape type="sphere"><ref id="c"/></shape>'
    )
    p = scene(tmp_path, body)
    params = mi.traverse(mi.load_file(str(p), optimize=False))
    ours_d = read_asset(p, "d").constants["reflectance"]
    ours_c = read_asset(p, "c").constants
    assert np.allclose(ours_d, np.asarray(params["d.reflectance.value"]).reshape(-1), atol=2e-6)
    assert np.allclose(ours_c["eta"], np.asarray(params["c.eta.value"]).reshape(-1), rtol=2e-6)
    assert ours_c["k"] == 3.0
    # eta is unbounded (above 1), a reflectance bounded: the two conversions differ
    assert max(ours_c["eta"]) > 1.0
    assert np.allclose(spectrum_to_srgb([400, 700], [2.0, 2.0]), 1.0)


def test_a_spectrum_file_is_read_and_confined(tmp_path):
    (tmp_path / "r.spd").write_text("# wavelength value\n400 0.5\n550 0.5\n700 0.5\n")
    p = scene(tmp_path, '<bsdf type="diffuse"><spectrum name="reflectance" filename="r.spd"/></bsdf>')
    flat = read_asset(p).constants["reflectance"]
    assert np.allclose(flat, spectrum_to_srgb([400, 550, 700], [0.5] * 3))
    out = scene(tmp_path, '<bsdf type="diffuse"><spectrum name="reflectance" filename="../x.spd"/></bsdf>', "o.xml")
    with pytest.raises(MatremapError, match="points outside the asset folder"):
        read_asset(out)


def test_smooth_conductor_and_plastic_at_the_mirror_limit(tmp_path):
    p = scene(
        tmp_path,
        '<bsdf type="conductor" id="c"><string name="material" value="Au"/></bsdf>'
        '<bsdf type="plastic" id="p"><rgb name="diffuse_reflectance" value="0.3, 0.2, 0.1"/>'
        '<float name="int_ior" value="1.6"/></bsdf>',
    )
    c, pl = read_asset(p, "c"), read_asset(p, "p")
    assert (c.model, c.constants) == (
        "mitsuba3:roughconductor",
        {"alpha": 1e-4, "distribution": "ggx", "material": "Au"},
    )
    assert pl.model == "mitsuba3:roughplastic" and pl.constants["alpha"] == 1e-4 and pl.constants["int_ior"] == 1.6
    assert all(any("mirror limit" in n for n in a.notes) for a in (c, pl))


@needs_mitsuba
def test_smooth_plastic_renders_as_roughplastic_at_alpha_1e_4(tmp_path):
    """What the reading rests on: under a point light Mitsuba's plastic and roughplastic (GGX) at alpha 1e-4
    agree within 1.9 % relative RMSE."""
    mi = mi_scalar()

    def render(bsdf: dict) -> np.ndarray:
        s = mi.load_dict(
            {
                "type": "scene",
                "integrator": {"type": "direct", "emitter_samples": 1, "bsdf_samples": 0},
                "sensor": {
                    "type": "perspective",
                    "fov": 30,
                    "to_world": mi.ScalarTransform4f().look_at([0, 0, 8], [0, 0, 0], [0, 1, 0]),
                    "film": {"type": "hdrfilm", "width": 24, "height": 24, "rfilter": {"type": "box"}},
                    "sampler": {"type": "independent", "sample_count": 4},
                },
                "light": {"type": "point", "position": [3, 3, 8], "intensity": {"type": "rgb", "value": 100}},
                "ball": {"type": "sphere", "radius": 2, "bsdf": bsdf},
            }
        )
        return np.asarray(mi.render(s, seed=0))

    common = {"diffuse_reflectance": {"type": "rgb", "value": [0.5, 0.3, 0.2]}, "int_ior": 1.6}
    smooth = render({"type": "plastic", **common})
    rough = render({"type": "roughplastic", "alpha": 1e-4, "distribution": "ggx", **common})
    assert smooth.mean() > 0.05
    assert np.linalg.norm(smooth - rough) / np.linalg.norm(smooth) < 0.025  # measured 1.9 %


def bump_scene(tmp_path: Path, height: np.ndarray, scale: float) -> Path:
    image(tmp_path / "h.exr", height[..., None])
    return scene(
        tmp_path,
        f'<bsdf type="bumpmap" id="b"><float name="scale" value="{scale}"/>'
        '<texture type="bitmap"><string name="filename" value="h.exr"/></texture>'
        '<bsdf type="diffuse"/></bsdf>',
    )


def test_bumpmap_bakes_the_normal_mitsuba_derives_from_the_height(tmp_path):
    w = 16
    ramp = np.tile(np.arange(w, dtype=np.float32) / w, (w, 1))  # height grows along u by 1 per unit of u
    a = read_asset(bump_scene(tmp_path, ramp, 0.5))
    n = a.normal.bake() * 2.0 - 1.0
    inner = n[:, 2:-2]  # away from the wrap-around seam
    # dh/du = 1, scale 0.5: n = normalize(-0.5, 0, 1), tilted against the slope
    assert np.allclose(inner, np.array([-0.5, 0.0, 1.0]) / np.sqrt(1.25), atol=1e-5)
    down = read_asset(bump_scene(tmp_path, ramp.T.copy(), 2.0)).normal.bake() * 2.0 - 1.0
    # height growing down the image (along v) tilts the normal towards the image's top (+t, green up)
    assert np.allclose(down[2:-2], np.array([0.0, 2.0, 1.0]) / np.sqrt(5.0), atol=1e-5)
    assert any("bumpmap wrapper" in x and "scale 0.5" in x for x in a.notes)


def test_mask_opacity_is_carried(tmp_path):
    image(tmp_path / "o.exr", np.full((4, 4, 1), 0.25))
    p = scene(
        tmp_path,
        '<bsdf type="mask" id="leaf"><texture type="bitmap" name="opacity"><string name="filename" value="o.exr"/>'
        '</texture><bsdf type="diffuse"><rgb name="reflectance" value="0.2, 0.6, 0.1"/></bsdf></bsdf>'
        '<bsdf type="mask" id="half"><bsdf type="diffuse"/></bsdf>',
    )
    leaf, half = read_asset(p, "leaf"), read_asset(p, "half")
    assert leaf.constants == {"reflectance": [0.2, 0.6, 0.1]}
    op = leaf.carried["opacity"]
    assert op.settings["mode"] == "blend" and op.texture is not None and op.texture.path.name == "o.exr"
    assert half.carried["opacity"].value == 0.5 and half.carried["opacity"].texture is None  # Mitsuba's default


def test_blendbsdf_of_one_model_is_blended_texel_by_texel(tmp_path):
    image(tmp_path / "w.exr", np.tile(np.linspace(0, 1, 8, dtype=np.float32), (8, 1))[..., None])
    weight = '<texture type="bitmap" name="weight"><string name="filename" value="w.exr"/></texture>'
    p = scene(
        tmp_path,
        f'<bsdf type="blendbsdf" id="mix">{weight}'
        '<bsdf type="roughconductor"><rgb name="specular_reflectance" value="0.8, 0.1, 0.1"/></bsdf>'
        '<bsdf type="roughconductor"><rgb name="specular_reflectance" value="0.1, 0.1, 0.8"/>'
        '<float name="alpha" value="0.3"/></bsdf></bsdf>'
        '<bsdf type="blendbsdf" id="uniform"><float name="weight" value="0.25"/><bsdf type="diffuse"/>'
        '<bsdf type="diffuse"><rgb name="reflectance" value="0.9"/></bsdf></bsdf>'
        '<bsdf type="blendbsdf" id="two"><float name="weight" value="0.5"/><bsdf type="diffuse"/>'
        '<bsdf type="roughconductor"/></bsdf>'
        f'<bsdf type="blendbsdf" id="plastics">{weight}<bsdf type="roughplastic"/>'
        '<bsdf type="roughplastic"><float name="alpha" value="0.3"/></bsdf></bsdf>',
    )
    mix = read_asset(p, "mix")
    refl = mix.textures["specular_reflectance"].bake()
    w = np.linspace(0, 1, 8)
    assert np.allclose(refl[3, :, 0], 0.8 * (1 - w) + 0.1 * w, atol=1e-6)
    assert np.allclose(refl[3, :, 2], 0.1 * (1 - w) + 0.8 * w, atol=1e-6)
    assert np.allclose(mix.textures["alpha"].bake()[0, :, 0], 0.1 * (1 - w) + 0.3 * w, atol=1e-6)
    assert any("alpha differ" in n for n in mix.notes) and mix.constants["material"] == "none"
    assert read_asset(p, "uniform").constants == {"reflectance": pytest.approx([0.5 * 0.75 + 0.9 * 0.25] * 3)}
    with pytest.raises(MatremapError, match="blendbsdf of a mitsuba3:diffuse and a mitsuba3:roughconductor"):
        read_asset(p, "two")
    with pytest.raises(MatremapError, match="differ in alpha, which Mitsuba takes as a number"):
        read_asset(p, "plastics")


@needs_mitsuba
def test_a_3x3_matrix_loses_its_translation_as_in_mitsuba(tmp_path):
    """A 9-value <matrix> fills the upper-left 3x3 of Mitsuba's 4x4; a texture keeps columns 0, 1 and 3."""
    rng = np.random.default_rng(5)
    img = image(tmp_path / "c.exr", rng.uniform(0.0, 1.0, (6, 6, 3)))
    to_uv = '<transform name="to_uv"><matrix value="1.5 0.2 0.3  -0.1 1.2 0.4  0 0 1"/></transform>'
    tex = f'<texture type="bitmap" name="reflectance"><string name="filename" value="{img}"/>{to_uv}</texture>'
    ours = read_asset(scene(tmp_path, f'<bsdf type="diffuse">{tex}</bsdf>')).textures["reflectance"].bake()
    assert np.abs(ours - mitsuba_texture_at(tex, (6, 6), scalar=False)).max() < 1e-5
