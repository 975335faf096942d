"""Models the dialects show to be equal (issue 14, "same model in = same maps out"): each listed pair draws
the same image for renamed values (checked by rendering both, with the real renderer where it draws the
model), a remap between them copies the maps bit for bit without a sweep, and pairs that only look alike
(Mitsuba 0.6 and Mitsuba 3 roughplastic) are not listed because they render differently."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from matremap.cli import main
from matremap.core.material import Material
from matremap.core.scene import Scene
from matremap.dialects.equivalence import EQUIVALENCES, equivalence
from matremap.remap import identity_route, uniform_identity
from matremap.renderers import get_renderer, renderer_for
from matremap.svbrdf.textures import load_map_set, read_image

HAS_MITSUBA = importlib.util.find_spec("mitsuba") is not None
FAST = ["--rotations", "0:360:2", "--size", "48", "--env-lights", "32"]

#: source values each pair is rendered with (the requirements are added)
VALUES = {
    "mitsuba06:diffuse": [{"reflectance": [0.7, 0.4, 0.2]}, {"reflectance": 1.0}],
    "mitsuba06:roughconductor": [
        {"alpha": a, "eta": [0.2, 0.92, 1.1], "k": [3.9, 2.45, 2.14], "distribution": d}
        for a in (0.05, 0.3)
        for d in ("beckmann", "ggx")
    ],
    "mitsuba3:diffuse": [{"reflectance": [0.1, 0.5, 0.9]}],
}


def draw(material: Material, scene: Scene) -> np.ndarray:
    name = renderer_for(material.model)
    if name == "mitsuba3" and not HAS_MITSUBA:
        pytest.skip("Mitsuba 3 not installed: pip install 'matremap[mitsuba]'")
    return get_renderer(name).render([material], scene)[0]


def relative_rmse(a: np.ndarray, b: np.ndarray, mask: np.ndarray) -> float:
    return float(np.linalg.norm(a[mask] - b[mask]) / np.linalg.norm(b[mask]))


@pytest.mark.parametrize("eq", EQUIVALENCES, ids=lambda e: f"{e.source}={e.target}")
def test_each_listed_pair_draws_the_same_image(eq):
    scene = Scene.probe([0.0, 45.0], resolution=64)
    for values in VALUES[eq.source]:
        source = Material.create(eq.source, {**values, **eq.source_requires})
        target = Material.create(eq.target, eq.rename({**source.values, **source.options}))
        assert relative_rmse(draw(target, scene), draw(source, scene), scene.mask()) < 1e-3, values


@pytest.mark.skipif(not HAS_MITSUBA, reason="Mitsuba 3 not installed")
def test_roughplastic_of_mitsuba_06_and_3_differ_so_they_are_fitted_not_copied():
    scene = Scene.probe([0.0], resolution=64)
    m06 = Material.create("mitsuba06:roughplastic", {"alpha": 0.2, "intIOR": 1.5, "extIOR": 1.0})
    m3 = Material.create("mitsuba3:roughplastic", {"alpha": 0.2, "int_ior": 1.5, "ext_ior": 1.0})
    assert relative_rmse(draw(m3, scene), draw(m06, scene), scene.mask()) > 0.01
    assert equivalence("mitsuba06:roughplastic", "mitsuba3:roughplastic") is None


def test_equivalence_is_found_both_ways_and_renames_back():
    there = equivalence("mitsuba06:roughconductor", "mitsuba3:roughconductor")
    back = equivalence("mitsuba3:roughconductor", "mitsuba06:roughconductor")
    assert there is not None and back is not None
    values = {"alpha": 0.1, "eta": 0.5, "k": 3.0, "specularReflectance": 1.0, "distribution": "ggx", "extEta": 1.0}
    assert back.rename(there.rename(values)) == {k: v for k, v in values.items()}


def test_requirements_decide_whether_a_material_is_copied():
    conductor = Material.create("mitsuba06:roughconductor", {"alpha": 0.1, "extEta": 1.0})
    assert uniform_identity(conductor, "mitsuba3:roughconductor", {}) is not None
    in_air = conductor.with_params({"extEta": 1.000277})  # Mitsuba 3's conductor has no exterior IOR
    assert uniform_identity(in_air, "mitsuba3:roughconductor", {}) is None
    phong = conductor.with_params({"distribution": "phong"})  # Mitsuba 3 has no Phong distribution
    assert uniform_identity(phong, "mitsuba3:roughconductor", {}) is None
    named = Material.create("mitsuba3:roughconductor", {"material": "Au"})  # spectral data, not eta/k
    assert uniform_identity(named, "mitsuba06:roughconductor", {}) is None
    assert uniform_identity(conductor, "mitsuba3:roughconductor", {"distribution": "ggx"}) is None  # a change


def png(path: Path, rgb: np.ndarray) -> None:
    import OpenImageIO as oiio

    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(rgb.shape[1], rgb.shape[0], 3, "uint8"))
    out.write_image(np.round(np.clip(rgb, 0, 1) * 255).astype(np.uint8))
    out.close()


def albedo_map_set(folder: Path, normal: bool = False) -> Path:
    folder.mkdir(parents=True)
    y, x = np.mgrid[0:16, 0:16] / 15.0
    png(folder / "albedo.png", np.stack([0.2 + 0.7 * x, 0.3 * y + 0.1, 0.5 + 0 * x], -1))
    doc = {"model": "mitsuba06:diffuse", "maps": {"reflectance": "albedo.png"}, "colorspace": {"albedo.png": "srgb"}}
    if normal:
        png(folder / "normal.png", np.stack([0.5 + 0.2 * x, 0.5 + 0 * y, 1 + 0 * x], -1))
        doc["normal"] = "normal.png"
    (folder / "material.json").write_text(json.dumps(doc))
    return folder


def test_a_map_set_onto_an_equal_model_copies_the_maps_without_a_sweep(tmp_path, capsys):
    src = albedo_map_set(tmp_path / "in")
    out = tmp_path / "out"
    assert main(["remap", str(src), "--to", "cycles:diffuse", "-o", str(out), *FAST]) == 0
    err = capsys.readouterr().err
    assert "identity: mitsuba06:diffuse equals cycles:diffuse" in err and "sweep" not in err, err
    maps = load_map_set(out / "maps")
    assert maps.model == "cycles:diffuse" and set(maps.maps) == {"Color"}
    assert (out / "maps" / maps.maps["Color"].name).read_bytes() == (src / "albedo.png").read_bytes()
    a, _ = read_image(maps.maps["Color"], maps.colorspace["Color"])
    assert a.max() > 0.5  # the copy is the texture, not a placeholder


def test_a_normal_map_cycles_shades_differently_is_not_an_identity(tmp_path):
    """Cycles' bump shadowing term changes diffuse shading under a normal map: no longer the same BRDF."""
    plain = load_map_set(albedo_map_set(tmp_path / "plain"))
    bumpy = load_map_set(albedo_map_set(tmp_path / "bumpy", normal=True))
    assert identity_route(plain, "cycles:diffuse", {}) is not None
    assert identity_route(bumpy, "cycles:diffuse", {}) is None
    assert identity_route(bumpy, "mitsuba06:diffuse", {}) is not None  # onto itself it still is
