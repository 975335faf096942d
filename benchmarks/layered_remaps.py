"""`matremap remap` of coated and sheen materials between the five layered models, through their files (issue 16).

    .venv/bin/python benchmarks/layered_remaps.py [--only WORDS ...] [--json FILE]

Sources, one coated and one sheen material per model, each in its model's own file: OpenPBR Surface and Standard
Surface in MaterialX (Standard Surface's copper and velvet are the MaterialX examples of tests/data/corpus, the
others are written here), glTF with KHR_materials_clearcoat / _sheen, Mitsuba 3 ``principled`` XML (clearcoat,
sheen) and a .blend with a Principled BSDF (Coat, Sheen; needs the bpy venv). Each is remapped with the command
line, as a user runs it, onto each of the four other models (``mtlx:open_pbr_surface``,
``mtlx:standard_surface``, ``gltf:pbr``, ``cycles:principled``, ``mitsuba3:principled``), written as the target's
file. The table gives the exit code (0 passed the quality gate, 3 written but failed by it, 2 refused), the fit's
relative RMSE on the probe, the layer parameters fitted on the target and the seconds of the whole command.

``--set transmissive`` remaps glasses instead (fitted on the transmission probe, matremap.transmissive): the
MaterialX examples OpenPBR glass and honey and Standard Surface tinted glass, the Khronos AttenuationTest's blue
volume and thin blue glass, a Mitsuba 3 ``principled`` glass (spec_trans 1) and a Cycles Principled glass
(Transmission Weight 1); the layers column then gives the target's transmission weight and colour.

``--set textured`` remaps textured materials under a layer (docs/models.md, "Textured materials under a uniform
layer"): the Khronos ClearcoatWicker (a uniform coat over its maps) and ClearCoatTest's Partial_Coated (a coat mask
over a uniform base), and the MaterialX Standard Surface copper with an image as its base colour (as a dielectric,
as a metal, and with its coat weight fed by an image too: a coat mask over textured maps). The fit column then gives
the evaluation's mean 1 - SSIM under the environment, and the layers column the written coat (a value, or "map").
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CORPUS = ROOT / "tests" / "data" / "corpus"
TARGETS = ("mtlx:open_pbr_surface", "mtlx:standard_surface", "gltf:pbr", "cycles:principled", "mitsuba3:principled")

OPENPBR = """<?xml version="1.0"?>
<materialx version="1.39" colorspace="lin_rec709">
  <open_pbr_surface name="SR_coated_copper" type="surfaceshader">
    <input name="base_color" type="color3" value="0.93, 0.62, 0.52" />
    <input name="base_metalness" type="float" value="1" />
    <input name="specular_roughness" type="float" value="0.3" />
    <input name="coat_weight" type="float" value="1" />
    <input name="coat_color" type="color3" value="0.9, 0.6, 0.45" />
    <input name="coat_roughness" type="float" value="0.2" />
  </open_pbr_surface>
  <surfacematerial name="CoatedCopper" type="material">
    <input name="surfaceshader" type="surfaceshader" nodename="SR_coated_copper" />
  </surfacematerial>
  <open_pbr_surface name="SR_velvet" type="surfaceshader">
    <input name="base_color" type="color3" value="0.25, 0.03, 0.08" />
    <input name="specular_weight" type="float" value="0.2" />
    <input name="specular_roughness" type="float" value="0.6" />
    <input name="fuzz_weight" type="float" value="1" />
    <input name="fuzz_color" type="color3" value="0.8, 0.35, 0.45" />
    <input name="fuzz_roughness" type="float" value="0.5" />
  </open_pbr_surface>
  <surfacematerial name="Velvet" type="material">
    <input name="surfaceshader" type="surfaceshader" nodename="SR_velvet" />
  </surfacematerial>
</materialx>
"""
PRINCIPLED = """<scene version="3.0.0">
  <bsdf type="principled" id="coated">
    <rgb name="base_color" value="0.7, 0.2, 0.1"/>
    <float name="roughness" value="0.45"/>
    <float name="clearcoat" value="1.0"/>
    <float name="clearcoat_gloss" value="0.8"/>
  </bsdf>
  <bsdf type="principled" id="sheen">
    <rgb name="base_color" value="0.3, 0.1, 0.4"/>
    <float name="roughness" value="0.8"/>
    <float name="sheen" value="1.0"/>
    <float name="sheen_tint" value="0.5"/>
  </bsdf>
</scene>
"""
GLTF = {
    "asset": {"version": "2.0"},
    "extensionsUsed": ["KHR_materials_clearcoat", "KHR_materials_sheen"],
    "materials": [
        {
            "name": "Coated",
            "pbrMetallicRoughness": {
                "baseColorFactor": [0.5, 0.05, 0.02, 1],
                "metallicFactor": 0,
                "roughnessFactor": 0.45,
            },
            "extensions": {"KHR_materials_clearcoat": {"clearcoatFactor": 1.0, "clearcoatRoughnessFactor": 0.2}},
        },
        {
            "name": "Sheen",
            "pbrMetallicRoughness": {
                "baseColorFactor": [0.1, 0.02, 0.05, 1],
                "metallicFactor": 0,
                "roughnessFactor": 0.8,
            },
            "extensions": {"KHR_materials_sheen": {"sheenColorFactor": [0.9, 0.4, 0.5], "sheenRoughnessFactor": 0.5}},
        },
    ],
}
CYCLES = {
    "coated": {
        "Base Color": [0.8, 0.5, 0.35],
        "Metallic": 1.0,
        "Roughness": 0.35,
        "Coat Weight": 1.0,
        "Coat Roughness": 0.15,
        "Coat Tint": [0.9, 0.7, 0.5],
    },
    "sheen": {
        "Base Color": [0.2, 0.05, 0.1],
        "Roughness": 0.7,
        "Sheen Weight": 1.0,
        "Sheen Roughness": 0.4,
        "Sheen Tint": [0.9, 0.5, 0.6],
    },
}
PRINCIPLED_GLASS = """<scene version="3.0.0">
  <bsdf type="principled" id="glass">
    <rgb name="base_color" value="0.75, 0.9, 0.55"/>
    <float name="roughness" value="0.3"/>
    <float name="specular" value="0.5"/>
    <float name="spec_trans" value="1.0"/>
  </bsdf>
</scene>
"""
MITSUBA_GLASS = """<scene version="3.0.0">
  <bsdf type="roughdielectric" id="glass">
    <string name="int_ior" value="bk7"/>
    <string name="ext_ior" value="air"/>
    <string name="distribution" value="ggx"/>
    <float name="alpha" value="0.1"/>
  </bsdf>
</scene>
"""
CYCLES_GLASS = {"Base Color": [0.95, 0.55, 0.35], "Roughness": 0.25, "IOR": 1.45, "Transmission Weight": 1.0}
#: the transmission parameters of each target, shown in the table for ``--set transmissive``
TRANSMISSION_PARAMS = {
    "mtlx:open_pbr_surface": ("transmission_weight", "transmission_color"),
    "mtlx:standard_surface": ("transmission", "transmission_color"),
    "gltf:pbr": ("transmission", "attenuationColor"),
    "cycles:principled": ("Transmission Weight", "Base Color"),
    "mitsuba3:principled": ("spec_trans", "base_color"),
}
#: the layer parameters of each target, shown in the table
LAYER_PARAMS = {
    "mtlx:open_pbr_surface": ("coat_weight", "fuzz_weight"),
    "mtlx:standard_surface": ("coat", "sheen"),
    "gltf:pbr": ("clearcoat", "sheenColor"),
    "cycles:principled": ("Coat Weight", "Sheen Weight"),
    "mitsuba3:principled": ("clearcoat", "sheen"),
}


def sources(folder: Path) -> list[tuple[str, Path, str | None, str]]:
    """(label, file, material, its model) of every source, written into ``folder`` where not in the corpus."""
    (folder / "openpbr.mtlx").write_text(OPENPBR)
    (folder / "principled.xml").write_text(PRINCIPLED)
    (folder / "layers.gltf").write_text(json.dumps(GLTF))
    out = [
        ("OpenPBR coated copper", folder / "openpbr.mtlx", "CoatedCopper", "mtlx:open_pbr_surface"),
        ("OpenPBR velvet (fuzz)", folder / "openpbr.mtlx", "Velvet", "mtlx:open_pbr_surface"),
        (
            "Standard Surface copper (coat)",
            CORPUS / "mtlx-standard_surface_copper" / "standard_surface_copper.mtlx",
            None,
            "mtlx:standard_surface",
        ),
        (
            "Standard Surface velvet (sheen)",
            CORPUS / "mtlx-standard_surface_velvet" / "standard_surface_velvet.mtlx",
            None,
            "mtlx:standard_surface",
        ),
        ("glTF clearcoat", folder / "layers.gltf", "Coated", "gltf:pbr"),
        ("glTF sheen", folder / "layers.gltf", "Sheen", "gltf:pbr"),
        ("Mitsuba 3 clearcoat", folder / "principled.xml", "coated", "mitsuba3:principled"),
        ("Mitsuba 3 sheen", folder / "principled.xml", "sheen", "mitsuba3:principled"),
    ]
    from matremap.renderers.cycles.client import bpy_available

    if bpy_available():
        from matremap.core.material import Material
        from matremap.formats.blend import write

        for name, values in CYCLES.items():
            write(folder / f"cycles_{name}.blend", Material.create("cycles:principled", values), force=True)
            out.append((f"Cycles Principled {name}", folder / f"cycles_{name}.blend", None, "cycles:principled"))
    return out


def transmissive_sources(folder: Path) -> list[tuple[str, Path, str | None, str]]:
    """(label, file, material, its model) of the glasses, written into ``folder`` where not in the corpus."""
    (folder / "principled_glass.xml").write_text(PRINCIPLED_GLASS)
    (folder / "rough_glass.xml").write_text(MITSUBA_GLASS)
    attenuation = CORPUS / "gltf-AttenuationTest" / "AttenuationTest.glb"
    out = [
        ("OpenPBR glass", CORPUS / "mtlx-open_pbr_glass" / "open_pbr_glass.mtlx", None, "mtlx:open_pbr_surface"),
        ("OpenPBR honey", CORPUS / "mtlx-open_pbr_honey" / "open_pbr_honey.mtlx", None, "mtlx:open_pbr_surface"),
        (
            "Standard Surface tinted glass",
            CORPUS / "mtlx-standard_surface_glass_tinted" / "standard_surface_glass_tinted.mtlx",
            None,
            "mtlx:standard_surface",
        ),
        ("glTF AttenuationTest volume", attenuation, "R5_Attenuation_1.0", "gltf:pbr"),
        ("glTF AttenuationTest thin", attenuation, "R1_Sample_1.5", "gltf:pbr"),
        ("Mitsuba 3 principled glass", folder / "principled_glass.xml", "glass", "mitsuba3:principled"),
        ("Mitsuba 3 roughdielectric bk7", folder / "rough_glass.xml", "glass", "mitsuba3:roughdielectric"),
    ]
    from matremap.renderers.cycles.client import bpy_available

    if bpy_available():
        from matremap.core.material import Material
        from matremap.formats.blend import write

        write(folder / "cycles_glass.blend", Material.create("cycles:principled", CYCLES_GLASS), force=True)
        out.append(("Cycles Principled glass", folder / "cycles_glass.blend", None, "cycles:principled"))
    return out


def textured_sources(folder: Path) -> list[tuple[str, Path, str | None, str]]:
    """(label, file, material, its model) of the textured layered materials (the copper variants written into
    ``folder`` by the tests' own fixture, tests/test_held_layers.py)."""
    sys.path.insert(0, str(ROOT / "tests"))
    from test_held_layers import COAT_TEST, WICKER, textured_copper

    return [
        ("glTF ClearcoatWicker (uniform coat)", WICKER, None, "gltf:pbr"),
        ("glTF ClearCoatTest Partial_Coated (coat mask)", COAT_TEST, "Partial_Coated", "gltf:pbr"),
        ("SS dielectric, image base, copper coat", textured_copper(folder / "d", 0.0), None, "mtlx:standard_surface"),
        ("SS metal, image base, copper coat", textured_copper(folder / "m", 1.0), None, "mtlx:standard_surface"),
        ("SS image base, coat mask", textured_copper(folder / "c", 0.0, True), None, "mtlx:standard_surface"),
    ]


def written_layers(out: Path, target: str) -> dict:
    """The coat and sheen of a textured remap's written maps: a value, or "map"."""
    doc_file = out / "maps" / "material.json"
    if not doc_file.is_file():
        return {}
    doc = json.loads(doc_file.read_text())
    layers = {}
    for k in LAYER_PARAMS[target]:
        v = "map" if k in doc.get("maps", {}) else doc.get("params", {}).get(k)
        layers[k] = max(v) if isinstance(v, list) else v
    return layers


def run(src: Path, material: str | None, target: str, out: Path, shown: dict | None = None) -> dict:
    cmd = [str(Path(sys.executable).parent / "matremap"), "remap", str(src), "--to", target, "-o", str(out), "--force"]
    cmd += ["--material", material] if material else []
    t = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True)
    seconds = time.perf_counter() - t
    log = p.stdout + p.stderr
    fit = re.search(r"relative L2 error ([0-9.]+)", log)
    params = re.search(r"^fit: \S+ (\{.*\}); relative", log, re.M)
    layers = {}
    if params:
        values = json.loads(params.group(1))
        for k in (shown or LAYER_PARAMS)[target]:
            v = values.get(k)
            layers[k] = (max(v) if shown is None else [round(x, 2) for x in v]) if isinstance(v, list) else v
    last = [line for line in log.strip().splitlines() if line.startswith(("done", "written", "matremap:"))]
    if fit is None and (ssim := re.search(r"mean 1-SSIM ([0-9.]+)", log)):  # a textured remap: its evaluation
        fit, layers = ssim, written_layers(out, target)
    return {
        "exit": p.returncode,
        "fit": float(fit.group(1)) if fit else None,
        "layers": layers,
        "s": seconds,
        "last": last[-1] if last else log.strip().splitlines()[-1],
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="*", default=[], help="sources whose label holds one of these words")
    ap.add_argument("--json", help="write the rows to this JSON file")
    ap.add_argument("--set", choices=("layered", "transmissive", "textured"), default="layered", help="which sources")
    args = ap.parse_args(argv)
    glass = args.set == "transmissive"
    listed = {"layered": sources, "transmissive": transmissive_sources, "textured": textured_sources}[args.set]
    shown = TRANSMISSION_PARAMS if glass else None
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        what = "transmission weight, colour" if glass else "coat, sheen"
        measure = "mean 1 - SSIM" if args.set == "textured" else "fit rel. RMSE"
        print(f"| source | target | exit | {measure} | target's layers ({what}) | s |")
        print("|---|---|---|---|---|---|")
        for label, src, material, own in listed(folder):
            if args.only and not any(w in label for w in args.only):
                continue
            for target in TARGETS:
                if target == own:
                    continue
                r = run(src, material, target, folder / "out", shown)
                rows.append({"source": label, "target": target, **r})
                fit = "-" if r["fit"] is None else f"{r['fit']:.4f}"
                layers = ", ".join(
                    f"{k} {v:.2f}" if isinstance(v, float) else f"{k} {v}"
                    for k, v in r["layers"].items()
                    if v is not None
                )
                print(f"| {label} | {target} | {r['exit']} | {fit} | {layers} | {r['s']:.1f} |", flush=True)
    passed = sum(r["exit"] == 0 for r in rows)
    print(
        f"\n{passed}/{len(rows)} passed the quality gate; failed by it (exit 3): "
        f"{sum(r['exit'] == 3 for r in rows)}; refused (exit 2): {sum(r['exit'] == 2 for r in rows)}"
    )
    for r in rows:
        if r["exit"] not in (0, 3):
            print(f"- {r['source']} -> {r['target']}: {r['last']}")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
