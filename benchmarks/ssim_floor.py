"""How low can mean 1-SSIM go for Ward -> Ashikhmin-Shirley under an environment map? (issue #5)

For each example map set (Mitsuba 0.6 Ward, variant=ward) this prints, over 6 rotations of the
builtin environment at 160^2 with 128 lights (the `remap` defaults):

* remapped  -- `matremap remap ... --to mitsuba06:pbr --fix distribution=as` (the headlight probe);
* naive     -- the same maps given to AS under the same names (alpha, specularReflectance -> F0,
               diffuseReflectance): what hand-written exporters do;

and, for a uniform material at each example's median parameters, two *floors*: AS parameters fitted
to the environment-lit Ward image itself, by least squares (L2) and by a direct search for the
highest SSIM (Nelder-Mead) -- what the best per-texel mapping could reach for that texel -- with
where on the sphere the dissimilarity lies (1-SSIM by distance from the centre, AS/Ward brightness).

    python benchmarks/ssim_floor.py
"""

from __future__ import annotations

import json
import tempfile
import warnings
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares, minimize

from matremap.core.envmap import directional_lights, resolve
from matremap.core.material import Material
from matremap.remap import load_arrays, remap
from matremap.renderers.embedded.environment import SVBRDFRender
from matremap.renderers.textured import object_mask
from matremap.svbrdf.evaluate import evaluate, ssim_map
from matremap.svbrdf.textures import load_map_set
from matremap.uniform import fit

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ("bronze", "blue-plastic", "scratched-gold")
ROTATIONS, RES, LIGHTS = [0.0, 60.0, 120.0, 180.0, 240.0, 300.0], 160, 128
AS = {"distribution": "as"}


def naive(example: str, tmp: Path) -> float:
    ms = load_map_set(ROOT / "examples" / example)
    params, normal = load_arrays(ms)
    renamed = {
        "alpha": params["alpha"],
        "F0": params["specularReflectance"],
        "diffuseReflectance": params["diffuseReflectance"],
    }
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = evaluate(
            (ms.model, params, ms.options, normal),
            ("mitsuba06:pbr", renamed, AS, normal),
            resolve("builtin"),
            ROTATIONS,
            tmp / f"naive-{example}",
            resolution=RES,
            lights=LIGHTS,
        )
    return float(r.mean_full)


def remapped(example: str, tmp: Path) -> tuple[float, float]:
    """Mean 1-SSIM of the remap, full and specular only."""
    r = remap(
        ROOT / "examples" / example,
        None,
        "mitsuba06:pbr",
        tmp / f"remap-{example}",
        fix=AS,
        rotations="0:360:6",
        resolution=RES,
        lights=LIGHTS,
        cache=tmp / "cache",
        log=lambda m: None,
    )
    results = json.loads((r.report.parent / "results.json").read_text())
    return float(r.mean_dssim), float(results["mean_dssim_specular"])


def floor(example: str) -> str:
    ms = load_map_set(ROOT / "examples" / example)
    params, _ = load_arrays(ms)
    med = {k: np.median(np.asarray(v).reshape(-1, *np.shape(v)[2:]), axis=0) for k, v in params.items()}
    env = resolve("builtin")
    d, i = directional_lights(env, LIGHTS, 0.0, 0)

    def render(model, p, opts):
        return SVBRDFRender(model, p, opts, "sphere", RES, "full", None).render(d, i).astype(float)

    src = render(ms.model, med, ms.options)
    probe = fit(Material.create(ms.model, {**med, **ms.options}), "mitsuba06:pbr", fix=AS).target
    x0 = np.r_[probe.values["alpha"], probe.values["F0"], probe.values["diffuseReflectance"]]

    def unpack(x):
        return {"alpha": x[0], "F0": x[1:4], "diffuseReflectance": x[4:7]}

    sol = least_squares(
        lambda x: (render("mitsuba06:pbr", unpack(x), AS) - src).ravel(),
        x0,
        bounds=([1e-3] + [0.0] * 6, [1.0] * 7),
        x_scale="jac",
    )
    best = render("mitsuba06:pbr", unpack(sol.x), AS)
    fitted = render("mitsuba06:pbr", dict(probe.values), dict(probe.options))
    m_best, smap = ssim_map(src, best)
    m_fit = ssim_map(src, fitted)[0]

    def dssim(x):
        p = {
            "alpha": np.clip(x[0], 1e-3, 1.0),
            "F0": np.clip(x[1:4], 0, 1),
            "diffuseReflectance": np.clip(x[4:7], 0, 1),
        }
        return 1.0 - ssim_map(src, render("mitsuba06:pbr", p, AS))[0]

    search = minimize(dssim, x0, method="Nelder-Mead", options={"maxfev": 600, "xatol": 1e-4, "fatol": 1e-5})
    mask = object_mask("sphere", RES)
    yy, xx = np.mgrid[0:RES, 0:RES]
    r = np.hypot(xx - (RES - 1) / 2, yy - (RES - 1) / 2) / (RES / 2)
    rings = []
    for lo, hi in ((0.0, 0.5), (0.5, 0.8), (0.8, 1.0)):
        sel = mask & (r >= lo) & (r < hi)
        ratio = np.median(best[sel].sum(-1) / np.maximum(src[sel].sum(-1), 1e-12))
        rings.append(f"r {lo:.1f}-{hi:.1f}: {1 - smap[sel].mean():.3f} (AS/Ward {ratio:.2f})")
    return (
        f"probe fit {1 - m_fit:.4f}; L2 floor {1 - m_best:.4f}, SSIM floor {search.fun:.4f}\n{'':<17}"
        "L2 floor by ring: " + ", ".join(rings)
    )


def main() -> None:
    with tempfile.TemporaryDirectory() as t:
        tmp = Path(t)
        print(f"Ward -> AS, mean 1-SSIM over {len(ROTATIONS)} rotations, {RES}^2, {LIGHTS} lights (builtin env)")
        print(f"{'example':<16} {'remapped':>9} {'naive':>9} {'remapped, specular only':>24}")
        for ex in EXAMPLES:
            full, spec = remapped(ex, tmp)
            print(f"{ex:<16} {full:9.4f} {naive(ex, tmp):9.4f} {spec:24.4f}")
        print(
            "\nuniform material at the median parameters, rotation 0; floors: AS fitted to the environment-lit "
            "Ward image itself"
        )
        for ex in EXAMPLES:
            print(f"{ex:<16} {floor(ex)}")


if __name__ == "__main__":
    main()
