"""Generate the example SVBRDF map sets in this folder (deterministic: fixed seeds).

    .venv/bin/python examples/make_examples.py [--size 256] [--out examples] [--force]

Three Mitsuba 0.6 Ward materials (``mitsuba06:ward``, variant ``ward``, the paper's source model),
each a folder with a ``material.json`` and four 8-bit PNG maps named by the conventions:

* ``*_diffuse.png``   diffuseReflectance, sRGB;
* ``*_specular.png``  specularReflectance (rho_s), sRGB;
* ``*_roughness.png`` alpha, linear grey (code / 255 = alpha);
* ``*_normal.png``    tangent-space normal map, linear ((n + 1) / 2).

``scratched-gold``  bright gold with fine scratches (rougher, darker grooves);
``blue-plastic``    blue diffuse base, grey low specular, blotchy roughness, small bumps;
``bronze``          hammered bronze with patches of green patina (rougher, less specular).

and one glTF 2.0 file (``brass-gltf/brass.gltf``, model ``gltf:metal-rough``) for ``matremap remap
FILE``: a hammered brass metal with a base-colour map (sRGB), the packed metallic-roughness map
(G = perceptual roughness, B = metallic = 1) and a normal map, as external PNGs.

Roughness stays in alpha 0.03..0.6 and rho_s mostly inside a Ward -> AS sweep's training domain
(rho_s 0.02..0.232) — except gold, whose red and green rho_s exceed 0.232 on purpose: converting
it with such a transform flags those texels in ``outside_domain.png``. Note that a transform
learned with the diffuse term held at 0 flags every texel with a non-zero diffuse map as well.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "src"))

from matremap.svbrdf.textures import ImageInfo, write_image_like  # noqa: E402

BUDGET = 1 << 20  # bytes for all example files together


def value_noise(rng: np.random.Generator, size: int, cells: int) -> np.ndarray:
    """Smooth noise in [0, 1]: a random grid of cells x cells, bicubic-ish (smoothstep) upsampled, tiling."""
    grid = rng.uniform(0, 1, (cells, cells))
    t = np.arange(size) * cells / size
    i0 = np.floor(t).astype(int)
    f = t - i0
    f = f * f * (3 - 2 * f)
    i1 = (i0 + 1) % cells
    rows = grid[i0] * (1 - f)[:, None] + grid[i1] * f[:, None]
    return rows[:, i0] * (1 - f)[None, :] + rows[:, i1] * f[None, :]


def fbm(rng: np.random.Generator, size: int, base: int = 4, octaves: int = 4) -> np.ndarray:
    out, amp, total = np.zeros((size, size)), 1.0, 0.0
    for o in range(octaves):
        cells = min(base << o, size)
        out += amp * value_noise(rng, size, cells)
        total += amp
        amp *= 0.5
    return out / total


def scratches(rng: np.random.Generator, size: int, count: int, width: float = 0.8) -> np.ndarray:
    """Straight fine scratches: 1 on a scratch, fading to 0 within ``width`` texels."""
    y, x = np.mgrid[0:size, 0:size].astype(float)
    out = np.zeros((size, size))
    for _ in range(count):
        angle = rng.normal(0.35, 0.25)  # mostly one brushing direction
        cx, cy = rng.uniform(0, size, 2)
        length = rng.uniform(0.2, 0.9) * size
        d = np.cos(angle) * (y - cy) - np.sin(angle) * (x - cx)  # distance across the scratch
        along = np.cos(angle) * (x - cx) + np.sin(angle) * (y - cy)
        depth = rng.uniform(0.4, 1.0)
        s = depth * np.clip(1 - np.abs(d) / width, 0, 1) * (np.abs(along) < length / 2)
        out = np.maximum(out, s)
    return out


def dimples(rng: np.random.Generator, size: int, count: int, radius: tuple[float, float]) -> np.ndarray:
    """Height field of round dents (hammer marks, bumps), tiling."""
    y, x = np.mgrid[0:size, 0:size].astype(float)
    h = np.zeros((size, size))
    for _ in range(count):
        cx, cy = rng.uniform(0, size, 2)
        r = rng.uniform(*radius)
        dx = (x - cx + size / 2) % size - size / 2
        dy = (y - cy + size / 2) % size - size / 2
        q = (dx * dx + dy * dy) / (r * r)
        h = np.minimum(h, -np.where(q < 1, (1 - q) ** 2, 0.0))
    return h


def normal_map(height: np.ndarray, strength: float) -> np.ndarray:
    """Tangent-space normals of a height field (texel units), encoded (n + 1) / 2."""
    gy, gx = np.gradient(height)
    n = np.stack([-gx * strength, -gy * strength, np.ones_like(height)], axis=-1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    return (n + 1) / 2


def scratched_gold(size: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(20190401)
    s = scratches(rng, size, 70)
    n = fbm(rng, size, 4, 3)
    gold = np.array([0.30, 0.215, 0.075])  # rho_s: red and green beyond a 0.232 training domain
    spec = gold * (0.85 + 0.15 * n)[..., None] * (1 - 0.55 * s)[..., None]
    diffuse = np.broadcast_to(np.array([0.03, 0.02, 0.005]), (size, size, 3)) * (1 + 0.2 * n)[..., None]
    alpha = 0.07 + 0.03 * n + 0.22 * s
    return {"diffuse": diffuse, "specular": spec, "roughness": alpha, "normal": normal_map(-s, 1.2)}


def blue_plastic(size: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(20190402)
    n = fbm(rng, size, 4, 4)
    blotch = np.clip((fbm(rng, size, 3, 3) - 0.45) * 4, 0, 1)
    diffuse = np.array([0.03, 0.09, 0.45]) * (0.9 + 0.2 * n)[..., None]
    spec = np.broadcast_to((0.045 - 0.015 * blotch)[..., None], (size, size, 3))
    alpha = 0.12 + 0.05 * n + 0.2 * blotch
    h = dimples(rng, size, 220, (2.0, 5.0)) * 0.6
    return {"diffuse": diffuse, "specular": spec, "roughness": alpha, "normal": normal_map(h, 0.8)}


def bronze(size: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(20190403)
    n = fbm(rng, size, 4, 4)
    patina = np.clip((fbm(rng, size, 3, 4) - 0.5) * 5, 0, 1)[..., None]
    metal_d = np.array([0.06, 0.035, 0.015])
    patina_d = np.array([0.12, 0.30, 0.22])
    diffuse = (metal_d * (1 - patina) + patina_d * patina) * (0.85 + 0.3 * n)[..., None]
    metal_s = np.array([0.21, 0.13, 0.06])
    spec = metal_s * (1 - 0.8 * patina) * (0.9 + 0.1 * n)[..., None] + 0.02 * patina
    alpha = 0.18 + 0.1 * n + 0.3 * patina[..., 0]
    h = dimples(rng, size, 60, (8.0, 20.0)) * 3.0
    return {"diffuse": diffuse, "specular": spec, "roughness": alpha, "normal": normal_map(h, 0.6)}


MATERIALS = {
    "scratched-gold": ("gold", scratched_gold),
    "blue-plastic": ("plastic", blue_plastic),
    "bronze": ("bronze", bronze),
}


def write_set(folder: Path, prefix: str, maps: dict[str, np.ndarray], force: bool) -> list[Path]:
    import json

    folder.mkdir(parents=True, exist_ok=True)
    size = maps["roughness"].shape[0]
    written = []
    cs = {"diffuse": "srgb", "specular": "srgb", "roughness": "linear", "normal": "linear"}
    for role, a in maps.items():
        a = np.asarray(a, dtype=np.float32)
        channels = 1 if a.ndim == 2 else a.shape[-1]
        info = ImageInfo("png", "uint8", channels, size, size, cs[role])
        written.append(write_image_like(folder / f"{prefix}_{role}.png", a, info, force=force))
    manifest = {
        "model": "mitsuba06:ward",
        "maps": {
            "diffuseReflectance": f"{prefix}_diffuse.png",
            "specularReflectance": f"{prefix}_specular.png",
            "alpha": f"{prefix}_roughness.png",
        },
        "normal": f"{prefix}_normal.png",
        "params": {"variant": "ward"},
        "colorspace": {
            f"{prefix}_diffuse.png": "srgb",
            f"{prefix}_specular.png": "srgb",
            f"{prefix}_roughness.png": "linear",
        },
    }
    m = folder / "material.json"
    if m.exists() and not force:
        raise SystemExit(f"{m} exists; pass --force to regenerate")
    m.write_text(json.dumps(manifest, indent=1) + "\n")
    written.append(m)
    return written


def brass(size: int) -> dict[str, np.ndarray]:
    """A glTF metal: base colour (F0 of brass, worn), perceptual roughness, normal map."""
    rng = np.random.default_rng(20190404)
    n = fbm(rng, size, 4, 4)
    wear = np.clip((fbm(rng, size, 3, 3) - 0.4) * 3, 0, 1)
    base = np.array([0.91, 0.78, 0.42]) * (0.92 + 0.08 * n)[..., None] * (1 - 0.15 * wear)[..., None]
    roughness = 0.3 + 0.15 * n + 0.25 * wear
    h = dimples(rng, size, 80, (6.0, 14.0)) * 2.0
    return {"base": base, "roughness": roughness, "normal": normal_map(h, 0.6)}


def write_gltf(folder: Path, maps: dict[str, np.ndarray], force: bool) -> list[Path]:
    """One glTF 2.0 material (no mesh: matremap reads materials) with its three PNG textures."""
    import json

    folder.mkdir(parents=True, exist_ok=True)
    size = maps["roughness"].shape[0]
    mr = np.stack([np.zeros((size, size)), maps["roughness"], np.ones((size, size))], axis=-1)
    images = {
        "brass_basecolor.png": (maps["base"], "srgb"),
        "brass_metalrough.png": (mr, "linear"),
        "brass_normal.png": (maps["normal"], "linear"),
    }
    written = []
    for name, (a, cs) in images.items():
        info = ImageInfo("png", "uint8", 3, size, size, cs)
        written.append(write_image_like(folder / name, np.asarray(a, dtype=np.float32), info, force=force))
    doc = {
        "asset": {"version": "2.0", "generator": "matremap examples/make_examples.py"},
        "images": [{"uri": n} for n in images],
        "textures": [{"source": i} for i in range(len(images))],
        "materials": [
            {
                "name": "brass",
                "normalTexture": {"index": 2},
                "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}, "metallicRoughnessTexture": {"index": 1}},
            }
        ],
    }
    path = folder / "brass.gltf"
    if path.exists() and not force:
        raise SystemExit(f"{path} exists; pass --force to regenerate")
    path.write_text(json.dumps(doc, indent=1) + "\n")
    written.append(path)
    return written


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=256, help="texels per side (default 256)")
    ap.add_argument("--out", type=Path, default=HERE, help="folder for the map sets (default: examples/)")
    ap.add_argument("--force", action="store_true", help="overwrite existing files")
    args = ap.parse_args(argv)
    total = 0
    for name, (prefix, make) in MATERIALS.items():
        maps = make(args.size)
        files = write_set(args.out / name, prefix, maps, args.force)
        size = sum(f.stat().st_size for f in files)
        total += size
        a, s = maps["roughness"], maps["specular"]
        print(
            f"{name:15s} {size / 1024:7.1f} KiB  alpha {a.min():.3f}..{a.max():.3f}  rho_s {s.min():.3f}..{s.max():.3f}"
        )
    maps = brass(args.size)
    files = write_gltf(args.out / "brass-gltf", maps, args.force)
    size = sum(f.stat().st_size for f in files)
    total += size
    print(
        f"{'brass-gltf':15s} {size / 1024:7.1f} KiB  roughness {maps['roughness'].min():.3f}.."
        f"{maps['roughness'].max():.3f} (glTF, alpha = roughness^2)"
    )
    print(f"total {total / 1024:.1f} KiB (budget {BUDGET / 1024:.0f} KiB)")
    if total > BUDGET:
        print("over budget: use a smaller --size", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
