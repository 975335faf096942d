"""Several probe objects per Cycles frame (issue 17, must-have 3): does it pay? Both sides in one run.

    .venv/bin/python benchmarks/cycles_multiprobe.py [--materials 36] [--resolution 64 128] [--grids 1x1 2x2 3x3 4x4]
        [--repeat 3]

One bpy process (the bpy venv) renders the same ``--materials`` random ``cycles:principled`` materials
(coat and sheen included) in the probe scene with two lights (0 and 45 degrees, ``Scene.probe([0, 45])``):

* **one probe per frame**: the worker's own code path (``renderers/cycles/worker.py`` ``Probe.render``, imported
  from this checkout): per material and light, set the sockets, render one frame, write the 32-bit EXR, read it
  back. Also timed without the EXR round trip (``write_still=False``), to show what a frame costs by itself.
* **k probe objects per frame**: the same Cycles settings, a grid of k spheres (point clouds, each with its own
  material) and a camera widened so that every sphere covers the pixels the single probe's sphere covers
  (frame cols x R by rows x R); each sphere has its own point light per scene light, at the probe's position
  relative to it, restricted to it with Blender's light linking (receiver and blocker collections); the light
  tree is on, since light linking without it is rejection sampling (noise at 1 spp). One frame (EXR written and
  read) per light for k materials.

Reported per resolution and grid: ms per material (median of ``--repeat`` interleaved runs), and the relative
RMSE of each k-grid cell against the one-probe-per-frame image of the same material: the centre cell of an
odd grid sees its sphere along the probe's axis (it checks that the light linking leaves no cross-talk); an
off-axis cell sees its sphere from another direction (perspective), so its image is not the probe's.

Needs the bpy venv (``MATREMAP_BPY_PYTHON`` or ``.venv-bpy``).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

#: runs inside the bpy venv: argv[1] = worker.py, argv[2] = JSON job, argv[3] = output JSON
BPY_SCRIPT = r"""
import importlib.util, json, math, os, statistics, sys, tempfile, time
def load(name, path):
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec); spec.loader.exec_module(module)
    return module


worker = load("worker", sys.argv[1])
before = load("worker_before", sys.argv[4]) if len(sys.argv) > 4 else None
import bpy
import numpy as np
job = json.load(open(sys.argv[2]))
materials = job["materials"]


def one_per_frame(scene_dict, write, module=None):
    module = module or worker
    probe = module.Probe()
    if not write:  # the frame alone: no EXR round trip
        module._render_still = lambda scene, path, res: (bpy.ops.render.render(write_still=False),
                                                          np.zeros((res, res, 3), np.float32))[1]
    else:
        module._render_still = RENDER_STILL
    request = {"op": "render", "scene": scene_dict, "materials": materials}
    probe.render({**request, "materials": materials[:1]})  # build the scene and warm up
    t, c = time.perf_counter(), time.process_time()
    out = probe.render(request)
    return (time.perf_counter() - t, time.process_time() - c), out


RENDER_STILL = worker._render_still


def grid_frames(scene_dict, cols, rows):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    res = worker._probe_settings(scene, scene_dict)
    scene.cycles.use_light_tree = True  # light linking picks among the linked lights only with the tree
    d, r = float(scene_dict["camera_distance"]), float(scene_dict["sphere_radius"])
    half = math.tan(math.radians(float(scene_dict["fov"])) / 2)
    width = 2 * d * half  # the probe image's width in the sphere's plane
    cam = scene.camera
    cam.data.sensor_fit = "HORIZONTAL"
    cam.data.angle = 2 * math.atan(cols * half)
    scene.render.resolution_x, scene.render.resolution_y = cols * res, rows * res
    probe = worker.Probe.__new__(worker.Probe)
    probe.materials = {}
    spheres, mats = [], []
    for j in range(rows):
        for i in range(cols):
            centre = ((i - (cols - 1) / 2) * width, ((rows - 1) / 2 - j) * width, 0.0)
            obj = probe._sphere(r, "points")
            obj.name = f"sphere_{j}_{i}"
            obj.location = centre
            scene.collection.objects.link(obj)
            coll = bpy.data.collections.new(f"probe_{j}_{i}")
            coll.objects.link(obj)
            node = probe.set_material_node
            mat = bpy.data.materials.new(f"m_{j}_{i}")
            mat.use_nodes = True
            nt = mat.node_tree
            for n in list(nt.nodes):
                nt.nodes.remove(n)
            sockets, _ = worker._material_nodes(nt, "cycles:principled", {})
            node.inputs["Material"].default_value = mat
            lights = []
            for lt in scene_dict["lights"]:
                data = bpy.data.lights.new(f"l_{j}_{i}", type="POINT")
                data.shadow_soft_size = 0.0
                if hasattr(data, "use_soft_falloff"):
                    data.use_soft_falloff = False
                data.energy = 4.0 * math.pi * float(lt["intensity"])
                lo = bpy.data.objects.new(f"l_{j}_{i}", data)
                lo.location = tuple(c + float(p) for c, p in zip(centre, lt["position"]))
                scene.collection.objects.link(lo)
                lo.light_linking.receiver_collection = coll
                lo.light_linking.blocker_collection = coll
                lights.append(lo)
            spheres.append((sockets, lights))
    path = os.path.join(tempfile.mkdtemp(), "grid.exr")
    k = cols * rows
    out = np.zeros((len(materials), res, res, 3), np.float32)

    # warm up, then time
    for _ in range(2):
        t, c = time.perf_counter(), time.process_time()
        for start in range(0, len(materials), k):
            batch = materials[start:start + k]
            for (sockets, _), m in zip(spheres, batch):
                for name, socket in sockets.items():
                    worker._set_socket(socket, m["values"][name])
            acc = np.zeros((rows * res, cols * res, 3), np.float32)
            for li in range(len(scene_dict["lights"])):
                for s, (_, lights) in enumerate(spheres):
                    for lj, lo in enumerate(lights):
                        lo.hide_render = lj != li
                scene.render.filepath = path
                bpy.ops.render.render(write_still=True)
                im = bpy.data.images.load(path, check_existing=False)
                buf = np.empty(rows * res * cols * res * 4, np.float32)
                im.pixels.foreach_get(buf)
                bpy.data.images.remove(im)
                acc += buf.reshape(rows * res, cols * res, 4)[::-1, :, :3]
            for s in range(len(batch)):
                j, i = divmod(s, cols)
                out[start + s] = acc[j * res:(j + 1) * res, i * res:(i + 1) * res]
        seconds = (time.perf_counter() - t, time.process_time() - c)
    return seconds, out


results = {}
for rep in range(job["repeat"]):
    for res in job["resolutions"]:
        s = dict(job["scene"], resolution=res)
        if before is not None:
            t_before, ref_before = one_per_frame(s, True, before)
            results.setdefault(f"{res} one per frame, before", []).append({"s": t_before[0], "cpu": t_before[1]})
        t_one, ref = one_per_frame(s, True)
        if before is not None:
            same = float(np.abs(ref - ref_before).max())
            results[f"{res} one per frame, before"][-1]["centre"] = same  # max |after - before|
        t_bare, _ = one_per_frame(s, False)
        results.setdefault(f"{res} one per frame", []).append({"s": t_one[0], "cpu": t_one[1]})
        results.setdefault(f"{res} one per frame, no EXR", []).append({"s": t_bare[0], "cpu": t_bare[1]})
        for g in job["grids"]:
            cols, rows = (int(x) for x in g.split("x"))
            t_grid, img = grid_frames(s, cols, rows)
            k = cols * rows
            errs = []
            for n in range(len(materials)):
                a, b = img[n].astype(float), ref[n].astype(float)
                errs.append(float(np.linalg.norm(a - b) / max(np.linalg.norm(b), 1e-30)))
            cell = np.arange(len(materials)) % k
            centre = (rows // 2) * cols + cols // 2 if cols % 2 and rows % 2 else None
            on = [e for e, c in zip(errs, cell) if c == centre]
            off = [e for e, c in zip(errs, cell) if c != centre]
            results.setdefault(f"{res} {g}", []).append({
                "s": t_grid[0], "cpu": t_grid[1], "centre": max(on) if on else None,
                "off-axis median": statistics.median(off) if off else None})
json.dump(results, open(sys.argv[3], "w"))
"""


def materials(n: int, seed: int = 0) -> list[dict]:
    """Random cycles:principled materials (coat and sheen on half of them)."""
    from matremap.core.material import Material

    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        layered = i % 2 == 1
        m = Material.create(
            "cycles:principled",
            {
                "Base Color": rng.uniform(0.05, 0.9, 3).tolist(),
                "Metallic": float(rng.choice([0.0, 1.0])),
                "Roughness": float(rng.uniform(0.15, 0.9)),
                "IOR": float(rng.uniform(1.3, 2.0)),
                "Coat Weight": float(rng.uniform(0.3, 1.0)) if layered else 0.0,
                "Coat Roughness": float(rng.uniform(0.05, 0.5)),
                "Sheen Weight": float(rng.uniform(0.3, 1.0)) if layered else 0.0,
                "Sheen Tint": rng.uniform(0.2, 1.0, 3).tolist(),
            },
        )
        out.append(
            {
                "model": m.model,
                "options": dict(m.options),
                "values": {k: [float(x) for x in np.ravel(v)] for k, v in m.values.items()},
            }
        )
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--materials", type=int, default=36)
    ap.add_argument("--resolution", type=int, nargs="+", default=[64, 128])
    ap.add_argument("--grids", nargs="+", default=["1x1", "2x2", "3x3", "4x4"])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument(
        "--before-worker",
        help="another worker.py to time one probe per frame with (e.g. git show HEAD~1:src/matremap/renderers/"
        "cycles/worker.py > /tmp/w.py); the largest pixel difference is shown in the centre column",
    )
    args = ap.parse_args(argv)
    from matremap.core.scene import Scene
    from matremap.renderers.cycles.client import bpy_available, find_python
    from matremap.renderers.cycles.probe import CyclesRenderer

    if not bpy_available():
        print("needs the bpy venv (MATREMAP_BPY_PYTHON or .venv-bpy)")
        return 1
    scene = CyclesRenderer().scene_dict(Scene.probe([0.0, 45.0]))  # starts no worker
    job = {
        "scene": scene,
        "materials": materials(args.materials),
        "resolutions": args.resolution,
        "grids": args.grids,
        "repeat": args.repeat,
    }
    worker = ROOT / "src" / "matremap" / "renderers" / "cycles" / "worker.py"
    with tempfile.TemporaryDirectory() as tmp:
        jp, op = Path(tmp) / "job.json", Path(tmp) / "out.json"
        jp.write_text(json.dumps(job))
        extra = [str(Path(args.before_worker).resolve())] if args.before_worker else []
        p = subprocess.run(
            [find_python(), "-c", BPY_SCRIPT, str(worker), str(jp), str(op), *extra], capture_output=True, text=True
        )
        if not op.exists():
            print(p.stderr[-3000:])
            return 1
        results = json.loads(op.read_text())
    n = args.materials
    print(f"{n} cycles:principled materials, lights at 0 and 45 degrees, medians of {args.repeat} interleaved runs")
    print(
        "| frame | ms per material | CPU ms per material (all threads) | centre cell rel. RMSE |"
        " off-axis cells, median rel. RMSE |"
    )
    print("|---|---|---|---|---|")
    for key, runs in results.items():
        ms = 1000 * float(np.median([r["s"] for r in runs])) / n
        cpu = 1000 * float(np.median([r["cpu"] for r in runs])) / n
        c = runs[0].get("centre")
        o = runs[0].get("off-axis median")
        print(
            f"| {key} | {ms:.1f} | {cpu:.1f} | {'' if c is None else f'{c:.1e}'} | {'' if o is None else f'{o:.2g}'} |"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
