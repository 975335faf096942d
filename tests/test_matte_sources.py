"""A target's lobe is decided by what the source has, not left where a fit under the headlight wandered: a matte
source gives no lobe, and a lobe too narrow for the point probe to resolve is chosen under the environment."""

import numpy as np
import pytest

from matremap.core.material import Material
from matremap.regress.data import TrainingData
from matremap.regress.parametric import learn
from matremap.regress.transform import learn_transform
from matremap.sweep.executors import InlineExecutor
from matremap.sweep.grid import parse_grid
from matremap.sweep.run import SweepConfig, run_sweep
from matremap.uniform import fit

LAMBERTIAN = Material.create("mitsuba3:diffuse", {"reflectance": 0.45})
#: glTF's dielectric at roughness 1: a lobe as wide as it gets, at F0 0.04
ROUGH_GREY = Material.create("gltf:metal-rough", {"baseColor": 0.45, "roughness": 1.0, "metallic": 0.0})
PRINCIPLED_ROUGHNESS = 0.5  # Mitsuba 3's principled default
DIELECTRIC = {"metallic": 0.0}  # as remap holds it for a dielectric source


def scalar(m: Material, name: str) -> float:
    return float(np.mean(m.values[name]))


@pytest.mark.parametrize("strategy", ["simple", "separable", "two-stage", "three-stage"])
def test_a_matte_source_gives_no_lobe_under_every_strategy(strategy):
    r = fit(LAMBERTIAN, "mitsuba3:principled", strategy, fix=DIELECTRIC)
    assert scalar(r.target, "specular") == 0.0
    # a lobe that draws nothing keeps the roughness the fit started from (the target's default)
    assert scalar(r.target, "roughness") == pytest.approx(PRINCIPLED_ROUGHNESS)
    assert scalar(r.target, "base_color") == pytest.approx(0.45, abs=0.02)
    assert r.loss < 0.05


def test_a_lobe_the_headlight_cannot_resolve_is_chosen_under_the_environment():
    r = fit(ROUGH_GREY, "mitsuba3:principled", "simple", fix=DIELECTRIC)
    # F0 0.08 * specular: a near-mirror lobe of specular 0.44 (F0 0.035) is what the point probe alone chose
    assert scalar(r.target, "specular") < 0.1
    assert scalar(r.target, "roughness") > 0.25
    assert any("environment views" in w for w in r.warnings)


def test_a_resolved_lobe_is_not_second_guessed():
    glossy = Material.create("gltf:metal-rough", {"baseColor": 0.3, "roughness": 0.4, "metallic": 0.0})
    r = fit(glossy, "mitsuba3:principled", "simple", fix=DIELECTRIC)
    assert not any("environment views" in w for w in r.warnings)
    assert scalar(r.target, "specular") > 0.2


def test_a_matte_sweep_learns_no_lobe(tmp_path):
    db = tmp_path / "matte.sqlite"
    config = SweepConfig(source=LAMBERTIAN, target="mitsuba3:principled", fix=DIELECTRIC, strategy="simple")
    grid = parse_grid("reflectance=0.1:0.8:6", LAMBERTIAN.spec)
    swept = run_sweep(config, grid, str(db), InlineExecutor())
    assert swept.failed == 0
    t = learn_transform(db)
    values, _ = t.apply({"reflectance": np.array([[0.2, 0.5, 0.7]])})
    assert np.all(np.asarray(values["specular"]) == 0.0)
    assert np.allclose(values["roughness"], PRINCIPLED_ROUGHNESS)


def test_a_constant_roughness_is_learned_from_the_rows_that_draw_a_lobe():
    n = 14
    off = np.arange(n) % 7 < 4  # most fits turned the lobe off and left the roughness anywhere; six drew one
    data = TrainingData(
        source=None,  # type: ignore[arg-type]
        target=None,  # type: ignore[arg-type]
        source_options={},
        target_options={},
        x={"diffuse": np.linspace(0.1, 0.8, n)[:, None].repeat(3, 1)},
        y={
            "roughness": np.where(off, 0.001, 0.6),
            "reflectance": np.where(off[:, None], 0.0, 0.04).repeat(3, 1),
            "diffuse": np.linspace(0.1, 0.8, n)[:, None].repeat(3, 1),
        },
        template={},
        provenance={},
        source_template={},
    )
    assert learn(data)["roughness"] == {"kind": "constant", "value": pytest.approx(0.6)}
