"""USD stages in and out (formats/usd.py), on public third-party files (tests/data/corpus/usd-*, licences in its
README) and on round trips. Written files are checked with pxr itself (Usd.Stage.Open, UsdShade, the
MaterialBindingAPI, asset paths resolved by Ar, UsdValidation's validators), textures with PIL and the sRGB
formula written out here, not with matremap's own reader where it matters."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from matremap.core.material import Material
from matremap.errors import MatremapError
from matremap.formats import material_names, read_asset, write_all, write_asset
from matremap.svbrdf.textures import load_map_set, read_image

pxr = pytest.importorskip("pxr", reason="USD needs usd-core: pip install 'matremap[usd]'")
from pxr import Sdf, Usd, UsdGeom, UsdShade  # noqa: E402

CORPUS = Path(__file__).resolve().parent / "data" / "corpus"
TRANSFORM = CORPUS / "usd-TextureTransformTest" / "TextureTransformTest.usd"
COORD = CORPUS / "usd-TextureCoordinateTest" / "TextureCoordinateTest.usda"
ROUGH = CORPUS / "usd-RoughnessTest" / "RoughnessTest.usdz"
BRASS = Path(__file__).resolve().parents[1] / "examples" / "brass-gltf" / "brass.gltf"


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("MATREMAP_CACHE", str(tmp_path / "cache"))


def srgb_decode(code: np.ndarray) -> np.ndarray:
    c = code / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def png(path: Path) -> np.ndarray:
    return np.asarray(Image.open(path).convert("RGBA"), dtype=float)


def validation_errors(path: Path) -> list[str]:
    """UsdValidation's errors on a stage (the successor of UsdUtils' compliance checker); shader ids of
    MaterialX nodes are unknown to usd-core's registry (no usdMtlx plugin) and are left out."""
    from pxr import UsdValidation

    ctx = UsdValidation.ValidationContext(UsdValidation.ValidationRegistry().GetOrLoadAllValidators())
    errors = ctx.Validate(Usd.Stage.Open(str(path)))
    return [
        f"{e.GetName()}: {e.GetMessage()}"
        for e in errors
        if not (e.GetName() == "MissingShaderIdInRegistry" and "'ND_" in e.GetMessage())
    ]


def surface(stage, material_path: str):
    shader, _, _ = UsdShade.Material(stage.GetPrimAtPath(material_path)).ComputeSurfaceSource()
    return shader


def connected(shader, name: str):
    """(upstream shader, its output name) feeding an input, or None."""
    sources, _ = shader.GetInput(name).GetConnectedSources()
    return (UsdShade.Shader(sources[0].source.GetPrim()), sources[0].sourceName) if sources else None


# ------------------------------------------------------------------------------------------------
# reading third-party files


def test_texture_transform_test_lists_its_materials_and_reads_the_specular_workflow_as_metalness():
    names = material_names(TRANSFORM)
    assert len(names) == 9 and "/TextureTransformTest/Materials/Offset_U_53148" in names
    a = read_asset(TRANSFORM, "Offset_U_53148")  # a unique prim name picks it too
    assert a.model == "usd:preview_surface" and a.name == names[0]
    # useSpecularWorkflow = 1 with specularColor 0 is the metalness workflow's dielectric with ior 1
    assert a.constants["useSpecularWorkflow"] == "0" and a.constants["ior"] == 1.0
    assert any("useSpecularWorkflow=1" in n for n in a.notes)


def test_the_specular_workflow_equivalence_renders_the_same():
    """The reader's claim, checked by drawing both: the file's specular-workflow material and what it reads."""
    from matremap.core.scene import PointLight, Scene
    from matremap.renderers import get_renderer

    base = {"diffuseColor": [0.4, 0.3, 0.2], "roughness": 0.45}
    as_written = Material.create("usd:preview_surface", {**base, "useSpecularWorkflow": "1", "specularColor": 0.05})
    a_ior = (1 + 0.05**0.5) / (1 - 0.05**0.5)
    as_read = Material.create("usd:preview_surface", {**base, "ior": a_ior})
    scene = Scene(resolution=48, lights=(PointLight(0.0), PointLight(60.0)))
    x, y = get_renderer("embedded").render([as_written, as_read], scene)
    np.testing.assert_allclose(x, y, rtol=1e-5, atol=1e-7)


@pytest.mark.parametrize(
    ("material", "expect"),
    [
        # st + (0.5, 0): the left half of the map is the image's right half
        ("Offset_U_53148", lambda img, h, w: (np.s_[:, : w // 2], img[:, w // 2 :])),
        # st + (0, -0.5) in USD's lower-left origin: the top half of the map is the image's bottom half
        ("Offset_V_53152", lambda img, h, w: (np.s_[: h // 2, :], img[h // 2 :, :])),
    ],
)
def test_usd_transform2d_is_baked_in_the_lower_left_st_origin(tmp_path, material, expect):
    a = read_asset(TRANSFORM, material)
    ref = a.textures["diffuseColor"]
    assert ref.bake is not None
    baked = np.asarray(ref.bake())
    image = srgb_decode(png(ref.path))[..., :3]
    h, w = image.shape[:2]
    where, want = expect(image, h, w)
    np.testing.assert_allclose(baked[where][..., :3], want, atol=2e-5)
    # and the map set matremap makes of it holds those values
    a.coverage = None  # the texture as read, every texel (not only those its plane shows: test_gltf_coverage.py)
    ms = load_map_set(a.to_map_set(tmp_path / "maps"))
    got, _ = read_image(ms.maps["diffuseColor"])
    np.testing.assert_allclose(got[where][..., :3], want, atol=1e-3)


def test_a_tinted_texture_keeps_its_per_channel_scale(tmp_path):
    """TextureCoordinateTest (CC-BY 4.0): the template's sRGB image times scale (0.8, 0.8, 0)."""
    a = read_asset(COORD, "TopLeftMat")
    ref = a.textures["diffuseColor"]
    assert ref.colorspace == "srgb" and ref.scale == pytest.approx((0.8, 0.8, 0.0))
    a.coverage = None  # the texture as read, every texel (not only those its plane shows: test_gltf_coverage.py)
    ms = load_map_set(a.to_map_set(tmp_path / "maps"))
    got, _ = read_image(ms.maps["diffuseColor"])
    want = srgb_decode(png(COORD.parent / "TextureCoordinateTemplate.png"))[..., :3] * [0.8, 0.8, 0.0]
    np.testing.assert_allclose(got[..., :3], want, atol=2e-3)
    assert read_asset(COORD, "BackPlaneMat").constants["diffuseColor"] == pytest.approx([0.16] * 3)


def test_a_usdz_member_is_extracted_to_the_private_cache_and_copied_into_the_map_set(tmp_path):
    """RoughnessTest (CC0): a usdz whose opacity comes from an alpha channel, roughness 0.33, metallic 0.6."""
    a = read_asset(ROUGH, "Const033")
    assert a.constants["roughness"] == pytest.approx(0.33) and a.constants["metallic"] == pytest.approx(0.6)
    ref = a.textures["diffuseColor"]
    assert ref.extracted and ref.path.is_relative_to(tmp_path / "cache")
    with Image.open(ref.path) as im:
        assert im.size[0] > 0
    opacity = a.carried["opacity"]
    assert opacity.texture is not None and opacity.texture.channels == (3,) and opacity.settings["mode"] == "blend"
    assert any("specular is not a UsdPreviewSurface input" in n for n in a.notes)
    manifest = json.loads((a.to_map_set(tmp_path / "maps") / "material.json").read_text())
    assert all("cache" not in str(v) for v in manifest["maps"].values())


def test_an_unreadable_texture_is_refused_in_one_line_naming_it(tmp_path):
    """A texture that is not an image (here, text named .png) is refused in one line naming the file. (A Targa
    texture, refused so until 2026-11-27, is read: tests/test_usd_roughness_test.py.)"""
    import shutil

    shutil.copy(COORD, tmp_path / COORD.name)
    (tmp_path / "TextureCoordinateTemplate.png").write_text("not an image")
    with pytest.raises(MatremapError) as e:
        read_asset(tmp_path / COORD.name, "BottomLeftMat")
    msg = str(e.value)
    assert "\n" not in msg and "TextureCoordinateTemplate.png" in msg and "not a readable image" in msg


# ------------------------------------------------------------------------------------------------
# round trips, checked in pxr


def test_uniform_materials_round_trip_in_every_container(tmp_path):
    m = Material.create(
        "usd:preview_surface",
        {"diffuseColor": [0.5, 0.2, 0.1], "roughness": 0.3, "metallic": 1.0, "clearcoat": 0.4, "ior": 1.7},
    )
    for suffix in (".usda", ".usdc", ".usdz"):
        out = write_asset(tmp_path / f"m{suffix}", m)
        stage = Usd.Stage.Open(str(out))
        mesh = next(p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh))
        bound, _ = UsdShade.MaterialBindingAPI(mesh).ComputeBoundMaterial()
        shader = surface(stage, str(bound.GetPath()))
        assert shader.GetIdAttr().Get() == "UsdPreviewSurface"
        assert shader.GetInput("clearcoat").Get() == pytest.approx(0.4)
        assert UsdGeom.PrimvarsAPI(mesh).GetPrimvar("st").Get() is not None
        back = read_asset(out).material()
        for k, v in m.values.items():
            np.testing.assert_allclose(back.values[k], v, rtol=1e-6, err_msg=f"{suffix} {k}")
        assert back.options == m.options
        assert validation_errors(out) == []


def test_a_map_set_round_trips_with_srgb_colour_and_raw_data_maps(tmp_path):
    src = read_asset(COORD, "TopRightMat")
    ms = load_map_set(src.to_map_set(tmp_path / "maps"))
    rough = np.linspace(0.2, 0.9, 64 * 64, dtype=np.float32).reshape(64, 64)
    Image.fromarray((rough * 255).round().astype(np.uint8)).resize((ms.size[1], ms.size[0])).save(
        tmp_path / "maps" / "roughness.png"
    )
    manifest = json.loads((tmp_path / "maps" / "material.json").read_text())
    manifest["maps"]["roughness"] = "roughness.png"
    manifest["params"].pop("roughness")
    manifest["colorspace"]["roughness"] = "linear"
    (tmp_path / "maps" / "material.json").write_text(json.dumps(manifest))
    ms = load_map_set(tmp_path / "maps")
    (tmp_path / "out").mkdir()
    out = write_asset(tmp_path / "out" / "t.usda", ms)
    stage = Usd.Stage.Open(str(out))
    shader = surface(stage, "/Root/Materials/material")
    tex, output = connected(shader, "roughness")
    assert tex.GetIdAttr().Get() == "UsdUVTexture" and output == "r"
    assert tex.GetInput("sourceColorSpace").Get() == "raw"
    file = tex.GetInput("file").Get()
    assert Path(file.resolvedPath).is_file()  # found by USD's own resolver
    st, _ = connected(tex, "st")
    assert st.GetIdAttr().Get() == "UsdPrimvarReader_float2" and st.GetInput("varname").Get() == "st"
    colour, output = connected(shader, "diffuseColor")
    assert output == "rgb"
    # the diffuse map was written linear (a tinted map): raw, or kept sRGB: tagged so
    cs = colour.GetInput("sourceColorSpace").Get()
    assert cs == ("sRGB" if Path(colour.GetInput("file").Get().resolvedPath).suffix == ".png" else "raw")
    back = read_asset(out)
    again = load_map_set(back.to_map_set(tmp_path / "again"))
    for name in ("diffuseColor", "roughness"):
        a, _ = read_image(ms.maps[name], ms.colorspace.get(name))
        b, _ = read_image(again.maps[name], again.colorspace.get(name))
        np.testing.assert_allclose(np.atleast_3d(b)[..., :1], np.atleast_3d(a)[..., :1], atol=2e-3, err_msg=name)
    assert validation_errors(out) == []


def test_a_gltf_material_is_written_as_a_materialx_gltf_pbr_shader_and_read_back(tmp_path):
    m = Material.create("gltf:metal-rough", {"baseColor": [0.5, 0.2, 0.1], "metallic": 0.0, "roughness": 0.3})
    out = write_asset(tmp_path / "g.usda", m)
    stage = Usd.Stage.Open(str(out))
    shader = surface(stage, "/Root/Materials/material")
    assert shader.GetIdAttr().Get() == "ND_gltf_pbr_surfaceshader"
    assert tuple(shader.GetInput("base_color").Get()) == pytest.approx((0.5, 0.2, 0.1))
    assert shader.GetInput("roughness").Get() == pytest.approx(0.3)
    back = read_asset(out)
    assert back.model == "gltf:metal-rough"
    for k, v in m.values.items():
        np.testing.assert_allclose(back.material().values[k], v, rtol=1e-6)
    assert validation_errors(out) == []


def test_a_normal_map_with_a_flipped_green_scale_is_baked_into_the_usual_encoding(tmp_path):
    img = np.zeros((8, 8, 3), dtype=np.uint8)
    img[..., 0], img[..., 1], img[..., 2] = 128, np.arange(8)[:, None] * 30, 255
    Image.fromarray(img).save(tmp_path / "n.png")
    stage = Usd.Stage.CreateNew(str(tmp_path / "n.usda"))
    mat = UsdShade.Material.Define(stage, "/M")
    ps = UsdShade.Shader.Define(stage, "/M/PS")
    ps.CreateIdAttr("UsdPreviewSurface")
    st = UsdShade.Shader.Define(stage, "/M/st")
    st.CreateIdAttr("UsdPrimvarReader_float2")
    st.CreateInput("varname", Sdf.ValueTypeNames.String).Set("st")
    tex = UsdShade.Shader.Define(stage, "/M/normal")
    tex.CreateIdAttr("UsdUVTexture")
    tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set("./n.png")
    tex.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set("raw")
    tex.CreateInput("scale", Sdf.ValueTypeNames.Float4).Set((2, -2, 2, 1))
    tex.CreateInput("bias", Sdf.ValueTypeNames.Float4).Set((-1, 1, -1, 0))
    tex.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(
        st.CreateOutput("result", Sdf.ValueTypeNames.Float2)
    )
    ps.CreateInput("normal", Sdf.ValueTypeNames.Normal3f).ConnectToSource(
        tex.CreateOutput("rgb", Sdf.ValueTypeNames.Float3)
    )
    mat.CreateSurfaceOutput().ConnectToSource(ps.CreateOutput("surface", Sdf.ValueTypeNames.Token))
    stage.Save()
    a = read_asset(tmp_path / "n.usda")
    code = np.asarray(a.normal.bake())
    np.testing.assert_allclose(code[..., 1], 1.0 - img[..., 1] / 255.0, atol=1e-6)  # green flipped
    np.testing.assert_allclose(code[..., 0], img[..., 0] / 255.0, atol=1e-6)


# ------------------------------------------------------------------------------------------------
# every material of a file into one stage


def test_write_all_copies_a_usd_source_keeping_prims_and_bindings(tmp_path):
    src_dir = tmp_path / "src"
    shutil.copytree(COORD.parent, src_dir)
    source = src_dir / COORD.name
    results = [
        (
            "/Asset/Materials/UsdPreviewSurface/Materials/BackPlaneMat",
            Material.create("usd:preview_surface", {"diffuseColor": [0.3, 0.6, 0.9], "roughness": 0.25}),
        ),
        (
            "/Asset/Materials/UsdPreviewSurface/Materials/TopLeftMat",
            Material.create("gltf:metal-rough", {"baseColor": [0.9, 0.1, 0.1], "metallic": 1.0, "roughness": 0.4}),
        ),
    ]
    (tmp_path / "out").mkdir()
    out = write_all(tmp_path / "out" / "all.usda", results, source)
    before, after = Usd.Stage.Open(str(source)), Usd.Stage.Open(str(out))
    paths = {str(p.GetPath()) for p in before.Traverse()}
    assert paths <= {str(p.GetPath()) for p in after.Traverse()}
    for prim in before.Traverse():
        if prim.IsA(UsdGeom.Mesh):
            a, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()
            b, _ = UsdShade.MaterialBindingAPI(after.GetPrimAtPath(prim.GetPath())).ComputeBoundMaterial()
            assert a.GetPath() == b.GetPath()
    back = surface(after, results[0][0])
    assert tuple(back.GetInput("diffuseColor").Get()) == pytest.approx((0.3, 0.6, 0.9))
    assert surface(after, results[1][0]).GetIdAttr().Get() == "ND_gltf_pbr_surfaceshader"
    # an untouched material keeps its texture, found from the copy's folder
    kept = surface(after, "/Asset/Materials/UsdPreviewSurface/Materials/TopRightMat")
    tex, _ = connected(kept, "diffuseColor")
    assert Path(tex.GetInput("file").Get().resolvedPath).samefile(src_dir / "TextureCoordinateTemplate.png")
    # the copy adds no validation error to the source's own (it types diffuseColor float3, not color3f)
    assert set(validation_errors(out)) - set(validation_errors(source)) == set()


def test_write_all_without_a_usd_source_puts_every_material_under_materials_each_bound(tmp_path):
    results = [
        ("red", Material.create("usd:preview_surface", {"diffuseColor": [0.8, 0.1, 0.1]})),
        ("gold", Material.create("usd:preview_surface", {"diffuseColor": [1.0, 0.8, 0.3], "metallic": 1.0})),
    ]
    out = write_all(tmp_path / "all.usdz", results, None)
    stage = Usd.Stage.Open(str(out))
    mats = {str(p.GetPath()) for p in stage.Traverse() if p.IsA(UsdShade.Material)}
    assert mats == {"/Root/Materials/red", "/Root/Materials/gold"}
    bound = set()
    for p in stage.Traverse():
        if p.IsA(UsdGeom.Mesh):
            m, _ = UsdShade.MaterialBindingAPI(p).ComputeBoundMaterial()
            bound.add(str(m.GetPath()))
    assert bound == mats
    assert read_asset(out, "gold").constants["metallic"] == 1.0
    assert validation_errors(out) == []


def test_a_usdz_copy_carries_the_sources_opacity_texture(tmp_path):
    a = read_asset(ROUGH, "Const033")
    m = Material.create("usd:preview_surface", {"diffuseColor": [0.5] * 3, "roughness": 0.5, "metallic": 0.0})
    out = write_asset(tmp_path / "c.usda", m, source=a)
    stage = Usd.Stage.Open(str(out))
    shader = surface(stage, a.name)
    tex, output = connected(shader, "opacity")
    assert output == "a" and Path(tex.GetInput("file").Get().resolvedPath).is_file()
    assert Path(tex.GetInput("file").Get().resolvedPath).parent == tmp_path  # copied beside it, not the cache


# ------------------------------------------------------------------------------------------------
# refusals and confinement


def test_a_materialx_standard_surface_in_usd_is_refused_in_one_line(tmp_path):
    stage = Usd.Stage.CreateNew(str(tmp_path / "s.usda"))
    mat = UsdShade.Material.Define(stage, "/M")
    sh = UsdShade.Shader.Define(stage, "/M/SS")
    sh.CreateIdAttr("ND_standard_surface_surfaceshader")
    mat.CreateSurfaceOutput("mtlx").ConnectToSource(sh.CreateOutput("out", Sdf.ValueTypeNames.Token))
    stage.Save()
    with pytest.raises(MatremapError, match=r"standard_surface shader \(ND_standard_surface_surfaceshader\)"):
        read_asset(tmp_path / "s.usda")


@pytest.mark.parametrize("exists", [True, False])
def test_layers_and_textures_outside_the_folder_are_refused_the_same_whether_they_exist(tmp_path, exists):
    outside = tmp_path / "outside"
    outside.mkdir()
    if exists:
        (outside / "secret.usda").write_text("#usda 1.0\n")
        shutil.copy(COORD.parent / "TextureCoordinateTemplate.png", outside / "secret.png")
    asset = tmp_path / "asset"
    asset.mkdir()
    (asset / "sub.usda").write_text("#usda 1.0\n(\n    subLayers = [@../outside/secret.usda@]\n)\n")
    with pytest.raises(MatremapError) as e:
        read_asset(asset / "sub.usda")
    assert "'../outside/secret.usda' points outside the asset folder" in str(e.value)
    text = COORD.read_text().replace("@TextureCoordinateTemplate.png@", "@../outside/secret.png@")
    (asset / "tex.usda").write_text(text)
    with pytest.raises(MatremapError) as e:
        read_asset(asset / "tex.usda", "TopLeftMat")
    assert "'../outside/secret.png' points outside the asset folder" in str(e.value)


def source_naming_outside(tmp_path: Path, exists: bool) -> tuple[Path, Path]:
    """The TextureCoordinateTest stage, its TopRightMat's texture moved to ``outside/secret.png`` (written
    when ``exists``, with bytes a copy would carry); (the stage, the outside folder)."""
    outside = tmp_path / "outside"
    outside.mkdir()
    if exists:
        (outside / "secret.png").write_bytes((COORD.parent / "TextureCoordinateTemplate.png").read_bytes() + SECRET)
    src = tmp_path / "asset"
    shutil.copytree(COORD.parent, src)
    text = (src / COORD.name).read_text()
    head, mat, tail = text.partition('def Material "TopRightMat"')
    tail = tail.replace("@TextureCoordinateTemplate.png@", "@../outside/secret.png@", 1)
    (src / COORD.name).write_text(head + mat + tail)
    return src / COORD.name, outside


SECRET = b"SECRET-IMAGE-BYTES"


@pytest.mark.parametrize("suffix", [".usdz", ".usda"])
@pytest.mark.parametrize("exists", [True, False])
def test_a_copy_refuses_a_texture_outside_the_folder_that_another_material_names(tmp_path, suffix, exists):
    """Issue 19, finding 1: reading BackPlaneMat confines its own textures only; a copy of the whole stage
    named TopRightMat's ../outside/secret.png too, and a .usdz packed its bytes."""
    from matremap.formats.confine import allowed_paths

    source, outside = source_naming_outside(tmp_path, exists)
    mat = "/Asset/Materials/UsdPreviewSurface/Materials/BackPlaneMat"
    assert read_asset(source, mat).constants  # the material itself reads
    results = [(mat, Material.create("usd:preview_surface", {"diffuseColor": [0.3, 0.6, 0.9]}))]
    (tmp_path / "out").mkdir()
    with pytest.raises(MatremapError) as e:
        write_all(tmp_path / "out" / f"all{suffix}", results, source)
    assert "TopRightMat" in str(e.value) and "points outside the asset folder" in str(e.value)
    assert "\n" not in str(e.value)
    assert list((tmp_path / "out").iterdir()) == []  # nothing written, no staging left
    if exists:  # allowed, the copy is written (a .usdz with the file inside)
        with allowed_paths([outside]):
            out = write_all(tmp_path / "out" / f"all{suffix}", results, source)
        assert (SECRET in out.read_bytes()) == (suffix == ".usdz")


def clip_stage(folder: Path, clip: str) -> Path:
    """TextureCoordinateTest's stage with a value clip on its root prim: ``clip`` is a layer path, or a template
    with #."""
    if "#" in clip:
        clips = f'string templateAssetPath = "{clip}"\n double templateStride = 1\n double templateStartTime = 0\n'
        clips += " double templateEndTime = 1\n"
    else:
        clips = f"asset[] assetPaths = [@{clip}@]\n double2[] active = [(0, 0)]\n"
    meta = f'clips = {{\n dictionary default = {{\n {clips} string primPath = "/Asset"\n }}\n }}\n'
    text = COORD.read_text().replace('def Xform "Asset" (\n', 'def Xform "Asset" (\n' + meta, 1)
    folder.mkdir(parents=True, exist_ok=True)
    shutil.copy(COORD.parent / "TextureCoordinateTemplate.png", folder)
    (folder / "clip.usda").write_text("#usda 1.0\n")
    (folder / "s.usda").write_text(text)
    return folder / "s.usda"


@pytest.mark.parametrize("exists", [True, False])
@pytest.mark.parametrize("clip", ["../outside/clip.usda", "../outside/clip.#.usda"])
def test_value_clips_outside_the_folder_are_refused_the_same_whether_they_exist(tmp_path, clip, exists):
    """Value clips are not composition arcs: USD opened ../outside/clip.usda while matremap read the stage."""
    if exists:
        (tmp_path / "outside").mkdir()
        (tmp_path / "outside" / "clip.usda").write_text("#usda 1.0\n")
    with pytest.raises(MatremapError) as e:
        read_asset(clip_stage(tmp_path / "asset", clip), "TopLeftMat")
    assert "points outside the asset folder" in str(e.value) and "../outside" in str(e.value)


@pytest.mark.parametrize("clip", ["clip.usda", "clip.#.usda"])
def test_value_clips_inside_the_folder_still_read(tmp_path, clip):
    assert read_asset(clip_stage(tmp_path, clip), "TopLeftMat").textures


# ------------------------------------------------------------------------------------------------
# the command line, both ways, evaluated and gated


def test_remap_gltf_to_usd_and_back_on_a_textured_metal(tmp_path):
    pytest.importorskip("colour", reason="the quality gate needs colour-science")
    from matremap.cli import main

    fast = ["--rotations", "0:360:2", "--size", "48", "--env-lights", "32"]
    assert main(["remap", str(BRASS), "--to", "usd:preview_surface", "-o", str(tmp_path / "u"), *fast]) == 0
    usd = tmp_path / "u" / "brass.usda"  # the default suffix of usd:* targets
    stage = Usd.Stage.Open(str(usd))
    mat = next(p for p in stage.Traverse() if p.IsA(UsdShade.Material))
    shader = surface(stage, str(mat.GetPath()))
    assert shader.GetInput("metallic").Get() == 1.0
    tex, _ = connected(shader, "diffuseColor")
    colour = srgb_decode(png(Path(tex.GetInput("file").Get().resolvedPath)))[..., :3].reshape(-1, 3).mean(axis=0)
    assert colour[0] > colour[1] > colour[2]  # brass: red > green > blue, as the glTF's base colour
    assert validation_errors(usd) == []
    assert main(["remap", str(usd), "--to", "gltf:metal-rough", "-o", str(tmp_path / "g"), *fast]) == 0
    gltf = json.loads((tmp_path / "g" / "brass.gltf").read_text())
    assert gltf["materials"][0]["pbrMetallicRoughness"].get("metallicFactor", 1.0) == 1.0
