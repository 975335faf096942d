"""What the command groups share: reading materials and NAME=VALUE lists, the probe scene, and the
options several commands take (``--fix``, ``--strategy``, the renderers, ``--force``, ``--allow-path``)."""

from __future__ import annotations

import argparse
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Protocol

from matremap.core.fit import STRATEGIES
from matremap.core.material import Material, parse_material
from matremap.core.objective import OBJECTIVES
from matremap.core.scene import Scene, parse_lights, parse_probe
from matremap.errors import MatremapError


class Subparsers(Protocol):
    """What a command group needs of ``ArgumentParser.add_subparsers()``: adding a command."""

    def add_parser(self, name: str, **kwargs: Any) -> argparse.ArgumentParser: ...


def add_command(subparsers: Subparsers, name: str, help: str, examples: str) -> argparse.ArgumentParser:
    """A subcommand's parser: ``help`` is its line in ``matremap --help`` and the description of its own
    ``--help``, ``examples`` (kept as written) come below the options."""
    return subparsers.add_parser(name, help=help, description=help, epilog=examples, formatter_class=HelpFormatter)


#: the release after which the old spellings of renamed options (:func:`add_renamed`) are no longer accepted
OLD_NAMES_REMOVED_IN = "0.3"


class Renamed(argparse.Action):
    """Stores an option's value; given under one of its ``old`` spellings (hidden from ``--help``), it says
    on stderr that the spelling is deprecated and which one to use."""

    def __init__(self, option_strings: Sequence[str], dest: str, old: Sequence[str] = (), **kwargs: Any) -> None:
        self.old = tuple(old)
        super().__init__(option_strings, dest, **kwargs)

    def __call__(
        self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: Any, option: str | None = None
    ) -> None:
        if option in self.old:
            import sys

            note = f"{option} is deprecated (removed in {OLD_NAMES_REMOVED_IN}); use {self.option_strings[0]}"
            print(f"matremap: note: {note}", file=sys.stderr)
        setattr(namespace, self.dest, values)


def add_renamed(p: argparse.ArgumentParser, *flags: str, old: Sequence[str], **kwargs: Any) -> None:
    """An option whose earlier spellings ``old`` still work for a release (hidden, with a note)."""
    p.add_argument(*flags, *old, action=Renamed, old=old, **kwargs)


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """argparse's, with examples kept as written and the old spellings of renamed options left out."""

    def _format_action_invocation(self, action: argparse.Action) -> str:
        old = getattr(action, "old", ())
        if old:
            import copy

            action = copy.copy(action)
            action.option_strings = [o for o in action.option_strings if o not in old]
        return super()._format_action_invocation(action)


def load_material(arg: str) -> Material:
    """A material from a JSON file path, inline JSON, or the compact form MODEL,name=value,..."""
    text = arg.strip()
    if text.startswith("{"):  # inline JSON: never a path (a long one is not even a valid file name)
        return parse_material(text)
    if text.endswith(".json") or os.sep in text or _is_file(text):
        from matremap.core.documents import read_document

        return Material.from_dict(read_document(text, "material file"), where=text)
    return parse_material(text)


def _is_file(text: str) -> bool:
    """Whether ``text`` names an existing file; a string no file can have (too long) does not."""
    try:
        return Path(text).is_file()
    except (OSError, ValueError):
        return False


def parse_assignments(items: Sequence[str], flag: str) -> dict[str, str]:
    """``NAME=VALUE`` items of a repeatable option (``flag`` names it in errors) as a dict of strings."""
    out: dict[str, str] = {}
    for item in items:
        if "=" not in item:
            raise MatremapError(f"{flag} takes NAME=VALUE, got {item!r}")
        k, v = item.split("=", 1)
        out[k.strip()] = v.strip()
    return out


def make_scene(args: argparse.Namespace) -> Scene:
    """The probe scene of ``--probe``, ``--light`` and ``--size``."""
    return parse_probe(getattr(args, "probe", "point"), parse_lights(args.light), args.size)


def add_scene_args(p: argparse.ArgumentParser) -> None:
    """``--probe``, ``--light`` and ``--size``: the probe scene (read back with :func:`make_scene`)."""
    add_probe_option(p)
    add_light_option(p, "point lights of the probe scene, each at DEG degrees from the view axis")
    p.add_argument(
        "--size",
        type=int,
        default=None,
        metavar="N",
        help="probe image side in pixels, N x N (default 128 for the point probe, 64 for env, mixed and transmission; "
        "the paper used 512)",
    )


PROBE_HELP = (
    "the light fits are made under: point (the paper's point lights, --light), env (the sphere under the built-in "
    "studio environment at 30, 150 and 270 degrees; env:FILE.exr for your own lat-long map), mixed (both; "
    "mixed:FILE.exr) or transmission (the point lights and the sphere before a tiled background, what a glass "
    "lets through; taken by itself for a source that transmits)"
)


def add_probe_option(p: argparse.ArgumentParser, default: str = "point", help: str = PROBE_HELP) -> None:
    """``--probe``: the light the fit is made under (:func:`matremap.core.scene.parse_probe`)."""
    p.add_argument(
        "--probe", default=default, metavar="KIND[:FILE]", help=f"{help} (default {default}; docs/fitting.md)"
    )


def add_objective_option(p: argparse.ArgumentParser, default: str = "l2") -> None:
    """``--objective``: what a fit makes small (:mod:`matremap.core.objective`)."""
    p.add_argument(
        "--objective",
        choices=OBJECTIVES,
        default=default,
        help="what the fit makes small: l2 (linear HDR, the paper's), log (relative differences) or ssim (1 - SSIM "
        f"of the probe views, what the evaluation judges) (default {default}; docs/fitting.md)",
    )


def add_light_option(p: argparse.ArgumentParser, help: str) -> None:
    """``--light DEG [DEG ...]``: the probe scene's point lights (angles in degrees)."""
    p.add_argument("--light", nargs="+", metavar="DEG", help=f"{help} (default: one at 0, a headlight)")


def add_target_option(p: argparse.ArgumentParser, help: str = "target model id (see `matremap models`)") -> None:
    """``--to MODEL`` (``args.target``): the model to remap onto; ``--target`` is its old spelling."""
    add_renamed(p, "--to", old=["--target"], dest="target", required=True, metavar="MODEL", help=help)


def add_fix_option(p: argparse.ArgumentParser, help: str) -> None:
    """The repeatable ``--fix NAME=VALUE`` (read with :func:`parse_assignments`)."""
    p.add_argument("--fix", action="append", default=[], metavar="NAME=VALUE", help=help)


def add_free_option(p: argparse.ArgumentParser, help: str) -> None:
    """The repeatable ``--free NAME``: fit a parameter the target model holds by default."""
    p.add_argument("--free", action="append", default=[], metavar="NAME", help=help)


def add_strategy_option(p: argparse.ArgumentParser) -> None:
    """``--strategy``: one of the fit strategies of :mod:`matremap.core.fit`."""
    p.add_argument(
        "--strategy",
        choices=STRATEGIES,
        default="two-stage",
        help="how the fit splits the parameters: two-stage fits the diffuse ones to the diffuse-only render and the "
        "specular ones to the specular-only render, simple all at once, three-stage refines two-stage jointly, "
        "separable solves the linear ones in closed form (default %(default)s; docs/fitting.md)",
    )


def add_renderer_options(p: argparse.ArgumentParser) -> None:
    """``--source-renderer`` and ``--target-renderer``; None leaves the choice to the model."""
    for side in ("source", "target"):
        p.add_argument(
            f"--{side}-renderer",
            metavar="NAME",
            help=f"renderer that draws the {side} material: embedded, mitsuba3 or cycles (default: the model's "
            "own renderer, or the embedded one where it emulates it; see `matremap renderers`)",
        )


def add_executor_options(p: argparse.ArgumentParser, unit: str) -> None:
    """``--workers``, ``--scheduler`` and ``--dask-local``: where the ``unit``s (fits, materials) run
    (read with :func:`matremap.sweep.executors.make_executor`)."""
    p.add_argument(
        "--workers",
        type=int,
        metavar="N",
        help=f"local worker processes, one {unit} each at a time (default: every core; 1 runs in this process)",
    )
    p.add_argument(
        "--scheduler", metavar="ADDRESS", help="run on a running Dask scheduler instead, e.g. tcp://host:8786"
    )
    p.add_argument(
        "--dask-local",
        type=int,
        metavar="N",
        help="run on a Dask cluster of N worker processes started here (needs pip install 'matremap[dask]')",
    )


def add_json_option(p: argparse.ArgumentParser, what: str = "the listing") -> None:
    """``--json``: print ``what`` as JSON on stdout instead of text."""
    p.add_argument("--json", action="store_true", help=f"print {what} as JSON on stdout (for scripts)")


def add_force_option(p: argparse.ArgumentParser, help: str) -> None:
    """``--force``: overwrite existing outputs (``help`` says which)."""
    p.add_argument("--force", action="store_true", help=help)


def add_allow_path_option(p: argparse.ArgumentParser) -> None:
    """The repeatable ``--allow-path DIR``: a folder outside the asset's own that the files a material
    file names may lie in (entered with :func:`matremap.formats.confine.allowed_paths`)."""
    p.add_argument(
        "--allow-path",
        action="append",
        default=[],
        metavar="DIR",
        help="let the material file's textures and buffers lie in DIR too (repeatable; by default only "
        "files inside the material file's own folder are read)",
    )
