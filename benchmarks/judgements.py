"""The quality gate against a labelled set of converted results: its confusion matrix.

Each case is a source material and a result a technical artist judges at a glance, labelled by the rule of how
the result was made, never by matremap's score:

* **acceptable**: a correct conversion -- the tool's own remap of an example map set (Mitsuba 0.6 Ward ->
  Ashikhmin-Shirley, the README's main job) or the exact identity of a glTF material -- and the same within a few
  per cent (diffuse x1.03, the lobe's alpha x1.04, F0 x0.97);
* **rejected**: the correct result changed by a kind of change that is rejected at a glance: the lobe's alpha
  x1.5 or /1.5 (duller, sharper), matte (alpha x4), highlights removed, the diffuse x1.25 or x0.75, the hue of the
  colours turned by 12 degrees either way, metal <-> dielectric, a clear coat or a sheen lost or invented, a
  matte material made glossy.

Each case is measured as ``remap``'s evaluation measures it (a sphere, 128 lights, the built-in studio at 0, 60,
..., 300 degrees; the map checks on the common quantities), at 96^2 pixels, the values kept in
``tests/data/judgements/measures.json``; the gate's verdict of each case is then :class:`Verdict` over those checks
and the thresholds. A third of the cases (chosen by seed 0 before any was measured) are held out: the thresholds
of docs/quality.md were chosen on the rest; the confusion matrix of each part is printed.

    python benchmarks/judgements.py            # measure every case (about 10 minutes), then the matrices
    python benchmarks/judgements.py --tables   # the matrices from the stored measures
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

from matremap.core.envmap import resolve
from matremap.core.material import SVMaterial
from matremap.dialects import get_model
from matremap.renderers.base import EnvironmentLight
from matremap.renderers.textured import object_mask
from matremap.svbrdf.evaluate import (
    _Comparison,
    _ReportImages,
    highlight_image,
    highlight_part,
    irradiance_scale_under,
    parse_rotations,
    prepare,
)
from matremap.svbrdf.gloss import facing, highlight
from matremap.svbrdf.quality import Check, Thresholds, Verdict

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data" / "judgements"
MEASURES = DATA / "measures.json"
#: remap's evaluation (its lights and views; 96^2 pixels rather than 160^2, a third of the time: the measures are
#: means, medians and ratios over the object's pixels)
RESOLUTION, LIGHTS, ROTATIONS = 96, 128, "0:360:6"
SEED = 0

Params = dict[str, Any]


@dataclass(frozen=True)
class Case:
    name: str
    source: str
    label: str  # "acceptable" or "rejected"
    kind: str
    change: Callable[[Params], Params]


def _hue(rgb: Any, degrees: float) -> np.ndarray:
    """RGB turned about the grey axis by ``degrees`` (Rodrigues' rotation), clipped to [0, 1]."""
    a = np.asarray(rgb, dtype=np.float64)
    k = np.ones(3) / np.sqrt(3.0)
    c, s = np.cos(np.radians(degrees)), np.sin(np.radians(degrees))
    out = a * c + np.cross(k, a) * s + (a @ k)[..., None] * k * (1.0 - c)
    return np.clip(out, 0.0, 1.0)


def _scale(name: str, f: float, hi: float = 1.0) -> Callable[[Params], Params]:
    return lambda p: {**p, name: np.clip(np.asarray(p[name], dtype=np.float64) * f, 0.0, hi)}


def _set(**values: Any) -> Callable[[Params], Params]:
    return lambda p: {**p, **{k: np.asarray(v, dtype=np.float64) for k, v in values.items()}}


def _turn(names: tuple[str, ...], degrees: float) -> Callable[[Params], Params]:
    return lambda p: {**p, **{n: _hue(p[n], degrees) for n in names if np.ndim(p[n]) >= 1 and np.shape(p[n])[-1] == 3}}


def _same(p: Params) -> Params:
    return dict(p)


#: the roughness parameter and the power that takes it to the lobe's alpha, the diffuse colours, the colours
#: whose hue counts, and what removes the highlight, per model of the set
MODELS: dict[str, dict[str, Any]] = {
    "mitsuba06:pbr": {
        "roughness": ("alpha", 1.0),
        "diffuse": "diffuseReflectance",
        "colours": ("diffuseReflectance", "F0"),
        "f0": "F0",
        "no_highlight": {"specularReflectance": [0.0, 0.0, 0.0]},
    },
    "gltf:pbr": {
        "roughness": ("roughness", 2.0),
        "diffuse": "baseColor",
        "colours": ("baseColor",),
        "f0": "specular",
        "no_highlight": {"specular": 0.0},
    },
}


def _cases_for(source: str, model: str, extra: list[tuple[str, str, Callable[[Params], Params]]]) -> list[Case]:
    m = MODELS[model]
    rough, power = m["roughness"]

    def alpha(f: float) -> Callable[[Params], Params]:
        return _scale(rough, f ** (1.0 / power))

    kinds: list[tuple[str, str, Callable[[Params], Params]]] = [
        ("acceptable", "correct conversion", _same),
        ("acceptable", "diffuse x1.03", _scale(m["diffuse"], 1.03)),
        ("acceptable", "alpha x1.04", alpha(1.04)),
        ("acceptable", "F0 x0.97", _scale(m["f0"], 0.97)),
        ("rejected", "duller: alpha x1.5", alpha(1.5)),
        ("rejected", "sharper: alpha /1.5", alpha(1 / 1.5)),
        ("rejected", "matte: alpha x4", alpha(4.0)),
        ("rejected", "highlights removed", _set(**m["no_highlight"])),
        ("rejected", "diffuse x1.25", _scale(m["diffuse"], 1.25)),
        ("rejected", "diffuse x0.75", _scale(m["diffuse"], 0.75)),
        ("rejected", "hue +12 degrees", _turn(m["colours"], 12.0)),
        ("rejected", "hue -12 degrees", _turn(m["colours"], -12.0)),
        *extra,
    ]
    return [Case(f"{source}: {kind}", source, label, kind, change) for label, kind, change in kinds]


#: uniform glTF materials (KHR_materials_clearcoat and _sheen as the corpus' ClearCoatTest and the Standard Surface
#: velvet use them), each its own correct conversion
GLTF: dict[str, Params] = {
    "red plastic": {"baseColor": [0.6, 0.08, 0.05], "metallic": 0.0, "roughness": 0.35, "specular": 1.0},
    "gold": {"baseColor": [1.0, 0.78, 0.34], "metallic": 1.0, "roughness": 0.3, "specular": 1.0},
    "coated blue": {
        "baseColor": [0.05, 0.15, 0.5],
        "metallic": 0.0,
        "roughness": 0.6,
        "specular": 1.0,
        "clearcoat": 1.0,
        "clearcoatRoughness": 0.05,
    },
    "green velvet": {
        "baseColor": [0.15, 0.3, 0.08],
        "metallic": 0.0,
        "roughness": 0.8,
        "specular": 1.0,
        "sheenColor": [0.8, 0.8, 0.8],
        "sheenRoughness": 0.3,
    },
}
EXAMPLES = ("bronze", "blue-plastic", "scratched-gold")


def cases() -> list[Case]:
    """Every case of the set, in a fixed order."""
    out = [c for ex in EXAMPLES for c in _cases_for(ex, "mitsuba06:pbr", [])]
    extra = {
        "red plastic": [
            ("rejected", "dielectric -> metal", _set(metallic=1.0)),
            ("rejected", "coat invented", _set(clearcoat=1.0, clearcoatRoughness=0.05)),
            ("rejected", "sheen invented", _set(sheenColor=[0.8, 0.8, 0.8], sheenRoughness=0.3)),
        ],
        "gold": [("rejected", "metal -> dielectric", _set(metallic=0.0))],
        "coated blue": [("rejected", "coat lost", _set(clearcoat=0.0))],
        "green velvet": [
            ("rejected", "sheen lost", _set(sheenColor=[0.0, 0.0, 0.0])),
            ("rejected", "glossy: roughness 0.3", _set(roughness=0.3)),
        ],
    }
    for name in GLTF:
        if name == "green velvet":  # its look is the sheen: the correct one, the sheen lost, made glossy
            out += [Case(f"{name}: correct conversion", name, "acceptable", "correct conversion", _same)]
            out += [Case(f"{name}: {kind}", name, label, kind, change) for label, kind, change in extra[name]]
            continue
        # a metal's highlight is its colour: glTF's specular, which removes a dielectric's, does nothing to it
        out += [c for c in _cases_for(name, "gltf:pbr", extra[name]) if not (name == "gold" and "removed" in c.kind)]
    return out


def held_out(names: list[str]) -> set[str]:
    """A third of the cases, drawn by :data:`SEED` from the names alone (before anything is measured)."""
    rng = np.random.default_rng(SEED)
    order = rng.permutation(len(names))
    return {names[i] for i in order[: len(names) // 3]}


# ---------------------------------------------------------------------------------------------
# the materials


def _example(name: str, work: Path) -> tuple[SVMaterial, SVMaterial, Any, Any]:
    """An example map set and the tool's own remap of it (the README's main job), with their map sets."""
    from matremap.remap import load_arrays, remap
    from matremap.svbrdf.textures import load_map_set

    out = work / name
    remap(
        ROOT / "examples" / name,
        None,
        "mitsuba06:pbr",
        out,
        fix={"distribution": "as"},
        evaluate=False,
        log=lambda s: None,
    )
    sets = [load_map_set(ROOT / "examples" / name), load_map_set(out / "maps")]
    mats = []
    for ms in sets:
        params, normal = load_arrays(ms)
        mats.append(SVMaterial(ms.model, params, ms.options, normal))
    return mats[0], mats[1], sets[0], sets[1]


def _map_checks(source: SVMaterial, src_set: Any, target: SVMaterial, tgt_set: Any, limits: Thresholds) -> list[Check]:
    from matremap.remap import map_quality

    def side(m: SVMaterial, ms: Any) -> Any:
        return SimpleNamespace(model=m.model, spec=get_model(m.model), constants={**m.options})

    return map_quality(side(source, src_set), dict(source.params), side(target, tgt_set), dict(target.params), limits)


def measure(
    log: Callable[[str], None] = print,
    keep: Callable[[dict[str, Any]], None] = lambda e: None,
    only: tuple[str, ...] = (),
    kinds: tuple[str, ...] = (),
    done: dict[str, Any] | None = None,
    refresh: bool = False,
) -> dict[str, Any]:
    """Every case's checks (name, value, where) under the default thresholds, with its label and kind; ``keep`` is
    given the entries measured so far after each case; ``only``, ``kinds``: only these sources' cases of these
    kinds; ``done``: cases measured before (kept, not rendered again; ``refresh``: their map checks measured
    again)."""
    env = resolve("builtin")
    light = EnvironmentLight(env, LIGHTS)
    rotations = parse_rotations(ROTATIONS)
    mask = object_mask("sphere", RESOLUTION)
    limits = Thresholds.calibrated()
    rendered: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
    out: dict[str, Any] = {}
    done = done or {}
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        pairs: dict[str, tuple[SVMaterial, SVMaterial, Any, Any]] = {}
        for ex in EXAMPLES:
            if (not only or ex in only) and (refresh or any(c.source == ex and c.name not in done for c in cases())):
                pairs[ex] = _example(ex, work)
        for name, values in GLTF.items():
            m = SVMaterial("gltf:pbr", {k: np.asarray(v, dtype=np.float64) for k, v in values.items()}, {}, None)
            pairs[name] = (m, m, None, None)

        def views(m: SVMaterial) -> list[tuple[np.ndarray, np.ndarray]]:
            kind = highlight_part(m)
            full = prepare(m, light, "sphere", RESOLUTION, "full")
            part = prepare(m, light, "sphere", RESOLUTION, kind) if kind != "full" else full
            return [(f := full.render(r), highlight_image(f, part.render(r), kind)) for r in rotations]

        for case in cases():
            if only and (case.source not in only or (kinds and case.kind not in kinds)):
                continue
            if case.name in done:
                out[case.name] = done[case.name]
                if refresh:  # the map checks again (no render)
                    source, correct, src_set, tgt_set = pairs[case.source]
                    target = SVMaterial(correct.model, case.change(dict(correct.params)), correct.options, None)
                    fresh = _map_checks(source, src_set, target, tgt_set, limits)
                    names = {c.name for c in fresh}
                    kept = [c for c in done[case.name]["checks"] if c["name"] not in names]
                    maps = [{"name": c.name, "value": c.value, "where": c.where} for c in fresh]
                    out[case.name] = {**done[case.name], "checks": maps + kept}
                continue
            t0 = time.perf_counter()
            source, correct, src_set, tgt_set = pairs[case.source]
            if case.source not in rendered:
                rendered[case.source] = views(source)
            target = SVMaterial(correct.model, case.change(dict(correct.params)), correct.options, correct.normal)
            scale = irradiance_scale_under(light, source.model, target.model)
            comparison = _Comparison(mask, scale)
            images = _ReportImages(work / "images")
            for k, ((sf, sh), (tf, th)) in enumerate(zip(rendered[case.source], views(target), strict=True)):
                comparison.add(k, "full", sf, tf, images)
                comparison.add(k, "specular", sh, th, images)
            checks = [*_map_checks(source, src_set, target, tgt_set, limits), *comparison.checks(limits)]
            out[case.name] = {
                "source": case.source,
                "kind": case.kind,
                "label": case.label,
                "checks": [{"name": c.name, "value": c.value, "where": c.where} for c in checks],
                "views": [
                    [dataclasses.astuple(highlight(h, f, facing(mask))) for f, h in ((s, hs), (t, ht))]
                    for (_, s, t), (hs, ht) in zip(comparison.full_pairs, comparison.highlights, strict=True)
                ],
            }
            keep(out)
            log(f"{case.name}: {time.perf_counter() - t0:.1f} s")
    return out


# ---------------------------------------------------------------------------------------------
# the tables


def verdict(entry: dict[str, Any], limits: Thresholds) -> Verdict:
    """The gate's verdict of a measured case under ``limits``."""
    return Verdict(
        [
            Check(c["name"], float(c["value"]), getattr(limits, c["name"], 0.0), c["where"])
            for c in entry["checks"]
            if hasattr(limits, c["name"])
        ]
    )


def confusion(entries: dict[str, Any], limits: Thresholds) -> tuple[dict[tuple[str, str], int], list[str]]:
    """(label, verdict) -> count, and the cases the gate got wrong with its line."""
    counts = {(lab, v): 0 for lab in ("acceptable", "rejected") for v in ("passed", "failed")}
    wrong = []
    for name, e in entries.items():
        v = verdict(e, limits)
        counts[(e["label"], "passed" if v.passed else "failed")] += 1
        if v.passed != (e["label"] == "acceptable"):
            wrong.append(f"  {name} ({e['label']}): {v.line()}")
    return counts, wrong


def table(title: str, entries: dict[str, Any], limits: Thresholds) -> str:
    counts, wrong = confusion(entries, limits)
    rows = [
        f"{title} ({len(entries)} cases)",
        "| label \\ verdict | passed | failed |",
        "|---|---|---|",
        *(f"| {lab} | {counts[(lab, 'passed')]} | {counts[(lab, 'failed')]} |" for lab in ("acceptable", "rejected")),
    ]
    return "\n".join(rows + wrong)


def measure_table(entries: dict[str, Any]) -> str:
    """Each measure's largest value over the acceptable cases and the rejected cases it alone fails."""
    limits = Thresholds.calibrated()
    names = [c["name"] for c in next(iter(entries.values()))["checks"] if hasattr(limits, c["name"])]
    rows = ["| measure | threshold | worst acceptable | rejected cases it fails |", "|---|---|---|---|"]
    for n in dict.fromkeys(names):
        values = {k: next(c["value"] for c in e["checks"] if c["name"] == n) for k, e in entries.items()}
        ok = max(v for k, v in values.items() if entries[k]["label"] == "acceptable")
        t = getattr(limits, n)
        caught = sum(1 for k, v in values.items() if entries[k]["label"] == "rejected" and v > t)
        rows.append(f"| {n} | {t:.4g} | {ok:.4g} | {caught} |")
    return "\n".join(rows)


def _value(entry: dict[str, Any], name: str) -> float:
    return float(next((c["value"] for c in entry["checks"] if c["name"] == name), 0.0))


def choose(entries: dict[str, Any], limits: Thresholds) -> dict[str, tuple[float, float, float]]:
    """Per measure: the largest value over the acceptable cases, the smallest over the rejected cases that it alone
    fails under ``limits`` (those only it catches), and the threshold halfway between them."""
    out = {}
    names = [c["name"] for c in next(iter(entries.values()))["checks"] if hasattr(limits, c["name"])]
    for name in dict.fromkeys(names):
        ok = max(_value(e, name) for e in entries.values() if e["label"] == "acceptable")
        alone = [
            _value(e, name)
            for e in entries.values()
            if e["label"] == "rejected" and [c.name for c in verdict(e, limits).failed] == [name]
        ]
        low = min(alone) if alone else float("inf")
        out[name] = (ok, low, (ok + low) / 2.0 if np.isfinite(low) else float("nan"))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--tables", action="store_true", help="print the matrices from the stored measures")
    parser.add_argument("--only", nargs="+", default=[], help="measure only these sources' cases; print, store nothing")
    parser.add_argument("--resume", action="store_true", help="keep the cases already in the stored measures")
    parser.add_argument("--save", metavar="FILE", help="with --only, write the measures to FILE")
    parser.add_argument("--refresh-maps", action="store_true", help="measure the stored cases' map checks again")
    parser.add_argument("--kinds", nargs="+", default=[], help="with --only, only the cases of these kinds")
    args = parser.parse_args()
    if args.only:
        save = Path(args.save) if args.save else None
        found = measure(
            only=tuple(args.only),
            kinds=tuple(args.kinds),
            keep=lambda e: save.write_text(json.dumps(e, indent=1) + "\n") if save else None,
        )
        for name, e in found.items():
            print(name, e["label"], {c["name"]: round(c["value"], 4) for c in e["checks"]})
        return
    if args.refresh_maps:
        found = measure(done=json.loads(MEASURES.read_text()), refresh=True)
        MEASURES.write_text(json.dumps(found, indent=1) + "\n")
    if not args.tables and not args.refresh_maps:
        DATA.mkdir(parents=True, exist_ok=True)
        done = json.loads(MEASURES.read_text()) if args.resume and MEASURES.is_file() else {}
        measure(keep=lambda e: MEASURES.write_text(json.dumps(e, indent=1) + "\n"), done=done)
    entries = json.loads(MEASURES.read_text())
    held = held_out(list(entries))
    limits = Thresholds.calibrated()
    chosen = {k: e for k, e in entries.items() if k not in held}
    print(table("thresholds chosen on", chosen, limits))
    print()
    print(table("held out", {k: e for k, e in entries.items() if k in held}, limits))
    print()
    print(table("all", entries, limits))
    print()
    print(measure_table(entries))
    print()
    print("| measure | worst acceptable | least rejected only it fails | halfway |")
    print("|---|---|---|---|")
    for name, (ok, low, mid) in choose(chosen, limits).items():
        print(f"| {name} | {ok:.4g} | {low:.4g} | {mid:.4g} |")


if __name__ == "__main__":
    main()
