"""The ``matremap`` command.

Subcommands are verbs: ``models`` lists the reflectance models, ``render`` draws a material on
the probe sphere, ``fit`` remaps a uniform material onto another model. Errors print one line on
stderr and exit with status 2; nothing is written when a command fails. What the system refuses is one
line too: a full disk or quota exit 4 naming the folder, a file it will not let matremap read or write
exit 2. An exception no command expected is one line (``internal error: Type: message``, exit 70);
``matremap --debug COMMAND`` prints its traceback. Every line is printable whatever bytes a file name
holds, and at most :data:`~matremap.errors.MAX_LINE` characters.

Each command group is a module that adds its commands' parsers and holds their handlers:
:mod:`.inspect` (models, renderers, transforms), :mod:`.fit` (render, fit, apply), :mod:`.sweep`
(sweep, sweep-report, export), :mod:`.learn` (learn, chain), :mod:`.maps` (convert, evaluate,
remap) and :mod:`.doctor` (doctor); :mod:`.common` holds what they share. This module assembles the
parser and runs a command.
"""

from __future__ import annotations

import argparse
import codecs
import os
import sys
import traceback
from collections.abc import Callable, Sequence
from typing import NoReturn

from matremap import __version__
from matremap.cli import doctor, fit, inspect, learn, maps, sweep
from matremap.cli.common import Subparsers
from matremap.errors import (
    EXIT_INTERNAL,
    EXIT_INTERRUPTED,
    EXIT_QUALITY,
    MatremapError,
    encode_paths,
    one_line,
    system_error,
)

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
#: the commands that write images (through OpenImageIO, which takes UTF-8 file names only) under -o
IMAGE_WRITERS = ("render", "fit", "convert", "evaluate", "remap")


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
    printable_paths()
    parser = build_parser()
    args = parser.parse_args(argv)
    from matremap.sweep.executors import limit_blas_threads

    limit_blas_threads()
    try:
        if args.command in IMAGE_WRITERS:
            check_output_names(args)
        return args.func(args)
    except MatremapError as e:
        return _refused(e)
    except KeyboardInterrupt:
        print("matremap: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:  # the reader went away (`matremap transforms | head`): stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except Exception as e:  # not the input's fault as far as the code knows: one line, not a traceback
        known = system_error(e, written_folders(args))
        if known is not None:
            return _refused(known)
        if args.debug:
            traceback.print_exc()
        print(f"matremap: {describe_unexpected(e)}", file=sys.stderr)
        return EXIT_INTERNAL


def printable_paths() -> None:
    """Let stdout and stderr print any file name: the bytes of a name that are not UTF-8 are written
    back as they were (:func:`matremap.errors.encode_paths`), never an encoding error."""
    codecs.register_error("matremap-paths", encode_paths)
    for stream in (sys.stdout, sys.stderr):
        reconfigure = getattr(stream, "reconfigure", None)
        if reconfigure is not None:
            reconfigure(errors="matremap-paths")


def check_output_names(args: argparse.Namespace) -> None:
    """Refuse, before any work, an output name (``-o``, ``--write``) that images cannot be written under."""
    from matremap.core.imageio import oiio_name

    for option, name in (("-o", getattr(args, "output", None)), ("--write", getattr(args, "write", None))):
        if isinstance(name, str):
            try:
                oiio_name(os.path.abspath(name))
            except MatremapError as e:
                raise MatremapError(f"{option} {e}") from None


def _refused(e: MatremapError) -> int:
    """Print a refusal's one line; its exit status."""
    text = one_line(str(e))
    kind = "FAILED" if e.exit_code == EXIT_QUALITY else "error"
    # a verdict line already starts with its word ("FAILED: clamped ..."): not said twice
    print(f"matremap: {text}" if text.startswith(f"{kind}:") else f"matremap: {kind}: {text}", file=sys.stderr)
    return e.exit_code


def written_folders(args: argparse.Namespace) -> list[str]:
    """The files and folders a command writes: its ``-o``, its ``--db``, and the cache."""
    from matremap.core.diskcache import cache_dir

    named = [getattr(args, k, None) for k in ("output", "db")]
    return [os.fspath(p) for p in named if isinstance(p, (str, os.PathLike))] + [os.fspath(cache_dir())]


def describe_unexpected(e: BaseException) -> str:
    """The one line for an exception no command turned into a MatremapError and the system did not
    raise (:func:`matremap.errors.system_error`): an internal error, with where to report it."""
    known = system_error(e)
    if known is not None:
        return f"error: {one_line(str(known))}"
    message = one_line(str(e), 300)
    return (
        f"internal error: {type(e).__name__}: {message} \N{EM DASH} please report it {REPORT_TO}; "
        "rerun with --debug for the traceback"
    )
