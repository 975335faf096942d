"""The ``matremap`` command.

Subcommands are verbs: ``models`` lists the reflectance models, ``render`` draws a material on
the probe sphere, ``fit`` remaps a uniform material onto another model. Errors print one line on
stderr and exit with status 2; nothing is written when a command fails. An exception no command
expected is one line too (``internal error: Type: message``, exit 70); ``matremap --debug COMMAND``
prints its traceback.

Each command group is a module that adds its commands' parsers and holds their handlers:
:mod:`.inspect` (models, renderers, transforms), :mod:`.fit` (render, fit, apply), :mod:`.sweep`
(sweep, sweep-report, export), :mod:`.learn` (learn, chain), :mod:`.maps` (convert, evaluate,
remap) and :mod:`.doctor` (doctor); :mod:`.common` holds what they share. This module assembles the
parser and runs a command.
"""

from __future__ import annotations

import argparse
import os
import sys
import traceback
from collections.abc import Callable, Sequence
from typing import NoReturn

from matremap import __version__
from matremap.cli import doctor, fit, inspect, learn, maps, sweep
from matremap.cli.common import Subparsers
from matremap.errors import EXIT_INTERNAL, EXIT_INTERRUPTED, EXIT_QUALITY, MatremapError

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
    "doctor",
)
#: command name -> the function (in its group's module) adding its parser
PARSERS: dict[str, Callable[[Subparsers], None]] = {
    **inspect.PARSERS,
    **fit.PARSERS,
    **sweep.PARSERS,
    **learn.PARSERS,
    **maps.PARSERS,
    **doctor.PARSERS,
}


#: where an internal error is to be reported (the project has no public tracker address)
REPORT_TO = "to the maintainers"


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:  # one line, exit 2
        self.exit(2, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    """The ``matremap`` parser with every command's subparser; ``args.func`` runs the command."""
    parser = _Parser(prog="matremap", description="Remap material parameters between renderers and models.")
    parser.add_argument("--version", action="version", version=f"matremap {__version__}")
    parser.add_argument(
        "--debug", action="store_true", help="on an internal error, print the traceback (give it before the command)"
    )
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    for name in COMMANDS:
        PARSERS[name](sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run one command; the exit status (see :mod:`matremap.errors`): 0, 2 on bad input, 3 when a result
    failed the quality gate, 4 when a renderer or the environment failed (one line on stderr), 70 on an
    internal error (one line; ``--debug`` shows the traceback), 130 when interrupted."""
    parser = build_parser()
    args = parser.parse_args(argv)
    from matremap.sweep.executors import limit_blas_threads

    limit_blas_threads()
    try:
        return args.func(args)
    except MatremapError as e:
        text = str(e)
        kind = "FAILED" if e.exit_code == EXIT_QUALITY else "error"
        # a verdict line already starts with its word ("FAILED: clamped ..."): not said twice
        print(f"matremap: {text}" if text.startswith(f"{kind}:") else f"matremap: {kind}: {text}", file=sys.stderr)
        return e.exit_code
    except KeyboardInterrupt:
        print("matremap: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:  # the reader went away (`matremap transforms | head`): stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except Exception as e:  # not the input's fault as far as the code knows: one line, not a traceback
        if args.debug:
            traceback.print_exc()
        print(f"matremap: {describe_unexpected(e)}", file=sys.stderr)
        return EXIT_INTERNAL if _internal(e) else 2


def _internal(e: BaseException) -> bool:
    """Whether an exception that escaped a command is a bug (exit 70) rather than a file the system
    refused or memory the input needed (exit 2)."""
    return not ((isinstance(e, OSError) and e.filename is not None) or isinstance(e, MemoryError))


def describe_unexpected(e: BaseException) -> str:
    """The one line for an exception no command turned into a MatremapError: a file the system refused
    (``cannot read X: reason``), memory, or an internal error with where to report it."""
    if isinstance(e, OSError) and e.filename is not None:
        return f"error: cannot read {e.filename}: {e.strerror or e}"
    if isinstance(e, MemoryError):
        return "error: not enough memory for this input; use smaller maps or free memory, then retry"
    message = " ".join(str(e).split()) or "(no message)"
    if len(message) > 300:
        message = message[:297] + "..."
    return (
        f"internal error: {type(e).__name__}: {message} \N{EM DASH} please report it {REPORT_TO}; "
        "rerun with --debug for the traceback"
    )
