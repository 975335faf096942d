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
from matremap.core.scene import Scene, parse_lights
from matremap.errors import MatremapError


class Subparsers(Protocol):
    """What a command group needs of ``ArgumentParser.add_subparsers()``: adding a command."""

    def add_parser(self, name: str, **kwargs: Any) -> argparse.ArgumentParser: ...


def add_command(subparsers: Subparsers, name: str, help: str, examples: str | None = None) -> argparse.ArgumentParser:
    """A subcommand's parser, with its examples (kept as written) below the options."""
    if examples is None:
        return subparsers.add_parser(name, help=help)
    return subparsers.add_parser(name, help=help, epilog=examples, formatter_class=argparse.RawDescriptionHelpFormatter)


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
    """The probe scene of ``--light`` and ``--size``."""
    return Scene.probe(lights=parse_lights(args.light), resolution=args.size)


def add_scene_args(p: argparse.ArgumentParser) -> None:
    """``--light`` and ``--size``: the probe scene (read back with :func:`make_scene`)."""
    p.add_argument("--light", nargs="+", metavar="DEG", help="light angles from the view axis (default 0: headlight)")
    p.add_argument("--size", type=int, default=128, metavar="N", help="image resolution (default 128)")


def add_fix_option(p: argparse.ArgumentParser, help: str) -> None:
    """The repeatable ``--fix NAME=VALUE`` (read with :func:`parse_assignments`)."""
    p.add_argument("--fix", action="append", default=[], metavar="NAME=VALUE", help=help)


def add_free_option(p: argparse.ArgumentParser, help: str) -> None:
    """The repeatable ``--free NAME``: fit a parameter the target model holds by default."""
    p.add_argument("--free", action="append", default=[], metavar="NAME", help=help)


def add_strategy_option(p: argparse.ArgumentParser) -> None:
    """``--strategy``: one of the fit strategies of :mod:`matremap.core.fit`."""
    p.add_argument("--strategy", choices=STRATEGIES, default="two-stage")


def add_renderer_options(p: argparse.ArgumentParser) -> None:
    """``--source-renderer`` and ``--target-renderer``; None leaves the choice to the model."""
    for side in ("source", "target"):
        p.add_argument(
            f"--{side}-renderer",
            metavar="NAME",
            help="default: the model's own renderer, see `matremap renderers`",
        )


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
