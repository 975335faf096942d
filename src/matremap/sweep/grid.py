"""Grids over a model's parameter space, for sweeps.

A grid is a list of axes; each axis sweeps one parameter (or one channel of an RGB parameter,
``name.r`` / ``name.g`` / ``name.b``) over a range or an explicit list of values. RGB parameters
named without a channel are swept as grey. Parameters not on the grid keep the base material's
values. Points are the Cartesian product, last axis fastest.

Written on the command line::

    alpha=0.005:0.99:35,specularReflectance=0.02:0.232:23      # lo:hi:count, linear spacing
    alpha=0.01:1:20:log                                         # log spacing
    variant=ward;balanced , F0=0.02;0.04;0.08                   # explicit lists (';'-separated)

or as TOML::

    [grid]
    alpha = { start = 0.005, stop = 0.99, count = 35 }
    specularReflectance = { start = 0.02, stop = 0.232, count = 23, spacing = "linear" }
    variant = ["ward"]
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from matremap.core.documents import read_document
from matremap.core.material import Material
from matremap.core.models import ModelSpec
from matremap.errors import MatremapError

CHANNELS = {"r": 0, "g": 1, "b": 2}


@dataclass(frozen=True)
class Axis:
    """One swept parameter (``channel`` None = all channels / grey) and its values."""

    name: str
    values: tuple[Any, ...]
    channel: int | None = None

    @property
    def label(self) -> str:
        return self.name if self.channel is None else f"{self.name}.{'rgb'[self.channel]}"

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "channel": self.channel, "values": list(self.values)}


@dataclass(frozen=True)
class Grid:
    axes: tuple[Axis, ...]

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(len(a.values) for a in self.axes)

    def __len__(self) -> int:
        return math.prod(self.shape)

    def indices(self) -> Iterator[tuple[int, ...]]:
        return itertools.product(*(range(n) for n in self.shape))

    def values_at(self, index: tuple[int, ...]) -> dict[str, Any]:
        """The swept values of a point, keyed by axis label."""
        return {a.label: a.values[i] for a, i in zip(self.axes, index, strict=True)}

    def material(self, base: Material, index: tuple[int, ...]) -> Material:
        """The base material with this point's values applied."""
        updates: dict[str, Any] = {}
        for a, i in zip(self.axes, index, strict=True):
            v = a.values[i]
            if a.channel is None:
                updates[a.name] = v
            else:
                rgb = np.array(updates.get(a.name, base.values[a.name]), dtype=float)
                rgb[a.channel] = v
                updates[a.name] = rgb
        return base.with_params(updates)

    def to_dict(self) -> dict[str, Any]:
        return {"axes": [a.to_dict() for a in self.axes]}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Grid:
        return cls(tuple(Axis(a["name"], tuple(a["values"]), a.get("channel")) for a in d["axes"]))


def _number(text: str, where: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise MatremapError(f"grid {where}: {text!r} is not a number") from None
    if not math.isfinite(v):
        raise MatremapError(f"grid {where}: {text!r} is not finite")
    return v


def _range(lo: float, hi: float, count: int, spacing: str, where: str) -> tuple[float, ...]:
    if count < 1:
        raise MatremapError(f"grid {where}: the count must be at least 1, got {count}")
    if count > 1 and lo == hi:
        raise MatremapError(f"grid {where}: empty range {lo:g}:{hi:g} with {count} points")
    if spacing == "log":
        if lo <= 0 or hi <= 0:
            raise MatremapError(f"grid {where}: log spacing needs positive bounds, got {lo:g}:{hi:g}")
        return tuple(float(v) for v in np.geomspace(lo, hi, count))
    if spacing != "linear":
        raise MatremapError(f"grid {where}: spacing must be 'linear' or 'log', got {spacing!r}")
    return tuple(float(v) for v in np.linspace(lo, hi, count))


def _axis(spec: ModelSpec, label: str, values: tuple[Any, ...]) -> Axis:
    name, _, chan = label.partition(".")
    if name in spec.option_names:
        if chan:
            raise MatremapError(f"grid: option {name} has no channels")
        opt = spec.option(name)
        bad = [v for v in values if str(v) not in opt.choices]
        if bad:
            raise MatremapError(f"grid: {name}={bad[0]!r} is not one of {', '.join(opt.choices)}")
        return Axis(name, tuple(str(v) for v in values))
    p = spec.param(name)  # raises with the valid names
    channel = None
    if chan:
        if p.channels != 3 or chan not in CHANNELS:
            raise MatremapError(f"grid: {label} names a channel; only RGB parameters have .r, .g, .b")
        channel = CHANNELS[chan]
    lo, hi = p.bounds
    for v in values:
        if not isinstance(v, (int, float)) or not lo <= v <= hi:
            raise MatremapError(f"grid: {label}={v!r} is outside the range [{lo:g}, {hi:g}] of {spec.id}")
    return Axis(name, tuple(float(v) for v in values), channel)


def parse_grid(text: str, spec: ModelSpec) -> Grid:
    """A grid from the command-line form, or from a TOML file when ``text`` names one."""
    if text.strip().endswith(".toml"):
        return load_grid_toml(Path(text.strip()), spec)
    axes = []
    for item in (s.strip() for s in text.split(",")):
        if not item:
            continue
        if "=" not in item:
            raise MatremapError(f"grid: {item!r} is not NAME=LO:HI:COUNT or NAME=V1;V2;...")
        label, body = (s.strip() for s in item.split("=", 1))
        if ";" in body or ":" not in body:
            parts = [s.strip() for s in body.split(";") if s.strip()]
            if not parts:
                raise MatremapError(f"grid: {label} has no values")
            is_option = label in spec.option_names
            values = tuple(parts) if is_option else tuple(_number(s, label) for s in parts)
        else:
            parts = body.split(":")
            if len(parts) not in (3, 4):
                raise MatremapError(f"grid: {label}={body!r} is not LO:HI:COUNT[:log]")
            lo, hi = _number(parts[0], label), _number(parts[1], label)
            try:
                count = int(parts[2])
            except ValueError:
                raise MatremapError(f"grid: {label}: the count {parts[2]!r} is not an integer") from None
            values = _range(lo, hi, count, parts[3] if len(parts) == 4 else "linear", label)
        axes.append(_axis(spec, label, values))
    return _checked(axes)


def load_grid_toml(path: Path, spec: ModelSpec) -> Grid:
    doc = read_document(path, "grid file")
    table = doc.get("grid") if isinstance(doc, dict) else None
    if not isinstance(table, dict) or not table:
        raise MatremapError(f"grid file {path} needs a [grid] table with one entry per swept parameter")
    axes = []
    for label, entry in table.items():
        if isinstance(entry, list):
            values = tuple(entry)
        elif isinstance(entry, dict):
            unknown = set(entry) - {"start", "stop", "count", "spacing"}
            if unknown or not {"start", "stop", "count"} <= set(entry):
                raise MatremapError(f"grid file {path}: {label} needs start, stop, count (and optionally spacing)")
            values = _range(
                float(entry["start"]),
                float(entry["stop"]),
                int(entry["count"]),
                str(entry.get("spacing", "linear")),
                label,
            )
        else:
            values = (entry,)
        axes.append(_axis(spec, label, values))
    return _checked(axes)


def _checked(axes: list[Axis]) -> Grid:
    if not axes:
        raise MatremapError("grid: no parameter to sweep; give e.g. alpha=0.01:1:20")
    labels = [a.label for a in axes]
    dupes = {x for x in labels if labels.count(x) > 1}
    if dupes:
        raise MatremapError(f"grid: {', '.join(sorted(dupes))} given twice")
    names = {a.name for a in axes if a.channel is None}
    both = [a.label for a in axes if a.channel is not None and a.name in names]
    if both:
        raise MatremapError(f"grid: {both[0]} and its grey parameter are both swept; sweep one or the other")
    return Grid(tuple(axes))
