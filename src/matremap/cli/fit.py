"""Uniform materials: ``render`` (a material on the probe sphere), ``fit`` (remap one material onto
another model) and ``apply`` (run a learned transform on one material)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from matremap.cli.common import (
    Subparsers,
    add_command,
    add_fix_option,
    add_force_option,
    add_free_option,
    add_objective_option,
    add_renderer_options,
    add_scene_args,
    add_strategy_option,
    add_target_option,
    load_material,
    make_scene,
    parse_assignments,
)
from matremap.core.material import Material
from matremap.core.scene import Scene
from matremap.dialects import get_model
from matremap.errors import MatremapError, QualityGateFailed

RENDER_EXAMPLES = """examples:
  matremap render 'mitsuba06:ward,alpha=0.2,specularReflectance=0.1' -o ward.exr
  matremap render material.json -o sphere.png --light 45 --size 256 --part specular
  matremap render 'mitsuba3:roughplastic,alpha=0.1' --renderer mitsuba3 -o plastic.exr"""

FIT_EXAMPLES = """examples:
  matremap fit --source mitsuba06:ward,variant=ward,alpha=0.3,specularReflectance=0.12,diffuseReflectance=0 \\
      --to mitsuba06:pbr --fix distribution=as
  matremap fit --source ward.json --to cycles:glossy --strategy three-stage --light 0 45 --json
  matremap fit --source mitsuba06:roughconductor,distribution=as,alpha=0.2 --to mitsuba06:ward \\
      --compare strip.png     (source | target | difference x10, labelled)
  matremap fit --source ward.json --to mitsuba06:pbr --fix distribution=as --probe env --objective ssim
      (fitted under the built-in environment, for the look SSIM judges there)"""

APPLY_EXAMPLES = """examples:
  matremap apply ward2as.json --source mitsuba06:ward,variant=ward,alpha=0.3,specularReflectance=0.12"""

#: image files ``fit --compare`` writes
COMPARE_SUFFIXES = (".png", ".exr", ".tif", ".tiff")


def add_render(subparsers: Subparsers) -> None:
    """The ``render`` command."""
    p = add_command(subparsers, "render", "render a material on the probe sphere", RENDER_EXAMPLES)
    p.add_argument("material", metavar="MATERIAL", help="JSON file, inline JSON, or MODEL,name=value,...")
    p.add_argument(
        "-o",
        "--output",
        required=True,
        metavar="FILE",
        help="image file: .exr (linear float), .png (sRGB 8-bit), .npy, .tif, .hdr",
    )
    p.add_argument(
        "--part",
        choices=("full", "diffuse", "specular"),
        default="full",
        help="draw the whole material or only its diffuse or specular lobe (default %(default)s)",
    )
    p.add_argument(
        "--renderer",
        default="embedded",
        metavar="NAME",
        help="embedded, mitsuba3 or cycles (default %(default)s; see `matremap renderers`)",
    )
    add_force_option(p, "overwrite an existing output file")
    add_scene_args(p)
    p.set_defaults(func=cmd_render)


def cmd_render(args: argparse.Namespace) -> int:
    """Render one material (or its diffuse or specular part) and write the image."""
    from matremap.core.fit import part
    from matremap.core.imageio import IMAGE_SUFFIXES, check_output, write_image
    from matremap.renderers import get_renderer
    from matremap.renderers.base import render_images

    material = load_material(args.material)
    scene = make_scene(args)
    out = check_output(args.output, args.force, IMAGE_SUFFIXES)
    renderer = get_renderer(args.renderer)
    shown = part(material, args.part)
    if shown is None:
        raise MatremapError(f"{material.model} has no {args.part} part to render")
    image = render_images(renderer, [shown], scene)[0]
    write_image(out, image, force=args.force)
    views = f", {scene.view_count} views side by side" if scene.view_count > 1 else ""
    print(f"wrote {out} ({scene.resolution}x{scene.resolution}{views}, {material.model}, {args.part})", file=sys.stderr)
    return 0


def add_fit(subparsers: Subparsers) -> None:
    """The ``fit`` command."""
    p = add_command(subparsers, "fit", "remap a uniform material onto a target model", FIT_EXAMPLES)
    p.add_argument(
        "--source", required=True, metavar="MATERIAL", help="JSON file, inline JSON, or MODEL,name=value,..."
    )
    add_target_option(p)
    add_fix_option(p, "set a target option or hold a parameter (repeatable), e.g. distribution=as")
    add_free_option(p, "also fit a parameter that is held by default (repeatable)")
    add_strategy_option(p)
    add_objective_option(p)
    add_renderer_options(p)
    p.add_argument(
        "--max-error",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="a quality-gate threshold (repeatable): fit_error, luminance_error, delta_e, delta_e_fraction "
        "(the measures of a uniform remap); see docs/quality.md",
    )
    p.add_argument("--json", action="store_true", help="print the result as one JSON object on stdout")
    p.add_argument("-o", "--output", metavar="FILE.json", help="also save the result as JSON")
    p.add_argument(
        "--compare",
        metavar="FILE.png",
        help="write the probe renders source | target | difference x10 side by side: .png (sRGB, labelled), "
        ".exr (linear, unlabelled)",
    )
    add_force_option(p, "overwrite existing output files")
    add_scene_args(p)
    p.set_defaults(func=cmd_fit)


def cmd_fit(args: argparse.Namespace) -> int:
    """Fit the target model to the source material as a uniform remap does (:mod:`matremap.uniform_remap`: the
    same held values, the anisotropic probe, the same verdict); print (or save) the result, write the comparison;
    exit 3 when the fit fails the quality gate (the result is printed and written all the same)."""
    from matremap import uniform_remap
    from matremap.core.imageio import check_output
    from matremap.dialects.mtlx import freed_layers
    from matremap.svbrdf.quality import Thresholds
    from matremap.uniform import fit

    source = load_material(args.source)
    spec = get_model(args.target)
    fix = parse_assignments(args.fix, "--fix")
    for name in fix:
        if name not in spec.param_names and name not in spec.option_names:
            spec.param(name)  # raises with the list of valid names
    thresholds = Thresholds.parse(args.max_error)
    out = check_output(args.output, args.force, (".json",)) if args.output else None
    compare = check_output(args.compare, args.force, COMPARE_SUFFIXES) if args.compare else None

    def note(line: str) -> None:
        print(f"matremap: note: {line}", file=sys.stderr)

    held = uniform_remap.choose_held(source, spec.id, fix, note)
    chosen = {k: v for k, v in held.fix.items() if k not in fix and k not in args.free}
    if chosen:
        note(
            "held for this source: "
            + ", ".join(f"{k} = {v:g}" for k, v in chosen.items())
            + " (as remap holds them; --fix NAME=VALUE to choose)"
        )
    layers, start = freed_layers(source.model, source.values, spec, held=fix)
    free = list(dict.fromkeys([*args.free, *layers, *held.start]))
    scene = make_scene(args)
    if not args.light and args.probe == "point":
        lights = uniform_remap.anisotropic_lights(source.model, spec.id, args.free)
        if lights is not None:
            note(f"two roughnesses are fitted: under lights at {lights} degrees (--light to choose)")
            scene = Scene.probe(lights, args.size or scene.resolution)
    result = fit(
        source,
        spec,
        strategy=held.strategy or args.strategy,
        scene=scene,
        source_renderer=args.source_renderer,
        target_renderer=args.target_renderer,
        fix={**fix, **chosen},
        free=free,
        start={**start, **held.start} or None,
        objective=args.objective,
    )
    verdict = uniform_remap.fit_verdict(result, thresholds)
    record = {**result.to_dict(), "verdict": verdict.to_dict()}
    for w in result.warnings:
        print(f"matremap: warning: {w}", file=sys.stderr)
    if compare is not None:
        from matremap.core.imageio import write_image
        from matremap.uniform import comparison_strip

        # a picture to look at is labelled; an EXR keeps the measured values, unlabelled
        labels = Path(compare).suffix.lower() != ".exr"
        write_image(compare, comparison_strip(result, labels=labels), force=args.force)
    if out is not None:
        from matremap.core.imageio import write_text

        write_text(out, json.dumps(record, indent=2) + "\n")
    if args.json:
        print(json.dumps(record))
    else:
        print_fit(record)
    if not verdict.passed:
        raise QualityGateFailed(verdict.line())
    return 0


def print_fit(r: dict[str, Any]) -> None:
    """A fit record (:meth:`FitResult.to_dict`) as a short table."""
    objective = r.get("objective", "l2")
    probe = Scene.from_dict(r["scene"]).describe() if "scene" in r else "point probe"
    print(
        f"{r['source']['model']} -> {r['model']}  ({r['strategy']}, {r['renderers']['source']} -> "
        f"{r['renderers']['target']}; {probe})"
    )
    for k, v in r["params"].items():
        v = (
            f"{v:.6g}"
            if isinstance(v, float)
            else ("[" + ", ".join(f"{x:.6g}" for x in v) + "]" if isinstance(v, list) else v)
        )
        print(f"  {k} = {v}")
    measure = {"l2": "relative RMSE", "log": "RMS log difference", "ssim": "mean 1 - SSIM"}.get(objective, objective)
    print(
        f"loss ({measure}) {r['loss']:.4g}   renders {r['renders']}   {r['seconds'] * 1000:.1f} ms"
        + (f"   irradiance scale {r['irradiance_scale']:.4g}" if r["irradiance_scale"] != 1.0 else "")
        + (f"   relative RMSE {r['relative_rmse']:.4g}" if objective != "l2" else "")
    )
    for s in r["stages"]:
        print(f"  stage {s['name']}: loss {s['loss']:.4g}, {s['renders']} renders, {s['message']}")
    if "verdict" in r:
        print(r["verdict"]["line"])


def add_apply(subparsers: Subparsers) -> None:
    """The ``apply`` command."""
    p = add_command(subparsers, "apply", "apply a transform to a uniform material", APPLY_EXAMPLES)
    p.add_argument("transform", metavar="T.json", help="a transform file (from `matremap learn` or `chain`)")
    p.add_argument(
        "--source", required=True, metavar="MATERIAL", help="JSON file, inline JSON, or MODEL,name=value,..."
    )
    p.add_argument("--json", action="store_true", help="print the target material as one JSON object")
    p.set_defaults(func=cmd_apply)


def cmd_apply(args: argparse.Namespace) -> int:
    """Map one material through a transform file; warn when it lies outside the training domain."""
    from matremap.regress.quantities import material_values
    from matremap.regress.transform import Transform

    t = Transform.load(args.transform)
    source = load_material(args.source)
    if source.model != t.source:
        raise MatremapError(f"the transform maps {t.source}, not {source.model}")
    values, outside = t.apply(material_values(source))
    params = {k: (v.tolist() if np.ndim(v) else float(v)) for k, v in values.items()}
    target = Material.create(t.target, {**t.target_options, **params})
    record = {**target.to_dict(), "outside_domain": bool(outside)}
    if args.json:
        print(json.dumps(record))
    else:
        print(f"{t.describe()}: {json.dumps(record['params'])}")
        if outside:
            print("warning: the source lies outside the transform's training domain", file=sys.stderr)
    return 0


#: command name -> the function adding its parser
PARSERS = {"render": add_render, "fit": add_fit, "apply": add_apply}
