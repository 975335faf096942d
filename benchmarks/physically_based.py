"""PhysicallyBased, all 110: each material's OpenPBR definition (or, with ``--source standard_surface``, its
Standard Surface one) remapped onto glTF (with its KHR layer extensions) by matremap, against the hand-made glTF
version shipped beside it.

    .venv/bin/python benchmarks/physically_based.py [--source open_pbr|standard_surface] [--size 96]
        [--min-roughness 0.3] [--only NAME,...] [--json FILE]

Data: the PhysicallyBased database (Anton Palmqvist, https://physicallybased.info, CC0) with Bernard Kwok's
MaterialX translations in the PyPI package ``materialxmaterials`` (``pip install materialxmaterials``):
``PhysicallyBasedMaterialX_OPBR.mtlx`` (an ``open_pbr_surface`` per material),
``PhysicallyBasedMaterialX_SS.mtlx`` (a ``standard_surface`` per material: the same values, the metals' edge tint
in Gulbrandsen's form instead of F82) and ``PhysicallyBasedMaterialX_GLTF.mtlx`` (the hand-made ``gltf_pbr``
versions); categories from ``PhysicallyBasedMaterial.json``.

For every material:

* **reference**: its source node read with MaterialX into ``mtlx:open_pbr_surface`` or ``mtlx:standard_surface``
  (the inputs the embedded model has; inputs whose weight is absent, so 0 by the spec -- subsurface radius without
  subsurface weight, thin film without thin-film weight, transmission colour without transmission weight --
  are noted and change nothing);
* **(a) hand-made**: its ``gltf_pbr`` node into ``gltf:pbr`` (base_color, metallic, roughness, ior,
  specular_color, clearcoat, clearcoat_roughness, sheen_color, sheen_roughness, transmission, thickness,
  attenuation_color, attenuation_distance; iridescence noted);
* **(b) matremap**, opaque materials: ``matremap.fit(reference, "gltf:pbr", ...)`` with metallic held at the
  source's metalness, the glTF layers freed where the source has the matching layer (coat: clearcoat,
  clearcoatRoughness; fuzz or sheen: sheenColor, sheenRoughness), fitted on the probe, strategy three-stage:
  dielectrics under a headlight and a light at 60 degrees (``--fit-lights``), metals under a headlight and a
  grazing light at 89 degrees (``--fit-lights-metal``), which reaches the half-angles near 82 degrees where
  OpenPBR's F82 edge tint dips and the environment's back light shows it (glTF's Schlick metal cannot dip; the fit
  weighs how much to give up). The metal lights were chosen on this set: with 0/85 twelve F82 metals lose by
  0.1-1.5 %, with 0/89 four by less than 0.4 %; with the headlight alone (``--fit-lights-metal 0``) most F82 metals
  lose by 1-3 %.
* **(b) matremap**, transmissive materials (transmission weight > 0): exactly what
  ``matremap remap PhysicallyBasedMaterialX_OPBR.mtlx --material NAME --to gltf:pbr -o OUT`` does (the call is
  :func:`matremap.remap.remap_file` with the CLI's defaults, into a scratch folder): the file's material read by
  matremap's MaterialX reader, metallic held at 0 (``glass_is_dielectric``), and the fit of
  :mod:`matremap.transmissive` -- the transmission probe (a headlight plus the sphere before a tiled plane under
  the built-in map, 64 px, 8 paths), strategy ``simple``, started from the transmission read across
  (``transmission.EQUIVALENTS``) with glTF's ``transmission`` and ``attenuationColor`` freed. The remap's gate
  verdict is kept. **(c) formula**: the read-across alone (``transmission.gltf_equivalent``: KHR_materials_
  transmission and _volume with the sphere's thickness), unfitted, as an extra column. No roughness floor here.

Opaque materials are rendered by the embedded renderer on the evaluation sphere under the environment map
(``--env``, default matremap's built-in one, sampled into 256 directional lights); perceptual roughness is raised
to ``--min-roughness`` in the reference and the hand-made version alike (the PhysicallyBased metals are mirrors,
which directional lights cannot show). Transmissive ones are compared in the transmission probe
(:mod:`matremap.renderers.embedded.transmission`: the sphere before a tiled plane under the same environment,
``--size`` px, 32 paths per pixel for a rough one). Error: relative RMSE over the sphere against the reference,
and DSSIM = 1 - SSIM. The table lists every material; the losers follow with what each candidate got wrong.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
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

TARGET = "gltf:pbr"
ENV_LIGHTS = 256


@dataclass(frozen=True)
class Layer:
    """A source layer and the gltf:pbr parameters freed for it: ``frees[0]`` starts at the layer's weight (times
    its ``colour`` when it has one), ``frees[1]`` at its ``roughness``."""

    weight: str
    roughness: str
    colour: str | None
    frees: tuple[str, str]


@dataclass(frozen=True)
class Source:
    """One of the package's translations of the database: its file, node category, matremap model and the names of
    the inputs the benchmark reads."""

    file: str
    category: str
    model: str
    metalness: str
    ior: str
    transmission: str
    layers: tuple[Layer, ...]
    #: inputs that do nothing while the weight named beside them is absent (0 by the spec)
    inert: dict[str, str]


SOURCES = {
    "open_pbr": Source(
        "PhysicallyBasedMaterialX_OPBR.mtlx",
        "open_pbr_surface",
        "mtlx:open_pbr_surface",
        "base_metalness",
        "specular_ior",
        "transmission_weight",
        (
            Layer("coat_weight", "coat_roughness", None, ("clearcoat", "clearcoatRoughness")),
            Layer("fuzz_weight", "fuzz_roughness", "fuzz_color", ("sheenColor", "sheenRoughness")),
        ),
        {
            "subsurface_radius": "subsurface_weight",
            "subsurface_radius_scale": "subsurface_weight",
            "subsurface_color": "subsurface_weight",
            "thin_film_ior": "thin_film_weight",
            "thin_film_thickness": "thin_film_weight",
            "transmission_color": "transmission_weight",
            "transmission_depth": "transmission_weight",
            "transmission_dispersion_abbe_number": "transmission_weight",
            "transmission_dispersion_scale": "transmission_weight",
        },
    ),
    "standard_surface": Source(
        "PhysicallyBasedMaterialX_SS.mtlx",
        "standard_surface",
        "mtlx:standard_surface",
        "metalness",
        "specular_IOR",
        "transmission",
        (
            Layer("coat", "coat_roughness", None, ("clearcoat", "clearcoatRoughness")),
            Layer("sheen", "sheen_roughness", "sheen_color", ("sheenColor", "sheenRoughness")),
        ),
        {
            "subsurface_radius": "subsurface",
            "subsurface_scale": "subsurface",
            "subsurface_color": "subsurface",
            "thin_film_IOR": "thin_film_thickness",
            "transmission_color": "transmission",
            "transmission_depth": "transmission",
            "transmission_dispersion": "transmission",
        },
    ),
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


def shader_inputs(path: Path, category: str) -> dict[str, tuple[str, dict[str, Any]]]:
    """uiname -> (its surfacematerial's name, {input name: value (float or list)}) of every ``category`` node of a
    MaterialX document."""
    import MaterialX as mx

    doc = mx.createDocument()
    mx.readFromXmlFile(doc, str(path))
    material_of = {s.getName(): m.getName() for m in doc.getMaterialNodes() for s in mx.getShaderNodes(m)}
    out: dict[str, tuple[str, dict[str, Any]]] = {}
    for node in doc.getNodes():
        if node.getCategory() != category:
            continue
        values: dict[str, Any] = {}
        for inp in node.getInputs():
            vals = [float(v) for v in inp.getValueString().replace(",", " ").split()]
            values[inp.getName()] = vals[0] if len(vals) == 1 else vals
        name = node.getAttribute("uiname") or node.getName()
        out[name] = (material_of.get(node.getName(), node.getName()), values)
    return out


@dataclass
class Entry:
    name: str
    category: str
    material: str  # the surfacematerial's name in the source file
    kind: str = "opaque"  # opaque | layered | transmissive
    layers: list[Layer] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    source: Material | None = None
    hand: Material | None = None
    fitted: Material | None = None
    formula: Material | None = None  # transmissive: the read-across, unfitted
    fit_loss: float = float("nan")
    verdict: str = ""  # transmissive: the remap's gate verdict
    passed: bool | None = None
    seconds: float = 0.0
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


def on(values: dict[str, Any], weight: str) -> bool:
    """Whether the input ``weight`` is above 0 (a list: any of its values; the package writes Standard Surface's
    scalar ``thin_film_thickness`` as three values)."""
    return float(np.max(values.get(weight, 0.0))) > 0.0


def classify(
    src: Source, name: str, category: str, material: str, values: dict[str, Any], gltf: dict[str, Any] | None
) -> Entry:
    e = Entry(name, category, material)
    if on(values, src.transmission):
        e.kind = "transmissive"
    inert = {k for k, w in src.inert.items() if not on(values, w)}
    for inp in sorted(inert & set(values)):
        e.notes.append(f"{inp} without {src.inert[inp]}: no effect")
    spec = get_model(src.model)
    unknown = [k for k in values if k not in spec.param_names and k not in inert and k != "surfaceshader"]
    if unknown:
        e.notes.append(f"{src.category} inputs not modelled: {', '.join(unknown)}")
    e.layers = [layer for layer in src.layers if on(values, layer.weight)]
    if e.layers and e.kind != "transmissive":
        e.kind = "layered"
    e.source = to_model(src.model, values, None, e.notes)
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


def layer_start(source: Material, layers: list[Layer]) -> dict[str, Any]:
    """gltf:pbr layer values read off the source's layers: a start for the fit."""
    v = source.values
    start: dict[str, Any] = {}
    for layer in layers:
        w = float(v[layer.weight][0])
        start[layer.frees[0]] = w if layer.colour is None else np.clip(w * v[layer.colour], 0.0, 1.0).tolist()
        start[layer.frees[1]] = float(v[layer.roughness][0])
    return start


def run_transmissive(e: Entry, path: Path, size: int, env: str, work: Path) -> None:
    """A transmissive material as ``matremap remap PATH --material NAME --to gltf:pbr -o OUT`` converts it
    (:func:`matremap.remap.remap_file`, the CLI's defaults: the transmission-probe fit of
    :mod:`matremap.transmissive`), the read-across formula beside it (:func:`~matremap.renderers.embedded.
    transmission.gltf_equivalent`), and the hand-made glTF, each against the source in the transmission probe."""
    from matremap.formats import read_asset
    from matremap.remap import remap_file
    from matremap.renderers.embedded import transmission as tr

    assert e.source is not None
    read = read_asset(path, e.material).material()  # what the CLI fits: the benchmark's reference, or noted
    differ = [k for k, v in e.source.values.items() if k in read.values and not np.allclose(v, read.values[k])]
    if read.model != e.source.model or differ:
        e.notes.append(f"matremap's reader reads it as {read.model} with {', '.join(differ) or 'other values'}")
    log: list[str] = []
    t0 = time.perf_counter()
    result = remap_file(path, TARGET, work / e.material, material=e.material, force=True, log=log.append)
    e.seconds = time.perf_counter() - t0
    assert result.material is not None and result.loss is not None
    e.fitted, e.fit_loss = result.material, result.loss
    e.verdict, e.passed = result.verdict.line(), result.verdict.passed
    e.notes += [line[len("warning: ") :] for line in log if "narrower" in line or "lost" in line]
    e.formula = Material.create(TARGET, tr.gltf_equivalent(tr.interface_of(e.source)))
    scene = tr.TransmissionScene(resolution=size, env=env)
    mask = object_mask("sphere", size)
    ref = tr.render(e.source, scene)
    cands = {"b": e.fitted, "c": e.formula}
    if e.hand is not None:
        cands["a"] = e.hand
    for who, m in cands.items():
        img = tr.render(m, scene)
        e.err[who] = {"rmse": rel_rmse(img, ref, mask), "dssim": dssim(img, ref, mask)}


def run_entry(e: Entry, src: Source, views: EnvViews, floor: float, fit_scenes: dict[str, Scene]) -> None:
    assert e.source is not None
    e.source = source = floored(e.source, "specular_roughness", floor)
    metal = float(source.values[src.metalness][0])
    free = [p for layer in e.layers for p in layer.frees]
    fix = {"metallic": 1.0 if metal >= 0.5 else 0.0}
    fit_scene = fit_scenes["metal" if metal >= 0.5 else "dielectric"]
    t0 = time.perf_counter()
    r = fit(source, TARGET, "three-stage", scene=fit_scene, fix=fix, free=free)
    if e.layers:  # a second start with the layers on, at the source's own values (a freed layer starts off)
        start = layer_start(source, e.layers)
        r2 = fit(source, TARGET, "three-stage", scene=fit_scene, fix=fix, free=free, start=start)
        r = r2 if r2.loss < r.loss else r
    e.seconds = time.perf_counter() - t0
    e.fitted, e.fit_loss = r.target, r.loss
    ref = views.render(source)
    cands = {"b": e.fitted}
    if e.hand is not None:
        e.hand = cands["a"] = floored(e.hand, "roughness", floor)
    for who, m in cands.items():
        img = views.render(m)
        e.err[who] = {"rmse": rel_rmse(img, ref, views.mask), "dssim": dssim(img, ref, views.mask)}


def brief(m: Material, src: Source) -> str:
    v = m.values
    if m.model == TARGET:
        s = f"base {np.round(v['baseColor'], 3).tolist()} m {v['metallic'][0]:g} r {v['roughness'][0]:.3f}"
        if v["metallic"][0] < 0.5:
            s += f" ior {v['ior'][0]:.3f}"
            if np.any(np.abs(v["specularColor"] - 1.0) > 1e-6):
                s += f" specColor {np.round(v['specularColor'], 2).tolist()}"
        if v["transmission"][0] > 0:
            s += f" transmission {v['transmission'][0]:.3f} thickness {v['thickness'][0]:g}"
            if v["thickness"][0] > 0:
                s += f" attenuation {np.round(v['attenuationColor'], 3).tolist()}@{v['attenuationDistance'][0]:g}"
        if v["clearcoat"][0] > 0:
            s += f" clearcoat {v['clearcoat'][0]:.2f}/{v['clearcoatRoughness'][0]:.2f}"
        if np.max(v["sheenColor"]) > 0:
            s += f" sheen {np.round(v['sheenColor'], 2).tolist()}/{v['sheenRoughness'][0]:.2f}"
        return s
    s = f"base {np.round(v['base_color'], 3).tolist()} metal {v[src.metalness][0]:g}"
    s += f" r {v['specular_roughness'][0]:.3f} ior {v[src.ior][0]:.3f}"
    if np.any(np.abs(v["specular_color"] - 1.0) > 1e-6):
        s += f" specular_color {np.round(v['specular_color'], 3).tolist()}"
    if v[src.transmission][0] > 0:
        s += f" transmission {v[src.transmission][0]:g} colour {np.round(v['transmission_color'], 3).tolist()}"
    return s


def why(e: Entry, src: Source) -> str:
    """What separates the two candidates of a loser, from their parameters."""
    assert e.hand is not None and e.fitted is not None and e.source is not None
    h, b, s = e.hand.values, e.fitted.values, e.source.values
    reasons = []
    if s[src.metalness][0] >= 0.5 and np.any(np.abs(s["specular_color"] - 1.0) > 0.02):
        reasons.append(
            "an edge-tinted metal: glTF's Schlick metal has no edge tint, so the fit trades base colour against "
            "the rim under the probe's lights while the hand-made base colour is the F0 exactly"
        )
    if e.kind == "transmissive":
        if h["thickness"][0] == 0 and b["thickness"][0] > 0:
            reasons.append("hand-made thin-walled (no KHR_materials_volume thickness), matremap a volume")
        d = np.abs(h["attenuationColor"] - b["attenuationColor"]).max()
        if d > 0.03 and b["thickness"][0] > 0:
            reasons.append(f"attenuation colour differs by up to {d:.3f}")
        if abs(h["transmission"][0] - b["transmission"][0]) > 0.02:
            reasons.append(f"transmission: hand-made {h['transmission'][0]:.3f}, fitted {b['transmission'][0]:.3f}")
    if abs(h["roughness"][0] - b["roughness"][0]) > 0.05:
        reasons.append(f"roughness: hand-made {h['roughness'][0]:.3f}, fitted {b['roughness'][0]:.3f}")
    d = np.abs(h["baseColor"] - b["baseColor"]).max()
    if d > 0.03:
        reasons.append(f"base colour differs by up to {d:.3f}")
    if s[src.metalness][0] < 0.5 and abs(h["ior"][0] - b["ior"][0]) > 0.05:
        reasons.append(f"ior: hand-made {h['ior'][0]:.3f}, fitted {b['ior'][0]:.3f}")
    return "; ".join(reasons) or "parameters within rounding: the two differ only in detail"


def cell(err: dict[str, float] | None) -> str:
    return f"{err['rmse']:.4f} / {err['dssim']:.4f}" if err else "-"


def print_report(entries: list[Entry], src: Source, seconds: float) -> dict[str, Any]:
    """Print the table, the summary lines, the losers and the notes; return the figures.

    Long: one block per part of the report, in the order printed."""
    kinds = {k: [e for e in entries if e.kind == k] for k in ("opaque", "layered", "transmissive")}
    done = [e for e in entries if "a" in e.err and "b" in e.err]
    print(
        f"# {len(entries)} materials from {src.file} ({src.model}): {len(kinds['opaque'])} opaque, "
        f"{len(kinds['layered'])} coated or sheen (layers freed), {len(kinds['transmissive'])} transmissive (in the "
        f"transmission probe, converted as `matremap remap` does); {len(done)} compared in {seconds:.0f} s\n"
    )
    print(
        "| material | category | kind | (a) hand-made rel. RMSE / DSSIM | (b) matremap rel. RMSE / DSSIM "
        "| (c) formula rel. RMSE / DSSIM | winner |"
    )
    print("|---|---|---|---|---|---|---|")
    for e in entries:
        a, b = e.err.get("a"), e.err.get("b")
        win = "-" if not (a and b) else ("matremap" if b["rmse"] < a["rmse"] else "hand-made")
        row = f"| {e.name} | {e.category} | {e.kind} | {cell(a)} | {cell(b)} | {cell(e.err.get('c'))} | {win} |"
        print(row)
    wins = [e for e in done if e.err["b"]["rmse"] < e.err["a"]["rmse"]]
    wins_dssim = [e for e in done if e.err["b"]["dssim"] < e.err["a"]["dssim"]]
    med_a = float(np.median([e.err["a"]["rmse"] for e in done])) if done else float("nan")
    med_b = float(np.median([e.err["b"]["rmse"] for e in done])) if done else float("nan")
    print(
        f"\nmatremap lower relative RMSE on {len(wins)}/{len(done)} compared ({len(wins_dssim)}/{len(done)} by DSSIM); "
        f"of all {len(entries)}: {len(wins)}/{len(entries)} = {100 * len(wins) / max(len(entries), 1):.0f}%; "
        f"median relative RMSE hand-made {med_a:.4f}, matremap {med_b:.4f}\n"
    )
    for kind, rows in kinds.items():
        compared = [e for e in rows if e in done]
        if compared:
            won = sum(e in wins for e in compared)
            ra = [e.err["a"]["rmse"] for e in compared]
            rb = [e.err["b"]["rmse"] for e in compared]
            print(
                f"- {kind}: matremap lower on {won}/{len(compared)}; relative RMSE hand-made {min(ra):.4f}-"
                f"{max(ra):.4f} (median {np.median(ra):.4f}), matremap {min(rb):.4f}-{max(rb):.4f} (median "
                f"{np.median(rb):.4f}); fit time {sum(e.seconds for e in compared):.0f} s"
            )
    through = [e for e in kinds["transmissive"] if "b" in e.err and "c" in e.err]
    if through:
        better = sum(e.err["b"]["rmse"] < e.err["c"]["rmse"] for e in through)
        rc = [e.err["c"]["rmse"] for e in through]
        passed = sum(bool(e.passed) for e in through)
        print(
            f"- transmissive, (b) fit against (c) formula: fit lower on {better}/{len(through)}; formula "
            f"{min(rc):.4f}-{max(rc):.4f} (median {np.median(rc):.4f}); remap gate passed {passed}/{len(through)}"
        )
    print()
    losers = sorted((e for e in done if e not in wins), key=lambda e: e.err["b"]["rmse"] / e.err["a"]["rmse"])
    if losers:
        print(f"## losers (hand-made closer to the {src.category} reference)\n")
    for e in losers:
        assert e.source is not None and e.hand is not None and e.fitted is not None
        print(
            f"- **{e.name}**: hand-made {e.err['a']['rmse']:.4f}, matremap {e.err['b']['rmse']:.4f} "
            f"(fit loss on the probe {e.fit_loss:.4f}). {src.category}: {brief(e.source, src)}; hand-made: "
            f"{brief(e.hand, src)}; matremap: {brief(e.fitted, src)}. Why: {why(e, src)}"
        )
    failed = [e for e in kinds["transmissive"] if e.passed is False]
    if failed:
        print("\n## transmissive remaps the gate failed\n")
        for e in failed:
            print(f"- {e.name}: {e.verdict}")
    notes = [e for e in entries if e.notes]
    if notes:
        print("\n## notes\n")
        for e in notes:
            print(f"- {e.name}: {'; '.join(e.notes)}")
    return {
        "source": src.model,
        "materials": len(entries),
        "opaque": len(kinds["opaque"]),
        "layered": len(kinds["layered"]),
        "transmissive": len(kinds["transmissive"]),
        "compared": len(done),
        "wins": len(wins),
        "wins_dssim": len(wins_dssim),
        "seconds": seconds,
        "rows": {
            e.name: {
                "kind": e.kind,
                **e.err,
                "fit_loss": e.fit_loss,
                "seconds": e.seconds,
                **({"verdict": e.verdict} if e.verdict else {}),
                **({"fitted": e.fitted.to_dict()["params"]} if e.fitted is not None else {}),
            }
            for e in entries
        },
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--source", choices=sorted(SOURCES), default="open_pbr", help="translation (default open_pbr)")
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
    src = SOURCES[args.source]
    data = data_dir()
    records = json.loads((data / "PhysicallyBasedMaterial.json").read_text())
    defs = shader_inputs(data / src.file, src.category)
    gltf = shader_inputs(data / "PhysicallyBasedMaterialX_GLTF.mtlx", "gltf_pbr")
    only = {s.strip() for s in args.only.split(",") if s.strip()}
    entries = []
    for rec in records:
        if only and rec["name"] not in only:
            continue
        if rec["name"] not in defs:
            print(f"(no {src.category} definition of {rec['name']})", file=sys.stderr)
            continue
        material, values = defs[rec["name"]]
        hand = gltf[rec["name"]][1] if rec["name"] in gltf else None
        entries.append(classify(src, rec["name"], "/".join(rec["category"]), material, values, hand))
    if args.opaque_only:
        entries = [e for e in entries if e.kind != "transmissive"]
    views = EnvViews(args.size, args.env)
    fit_scenes = {
        kind: Scene.probe([float(x) for x in lights.split(",")], args.size)
        for kind, lights in (("dielectric", args.fit_lights), ("metal", args.fit_lights_metal))
    }
    with tempfile.TemporaryDirectory(prefix="physically_based_") as work:
        for e in entries:
            if e.kind == "transmissive":
                run_transmissive(e, data / src.file, args.size, args.env, Path(work))
            else:
                run_entry(e, src, views, args.min_roughness, fit_scenes)
    figures = print_report(entries, src, time.perf_counter() - t0)
    if args.json:
        Path(args.json).write_text(json.dumps(figures, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
