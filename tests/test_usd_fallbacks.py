"""USD inputs read by the UsdPreviewSurface spec's fallbacks (formats/usd.py): a UsdPrimvarReader of the bound mesh's
uniform primvar (displayColor) and a UsdUVTexture without an st connection (the texture at st = (0, 0)). Built
stages, and the usd-wg Teapot (fetched on demand: tools/fetch_assets.py usd-Teapot)."""

from __future__ import annotations

import numpy as np
import pytest
from large_assets import large_asset
from test_formats_gltf import png_bytes

from matremap.cli import main
from matremap.errors import MatremapError

pytest.importorskip("pxr")
from matremap.formats import usd  # noqa: E402

MESH = """
def Mesh "Quad" (prepend apiSchemas = ["MaterialBindingAPI"])
{{
    int[] faceVertexCounts = [4]
    int[] faceVertexIndices = [0, 1, 2, 3]
    point3f[] points = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]
    color3f[] primvars:displayColor = {colour} (interpolation = "{interp}")
    rel material:binding = </Looks/M>
}}
"""

PRIMVAR_MATERIAL = """#usda 1.0
{mesh}
def Scope "Looks"
{{
    def Material "M"
    {{
        token outputs:surface.connect = </Looks/M/S.outputs:surface>
        def Shader "S"
        {{
            uniform token info:id = "UsdPreviewSurface"
            color3f inputs:diffuseColor.connect = </Looks/M/P.outputs:result>
            float inputs:roughness = 0.3
            token outputs:surface
        }}
        def Shader "P"
        {{
            uniform token info:id = "UsdPrimvarReader_float3"
            string inputs:varname = "displayColor"
            {fallback}
            float3 outputs:result
        }}
    }}
}}
"""


def stage(tmp_path, colour="[(0.9, 0.2, 0.05)]", interp="constant", bound=True, fallback=""):
    mesh = MESH.format(colour=colour, interp=interp) if bound else ""
    f = tmp_path / "m.usda"
    f.write_text(PRIMVAR_MATERIAL.format(mesh=mesh, fallback=fallback))
    return f


def test_a_constant_display_color_read_through_a_primvar_reader_is_the_base_colour(tmp_path):
    """Before: refused ('driven by a UsdPrimvarReader_float3')."""
    a = usd.read(stage(tmp_path))
    np.testing.assert_allclose(a.constants["diffuseColor"], [0.9, 0.2, 0.05], atol=1e-6)
    assert a.constants["roughness"] == pytest.approx(0.3) and not a.textures


def test_a_vertex_display_color_of_one_value_is_uniform_and_one_that_varies_is_refused(tmp_path):
    same = stage(tmp_path, "[(0.1, 0.5, 0.2), (0.1, 0.5, 0.2), (0.1, 0.5, 0.2), (0.1, 0.5, 0.2)]", "vertex")
    np.testing.assert_allclose(usd.read(same).constants["diffuseColor"], [0.1, 0.5, 0.2], atol=1e-6)
    varies = stage(tmp_path, "[(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 1)]", "vertex")
    with pytest.raises(MatremapError, match="varies over /Quad.*bake it into a texture"):
        usd.read(varies)


def test_without_bound_geometry_the_primvar_reader_gives_its_fallback(tmp_path):
    a = usd.read(stage(tmp_path, bound=False, fallback="float3 inputs:fallback = (0.2, 0.3, 0.4)"))
    np.testing.assert_allclose(a.constants["diffuseColor"], [0.2, 0.3, 0.4], atol=1e-6)
    assert any("fallback" in n for n in a.notes)


TEXTURE_MATERIAL = """#usda 1.0
def Material "M"
{{
    token outputs:surface.connect = </M/S.outputs:surface>
    def Shader "S"
    {{
        uniform token info:id = "UsdPreviewSurface"
        color3f inputs:diffuseColor.connect = </M/T.outputs:rgb>
        float inputs:roughness.connect = </M/T.outputs:g>
        token outputs:surface
    }}
    def Shader "T"
    {{
        uniform token info:id = "UsdUVTexture"
        asset inputs:file = @tex.png@
        token inputs:sourceColorSpace = "raw"
        token inputs:wrapS = "clamp"
        token inputs:wrapT = "clamp"
        {st}
        float3 outputs:rgb
        float outputs:g
    }}
}}
"""


@pytest.mark.parametrize(
    "st, texel", [("", (1, 0)), ("float2 inputs:st = (1, 1)", (0, 1))], ids=["fallback-0-0", "authored-1-1"]
)
def test_an_unconnected_st_reads_the_texture_at_that_one_point(tmp_path, st, texel):
    """Before: refused ('st is not connected'). The spec's st fallback is (0, 0): the image's lower-left corner
    (the bottom row as stored top first, clamped)."""
    image = np.array([[[200, 10, 10], [10, 200, 10]], [[10, 10, 200], [100, 150, 50]]], dtype=np.uint8)
    (tmp_path / "tex.png").write_bytes(png_bytes(tmp_path, image))
    f = tmp_path / "m.usda"
    f.write_text(TEXTURE_MATERIAL.format(st=st))
    a = usd.read(f)
    want = image[texel] / 255.0
    np.testing.assert_allclose(a.constants["diffuseColor"], want, atol=2e-3)
    assert a.constants["roughness"] == pytest.approx(want[1], abs=2e-3)
    assert not a.textures and any("st is not connected" in n for n in a.notes)


def test_usd_wg_teapot_ceramic_is_its_display_color(tmp_path, capsys):
    """usd-wg/assets' Teapot: material Ceramic reads the Utah teapot's constant displayColor (shading variant
    CeramicLimeGreen, (0.325, 0.825, 0)) through a UsdPrimvarReader_float3; converted onto glTF, the written base
    colour has its hue and luminance, roughness 0.125 and no metal."""
    src = large_asset("usd-Teapot") / "Teapot.usd"
    a = usd.read(src, "Ceramic")
    np.testing.assert_allclose(a.constants["diffuseColor"], [0.325, 0.825, 0.0], atol=1e-5)
    out = tmp_path / "out"
    code = main(["remap", str(src), "--material", "Ceramic", "--to", "gltf:metal-rough", "-o", str(out)])
    assert code == 0, capsys.readouterr().err
    import colorsys
    import json

    doc = json.loads(next(out.glob("*.gltf")).read_text())
    pbr = doc["materials"][0]["pbrMetallicRoughness"]
    rgb = pbr["baseColorFactor"][:3]
    src_rgb = [0.325, 0.825, 0.0]
    assert colorsys.rgb_to_hsv(*rgb)[0] == pytest.approx(colorsys.rgb_to_hsv(*src_rgb)[0], abs=0.03)
    lum = np.dot([0.2126, 0.7152, 0.0722], rgb)
    assert lum == pytest.approx(np.dot([0.2126, 0.7152, 0.0722], src_rgb), rel=0.15)
    assert pbr.get("metallicFactor", 1.0) < 0.05
    assert pbr.get("roughnessFactor", 1.0) == pytest.approx(0.125, abs=0.1)


def test_a_stage_without_materials_is_its_gprims_display_colour(tmp_path, capsys):
    """Before: refused ('holds no UsdShade Material'). A gprim without a material is drawn by the renderer's fallback
    surface with its displayColor; one that varies is not listed."""
    f = tmp_path / "plain.usda"
    quad = MESH.replace("    rel material:binding = </Looks/M>\n", "")
    f.write_text(
        "#usda 1.0\n"
        + quad.format(colour="[(0.8, 0.3, 0.1)]", interp="constant")
        + quad.replace('"Quad"', '"Ramp"').format(
            colour="[(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 1)]", interp="vertex"
        )
    )
    assert usd.material_names(f) == ["/Quad"]
    a = usd.read(f)
    np.testing.assert_allclose(a.constants["diffuseColor"], [0.8, 0.3, 0.1], atol=1e-6)
    assert a.model == "usd:preview_surface" and "roughness" not in a.constants  # the spec's default 0.5
    out = tmp_path / "out"
    assert main(["remap", str(f), "--to", "usd:preview_surface", "-o", str(out)]) == 0, capsys.readouterr().err
    back = usd.read(next(out.glob("*.usd*")))
    np.testing.assert_allclose(back.constants["diffuseColor"], [0.8, 0.3, 0.1], atol=1e-4)
    empty = tmp_path / "empty.usda"
    empty.write_text(
        "#usda 1.0\n" + quad.format(colour="[(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 1)]", interp="vertex")
    )
    with pytest.raises(MatremapError, match="no UsdShade Material and no gprim with a uniform displayColor"):
        usd.read(empty)
