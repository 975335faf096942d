"""Throughput before and after, measured side by side in one run.

Every measurement runs in a fresh process, once with the "before" sources (``--before``: another checkout's
``src`` folder, e.g. one made with ``git worktree add``; default: this checkout's own, which measures the noise)
and once with this checkout's, interleaved (before, after, before, after, ...) so that both see the same
machine load; the table shows medians over ``--repeat`` runs.

    python benchmarks/throughput.py [--before OTHER/src] [--repeat 3] [--jobs fit grid ...]
        [--mitsuba-points 1000] [--cycles-points 24]

Jobs (each prints one JSON line when run as ``--job NAME``):

``fit``       uniform fits on the embedded renderer, 128^2: 20 coloured ``cycles:glossy`` sources onto
              ``mitsuba06:pbr`` GGX and the issue's Ward (balanced, alpha 0.2, rho_s 0.06, diffuse
              [0.4, 0.3, 0.2]) onto ``mitsuba06:roughplastic`` GGX, per strategy: median ms per fit (best of 3),
              renders, render calls, loss;
``grid``      the authors' Ward -> AS grid (35 x 23 = 805 points, a superset of their 721 rows) on 2 worker
              processes: seconds; and its first 4 columns (140 points) in one process, counting renders, render
              calls per sweep and CPU time per point (on a shared machine the wall time depends on the others'
              load; 805 x CPU per point / 2 is what two free cores would take);
``mitsuba``   uniform fits onto real Mitsuba 3 (warm renderer): 10 Ward sources onto ``roughconductor`` GGX,
              and the issue's coloured Ward onto ``roughplastic`` GGX;
``mitsuba-sweep``  a sweep of ``--mitsuba-points`` Ward points onto Mitsuba 3's ``roughconductor`` GGX, 2 workers;
``cycles-sweep``   a sweep of ``--cycles-points`` coloured Ward points onto real Cycles ``principled`` in one process
              (Cycles renders with every core), CPU time of both processes (Cycles' threads included);
``cycles-frame``   Cycles' time for one 1-spp frame of a sphere at 128^2, 256^2 and 512^2 (the bpy venv): a frame
              of k probe objects costs k frames when the time is per pixel;
``readme``    the README main job (``matremap remap examples/bronze --to mitsuba06:pbr --fix distribution=as``),
              a fresh process and cache.

Seconds are wall-clock on whatever else runs on the machine: compare before and after within one run.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
COLOURED_WARD = {
    "variant": "balanced",
    "alpha": 0.2,
    "specularReflectance": 0.06,
    "diffuseReflectance": [0.4, 0.3, 0.2],
}
#: CPU seconds of the last sweep, all processes (wall time on a shared machine says little)
CPU = [0.0]
JOBS = ("fit", "grid", "mitsuba", "mitsuba-sweep", "cycles-sweep", "cycles-frame", "readme")

#: Cycles' cost of one frame by its size (bpy venv): whether several probe objects per frame could pay
CYCLES_FRAME = """
import sys, time, json, statistics
import bpy
bpy.ops.wm.read_factory_settings(use_empty=True)
sc = bpy.context.scene
sc.render.engine = "CYCLES"; cy = sc.cycles; cy.device = "CPU"; cy.samples = 1
cy.use_adaptive_sampling = False; cy.use_denoising = False; cy.filter_width = 0.01; cy.max_bounces = 0
sc.render.use_persistent_data = True
bpy.ops.mesh.primitive_uv_sphere_add(radius=2, segments=128, ring_count=64)
cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam")); sc.collection.objects.link(cam)
sc.camera = cam; cam.location = (0, 0, 8); cam.data.angle = 0.52
light = bpy.data.lights.new("l", "POINT"); light.shadow_soft_size = 0
obj = bpy.data.objects.new("l", light); sc.collection.objects.link(obj); obj.location = (0, 0, 8); light.energy = 1000
mat = bpy.data.materials.new("m"); mat.use_nodes = True
bpy.context.active_object.data.materials.append(mat)
bsdf = mat.node_tree.nodes["Principled BSDF"]
out = {}
for res in (128, 256, 512):
    sc.render.resolution_x = sc.render.resolution_y = res
    times = []
    for i in range(6):
        bsdf.inputs["Roughness"].default_value = 0.2 + 0.01 * i
        t = time.perf_counter(); bpy.ops.render.render(write_still=False); times.append(time.perf_counter() - t)
    out[f"{res}x{res} frame"] = {"ms": 1000 * statistics.median(times[1:]),
                                 "us/pixel": 1e6 * statistics.median(times[1:]) / res / res}
print(json.dumps(out), file=sys.__stdout__)
"""


def counting(renderer: Any) -> dict[str, int]:
    """Count the render calls and images of a renderer instance (both versions draw through ``render_pixels``)."""
    stats = {"calls": 0, "images": 0}
    inner = renderer.render_pixels

    def wrapped(materials, scene):
        stats["calls"] += 1
        stats["images"] += len(materials)
        return inner(materials, scene)

    renderer.render_pixels = wrapped
    return stats


def timed_fits(sources, target, fix, strategy, scene, target_renderer=None, best_of=3) -> dict[str, float]:
    """Median wall and CPU milliseconds (best of ``best_of`` per source; CPU time of this process, which the
    machine's other load disturbs less; the target renderer's own threads, if any, included), renders, calls
    to the target renderer (all renders on the embedded one) and loss of fits."""
    from matremap.renderers import get_renderer
    from matremap.uniform import fit

    renderer = get_renderer(target_renderer) if target_renderer else get_renderer()
    stats = counting(renderer)
    seconds, cpu, renders, calls, losses = [], [], [], [], []
    for s in sources:
        best = best_cpu = float("inf")
        for _ in range(best_of):
            before = stats["calls"]
            t, c = time.perf_counter(), time.process_time()
            r = fit(s, target, strategy, scene, target_renderer=target_renderer, fix=fix)
            best, best_cpu = min(best, time.perf_counter() - t), min(best_cpu, time.process_time() - c)
            calls.append(stats["calls"] - before)
        seconds.append(best)
        cpu.append(best_cpu)
        renders.append(r.renders)
        losses.append(r.loss)
    del renderer.render_pixels  # the class's method again
    med = statistics.median
    return {
        "ms": 1000 * med(seconds),
        "cpu ms": 1000 * med(cpu),
        "renders": med(renders),
        "calls": med(calls),
        "loss": med(losses),
    }


def job_fit() -> dict[str, Any]:
    import numpy as np

    from matremap.core.material import Material
    from matremap.core.scene import Scene
    from matremap.uniform import fit

    scene = Scene(resolution=128)
    rng = np.random.default_rng(0)
    glossy = [
        Material.create(
            "cycles:glossy",
            {
                "Roughness": rng.uniform(0.2, 0.9),
                "Color": rng.uniform(0.1, 0.9, 3).tolist(),
                "Diffuse Color": rng.uniform(0.0, 0.5, 3).tolist(),
            },
        )
        for _ in range(20)
    ]
    ward = [Material.create("mitsuba06:ward", COLOURED_WARD)]
    fit(ward[0], "mitsuba06:pbr", scene=scene)  # warm up (imports, tables)
    out: dict[str, Any] = {}
    for strategy in ("two-stage", "separable", "simple"):
        out[f"glossy->pbr {strategy}"] = timed_fits(glossy, "mitsuba06:pbr", {"distribution": "ggx"}, strategy, scene)
        out[f"ward->roughplastic {strategy}"] = timed_fits(
            ward, "mitsuba06:roughplastic", {"distribution": "ggx"}, strategy, scene, best_of=5
        )
    return out


def cpu_seconds() -> float:
    """CPU seconds used so far by this process (all its threads)."""
    return time.process_time()


def sweep_seconds(source, target, fix, grid_text, workers, scene, target_renderer=None) -> tuple[float, list]:
    """Seconds of a fresh sweep and its rows (and, in ``CPU[0]``, the CPU seconds this process used: all of the
    sweep's with one worker, which runs in this process)."""
    from matremap.sweep.executors import make_executor
    from matremap.sweep.grid import parse_grid
    from matremap.sweep.run import SweepConfig, run_sweep
    from matremap.sweep.store import SweepStore

    config = SweepConfig(source=source, target=target, fix=fix, scene=scene, target_renderer=target_renderer)
    grid = parse_grid(grid_text, source.spec)
    with tempfile.TemporaryDirectory() as tmp:
        db = Path(tmp) / "s.sqlite"
        t, c = time.perf_counter(), cpu_seconds()
        with make_executor(workers=workers) as (ex, _):
            summary = run_sweep(config, grid, str(db), ex, in_flight=2 * workers)
        seconds = time.perf_counter() - t
        CPU[0] = cpu_seconds() - c
        assert summary.failed == 0, summary
        return seconds, SweepStore.open(db).rows()


def job_grid() -> dict[str, Any]:
    from matremap.core.material import Material
    from matremap.core.scene import Scene
    from matremap.renderers import get_renderer

    source = Material.create("mitsuba06:ward", {"variant": "ward", "diffuseReflectance": 0.0})
    fix = {"distribution": "as"}
    grid = "alpha=0.005:0.99:35,specularReflectance=0.02:0.232413793103:23"
    seconds, rows = sweep_seconds(source, "mitsuba06:pbr", fix, grid, 2, Scene(resolution=128))
    stats = counting(get_renderer())
    small = "alpha=0.005:0.99:35,specularReflectance=0.02:0.0753:4"
    inline, small_rows = sweep_seconds(source, "mitsuba06:pbr", fix, small, 1, Scene(resolution=128))
    return {
        "authors' grid (805 points), 2 workers": {"s": seconds, "ms/point": 1000 * seconds / len(rows)},
        "its first 4 columns (140 points), 1 process": {
            "s": inline,
            "cpu ms/point": 1000 * CPU[0] / len(small_rows),
            "805 points on 2 free cores s": len(rows) * CPU[0] / len(small_rows) / 2,
            "renders/fit": sum(r["renders"] for r in small_rows) / len(small_rows),
            "render calls": stats["calls"],
            "images drawn": stats["images"],
        },
    }


def job_mitsuba() -> dict[str, Any]:
    from matremap.core.material import Material
    from matremap.core.scene import Scene

    scene = Scene(resolution=128)
    sources = [
        Material.create(
            "mitsuba06:ward", {"variant": "ward", "alpha": a, "specularReflectance": s, "diffuseReflectance": 0}
        )
        for a in (0.05, 0.15, 0.3, 0.5, 0.8)
        for s in (0.04, 0.15)
    ]
    conductor = ("mitsuba3:roughconductor", {"distribution": "ggx"})
    plastic = ("mitsuba3:roughplastic", {"distribution": "ggx"})
    ward = [Material.create("mitsuba06:ward", COLOURED_WARD)]
    timed_fits(sources[:1], *conductor, "two-stage", scene, "mitsuba3", best_of=1)  # warm up: import, JIT
    out = {"ward->mitsuba3 roughconductor two-stage": timed_fits(sources, *conductor, "two-stage", scene, "mitsuba3")}
    for s in ("two-stage", "separable"):
        out[f"ward->mitsuba3 roughplastic {s}"] = timed_fits(ward, *plastic, s, scene, "mitsuba3", best_of=1)
    return out


def job_real_sweep(kind: str, points: int) -> dict[str, Any]:
    from matremap.core.material import Material
    from matremap.core.scene import Scene

    if kind == "mitsuba":
        source = Material.create("mitsuba06:ward", {"variant": "ward", "diffuseReflectance": 0.0})
        target, fix, renderer = "mitsuba3:roughconductor", {"distribution": "ggx"}, "mitsuba3"
    else:
        source = Material.create("mitsuba06:ward", COLOURED_WARD)
        target, fix, renderer = "cycles:principled", {}, "cycles"
    columns = max(1, points // 40) if points >= 40 else 1
    rows_n = points // columns
    grid = f"alpha=0.02:0.9:{rows_n},specularReflectance=0.02:0.25:{columns}"
    # Cycles renders with both cores in one worker process: one sweep process, its bpy worker's CPU counted
    workers = 2 if kind == "mitsuba" else 1
    c = cpu_seconds()
    seconds, rows = sweep_seconds(source, target, fix, grid, workers, Scene(resolution=128), renderer)
    cpu = {}
    if kind == "cycles":  # this process and its bpy worker (Cycles' threads included)
        import psutil

        from matremap.renderers import get_renderer

        worker = psutil.Process(get_renderer("cycles").pid).cpu_times()
        cpu = {"cpu s (with bpy)": cpu_seconds() - c + worker.user + worker.system}
    return {
        f"{kind} sweep ({len(rows)} points), {workers} worker(s)": {
            "s": seconds,
            **cpu,
            "s/point": seconds / len(rows),
            "1,000 points s": 1000 * seconds / len(rows),
            "renders/fit": sum(r["renders"] for r in rows) / len(rows),
        }
    }


def job_readme() -> dict[str, Any]:
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        (work / "examples").symlink_to(ROOT / "examples")
        env = {**os.environ, "MATREMAP_CACHE": str(work / "cache")}
        argv = [str(Path(sys.executable).parent / "matremap"), "remap", "examples/bronze", "--to", "mitsuba06:pbr"]
        argv += ["--fix", "distribution=as", "-o", "out/bronze"]
        t = time.perf_counter()
        p = subprocess.run(argv, cwd=work, env=env, capture_output=True, text=True)
        return {"README main job": {"s": time.perf_counter() - t, "exit": p.returncode}}


def run_job(name: str, args: argparse.Namespace) -> dict[str, Any]:
    if name == "fit":
        return job_fit()
    if name == "grid":
        return job_grid()
    if name == "mitsuba":
        return job_mitsuba()
    if name == "mitsuba-sweep":
        return job_real_sweep("mitsuba", args.mitsuba_points)
    if name == "cycles-sweep":
        return job_real_sweep("cycles", args.cycles_points)
    if name == "cycles-frame":
        return job_cycles_frame()
    return job_readme()


def job_cycles_frame() -> dict[str, Any]:
    from matremap.renderers.cycles.client import find_python

    p = subprocess.run([find_python(), "-c", CYCLES_FRAME], capture_output=True, text=True)
    lines = [line for line in p.stdout.splitlines() if line.startswith("{")]
    return json.loads(lines[-1]) if lines else {"cycles frame": {"error": 1.0}}


def spawn(name: str, src: str, args: argparse.Namespace) -> dict[str, Any]:
    """Run one job in a fresh process on the sources in ``src``; its JSON result (or the error)."""
    env = {**os.environ, "PYTHONPATH": src, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    argv = [sys.executable, __file__, "--job", name]
    argv += ["--mitsuba-points", str(args.mitsuba_points), "--cycles-points", str(args.cycles_points)]
    p = subprocess.run(argv, env=env, capture_output=True, text=True)
    lines = [line for line in p.stdout.splitlines() if line.startswith("{")]
    if p.returncode != 0 or not lines:
        return {"error": (p.stderr.strip().splitlines() or ["no output"])[-1][:200]}
    return json.loads(lines[-1])


def table(results: dict[str, dict[str, list[dict[str, Any]]]]) -> None:
    """One row per measured quantity: before and after medians side by side."""
    print(f"{'measurement':<52} {'quantity':<16} {'before':>10} {'after':>10}")
    for job, sides in results.items():
        if any("error" in r for side in sides.values() for r in side):
            errors = {k: [r.get("error") for r in v if "error" in r] for k, v in sides.items()}
            print(f"{job:<52} error: {errors}")
            continue
        for row in sides["after"][0]:
            for quantity in sides["after"][0][row]:
                values = []
                for side in ("before", "after"):
                    got = [r[row][quantity] for r in sides[side] if row in r and quantity in r[row]]
                    values.append(f"{statistics.median(got):10.4g}" if got else f"{'-':>10}")
                print(f"{row:<52} {quantity:<16} {values[0]} {values[1]}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--before",
        default=str(Path(__file__).resolve().parents[1] / "src"),
        help="the sources to compare with (default: this checkout's own)",
    )
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--jobs", nargs="+", choices=JOBS, default=list(JOBS))
    ap.add_argument("--mitsuba-points", type=int, default=1000)
    ap.add_argument("--cycles-points", type=int, default=24)
    ap.add_argument("--job", choices=JOBS, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.job:
        print(json.dumps(run_job(args.job, args)))
        return
    after = str(ROOT / "src")
    results: dict[str, dict[str, list[dict[str, Any]]]] = {}
    for name in args.jobs:
        results[name] = {"before": [], "after": []}
        for _ in range(args.repeat):
            results[name]["before"].append(spawn(name, args.before, args))
            results[name]["after"].append(spawn(name, after, args))
    print(f"before: {args.before}   after: {after}   medians of {args.repeat} interleaved runs", end="")
    print(f", {os.cpu_count()} cores\n")
    table(results)


if __name__ == "__main__":
    main()
