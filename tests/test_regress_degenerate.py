"""Learning from sweeps that cannot determine a k(alpha) mapping (matremap.regress.parametric).

The rows below are a real sweep's: OpenPBR -> glTF under a sheen (the second step of SheenCloth's
glTF -> OpenPBR -> glTF round trip), specular_roughness over 10 levels and specular_ior over 6, with the
points the stability analysis flagged left out. glTF takes its ior as a number only, so the remap held it at the
fit at the typical texel (1.3003): the target F0 is one value, 0.017047, over the whole sweep while the source's
varies 300-fold. The paper's k(alpha) s1 cannot be a constant; its c5/alpha form chased which points each
roughness level kept, with c1 = 8.76e8 (c2 = 69.4: a spike at the lowest roughness), and the remap stopped with
exit 2 on "mapping reflectance.coef[1] = 876039386.3616362 is not a finite number in [-1e+06, 1e+06]".
"""

import numpy as np
import pytest

from matremap.core.material import Material
from matremap.core.optics import f0_from_ior
from matremap.dialects import get_model
from matremap.errors import MatremapError
from matremap.regress import schema
from matremap.regress.data import TrainingData
from matremap.regress.library import entries
from matremap.regress.parametric import COEF_MAX, evaluate, fit_reflectance, k_alpha, learn
from matremap.regress.transform import Transform, transform_from_data

SOURCE, TARGET = get_model("mtlx:open_pbr_surface"), get_model("gltf:pbr")
#: (roughness level, ior level) of each kept row, in the database's order
ROWS = (
    "0111220313233343530414243444546474940515253545556575102030406070809001112131415161718191223242526272829203"
    "1323334353637383930414243444546474849405152535455565758595"
)
HELD_F0 = 0.017047332149109723  # the target's F0 over the sweep: glTF's ior held at 1.3003


def sweep_rows() -> tuple[np.ndarray, np.ndarray]:
    """alpha [82] and the source F0 [82, 3] of the sweep's kept rows."""
    alpha = np.linspace(0.339091, 0.680221, 10)[[int(c) for c in ROWS[::2]]]
    f0 = f0_from_ior(np.linspace(1.029404, 1.687492, 6))[[int(c) for c in ROWS[1::2]]]
    return alpha, np.repeat(f0[:, None], 3, axis=1)


def accepted(name: str, mapping: dict) -> None:
    """The mapping as a transform file may hold it (every coefficient finite and within 1e6)."""
    schema.mapping(name, mapping, SOURCE, TARGET, "test")


def test_a_held_target_f0_is_learned_as_the_constant_it_is():
    alpha, s1 = sweep_rows()
    s2 = np.full_like(s1, HELD_F0)
    m = fit_reflectance(alpha, s1, s2)
    accepted("reflectance", m)
    pred = evaluate(m, {"roughness": alpha, "reflectance": s1})
    np.testing.assert_allclose(pred, s2, rtol=0, atol=1e-9)
    assert m["kind"] == "constant" and m["heldout_rmse"] == 0.0
    # the k(alpha) forms it was weighed against: an error of a third of the F0 itself
    assert min(m["heldout_rmse_by_form"]["paper"], m["heldout_rmse_by_form"]["paper+c5/alpha"]) > 0.3 * HELD_F0


def test_a_target_f0_that_barely_varies_is_still_the_constant():
    """A fitted ior a little off the held one (a relative scatter of 1e-3): the constant predicts the held-out
    points 300 times better than any k(alpha) s1."""
    alpha, s1 = sweep_rows()
    s2 = HELD_F0 * (1 + 1e-3 * np.random.default_rng(3).standard_normal(s1.shape))
    m = fit_reflectance(alpha, s1, s2)
    accepted("reflectance", m)
    pred = evaluate(m, {"roughness": alpha, "reflectance": s1})
    assert m["kind"] == "constant"
    assert np.max(np.abs(pred - HELD_F0)) < 1e-3 * HELD_F0


def test_a_fit_that_runs_off_keeps_its_coefficients_bounded():
    """An offset target (s2 = F0_held + s1 / 2), which k(alpha) s1 can only approximate: the c5/alpha form ran
    to coefficients of 2.9e9. Every coefficient now stays within COEF_MAX, and the mapping still beats the
    constant on held-out points."""
    alpha, s1 = sweep_rows()
    s2 = HELD_F0 + 0.5 * s1
    m = fit_reflectance(alpha, s1, s2)
    accepted("reflectance", m)
    assert m["kind"] == "k_alpha" and np.max(np.abs(m["coef"])) <= COEF_MAX
    assert m["heldout_rmse"] < m["heldout_rmse_by_form"]["constant"]
    assert all(np.isfinite(v) and v < 0.5 * np.ptp(s2) for v in m["heldout_rmse_by_form"].values())


def test_a_well_posed_k_alpha_keeps_its_coefficients():
    """Data that follow the paper's k(alpha) exactly give it back (either form: both fit to rounding, c5 = 0):
    the bound and the constant never enter."""
    true = [0.9, 0.3, 3.0, -0.2, 4.0]
    a, f = np.meshgrid(np.linspace(0.05, 0.9, 8), np.linspace(0.02, 0.25, 6), indexing="ij")
    alpha, s1 = a.ravel(), np.repeat(f.ravel()[:, None], 3, axis=1)
    m = fit_reflectance(alpha, s1, k_alpha(alpha, true)[:, None] * s1)
    assert m["kind"] == "k_alpha" and "bounded" not in m and "tint" not in m
    np.testing.assert_allclose(m["coef"], true + [0.0] * (len(m["coef"]) - 5), atol=1e-6)
    assert m["heldout_rmse"] < 1e-9


def test_shipped_k_alpha_fits_stay_within_the_bound():
    """The bound is no stricter than what the library was learned with (its largest coefficient is 322)."""
    seen = 0
    for e in entries():
        for t in e.transform.steps or [e.transform]:
            m = t.mappings.get("reflectance", {})
            if m.get("kind") == "k_alpha":
                assert np.max(np.abs(m["coef"])) <= COEF_MAX, e.name
                seen += 1
    assert seen > 20


def training_data(y_diffuse: np.ndarray) -> TrainingData:
    alpha, s1 = sweep_rows()
    diffuse = np.where(np.arange(len(alpha))[:, None] % 2, 0.318747, 0.0) * np.ones(3)
    template = Material.create(TARGET.id, {"metallic": 0.0, "ior": 1.3003}).to_dict()["params"]
    return TrainingData(
        SOURCE,
        TARGET,
        {"multiscatter": "turquin"},
        {"visibility": "height-correlated"},
        {"roughness": alpha, "reflectance": s1, "diffuse": diffuse},
        {"roughness": 0.2 + alpha**2, "reflectance": np.full_like(s1, HELD_F0), "diffuse": y_diffuse},
        template,
        {},
        Material.create(SOURCE.id, {}).to_dict()["params"],
    )


def test_learning_a_held_target_gives_a_transform_that_saves_and_applies(tmp_path):
    """The whole path the remap took: learn, seal (the schema check that stopped it), save, load, apply."""
    alpha, s1 = sweep_rows()
    data = training_data(np.full((len(alpha), 3), 0.25))  # a target diffuse held too, while the source's varies
    t = transform_from_data(data)
    assert t.mappings["reflectance"]["kind"] == "constant"
    assert t.mappings["diffuse"] == {"kind": "constant", "value": [0.25, 0.25, 0.25]}  # not a scale of the source
    assert t.mappings["roughness"]["kind"] == "polynomial"
    back = Transform.load(t.save(tmp_path / "t.json"), require_checksum=True)
    ior = np.array([1.1, 1.4, 1.6])
    source = {"specular_roughness": np.array([0.4, 0.5, 0.6]), "specular_ior": ior, "base_color": 0.2}
    out, outside = back.apply(source)
    np.testing.assert_allclose(out["ior"], 1.3003, atol=1e-3)
    np.testing.assert_allclose(out["baseColor"], 0.25)
    assert not outside.any()


def test_a_sweep_that_varies_nothing_the_target_follows_is_still_refused():
    data = training_data(np.full((82, 3), 0.25))
    data.x = {k: np.broadcast_to(v[:1], v.shape) for k, v in data.x.items()}
    with pytest.raises(MatremapError, match="varies no source quantity"):
        learn(data)
