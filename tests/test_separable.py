"""Variable projection (issue 17): the parameters a model declares affine are affine in its renders, and the
``separable`` strategy, which solves them in closed form for each trial of the others, reaches the joint
optimum of ``simple`` (which ``two-stage`` misses when diffuse and specular are coupled) at about the
cost of ``two-stage``."""

from __future__ import annotations

import importlib.util
import itertools

import numpy as np
import pytest

from matremap.core.material import Material
from matremap.core.scene import Scene
from matremap.dialects import list_models
from matremap.renderers import get_renderer, renderer_for
from matremap.uniform import fit

HAS_MITSUBA = importlib.util.find_spec("mitsuba") is not None


def option_sets(spec):
    names = [o.name for o in spec.options]
    for values in itertools.product(*(o.choices for o in spec.options)):
        yield dict(zip(names, values, strict=True))


def cases():
    for spec in list_models():
        if not spec.affine:
            continue
        seen = set()
        for options in option_sets(spec):
            affine = spec.affine_params(options)
            relevant = tuple(
                sorted((k, v) for k, v in options.items() if k in ("distribution", "nonlinear", "variant"))
            )
            if affine and (affine, relevant) not in seen:
                seen.add((affine, relevant))
                yield pytest.param(spec.id, options, affine, id=f"{spec.id}-{'-'.join(v for _, v in relevant)}")


@pytest.mark.parametrize(("model", "options", "affine"), list(cases()))
def test_declared_affine_parameters_are_affine_in_the_render(model, options, affine):
    """image(theta) = C + sum_j theta_j B_j, with C at theta = 0 and B_j from theta_j = 1, at random values."""
    name = renderer_for(model)
    if name == "mitsuba3" and not HAS_MITSUBA:
        pytest.skip("Mitsuba 3 not installed")
    if name == "cycles":
        pytest.skip("drawn by the embedded emulation in fits")
    renderer = get_renderer(name)
    rng = np.random.default_rng(7)
    spec = Material.create(model, options).spec
    scene = Scene.probe([0.0, 40.0], resolution=48)
    mask = scene.mask()
    for _ in range(2):
        base = Material.create(model, options)
        others = {}
        for p in spec.params:  # the other parameters at random values inside their bounds
            if p.name in affine or p.name in ("extEta", "extIOR", "ext_ior"):
                continue
            lo, hi = p.bounds
            hi = min(hi, 4.0 if p.role == "fresnel" else 1.0 if p.role != "roughness" else 0.8)
            lo = max(lo, 0.05 if p.role == "roughness" else lo)
            others[p.name] = rng.uniform(lo, hi, p.channels) if p.channels == 3 else float(rng.uniform(lo, hi))
        base = base.with_params(others)
        zero = base.with_params({n: 0.0 for n in affine})
        units = [zero.with_params({n: 1.0}) for n in affine]
        theta = {n: rng.uniform(0.05, 0.95, spec.param(n).channels) for n in affine}
        if spec.affine_sum_limit is not None:  # inside the region where the model is affine
            theta = {n: v * 0.9 * spec.affine_sum_limit / len(affine) for n, v in theta.items()}
        mixed = zero.with_params({n: v if v.size == 3 else float(v[0]) for n, v in theta.items()})
        c, *b, img = renderer.render([zero, *units, mixed], scene)
        predicted = c + sum(np.asarray(theta[n]).reshape(-1)[-3:] * (bj - c) for n, bj in zip(affine, b, strict=True))
        error = np.linalg.norm((img - predicted)[mask]) / np.linalg.norm(img[mask])
        assert error < 1e-4, (others, theta, error)


COLOURED_WARD = {
    "variant": "balanced",
    "alpha": 0.2,
    "specularReflectance": 0.06,
    "diffuseReflectance": [0.4, 0.3, 0.2],
}


@pytest.mark.parametrize(
    ("source", "target", "fix"),
    [
        (("mitsuba06:ward", COLOURED_WARD), "mitsuba06:roughplastic", {"distribution": "ggx"}),
        (
            ("cycles:glossy", {"Roughness": 0.4, "Color": [0.8, 0.5, 0.2], "Diffuse Color": [0.1, 0.3, 0.2]}),
            "mitsuba06:pbr",
            {},
        ),
        (
            ("mitsuba06:ward", {"alpha": 0.3, "specularReflectance": 0.1, "diffuseReflectance": 0.3}),
            "mitsuba06:phong",
            {},
        ),
        (
            ("mitsuba06:roughconductor", {"alpha": 0.2, "eta": [0.2, 0.9, 1.1], "k": [3.9, 2.4, 2.1]}),
            "mitsuba06:ward",
            {},
        ),
    ],
)
def test_separable_reaches_the_joint_optimum_at_about_two_stage_cost(source, target, fix):
    material = Material.create(*source)
    joint = fit(material, target, strategy="simple", fix=fix)
    separable = fit(material, target, strategy="separable", fix=fix)
    staged = fit(material, target, strategy="two-stage", fix=fix)
    assert separable.loss <= 1.01 * joint.loss + 1e-4, (separable.loss, joint.loss)
    assert separable.loss <= staged.loss + 1e-4
    assert separable.renders <= 1.5 * staged.renders, (separable.renders, staged.renders)
    for p in separable.target.spec.params:  # every value inside the renderer's bounds
        v = separable.target.values[p.name]
        assert np.all(v >= p.bounds[0]) and np.all(v <= p.bounds[1])


@pytest.mark.parametrize("k", [1, 2, 3])
def test_the_small_box_constrained_solve_is_exact(k):
    """varpro.box_lsq (the per-channel affine solve) against SciPy's bounded least squares, most optima
    on a bound."""
    from scipy.optimize import lsq_linear

    from matremap.core.varpro import box_lsq

    rng = np.random.default_rng(k)
    lower, upper = np.zeros(k), np.ones(k)
    for _ in range(200):
        a, b = rng.normal(size=(12, k)), 2.0 * rng.normal(size=12)
        ours = box_lsq(a.T @ a, a.T @ b, lower, upper)
        theirs = lsq_linear(a, b, bounds=(lower, upper), method="bvls", tol=1e-12).x
        assert np.linalg.norm(a @ ours - b) <= np.linalg.norm(a @ theirs - b) + 1e-9
        np.testing.assert_allclose(ours, theirs, atol=1e-6)
