"""Fits in lockstep and batched renders (issue 17): many fits driven together give the results of one-at-a-time
fits with about as many render calls as the slowest fit makes requests; a fit that cannot be rendered fails alone;
the bounded Levenberg-Marquardt reaches SciPy's optimum; real renderers' batches equal their single renders."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest

from matremap.core.descent import descend
from matremap.core.lockstep import Stats, lockstep, run
from matremap.core.material import Material
from matremap.core.scene import Scene
from matremap.errors import MatremapError, RendererUnavailable
from matremap.renderers import get_renderer
from matremap.uniform import fit, fit_steps

SOURCES = [
    ("mitsuba06:ward", {"variant": "ward", "alpha": a, "specularReflectance": s, "diffuseReflectance": d})
    for a, s, d in ((0.08, 0.05, 0.0), (0.2, 0.12, [0.4, 0.3, 0.2]), (0.45, 0.2, 0.3), (0.3, 0.03, [0.1, 0.5, 0.2]))
]


def requests_of(steps) -> tuple[object, int]:
    """Drive one fit alone, counting its render requests."""
    count = 0
    try:
        request = next(steps)
        while True:
            count += 1
            request = steps.send(get_renderer().render_pixels(list(request.materials), request.scene))
    except StopIteration as done:
        return done.value, count


@pytest.mark.parametrize("strategy", ["two-stage", "separable", "simple"])
def test_fits_in_lockstep_equal_fits_one_at_a_time_with_far_fewer_render_calls(strategy, monkeypatch):
    monkeypatch.setattr(get_renderer(), "batch_size", 1000)  # one call per step (else cut at 8 materials)
    scene = Scene(resolution=48)
    sources = [Material.create(*s) for s in SOURCES]
    target, fix = "mitsuba06:pbr", {"distribution": "ggx"}
    alone = [fit(s, target, strategy, scene, fix=fix) for s in sources]
    counts = [requests_of(fit_steps(s, target, strategy, scene, fix=fix))[1] for s in sources]
    stats = Stats()
    together = lockstep([fit_steps(s, target, strategy, scene, fix=fix) for s in sources], stats)
    for a, b in zip(alone, together, strict=True):
        assert b.params == a.params and b.loss == a.loss and b.renders == a.renders
    assert stats.calls <= max(counts) + 2 < sum(counts)
    assert stats.requested == sum(a.renders for a in alone)
    assert stats.rendered < stats.requested  # identical requests (the coarse search's) are drawn once


class Failing:
    """The embedded renderer, except that one colour of diffuse reflectance makes it fail."""

    name = "embedded"

    def __init__(self, error: Exception) -> None:
        self.inner, self.error = get_renderer(), error

    def can_render(self, model_id):
        return self.inner.can_render(model_id)

    def render_pixels(self, materials, scene):
        if any(np.allclose(m.values.get("diffuseReflectance", [0]), [0.1, 0.5, 0.2]) for m in materials):
            raise self.error
        return self.inner.render_pixels(materials, scene)


def test_a_fit_that_cannot_be_rendered_fails_alone_and_a_missing_renderer_stops_everything():
    scene = Scene(resolution=32)
    sources = [Material.create(*s) for s in SOURCES]
    broken = Failing(MatremapError("the renderer refuses this material"))
    jobs = [fit_steps(s, "mitsuba06:pbr", "two-stage", scene, broken, get_renderer()) for s in sources]
    results = lockstep(jobs)
    assert isinstance(results[3], MatremapError) and "refuses" in str(results[3])
    for s, r in zip(sources[:3], results[:3], strict=True):
        assert r.params == fit(s, "mitsuba06:pbr", "two-stage", scene).params
    gone = Failing(RendererUnavailable("Mitsuba 3 is not installed"))
    with pytest.raises(RendererUnavailable, match="not installed"):
        lockstep([fit_steps(s, "mitsuba06:pbr", "two-stage", scene, gone, get_renderer()) for s in sources])


def test_bounded_levenberg_marquardt_reaches_scipys_optimum():
    """A curved, badly scaled problem with one bound active at the optimum: the same minimum as
    SciPy's trust-region reflective method, to the fit tolerance."""
    from scipy.optimize import least_squares

    t = np.linspace(0.0, 4.0, 400)
    y = 3.0 * np.exp(-1.3 * t) + 0.02 * np.sin(7 * t) - 0.05
    lower, upper = np.array([0.0, 0.1, 0.0]), np.array([10.0, 5.0, 1.0])

    def residual(x):
        return x[0] * np.exp(-x[1] * t) + x[2] - y

    def ask_residual(x):
        return residual(x)
        yield

    def ask_jacobian(x):
        e = np.exp(-x[1] * t)
        return np.stack([e, -x[0] * t * e, np.ones_like(t)], axis=1)
        yield

    x0 = np.array([1.0, 0.5, 0.5])
    ours = run(descend(ask_residual, ask_jacobian, x0, lower, upper, tol=1e-10, max_evaluations=200))
    theirs = least_squares(residual, x0, bounds=(lower, upper), method="trf", ftol=1e-12, xtol=1e-12, gtol=1e-12)
    np.testing.assert_allclose(ours.x, theirs.x, rtol=1e-5, atol=1e-8)
    assert ours.x[2] == 0.0  # the offset wants to be negative: held on its bound
    assert ours.cost == pytest.approx(theirs.cost, rel=1e-8)


HAS_MITSUBA = importlib.util.find_spec("mitsuba") is not None


@pytest.fixture(scope="module")
def mitsuba3_jit():
    if not HAS_MITSUBA:
        pytest.skip("Mitsuba 3 not installed: pip install 'matremap[mitsuba]'")
    from matremap.renderers.mitsuba3.probe import Mitsuba3Renderer, llvm_renders

    if not llvm_renders():
        pytest.skip("Mitsuba's llvm_ad_rgb variant does not render here (Debian: apt install libllvm19)")
    return Mitsuba3Renderer(variant="llvm_ad_rgb")


MITSUBA3_BATCH = [
    ("mitsuba3:roughconductor", {"distribution": "ggx", "alpha": 0.1, "k": [3.0, 2.0, 1.0]}),
    ("mitsuba3:roughconductor", {"distribution": "beckmann", "alpha": 0.35, "eta": [0.2, 0.9, 1.1], "k": 2.0}),
    ("mitsuba3:roughconductor", {"distribution": "ggx", "alpha": 0.3, "material": "Au"}),
    ("mitsuba3:roughplastic", {"distribution": "ggx", "alpha": 0.2, "diffuse_reflectance": [0.4, 0.3, 0.2]}),
    ("mitsuba3:roughplastic", {"distribution": "beckmann", "alpha": 0.5, "int_ior": 1.8}),
    ("mitsuba3:principled", {"roughness": 0.3, "base_color": [0.5, 0.4, 0.3], "metallic": 0.5}),
    ("mitsuba3:diffuse", {"reflectance": [0.5, 0.4, 0.3]}),
]


def test_mitsuba3_batches_equal_rendered_images(mitsuba3_jit):
    """A batch of materials evaluated with Mitsuba's BSDF API over the probe's own rays equals each material's
    rendered image (mi.render, direct integrator) at the sphere pixels, two lights summed."""
    scene = Scene.probe([0.0, 40.0], resolution=48)
    mats = [Material.create(*m) for m in MITSUBA3_BATCH]
    batch = mitsuba3_jit.render_pixels(mats + mats[:2], scene)
    for i, m in enumerate(mats):
        image = mitsuba3_jit.render([m], scene)[0].reshape(-1, 3)[scene.pixel_indices()]
        error = np.linalg.norm(batch[i] - image) / np.linalg.norm(image)
        assert error < 1e-4, (m.model, error)
    np.testing.assert_array_equal(batch[len(mats) :], batch[:2])  # re-set values give the same pixels


def test_a_fit_onto_mitsuba3_in_lockstep_equals_the_fit_alone(mitsuba3_jit):
    scene = Scene(resolution=32)
    sources = [
        Material.create("mitsuba06:roughconductor", {"distribution": "ggx", "alpha": a, "k": [3.0, k, 1.0]})
        for a, k in ((0.1, 2.0), (0.3, 1.2))
    ]
    args = dict(strategy="two-stage", scene=scene, target_renderer=mitsuba3_jit, fix={"distribution": "ggx"})
    alone = [fit(s, "mitsuba3:roughconductor", **args) for s in sources]
    together = lockstep([fit_steps(s, "mitsuba3:roughconductor", **args) for s in sources])
    for a, b in zip(alone, together, strict=True):
        assert b.params == a.params and b.loss == a.loss


def test_cycles_batches_equal_single_renders():
    from matremap.renderers.cycles.probe import CyclesRenderer, bpy_available

    if not bpy_available():
        pytest.skip("bpy is not set up: python3.11 -m venv .venv-bpy && .venv-bpy/bin/pip install bpy==5.0.1")
    renderer = CyclesRenderer()
    try:
        scene = Scene.probe([0.0, 40.0], resolution=32)
        mats = [
            Material.create("cycles:principled", {"Roughness": 0.3, "Base Color": [0.6, 0.4, 0.2], "Metallic": 0.3}),
            Material.create("cycles:glossy", {"Roughness": 0.2, "Color": [0.8, 0.5, 0.2], "Diffuse Color": 0.1}),
            Material.create("cycles:diffuse", {"Color": [0.5, 0.4, 0.3]}),
        ]
        batch = renderer.render_pixels(mats, scene)
        for i, m in enumerate(mats):
            single = renderer.render_pixels([m], scene)[0]
            assert np.linalg.norm(batch[i] - single) <= 1e-4 * np.linalg.norm(single), m.model
    finally:
        renderer.close()
