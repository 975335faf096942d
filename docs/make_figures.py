"""Regenerate the pictures in docs/img (run from the repository root):

python docs/make_figures.py
"""

from __future__ import annotations

from pathlib import Path

from matremap.core.imageio import write_image
from matremap.core.material import parse_material
from matremap.core.scene import Scene
from matremap.uniform import comparison_strip, fit

OUT = Path(__file__).resolve().parent / "img"

FIGURES = {
    "fit-ward-to-as.png": (
        "mitsuba06:ward,variant=ward,alpha=0.3,specularReflectance=0.12,diffuseReflectance=0",
        "mitsuba06:pbr",
        {"distribution": "as"},
        [0.0],
    ),
    "fit-plastic-to-cycles.png": (
        "mitsuba06:roughplastic,alpha=0.2,diffuseReflectance=0.5:0.2:0.1",
        "cycles:glossy",
        {},
        [0.0],
    ),
    "fit-blender-to-ward-45.png": (
        "blender27:ward,specular_slope=0.15,specular_intensity=1,diffuse_color=0.4:0.5:0.6",
        "mitsuba06:ward",
        {},
        [45.0],
    ),
    "fit-conductor-to-ward.png": ("mitsuba06:roughconductor,distribution=ggx,alpha=0.25", "mitsuba06:ward", {}, [0.0]),
}


def main() -> None:
    OUT.mkdir(exist_ok=True)
    for name, (source, target, fix, lights) in FIGURES.items():
        result = fit(parse_material(source), target, fix=fix, scene=Scene.probe(lights, resolution=160))
        write_image(OUT / name, comparison_strip(result), force=True)
        print(f"{name}: loss {result.loss:.4f}, {result.renders} renders")


if __name__ == "__main__":
    main()
