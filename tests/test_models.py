import json

import numpy as np
import pytest

from matremap.core.material import Material, parse_material
from matremap.dialects import get_model, list_models
from matremap.errors import MatremapError


def test_every_embedded_dialect_is_registered():
    ids = {m.id for m in list_models()}
    assert {
        "mitsuba06:ward",
        "mitsuba06:phong",
        "mitsuba06:roughconductor",
        "mitsuba06:roughplastic",
        "mitsuba06:pbr",
        "blender27:ward",
        "cycles:glossy",
    } <= ids


def test_unknown_model_suggests_nearest_ids():
    with pytest.raises(MatremapError, match="did you mean mitsuba06:ward"):
        get_model("mitsuba06:wart")


def test_material_fills_defaults_and_broadcasts_grey():
    m = Material.create("mitsuba06:ward", {"specularReflectance": 0.12})
    assert m.options["variant"] == "balanced"
    np.testing.assert_array_equal(m.values["specularReflectance"], [0.12, 0.12, 0.12])
    assert m.values["alpha"].shape == (1,)


@pytest.mark.parametrize(
    "params, message",
    [
        ({"alpha": float("nan")}, "not finite"),
        ({"alpha": 3.0}, "outside its range"),
        ({"alpha": [0.1, 0.2, 0.3]}, "takes a single number"),
        ({"diffuseReflectance": [0.1, 0.2]}, "takes an RGB triple"),
        ({"shininess": 2}, "has no parameter 'shininess'"),
        ({"variant": "cook-torrance"}, "not one of ward, ward-duer, balanced"),
        ({"alpha": "rough"}, "is not a number"),
        ({"alpha": True}, "must be a number"),
    ],
)
def test_bad_values_are_refused_with_the_reason(params, message):
    with pytest.raises(MatremapError, match=message):
        Material.create("mitsuba06:ward", params)


def test_material_json_round_trip():
    m = Material.create("cycles:glossy", {"Color": [0.9, 0.5, 0.1], "Roughness": 0.3, "distribution": "beckmann"})
    again = Material.from_dict(json.loads(json.dumps(m.to_dict())))
    assert again == m


def test_compact_inline_form_with_rgb_triples():
    m = parse_material("mitsuba06:ward,variant=ward,alpha=0.3,diffuseReflectance=0.5:0.25:0.125")
    assert m.options["variant"] == "ward"
    np.testing.assert_array_equal(m.values["diffuseReflectance"], [0.5, 0.25, 0.125])


def test_malformed_material_documents():
    with pytest.raises(MatremapError, match='missing "model"'):
        Material.from_dict({"params": {}})
    with pytest.raises(MatremapError, match="unknown key"):
        Material.from_dict({"model": "mitsuba06:ward", "parameters": {}})
    with pytest.raises(MatremapError, match="not valid JSON"):
        parse_material('{"model": "mitsuba06:ward",')


def test_specs_describe_parts_with_their_own_parameters():
    for spec in list_models():
        for overrides in (spec.diffuse_only, spec.specular_only):
            assert set(overrides or {}) <= set(spec.param_names)
        assert spec.diffuse_only is not None or spec.specular_only is not None
