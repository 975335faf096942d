""".blend output (:mod:`matremap.formats.blend`): Blender, in the bpy worker, reopens the file and
finds the material's nodes, values, links, colour spaces and packed images as asked, and a render of
the file's own sphere (its material, the probe camera and lights) agrees with the Cycles backend's
probe render of the same material. Skip without the bpy venv (see tests/test_cycles.py)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from matremap.core.material import Material
from matremap.core.scene import Scene
from matremap.errors import MatremapError
from matremap.formats import format_for, write_asset
from matremap.renderers.cycles.client import ENV_PYTHON, bpy_available
from matremap.renderers.cycles.probe import CyclesRenderer

needs_bpy = pytest.mark.skipif(
    not bpy_available(),
    reason=f"no bpy venv: python3.11 -m venv .venv-bpy && .venv-bpy/bin/pip install bpy==5.0.1 (or set {ENV_PYTHON})",
)


@pytest.fixture(scope="module")
def cycles():
    r = CyclesRenderer(timeout=600.0)
    yield r
    r.close()


def relative_rmse(a: np.ndarray, b: np.ndarray, mask: np.ndarray) -> float:
    return float(np.linalg.norm(a[mask] - b[mask]) / np.linalg.norm(b[mask]))


def inspect(cycles, path) -> dict:
    return cycles.call({"op": "inspect_blend", "path": str(path)})


def render_file(cycles, path, scene: Scene) -> np.ndarray:
    return cycles.request({"op": "render_blend", "path": str(path), "scene": cycles.scene_dict(scene)})[0]


def linked(material: dict, to_node: str, to_socket: str) -> tuple[str, str] | None:
    """The (node, socket) linked into ``to_node``'s input ``to_socket``, or None."""
    hits = [(a, b) for a, b, c, d in material["links"] if (c, d) == (to_node, to_socket)]
    assert len(hits) <= 1
    return hits[0] if hits else None


# -- without bpy ---------------------------------------------------------------------------------------


def test_blend_is_a_known_output_format():
    assert format_for("x.blend") == "blend"


def test_refuses_other_models_and_existing_files(tmp_path):
    from matremap.formats import blend

    with pytest.raises(MatremapError, match="cycles:principled"):
        blend.write_request(str(tmp_path / "t.blend"), Material.create("mitsuba06:ward"), None, tmp_path / "x.blend")
    (tmp_path / "x.blend").write_bytes(b"old")
    with pytest.raises(MatremapError, match="already exists"):
        write_asset(tmp_path / "x.blend", Material.create("cycles:glossy"))
    assert (tmp_path / "x.blend").read_bytes() == b"old"


def test_without_bpy_says_how_to_set_it_up(tmp_path, monkeypatch):
    import matremap.renderers.cycles.client as cs

    monkeypatch.setattr(cs, "_shared", None)
    monkeypatch.setenv(ENV_PYTHON, str(tmp_path / "no-python"))
    with pytest.raises(MatremapError, match=r"pip install bpy==5\.0\.1"):
        write_asset(tmp_path / "x.blend", Material.create("cycles:glossy"))
    assert not list(tmp_path.iterdir())


# -- with bpy ------------------------------------------------------------------------------------------


@needs_bpy
@pytest.mark.parametrize(
    "material",
    [
        Material.create("cycles:principled", {"Base Color": [0.8, 0.3, 0.1], "Roughness": 0.4, "IOR": 1.6}),
        Material.create(
            "cycles:glossy",
            {
                "distribution": "multi_ggx",
                "Color": [1.0, 0.7, 0.3],
                "Roughness": 0.5,
                "Diffuse Color": [0.2, 0.25, 0.3],
            },
        ),
    ],
    ids=["principled", "glossy"],
)
def test_uniform_material_round_trips_and_renders_like_the_backend(cycles, tmp_path, material):
    """Measured relative RMSE of the file's 128x64 UV sphere against the backend's true sphere, 64^2,
    lights at 0 and 45 degrees: principled 8.8e-4, glossy 9.0e-4 (the mesh's faceting)."""
    out = tmp_path / "brass.blend"
    assert write_asset(out, material, force=False) == out
    assert out.is_file() and [p.name for p in tmp_path.iterdir()] == ["brass.blend"]  # no temporary left
    info = inspect(cycles, out)
    assert list(info["materials"]) == ["brass"]  # named after the file without a source asset
    assert info["objects"]["sphere"]["materials"] == ["brass"]
    assert info["objects"]["sphere"]["uv_layers"] == ["UVMap"]
    mat = info["materials"]["brass"]
    nodes = mat["nodes"]
    if material.model == "cycles:principled":
        p = nodes["Principled BSDF"]
        assert p["distribution"] == "MULTI_GGX"
        np.testing.assert_allclose(p["inputs"]["Base Color"], [0.8, 0.3, 0.1, 1.0], rtol=1e-6)
        assert p["inputs"]["Roughness"] == pytest.approx(0.4) and p["inputs"]["IOR"] == pytest.approx(1.6)
        assert p["inputs"]["Metallic"] == 0.0 and p["inputs"]["Specular IOR Level"] == pytest.approx(0.5)
        assert linked(mat, "Material Output", "Surface") == ("Principled BSDF", "BSDF")
    else:
        g, d = nodes["Glossy BSDF"], nodes["Diffuse BSDF"]
        assert g["distribution"] == "MULTI_GGX"
        np.testing.assert_allclose(g["inputs"]["Color"], [1.0, 0.7, 0.3, 1.0], rtol=1e-6)
        assert g["inputs"]["Roughness"] == pytest.approx(0.5) and d["inputs"]["Roughness"] == 0.0
        np.testing.assert_allclose(d["inputs"]["Color"], [0.2, 0.25, 0.3, 1.0], rtol=1e-6)
        assert linked(mat, "Add Shader", "Shader") == ("Glossy BSDF", "BSDF")
        assert linked(mat, "Add Shader", "Shader_001") == ("Diffuse BSDF", "BSDF")
        assert linked(mat, "Material Output", "Surface") == ("Add Shader", "Shader")

    scene = Scene.probe([0.0, 45.0], resolution=64)
    img = render_file(cycles, out, scene)
    ref = cycles.render([material], scene)[0]
    assert relative_rmse(img, ref, scene.mask()) < 5e-3
    with pytest.raises(MatremapError, match="already exists"):
        write_asset(out, material)
    write_asset(out, Material.create("cycles:diffuse"), force=True)
    assert list(inspect(cycles, out)["materials"]["brass"]["nodes"]) == ["Material Output", "Diffuse BSDF"]


def _write(path, image: np.ndarray, dtype) -> None:
    import OpenImageIO as oiio

    h, w, c = image.shape
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(w, h, c, dtype))
    out.write_image(image)
    out.close()


@needs_bpy
def test_map_set_becomes_packed_image_textures_with_their_colour_spaces(cycles, tmp_path):
    """Constant maps in each encoding (8-bit sRGB colour, 8-bit grey data, float EXR colour, an EXR normal
    map) give the nodes asked for, and the file renders as the uniform material the maps decode to
    (measured 1.2e-3 relative RMSE); with every image Non-Color it would be 0.38 off, all sRGB 4.6."""
    from matremap.svbrdf.textures import load_map_set

    maps = tmp_path / "maps"
    maps.mkdir()
    n = (16, 32)
    _write(maps / "color.png", np.full((*n, 3), [230, 160, 60], np.uint8), "uint8")
    _write(maps / "rough.png", np.full((*n, 1), 115, np.uint8), "uint8")
    _write(maps / "diffuse.exr", np.full((*n, 3), [0.05, 0.1, 0.2], np.float32), "float")
    _write(maps / "normal.exr", np.full((*n, 3), [0.5, 0.5, 1.0], np.float32), "float")
    (maps / "material.json").write_text(
        json.dumps(
            {
                "model": "cycles:glossy",
                "maps": {"Color": "color.png", "Roughness": "rough.png", "Diffuse Color": "diffuse.exr"},
                "normal": "normal.exr",
                "params": {"distribution": "multi_ggx"},
                "colorspace": {"color.png": "srgb", "rough.png": "linear"},
            }
        )
    )
    ms = load_map_set(maps)

    class Asset:
        name = "painted metal"

    out = write_asset(tmp_path / "out.blend", ms, source=Asset())
    info = inspect(cycles, out)
    mat = info["materials"]["painted metal"]
    nodes = mat["nodes"]
    assert nodes["Glossy BSDF"]["distribution"] == "MULTI_GGX"
    expected = {"Color": "sRGB", "Roughness": "Non-Color", "Diffuse Color": "Linear Rec.709", "Normal": "Non-Color"}
    for name, cs in expected.items():
        tex = nodes[name]
        assert tex["type"] == "ShaderNodeTexImage" and tex["image"]["colorspace"] == cs, name
        assert tex["image"]["packed"] and tex["image"]["size"] == [32, 16]
        assert tex["interpolation"] == "Linear" and tex["extension"] == "EXTEND"
        assert linked(mat, name, "Vector") == ("UV Map", "UV")
    assert nodes["UV Map"]["uv_map"] == "UVMap"
    assert linked(mat, "Glossy BSDF", "Color") == ("Color", "Color")
    assert linked(mat, "Glossy BSDF", "Roughness") == ("Roughness", "Color")
    assert linked(mat, "Diffuse BSDF", "Color") == ("Diffuse Color", "Color")
    assert nodes["Normal Map"]["space"] == "TANGENT" and nodes["Normal Map"]["uv_map"] == "UVMap"
    assert linked(mat, "Normal Map", "Color") == ("Normal", "Color")
    assert linked(mat, "Glossy BSDF", "Normal") == linked(mat, "Diffuse BSDF", "Normal") == ("Normal Map", "Normal")

    from matremap.core.imageio import srgb_to_linear

    uniform = Material.create(
        "cycles:glossy",
        {
            "distribution": "multi_ggx",
            "Color": srgb_to_linear(np.array([230, 160, 60]) / 255.0),
            "Roughness": 115 / 255,
            "Diffuse Color": [0.05, 0.1, 0.2],
        },
    )
    scene = Scene.probe([0.0, 45.0], resolution=64)
    img = render_file(cycles, out, scene)
    ref = cycles.render([uniform], scene)[0]
    assert relative_rmse(img, ref, scene.mask()) < 5e-3


@needs_bpy
def test_transmission_weight_is_written_and_read_back(cycles, tmp_path):
    """cycles:principled's Transmission Weight is a socket the file holds and the reader takes (no longer a
    'no such parameter' note); a glass is read like the rest (fitted on the transmission probe), not lost."""
    from matremap.formats import read_asset

    for t, lost in ((0.3, []), (0.8, [])):
        out = tmp_path / f"glass{t}.blend"
        write_asset(out, Material.create("cycles:principled", {"Roughness": 0.2, "Transmission Weight": t}))
        asset = read_asset(out)
        assert asset.model == "cycles:principled" and asset.constants["Transmission Weight"] == pytest.approx(t)
        assert asset.lost == lost and not any("Transmission" in n for n in asset.notes)
