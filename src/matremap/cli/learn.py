"""Transforms: ``learn`` (a compact transform from a sweep database) and ``chain`` (compose
transforms A -> B -> C)."""

from __future__ import annotations

import argparse
import sys

from matremap.cli.common import Subparsers, add_command, add_force_option
from matremap.regress.learners import LEARNERS

LEARN_EXAMPLES = """examples:
  matremap learn ward2as.sqlite -o ward2as.json
  matremap learn ward2as.sqlite --reverse -o as2ward.json
  matremap learn ward2as.sqlite --method svr -o ward2as-svr.json"""

CHAIN_EXAMPLES = """examples:
  matremap chain blender2ward.json ward2ggx.json -o blender2ggx.json"""


def add_learn(subparsers: Subparsers) -> None:
    """The ``learn`` command."""
    p = add_command(subparsers, "learn", "learn a transform from a sweep database", LEARN_EXAMPLES)
    p.add_argument("db", metavar="DB", help="a sweep database (.sqlite, from `matremap sweep`)")
    p.add_argument(
        "--method",
        choices=tuple(LEARNERS),
        default="parametric",
        help="parametric: a closed form per quantity, picked on the held-out points; svr: support vector "
        "regression, needs scikit-learn (default %(default)s; docs/regression.md)",
    )
    p.add_argument("-o", "--output", required=True, metavar="T.json", help="the transform file to write")
    p.add_argument("--reverse", action="store_true", help="learn the target -> source direction")
    p.add_argument(
        "--holdout",
        type=float,
        default=0.2,
        metavar="FRACTION",
        help="fraction of the points held out to pick the forms and measure the error, 0 to 1 (default %(default)s)",
    )
    p.add_argument("--keep-flagged", action="store_true", help="also train on points the stability analysis flags")
    add_force_option(p, "overwrite an existing file")
    p.set_defaults(func=cmd_learn)


def cmd_learn(args: argparse.Namespace) -> int:
    """Learn and save a transform; report each quantity's held-out error and training domain."""
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
        held = e.get("heldout_rmse")
        held_text = f"held-out RMSE {held:.3g}" if held is not None else "not fitted (constant)"
        span = t.domain.get(name)  # the source's counterpart (a glTF coat has no colour of its own)
        where = f", training domain [{span[0]:.4g}, {span[1]:.4g}]" if span else ", the source has no counterpart"
        print(f"  {name}: {held_text}{where}", file=sys.stderr)
    return 0


def add_chain(subparsers: Subparsers) -> None:
    """The ``chain`` command."""
    p = add_command(subparsers, "chain", "compose transforms A -> B -> C", CHAIN_EXAMPLES)
    p.add_argument("transforms", nargs="+", metavar="T.json", help="transforms A -> B, B -> C, ... in order")
    p.add_argument("-o", "--output", required=True, metavar="AC.json", help="the composed transform file to write")
    add_force_option(p, "overwrite an existing file")
    p.set_defaults(func=cmd_chain)


def cmd_chain(args: argparse.Namespace) -> int:
    """Compose transform files in order and save the chain."""
    from matremap.core.imageio import check_output
    from matremap.regress.transform import Transform

    out = check_output(args.output, args.force, (".json",))
    chained = Transform.chain([Transform.load(p) for p in args.transforms])
    chained.save(out, force=args.force)
    print(f"wrote {out}: {chained.describe()}", file=sys.stderr)
    return 0


#: command name -> the function adding its parser
PARSERS = {"learn": add_learn, "chain": add_chain}
