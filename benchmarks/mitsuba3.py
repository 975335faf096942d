"""Seconds and renders per two-stage fit with the real Mitsuba 3 renderer in the loop.

For a few model pairs with Mitsuba 3 as target (and one as source), ``--count`` fixed source
materials each (drawn with a fixed seed): prints median / 90th-percentile seconds per fit, median
renders per fit (materials rendered, as the fit reports them; Mitsuba renders one image per light
each) and median loss. The issue's target: a two-stage fit with Mitsuba 3 as target at 128^2 in
<= 20 s.

    python benchmarks/mitsuba3.py [--size 128] [--count 10] [--variant scalar_rgb] [--lights 0]
    python benchmarks/mitsuba3.py --autodiff [--size 128] [--count 10] [--lights 0]

``--autodiff`` compares, for ``mitsuba3:roughconductor`` targets, the finite-difference two-stage
fit (:func:`matremap.core.fit.fit`, llvm_ad_rgb renderer) with the gradient-based fit through Mitsuba's
autodiff (:func:`matremap.renderers.mitsuba3.probe.fit_roughconductor_autodiff`): seconds, renders and
the relative RMSE of the fitted material's image against the source image (sphere pixels).

Needs ``pip install 'matremap[mitsuba]'``.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from matremap.core.material import Material
from matremap.core.scene import Scene
from matremap.renderers.mitsuba3.probe import Mitsuba3Renderer
from matremap.uniform import fit


def sources(model: str, n: int, rng: np.random.Generator) -> list[Material]:
    out = []
    for _ in range(n):
        name = model
        if model == "mitsuba06:ward":
            p = {
                "variant": "ward",
                "alpha": rng.uniform(0.05, 0.6),
                "specularReflectance": rng.uniform(0.02, 0.5),
                "diffuseReflectance": 0.0,
            }
        elif model == "mitsuba06:ward+diffuse":
            name = "mitsuba06:ward"
            p = {
                "variant": "ward",
                "alpha": rng.uniform(0.05, 0.6),
                "specularReflectance": rng.uniform(0.02, 0.25),
                "diffuseReflectance": rng.uniform(0.05, 0.5, 3).tolist(),
            }
        elif model == "mitsuba3:roughconductor":
            p = {
                "distribution": "ggx",
                "alpha": rng.uniform(0.05, 0.6),
                "eta": rng.uniform(0.2, 2.0, 3).tolist(),
                "k": rng.uniform(0.5, 4.0, 3).tolist(),
            }
        elif model == "cycles:glossy":
            p = {
                "distribution": "ggx",
                "Roughness": rng.uniform(0.2, 0.8),
                "Color": rng.uniform(0.2, 0.9, 3).tolist(),
                "Diffuse Color": 0.0,
            }
        else:
            raise ValueError(model)
        out.append(Material.create(name, p))
    return out


# (source model, source renderer, target model, target renderer, fixed target options, note)
PAIRS = [
    ("mitsuba06:ward", "embedded", "mitsuba3:roughconductor", "mitsuba3", {"distribution": "ggx"}, "grey"),
    ("mitsuba06:ward", "embedded", "mitsuba3:roughconductor", "mitsuba3", {"distribution": "beckmann"}, "grey"),
    ("cycles:glossy", "embedded", "mitsuba3:roughconductor", "mitsuba3", {"distribution": "ggx"}, "RGB"),
    ("mitsuba06:ward+diffuse", "embedded", "mitsuba3:roughplastic", "mitsuba3", {"distribution": "ggx"}, "RGB diffuse"),
    (
        "mitsuba06:ward+diffuse",
        "embedded",
        "mitsuba3:roughplastic",
        "mitsuba3",
        {"distribution": "ggx"},
        "RGB diffuse, three-stage",
    ),
    ("mitsuba3:roughconductor", "mitsuba3", "mitsuba06:ward", "embedded", {"variant": "ward"}, "Mitsuba 3 source"),
]


def relative_rmse(a: np.ndarray, b: np.ndarray, mask: np.ndarray) -> float:
    return float(np.linalg.norm(a[mask] - b[mask]) / np.linalg.norm(b[mask]))


def autodiff(args: argparse.Namespace) -> None:
    from matremap.renderers import get_renderer
    from matremap.renderers.mitsuba3.probe import fit_roughconductor_autodiff, llvm_renders

    if not llvm_renders():
        raise SystemExit("llvm_ad_rgb does not render here: install Debian libllvm19")
    scene = Scene.probe(args.lights, resolution=args.size)
    mask = scene.mask()
    renderer = Mitsuba3Renderer(variant="llvm_ad_rgb")
    cases = [
        ("mitsuba3:roughconductor", "mitsuba3", "ggx"),
        ("mitsuba3:roughconductor", "mitsuba3", "beckmann"),
        ("cycles:glossy", "embedded", "ggx"),
        ("mitsuba06:ward", "embedded", "ggx"),
    ]
    # warm up both paths (JIT compilation of the kernels)
    warm = sources("mitsuba3:roughconductor", 1, np.random.default_rng(1))[0]
    t = renderer.render([warm], scene)[0]
    for dist in ("ggx", "beckmann"):
        fit_roughconductor_autodiff(t, scene, dist)
        fit(
            warm,
            "mitsuba3:roughconductor",
            scene=scene,
            source_renderer=renderer,
            target_renderer=renderer,
            fix={"distribution": dist, "eta": 1.0},
        )
    print(
        f"{args.size}x{args.size}, lights {args.lights}, {args.count} sources per case, llvm_ad_rgb; "
        "image error: relative RMSE of the fitted image vs the source image\n"
    )
    print(f"{'source -> mitsuba3:roughconductor':<52} {'method':<22} {'median s':>8} {'renders':>7} {'image err':>9}")
    for model, src_r, dist in cases:
        mats = sources(model, args.count, np.random.default_rng(0))
        if model == "mitsuba3:roughconductor":  # eta = 1: the fits hold eta at 1
            mats = [m.with_params({"eta": 1.0, "distribution": dist}) for m in mats]
        rows: dict[str, list[tuple[float, float, float]]] = {"finite differences": [], "autodiff L-BFGS-B": []}
        for m in mats:
            src_renderer = renderer if src_r == "mitsuba3" else "embedded"
            target = get_renderer(src_renderer).render([m], scene)[0]
            t0 = time.perf_counter()
            r = fit(
                m,
                "mitsuba3:roughconductor",
                scene=scene,
                source_renderer=src_renderer,
                target_renderer=renderer,
                fix={"distribution": dist, "eta": 1.0},
            )
            secs = time.perf_counter() - t0
            target = target * r.irradiance_scale  # what the fit matches (1 within the same probe physics)
            img = renderer.render([r.target], scene)[0]
            rows["finite differences"].append((secs, r.renders, relative_rmse(img, target, mask)))
            a = fit_roughconductor_autodiff(target, scene, dist)
            img = renderer.render([a.material], scene)[0]
            rows["autodiff L-BFGS-B"].append((a.seconds, a.evaluations, relative_rmse(img, target, mask)))
        for method, vals in rows.items():
            s, n, e = (statistics.median(v[i] for v in vals) for i in range(3))
            print(f"{model + ' (' + src_r + ') ' + dist:<52} {method:<22} {s:8.2f} {n:7.0f} {e:9.4f}")
    print(
        "\nrenders: materials rendered (finite differences, as the fit reports them) or forward+backward "
        "evaluations (autodiff), each one Mitsuba image per light"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--count", type=int, default=10)
    ap.add_argument("--variant", default=None, help="Mitsuba variant (default scalar_rgb; 'auto' picks llvm if usable)")
    ap.add_argument("--env-lights", type=float, nargs="+", default=[0.0], help="light angles (degrees)")
    ap.add_argument("--autodiff", action="store_true", help="compare autodiff and finite-difference conductor fits")
    args = ap.parse_args()
    if args.autodiff:
        autodiff(args)
        return
    scene = Scene.probe(args.lights, resolution=args.size)
    renderer = Mitsuba3Renderer(variant=args.variant)
    renderers = {"embedded": "embedded", "mitsuba3": renderer}
    # warm up (first scene load, imports)
    fit(
        sources("mitsuba06:ward", 1, np.random.default_rng(1))[0],
        "mitsuba3:roughconductor",
        scene=scene,
        target_renderer=renderer,
    )
    print(
        f"Mitsuba 3 {renderer.mi.__version__} ({renderer.variant}), {args.size}x{args.size}, "
        f"lights {args.lights}, two-stage unless noted, {args.count} sources per pair\n"
    )
    print(f"{'source -> target':<92} {'median s':>8} {'p90 s':>6} {'renders':>7} {'Mitsuba':>7} {'loss':>7}")
    for src_model, src_r, tgt_model, tgt_r, fix, note in PAIRS:
        mats = sources(src_model, args.count, np.random.default_rng(0))
        secs, renders, images, losses = [], [], [], []
        for m in mats:
            before = renderer.renders
            t = time.perf_counter()
            r = fit(
                m,
                tgt_model,
                strategy="three-stage" if "three-stage" in note else "two-stage",
                scene=scene,
                source_renderer=renderers[src_r],
                target_renderer=renderers[tgt_r],
                fix=fix,
            )
            secs.append(time.perf_counter() - t)
            renders.append(r.renders)
            images.append(renderer.renders - before)
            losses.append(r.loss)
        label = f"{m.model} ({src_r}) -> {tgt_model} {'/'.join(fix.values())} ({tgt_r}), {note}"
        p90 = float(np.percentile(secs, 90))
        print(
            f"{label:<92} {statistics.median(secs):8.2f} {p90:6.2f} {statistics.median(renders):7.0f} "
            f"{statistics.median(images):7.0f} {statistics.median(losses):7.4f}"
        )
    print(
        "\nrenders: materials rendered per fit (fit's count); Mitsuba: images Mitsuba rendered per fit "
        "(one per material and light)"
    )


if __name__ == "__main__":
    main()
