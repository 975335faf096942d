"""The library holds transforms fitted under the point and the environment probe; remap chooses (issue 18)."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from matremap.core.scene import Scene
from matremap.regress.library import entries, find_route, fitted_under
from matremap.regress.transform import Transform
from matremap.remap import RemapJob, library_probes, remap, sweep_probe
from matremap.svbrdf.choice import best_transform, texel_materials
from matremap.svbrdf.evaluate import parse_rotations
from matremap.svbrdf.mapstats import LIBRARY_LIMIT, summarise
from matremap.svbrdf.textures import load_map_set

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
STUDIO = Path(__file__).parent / "data" / "envmaps" / "studio_small_03_256x128.exr"
AS = {"distribution": "as"}


def routes(model="mitsuba06:ward", options=None):
    options = options or {"variant": "ward"}
    return {p: find_route(model, options, "mitsuba06:pbr", AS, probe=p) for p in ("point", "env", "mixed")}


def test_the_environment_entry_is_tagged_and_fitted_away_from_the_evaluation_views():
    (env,) = [e for e in entries() if e.probe == "env"]
    assert env.name == "wardclassic-as-env" and env.objective == "ssim"
    scene, objective = fitted_under(env.transform)[0]
    default_evaluation = set(parse_rotations(RemapJob("mitsuba06:pbr").rotations))
    assert scene.environment is not None and not set(scene.environment.rotations) & default_evaluation
    assert scene.environment.seed != 0  # the evaluation samples its lights with seed 0
    assert objective == "ssim"


def test_routes_never_mix_probes():
    found = routes()
    assert [e.name for e in found["point"].steps] == ["wardclassic-as"]
    assert [e.name for e in found["env"].steps] == ["wardclassic-as-env"]
    assert found["mixed"] is None
    # a chain through the point library keeps to it
    chain = find_route("mitsuba06:ward", {"variant": "ward"}, "cycles:glossy", {"distribution": "ggx"}, probe="point")
    assert chain is not None and all(e.probe == "point" for e in chain.steps)
    assert (
        find_route("mitsuba06:ward", {"variant": "ward"}, "cycles:glossy", {"distribution": "ggx"}, probe="env") is None
    )


def test_the_choice_takes_the_candidate_whose_look_is_closest():
    """Independent of which probe is better: a transform that goes to AS and straight back to Ward (nearly the
    identity) must beat one that stops at AS, whose Fresnel rims no Ward has; and the scores do not depend on
    the candidates' order."""
    ms = load_map_set(EXAMPLES / "bronze")
    params = summarise(ms).sample(LIBRARY_LIMIT)
    to_as = routes()["point"].transform
    back = Transform.chain([to_as, find_route("mitsuba06:pbr", AS, "mitsuba06:ward", {"variant": "ward"}).transform])
    c = best_transform([to_as, back], ms.model, ms.options, params, "builtin")
    assert c.index == 1 and c.scores[1] < 0.5 * c.scores[0]
    swapped = best_transform([back, to_as], ms.model, ms.options, params, "builtin")
    assert swapped.index == 0 and swapped.scores == pytest.approx(c.scores[::-1])


def test_texel_materials_are_the_median_then_texels_of_the_maps():
    a = np.arange(16.0).reshape(4, 4) / 16
    rgb = np.stack([a, a, a], axis=-1)
    t = texel_materials("mitsuba06:ward", {}, {"alpha": a, "diffuseReflectance": rgb, "specularReflectance": 0.1}, 5)
    assert t["alpha"][0] == pytest.approx(np.median(a)) and t["alpha"].shape == (6,)
    assert set(t["alpha"][1:]) <= set(a.ravel()) and len(set(t["alpha"][1:])) == 5
    np.testing.assert_allclose(t["diffuseReflectance"][1:, 0], t["alpha"][1:])  # the same texels in every map
    assert np.all(t["specularReflectance"] == 0.1)


@pytest.mark.parametrize(
    "probe, objective, kinds, swept",
    [
        ("auto", None, ["point", "env"], ("point", "l2")),
        ("point", None, ["point"], ("point", "l2")),
        ("env", None, ["env"], ("env", "ssim")),
        ("env", "l2", [], ("env", "l2")),
        (f"env:{STUDIO}", None, [], ("env", "ssim")),
        ("mixed", "log", [], ("mixed", "log")),
    ],
)
def test_what_remap_looks_up_and_sweeps_under(probe, objective, kinds, swept):
    job = RemapJob("mitsuba06:pbr", probe=probe, objective=objective)
    assert library_probes(job) == kinds
    scene, obj = sweep_probe(job)
    assert ((scene or Scene()).kind, obj) == swept


def test_remap_auto_picks_a_route_says_which_and_warns_when_judged_on_its_own_views(tmp_path):
    src = tmp_path / "bronze"
    shutil.copytree(EXAMPLES / "bronze", src)
    lines: list[str] = []
    r = remap(src, None, "mitsuba06:pbr", tmp_path / "auto", fix=AS, rotations="30,90", resolution=48, lights=16,
              workers=1, log=lines.append, cache=tmp_path / "cache")  # fmt: skip
    chose = [m for m in lines if m.startswith("library: routes fitted under several probes")]
    assert len(chose) == 1 and "point probe" in chose[0] and "env probe" in chose[0]
    settings = json.loads((r.report.parent / "results.json").read_text())["settings"]
    assert "fitted under" in settings
    if "env probe" in settings["fitted under"]:  # 30 degrees is one of the env fit's rotations
        assert settings["held out"].startswith("no:") and any("warning: no: the evaluation" in m for m in lines)
    else:
        assert "held out" not in settings
    assert not any(m.startswith("sweep:") for m in lines)  # a library route: nothing swept
