"""Values a transform asks for beyond what the target model accepts are clipped to its bounds, and counted
(issue 14: a bronze example once wrote a specular colour of [7.05, 4.35, 2.0] "clamped to 1" with exit 0):
the count reaches the conversion report and the quality gate's ``clamped`` measure."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from matremap.dialects import get_model
from matremap.regress import quantities as qty
from matremap.regress.transform import Transform
from matremap.svbrdf.convert import convert
from matremap.svbrdf.textures import load_map_set

ROOT = Path(__file__).resolve().parents[1]
LIBRARY = ROOT / "src" / "matremap" / "regress" / "transforms"


def test_write_counts_values_moved_beyond_the_tolerance():
    spec = get_model("mitsuba06:pbr")
    template = {p.name: p.default_array if p.channels == 3 else p.default_array[0] for p in spec.params}
    rough = np.array([0.2, 0.5, 1.0 + 1e-6, 3.0, -0.5])  # alpha's bounds are (1e-4, 1): two far outside
    f0 = np.tile([[0.5, 0.5, 0.5]], (5, 1))
    f0[0] = [1.5, 0.2, 0.2]  # F0 above 1 in one channel
    counts: dict[str, int] = {}
    out = qty.write(spec, {"roughness": rough, "reflectance": f0}, template, counts)
    assert counts == {"alpha": 2, "reflectance": 1}
    assert out["alpha"].max() <= 1.0 and out["F0"].max() < 1.0
    uniform = np.broadcast_to(np.array([4.0]), (7,))  # one value for every element: counted for each
    counts = {}
    qty.write(spec, {"roughness": uniform, "reflectance": np.tile([[0.1] * 3], (7, 1))}, template, counts)
    assert counts == {"alpha": 7}


def test_an_overshoot_within_the_mappings_own_error_is_not_counted():
    """A regression trained at a bound (glTF roughness 1 fitted at alpha 1) lands past it by its own error
    (alpha 1.0048 from a quartic of held-out RMSE 0.0064): clipping that back asks nothing of the target. The
    excuse is capped (SLACK_MAX of the range), so a poor mapping's overshoots still count."""
    spec = get_model("mitsuba06:pbr")
    template = {p.name: p.default_array if p.channels == 3 else p.default_array[0] for p in spec.params}
    rough = np.array([1.0048, 1.0048, 1.05, -0.002])
    f0 = np.tile([[1.004, 0.5, 0.5]], (4, 1))

    def count(slack=None):
        counts: dict[str, int] = {}  # write clips its quantities in place: fresh copies each time
        qty.write(spec, {"roughness": rough.copy(), "reflectance": f0.copy()}, template, counts, slack)
        return counts

    assert count() == {"alpha": 4, "reflectance": 4}
    assert count({"roughness": 0.0064, "reflectance": 0.005}) == {"alpha": 1}  # 1.05 is beyond any honest error
    assert count({"roughness": 0.5, "reflectance": 0.5}) == {"alpha": 1}  # a poor mapping excuses no more


def test_convert_reports_values_clipped_to_the_targets_bounds(tmp_path):
    doc = json.loads((LIBRARY / "ward-as.json").read_text())
    doc.pop("checksum", None)
    coef = doc["mappings"]["roughness"]["coef"]
    doc["mappings"]["roughness"]["coef"] = [0.0] * (len(coef) - 1) + [3.0]  # alpha 3 everywhere: above 1
    ward_balanced = Transform.from_dict(doc)
    maps = load_map_set(ROOT / "examples" / "blue-plastic")
    maps.constants["variant"] = "balanced"  # the transform's source variant (the maps are Ward)
    report = convert(maps, [ward_balanced], tmp_path / "out")
    h, w = maps.size
    assert report.bounded == h * w
    assert any("clipped to its bounds" in n for n in report.notes)
    honest = convert(maps, [Transform.load(LIBRARY / "ward-as.json")], tmp_path / "honest")
    assert honest.bounded == 0


def test_the_clamped_measure_is_a_fraction_of_the_values(tmp_path):
    """``clamped`` counts values, three to an RGB texel: divided by the texels alone it read 1.7 and 2.5 for
    USD TextureTransformTest onto glTF. With alpha clipped at every texel, one value in seven is clipped."""
    from matremap.remap import values_per_texel

    doc = json.loads((LIBRARY / "ward-as.json").read_text())
    doc.pop("checksum", None)
    coef = doc["mappings"]["roughness"]["coef"]
    doc["mappings"]["roughness"]["coef"] = [0.0] * (len(coef) - 1) + [3.0]  # alpha 3 everywhere: above 1
    maps = load_map_set(ROOT / "examples" / "blue-plastic")
    maps.constants["variant"] = "balanced"
    report = convert(maps, [Transform.from_dict(doc)], tmp_path / "out")
    out = load_map_set(tmp_path / "out")
    h, w = maps.size
    assert values_per_texel(out) == 1 + 3 + 3  # alpha, F0, diffuseReflectance (not the held multiplier)
    assert report.bounded + report.clipped == h * w
    assert (report.bounded + report.clipped) / (h * w * values_per_texel(out)) == 1 / 7
