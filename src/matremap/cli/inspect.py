"""What is there: ``models`` (the reflectance models), ``renderers`` (the backends and what they
draw) and ``transforms`` (the shipped transform library, and routes through it)."""

from __future__ import annotations

import argparse
import json
from typing import Any

from matremap.cli.common import Subparsers, add_command, add_fix_option, add_json_option, parse_assignments
from matremap.dialects import get_model, list_models
from matremap.errors import MatremapError

MODELS_EXAMPLES = """examples:
  matremap models
  matremap models mitsuba06:roughconductor
  matremap models --json"""

TRANSFORMS_EXAMPLES = """examples:
  matremap transforms
  matremap transforms --route blender27:ward cycles:glossy --fix distribution=ggx
  matremap transforms --route mitsuba06:ward mitsuba06:pbr --source-option variant=ward --fix distribution=as"""

RENDERERS_EXAMPLES = """examples:
  matremap renderers
  matremap renderers --json
  matremap doctor          (versions, the cache, and what is missing with the command to install it)"""


def add_models(subparsers: Subparsers) -> None:
    """The ``models`` command."""
    p = add_command(subparsers, "models", "list reflectance models", MODELS_EXAMPLES)
    p.add_argument("model", nargs="?", metavar="MODEL", help="show one model's options and parameters")
    add_json_option(p)
    p.set_defaults(func=cmd_models)


def cmd_models(args: argparse.Namespace) -> int:
    """List the models (one line each), or one model's options and parameters."""
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


def add_renderers(subparsers: Subparsers) -> None:
    """The ``renderers`` command."""
    p = add_command(
        subparsers,
        "renderers",
        "list renderer backends, whether they are installed, and their models",
        RENDERERS_EXAMPLES,
    )
    add_json_option(p)
    p.set_defaults(func=cmd_renderers)


def cmd_renderers(args: argparse.Namespace) -> int:
    """Each renderer backend: installed or why not, and the models it draws."""
    from matremap.renderers import get_renderer, renderer_names

    rows: list[dict[str, Any]] = []
    for name in renderer_names():
        try:
            r = get_renderer(name)
        except MatremapError as e:
            rows.append({"name": name, "available": False, "reason": str(e), "models": []})
            continue
        models = [m.id for m in list_models() if r.can_render(m.id)]
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


def add_transforms(subparsers: Subparsers) -> None:
    """The ``transforms`` command."""
    p = add_command(
        subparsers,
        "transforms",
        "list the shipped transform library, or find a route through it",
        TRANSFORMS_EXAMPLES,
    )
    p.add_argument("--route", nargs=2, metavar=("FROM", "TO"), help="show the route between two model ids")
    add_fix_option(p, "with --route: a target option or held value the route must have (repeatable)")
    p.add_argument(
        "--source-option",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="with --route: an option of the source, e.g. variant=ward (repeatable; default: the model's defaults)",
    )
    p.add_argument(
        "--probe",
        choices=("point", "env", "mixed"),
        default="point",
        help="with --route: through transforms fitted under this probe (default %(default)s; docs/fitting.md)",
    )
    add_json_option(p)
    p.set_defaults(func=cmd_transforms)


def cmd_transforms(args: argparse.Namespace) -> int:
    """The library as a table (or JSON), or the route between two models."""
    from matremap.regress.library import find_route, listing, nearest_routes

    if args.route:
        source, target = args.route
        fix = parse_assignments(args.fix, "--fix")
        options = parse_assignments(args.source_option, "--source-option")
        found = find_route(get_model(source).id, options, get_model(target).id, fix, probe=args.probe)
        if found is None:
            near = nearest_routes(source, options, target, fix)
            raise MatremapError(
                f"no route from {source} to {target} in the library; `matremap remap` sweeps instead"
                + (f"; nearest: {'; '.join(near)}" if near else "")
            )
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
        fitted = "" if r["probe"] == "point" else f"; fitted under the {r['probe']} probe, objective {r['objective']}"
        print(f"{'':<30} trained on {dom} ({how}{fitted})")
    return 0


#: command name -> the function adding its parser
PARSERS = {"models": add_models, "renderers": add_renderers, "transforms": add_transforms}
