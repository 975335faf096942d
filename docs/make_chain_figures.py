"""The paper's cross-renderer chains on an example SVBRDF (run from the repository root, ~2 minutes;
needs the Cycles worker venv, see docs/cycles.md):

    python docs/make_chain_figures.py

1. Blender Internal Ward -> Mitsuba 0.6 Ward -> Mitsuba 0.6 GGX conductor -> real Cycles Glossy GGX;
2. Mitsuba AS (the authors' pbr plugin) -> real Cycles Glossy GGX.

Each hop is learned from a sweep over the values the maps hold (the last hop with real Cycles in the
loop), the hops are chained into one transform, the chain is applied to the original maps, and the
result is compared with the source under the built-in environment (SSIM).
"""

from __future__ import annotations

import json
import shutil
import tempfile
import warnings
from pathlib import Path

import numpy as np

from matremap.core.envmap import resolve
from matremap.core.imageio import write_image
from matremap.regress.transform import Transform
from matremap.remap import load_arrays, remap
from matremap.svbrdf.convert import convert
from matremap.svbrdf.evaluate import evaluate
from matremap.svbrdf.textures import load_map_set

ROOT = Path(__file__).resolve().parents[1]
IMG = ROOT / "docs" / "img" / "chain"
ROTATIONS = [0.0, 90.0, 180.0, 270.0]


def blender_version_of(example: Path, out: Path) -> Path:
    """The example re-authored for Blender Internal as a metal (no diffuse, as the conductor hops
    require): same specular colours, rms slope = Ward alpha (<= 0.4)."""
    ward = load_map_set(example)
    p, _ = load_arrays(ward)
    out.mkdir(parents=True)
    write_image(out / "specular.exr", np.asarray(p["specularReflectance"], np.float32))
    slope = np.clip(np.asarray(p["alpha"], np.float32), 0.02, 0.4)
    write_image(out / "roughness.exr", np.repeat(slope[..., None], 3, axis=-1))
    shutil.copy(ward.normal, out / "normal.png")
    (out / "material.json").write_text(
        json.dumps(
            {
                "model": "blender27:ward",
                "maps": {"specular_color": "specular.exr", "specular_slope": "roughness.exr"},
                "normal": "normal.png",
                "params": {"diffuse_intensity": 0.0, "diffuse_color": 0.0, "specular_intensity": 1.0},
            },
            indent=1,
        )
    )
    return out


def chain(label: str, start: Path, hops: list[tuple[str, dict, str]], work: Path, cache: Path) -> dict:
    maps, transforms = start, []
    for i, (target, fix, renderer) in enumerate(hops):
        out = work / f"{label}-hop{i + 1}"
        r = remap(
            maps,
            None,
            target,
            out,
            fix=fix,
            cache=cache,
            evaluate=False,
            target_renderer=renderer,
            log=lambda m, hop=i + 1: print(f"  [{label} hop {hop}] {m}"),
        )
        transforms.append(Transform.load(r.transform))
        maps = r.maps
    chained = Transform.chain(transforms) if len(transforms) > 1 else transforms[0]
    final = work / f"{label}-chained"
    with warnings.catch_warnings():  # the outside count is printed below
        warnings.simplefilter("ignore", UserWarning)
        report = convert(load_map_set(start), [chained], final)
    src, tgt = load_map_set(start), load_map_set(final)
    (sp, sn), (tp, tn) = load_arrays(src), load_arrays(tgt)
    result = evaluate(
        (src.model, sp, src.options, sn),
        (tgt.model, tp, tgt.options, tn),
        resolve("builtin"),
        ROTATIONS,
        work / f"{label}-evaluation",
        resolution=160,
        lights=256,
        title=chained.describe(),
    )
    for name in ("r000_full_source", "r000_full_target", "r000_full_dssim", "dssim_vs_rotation"):
        shutil.copy(work / f"{label}-evaluation" / "images" / f"{name}.png", IMG / f"{label}-{name}.png")
    print(
        f"{label}: {chained.describe()}: outside {report.outside}/{report.texels}, mean 1-SSIM "
        f"{result.mean_full:.4f} (specular {result.mean_specular:.4f})"
    )
    return {"chain": chained.describe(), "mean_dssim": result.mean_full, "specular": result.mean_specular}


def main() -> None:
    IMG.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        work, cache = Path(tmp), Path(tmp) / "cache"
        example = ROOT / "examples" / "bronze"
        bi = blender_version_of(example, work / "bronze-blender27")
        results = {
            "blender27-to-cycles": chain(
                "blender27-to-cycles",
                bi,
                [
                    ("mitsuba06:ward", {"variant": "ward"}, "embedded"),
                    ("mitsuba06:roughconductor", {"distribution": "ggx"}, "embedded"),
                    ("cycles:glossy", {"distribution": "ggx"}, "cycles"),
                ],
                work,
                cache,
            ),
        }
        as_maps = remap(
            example,
            None,
            "mitsuba06:pbr",
            work / "bronze-as",
            fix={"distribution": "as"},
            cache=cache,
            evaluate=False,
            log=lambda m: None,
        ).maps
        results["as-to-cycles"] = chain(
            "as-to-cycles",
            as_maps,
            [
                ("cycles:glossy", {"distribution": "ggx"}, "cycles"),
            ],
            work,
            cache,
        )
        (IMG / "results.json").write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
