"""Textured materials: ``convert`` (apply transforms to a map set), ``evaluate`` (compare two map
sets under an environment map) and ``remap`` (the main job: sweep, learn, convert, evaluate)."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from matremap.cli.common import (
    PROBE_HELP,
    Subparsers,
    add_allow_path_option,
    add_command,
    add_executor_options,
    add_fix_option,
    add_force_option,
    add_json_option,
    add_light_option,
    add_probe_option,
    add_renamed,
    add_strategy_option,
    add_target_option,
    parse_assignments,
)
from matremap.core.objective import OBJECTIVES
from matremap.core.scene import parse_lights, parse_probe
from matremap.dialects import get_model
from matremap.errors import MatremapError, QualityGateFailed
from matremap.svbrdf.quality import Thresholds
from matremap.svbrdf.textures import OUT_FORMATS

if TYPE_CHECKING:
    from matremap.regress.transform import Transform
    from matremap.svbrdf.textures import MapSet

CONVERT_EXAMPLES = """examples:
  matremap convert examples/bronze --transform ward2as.json -o out/bronze-as
  matremap convert maps/ --model mitsuba06:ward --transform a.json --transform b.json -o out/
  matremap convert examples/bronze --to mitsuba06:pbr --fix distribution=as -o out/bronze-as
      (a route through the shipped library: `matremap transforms` lists it)"""

EVALUATE_EXAMPLES = """examples:
  matremap evaluate examples/bronze out/bronze-as/maps -o out/eval
  matremap evaluate src/ dst/ --envmap studio.exr --rotations 0,90,180 --size 512 --env-lights 512 -o out/eval"""

REMAP_EXAMPLES = """examples:
  matremap remap examples/bronze --to mitsuba06:pbr --fix distribution=as -o out/bronze
  matremap remap examples/blue-plastic --from mitsuba06:ward --to mitsuba06:pbr --fix distribution=as -o out/plastic
  (a second run reuses the cached transform)
  matremap remap examples/bronze --to gltf:metal-rough -o out/bronze-gltf --write bronze.gltf
      (the converted maps, and a glTF material that uses them)
  matremap remap helmet.glb --to mitsuba3:roughconductor -o out/helmet      (writes out/helmet/helmet.xml)
  matremap remap scene.xml --material gold --to gltf:metal-rough -o out/gold  (writes out/gold/scene.gltf)
  matremap remap examples/bronze --to mitsuba06:pbr --fix distribution=as --envmap studio.exr \\
      --probe env:studio.exr -o out/bronze-studio   (fitted for the light it will be seen in: sweeps)"""


def add_convert(subparsers: Subparsers) -> None:
    """The ``convert`` command."""
    p = add_command(subparsers, "convert", "apply transforms to an SVBRDF map set", CONVERT_EXAMPLES)
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
    add_fix_option(p, "with --to: target options/held values the route must have")
    p.add_argument("-o", "--output", required=True, metavar="OUT", help="output folder")
    add_renamed(
        p,
        "--from",
        old=["--model"],
        dest="source",
        metavar="MODEL",
        help="source model, when the folder has no manifest",
    )
    p.add_argument(
        "--format",
        choices=tuple(OUT_FORMATS),
        metavar="FORMAT",
        help=f"write the maps in this format instead of the inputs': {', '.join(OUT_FORMATS)} "
        "(default: each input map's own format)",
    )
    p.add_argument(
        "--workers", type=int, default=2, metavar="N", help="processes converting tiles of texels (default %(default)s)"
    )
    add_allow_path_option(p)
    _max_texels(p)
    add_force_option(p, "overwrite existing outputs")
    p.set_defaults(func=_limited(cmd_convert))


def library_transform(map_set: MapSet, target_model: str, fix_items: Sequence[str]) -> Transform:
    """The transform of the library route from a map set to ``target_model`` with ``--fix``
    ``fix_items``; raises when the library has none."""
    from matremap.regress.library import find_route
    from matremap.regress.quantities import diffuse_param
    from matremap.remap import complete_fix
    from matremap.svbrdf.mapstats import summarise

    target = get_model(target_model).id
    # what decides the route: whether the source has a diffuse part, and its held values (metallic), read
    # in bands (a map's range stands for it: whether every texel is metal, whether any is diffuse)
    spec = map_set.spec
    dp = diffuse_param(spec)
    names = {n for n, _, _ in spec.specialisations} | ({dp.name} if dp else set())
    stats = summarise(map_set, limits=(), names=names).stats
    values = {**map_set.constants, **{n: s.range for n, s in stats.items()}}
    fix = complete_fix(map_set.model, values, target, parse_assignments(fix_items, "--fix"))
    held = {n: stats[n].mean for n, _, _ in map_set.spec.specialisations if n in stats}
    found = find_route(map_set.model, map_set.options, target, fix, source_values=held)
    if found is None:
        raise MatremapError(
            f"no route from {map_set.model} to {target} in the transform library "
            f"(`matremap transforms` lists it); run `matremap remap` to sweep one"
        )
    print(f"matremap: route {found.describe()}", file=sys.stderr)
    return found.transform


def cmd_convert(args: argparse.Namespace) -> int:
    """Convert a map set with transform files, or with a route through the library (``--to``)."""
    import warnings

    from matremap.regress.transform import Transform
    from matremap.svbrdf.convert import convert

    map_set = user_map_set(args.maps, args.source, args.allow_path)
    if args.transform:
        if args.target:
            raise MatremapError("give either --transform files or --to MODEL (a route through the library), not both")
        transforms = [Transform.load(p) for p in args.transform]
    elif args.target:
        transforms = [library_transform(map_set, args.target, args.fix)]
    else:
        raise MatremapError("name the transform(s) with --transform T.json, or a target model with --to MODEL")
    for note in map_set.notes:
        print(f"matremap: note: {note}", file=sys.stderr)
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


def add_evaluate(subparsers: Subparsers) -> None:
    """The ``evaluate`` command."""
    p = add_command(
        subparsers,
        "evaluate",
        "compare two map sets under an environment map (SSIM, HTML report)",
        EVALUATE_EXAMPLES,
    )
    p.add_argument("source_maps", metavar="SOURCE_MAPS", help="the source map set folder")
    p.add_argument("target_maps", metavar="TARGET_MAPS", help="the converted map set folder (e.g. OUT/maps of remap)")
    p.add_argument("--source-model", metavar="MODEL", help="model of SOURCE_MAPS, when its folder has no manifest")
    p.add_argument("--target-model", metavar="MODEL", help="model of TARGET_MAPS, when its folder has no manifest")
    add_environment_options(p, rotations="0:360:12", size=256, lights=256)
    p.add_argument(
        "--geometry",
        choices=("sphere", "plane"),
        default="sphere",
        help="what the maps are drawn on: a UV sphere or a plane facing the camera (default %(default)s)",
    )
    p.add_argument("-o", "--output", required=True, metavar="DIR", help="folder of the HTML report and its images")
    add_allow_path_option(p)
    _max_texels(p)
    add_force_option(p, "overwrite an existing report")
    _max_error(p)
    p.set_defaults(func=_limited(cmd_evaluate))


def _max_texels(p: argparse.ArgumentParser) -> None:
    from matremap.svbrdf.textures import DEFAULT_MAX_TEXELS

    p.add_argument(
        "--max-texels",
        type=int,
        metavar="N",
        help=f"refuse any map of more than N texels (width x height), from its header, before reading it "
        f"(default {DEFAULT_MAX_TEXELS}, a 32768 x 32768 map)",
    )


def _limited(command: Callable[[argparse.Namespace], int]) -> Callable[[argparse.Namespace], int]:
    """``command`` run with ``--max-texels`` in effect for every image it opens."""

    def run(args: argparse.Namespace) -> int:
        from matremap.svbrdf.textures import texel_limit

        with texel_limit(args.max_texels):
            return command(args)

    return run


def add_environment_options(p: argparse.ArgumentParser, rotations: str, size: int, lights: int) -> None:
    """``--envmap``, ``--rotations``, ``--size`` and ``--env-lights``: the evaluation under an environment."""
    p.add_argument(
        "--envmap",
        default="builtin",
        metavar="FILE",
        help="environment map of the evaluation: an .exr/.hdr (equirectangular, linear), 'builtin' (a procedural "
        "studio) or 'constant' (default %(default)s)",
    )
    p.add_argument(
        "--rotations",
        default=rotations,
        metavar="START:STOP:COUNT",
        help="environment rotations about the vertical axis, in degrees: COUNT evenly spaced from START up to STOP "
        "(excluded), or angles 0,90,180 (default %(default)s)",
    )
    p.add_argument(
        "--size",
        type=int,
        default=size,
        metavar="N",
        help="side of each evaluation render in pixels, N x N (default %(default)s)",
    )
    add_renamed(
        p,
        "--env-lights",
        old=["--lights"],
        type=int,
        default=lights,
        metavar="N",
        help="directional lights importance-sampled from the environment map by the embedded renderer; more is "
        "smoother and slower (default %(default)s)",
    )


def _max_error(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--max-error",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="a quality-gate threshold (repeatable): luminance_error, delta_e, delta_e_fraction, dssim, hue_shift, "
        "flat, outside, clamped, fit_error, highlight_energy, highlight_sharpness, flip; see docs/quality.md",
    )


def _verdict(verdict: Any) -> int:
    """0 when the quality gate passed; else raise, so that the command exits 3 with the verdict's line."""
    if not verdict.passed:
        raise QualityGateFailed(verdict.line())
    return 0


def cmd_evaluate(args: argparse.Namespace) -> int:
    """Render both map sets under the environment at each rotation; write the SSIM report."""
    from matremap.core.envmap import resolve
    from matremap.remap import load_arrays, map_quality
    from matremap.svbrdf.evaluate import evaluate, parse_rotations

    rotations = parse_rotations(args.rotations)
    env = resolve(args.envmap)
    sets = [
        user_map_set(p, m, args.allow_path)
        for p, m in ((args.source_maps, args.source_model), (args.target_maps, args.target_model))
    ]
    materials = []
    for ms in sets:
        params, normal = load_arrays(ms)
        materials.append((ms.model, params, ms.options, normal))
    thresholds = Thresholds.parse(args.max_error)
    checks = map_quality(sets[0], materials[0][1], sets[1], materials[1][1], thresholds)
    result = evaluate(
        materials[0],
        materials[1],
        env,
        rotations,
        args.output,
        geometry=args.geometry,
        resolution=args.size,
        lights=args.env_lights,
        force=args.force,
        thresholds=thresholds,
        checks=checks,
    )
    print(
        f"mean 1-SSIM {result.mean_full:.4f} (specular only {result.mean_specular:.4f}) over "
        f"{len(rotations)} rotations; report {Path(args.output) / 'report.html'}; {result.verdict.line()}"
    )
    return _verdict(result.verdict)


def add_remap(subparsers: Subparsers) -> None:
    """The ``remap`` command."""
    p = add_command(
        subparsers,
        "remap",
        "the main job: convert map sets or every material of files onto a model "
        "(library route or sweep, convert the maps, evaluate, write the target's file)",
        REMAP_EXAMPLES,
    )
    p.add_argument(
        "maps",
        nargs="+",
        metavar="PATH",
        help="a map set folder, or a .gltf/.glb/.mtlx/Mitsuba .xml/.usda/.usdc/.usdz/.usd file; several files, "
        "folders of them or glob patterns convert every material of every file (OUT/summary.csv, summary.json, "
        "index.html)",
    )
    p.add_argument(
        "--from",
        dest="source",
        metavar="MODEL",
        help="source model of a map set folder without a manifest (default: the manifest's; a material file names "
        "its own)",
    )
    p.add_argument(
        "--material",
        metavar="NAME|INDEX",
        help="convert only this material of each file, by name or 0-based index (default: every material; a file "
        "with several is a batch, OUT/<file>/<material>/)",
    )
    p.add_argument(
        "--write",
        metavar="NAME.EXT",
        help="the material file to write into OUT: .gltf/.glb, .mtlx or .usda/.usdc/.usdz (gltf:* models), .xml "
        "(mitsuba3:*), .blend (cycles:*), .usda/.usdc/.usdz (usd:*) (default for a material file: the input's name "
        "with the target format's suffix; for a map set: none, only the maps)",
    )
    p.add_argument("--sweep", action="store_true", help="always sweep, even when the transform library has a route")
    add_target_option(p, "target model id (see `matremap models`)")
    add_fix_option(p, "set a target option or hold a target parameter at a value (repeatable), e.g. distribution=as")
    add_strategy_option(p)
    p.add_argument(
        "-o",
        "--output",
        required=True,
        metavar="OUT",
        help="output folder: maps/, report/, verdict.json (a batch: one folder per file and material, summary.csv, "
        "summary.json, index.html)",
    )
    add_environment_options(p, rotations="0:360:6", size=160, lights=128)
    _max_error(p)
    add_executor_options(p, "material (a batch) or fit (the sweep of one input)")
    p.add_argument(
        "--cache",
        metavar="DIR",
        help="folder of the learned transforms a rerun reuses (default: transforms/ in $MATREMAP_CACHE, else "
        "~/.cache/matremap)",
    )
    add_light_option(
        p,
        "point lights of the sweep's probe scene at DEG degrees from the view axis (any other than the "
        "default skips the library, whose transforms were learned with the headlight)",
    )
    add_fit_light_options(p)
    p.add_argument(
        "--target-renderer",
        metavar="NAME",
        help="renderer of the target model in the sweep (embedded, mitsuba3, cycles; default: embedded "
        "where it emulates the model, else the model's own renderer)",
    )
    p.add_argument(
        "--no-evaluate", action="store_true", help="skip the renders under the environment (and their 1-SSIM check)"
    )
    add_json_option(p, "the result (a batch: summary.json)")
    add_allow_path_option(p)
    _max_texels(p)
    add_force_option(p, "write into an existing output folder")
    p.set_defaults(func=_limited(cmd_remap))


def add_fit_light_options(p: argparse.ArgumentParser) -> None:
    """remap's ``--probe`` (with ``auto``) and ``--objective`` (its default depending on the probe)."""
    add_probe_option(
        p,
        "auto",
        "auto (a library route fitted under the headlight or the built-in environment, whichever looks closer "
        "under --envmap, else a sweep under the headlight), or " + PROBE_HELP,
    )
    p.add_argument(
        "--objective",
        choices=OBJECTIVES,
        default=None,
        help="what the fits make small: l2 (linear HDR, the paper's), log or ssim (default: ssim under an environment "
        "probe, l2 under the point probe; docs/fitting.md)",
    )


def cmd_remap(args: argparse.Namespace) -> int:
    """Remap a map set folder, or one material of a glTF / MaterialX / Mitsuba file, onto the target model."""
    from matremap.formats import allowed_paths, is_material_file
    from matremap.formats.confine import output_inside
    from matremap.remap import remap, remap_file

    if is_batch(args.maps, args.material) or (
        (args.scheduler or args.dask_local) and all(is_material_file(m) for m in args.maps)
    ):
        return _remap_batch(args)
    if args.scheduler or args.dask_local:
        raise MatremapError(
            "--scheduler and --dask-local run batches of material files on Dask; a map set's sweep runs on local "
            "processes (--workers)"
        )
    args.maps = args.maps[0]
    material_file = is_material_file(args.maps)
    if material_file and args.source:
        raise MatremapError(f"{args.maps} names its own model; drop --from")
    if not material_file and args.material is not None:
        raise MatremapError("--material applies to material files (.gltf, .glb, .mtlx, .xml, .usd*); a map set is one")
    if not material_file:
        user_map_set(args.maps, args.source, args.allow_path)  # its files lie where it may name them
    if args.write is not None:
        output_inside(args.output, args.write)
        folder = Path(args.write).parts[0] if Path(args.write).parent != Path(".") else None
        if folder in ("maps", "report", "source"):
            raise MatremapError(f"--write {args.write}: OUT/{folder}/ holds the remap's own files; choose another name")
        if folder is not None:
            raise MatremapError(
                f"--write {args.write}: the material file is written in OUT itself, not in a folder of it; give a "
                f"file name (--write {Path(args.write).name})"
            )
    options = remap_options(args)
    options.update(workers=args.workers, force=args.force, log=lambda m: print(m, file=sys.stderr))
    if material_file:
        with allowed_paths(args.allow_path):
            fres = remap_file(args.maps, args.target, args.output, material=args.material, write=args.write, **options)
        if args.json:
            doc = {"file": str(fres.file) if fres.file else None, "verdict": fres.verdict.to_dict()}
            print(json.dumps({"source_model": fres.source_model, "target_model": fres.target_model, **doc}, indent=1))
            return _verdict(fres.verdict)
        print(
            f"{'done' if fres.verdict.passed else 'written'}: {fres.source_model} -> {fres.target_model}"
            + (f", wrote {fres.file}" if fres.file else "")
            + (f", mean 1-SSIM {fres.remap.mean_dssim:.4f}" if fres.remap and fres.remap.mean_dssim is not None else "")
            + f"; {fres.verdict.line()}"
        )
        return _verdict(fres.verdict)
    scene = (
        parse_probe(args.probe if args.probe != "auto" else "point", parse_lights(args.light)) if args.light else None
    )
    result = remap(args.maps, args.source, args.target, args.output, scene=scene, write=args.write, **options)
    file = Path(args.output) / args.write if args.write else None
    if args.json:
        doc = {"maps": str(result.maps), "file": str(file) if file else None, "verdict": result.verdict.to_dict()}
        print(json.dumps(doc, indent=1))
        return _verdict(result.verdict)
    print(
        f"{'done' if result.verdict.passed else 'written'} in {result.seconds['total']:.1f} s: maps {result.maps}"
        + (f", {file}" if file else "")
        + (f", report {result.report}" if result.report else "")
        + (f", mean 1-SSIM {result.mean_dssim:.4f}" if result.mean_dssim is not None else "")
        + f"; {result.verdict.line()}"
    )
    return _verdict(result.verdict)


def user_map_set(path: str, model: str | None, allow: list[str] | None) -> Any:
    """A map set the user gave, its files confined to its folder and the ``--allow-path`` folders."""
    from matremap.formats import allowed_paths
    from matremap.svbrdf.textures import load_map_set

    with allowed_paths(allow or []):
        return load_map_set(path, model, confine=True)


def is_batch(paths: list[str], material: str | None = None) -> bool:
    """Whether ``remap`` was given a batch: several paths, a glob pattern, a folder of material files (a
    folder with a ``material.json`` manifest, or maps named by suffix, is one map set), or one material file
    with several materials and no ``--material`` (every material of a file is converted by default)."""
    from matremap.formats import is_material_file, material_names

    if len(paths) > 1 or any(ch in paths[0] for ch in "*?["):
        return True
    path = Path(paths[0])
    if is_material_file(path):
        return material is None and len(material_names(path)) > 1
    if not path.is_dir() or (path / "material.json").is_file():
        return False
    return any(p.is_file() and is_material_file(p) for p in path.rglob("*"))


def remap_options(args: argparse.Namespace) -> dict[str, Any]:
    """The :class:`matremap.remap.RemapJob` fields ``remap``'s options set (one input or a batch)."""
    return {
        "fix": parse_assignments(args.fix, "--fix"),
        "strategy": args.strategy,
        "envmap": args.envmap,
        "rotations": args.rotations,
        "resolution": args.size,
        "lights": args.env_lights,
        "cache": Path(args.cache) if args.cache else None,
        "evaluate": not args.no_evaluate,
        "target_renderer": args.target_renderer,
        "library": not args.sweep,
        "thresholds": Thresholds.parse(args.max_error),
        "max_texels": args.max_texels,
        "probe": args.probe,
        "objective": args.objective,
    }


def _remap_batch(args: argparse.Namespace) -> int:
    """Every material of every file ``args.maps`` names (:mod:`matremap.batch`)."""
    from matremap.batch import run_batch

    if args.source or args.write or args.light:
        raise MatremapError(
            "--from, --write and --light apply to one map set or one material; a batch (several files, a folder, "
            "a glob, or a file with several materials) takes each file's own model and writes one file per input"
        )
    options = remap_options(args)
    options["workers"] = 1  # the batch runs items in parallel; each sweeps on one core
    result = run_batch(
        args.maps,
        args.target,
        args.output,
        material=args.material,
        workers=args.workers,
        scheduler=args.scheduler,
        dask_local=args.dask_local,
        options=options,
        allow_paths=args.allow_path,
        log=lambda m: print(m, file=sys.stderr),
    )
    if result.interrupted:  # one line, no traceback; what finished is kept
        print(f"matremap: {result.line()}", file=sys.stderr)
        return result.exit_code
    if args.json:
        print((result.out / "summary.json").read_text(), end="")
    else:
        print(f"summary: {result.out / 'index.html'}")
        print(result.line())
    return result.exit_code


#: command name -> the function adding its parser
PARSERS = {"convert": add_convert, "evaluate": add_evaluate, "remap": add_remap}
