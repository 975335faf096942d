"""PhysicallyBased materials: the hand-made glTF translations shipped with ``materialxmaterials`` against
matremap's fitted remap, both judged against a physical render of the database's values.

Data: the PhysicallyBased database by Anton Palmqvist (https://physicallybased.info, CC0), as packaged
with MaterialX translations by Bernard Kwok in the PyPI package ``materialxmaterials`` (import name
``materialxMaterials``, file ``data/PhysicallyBasedMaterialX/PhysicallyBasedMaterial.json`` and the
``gltf_pbr`` document ``PhysicallyBasedMaterialX_GLTF.mtlx``). Install it with
``pip install -e '.[bench]'`` or ``pip install materialxmaterials``.

For every opaque material of the database:

* **truth**: the database values rendered with a physical model on the embedded renderer. Metals
  (metalness 1): ``mitsuba06:roughconductor`` (GGX, exact conductor Fresnel) with the database's
  RGB complex IOR (its ``srgb-linear`` n and k, used as they are); dielectrics (metalness 0):
  ``mitsuba06:roughplastic`` (GGX) with intIOR = ``ior`` and diffuseReflectance = ``color``. The
  database roughness is taken as perceptual, alpha = roughness^2, and raised to ``--min-roughness``
  (most metals are listed at 0, a mirror that a point-lit probe cannot show). Transmissive,
  subsurface, thin-film and dyed materials are skipped with their reason;
* **(a) hand-made**: the material of ``PhysicallyBasedMaterialX_GLTF.mtlx`` read by matremap's
  MaterialX reader (or, if the reader refuses it, straight from the MaterialX document), rendered with
  ``gltf:metal-rough``, roughness raised to the same floor;
* **(b) matremap**: ``fit(truth, "gltf:metal-rough", fix={"metallic": 1 or 0})`` on the probe
  (headlight); for dielectrics also with ``ior`` or ``specularColor`` freed.

Errors: relative RMSE of linear images over the sphere, ||x - truth|| / ||truth||, on the fit's
probe (headlight), on a probe with three lights (0, 45, 70 degrees) and under the built-in
environment map (with DSSIM = 1 - SSIM over the sphere, scikit-image). Metals are also rendered with
real Mitsuba 3 (``mitsuba3:roughconductor``) to check the embedded conductor.

    .venv/bin/python benchmarks/materialx_compare.py [--size 128] [--plots] [--json out.json]

``--plots`` writes docs/img/materials/*.png.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

from matremap.core.envmap import directional_lights, resolve
from matremap.core.imageio import linear_to_srgb
from matremap.core.material import Material
from matremap.core.scene import Scene
from matremap.dialects import get_model
from matremap.errors import MatremapError
from matremap.renderers import get_renderer
from matremap.renderers.embedded.environment import SVBRDFRender
from matremap.renderers.textured import object_mask
from matremap.svbrdf.evaluate import ssim_map
from matremap.uniform import fit

TARGET = "gltf:metal-rough"
FIT_LIGHTS = (0.0,)
#: a second fit scene for dielectric variants: headlight and a light 60 degrees off
FIT_LIGHTS_2 = (0.0, 60.0)
CHECK_LIGHTS = (0.0, 45.0, 70.0)
ENV_LIGHTS = 256
#: a metal whose listed colour is this far (max over RGB) from the F0 of its n, k is coloured by something else
DYE_GAP = 0.15
IMG_DIR = Path(__file__).resolve().parent.parent / "docs" / "img" / "materials"
VIEWS = ("probe", "lights3", "env")
#: fit variants for dielectrics: name -> (strategy, parameters freed); "b" is the default remap (and the
#: only one for metals, whose glTF form has no diffuse part, so every strategy is the same there)
VARIANTS = {
    "b": ("two-stage", (), FIT_LIGHTS),
    "b_ior": ("two-stage", ("ior",), FIT_LIGHTS),
    "b3": ("three-stage", (), FIT_LIGHTS),
    "b3_ior": ("three-stage", ("ior",), FIT_LIGHTS),
    "b3_spec": ("three-stage", ("specularColor",), FIT_LIGHTS),
    "b_ior_2L": ("two-stage", ("ior",), FIT_LIGHTS_2),
    "b3_ior_2L": ("three-stage", ("ior",), FIT_LIGHTS_2),
}
#: every candidate, in table order: (a) as shipped, (a) with F0 computed from n,k (metals), the fits
CANDIDATES = ("a", "a_nk", *VARIANTS)


def data_dir() -> Path:
    try:
        import materialxMaterials
    except ImportError:
        raise SystemExit("needs the materialxmaterials package: .venv/bin/pip install materialxmaterials") from None
    return Path(materialxMaterials.__file__).resolve().parent / "data" / "PhysicallyBasedMaterialX"


def linear_rgb(entries: Any, key: str = "color") -> list[float] | None:
    """The ``srgb-linear`` triple of a database colour field (a list of per-colour-space entries)."""
    if not entries:
        return None
    for e in entries:
        if isinstance(e, dict) and e.get("colorSpace") == "srgb-linear":
            return [float(x) for x in e[key]]
    return None


def conductor_f0(n: np.ndarray, k: np.ndarray) -> np.ndarray:
    return ((n - 1.0) ** 2 + k * k) / ((n + 1.0) ** 2 + k * k)


@dataclass
class Entry:
    name: str
    kind: str = ""
    skip: str = ""
    roughness_db: float = 0.0
    roughness: float = 0.0
    truth: Material | None = None
    hand: Material | None = None
    hand_nk: Material | None = None  # metals: the hand-made glTF with baseColor = F0 of the database's n, k
    hand_how: str = ""
    notes: list[str] = field(default_factory=list)
    fits: dict[str, Any] = field(default_factory=dict)  # variant -> FitResult
    err: dict[str, dict[str, float]] = field(default_factory=dict)  # candidate -> {view: error}
    mitsuba3: dict[str, float] = field(default_factory=dict)
    images: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)  # view -> {who: image}


def classify(rec: dict[str, Any], min_roughness: float) -> Entry:
    e = Entry(rec["name"])
    e.roughness_db = float(rec.get("roughness", 0.0))
    e.roughness = max(e.roughness_db, min_roughness)
    metal = rec.get("metalness", 0)
    if rec.get("transmission"):
        e.skip = f"transmissive (transmission={rec['transmission']}): a clear body, not an opaque BRDF"
    elif rec.get("subsurfaceRadius"):
        e.skip = "subsurface scattering (subsurfaceRadius): translucent body, not an opaque BRDF"
    elif rec.get("thinFilmIor") or rec.get("thinFilmThickness"):
        e.skip = "thin-film interference (thinFilmIor / thinFilmThickness)"
    elif metal not in (0, 1):
        e.skip = f"partly metallic (metalness={metal})"
    if e.skip:
        return e
    colour = linear_rgb(rec.get("color"))
    alpha = e.roughness**2
    if metal == 1:
        nk = next((c for c in rec.get("complexIor", []) if c.get("colorSpace") == "srgb-linear"), None)
        if nk is None:
            e.skip = "metal without an RGB complex IOR"
            return e
        n, k = np.array(nk["n"], float), np.array(nk["k"], float)
        f0 = conductor_f0(n, k)
        gap = float(np.max(np.abs(f0 - np.array(colour))))
        if gap > DYE_GAP:
            e.skip = (
                f"colour {colour} is not its n,k's F0 {np.round(f0, 3).tolist()} (a dye or coating; "
                f"the n,k are the bare metal's)"
            )
            return e
        e.kind = "metal"
        e.truth = Material.create(
            "mitsuba06:roughconductor",
            {"distribution": "ggx", "alpha": alpha, "eta": n.tolist(), "k": k.tolist(), "extEta": 1.0},
        )
        if gap > 0.02:
            e.notes.append(f"listed colour {colour} vs F0 of n,k {np.round(f0, 3).tolist()}")
    else:
        e.kind = "dielectric"
        ior = float(rec.get("ior", 1.5))
        diffuse = np.clip(colour, 0.0, 1.0).tolist()
        e.truth = Material.create(
            "mitsuba06:roughplastic",
            {"distribution": "ggx", "alpha": alpha, "intIOR": ior, "extIOR": 1.0, "diffuseReflectance": diffuse},
        )
    return e


# ---------------------------------------------------------------------------------------------
# the hand-made glTF translation


def mtlx_index(path: Path) -> dict[str, tuple[str, Any]]:
    """uiname -> (surfacematerial name, its shader node), from the MaterialX document."""
    import MaterialX as mx

    doc = mx.createDocument()
    mx.readFromXmlFile(doc, str(path))
    out = {}
    for m in doc.getMaterialNodes():
        shaders = mx.getShaderNodes(m)
        if shaders:
            out[shaders[0].getAttribute("uiname") or m.getName()] = (m.getName(), shaders[0])
    return out


def hand_made(e: Entry, path: Path, index: dict[str, tuple[str, Any]]) -> None:
    from matremap.formats import materialx

    if e.name not in index:
        e.skip = "no material of that name in the glTF document"
        return
    mat_name, shader = index[e.name]
    try:
        asset = materialx.read(path, mat_name)
        m = asset.material()
        e.hand_how = "matremap reader"
        e.notes += [n for n in asset.notes if not n.startswith("gltf_pbr inputs not remapped")]
    except MatremapError as err:  # read the node's values with MaterialX and clamp them to glTF's ranges
        spec = get_model(TARGET)
        table = materialx.SHADERS["gltf_pbr"]
        params = {}
        for inp in shader.getInputs():
            if inp.getName() in table:
                p = spec.param(table[inp.getName()])
                vals = [float(v) for v in inp.getValueString().replace(",", " ").split()]
                raw = vals[0] if p.channels == 1 else vals
                params[p.name] = np.clip(raw, *p.bounds).tolist()
                if not np.allclose(raw, params[p.name]):
                    e.notes.append(f"hand-made {inp.getName()}={vals} clamped to {params[p.name]}")
        m = Material.create(TARGET, params)
        e.hand_how = f"MaterialX fallback (matremap's reader: {str(err).split(': ', 2)[-1]})"
    r = float(m.values["roughness"][0])
    if abs(r - e.roughness_db) > 1e-6:
        e.notes.append(f"hand-made roughness {r} differs from the database's {e.roughness_db}")
    e.hand = m.with_params({"roughness": max(r, e.roughness)})
    if e.kind == "metal":
        v = e.truth.values
        f0 = conductor_f0(v["eta"] / v["extEta"], v["k"] / v["extEta"])
        e.hand_nk = e.hand.with_params({"baseColor": np.clip(f0, 0.0, 1.0).tolist()})


# ---------------------------------------------------------------------------------------------
# rendering and errors


class Views:
    def __init__(self, size: int, env_name: str) -> None:
        self.size = size
        self.scenes = {"probe": Scene.probe(FIT_LIGHTS, size), "lights3": Scene.probe(CHECK_LIGHTS, size)}
        self.masks = {k: s.mask() for k, s in self.scenes.items()}
        self.env = resolve(env_name)
        self.env_lights = directional_lights(self.env, ENV_LIGHTS, 0.0)
        self.masks["env"] = object_mask("sphere", size)
        self.embedded = get_renderer("embedded")

    def render(self, materials: list[Material], view: str) -> list[np.ndarray]:
        if view == "env":
            out = []
            for m in materials:
                params = {k: v for k, v in m.values.items()}
                r = SVBRDFRender(m.model, params, dict(m.options), "sphere", self.size)
                out.append(r.render(*self.env_lights))
            return out
        return list(self.embedded.render(materials, self.scenes[view]))


def rel_rmse(x: np.ndarray, truth: np.ndarray, mask: np.ndarray) -> float:
    t = truth[mask].astype(np.float64)
    return float(np.linalg.norm(x[mask].astype(np.float64) - t) / np.linalg.norm(t))


def dssim(x: np.ndarray, truth: np.ndarray, mask: np.ndarray) -> float:
    _, smap = ssim_map(truth, x)
    return float(np.mean(1.0 - smap[mask]))


def mitsuba3_check(e: Entry, views: Views) -> None:
    """Real Mitsuba 3's roughconductor with the truth's parameters against the embedded one."""
    v = e.truth.values
    m3 = Material.create(
        "mitsuba3:roughconductor",
        {"distribution": "ggx", "alpha": float(v["alpha"][0]), "eta": v["eta"].tolist(), "k": v["k"].tolist()},
    )
    r = get_renderer("mitsuba3")
    for view in ("probe", "lights3"):
        img = r.render([m3], views.scenes[view])[0]
        e.mitsuba3[view] = rel_rmse(img, e.images[view]["truth"], views.masks[view])


def run_entry(e: Entry, views: Views, variants: dict[str, Any], keep_images: bool) -> None:
    metallic = 1.0 if e.kind == "metal" else 0.0
    names = ["b"] if e.kind == "metal" else list(variants)
    for name in names:
        strategy, free, lights = variants[name]
        e.fits[name] = fit(
            e.truth,
            TARGET,
            strategy=strategy,
            scene=Scene.probe(lights, views.size),
            fix={"metallic": metallic},
            free=free,
        )
    cands = {"a": e.hand}
    if e.hand_nk is not None:
        cands["a_nk"] = e.hand_nk
    cands.update({k: f.target for k, f in e.fits.items()})
    for view in VIEWS:
        imgs = views.render([e.truth, *cands.values()], view)
        truth, mask = imgs[0], views.masks[view]
        e.images[view] = {"truth": truth, **dict(zip(cands, imgs[1:], strict=True))}
        for who, img in zip(cands, imgs[1:], strict=True):
            e.err.setdefault(who, {})[view] = rel_rmse(img, truth, mask)
            if view == "env":
                e.err[who]["env_dssim"] = dssim(img, truth, mask)
    if not keep_images:
        e.images = {v: {"truth": d["truth"]} for v, d in e.images.items()}  # the Mitsuba 3 check needs the truth


# ---------------------------------------------------------------------------------------------
# reporting


def fmt_params(m: Material) -> str:
    v = m.values
    bc = ", ".join(f"{x:.3f}" for x in v["baseColor"])
    s = f"base ({bc}), r {v['roughness'][0]:.3f}"
    if v["metallic"][0] < 0.5 and abs(v["ior"][0] - 1.5) > 1e-6:
        s += f", ior {v['ior'][0]:.3f}"
    if v["metallic"][0] < 0.5 and np.any(np.abs(v["specularColor"] - 1.0) > 1e-6):
        s += ", specColor (" + ", ".join(f"{x:.2f}" for x in v["specularColor"]) + ")"
    return s


def summary(entries: list[Entry], cand: str, view: str, kind: str | None = None) -> dict[str, Any]:
    rows = [e for e in entries if cand in e.err and (kind is None or e.kind == kind)]
    if not rows:
        return {"n": 0}
    a = np.array([e.err["a"][view] for e in rows])
    b = np.array([e.err[cand][view] for e in rows])
    ratio = b / a
    return {
        "n": len(rows),
        "wins": int(np.sum(b < a)),
        "median_a": float(np.median(a)),
        "median_b": float(np.median(b)),
        "median_ratio": float(np.median(ratio)),
        "worst_ratio": float(np.max(ratio)),
        "worst": rows[int(np.argmax(ratio))].name if rows else "",
    }


def print_report(entries: list[Entry], skipped: list[Entry], seconds: float) -> None:
    done = [e for e in entries if e.err]
    print(
        f"# {len(done)} materials compared ({sum(e.kind == 'metal' for e in done)} metals, "
        f"{sum(e.kind == 'dielectric' for e in done)} dielectrics), {len(skipped)} skipped, {seconds:.0f} s\n"
    )
    cells = {"metal": ("a", "a_nk", "b"), "dielectric": ("a", "b", "b_ior", "b3", "b3_ior", "b3_ior_2L")}
    for kind, cands in cells.items():
        rows = [e for e in done if e.kind == kind]
        if not rows:
            continue
        cands = tuple(c for c in cands if c in rows[0].err)
        print(f"### {kind}s: relative RMSE in % (probe / 3 lights / env map), env DSSIM x100 in brackets\n")
        print("| material | roughness db -> used | " + " | ".join(cands) + " | (a) hand-made | (b) matremap |")
        print("|---|---|" + "---|" * (len(cands) + 2))
        for e in rows:
            errs = " | ".join(
                f"{100 * e.err[c]['probe']:.1f} / {100 * e.err[c]['lights3']:.1f} / {100 * e.err[c]['env']:.1f} "
                f"[{100 * e.err[c]['env_dssim']:.2f}]"
                for c in cands
            )
            print(
                f"| {e.name} | {e.roughness_db:g} -> {e.roughness:g} | {errs} | {fmt_params(e.hand)} | "
                f"{fmt_params(e.fits['b'].target)} |"
            )
        print()
    print("## summary (x = a candidate; wins = materials where x's error < a's, the shipped hand-made glTF)\n")
    print("| x | materials | view | wins | median a | median x | median x/a | worst x/a (material) |")
    print("|---|---|---|---|---|---|---|---|")
    for cand in CANDIDATES[1:]:
        for kind in (None, "metal", "dielectric"):
            if (cand == "a_nk" and kind != "metal") or (cand != "b" and cand.startswith("b") and kind != "dielectric"):
                continue
            for view in ("probe", "lights3", "env", "env_dssim"):
                s = summary(done, cand, view, kind)
                if not s["n"]:
                    continue
                print(
                    f"| {cand} | {kind or 'all'} ({s['n']}) | {view} | {s['wins']} | {s['median_a']:.4f} | "
                    f"{s['median_b']:.4f} | {s['median_ratio']:.3f} | {s['worst_ratio']:.2f} ({s['worst']}) |"
                )
    m3 = [e for e in done if e.mitsuba3]
    if m3:
        worst = max(m3, key=lambda e: max(e.mitsuba3.values()))
        print(
            f"\nMitsuba 3 roughconductor vs embedded truth, {len(m3)} metals: median relative RMSE "
            f"{np.median([e.mitsuba3['probe'] for e in m3]):.1e} (probe), "
            f"{np.median([e.mitsuba3['lights3'] for e in m3]):.1e} (3 lights); worst "
            f"{max(worst.mitsuba3.values()):.1e} ({worst.name})"
        )
    print("\n## biggest losses of b against a (env relative RMSE ratio)\n")
    losses = sorted(
        (e for e in done if e.err["b"]["env"] > e.err["a"]["env"]),
        key=lambda e: e.err["b"]["env"] / e.err["a"]["env"],
        reverse=True,
    )
    for e in losses[:10]:
        print(
            f"- {e.name} ({e.kind}): env a {e.err['a']['env']:.3f}, b {e.err['b']['env']:.3f}; probe a "
            f"{e.err['a']['probe']:.3f}, b {e.err['b']['probe']:.3f}; 3 lights a {e.err['a']['lights3']:.3f}, "
            f"b {e.err['b']['lights3']:.3f}"
        )
    notes = [(e.name, n) for e in done for n in e.notes]
    hows = sorted({(e.name, e.hand_how) for e in done if e.hand_how != "matremap reader"})
    if hows or notes:
        print("\n## notes\n")
        for name, how in hows:
            print(f"- {name}: hand-made read by {how}")
        for name, n in notes:
            print(f"- {name}: {n}")
    print("\n## skipped\n")
    for e in skipped:
        print(f"- {e.name}: {e.skip}")


def to_json(entries: list[Entry], skipped: list[Entry]) -> dict[str, Any]:
    return {
        "materials": [
            {
                "name": e.name,
                "kind": e.kind,
                "roughness_db": e.roughness_db,
                "roughness": e.roughness,
                "truth": e.truth.to_dict(),
                "hand": e.hand.to_dict(),
                "hand_read_by": e.hand_how,
                "fits": {k: {"params": f.params, "loss": f.loss, "renders": f.renders} for k, f in e.fits.items()},
                "errors": e.err,
                "mitsuba3": e.mitsuba3,
                "notes": e.notes,
            }
            for e in entries
            if e.err
        ],
        "skipped": {e.name: e.skip for e in skipped},
    }


# ---------------------------------------------------------------------------------------------
# plots


def tonemap(img: np.ndarray, exposure: float) -> np.ndarray:
    return np.clip(linear_to_srgb(np.clip(img * exposure, 0.0, 1.0)), 0.0, 1.0)


def exposure_of(img: np.ndarray, mask: np.ndarray) -> float:
    p = float(np.percentile(img[mask].max(axis=-1), 99.5))
    return 0.9 / p if p > 0 else 1.0


def plot_errors(entries: list[Entry], out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    done = [e for e in entries if e.err]
    labels = {
        "probe": "probe, headlight (fit scene)",
        "lights3": "probe, lights 0/45/70 deg",
        "env": "environment map",
        "env_dssim": "environment map, DSSIM",
    }
    fig, axes = plt.subplots(1, 4, figsize=(17, 4.4))
    for ax, view in zip(axes, labels, strict=True):
        for kind, colour in (("metal", "tab:orange"), ("dielectric", "tab:blue")):
            a = [e.err["a"][view] for e in done if e.kind == kind]
            b = [e.err["b"][view] for e in done if e.kind == kind]
            ax.scatter(a, b, s=14, c=colour, label=kind, alpha=0.8)
        lo = min(min(e.err[c][view] for e in done for c in ("a", "b")), 1e-4)
        hi = max(e.err[c][view] for e in done for c in ("a", "b"))
        ax.plot([lo, hi], [lo, hi], "k--", lw=0.8)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("(a) hand-made glTF")
        ax.set_ylabel("(b) matremap fit")
        ax.set_title(labels[view], fontsize=10)
        ax.grid(alpha=0.3, which="both", lw=0.4)
    axes[0].legend(loc="upper left", fontsize=8)
    fig.suptitle("error against the physical render, per material (below the diagonal: matremap closer)", fontsize=11)
    fig.tight_layout()
    fig.savefig(out / "scatter.png", dpi=90)
    plt.close(fig)

    order = sorted(done, key=lambda e: (e.kind, e.err["a"]["env"]))
    fig, ax = plt.subplots(figsize=(16, 4.8))
    x = np.arange(len(order))
    ax.bar(x - 0.2, [e.err["a"]["env"] for e in order], 0.4, label="(a) hand-made glTF", color="tab:gray")
    ax.bar(x + 0.2, [e.err["b"]["env"] for e in order], 0.4, label="(b) matremap fit", color="tab:green")
    ax.set_xticks(x, [e.name for e in order], rotation=90, fontsize=7)
    ax.set_yscale("log")
    ax.set_ylabel("relative RMSE, environment map")
    ax.legend(fontsize=8)
    split = sum(e.kind == "dielectric" for e in order)
    ax.axvline(split - 0.5, color="k", lw=0.6)
    ax.set_title(
        "per material (dielectrics left, metals right), independent view: built-in environment map", fontsize=10
    )
    ax.grid(axis="y", alpha=0.3, which="both", lw=0.4)
    fig.tight_layout()
    fig.savefig(out / "bars.png", dpi=90)
    plt.close(fig)


def strip(entries: list[Entry], names: list[str], views: Views, out: Path, view: str, fname: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [e for name in names for e in entries if e.name == name and e.images]
    cols = ["truth", "a", "b", "diff a x4", "diff b x4"]
    titles = {
        "truth": "truth (physical)",
        "a": "(a) hand-made glTF",
        "b": "(b) matremap fit",
        "diff a x4": "|a - truth| x4",
        "diff b x4": "|b - truth| x4",
    }
    fig, axes = plt.subplots(len(rows), len(cols), figsize=(2.0 * len(cols), 2.0 * len(rows) + 0.3), squeeze=False)
    mask = views.masks[view]
    for i, e in enumerate(rows):
        ims = e.images[view]
        ex = exposure_of(ims["truth"], mask)
        for j, c in enumerate(cols):
            if c.startswith("diff"):
                who = c.split()[1]
                img = tonemap(np.abs(ims[who] - ims["truth"]) * 4.0, ex)
            else:
                img = tonemap(ims[c], ex)
            ax = axes[i, j]
            ax.imshow(img)
            ax.set_xticks([])
            ax.set_yticks([])
            if i == 0:
                ax.set_title(titles[c], fontsize=8)
            if j == 0:
                ax.set_ylabel(e.name, fontsize=8)
            if c in ("a", "b"):
                ax.text(2, views.size - 4, f"{e.err[c][view]:.3f}", color="w", fontsize=7)
    fig.tight_layout()
    fig.savefig(out / fname, dpi=90)
    plt.close(fig)


# ---------------------------------------------------------------------------------------------


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, default=128, help="image resolution (default 128)")
    ap.add_argument(
        "--min-roughness",
        type=float,
        default=0.3,
        help="perceptual roughness floor for truth and hand-made (default 0.3, alpha 0.09)",
    )
    ap.add_argument("--env", default="builtin", help="environment map for the third view (default builtin)")
    ap.add_argument("--only", default="", help="comma-separated material names")
    ap.add_argument("--no-mitsuba3", action="store_true", help="skip the real Mitsuba 3 check of the metals")
    ap.add_argument(
        "--default-only",
        action="store_true",
        help="fit only the default remap (no three-stage / ior / specularColor variants for dielectrics)",
    )
    ap.add_argument("--plots", action="store_true", help=f"write plots into {IMG_DIR}")
    ap.add_argument("--json", help="write every figure to this JSON file")
    args = ap.parse_args()

    t0 = time.perf_counter()
    data = data_dir()
    records = json.loads((data / "PhysicallyBasedMaterial.json").read_text())
    gltf = data / "PhysicallyBasedMaterialX_GLTF.mtlx"
    index = mtlx_index(gltf)
    only = {s.strip() for s in args.only.split(",") if s.strip()}
    entries, skipped = [], []
    for rec in records:
        if only and rec["name"] not in only:
            continue
        e = classify(rec, args.min_roughness)
        if not e.skip:
            hand_made(e, gltf, index)
        (skipped if e.skip else entries).append(e)

    variants = {"b": VARIANTS["b"]} if args.default_only else VARIANTS
    views = Views(args.size, args.env)
    m3 = not args.no_mitsuba3
    for e in entries:
        run_entry(e, views, variants, keep_images=args.plots)
        if e.kind == "metal" and m3:
            try:
                mitsuba3_check(e, views)
            except MatremapError as err:
                print(f"(Mitsuba 3 check skipped: {err})")
                m3 = False
    print_report(entries, skipped, time.perf_counter() - t0)
    if args.json:
        Path(args.json).write_text(json.dumps(to_json(entries, skipped), indent=1))
    if args.plots:
        IMG_DIR.mkdir(parents=True, exist_ok=True)
        plot_errors(entries, IMG_DIR)
        done = [e for e in entries if e.err]
        worst = sorted(done, key=lambda e: e.err["b"]["env"] / e.err["a"]["env"], reverse=True)
        pick = [n for n in ("Gold", "Copper", "Aluminum", "Brick", "Car Paint") if any(e.name == n for e in done)]
        pick += [e.name for e in worst[:3] if e.name not in pick]
        strip(entries, pick, views, IMG_DIR, "env", "strip-env.png")
        strip(entries, pick, views, IMG_DIR, "lights3", "strip-lights3.png")
        print(f"\nplots in {IMG_DIR}")


if __name__ == "__main__":
    main()
