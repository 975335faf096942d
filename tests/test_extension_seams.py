"""The seams of docs/architecture.md, exercised: a new renderer is one object implementing the protocol,
registered by name, and both fitting and evaluation use it without another module changing; a new model
is one spec in a dialect (and, to be emulated, one evaluator), and the fitter, the registry and the
renderers pick it up."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from matremap.core import envmap
from matremap.core.material import Material, SVMaterial
from matremap.core.models import ModelSpec, ParamSpec
from matremap.core.scene import Scene
from matremap.dialects import mitsuba06
from matremap.renderers import registry
from matremap.renderers.base import EnvironmentLight, Renderer
from matremap.renderers.embedded import EmbeddedRenderer
from matremap.renderers.embedded.evaluators import EVALUATORS
from matremap.uniform import fit


class HalfBrightRenderer:
    """A stand-in 'real' renderer of mitsuba06:diffuse that draws everything at half the embedded
    renderer's radiance: a renderer with its own irradiance units would look like this."""

    name = "half-bright"

    def __init__(self) -> None:
        self.inner = EmbeddedRenderer()
        self.probe_renders = 0
        self.environment_renders = 0

    def can_render(self, model_id: str) -> bool:
        return model_id == "mitsuba06:diffuse"

    def render(self, materials, scene):
        self.probe_renders += len(materials)
        return 0.5 * self.inner.render(materials, scene)

    def environment_support(self, model_id: str, geometry: str) -> str | None:
        return None if self.can_render(model_id) and geometry == "sphere" else "the sphere only"

    def supports_textures(self, model_id: str, param: str) -> bool:
        return True

    def prepare_environment(self, material, light, geometry, resolution, part):
        inner = self.inner.prepare_environment(material, light, geometry, resolution, part)
        outer = self

        class Half:
            label = "half-bright"

            def render(self, rotation_deg: float) -> np.ndarray:
                outer.environment_renders += 1
                return 0.5 * inner.render(rotation_deg)

        return Half()


@pytest.fixture
def half_bright(monkeypatch):
    registry._load_builtin()
    renderer = HalfBrightRenderer()
    monkeypatch.setitem(registry._FACTORIES, renderer.name, lambda: renderer)
    monkeypatch.setitem(registry._INSTANCES, renderer.name, renderer)
    yield renderer


def test_a_new_renderer_is_one_object_behind_the_protocol(half_bright):
    assert isinstance(half_bright, Renderer)
    source = Material.create("mitsuba06:diffuse", {"reflectance": [0.6, 0.4, 0.2]})
    scene = Scene.probe([0.0], resolution=32)
    # fitting draws with it when named, and its images are what the fit matches
    r = fit(source, "mitsuba06:diffuse", scene=scene, source_renderer="half-bright")
    assert r.source_renderer == "half-bright" and half_bright.probe_renders > 0
    np.testing.assert_allclose(r.target.values["reflectance"], [0.3, 0.2, 0.1], rtol=1e-3)
    # environment renders prefer it over the emulation (it is the model's real renderer)
    chosen = registry.environment_renderer_for("mitsuba06:diffuse", "sphere")
    assert chosen is half_bright
    light = EnvironmentLight(envmap.constant(1.0), lights=16)
    prepared = chosen.prepare_environment(SVMaterial("mitsuba06:diffuse", {}), light, "sphere", 16, "full")
    assert prepared.label == "half-bright" and prepared.render(0.0).max() > 0
    # where it cannot draw (not the sphere) the embedded emulation stands in, with a warning naming why
    with pytest.warns(RuntimeWarning, match="the sphere only"):
        assert registry.environment_renderer_for("mitsuba06:diffuse", "plane").name == "embedded"


def test_a_new_model_is_one_dialect_entry_and_one_evaluator(monkeypatch):
    """A Lambertian with its albedo given in percent: a spec (data) and an evaluator (numpy)."""
    spec = ModelSpec(
        id="mitsuba06:percent-diffuse",
        summary="Lambertian, albedo in percent",
        params=(ParamSpec("albedo", "diffuse", (50.0,) * 3, (0.0, 100.0), channels=3),),
        diffuse_only={},
        specular_only=None,
    )
    import matremap.dialects as dialects

    monkeypatch.setitem(dialects.MODELS, spec.id, spec)
    monkeypatch.setitem(EVALUATORS, spec.id, lambda p, opt, g: 0.01 * p["albedo"] * g.lambert)
    assert registry.renderer_for(spec.id) == "embedded"
    source = Material.create("mitsuba06:diffuse", {"reflectance": [0.6, 0.4, 0.2]})
    r = fit(source, spec.id, scene=Scene.probe([0.0], resolution=32))
    np.testing.assert_allclose(r.target.values["albedo"], [60.0, 40.0, 20.0], rtol=1e-3)
    # and back: the new model is a source like any other
    back = fit(r.target, "mitsuba06:diffuse", scene=Scene.probe([0.0], resolution=32))
    np.testing.assert_allclose(back.target.values["reflectance"], [0.6, 0.4, 0.2], rtol=1e-3)


def test_dialects_import_no_renderer():
    """Model specs are data: the dialect modules name no renderer module."""
    import ast
    from pathlib import Path

    import matremap.dialects

    folder = Path(matremap.dialects.__file__).parent
    for path in folder.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom):
                assert not (node.module or "").startswith("matremap.renderers"), f"{path.name} imports {node.module}"


def test_every_model_has_a_renderer_and_specs_are_declared_once():
    from matremap.dialects import FAMILIES, list_models

    for spec in list_models():
        assert registry.renderer_for(spec.id) in registry.renderer_names()
    declared = [s.id for module in FAMILIES.values() for s in module.MODELS]
    assert len(declared) == len(set(declared)) == len(list_models())
    # a spec is plain data: replacing a field gives an equal-but-different spec, nothing registers itself
    assert replace(mitsuba06.WARD, summary="x") != mitsuba06.WARD
