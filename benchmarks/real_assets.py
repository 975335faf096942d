"""Run `matremap remap` on the real-asset corpus and check every output independently (issue 14).

For each corpus file (tests/data/corpus, see its README for sources and licences) and a few target
models, runs ``.venv/bin/matremap remap FILE --to MODEL -o OUT/<case>`` as a subprocess and records
the exit code, wall time and last stderr line. Then, without matremap's own score, reads the input
and the written file with their own libraries (tests/corpus_checks.py) and compares the colour that
carries the look (base colour / diffuse / a conductor's F0): mean linear luminance, mean hue of the
saturated texels, whether the output is all zero or constant where the input varies, whether the
written file loads (json/pygltflib, MaterialX validate, mitsuba.load_file, bpy for .blend), and for
identity cases (the file's own model) the max difference from the input. Verdicts:

- OK       exit 0 and every check passes
- WRONG    exit 0 but a check fails (black/grey/zero output, hue lost, luminance off > 2x, no load)
- REFUSED  non-zero exit without a traceback
- CRASH    non-zero exit with a traceback, or the case timed out

    .venv/bin/python benchmarks/real_assets.py                       # all cases, OUT in a temp dir
    .venv/bin/python benchmarks/real_assets.py --only BoxTextured --out out/real --json out/real.json
    .venv/bin/python benchmarks/real_assets.py --list

Against an older commit (the BEFORE table of issue 14 was taken at df0750d), with its own cache:

    git archive df0750d src | tar -x -C /tmp/before
    MATREMAP_BPY_PYTHON=$PWD/.venv-bpy/bin/python PYTHONPATH=/tmp/before/src .venv/bin/python \
        benchmarks/real_assets.py --jobs 2 --matremap-arg=--cache --matremap-arg=/tmp/before-cache
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CORPUS = ROOT / "tests" / "data" / "corpus"
sys.path.insert(0, str(ROOT / "tests"))

import corpus_checks as cc  # noqa: E402

MATREMAP = ROOT / ".venv" / "bin" / "matremap"
BPY_PYTHON = ROOT / ".venv-bpy" / "bin" / "python"

GGX = ["--fix", "distribution=ggx"]
CONDUCTOR = ("mitsuba3:roughconductor", GGX)
PLASTIC = ("mitsuba3:roughplastic", GGX)
GLTF = ("gltf:metal-rough", [])
ALLOW_CORPUS = ["--allow-path", str(CORPUS)]  # documents whose fileprefix reaches a shared Images folder
CYCLES = ("cycles:principled", [])
OPENPBR = ("mtlx:open_pbr_surface", [])
USD = ("usd:preview_surface", [])
USD_SUFFIXES = (".usda", ".usdc", ".usdz", ".usd")


@dataclass
class Asset:
    """One corpus file, the material to take from it, its own model and the targets to try."""

    name: str
    file: str  # relative to CORPUS
    own: str  # the file's own model: a target equal to it is an identity case (copy expected)
    targets: list[tuple[str, list[str]]]
    material: str | None = None
    note: str = ""
    args: list[str] = field(default_factory=list)  # extra remap arguments (--allow-path for shared image folders)


# Targets: the file's own model first (identity), then across formats.
ASSETS: list[Asset] = [
    Asset(
        "usd-TextureCoordinateTest",
        "usd-TextureCoordinateTest/TextureCoordinateTest.usda",
        "usd:preview_surface",
        [USD, GLTF, PLASTIC],
        material="TopRightMat",
        note="UsdPreviewSurface, sRGB texture x per-channel scale, roughness 1",
    ),
    Asset(
        "usd-TextureTransformTest",
        "usd-TextureTransformTest/TextureTransformTest.usd",
        "usd:preview_surface",
        [USD, GLTF],
        material="Correct_53142",
        note="legacy isSRGB=auto texture, grey specular workflow read as metalness (transforms: tests)",
    ),
    Asset(
        "usd-RoughnessTest",
        "usd-RoughnessTest/RoughnessTest.usdz",
        "usd:preview_surface",
        [USD, GLTF],
        material="Const033",
        note=".usdz, metallic 0.6, opacity from alpha",
    ),
    Asset(
        "BoxTextured",
        "gltf-BoxTextured/BoxTextured.gltf",
        "gltf:metal-rough",
        [GLTF, PLASTIC, CYCLES, USD],
        note="textured base colour, metallic 0",
    ),
    Asset(
        "TwoSidedPlane",
        "gltf-TwoSidedPlane/TwoSidedPlane.gltf",
        "gltf:metal-rough",
        [GLTF, PLASTIC, CYCLES, USD],
        note="textured base colour, packed metal-rough (metal 0), normal map",
    ),
    Asset(
        "NormalTangentTest",
        "gltf-NormalTangentTest/NormalTangentTest.gltf",
        "gltf:metal-rough",
        [GLTF, CONDUCTOR, PLASTIC, CYCLES],
        note="mixed metallic 0 and 1 in the ORM texture",
    ),
    Asset(
        "TextureCoordinateTest",
        "gltf-TextureCoordinateTest/TextureCoordinateTest.glb",
        "gltf:metal-rough",
        [GLTF, PLASTIC, CYCLES],
        material="TopRightMat",
        note="red factor x texture, .glb",
    ),
    Asset(
        "SpecularTest",
        "gltf-SpecularTest/SpecularTest.glb",
        "gltf:metal-rough",
        [GLTF, PLASTIC, CYCLES],
        material="M6_yellowTex",
        note="KHR_materials_specular colour texture, black base, roughness 0",
    ),
    Asset(
        "ClearCoatTest",
        "gltf-ClearCoatTest/ClearCoatTest.glb",
        "gltf:pbr",  # a coat of factor 1: read into gltf:pbr (fitted, issue 16)
        [GLTF, PLASTIC, CYCLES],
        material="Simple_Coated",
        note="KHR_materials_clearcoat on a red dielectric",
    ),
    Asset(
        "TransmissionRoughnessTest",
        "gltf-TransmissionRoughnessTest/TransmissionRoughnessTest.glb",
        "gltf:metal-rough",
        [GLTF, PLASTIC, CYCLES],
        material="Mat_IOR_1.50",
        note="KHR_materials_transmission/volume, roughness texture",
    ),
    Asset(
        "TransmissionTest-stripes",
        "gltf-TransmissionTest/TransmissionTest.glb",
        "gltf:pbr",
        [OPENPBR, GLTF],
        material="RedTransTexture",
        note="KHR_materials_transmission with a transmissionTexture (glass stripes over an opaque red)",
    ),
    Asset(
        "TransmissionTest-metal",
        "gltf-TransmissionTest/TransmissionTest.glb",
        "gltf:pbr",
        [OPENPBR],
        material="YellowTransMetal",
        note="KHR_materials_transmission over a metallic map (metal stripes beside glass)",
    ),
    Asset(
        "ClearcoatWicker",
        "gltf-ClearcoatWicker/ClearcoatWicker.glb",
        "gltf:pbr",  # textured under a uniform coat: read into gltf:pbr, the coat held over the sweep (issue 16)
        [GLTF, CONDUCTOR, PLASTIC, CYCLES, OPENPBR],
        note="textured, metallicFactor 1 x texture 0, under a uniform clear coat (1, 0.1) with a coat normal map",
    ),
    Asset(
        "ClearCoatTest-mask",
        "gltf-ClearCoatTest/ClearCoatTest.glb",
        "gltf:pbr",
        [OPENPBR, CYCLES],
        material="Partial_Coated",
        note="a uniform blue base under a coat masked by clearcoatTexture (blended per texel)",
    ),
    Asset(
        "ClearCoatTest-rough",
        "gltf-ClearCoatTest/ClearCoatTest.glb",
        "gltf:pbr",
        [OPENPBR, CYCLES],
        material="RoughVariations_Coated",
        note="a coat whose roughness is clearcoatRoughnessTexture (converted at five levels, interpolated)",
    ),
    Asset(
        "MRSNoTex-gold-r0",
        "gltf-MetalRoughSpheresNoTextures/MetalRoughSpheresNoTextures.glb",
        "gltf:metal-rough",
        [GLTF, CONDUCTOR, CYCLES],
        material="mat_91",
        note="gold-coloured metal, roughness 0",
    ),
    Asset(
        "MRSNoTex-grey-r0",
        "gltf-MetalRoughSpheresNoTextures/MetalRoughSpheresNoTextures.glb",
        "gltf:metal-rough",
        [GLTF, PLASTIC, CYCLES],
        material="mat_0",
        note="grey dielectric, roughness 0",
    ),
    Asset(
        "TTT-Rotation",
        "gltf-TextureTransformTest/TextureTransformTest.gltf",
        "gltf:metal-rough+transform",  # baked: the checker reads the stored texture, so no identity check
        [GLTF, PLASTIC, CYCLES],
        material="Rotation",
        note="KHR_texture_transform rotation, clamp sampler (baked)",
    ),
    Asset(
        "TTMT-normal",
        "gltf-TextureTransformMultiTest/TextureTransformMultiTest.glb",
        "gltf:metal-rough",
        [GLTF, PLASTIC, CYCLES],
        material="NormalTest0Mat",
        note="transformed normal map (baked and turned)",
    ),
    Asset(
        "TTMT-basecolor-uv1",
        "gltf-TextureTransformMultiTest/TextureTransformMultiTest.glb",
        "gltf:metal-rough+transform",  # baked: the checker reads the stored texture, so no identity check
        [GLTF, PLASTIC, CYCLES],
        material="BaseColorTest1Mat",
        note="transformed base colour on TEXCOORD_1",
    ),
    Asset(
        "EmissiveStrength",
        "gltf-EmissiveStrengthTest/EmissiveStrengthTest.glb",
        "gltf:metal-rough",
        [GLTF, PLASTIC, CYCLES],
        material="Emit4",
        note="black base, emission x KHR_materials_emissive_strength 4 (carried)",
    ),
    Asset(
        "Attenuation",
        "gltf-AttenuationTest/AttenuationTest.glb",
        "gltf:metal-rough",
        [GLTF, PLASTIC, CYCLES],
        note="transmission 1 + volume: kept onto glTF, refused elsewhere",
    ),
    Asset(
        "MultiUV",
        "gltf-MultiUVTest/MultiUVTest.glb",
        "gltf:metal-rough",
        [GLTF, PLASTIC, CYCLES],
        note="base colour on TEXCOORD_0, emission on TEXCOORD_1",
    ),
    Asset(
        "TexLinearInterp-mask",
        "gltf-TextureLinearInterpolationTest/TextureLinearInterpolationTest.glb",
        "gltf:metal-rough",
        [GLTF, PLASTIC, CYCLES],
        material="2",
        note="alphaMode MASK over a grey+alpha texture (carried opacity)",
    ),
    Asset(
        "ss-copper",
        "mtlx-standard_surface_copper/standard_surface_copper.mtlx",
        "mtlx:standard_surface",  # read through a translation: no identity target
        [GLTF, CONDUCTOR, CYCLES],
        note="white metal under a copper coat_color",
    ),
    Asset(
        "ss-chrome",
        "mtlx-standard_surface_chrome/standard_surface_chrome.mtlx",
        "mtlx:standard_surface",  # read through a translation: no identity target
        [GLTF, CONDUCTOR, CYCLES],
        note="metal, specular_roughness 0",
    ),
    Asset(
        "ss-gold",
        "mtlx-standard_surface_gold/standard_surface_gold.mtlx",
        "mtlx:standard_surface",  # read through a translation: no identity target
        [GLTF, CONDUCTOR, CYCLES],
        note="metal, base_color 1.059 (> 1)",
    ),
    Asset(
        "ss-jade",
        "mtlx-standard_surface_jade/standard_surface_jade.mtlx",
        "mtlx:standard_surface",  # read through a translation: no identity target
        [GLTF, PLASTIC, CYCLES],
        note="dielectric, subsurface, IOR 2.418",
    ),
    Asset(
        "ss-wood-tiled",
        "mtlx-standard_surface_wood_tiled/resources/Materials/Examples/StandardSurface/standard_surface_wood_tiled.mtlx",  # noqa: E501
        "mtlx:standard_surface",  # read through a translation: no identity target
        [GLTF, PLASTIC, CYCLES],
        note="node graph, tiledimage colour + roughness",
        args=ALLOW_CORPUS,
    ),
    Asset(
        "ss-brick-procedural",
        "mtlx-standard_surface_brick_procedural/resources/Materials/Examples/StandardSurface/standard_surface_brick_procedural.mtlx",  # noqa: E501
        "mtlx:standard_surface",
        [GLTF, PLASTIC, CYCLES],
        note="procedural graph: tiledimage x 6, mix, HSV, clamp, normalmap",
        args=ALLOW_CORPUS,
    ),
    Asset(
        "ss-greysphere-place2d",
        "mtlx-standard_surface_greysphere_calibration/resources/Materials/Examples/StandardSurface/standard_surface_greysphere_calibration.mtlx",  # noqa: E501
        "mtlx:standard_surface",
        [GLTF, PLASTIC, CYCLES],
        note="texcoord -> place2d -> image, clamp",
        args=ALLOW_CORPUS,
    ),
    Asset(
        "ss-chess-queen-w",
        "mtlx-standard_surface_chess_set/standard_surface_chess_set.mtlx",
        "mtlx:standard_surface",
        [GLTF, CONDUCTOR, PLASTIC, CYCLES],
        material="M_Queen_W",
        note="15-material document with a look; textured, normal map",
    ),
    Asset(
        "ss-velvet",
        "mtlx-standard_surface_velvet/standard_surface_velvet.mtlx",
        "mtlx:standard_surface",
        [GLTF],
        note="specular_IOR 0 with specular 0; sheen 1 (refused: the look is the sheen)",
    ),
    Asset(
        "ss-marble",
        "mtlx-standard_surface_marble_solid/standard_surface_marble_solid.mtlx",
        "mtlx:standard_surface",
        [GLTF],
        note="3D procedural (fractal3d, position): refused naming the node",
    ),
    Asset(
        "gltfpbr-boombox",
        "mtlx-gltf_pbr_boombox/gltf_pbr_boombox.mtlx",
        "gltf:metal-rough",
        [GLTF, CONDUCTOR, PLASTIC, CYCLES],
        note="gltf_colorimage, separate3 ORM, gltf_normalmap, emission carried",
    ),
    Asset(
        "openpbr-lightbulb",
        "mtlx-open_pbr_lightbulb/open_pbr_lightbulb.mtlx",
        "mtlx:open_pbr_surface",
        [GLTF, PLASTIC],
        note="open_pbr emission 10000 nits (carried)",
    ),
    Asset(
        "gltfpbr-gold",
        "mtlx-gltf_pbr_gold/gltf_pbr_gold.mtlx",
        "gltf:metal-rough",
        [GLTF, CONDUCTOR, CYCLES],
        note="gltf_pbr metal, roughness 0.02",
    ),
    Asset(
        "gltfpbr-plastic",
        "mtlx-gltf_pbr_plastic/gltf_pbr_plastic.mtlx",
        "gltf:metal-rough",
        [GLTF, PLASTIC, CYCLES],
        note="gltf_pbr blue dielectric",
    ),
    Asset(
        "openpbr-aluminium",
        "mtlx-open_pbr_aluminum_brushed/open_pbr_aluminum_brushed.mtlx",
        "mtlx:open_pbr_surface",  # read through a translation: no identity target
        [GLTF, CONDUCTOR, CYCLES],
        note="open_pbr metal, anisotropy",
    ),
    Asset(
        "openpbr-ketchup",
        "mtlx-open_pbr_ketchup/open_pbr_ketchup.mtlx",
        "mtlx:open_pbr_surface",  # read through a translation: no identity target
        [GLTF, PLASTIC, CYCLES],
        note="open_pbr, subsurface/transmission",
    ),
    Asset(
        "usdps-plastic",
        "mtlx-usd_preview_surface_plastic/usd_preview_surface_plastic.mtlx",
        "mtlx:UsdPreviewSurface",  # read through a translation: no identity target
        [GLTF, PLASTIC],
        note="UsdPreviewSurface (not a documented input)",
    ),
    Asset(
        "mi-roughconductor",
        "mitsuba-roughconductor_isotropic/roughconductor_isotropic.xml",
        "mitsuba3:roughconductor",
        [CONDUCTOR, GLTF, CYCLES],
        note="named material Ag, GGX 0.7",
    ),
    Asset(
        "mi-conductor",
        "mitsuba-conductor/conductor.xml",
        "mitsuba3:roughconductor",
        [CONDUCTOR, GLTF, CYCLES],
        note="smooth conductor (Ag)",
    ),
    Asset(
        "mi-roughplastic",
        "mitsuba-roughplastic/roughplastic.xml",
        "mitsuba3:roughplastic",
        [PLASTIC, GLTF, CYCLES],
        note="named ext_ior bk7, nonlinear",
    ),
    Asset(
        "mi-plastic",
        "mitsuba-plastic/plastic.xml",
        "mitsuba3:roughplastic",
        [PLASTIC, GLTF, CYCLES],
        note="smooth plastic",
    ),
    Asset(
        "mi-principled",
        "mitsuba-principled/principled.xml",
        "mitsuba3:principled",
        [("mitsuba3:principled", []), GLTF, CYCLES],
        note="principled with sheen/clearcoat/anisotropy",
    ),
    Asset(
        "mi-test1",
        "mitsuba-test1/test1.xml",
        "mitsuba3:principled",
        [("mitsuba3:principled", []), GLTF, CYCLES],
        note="twosided principled, <default>/$params, ply mesh",
    ),
    Asset(
        "mi-normalmap",
        "mitsuba-normalmap/normalmap.xml",
        "mitsuba3:diffuse",
        [("mitsuba3:diffuse", []), GLTF, CYCLES],
        note="normalmap over a default diffuse, bitmap",
    ),
    Asset(
        "mi-diffuse",
        "mitsuba-diffuse/diffuse.xml",
        "mitsuba3:diffuse",
        [("mitsuba3:diffuse", []), GLTF, CYCLES],
        note="blue diffuse, referenced by id before it is defined",
    ),
    Asset(
        "mi-twosided",
        "mitsuba-twosided_2/twosided_2.xml",
        "mitsuba3:diffuse",
        [GLTF],
        note="twosided with a dielectric back side: refused (Mitsuba refuses it too)",
    ),
    Asset(
        "mi-mask",
        "mitsuba-mask/mask.xml",
        "mitsuba3:diffuse",
        [("mitsuba3:diffuse", []), GLTF, CYCLES],
        note="mask opacity 0.4 (carried)",
    ),
    Asset(
        "mi-aniso",
        "mitsuba-roughconductor_anisotropic/roughconductor_anisotropic.xml",
        "mitsuba3:roughconductor-anisotropic",
        [("mitsuba3:roughconductor-anisotropic", []), CONDUCTOR, GLTF, CYCLES],
        note="Ag, GGX alpha_u 0.4 / alpha_v 0.2",
    ),
    Asset(
        "mi-bumpmap",
        "mitsuba-bumpmap/bumpmap.xml",
        "mitsuba3:diffuse",
        [GLTF],
        note="bumpmap over a checkerboard: refused (Mitsuba cannot render it)",
    ),
    Asset(
        "mi-blendbsdf",
        "mitsuba-blendbsdf/blendbsdf.xml",
        "mitsuba3:diffuse",
        [GLTF],
        note="blend of diffuse and dielectric: refused (transmission)",
    ),
    Asset(
        "mi-dielectric",
        "mitsuba-dielectric/dielectric.xml",
        "mitsuba3:diffuse",
        [GLTF, CYCLES],
        note="dielectric: refused (transmission)",
    ),
    Asset(
        "mi-roughdielectric",
        "mitsuba-roughdielectric_isotropic/roughdielectric_isotropic.xml",
        "mitsuba3:diffuse",
        [GLTF],
        note="roughdielectric: refused (transmission)",
    ),
]


@dataclass
class Case:
    """One run and its independent measures."""

    asset: str
    target: str
    args: list[str]
    identity: bool
    exit: int | None = None
    seconds: float = 0.0
    last: str = ""
    output: str | None = None
    loads: bool | None = None
    loads_msg: str = ""
    lum_in: float | None = None
    lum_out: float | None = None
    hue_in: float | None = None
    hue_out: float | None = None
    in_varies: bool | None = None
    out_varies: bool | None = None
    out_zero: bool | None = None
    identity_diff: float | None = None
    const_maps: str = ""
    verdict: str = ""
    why: list[str] = field(default_factory=list)


def case_name(asset: Asset, target: str) -> str:
    return f"{asset.name}__{target.replace(':', '-')}"


def last_line(text: str) -> str:
    lines = [x.strip() for x in text.strip().splitlines() if x.strip()]
    return lines[-1] if lines else ""


def map_stats(out: Path, input_varies: bool | None) -> str:
    """'k/n': of the n maps in OUT/maps and next to the target file, k are all zero, or constant
    while the input's colour varies."""
    files = [
        p
        for d in (out, out / "maps")
        if d.is_dir()
        for p in d.iterdir()
        if p.suffix.lower() in (".png", ".exr", ".jpg") and p.name not in ("compare.png", "outside_domain.png")
    ]
    bad = 0
    for f in files:
        try:
            a = cc.read_image(f, srgb=False)
        except Exception:  # noqa: BLE001
            bad += 1
            continue
        if cc.is_all_zero(a) or (input_varies and not cc.varies(a[..., :3], tol=1e-3)):
            bad += 1
    return f"{bad}/{len(files)}" if files else ""


def usd_colour(path: Path, material: str | int | None = None) -> Any:
    """Linear diffuseColor (UsdPreviewSurface; base_color of a MaterialX gltf_pbr) of a USD material, read with
    pxr and OpenImageIO (tests/corpus_checks.read_image; the texture's scale applied), not with matremap."""
    import tempfile
    import zipfile

    import numpy as np
    from pxr import Usd, UsdShade

    stage = Usd.Stage.Open(str(path))
    mats = [UsdShade.Material(p) for p in stage.Traverse() if p.IsA(UsdShade.Material)]
    if isinstance(material, str):
        mats = [m for m in mats if str(m.GetPath()) == material or m.GetPrim().GetName() == material] or mats
    elif isinstance(material, int):
        mats = mats[material:]
    shader, _, _ = mats[0].ComputeSurfaceSource()
    name = "diffuseColor" if shader.GetIdAttr().Get() == "UsdPreviewSurface" else "base_color"
    inp = shader.GetInput(name)
    sources, _ = inp.GetConnectedSources() if inp else ([], [])
    if not sources:
        value = inp.Get() if inp else (0.18, 0.18, 0.18)
        return np.asarray(value, dtype=np.float64)[None, None, :3]
    tex = UsdShade.Shader(sources[0].source.GetPrim())
    asset = tex.GetInput("file").Get()
    cs = tex.GetInput("sourceColorSpace")
    srgb = {"raw": False, "sRGB": True}.get(cs.Get() if cs else "", None)  # auto: integer files decoded
    if "[" in asset.resolvedPath:  # a usdz member
        package, member = asset.resolvedPath.rstrip("]").split("[", 1)
        with zipfile.ZipFile(package) as z, tempfile.TemporaryDirectory() as tmp:
            f = Path(tmp) / Path(member).name
            f.write_bytes(z.read(member))
            lin = cc.read_image(f, srgb)[..., :3]
    else:
        lin = cc.read_image(asset.resolvedPath, srgb)[..., :3]
    sc = tex.GetInput("scale")
    return lin * (np.asarray(sc.Get(), dtype=np.float64)[:3] if sc and sc.Get() is not None else 1.0)


def usd_loads(path: Path) -> tuple[bool, str]:
    """Whether pxr opens the stage and every material's surface and textures resolve."""
    from pxr import Usd, UsdShade

    stage = Usd.Stage.Open(str(path))
    if stage is None:
        return False, "Usd.Stage.Open failed"
    for p in stage.Traverse():
        if p.IsA(UsdShade.Shader):
            f = UsdShade.Shader(p).GetInput("file")
            if f and f.Get() is not None and not f.Get().resolvedPath:
                return False, f"{p.GetPath()}: texture {f.Get().path} not found"
    return True, "pxr opens it"


def material_colour(path: Path, material: str | int | None = None) -> Any:
    return usd_colour(path, material) if path.suffix.lower() in USD_SUFFIXES else cc.material_colour(path, material)


def find_output_file(out: Path) -> Path | None:
    for suffix in USD_SUFFIXES:
        found = sorted(p for p in out.glob(f"*{suffix}") if p.is_file()) if out.is_dir() else []
        if found:
            return found[0]
    return cc.find_output_file(out)


def output_colour(path: Path, asset: Asset, n_input_materials: int | None) -> tuple[Any, bool | None, str]:
    """(colour, loads, message) of a written target file."""
    if path.suffix.lower() in USD_SUFFIXES:
        ok, msg = usd_loads(path)
        try:
            return usd_colour(path, asset.material if asset.own == "usd:preview_surface" else None), ok, msg
        except Exception as e:  # noqa: BLE001
            return None, ok, f"{msg}; colour: {type(e).__name__}: {e}"[:200]
    kind = cc.file_kind(path)
    if kind == "blend":
        if not BPY_PYTHON.exists():
            return None, None, "no bpy venv"
        return cc.blend_colour(path, BPY_PYTHON)
    ok, msg = cc.file_loads(path)
    material: Any = None
    if kind == "gltf":
        doc, _ = cc.gltf_load(path)
        same = n_input_materials is not None and len(doc.get("materials", [])) == n_input_materials
        material = asset.material if same else 0
    elif kind == "mtlx":
        # a MaterialX document written for one --material keeps every material by name: read that one (the
        # first material of the chess set's copy is another piece, which read as the queen's colour lost)
        material = asset.material
    try:
        try:
            return cc.material_colour(path, material), ok, msg
        except KeyError:  # a document of the converted material alone
            return cc.material_colour(path, None), ok, msg
    except Exception as e:  # noqa: BLE001
        return None, ok, f"{msg}; colour: {type(e).__name__}: {e}"[:200]


def shown(colour: Any, src: Path, material: str | int | None) -> Any:
    """A colour map ([H, W, 3]) of a glTF source's material, or of its conversion (laid on the same UVs), reduced to
    the texels the material's triangles show (tests/corpus_checks.py ``gltf_shown``, apart from matremap's own): a
    texture shared with other materials (an atlas) is judged where this one shows it, as matremap converts it."""
    if colour is None or np.ndim(colour) != 3 or colour.shape[0] * colour.shape[1] <= 1 or cc.file_kind(src) != "gltf":
        return colour
    mask = cc.gltf_shown(src, material, colour.shape[:2])
    return colour if mask is None or mask.all() or not mask.any() else colour[mask][None]


def run_case(asset: Asset, target: str, extra: list[str], out_root: Path, timeout: float, common: list[str]) -> Case:
    src = CORPUS / asset.file
    out = out_root / case_name(asset, target)
    if out.exists():
        shutil.rmtree(out)
    args = [str(MATREMAP), "remap", str(src), "--to", target, "-o", str(out), *extra, *asset.args, *common]
    if asset.material is not None:
        args += ["--material", asset.material]
    c = Case(asset.name, target, args[1:], identity=(target == asset.own))
    t0 = time.perf_counter()
    try:
        r = subprocess.run(args, capture_output=True, text=True, timeout=timeout, cwd=ROOT)
        c.exit, stderr, stdout = r.returncode, r.stderr, r.stdout
    except subprocess.TimeoutExpired as e:
        err = e.stderr or b""
        c.exit, stderr, stdout = None, err.decode() if isinstance(err, bytes) else err, ""
    c.seconds = time.perf_counter() - t0
    c.last = last_line(stderr) or last_line(stdout)
    (out_root / "logs").mkdir(exist_ok=True)
    (out_root / "logs" / f"{case_name(asset, target)}.log").write_text(
        " ".join(args) + "\n--- stdout\n" + stdout + "\n--- stderr\n" + stderr
    )

    try:
        cin = material_colour(src, asset.material)
        s_in = cc.summary(shown(cin, src, asset.material))
        c.lum_in, c.hue_in, c.in_varies = s_in["lum"], s_in["hue"], s_in["varies"]
        n_in = len(cc.gltf_load(src)[0].get("materials", [])) if cc.file_kind(src) == "gltf" else None
    except Exception as e:  # noqa: BLE001
        cin, n_in = None, None
        c.why.append(f"input colour: {e}")
    if c.exit == 0:
        f = find_output_file(out)
        c.output = str(f.relative_to(out_root)) if f else None
        if f is None:
            c.loads, c.loads_msg = False, "no target file in OUT"
        else:
            cout, c.loads, c.loads_msg = output_colour(f, asset, n_in)
            if cout is not None:
                s = cc.summary(shown(cout, src, asset.material))
                c.lum_out, c.hue_out, c.out_varies, c.out_zero = s["lum"], s["hue"], s["varies"], s["zero"]
                if c.identity and cin is not None:
                    c.identity_diff = cc.max_abs_diff(cin, cout)
        c.const_maps = map_stats(out, c.in_varies)
    v, why = cc.verdict(
        c.exit,
        stderr,
        c.loads,
        c.lum_in,
        c.lum_out,
        c.hue_in,
        c.hue_out,
        c.in_varies,
        c.out_varies,
        c.out_zero,
        c.identity_diff,
        c.identity,
    )
    c.verdict, c.why = v, c.why + why
    if c.loads is False and c.loads_msg and "does not load" in why:
        c.why[c.why.index("does not load")] = f"does not load ({c.loads_msg[:80]})"
    return c


def fmt(x: float | None, spec: str = ".3f") -> str:
    return "-" if x is None else format(x, spec)


def table(cases: list[Case]) -> str:
    head = [
        "asset",
        "target",
        "exit",
        "s",
        "lum in->out",
        "hue in->out",
        "loads",
        "maps bad",
        "verdict",
        "why / last message",
    ]
    rows = []
    for c in cases:
        loads = "-" if c.loads is None else ("yes" if c.loads else "NO")
        msg = "; ".join(c.why) if c.why else c.last
        if c.verdict in ("REFUSED", "CRASH"):
            msg = c.last
        rows.append(
            [
                c.asset,
                c.target + (" (id)" if c.identity else ""),
                "T/O" if c.exit is None else str(c.exit),
                f"{c.seconds:.1f}",
                f"{fmt(c.lum_in)}->{fmt(c.lum_out)}",
                f"{fmt(c.hue_in, '.0f')}->{fmt(c.hue_out, '.0f')}",
                loads,
                c.const_maps or "-",
                c.verdict,
                msg[:110],
            ]
        )
    w = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(head)] if rows else [len(h) for h in head]
    lines = [
        "| " + " | ".join(h.ljust(w[i]) for i, h in enumerate(head)) + " |",
        "|" + "|".join("-" * (x + 2) for x in w) + "|",
    ]
    lines += ["| " + " | ".join(r[i].replace("|", "/").ljust(w[i]) for i in range(len(head))) + " |" for r in rows]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, help="output folder (default: a new temporary folder)")
    ap.add_argument(
        "--only",
        action="append",
        default=[],
        help="run only assets whose name contains this (repeatable); 'asset:target' selects a target",
    )
    ap.add_argument("--json", type=Path, help="also write the cases as JSON here")
    ap.add_argument("--timeout", type=float, default=300.0, help="seconds per case (300)")
    ap.add_argument("--jobs", type=int, default=1, help="cases run at once (1)")
    ap.add_argument("--list", action="store_true", help="list the cases and exit")
    ap.add_argument(
        "--matremap-arg",
        action="append",
        default=[],
        metavar="ARG",
        help="extra argument for every remap (e.g. --matremap-arg=--no-evaluate)",
    )
    a = ap.parse_args(argv)

    todo: list[tuple[Asset, str, list[str]]] = []
    for asset in ASSETS:
        for target, extra in asset.targets:
            key = f"{asset.name}:{target}"
            if a.only and not any(o in asset.name or o in key for o in a.only):
                continue
            todo.append((asset, target, extra))
    if a.list:
        for asset, target, extra in todo:
            print(f"{asset.name:28s} {target:26s} {' '.join(extra):24s} {asset.file}")
        return 0
    out = a.out or Path(tempfile.mkdtemp(prefix="matremap-real-"))
    out.mkdir(parents=True, exist_ok=True)
    print(f"{len(todo)} cases -> {out}", flush=True)

    def one(item: tuple[Asset, str, list[str]]) -> Case:
        asset, target, extra = item
        c = run_case(asset, target, extra, out, a.timeout, a.matremap_arg)
        print(
            f"  {c.verdict:7s} {c.asset} -> {c.target} ({c.seconds:.1f} s) {'; '.join(c.why) or c.last}"[:200],
            flush=True,
        )
        return c

    with ThreadPoolExecutor(max_workers=max(1, a.jobs)) as ex:
        cases = list(ex.map(one, todo))
    print()
    print(table(cases))
    counts = {v: sum(c.verdict == v for c in cases) for v in ("OK", "WRONG", "REFUSED", "CRASH")}
    print("\n" + ", ".join(f"{k} {n}" for k, n in counts.items()) + f" of {len(cases)} cases")
    if a.json:
        a.json.parent.mkdir(parents=True, exist_ok=True)
        a.json.write_text(
            json.dumps({"out": str(out), "counts": counts, "cases": [asdict(c) for c in cases]}, indent=1)
        )
        print(f"wrote {a.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
