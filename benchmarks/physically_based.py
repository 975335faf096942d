"""PhysicallyBased, all 110: each material's OpenPBR definition remapped onto glTF (with its KHR layer
extensions) by matremap's uniform fit, against the hand-made glTF version shipped beside it.

    .venv/bin/python benchmarks/physically_based.py [--size 96] [--min-roughness 0.3] [--only NAME,...]

Data: the PhysicallyBased database (Anton Palmqvist, https://physicallybased.info, CC0) with Bernard Kwok's
MaterialX translations in the PyPI package ``materialxmaterials`` (``pip install materialxmaterials``):
``PhysicallyBasedMaterialX_OPBR.mtlx`` (an ``open_pbr_surface`` per material) and
``PhysicallyBasedMaterialX_GLTF.mtlx`` (the hand-made ``gltf_pbr`` versions); categories from
``PhysicallyBasedMaterial.json``.

For every material:

* **reference**: its OpenPBR node read with MaterialX into ``mtlx:open_pbr_surface`` (the inputs the embedded
  OpenPBR 1.1 model has; inputs whose weight is absent, so 0 by the spec -- subsurface radius without
  subsurface weight, thin film without thin-film weight, transmission colour without transmission weight --
  are noted and change nothing);
* **(a) hand-made**: its ``gltf_pbr`` node into ``gltf:pbr`` (base_color, metallic, roughness, ior,
  specular_color, clearcoat, clearcoat_roughness, sheen_color, sheen_roughness; iridescence noted);
* **(b) matremap**: ``matremap.fit(reference, "gltf:pbr", ...)`` with metallic held at the source's metalness,
  the glTF layers freed where the source has the matching OpenPBR layer (coat: clearcoat, clearcoatRoughness;
  fuzz: sheenColor, sheenRoughness), fitted on the probe, strategy three-stage: dielectrics under a headlight and
  a light at 60 degrees (``--fit-lights``), metals under a headlight and a grazing light at 89 degrees
  (``--fit-lights-metal``), which reaches the half-angles near 82 degrees where OpenPBR's F82 edge tint dips and
  the environment's back light shows it (glTF's Schlick metal cannot dip; the fit weighs how much to give up).
  The metal lights were chosen on this set: with 0/85 twelve F82 metals lose by 0.1-1.5 %, with 0/89 four by
  less than 0.4 %; with the headlight alone (``--fit-lights-metal 0``) most F82 metals lose by 1-3 %.
* transmissive materials (``transmission_weight`` > 0) are compared in the transmission probe
  (:mod:`matremap.renderers.embedded.transmission`: the sphere before a tiled plane under the same environment);
  matremap reads their transmission across (``gltf_equivalent``: KHR_materials_transmission and _volume with a
  thickness, so the sphere refracts) and fits the reflection's roughness and IOR on the opaque probe when it
  sees any reflection (a smooth one shows none under point lights). No roughness floor there.

All three are rendered by the embedded renderer on the evaluation sphere under the same environment map
(``--env``, default matremap's built-in one, sampled into 256 directional lights); perceptual roughness is raised
to ``--min-roughness`` in the reference and the hand-made version alike (the PhysicallyBased metals are mirrors,
which directional lights cannot show). Error: relative RMSE over the sphere against the reference, and
DSSIM = 1 - SSIM. The table lists every material; the losers follow with what each candidate got wrong.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

from matremap.core.envmap import directional_lights, resolve
from matremap.core.material import Material
from matremap.core.scene import Scene
from matremap.dialects import get_model
from matremap.renderers.embedded.environment import SVBRDFRender
from matremap.renderers.textured import object_mask
from matremap.svbrdf.evaluate import ssim_map
from matremap.uniform import fit

SOURCE = "mtlx:open_pbr_surface"
TARGET = "gltf:pbr"
ENV_LIGHTS = 256
#: OpenPBR inputs of a layer -> the gltf:pbr parameters freed for it
LAYER_FREES = {
    "coat_weight": ("clearcoat", "clearcoatRoughness"),
    "fuzz_weight": ("sheenColor", "sheenRoughness"),
}
#: OpenPBR inputs that do nothing while the weight named beside them is absent (0 by the spec)
INERT_WITHOUT = {
    "subsurface_radius": "subsurface_weight",
    "subsurface_radius_scale": "subsurface_weight",
    "subsurface_color": "subsurface_weight",
    "thin_film_ior": "thin_film_weight",
    "thin_film_thickness": "thin_film_weight",
    "transmission_color": "transmission_weight",
    "transmission_depth": "transmission_weight",
    "transmission_dispersion_abbe_number": "transmission_weight",
    "transmission_dispersion_scale": "transmission_weight",
}
#: gltf_pbr input -> gltf:pbr parameter
GLTF_INPUTS = {
    "transmission": "transmission",
    "thickness": "thickness",
    "attenuation_color": "attenuationColor",
    "attenuation_distance": "attenuationDistance",
    "base_color": "baseColor",
    "metallic": "metallic",
    "roughness": "roughness",
    "ior": "ior",
    "specular": "specular",
    "specular_color": "specularColor",
    "clearcoat": "clearcoat",
    "clearcoat_roughness": "clearcoatRoughness",
    "sheen_color": "sheenColor",
    "sheen_roughness": "sheenRoughness",
}


def data_dir() -> Path:
    try:
        import materialxMaterials
    except ImportError:
        raise SystemExit("needs the materialxmaterials package: .venv/bin/pip install materialxmaterials") from None
    return Path(materialxMaterials.__file__).resolve().parent / "data" / "PhysicallyBasedMaterialX"


def shader_inputs(path: Path, category: str) -> dict[str, dict[str, Any]]:
    """uiname -> {input name: value (float or list)} of every ``category`` node of a MaterialX document."""
    import MaterialX as mx

    doc = mx.createDocument()
    mx.readFromXmlFile(doc, str(path))
    out: dict[str, dict[str, Any]] = {}
    for node in doc.getNodes():
        if node.getCategory() != category:
            continue
        values: dict[str, Any] = {}
        for inp in node.getInputs():
            vals = [float(v) for v in inp.getValueString().replace(",", " ").split()]
            values[inp.getName()] = vals[0] if len(vals) == 1 else vals
        out[node.getAttribute("uiname") or node.getName()] = values
    return out


@dataclass
class Entry:
    name: str
    category: str
    kind: str = "opaque"  # opaque | layered | transmissive
    layers: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    source: Material | None = None
    hand: Material | None = None
    fitted: Material | None = None
    fit_loss: float = float("nan")
    err: dict[str, dict[str, float]] = field(default_factory=dict)  # who -> {rmse, dssim}


def to_model(model: str, values: dict[str, Any], table: dict[str, str] | None, notes: list[str]) -> Material:
    """A Material of ``model`` from node inputs (renamed through ``table``, or by their own names), each value
    clamped to the parameter's bounds with a note; inputs the model lacks are noted."""
    spec = get_model(model)
    params: dict[str, Any] = {}
    for name, raw in values.items():
        pname = table.get(name) if table is not None else name
        if pname is None or pname not in spec.param_names:
            continue
        p = spec.param(pname)
        clamped = np.clip(raw, *p.bounds)
        if not np.allclose(clamped, raw):
            notes.append(f"{model} {pname}={raw} clamped to {np.round(clamped, 4).tolist()}")
        params[pname] = clamped.tolist() if np.ndim(clamped) else float(clamped)
    return Material.create(model, params)


def classify(name: str, category: str, opbr: dict[str, Any], gltf: dict[str, Any] | None) -> Entry:
    e = Entry(name, category)
    if float(opbr.get("transmission_weight", 0.0)) > 0.0:
        e.kind = "transmissive"
    for inp, weight in INERT_WITHOUT.items():
        if inp in opbr and float(opbr.get(weight, 0.0)) == 0.0:
            e.notes.append(f"{inp} without {weight}: no effect in OpenPBR")
    spec = get_model(SOURCE)
    inert = {k for k, w in INERT_WITHOUT.items() if float(opbr.get(w, 0.0)) == 0.0}
    unknown = [k for k in opbr if k not in spec.param_names and k not in inert and k != "surfaceshader"]
    if unknown:
        e.notes.append(f"OpenPBR inputs not modelled: {', '.join(unknown)}")
    e.layers = [w for w in LAYER_FREES if float(opbr.get(w, 0.0)) > 0.0]
    if e.layers:
        e.kind = "layered"
    e.source = to_model(SOURCE, opbr, None, e.notes)
    if gltf is None:
        e.notes.append("no hand-made glTF version")
        return e
    extra = [k for k in gltf if k not in GLTF_INPUTS and k != "surfaceshader"]
    if extra:
        e.notes.append(f"hand-made glTF inputs gltf:pbr lacks: {', '.join(extra)}")
    e.hand = to_model(TARGET, gltf, GLTF_INPUTS, e.notes)
    return e


def floored(m: Material, param: str, floor: float) -> Material:
    return m.with_params({param: max(float(m.values[param][0]), floor)})


class EnvViews:
    """Renders of uniform materials on the evaluation sphere under the environment's directional lights."""

    def __init__(self, size: int, env: str) -> None:
        self.size = size
        self.lights = directional_lights(resolve(env), ENV_LIGHTS, 0.0)
        self.mask = object_mask("sphere", size)

    def render(self, m: Material) -> np.ndarray:
        r = SVBRDFRender(m.model, dict(m.values), dict(m.options), "sphere", self.size)
        return r.render(*self.lights)


def rel_rmse(x: np.ndarray, ref: np.ndarray, mask: np.ndarray) -> float:
    t = ref[mask].astype(np.float64)
    return float(np.linalg.norm(x[mask].astype(np.float64) - t) / np.linalg.norm(t))


def dssim(x: np.ndarray, ref: np.ndarray, mask: np.ndarray) -> float:
    _, smap = ssim_map(ref, x)
    return float(np.mean(1.0 - smap[mask]))


def layer_start(source: Material, layers: list[str]) -> dict[str, Any]:
    """gltf:pbr layer values read off the OpenPBR source's layers: a start for the fit."""
    v = source.values
    start: dict[str, Any] = {}
    if "coat_weight" in layers:
        start.update(clearcoat=float(v["coat_weight"][0]), clearcoatRoughness=float(v["coat_roughness"][0]))
    if "fuzz_weight" in layers:
        sheen = np.clip(v["fuzz_weight"][0] * v["fuzz_color"], 0.0, 1.0).tolist()
        start.update(sheenColor=sheen, sheenRoughness=float(v["fuzz_roughness"][0]))
    return start


def run_transmissive(e: Entry, size: int, env: str, fit_scene: Scene) -> None:
    """A transmissive material in the transmission probe: the reference and the hand-made glTF as they are; matremap
    reads the transmission across (:func:`~matremap.renderers.embedded.transmission.gltf_equivalent`) and fits
    the reflection's roughness and IOR on the opaque probe when it sees any (a smooth surface shows none there)."""
    from matremap.renderers import get_renderer
    from matremap.renderers.embedded import transmission as tr

    assert e.source is not None
    mapped = tr.gltf_equivalent(tr.interface_of(e.source))
    seen = get_renderer("embedded").render([e.source], fit_scene)[0]
    if float(np.max(seen)) > 1e-6:
        fix = {k: v for k, v in mapped.items() if k not in ("roughness", "ior")}
        start = {"roughness": mapped["roughness"], "ior": mapped["ior"]}
        r = fit(e.source, TARGET, "three-stage", scene=fit_scene, fix=fix, start=start)
        e.fitted, e.fit_loss = r.target, r.loss
    else:
        e.fitted, e.fit_loss = Material.create(TARGET, mapped), float("nan")
        e.notes.append("smooth: the opaque probe sees no reflection to fit; transmission read across")
    scene = tr.TransmissionScene(resolution=size, env=env)
    mask = object_mask("sphere", size)
    ref = tr.render(e.source, scene)
    cands = {"b": e.fitted} if e.hand is None else {"b": e.fitted, "a": e.hand}
    for who, m in cands.items():
        img = tr.render(m, scene)
        e.err[who] = {"rmse": rel_rmse(img, ref, mask), "dssim": dssim(img, ref, mask)}


def run_entry(e: Entry, views: EnvViews, floor: float, fit_scenes: dict[str, Scene]) -> None:
    assert e.source is not None
    e.source = source = floored(e.source, "specular_roughness", floor)
    metal = float(source.values["base_metalness"][0])
    free = [p for w in e.layers for p in LAYER_FREES[w]]
    fix = {"metallic": 1.0 if metal >= 0.5 else 0.0}
    fit_scene = fit_scenes["metal" if metal >= 0.5 else "dielectric"]
    r = fit(source, TARGET, "three-stage", scene=fit_scene, fix=fix, free=free)
    if e.layers:  # a second start with the layers on, at the source's own values (a freed layer starts off)
        start = layer_start(source, e.layers)
        r2 = fit(source, TARGET, "three-stage", scene=fit_scene, fix=fix, free=free, start=start)
        r = r2 if r2.loss < r.loss else r
    e.fitted, e.fit_loss = r.target, r.loss
    ref = views.render(source)
    cands = {"b": e.fitted}
    if e.hand is not None:
        e.hand = cands["a"] = floored(e.hand, "roughness", floor)
    for who, m in cands.items():
        img = views.render(m)
        e.err[who] = {"rmse": rel_rmse(img, ref, views.mask), "dssim": dssim(img, ref, views.mask)}


def brief(m: Material) -> str:
    v = m.values
    if m.model == TARGET:
        s = f"base {np.round(v['baseColor'], 3).tolist()} m {v['metallic'][0]:g} r {v['roughness'][0]:.3f}"
        if v["metallic"][0] < 0.5:
            s += f" ior {v['ior'][0]:.3f}"
            if np.any(np.abs(v["specularColor"] - 1.0) > 1e-6):
                s += f" specColor {np.round(v['specularColor'], 2).tolist()}"
        if v["clearcoat"][0] > 0:
            s += f" clearcoat {v['clearcoat'][0]:.2f}/{v['clearcoatRoughness'][0]:.2f}"
        if np.max(v["sheenColor"]) > 0:
            s += f" sheen {np.round(v['sheenColor'], 2).tolist()}/{v['sheenRoughness'][0]:.2f}"
        return s
    s = f"base {np.round(v['base_color'], 3).tolist()} metal {v['base_metalness'][0]:g}"
    s += f" r {v['specular_roughness'][0]:.3f} ior {v['specular_ior'][0]:.3f}"
    if np.any(np.abs(v["specular_color"] - 1.0) > 1e-6):
        s += f" specular_color {np.round(v['specular_color'], 3).tolist()}"
    return s


def why(e: Entry) -> str:
    """What separates the two candidates of a loser, from their parameters."""
    assert e.hand is not None and e.fitted is not None and e.source is not None
    h, b, s = e.hand.values, e.fitted.values, e.source.values
    reasons = []
    if s["base_metalness"][0] >= 0.5 and np.any(np.abs(s["specular_color"] - 1.0) > 0.02):
        reasons.append(
            "an F82-tinted metal: glTF's Schlick metal has no edge tint, so the fit trades base colour against "
            "the rim under the probe's lights while the hand-made base colour is the F0 exactly"
        )
    if abs(h["roughness"][0] - b["roughness"][0]) > 0.05:
        reasons.append(f"roughness: hand-made {h['roughness'][0]:.3f}, fitted {b['roughness'][0]:.3f}")
    d = np.abs(h["baseColor"] - b["baseColor"]).max()
    if d > 0.03:
        reasons.append(f"base colour differs by up to {d:.3f}")
    if s["base_metalness"][0] < 0.5 and abs(h["ior"][0] - b["ior"][0]) > 0.05:
        reasons.append(f"ior: hand-made {h['ior'][0]:.3f}, fitted {b['ior'][0]:.3f}")
    return "; ".join(reasons) or "parameters within rounding: the two differ only in detail"


def print_report(entries: list[Entry], seconds: float) -> dict[str, Any]:
    kinds = {k: [e for e in entries if e.kind == k] for k in ("opaque", "layered", "transmissive")}
    done = [e for e in entries if "a" in e.err and "b" in e.err]
    print(
        f"# {len(entries)} materials: {len(kinds['opaque'])} opaque, {len(kinds['layered'])} coated or sheen "
        f"(layers freed), {len(kinds['transmissive'])} transmissive (in the transmission probe); "
        f"{len(done)} compared in {seconds:.0f} s\n"
    )
    print("| material | category | kind | (a) hand-made rel. RMSE / DSSIM | (b) matremap rel. RMSE / DSSIM | winner |")
    print("|---|---|---|---|---|---|")
    for e in entries:
        a, b = e.err.get("a"), e.err.get("b")
        cell_a = f"{a['rmse']:.4f} / {a['dssim']:.4f}" if a else "-"
        cell_b = f"{b['rmse']:.4f} / {b['dssim']:.4f}" if b else "-"
        win = "-" if not (a and b) else ("matremap" if b["rmse"] < a["rmse"] else "hand-made")
        print(f"| {e.name} | {e.category} | {e.kind} | {cell_a} | {cell_b} | {win} |")
    wins = [e for e in done if e.err["b"]["rmse"] < e.err["a"]["rmse"]]
    wins_dssim = [e for e in done if e.err["b"]["dssim"] < e.err["a"]["dssim"]]
    med_a = float(np.median([e.err["a"]["rmse"] for e in done])) if done else float("nan")
    med_b = float(np.median([e.err["b"]["rmse"] for e in done])) if done else float("nan")
    print(
        f"\nmatremap lower relative RMSE on {len(wins)}/{len(done)} compared ({len(wins_dssim)}/{len(done)} by DSSIM); "
        f"of all {len(entries)}: {len(wins)}/{len(entries)} = {100 * len(wins) / len(entries):.0f}%; "
        f"median relative RMSE hand-made {med_a:.4f}, matremap {med_b:.4f}\n"
    )
    for kind, rows in kinds.items():
        compared = [e for e in rows if e in done]
        if compared:
            won = sum(e in wins for e in compared)
            print(f"- {kind}: matremap lower on {won}/{len(compared)}")
    print()
    losers = sorted((e for e in done if e not in wins), key=lambda e: e.err["b"]["rmse"] / e.err["a"]["rmse"])
    if losers:
        print("## losers (hand-made closer to the OpenPBR reference)\n")
    for e in losers:
        assert e.source is not None and e.hand is not None and e.fitted is not None
        print(
            f"- **{e.name}**: hand-made {e.err['a']['rmse']:.4f}, matremap {e.err['b']['rmse']:.4f} "
            f"(fit loss on the probe {e.fit_loss:.4f}). OpenPBR: {brief(e.source)}; hand-made: {brief(e.hand)}; "
            f"matremap: {brief(e.fitted)}. Why: {why(e)}"
        )
    notes = [e for e in entries if e.notes]
    if notes:
        print("\n## notes\n")
        for e in notes:
            print(f"- {e.name}: {'; '.join(e.notes)}")
    return {
        "materials": len(entries),
        "opaque": len(kinds["opaque"]),
        "layered": len(kinds["layered"]),
        "transmissive": len(kinds["transmissive"]),
        "compared": len(done),
        "wins": len(wins),
        "wins_dssim": len(wins_dssim),
        "rows": {e.name: {"kind": e.kind, **{k: v for k, v in e.err.items()}} for e in entries},
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, default=96, help="image resolution (default 96)")
    ap.add_argument("--min-roughness", type=float, default=0.3, help="perceptual roughness floor (default 0.3)")
    ap.add_argument("--env", default="builtin", help="environment map (default builtin)")
    ap.add_argument("--fit-lights", default="0,60", help="probe light angles of dielectric fits (default 0,60)")
    ap.add_argument("--fit-lights-metal", default="0,89", help="probe light angles of metal fits (default 0,89)")
    ap.add_argument("--only", default="", help="comma-separated material names")
    ap.add_argument("--opaque-only", action="store_true", help="leave the transmissive materials out")
    ap.add_argument("--json", help="write the figures to this JSON file")
    args = ap.parse_args(argv)

    t0 = time.perf_counter()
    data = data_dir()
    records = json.loads((data / "PhysicallyBasedMaterial.json").read_text())
    opbr = shader_inputs(data / "PhysicallyBasedMaterialX_OPBR.mtlx", "open_pbr_surface")
    gltf = shader_inputs(data / "PhysicallyBasedMaterialX_GLTF.mtlx", "gltf_pbr")
    only = {s.strip() for s in args.only.split(",") if s.strip()}
    entries = []
    for rec in records:
        if only and rec["name"] not in only:
            continue
        if rec["name"] not in opbr:
            print(f"(no OpenPBR definition of {rec['name']})", file=sys.stderr)
            continue
        entries.append(classify(rec["name"], "/".join(rec["category"]), opbr[rec["name"]], gltf.get(rec["name"])))
    views = EnvViews(args.size, args.env)
    fit_scenes = {
        kind: Scene.probe([float(x) for x in lights.split(",")], args.size)
        for kind, lights in (("dielectric", args.fit_lights), ("metal", args.fit_lights_metal))
    }
    for e in entries:
        if e.kind != "transmissive":
            run_entry(e, views, args.min_roughness, fit_scenes)
        elif not args.opaque_only:
            run_transmissive(e, args.size, args.env, fit_scenes["dielectric"])
    figures = print_report(entries, time.perf_counter() - t0)
    if args.json:
        Path(args.json).write_text(json.dumps(figures, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
