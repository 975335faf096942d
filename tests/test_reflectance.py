"""The typed reflectance classes against hand-computed F0 and the maps they name."""

from __future__ import annotations

import numpy as np
import pytest

from matremap.core.models import ModelSpec
from matremap.core.reflectance import (
    Conductor,
    Dielectric,
    Metalness,
    MetalRough,
    Reflectance,
    SpecularLevel,
    SpecularParam,
)
from matremap.dialects import list_models
from matremap.regress import quantities as qty


def test_specular_param_is_f0_itself() -> None:
    r = SpecularParam("F0")
    grey = r.f0({"F0": np.array([0.3, 0.5])}, {"F0": 1})
    assert np.allclose(grey, [[0.3] * 3, [0.5] * 3])
    rgb = r.f0({"F0": np.array([0.1, 0.2, 0.3])}, {"F0": 3})
    assert np.allclose(rgb, [0.1, 0.2, 0.3])
    assert r.params == r.map_params == ("F0",) and r.driven_param() == "F0" and r.specular_map_param == "F0"


def test_dielectric_f0_of_ior() -> None:
    # (1.5 - 1)^2 / (1.5 + 1)^2 = 0.25 / 6.25 = 0.04
    assert np.allclose(Dielectric("ior").f0({"ior": np.array(1.5)}, {"ior": 1}), [0.04] * 3)
    # relative IOR 1.8 / 1.2 = 1.5: the same 0.04
    r = Dielectric("int", "ext")
    assert np.allclose(r.f0({"int": np.array(1.8), "ext": np.array(1.2)}, {"int": 1, "ext": 1}), [0.04] * 3)
    assert r.params == ("int", "ext") and r.map_params == ("int",)
    assert r.driven_param() == "int" and r.specular_map_param is None


def test_dielectric_writes_ior_back() -> None:
    out = {"int": np.array(1.0), "ext": np.array(1.2)}
    assert Dielectric("int", "ext").write_f0(np.array([0.04] * 3), out, {"int": 1, "ext": 1}) == ["int"]
    assert np.isclose(out["int"], 1.8) and np.isclose(out["ext"], 1.2)


def test_conductor_f0_of_complex_ior() -> None:
    # eta 1, k 2: ((1 - 1)^2 + 4) / ((1 + 1)^2 + 4) = 4 / 8 = 0.5
    r = Conductor("eta", "k")
    assert np.allclose(r.f0({"eta": np.array([1.0] * 3), "k": np.array([2.0] * 3)}, {"eta": 3, "k": 3}), [0.5] * 3)
    # with an exterior IOR 2: eta 2, k 4 relative to it is again eta 1, k 2
    r3 = Conductor("eta", "k", "ext")
    values = {"eta": np.array(2.0), "k": np.array(4.0), "ext": np.array(2.0)}
    assert np.allclose(r3.f0(values, {"eta": 1, "k": 1, "ext": 1}), [0.5] * 3)
    assert r3.params == ("eta", "k", "ext") and r3.map_params == ("eta", "k")
    assert r3.driven_param() == "k" and r3.driven_param(metal=False) == "k" and r3.specular_map_param is None


def test_conductor_writes_k_with_eta_held() -> None:
    out = {"eta": np.array([1.0] * 3), "k": np.array([0.0] * 3)}
    assert Conductor("eta", "k").write_f0(np.array([0.5] * 3), out, {"eta": 3, "k": 3}) == ["k"]
    assert np.allclose(out["k"], 2.0) and np.allclose(out["eta"], 1.0)


GLTF = MetalRough("baseColor", "metallic", "ior", "specular", "specularColor")
GLTF_CH = {"baseColor": 3, "metallic": 1, "ior": 1, "specular": 1, "specularColor": 3}


def _gltf(metallic: float) -> dict[str, np.ndarray]:
    return {
        "baseColor": np.array([0.9, 0.6, 0.3]),
        "metallic": np.array(metallic),
        "ior": np.array(1.5),
        "specular": np.array(1.0),
        "specularColor": np.array([1.0, 1.0, 1.0]),
    }


def test_metal_rough_f0() -> None:
    assert np.allclose(GLTF.f0(_gltf(1.0), GLTF_CH), [0.9, 0.6, 0.3])  # a metal: F0 is the base colour
    assert np.allclose(GLTF.f0(_gltf(0.0), GLTF_CH), [0.04] * 3)  # a dielectric of IOR 1.5
    # half and half: 0.5 * 0.04 + 0.5 * base
    assert np.allclose(GLTF.f0(_gltf(0.5), GLTF_CH), [0.47, 0.32, 0.17])
    half_tint = {**_gltf(0.0), "specularColor": np.array([0.5, 1.0, 2.0])}
    assert np.allclose(GLTF.f0(half_tint, GLTF_CH), [0.02, 0.04, 0.08])


def test_metal_rough_albedo_and_maps() -> None:
    assert np.allclose(GLTF.albedo(np.array([0.9, 0.6, 0.3]), _gltf(0.25)), [0.675, 0.45, 0.225])
    assert GLTF.writes_albedo and not Conductor("eta", "k").writes_albedo
    assert GLTF.map_params == ("baseColor", "metallic")
    assert GLTF.driven_param(metal=True) == "baseColor" and GLTF.driven_param(metal=False) == "specularColor"
    assert GLTF.specular_map_param is None


def test_metal_rough_writes_base_colour_of_a_metal_and_albedo_of_a_dielectric() -> None:
    metal = _gltf(1.0)
    assert GLTF.write_f0(np.array([0.2, 0.4, 0.6]), metal, GLTF_CH, np.array([0.5] * 3)) == ["baseColor"]
    assert np.allclose(metal["baseColor"], [0.2, 0.4, 0.6])
    plastic = _gltf(0.0)
    driven = GLTF.write_f0(np.array([0.02, 0.04, 0.08]), plastic, GLTF_CH, np.array([0.5, 0.25, 0.125]))
    assert driven == ["baseColor", "specularColor"]
    assert np.allclose(plastic["baseColor"], [0.5, 0.25, 0.125])
    assert np.allclose(plastic["specularColor"], [0.5, 1.0, 2.0])


@pytest.mark.parametrize("spec", [s for s in list_models() if s.reflectance is not None], ids=lambda s: s.id)
def test_every_declared_reflectance_names_the_models_parameters(spec: ModelSpec) -> None:
    r = spec.reflectance
    assert isinstance(r, Reflectance)
    names = set(spec.param_names)
    assert set(r.params) <= names and set(r.map_params) <= set(r.params)
    assert {r.driven_param(True), r.driven_param(False)} <= set(r.params)
    # F0 read back from F0 written is the same F0 (a grey value every model can express)
    values = {p.name: np.asarray(p.default, dtype=float) for p in spec.params}
    if isinstance(r, Conductor):  # eta is held: one whose F0 alone is below the target's
        values[r.eta] = np.ones_like(values[r.eta])
    quantities = qty.read(spec, values)
    written = qty.write(spec, {"reflectance": np.array([[0.05] * 3])}, values)
    again = qty.read(spec, {k: np.asarray(v)[0] for k, v in written.items()})
    assert np.allclose(again["reflectance"], 0.05, atol=1e-6), (quantities["reflectance"], again["reflectance"])


def test_specular_level_is_a_scaled_grey_f0() -> None:
    r = SpecularLevel("specular")
    np.testing.assert_allclose(r.f0({"specular": np.array([0.5, 1.0])}, {"specular": 1}), [[0.04] * 3, [0.08] * 3])
    out: dict = {"specular": 0.5}
    assert r.write_f0(np.array([0.02, 0.02, 0.02]), out, {"specular": 1}) == ["specular"]
    assert float(out["specular"]) == pytest.approx(0.25)


def test_metalness_reads_a_metal_from_its_base_colour_and_a_dielectric_from_its_ior() -> None:
    """Principled BSDFs (Cycles, Mitsuba 3): a textured brass onto them lost its colour map, since F0 was read
    (and written) through the IOR alone and the base colour was taken for a diffuse albedo."""
    r = Metalness("Base Color", "Metallic", Dielectric("IOR"))
    ch = {"Base Color": 3, "Metallic": 1, "IOR": 1}
    values = {
        "Base Color": np.array([[0.9, 0.6, 0.2], [0.5, 0.4, 0.3]]),
        "Metallic": np.array([1.0, 0.0]),
        "IOR": np.array([1.5, 1.5]),
    }
    np.testing.assert_allclose(r.f0(values, ch), [[0.9, 0.6, 0.2], [0.04] * 3])
    np.testing.assert_allclose(r.albedo(values["Base Color"], values), [[0, 0, 0], [0.5, 0.4, 0.3]])
    out = {"Base Color": np.zeros((2, 3)), "Metallic": np.array([1.0, 0.0]), "IOR": np.array([1.5, 1.5])}
    f0 = np.array([[0.8, 0.5, 0.1], [0.0625] * 3])
    driven = r.write_f0(f0, out, ch, diffuse=np.array([[0.0] * 3, [0.2, 0.3, 0.4]]))
    assert driven == ["Base Color", "IOR"]
    np.testing.assert_allclose(out["Base Color"], [[0.8, 0.5, 0.1], [0.2, 0.3, 0.4]])
    np.testing.assert_allclose(out["IOR"], [1.5, 5.0 / 3.0])  # the metal's IOR held; F0 0.0625 is IOR 5/3
    assert r.driven_param(True) == "Base Color" and r.driven_param(False) == "IOR"
