"""Mitsuba 3's principled takes ``specular`` as a float (``principled.cpp``: ``props.get<float>("specular")``), not a
texture. A textured dielectric remapped onto it swept and learned (the example bronze: 120 fits, about 4 s) and
only then stopped with "Mitsuba 3 takes specular as a constant, not a texture": the F0 write-back had written a
per-texel specular map. Now the map writer writes one specular, the median of the F0 the texels ask for, counting
the texels it approximates, and the check before the sweep refuses, in one line, maps whose F0 varies (one
specular would fail the gate's ``flat`` check).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from matremap.cli import main
from matremap.dialects import get_model, list_models
from matremap.regress.transform import Transform
from matremap.renderers.registry import texture_refusal
from matremap.svbrdf.convert import convert
from matremap.svbrdf.quality import VARIES
from matremap.svbrdf.textures import ImageInfo, load_map_set, read_image, write_image_like

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
EXR = ImageInfo("exr", "float", 3, 0, 0, "linear")
EXR_GREY = ImageInfo("exr", "float", 1, 0, 0, "linear")


def test_a_parameter_written_as_one_constant_is_one_the_renderers_refuse_as_a_map():
    """The write-back's claim (:meth:`Reflectance.constant_param`) agrees with the renderers' (``texture_refusal``)."""
    for spec in list_models():
        for metal in (True, False):
            name = spec.reflectance.constant_param(metal) if spec.reflectance is not None else None
            if name is not None:
                assert name == spec.reflectance.driven_param(metal)
                assert texture_refusal(spec.id, [name]) is not None, (spec.id, name)
    principled = get_model("mitsuba3:principled").reflectance
    assert principled.constant_param(metal=False) == "specular" and principled.constant_param(metal=True) is None
    assert texture_refusal("mitsuba3:principled", ["specular"]) is not None


def _identity(template: dict) -> Transform:
    """Ward -> principled (metallic 0) passing roughness, F0 and albedo through unchanged."""
    spec = get_model("mitsuba3:principled")
    return Transform.from_dict(
        {
            "schema": "matremap.transform/1",
            "method": "parametric",
            "source": {"model": "mitsuba06:ward", "options": {"variant": "ward"}},
            "target": {"model": spec.id, "options": {}},
            "mappings": {
                "roughness": {"kind": "polynomial", "input": "roughness", "coef": [1.0, 0.0]},
                "reflectance": {"kind": "scale", "input": "reflectance", "coef": [1.0, 1.0, 1.0]},
                "diffuse": {"kind": "scale", "input": "diffuse", "coef": [1.0, 1.0, 1.0]},
            },
            "template": {**{p.name: p.default for p in spec.params}, **template},
            "domain": {},
        }
    )


def _ward_set(folder: Path, f0: np.ndarray, alpha: np.ndarray, diffuse: np.ndarray) -> Path:
    folder.mkdir(parents=True)
    write_image_like(folder / "w_specular.exr", np.repeat(f0[..., None], 3, axis=-1), EXR)
    write_image_like(folder / "w_roughness.exr", alpha, EXR_GREY)
    write_image_like(folder / "w_diffuse.exr", diffuse, EXR)
    maps = {"specularReflectance": "w_specular.exr", "alpha": "w_roughness.exr", "diffuseReflectance": "w_diffuse.exr"}
    doc = {"model": "mitsuba06:ward", "maps": maps, "params": {"variant": "ward"}}
    (folder / "material.json").write_text(json.dumps(doc))
    return folder


def test_convert_writes_one_specular_from_the_median_over_every_band(tmp_path):
    """F0 rising row by row, converted in bands of 4 rows: one specular for the whole map, the median of every texel's
    F0 over 0.08 (a band's own median would differ by band), and the texels more than VARIES from it counted."""
    rows, cols = 40, 24
    f0 = np.repeat(np.linspace(0.02, 0.06, rows)[:, None], cols, axis=1).astype(np.float32)
    alpha = np.repeat(np.linspace(0.2, 0.5, cols)[None, :], rows, axis=0).astype(np.float32)
    diffuse = np.repeat(alpha[..., None], 3, axis=-1)
    ms = load_map_set(_ward_set(tmp_path / "in", f0, alpha, diffuse))
    report = convert(ms, _identity({"metallic": 0.0}), tmp_path / "out", tile_rows=4, workers=1)
    out = load_map_set(tmp_path / "out")
    assert "specular" not in out.maps and not list((tmp_path / "out").glob("*specular*"))
    median = float(np.median(f0))
    assert out.constants["specular"] == pytest.approx(median / 0.08, abs=2e-4)
    assert report.approximated == int(np.count_nonzero(np.abs(f0 - median) > VARIES))
    assert any("specular: mitsuba3:principled takes it as one number" in n for n in report.notes)
    # the albedo and roughness stay maps
    assert {"base_color", "roughness"} <= set(out.maps)


def test_a_metal_keeps_its_f0_as_a_base_colour_map(tmp_path):
    """Metallic 1: F0 goes to base_color, which Mitsuba 3 takes as a texture; specular is no constant of the maps."""
    rows, cols = 8, 8
    f0 = np.linspace(0.3, 0.9, rows * cols, dtype=np.float32).reshape(rows, cols)
    ms = load_map_set(
        _ward_set(tmp_path / "in", f0, np.full((rows, cols), 0.3, np.float32), np.zeros((rows, cols, 3), np.float32))
    )
    report = convert(ms, _identity({"metallic": 1.0}), tmp_path / "out", workers=1)
    out = load_map_set(tmp_path / "out")
    assert "base_color" in out.maps and report.approximated == 0
    base, _ = read_image(out.maps["base_color"], out.colorspace["base_color"])
    assert np.allclose(base[..., 0], f0, atol=1e-5)


@pytest.fixture
def no_sweep(monkeypatch, tmp_path):
    """An empty transform cache, and a record of every sweep started (a sweep is what the refusal must precede)."""
    import matremap.sweep.run as sweep_run

    monkeypatch.setenv("MATREMAP_CACHE", str(tmp_path / "cache"))
    started: list[int] = []
    real = sweep_run.run_sweep

    def counted(config, grid, *args, **kwargs):
        started.append(len(grid))
        return real(config, grid, *args, **kwargs)

    monkeypatch.setattr(sweep_run, "run_sweep", counted)
    return started


def test_the_bronze_onto_principled_is_refused_in_one_line_before_any_fit(tmp_path, capsys, no_sweep):
    """Its F0 (a Ward specular map, 0.05 to 0.14) varies: refused before the sweep, nothing written. It was refused
    after 120 fits (4.2 s) by the environment render."""
    out = tmp_path / "out"
    code = main(["remap", str(EXAMPLES / "bronze"), "--to", "mitsuba3:principled", "-o", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and not out.exists()
    assert no_sweep == []  # no fit ran
    assert not any(line.startswith(("sweep:", "learn:", "convert:", "transform:")) for line in err)
    assert "specular" in err[-1] and "the maps' F0 varies" in err[-1] and "cycles:principled" in err[-1]


def test_a_uniform_specular_map_onto_principled_writes_one_specular_mitsuba_loads(tmp_path, capsys, no_sweep):
    """The bronze's albedo and roughness with a uniform F0 of 0.04: swept once, written with one specular (the median
    of what the learned transform asks for, texel by texel) in maps/material.json and in the Mitsuba XML, which
    Mitsuba 3 loads; the texels the constant approximates are counted in the gate's clamped measure."""
    from matremap.remap import load_arrays

    side = 32
    step = 256 // side
    bronze = load_map_set(EXAMPLES / "bronze")
    diffuse, _ = read_image(bronze.maps["diffuseReflectance"], "srgb")
    alpha, _ = read_image(bronze.maps["alpha"], "linear")
    src = _ward_set(
        tmp_path / "in",
        np.full((side, side), 0.04, np.float32),
        alpha[::step, ::step, 0].astype(np.float32),
        diffuse[::step, ::step, :3].astype(np.float32),
    )
    out = tmp_path / "out"
    args = ["remap", str(src), "--to", "mitsuba3:principled", "-o", str(out), "--write", "m.xml", "--no-evaluate"]
    code = main(args)
    err = capsys.readouterr().err
    assert code in (0, 3), err
    assert len(no_sweep) == 1  # one sweep, and the remap went on to write
    doc = json.loads((out / "maps" / "material.json").read_text())
    assert "specular" not in doc["maps"] and isinstance(doc["params"]["specular"], float)
    # the constant is the median of the per-texel specular the learned transform asks for
    t = Transform.load(out / "transform.json")
    values, _ = load_arrays(load_map_set(src))
    asked, _ = t.apply(values)
    assert doc["params"]["specular"] == pytest.approx(float(np.median(asked["specular"])), abs=2e-4)
    verdict = json.loads((out / "verdict.json").read_text())
    clamped = next(c for c in verdict["checks"] if c["name"] == "clamped")
    f0 = 0.08 * np.asarray(asked["specular"])
    off = int(np.count_nonzero(np.abs(f0 - 0.08 * doc["params"]["specular"]) > VARIES))
    assert (f"texels whose F0 one constant approximates: {off}" in clamped["where"]) == (off > 0)
    xml = (out / "m.xml").read_text()
    assert '<float name="specular"' in xml and "specular.png" not in xml
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")  # an earlier test may have left a vectorised variant (its floats do not cast)
    bsdf = mi.load_file(str(out / "m.xml")).shapes()[0].bsdf()
    assert float(mi.traverse(bsdf)["specular"]) == pytest.approx(doc["params"]["specular"], abs=1e-6)
