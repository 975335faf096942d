"""The ``matremap`` command.

Subcommands are verbs: ``models`` lists the reflectance models, ``render`` draws a material on
the probe sphere, ``fit`` remaps a uniform material onto another model. Errors print one line on
stderr and exit with status 2; nothing is written when a command fails.

Each command group is a module that adds its commands' parsers and holds their handlers:
:mod:`.inspect` (models, renderers, transforms), :mod:`.fit` (render, fit, apply), :mod:`.sweep`
(sweep, sweep-report, export), :mod:`.learn` (learn, chain) and :mod:`.maps` (convert, evaluate,
remap); :mod:`.common` holds what they share. This module assembles the parser and runs a command.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable, Sequence
from typing import NoReturn

from matremap import __version__
from matremap.cli import fit, inspect, learn, maps, sweep
from matremap.cli.common import Subparsers
from matremap.errors import EXIT_QUALITY, MatremapError

#: every command, as ``matremap --help`` lists them: what is there, then the workflow's order
COMMANDS = (
    "models",
    "renderers",
    "render",
    "fit",
    "sweep",
    "sweep-report",
    "export",
    "learn",
    "chain",
    "apply",
    "convert",
    "transforms",
    "evaluate",
    "remap",
)
#: command name -> the function (in its group's module) adding its parser
PARSERS: dict[str, Callable[[Subparsers], None]] = {
    **inspect.PARSERS,
    **fit.PARSERS,
    **sweep.PARSERS,
    **learn.PARSERS,
    **maps.PARSERS,
}


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:  # one line, exit 2
        self.exit(2, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    """The ``matremap`` parser with every command's subparser; ``args.func`` runs the command."""
    parser = _Parser(prog="matremap", description="Remap material parameters between renderers and models.")
    parser.add_argument("--version", action="version", version=f"matremap {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    for name in COMMANDS:
        PARSERS[name](sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run one command; the exit status (see :mod:`matremap.errors`): 0, 2 on bad input, 3 when a result
    failed the quality gate, 4 when a renderer or the environment failed (one line on stderr), 130 when
    interrupted."""
    parser = build_parser()
    args = parser.parse_args(argv)
    from matremap.sweep.executors import limit_blas_threads

    limit_blas_threads()
    try:
        return args.func(args)
    except MatremapError as e:
        kind = "FAILED" if e.exit_code == EXIT_QUALITY else "error"
        print(f"matremap: {kind}: {e}", file=sys.stderr)
        return e.exit_code
    except KeyboardInterrupt:
        print("matremap: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader went away (`matremap transforms | head`): stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
