"""The ``matremap`` command.

Subcommands are verbs: ``models`` lists the reflectance models, ``render`` draws a material on
the probe sphere, ``fit`` remaps a uniform material onto another model. Errors print one line on
stderr and exit with status 2; nothing is written when a command fails.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from matremap import __version__
from matremap.core.models import Material, get_model, list_models, parse_material
from matremap.core.scene import Scene, parse_lights
from matremap.errors import MatremapError

EXAMPLES = {
    "fit": """examples:
  matremap fit --source '{"model": "mitsuba06:ward", "params": {"variant": "ward", "alpha": 0.3,
      "specularReflectance": 0.12, "diffuseReflectance": 0}}' --target mitsuba06:pbr --fix distribution=as
  matremap fit --source ward.json --target cycles:glossy --strategy three-stage --light 0 45 --json
  matremap fit --source mitsuba06:roughconductor,distribution=as,alpha=0.2 --target mitsuba06:ward""",
    "render": """examples:
  matremap render 'mitsuba06:ward,alpha=0.2,specularReflectance=0.1' -o ward.exr
  matremap render material.json -o sphere.png --light 45 --size 256 --part specular""",
    "sweep": """examples:
  matremap sweep --source mitsuba06:ward,variant=ward,diffuseReflectance=0 --target mitsuba06:pbr \\
      --fix distribution=as --grid "alpha=0.005:0.99:35,specularReflectance=0.02:0.232:23" --db ward2as.sqlite
  matremap sweep --source mitsuba06:roughconductor,distribution=as --target mitsuba06:ward \\
      --grid grid.toml --db as2ward.sqlite --round-trip --dask-local 2
  (run the same command again to resume; Ctrl-C stops cleanly)""",
    "sweep-report": """examples:
  matremap sweep-report ward2as.sqlite -o report/""",
    "export": """examples:
  matremap export ward2as.sqlite -o ward2as.csv
  matremap export ward2as.sqlite -o ward2as.parquet   (needs pyarrow)""",
    "learn": """examples:
  matremap learn ward2as.sqlite -o ward2as.json
  matremap learn ward2as.sqlite --reverse -o as2ward.json
  matremap learn ward2as.sqlite --method svr -o ward2as-svr.json""",
    "chain": """examples:
  matremap chain blender2ward.json ward2ggx.json -o blender2ggx.json""",
    "apply": """examples:
  matremap apply ward2as.json --source mitsuba06:ward,variant=ward,alpha=0.3,specularReflectance=0.12""",
    "convert": """examples:
  matremap convert examples/bronze --transform ward2as.json -o out/bronze-as
  matremap convert maps/ --model mitsuba06:ward --transform a.json --transform b.json -o out/
  matremap convert examples/bronze --to cycles:glossy --fix distribution=ggx -o out/  (fails: bronze is
      variant=ward, the library's Ward transforms are trained on variant=balanced)""",
    "evaluate": """examples:
  matremap evaluate examples/bronze out/bronze-as --envmap builtin --rotations 0:360:12 -o out/eval""",
    "remap": """examples:
  matremap remap examples/blue-plastic --from mitsuba06:ward --to mitsuba06:pbr --fix distribution=as -o out/plastic
  (a second run reuses the cached transform)
  matremap remap helmet.glb --to mitsuba3:roughconductor -o out/helmet      (writes out/helmet/helmet.xml)
  matremap remap scene.xml --material gold --to gltf:metal-rough -o out/gold  (writes out/gold/scene.gltf)""",
    "transforms": """examples:
  matremap transforms
  matremap transforms --route blender27:ward cycles:glossy --fix distribution=ggx""",
    "models": """examples:
  matremap models
  matremap models mitsuba06:roughconductor
  matremap models --json""",
}


def load_material(arg: str) -> Material:
    """A material from a JSON file path, inline JSON, or the compact form MODEL,name=value,..."""
    text = arg.strip()
    looks_like_file = text.endswith(".json") or os.sep in text and not text.startswith("{")
    if looks_like_file or (Path(text).is_file() and not text.startswith("{")):
        from matremap.core.documents import read_document

        return Material.from_dict(read_document(text, "material file"), where=text)
    return parse_material(text)


def parse_assignments(items: Sequence[str], flag: str) -> dict[str, str]:
    out: dict[str, str] = {}
    for item in items:
        if "=" not in item:
            raise MatremapError(f"{flag} takes NAME=VALUE, got {item!r}")
        k, v = item.split("=", 1)
        out[k.strip()] = v.strip()
    return out


def make_scene(args: argparse.Namespace) -> Scene:
    return Scene.probe(lights=parse_lights(args.light), resolution=args.size)


# ---------------------------------------------------------------------------------------------
def cmd_models(args: argparse.Namespace) -> int:
    specs = [get_model(args.model)] if args.model else list_models()
    if args.json:
        print(json.dumps([s.to_dict() for s in specs], indent=2))
        return 0
    if not args.model:
        width = max(len(s.id) for s in specs)
        for s in specs:
            opts = "".join(f" [{o.name}: {'|'.join(o.choices)}]" for o in s.options)
            print(f"{s.id:<{width}}  {', '.join(s.param_names)}{opts}")
            if s.summary:
                print(f"{'':<{width}}    {s.summary}")
        return 0
    s = specs[0]
    print(f"{s.id}: {s.summary}")
    for o in s.options:
        print(f"  option {o.name}: {' | '.join(o.choices)} (default {o.default})")
    for p in s.params:
        default = p.default if not isinstance(p.default, tuple) else list(p.default)
        held = "" if p.fit else f", held at {p.fit_value if p.fit_value is not None else default} in fits"
        kind = "RGB" if p.channels == 3 else "scalar"
        print(f"  {p.name}: {kind} {p.role} in [{p.bounds[0]:g}, {p.bounds[1]:g}], default {default}{held}")
        if p.doc:
            print(f"      {p.doc}")
    return 0


def cmd_renderers(args: argparse.Namespace) -> int:
    from matremap.renderers import get_renderer, renderer_names

    rows = []
    for name in renderer_names():
        try:
            r = get_renderer(name)
        except MatremapError as e:
            rows.append({"name": name, "available": False, "reason": str(e), "models": []})
            continue
        models = [m.id for m in list_models() if r.supports(m.id)]
        rows.append(
            {"name": name, "available": True, "details": repr(r) if name != "embedded" else "numpy", "models": models}
        )
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    for row in rows:
        if row["available"]:
            print(f"{row['name']}: {row['details']}; models {', '.join(row['models'])}")
        else:
            print(f"{row['name']}: not available ({row['reason']})")
    return 0


def cmd_render(args: argparse.Namespace) -> int:
    from matremap.core.fit import part
    from matremap.core.imageio import IMAGE_SUFFIXES, check_output, write_image
    from matremap.renderers import get_renderer

    material = load_material(args.material)
    scene = make_scene(args)
    out = check_output(args.output, args.force, IMAGE_SUFFIXES)
    renderer = get_renderer(args.renderer)
    shown = part(material, args.part)
    if shown is None:
        raise MatremapError(f"{material.model} has no {args.part} part to render")
    image = renderer.render([shown], scene)[0]
    write_image(out, image, force=args.force)
    print(f"wrote {out} ({scene.resolution}x{scene.resolution}, {material.model}, {args.part})", file=sys.stderr)
    return 0


def cmd_fit(args: argparse.Namespace) -> int:
    from matremap.core.fit import fit

    source = load_material(args.source)
    spec = get_model(args.target)
    fix = parse_assignments(args.fix, "--fix")
    for name in fix:
        if name not in spec.param_names and name not in spec.option_names:
            spec.param(name)  # raises with the list of valid names
    out = None
    if args.output:
        from matremap.core.imageio import check_output

        out = check_output(args.output, args.force, (".json",))
    compare = None
    if args.compare:
        from matremap.core.imageio import check_output

        compare = check_output(args.compare, args.force, (".png", ".exr", ".tif", ".tiff"))
    result = fit(
        source,
        spec,
        strategy=args.strategy,
        scene=make_scene(args),
        source_renderer=args.source_renderer,
        target_renderer=args.target_renderer,
        fix=fix,
        free=args.free,
    )
    record = result.to_dict()
    for w in result.warnings:
        print(f"matremap: warning: {w}", file=sys.stderr)
    if compare is not None:
        from matremap.core.compare import comparison_strip
        from matremap.core.imageio import write_image

        write_image(compare, comparison_strip(result), force=args.force)
    if out is not None:
        from matremap.core.imageio import write_text

        write_text(out, json.dumps(record, indent=2) + "\n")
    if args.json:
        print(json.dumps(record))
    else:
        _print_fit(record)
    return 0


def _print_fit(r: dict[str, Any]) -> None:
    print(
        f"{r['source']['model']} -> {r['model']}  ({r['strategy']}, {r['renderers']['source']} -> "
        f"{r['renderers']['target']})"
    )
    for k, v in r["params"].items():
        v = (
            f"{v:.6g}"
            if isinstance(v, float)
            else ("[" + ", ".join(f"{x:.6g}" for x in v) + "]" if isinstance(v, list) else v)
        )
        print(f"  {k} = {v}")
    print(
        f"loss (relative RMSE) {r['loss']:.4g}   renders {r['renders']}   {r['seconds'] * 1000:.1f} ms"
        + (f"   irradiance scale {r['irradiance_scale']:.4g}" if r["irradiance_scale"] != 1.0 else "")
    )
    for s in r["stages"]:
        print(f"  stage {s['name']}: loss {s['loss']:.4g}, {s['renders']} renders, {s['message']}")


def cmd_sweep(args: argparse.Namespace) -> int:
    from matremap.sweep.executors import make_executor
    from matremap.sweep.grid import parse_grid
    from matremap.sweep.run import SweepConfig, check_grid_for, describe, run_sweep

    source = load_material(args.source)
    config = SweepConfig(
        source=source,
        target=get_model(args.target).id,
        fix=parse_assignments(args.fix, "--fix"),
        free=tuple(args.free),
        strategy=args.strategy,
        scene=make_scene(args),
        source_renderer=args.source_renderer,
        target_renderer=args.target_renderer,
        continuation=args.continuation,
        round_trip=args.round_trip,
    )
    grid = parse_grid(args.grid, source.spec)
    check_grid_for(config, grid)
    db = Path(args.db)
    if db.suffix.lower() not in (".sqlite", ".sqlite3", ".db"):
        raise MatremapError(f"--db {db}: use a .sqlite (or .db) file name")
    if not db.parent.is_dir():
        raise MatremapError(f"cannot create {db}: folder {db.parent} does not exist")
    with make_executor(args.workers, args.scheduler, args.dask_local) as (executor, desc):
        slots = getattr(executor, "slots", 1)
        from tqdm import tqdm

        print(
            f"sweep {source.model} -> {config.target}: {len(grid)} points "
            f"({' x '.join(f'{a.label} {len(a.values)}' for a in grid.axes)}) on {desc}",
            file=sys.stderr,
        )
        with tqdm(
            total=len(grid), unit="pt", disable=args.no_progress or None, dynamic_ncols=True, smoothing=0.1
        ) as bar:
            summary = run_sweep(
                config,
                grid,
                str(db),
                executor,
                progress=bar.update,
                executor_name=desc,
                on_start=lambda skipped: bar.update(skipped),
                in_flight=2 * slots,
            )
    print(describe(summary), file=sys.stderr)
    return 130 if summary.interrupted else 0


def cmd_sweep_report(args: argparse.Namespace) -> int:
    from matremap.sweep.report import write_report

    out = Path(args.output)
    if out.exists() and not out.is_dir():
        raise MatremapError(f"{out} exists and is not a folder")
    print(write_report(args.db, out, force=args.force))
    return 0


def cmd_export(args: argparse.Namespace) -> int:
    from matremap.core.imageio import check_output
    from matremap.sweep.report import export_table

    out = check_output(args.output, args.force, (".csv", ".parquet"))
    n = export_table(args.db, out)
    print(f"wrote {out} ({n} rows)", file=sys.stderr)
    return 0


def cmd_learn(args: argparse.Namespace) -> int:
    from matremap.core.imageio import check_output
    from matremap.regress.transform import learn_transform

    out = check_output(args.output, args.force, (".json",))
    t = learn_transform(
        args.db, method=args.method, reverse=args.reverse, holdout=args.holdout, exclude_flagged=not args.keep_flagged
    )
    t.save(out, force=args.force)
    print(
        f"wrote {out}: {t.describe()}, {t.provenance['used']} points "
        f"({t.provenance['excluded_flagged']} flagged points left out)",
        file=sys.stderr,
    )
    for name, e in t.errors.items():
        lo, hi = t.domain.get(name, (0.0, 0.0))
        held = e.get("heldout_rmse")
        held_text = f"held-out RMSE {held:.3g}" if held is not None else "not fitted (constant)"
        print(f"  {name}: {held_text}, training domain [{lo:.4g}, {hi:.4g}]", file=sys.stderr)
    return 0


def cmd_chain(args: argparse.Namespace) -> int:
    from matremap.core.imageio import check_output
    from matremap.regress.transform import Transform

    out = check_output(args.output, args.force, (".json",))
    chained = Transform.chain([Transform.load(p) for p in args.transforms])
    chained.save(out, force=args.force)
    print(f"wrote {out}: {chained.describe()}", file=sys.stderr)
    return 0


def cmd_apply(args: argparse.Namespace) -> int:
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


def cmd_convert(args: argparse.Namespace) -> int:
    from matremap.regress.transform import Transform
    from matremap.svbrdf.convert import convert
    from matremap.svbrdf.textures import load_map_set

    map_set = load_map_set(args.maps, args.model)
    if args.transform:
        if args.target:
            raise MatremapError("give either --transform files or --to MODEL (a route through the library), not both")
        transforms = [Transform.load(p) for p in args.transform]
    elif args.target:
        from matremap.regress.library import find_route
        from matremap.regress.quantities import diffuse_param
        from matremap.remap import complete_fix, load_arrays

        target = get_model(args.target).id
        # what decides the route: whether the source has a diffuse part, and its held values (metallic)
        spec = map_set.spec
        dp = diffuse_param(spec)
        params, _ = load_arrays(map_set, only={n for n, _, _ in spec.specialisations} | ({dp.name} if dp else set()))
        fix = complete_fix(map_set.model, {**map_set.constants, **params}, target, parse_assignments(args.fix, "--fix"))
        held = {n: params[n] for n, _, _ in map_set.spec.specialisations if n in params}
        found = find_route(map_set.model, map_set.options, target, fix, source_values=held)
        if found is None:
            raise MatremapError(
                f"no route from {map_set.model} to {target} in the transform library "
                f"(`matremap transforms` lists it); run `matremap remap` to sweep one"
            )
        print(f"matremap: route {found.describe()}", file=sys.stderr)
        transforms = [found.transform]
    else:
        raise MatremapError("name the transform(s) with --transform T.json, or a target model with --to MODEL")
    for note in map_set.notes:
        print(f"matremap: note: {note}", file=sys.stderr)
    import warnings

    with warnings.catch_warnings():  # reported below, in one line
        warnings.simplefilter("ignore", UserWarning)
        report = convert(
            map_set, transforms, args.output, workers=args.workers, force=args.force, out_format=args.format
        )
    for note in report.notes:
        print(f"matremap: note: {note}", file=sys.stderr)
    if report.outside:
        print(
            f"matremap: warning: {report.outside} of {report.texels} texels "
            f"({100 * report.outside_fraction:.2f}%) lie outside the transform's training domain; "
            f"see {Path(args.output) / 'outside_domain.png'}",
            file=sys.stderr,
        )
    print(f"wrote {args.output}: {report.model}, {report.texels} texels in {report.seconds:.2f} s", file=sys.stderr)
    return 0


def cmd_transforms(args: argparse.Namespace) -> int:
    from matremap.regress.library import find_route, listing

    if args.route:
        source, target = args.route
        fix = parse_assignments(args.fix, "--fix")
        found = find_route(
            get_model(source).id, parse_assignments(args.source_option, "--source-option"), get_model(target).id, fix
        )
        if found is None:
            raise MatremapError(f"no route from {source} to {target} in the library; `matremap remap` sweeps instead")
        print(found.describe())
        return 0
    rows = listing()
    if args.json:
        print(json.dumps(rows, indent=1))
        return 0
    print(f"{'name':<30} {'source -> target':<78} {'held-out RMSE (roughness, F0, diffuse)':<36}")
    for r in rows:
        errs = ", ".join(
            "-" if r["heldout_rmse"].get(q) is None else f"{r['heldout_rmse'][q]:.2g}"
            for q in ("roughness", "reflectance", "diffuse")
            if q in r["heldout_rmse"]
        )
        print(f"{r['name']:<30} {r['source'] + ' -> ' + r['target']:<78} {errs}")
        dom = ", ".join(f"{k} {lo:.3g}..{hi:.3g}" for k, (lo, hi) in r["domain"].items())
        rend = r["renderers"]
        how = (
            "embedded"
            if set(rend.values()) <= {"embedded"}
            else f"source {rend.get('source')}, target {rend.get('target')}"
        )
        print(f"{'':<30} trained on {dom} ({how})")
    return 0


def cmd_evaluate(args: argparse.Namespace) -> int:
    from matremap.core.envmap import resolve
    from matremap.remap import load_arrays
    from matremap.svbrdf.evaluate import evaluate, parse_rotations
    from matremap.svbrdf.textures import load_map_set

    rotations = parse_rotations(args.rotations)
    env = resolve(args.envmap)
    sets = [
        load_map_set(p, m) for p, m in ((args.source_maps, args.source_model), (args.target_maps, args.target_model))
    ]
    materials = []
    for ms in sets:
        params, normal = load_arrays(ms)
        materials.append((ms.model, params, ms.options, normal))
    result = evaluate(
        materials[0],
        materials[1],
        env,
        rotations,
        args.output,
        geometry=args.geometry,
        resolution=args.size,
        lights=args.lights,
        force=args.force,
    )
    print(
        f"mean 1-SSIM {result.mean_full:.4f} (specular only {result.mean_specular:.4f}) over "
        f"{len(rotations)} rotations; report {Path(args.output) / 'report.html'}"
    )
    return 0


def cmd_remap(args: argparse.Namespace) -> int:
    from matremap.formats import is_material_file
    from matremap.remap import remap, remap_file

    if is_material_file(args.maps):
        if args.source:
            raise MatremapError(f"{args.maps} names its own model; drop --from")
        fres = remap_file(
            args.maps,
            args.target,
            args.output,
            material=args.material,
            fix=parse_assignments(args.fix, "--fix"),
            write=args.write,
            force=args.force,
            log=lambda m: print(m, file=sys.stderr),
            strategy=args.strategy,
            envmap=args.envmap,
            rotations=args.rotations,
            resolution=args.size,
            lights=args.lights,
            workers=args.workers,
            cache=Path(args.cache) if args.cache else None,
            evaluate=not args.no_evaluate,
            target_renderer=args.target_renderer,
            library=not args.sweep,
        )
        print(
            f"done: {fres.source_model} -> {fres.target_model}"
            + (f", wrote {fres.file}" if fres.file else "")
            + (f", mean 1-SSIM {fres.remap.mean_dssim:.4f}" if fres.remap and fres.remap.mean_dssim is not None else "")
        )
        return 0
    if args.material is not None or args.write is not None:
        raise MatremapError("--material and --write apply to material files (.gltf, .glb, .mtlx, .xml)")
    result = remap(
        args.maps,
        args.source,
        args.target,
        args.output,
        fix=parse_assignments(args.fix, "--fix"),
        strategy=args.strategy,
        envmap=args.envmap,
        rotations=args.rotations,
        resolution=args.size,
        lights=args.lights,
        workers=args.workers,
        cache=Path(args.cache) if args.cache else None,
        evaluate=not args.no_evaluate,
        force=args.force,
        log=lambda m: print(m, file=sys.stderr),
        scene=Scene.probe(lights=parse_lights(args.light)) if args.light else None,
        target_renderer=args.target_renderer,
        library=not args.sweep,
    )
    print(
        f"done in {result.seconds['total']:.1f} s: maps {result.maps}"
        + (f", report {result.report}" if result.report else "")
        + (f", mean 1-SSIM {result.mean_dssim:.4f}" if result.mean_dssim is not None else "")
    )
    return 0


# ---------------------------------------------------------------------------------------------
class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, exit 2
        self.exit(2, f"{self.prog}: error: {message}\n")


def _scene_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--light", nargs="+", metavar="DEG", help="light angles from the view axis (default 0: headlight)")
    p.add_argument("--size", type=int, default=128, metavar="N", help="image resolution (default 128)")


def build_parser() -> argparse.ArgumentParser:
    fmt = argparse.RawDescriptionHelpFormatter
    parser = _Parser(prog="matremap", description="Remap material parameters between renderers and models.")
    parser.add_argument("--version", action="version", version=f"matremap {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    p = sub.add_parser("models", help="list reflectance models", epilog=EXAMPLES["models"], formatter_class=fmt)
    p.add_argument("model", nargs="?", help="show one model's parameters")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=cmd_models)

    p = sub.add_parser("renderers", help="list renderer backends, whether they are installed, and their models")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=cmd_renderers)

    p = sub.add_parser(
        "render", help="render a material on the probe sphere", epilog=EXAMPLES["render"], formatter_class=fmt
    )
    p.add_argument("material", help="JSON file, inline JSON, or MODEL,name=value,...")
    p.add_argument("-o", "--output", required=True, help="image file: .exr, .png (sRGB), .npy, .tif, .hdr")
    p.add_argument("--part", choices=("full", "diffuse", "specular"), default="full")
    p.add_argument("--renderer", default="embedded")
    p.add_argument("--force", action="store_true", help="overwrite an existing output file")
    _scene_args(p)
    p.set_defaults(func=cmd_render)

    p = sub.add_parser(
        "fit", help="remap a uniform material onto a target model", epilog=EXAMPLES["fit"], formatter_class=fmt
    )
    p.add_argument(
        "--source", required=True, metavar="MATERIAL", help="JSON file, inline JSON, or MODEL,name=value,..."
    )
    p.add_argument("--target", required=True, metavar="MODEL", help="target model id (see `matremap models`)")
    p.add_argument(
        "--fix",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="set a target option or hold a parameter (repeatable), e.g. distribution=as",
    )
    p.add_argument(
        "--free",
        action="append",
        default=[],
        metavar="NAME",
        help="also fit a parameter that is held by default (repeatable)",
    )
    p.add_argument("--strategy", choices=("simple", "two-stage", "three-stage"), default="two-stage")
    p.add_argument("--source-renderer", default="embedded", metavar="NAME")
    p.add_argument("--target-renderer", default="embedded", metavar="NAME")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("-o", "--output", metavar="FILE.json", help="also save the result as JSON")
    p.add_argument(
        "--compare",
        metavar="FILE.png",
        help="write source | target | difference renders side by side (.png sRGB, .exr linear)",
    )
    p.add_argument("--force", action="store_true", help="overwrite existing output files")
    _scene_args(p)
    p.set_defaults(func=cmd_fit)

    p = sub.add_parser(
        "sweep",
        help="fit a grid of source materials into a remapping database",
        epilog=EXAMPLES["sweep"],
        formatter_class=fmt,
    )
    p.add_argument(
        "--source",
        required=True,
        metavar="MATERIAL",
        help="the base source material; grid values replace its parameters",
    )
    p.add_argument("--target", required=True, metavar="MODEL", help="target model id")
    p.add_argument(
        "--grid", required=True, help="NAME=LO:HI:COUNT[:log] or NAME=V1;V2;..., comma-separated, or a .toml file"
    )
    p.add_argument("--db", required=True, metavar="FILE.sqlite", help="database (created, or resumed)")
    p.add_argument("--fix", action="append", default=[], metavar="NAME=VALUE", help="as for fit")
    p.add_argument("--free", action="append", default=[], metavar="NAME", help="as for fit")
    p.add_argument("--strategy", choices=("simple", "two-stage", "three-stage"), default="two-stage")
    p.add_argument("--source-renderer", default="embedded", metavar="NAME")
    p.add_argument("--target-renderer", default="embedded", metavar="NAME")
    p.add_argument("--workers", type=int, metavar="N", help="local worker processes (default: all cores)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="run on a Dask cluster (tcp://host:port)")
    p.add_argument("--dask-local", type=int, metavar="N", help="start a local Dask cluster of N workers")
    p.add_argument(
        "--continuation",
        action="store_true",
        help="start each fit from its finished neighbour along the last grid axis",
    )
    p.add_argument("--round-trip", action="store_true", help="also fit each result back onto the source model")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    _scene_args(p)
    p.set_defaults(func=cmd_sweep)

    p = sub.add_parser(
        "sweep-report",
        help="summarise a sweep database and plot it",
        epilog=EXAMPLES["sweep-report"],
        formatter_class=fmt,
    )
    p.add_argument("db", metavar="DB")
    p.add_argument("-o", "--output", required=True, metavar="DIR", help="folder for the PNG plots")
    p.add_argument("--force", action="store_true", help="overwrite existing plots in DIR")
    p.set_defaults(func=cmd_sweep_report)

    p = sub.add_parser(
        "export", help="export a sweep database as a table", epilog=EXAMPLES["export"], formatter_class=fmt
    )
    p.add_argument("db", metavar="DB")
    p.add_argument("-o", "--output", required=True, metavar="FILE", help=".csv or .parquet")
    p.add_argument("--force", action="store_true", help="overwrite an existing file")
    p.set_defaults(func=cmd_export)

    p = sub.add_parser(
        "learn", help="learn a transform from a sweep database", epilog=EXAMPLES["learn"], formatter_class=fmt
    )
    p.add_argument("db", metavar="DB")
    p.add_argument("--method", choices=("parametric", "svr"), default="parametric")
    p.add_argument("-o", "--output", required=True, metavar="T.json")
    p.add_argument("--reverse", action="store_true", help="learn the target -> source direction")
    p.add_argument("--holdout", type=float, default=0.2, help="fraction of points held out to pick forms (0.2)")
    p.add_argument("--keep-flagged", action="store_true", help="also train on points the stability analysis flags")
    p.add_argument("--force", action="store_true", help="overwrite an existing file")
    p.set_defaults(func=cmd_learn)

    p = sub.add_parser("chain", help="compose transforms A -> B -> C", epilog=EXAMPLES["chain"], formatter_class=fmt)
    p.add_argument("transforms", nargs="+", metavar="T.json")
    p.add_argument("-o", "--output", required=True, metavar="AC.json")
    p.add_argument("--force", action="store_true", help="overwrite an existing file")
    p.set_defaults(func=cmd_chain)

    p = sub.add_parser(
        "apply", help="apply a transform to a uniform material", epilog=EXAMPLES["apply"], formatter_class=fmt
    )
    p.add_argument("transform", metavar="T.json")
    p.add_argument("--source", required=True, metavar="MATERIAL")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_apply)

    p = sub.add_parser(
        "convert", help="apply transforms to an SVBRDF map set", epilog=EXAMPLES["convert"], formatter_class=fmt
    )
    p.add_argument(
        "maps",
        metavar="MAPS",
        help="folder of maps (material.json, or *_diffuse/_specular/_roughness/_normal file names)",
    )
    p.add_argument(
        "--transform",
        action="append",
        default=[],
        metavar="T.json",
        help="transform to apply; several are chained in order",
    )
    p.add_argument(
        "--to",
        dest="target",
        metavar="MODEL",
        help="instead of --transform: find a route to MODEL through the transform library",
    )
    p.add_argument(
        "--fix",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="with --to: target options/held values the route must have",
    )
    p.add_argument("-o", "--output", required=True, metavar="OUT", help="output folder")
    p.add_argument("--model", "--from", dest="model", help="source model, when the folder has no manifest")
    p.add_argument("--format", help="output format instead of the inputs' (e.g. exr, png16)")
    p.add_argument("--workers", type=int, default=2, metavar="N")
    p.add_argument("--force", action="store_true", help="overwrite existing outputs")
    p.set_defaults(func=cmd_convert)

    p = sub.add_parser(
        "transforms",
        help="list the shipped transform library, or find a route through it",
        epilog=EXAMPLES["transforms"],
        formatter_class=fmt,
    )
    p.add_argument("--route", nargs=2, metavar=("FROM", "TO"), help="show the route between two models")
    p.add_argument("--fix", action="append", default=[], metavar="NAME=VALUE", help="with --route: target values")
    p.add_argument(
        "--source-option", action="append", default=[], metavar="NAME=VALUE", help="with --route: source options"
    )
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_transforms)

    p = sub.add_parser(
        "evaluate",
        help="compare two map sets under an environment map (SSIM, HTML report)",
        epilog=EXAMPLES["evaluate"],
        formatter_class=fmt,
    )
    p.add_argument("source_maps", metavar="SOURCE_MAPS")
    p.add_argument("target_maps", metavar="TARGET_MAPS")
    p.add_argument("--source-model", help="source model, when its folder has no manifest")
    p.add_argument("--target-model", help="target model, when its folder has no manifest")
    p.add_argument("--envmap", default="builtin", help="EXR/HDR file, or 'builtin' (default)")
    p.add_argument("--rotations", default="0:360:12", help="START:STOP:COUNT in degrees (default 0:360:12)")
    p.add_argument("--geometry", choices=("sphere", "plane"), default="sphere")
    p.add_argument("--size", type=int, default=256, metavar="N", help="render resolution (default 256)")
    p.add_argument("--lights", type=int, default=256, help="directional lights sampled from the map (256)")
    p.add_argument("-o", "--output", required=True, metavar="DIR")
    p.add_argument("--force", action="store_true", help="overwrite an existing report")
    p.set_defaults(func=cmd_evaluate)

    p = sub.add_parser(
        "remap",
        help="the main job: sweep, learn, convert and evaluate a map set",
        epilog=EXAMPLES["remap"],
        formatter_class=fmt,
    )
    p.add_argument("maps", metavar="MAPS|FILE", help="a map set folder, or a .gltf/.glb/.mtlx/Mitsuba .xml file")
    p.add_argument("--from", dest="source", metavar="MODEL", help="source model (default: the manifest's)")
    p.add_argument("--material", metavar="NAME|INDEX", help="which material of the file (default: the first)")
    p.add_argument(
        "--write",
        metavar="NAME.EXT",
        help="the file to write into OUT (default: the input's name with "
        "the target format's suffix: .gltf/.glb/.mtlx for gltf:*, .xml for mitsuba3:*, .blend for cycles:*)",
    )
    p.add_argument("--sweep", action="store_true", help="always sweep, even when the transform library has a route")
    p.add_argument("--to", dest="target", required=True, metavar="MODEL", help="target model")
    p.add_argument("--fix", action="append", default=[], metavar="NAME=VALUE", help="target options/held values")
    p.add_argument("--strategy", choices=("simple", "two-stage", "three-stage"), default="two-stage")
    p.add_argument("-o", "--output", required=True, metavar="OUT", help="output folder (maps/ and report/)")
    p.add_argument("--envmap", default="builtin")
    p.add_argument("--rotations", default="0:360:6")
    p.add_argument("--size", type=int, default=160, metavar="N", help="evaluation render resolution (160)")
    p.add_argument("--lights", type=int, default=128)
    p.add_argument("--workers", type=int, metavar="N")
    p.add_argument("--cache", metavar="DIR", help="transform cache (default ~/.cache/matremap/transforms)")
    p.add_argument(
        "--light", nargs="+", metavar="DEG", help="light angles of the sweep's probe scene (default 0: headlight)"
    )
    p.add_argument(
        "--target-renderer",
        metavar="NAME",
        help="renderer of the target model in the sweep (embedded, mitsuba3, cycles; default: embedded "
        "where it emulates the model, else the model's own renderer)",
    )
    p.add_argument("--no-evaluate", action="store_true", help="skip the evaluation renders")
    p.add_argument("--force", action="store_true", help="write into an existing output folder")
    p.set_defaults(func=cmd_remap)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    from matremap.sweep.executors import limit_blas_threads

    limit_blas_threads()
    try:
        return args.func(args)
    except MatremapError as e:
        print(f"matremap: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("matremap: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader went away (`matremap transforms | head`): stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
