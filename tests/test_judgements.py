"""The quality gate on the labelled set of judged results (benchmarks/judgements.py, its measures stored in
tests/data/judgements/measures.json): it fails every rejected case and passes every acceptable one, under the
default thresholds, on the cases the thresholds were chosen on and on those held out."""

from __future__ import annotations

import importlib.util
import json
import sys
from dataclasses import replace
from pathlib import Path

import pytest

from matremap.svbrdf.quality import Thresholds

ROOT = Path(__file__).resolve().parents[1]
MEASURES = ROOT / "tests" / "data" / "judgements" / "measures.json"


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("judgements", ROOT / "benchmarks" / "judgements.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def entries():
    return json.loads(MEASURES.read_text())


def test_the_set_is_the_generators_and_labelled_by_the_kind_of_change(bench, entries):
    cases = bench.cases()
    assert [c.name for c in cases] == list(entries), "measures.json is stale: run benchmarks/judgements.py"
    assert len(cases) >= 60
    acceptable = {"correct conversion", "diffuse x1.03", "alpha x1.04", "F0 x0.97"}
    for c in cases:
        assert entries[c.name]["label"] == c.label == ("acceptable" if c.kind in acceptable else "rejected")
    labels = [c.label for c in cases]
    assert labels.count("acceptable") >= 20 and labels.count("rejected") >= 40


def test_a_third_is_held_out_by_seed(bench, entries):
    held = bench.held_out(list(entries))
    assert len(held) == len(entries) // 3
    assert held == bench.held_out(list(entries))  # drawn from the names and the seed alone


#: rejected cases the gate passes (docs/quality.md): the base lobe of a material under a glossy clear coat (coat
#: roughness 0.05 over base roughness 0.6) 1.5 times duller or sharper; the coat's highlight hides it from every
#: measure here (highlight energy 0.095 and sharpness 0.037 against 0.16 and 0.11 for correct conversions)
KNOWN_MISSES = {"coated blue: duller: alpha x1.5", "coated blue: sharper: alpha /1.5"}


@pytest.mark.parametrize("part", ["chosen on", "held out"])
def test_the_gate_fails_every_rejected_case_and_passes_every_acceptable_one(bench, entries, part):
    held = bench.held_out(list(entries))
    subset = {k: e for k, e in entries.items() if (k in held) == (part == "held out")}
    limits = Thresholds.calibrated()
    wrong = {k for k, e in subset.items() if bench.verdict(e, limits).passed != (e["label"] == "acceptable")}
    assert not any(subset[k]["label"] == "acceptable" for k in wrong), sorted(wrong)
    assert wrong == KNOWN_MISSES & set(subset), sorted(wrong)


def test_the_old_gate_passed_most_gloss_changes(bench, entries):
    """Under the thresholds before the gloss measures (1 - SSIM 0.4, CIEDE2000 12, luminance 0.5, hue 25 degrees,
    no highlight, albedo or HDR-FLIP measure), most of the sharper, duller and removed highlights and changed
    diffuse passed: the set asks what that gate could not see."""
    off = float("inf")
    old = replace(
        Thresholds(),
        luminance_error=0.5,
        delta_e=12.0,
        dssim=0.4,
        hue_shift=25.0,
        highlight_energy=off,
        highlight_sharpness=off,
        flip=off,
        albedo_error=off,
    )
    kinds = ("alpha x1.5", "alpha /1.5", "removed", "diffuse x1.25", "diffuse x0.75")
    changed = {k: e for k, e in entries.items() if any(w in e["kind"] for w in kinds)}
    passed = [k for k, e in changed.items() if bench.verdict(e, old).passed]
    assert len(passed) > len(changed) // 2
