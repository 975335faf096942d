"""Converting spatially-varying materials: a learned transform applied to every texel of a map set.

:func:`convert` streams the map set in bands of rows: each band of every source map is read
(:class:`~matremap.svbrdf.textures.MapReader`), turned into parameter arrays (constants broadcast),
passed through :meth:`Transform.apply`, and the target maps it drives are written band by band
(:class:`~matremap.svbrdf.textures.MapWriter`) in the format, bit depth and colour space of the matching
input map, together with ``outside_domain.png`` (8-bit, 255 where a texel lies outside the
transform's training domain). The normal map is copied byte for byte and a ``material.json``
describes the result. Memory stays bounded by the band size, whatever the map size.

Parallelism: OpenImageIO's Python calls hold the GIL, and PNG encoding dominates the cost, so
``workers`` > 1 starts that many processes, each streaming the (cheap) inputs and the transform
and writing its share of the output files.

Everything is written under temporary names in the output folder and renamed only when all of it
is complete; a failure (a NaN in the last band, a truncated file) leaves nothing behind.
"""

from __future__ import annotations

import contextlib
import json
import os
import sys
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from matremap.core.atomic import AtomicFiles
from matremap.core.models import ModelSpec
from matremap.dialects import get_model
from matremap.errors import MatremapError
from matremap.regress import quantities as qty
from matremap.regress.transform import Transform
from matremap.svbrdf.quality import VARIES
from matremap.svbrdf.textures import ImageInfo, MapReader, MapSet, MapWriter, map_values, output_info

MASK_NAME = "outside_domain.png"
MANIFEST_NAME = "material.json"
#: relative spread under which a converted parameter is the same at every texel (float32 round-off)
UNIFORM_OUTPUT = 1e-6
#: quantity -> the file-name convention its maps get
_CONVENTION = {"roughness": "roughness", "reflectance": "specular", "diffuse": "diffuse"}
#: F0 steps counted between 0 and 1 to find the median F0 of a parameter written as one constant (1e-5 apart)
F0_STEPS = 100_001


@dataclass
class ConvertReport:
    texels: int
    outside: int
    files: list[Path]
    seconds: float
    model: str
    notes: list[str] = field(default_factory=list)
    #: values clipped to fit an 8/16-bit file's [0, 1] (the notes say which maps)
    clipped: int = 0
    #: values the transform asked for beyond what the target model accepts, clipped to its bounds
    bounded: int = 0
    #: texels whose F0 lies beyond :data:`~matremap.svbrdf.quality.VARIES` from a parameter written as one
    #: constant (:func:`one_constant`)
    approximated: int = 0

    @property
    def outside_fraction(self) -> float:
        return self.outside / self.texels if self.texels else 0.0

    def to_dict(self) -> dict[str, Any]:
        return {
            "texels": self.texels,
            "outside": self.outside,
            "files": [str(f) for f in self.files],
            "seconds": self.seconds,
            "model": self.model,
            "notes": self.notes,
        }


# ---------------------------------------------------------------------------------------------
# which parameters feed and which are driven


def source_params(spec: ModelSpec, quantity: str) -> list[str]:
    """The source parameters a quantity is read from."""
    if quantity == "roughness":
        p = qty.roughness_param(spec)
        return [p.name] if p else []
    if quantity == "diffuse":
        p = qty.diffuse_param(spec)
        return [p.name] if p else []
    if quantity == "reflectance" and spec.reflectance is not None:
        return list(spec.reflectance.map_params)
    return []


def constant_param(t: Transform) -> str | None:
    """The target parameter that the transform's F0 drives and that the target's renderers take as one
    number only (Mitsuba 3 principled's ``specular``): written as one constant, not a map, or None."""
    tgt = get_model(t.target)
    last = t.steps[-1] if t.method == "chain" else t
    if tgt.reflectance is None or "reflectance" not in last.mappings:
        return None
    return tgt.reflectance.constant_param(tgt.specialise(last.template).diffuse_only is None)


def target_param(spec: ModelSpec, quantity: str, metal: bool = True) -> str | None:
    """The target parameter a quantity drives; ``metal``: whether the target is held metallic (a glTF
    dielectric's F0 goes to its specular colour, a metal's to its base colour)."""
    if quantity == "roughness":
        p = qty.roughness_param(spec)
        return p.name if p else None
    if quantity == "diffuse":
        p = qty.diffuse_param(spec)
        return p.name if p else None
    if quantity == "reflectance" and spec.reflectance is not None:
        return spec.reflectance.driven_param(metal)
    return None


@dataclass
class _Output:
    param: str | None  # None: the outside-domain mask
    path: Path  # final name
    tmp: str  # temporary name beside it
    info: ImageInfo
    cost: float = 1.0


@dataclass
class _Plan:
    transform: dict[str, Any]
    model: str
    maps: dict[str, str]
    infos: dict[str, ImageInfo]
    constants: dict[str, Any]
    size: tuple[int, int]
    rows: int
    #: the target parameter written as one constant (:func:`constant_param`), whose F0 the mask group counts
    constant: str | None = None


def _bands(height: int, rows: int) -> list[tuple[int, int]]:
    return [(y, min(y + rows, height)) for y in range(0, height, rows)]


def _check_transform(map_set: MapSet, t: Transform) -> list[str]:
    notes: list[str] = []
    src = get_model(t.source)
    if src.id != map_set.model:
        raise MatremapError(
            f"the transform maps {t.source} -> {t.target} but the maps are for {map_set.model}; "
            f"use a transform learned from {map_set.model}"
        )
    for k, v in t.source_options.items():
        given = map_set.constants.get(k)
        if given is None:
            notes.append(f"{k} not given by the map set; taking the transform's {k}={v}")
        elif given != v:
            raise MatremapError(
                f"the maps use {k}={given} but the transform was trained on {k}={v}; "
                f"use a transform learned for {k}={given}"
            )
    first = t.steps[0] if t.method == "chain" else t
    for q, (lo, hi) in first.domain.items():
        for name in source_params(src, q):
            if hi > lo and name not in map_set.maps and name not in map_set.constants:
                raise MatremapError(
                    f"the map set has no map or value for {name} ({q}), which the transform "
                    f"needs; add a *_{_CONVENTION.get(q, q)} map or set params.{name} in "
                    f"material.json"
                )
            if hi <= lo and name in map_set.maps:
                notes.append(
                    f"the transform was trained with {q} held at {lo:g}; texels of "
                    f"{map_set.maps[name].name} with other values count as outside its domain"
                )
    return notes


def _prefix(map_set: MapSet) -> str:
    stems = [f.stem for f in map_set.maps.values()]
    heads = {s.rsplit("_", 1)[0] for s in stems if "_" in s}
    return heads.pop() if len(heads) == 1 and len(stems) == sum("_" in s for s in stems) else "material"


# ---------------------------------------------------------------------------------------------
# the per-band work (runs in the calling process or in worker processes)


def _band_values(plan: _Plan, readers: dict[str, MapReader], y0: int, y1: int) -> dict[str, np.ndarray]:
    spec = get_model(plan.model)
    values: dict[str, np.ndarray] = {}
    for name, r in readers.items():
        values[name] = map_values(spec, name, r.read_rows(y0, y1), r.path, y0)
    shape = (y1 - y0, plan.size[1])
    for name, v in plan.constants.items():
        if name in spec.param_names and name not in values:
            p = spec.param(name)
            a = np.asarray(v, dtype=np.float32)
            values[name] = np.broadcast_to(
                a.reshape(-1)[0] if p.channels == 1 else np.broadcast_to(a, (3,)),
                shape if p.channels == 1 else (*shape, 3),
            )
    return values


def _run(plan: _Plan, outputs: list[_Output], progress_every: int = 0, progress=None) -> dict[str, Any]:
    """Stream every band through the transform and write ``outputs``; return the outside count,
    clipped counts and the value of every target parameter at texel (0, 0)."""
    t = Transform.from_dict(plan.transform)
    readers: dict[str, MapReader] = {}
    writers: list[tuple[_Output, MapWriter]] = []
    outside = 0
    bounded: dict[str, int] = {}
    first: dict[str, Any] = {}
    ranges: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    count_f0 = plan.constant is not None and any(o.param is None for o in outputs)  # once: in the mask's group
    f0_counts = np.zeros(F0_STEPS, dtype=np.int64) if count_f0 else None
    try:
        for name, path in plan.maps.items():
            info = plan.infos[name]
            readers[name] = MapReader(path, info.colorspace)
        for o in outputs:
            writers.append((o, MapWriter(o.tmp, o.info)))
        bands = _bands(plan.size[0], plan.rows)
        for i, (y0, y1) in enumerate(bands):
            values = _band_values(plan, readers, y0, y1)
            out, off = t.apply(values, clipped=bounded)
            outside += int(np.count_nonzero(off))
            if i == 0:
                first = {k: np.asarray(v)[(0,) * (np.ndim(off))].tolist() for k, v in out.items()}
            if f0_counts is not None:
                f0 = qty.read(get_model(t.target), out)["reflectance"].mean(axis=-1)
                f0_counts += np.bincount(_f0_step(f0).ravel(), minlength=F0_STEPS)
            for o, w in writers:
                w.write_rows(y0, off.astype(np.float32) if o.param is None else out[o.param])
                if o.param is not None:
                    ranges[o.param] = _band_range(out[o.param], ranges.get(o.param))
            if progress is not None:
                progress(y1, plan.size[0])
        for _, w in writers:
            w.close()
        clipped = {o.param: w.clipped for o, w in writers if o.param}
        done = {"outside": outside, "clipped": clipped, "bounded": bounded, "first": first, "ranges": ranges}
        return {**done, "f0_counts": f0_counts}
    finally:
        for r in readers.values():
            r.close()
        for _, w in writers:
            try:
                w.close()
            except Exception:  # noqa: BLE001 - the first error is the one to report
                pass


def _f0_step(f0: np.ndarray) -> np.ndarray:
    """F0 in [0, 1] as the index of its step of :data:`F0_STEPS`."""
    return np.rint(np.clip(f0, 0.0, 1.0) * (F0_STEPS - 1)).astype(np.int64)


def one_constant(t: Transform, name: str, f0_counts: np.ndarray) -> tuple[float, int, str | None]:
    """The value of ``name`` (:func:`constant_param`) written for every texel: the one that gives the median F0
    the texels ask for (``f0_counts``: texels per F0 step), through the target's own write-back; the texels whose
    F0 lies more than :data:`~matremap.svbrdf.quality.VARIES` from it (the gate counts them with the clamped values);
    and a note when they ask for more than one F0 (None when all ask for the same)."""
    tgt = get_model(t.target)
    last = t.steps[-1] if t.method == "chain" else t
    steps = np.arange(F0_STEPS) / (F0_STEPS - 1)
    total = int(f0_counts.sum())
    cum = np.cumsum(f0_counts)  # the middle texel's F0, or the mean of the two middle ones' (numpy's median)
    lo, hi = (int(np.searchsorted(cum, 0.5 * total, side=side)) for side in ("left", "right"))
    median = 0.5 * float(steps[lo] + steps[min(hi, F0_STEPS - 1)]) if total else 0.0
    written = qty.write(tgt, {"reflectance": np.full((1, 3), median)}, last.template)
    value = float(np.ravel(written[name])[0])
    off = int(f0_counts[np.abs(steps - median) > VARIES].sum())
    asked = steps[f0_counts > 0]
    if asked.size <= 1:
        return value, 0, None
    note = (
        f"{name}: {t.target} takes it as one number, not a map: written as {value:.4g} (F0 {median:.4g}, the median "
        f"the texels ask for, which range over {asked.min():.4g}-{asked.max():.4g}); {off} texels "
        f"({100 * off / max(total, 1):.1f}%) ask for an F0 more than {VARIES:g} from it"
    )
    return value, off, note


def _write_constant(t: Transform, name: str | None, result: dict[str, Any], notes: list[str]) -> int:
    """Put the one value of the parameter ``name`` (:func:`one_constant`, none when None) among the values the
    manifest takes (``result["first"]``), with its note; return the texels it approximates."""
    if name is None:
        return 0
    value, approximated, note = one_constant(t, name, result["f0_counts"])
    result["first"][name] = value
    notes += [note] if note else []
    return approximated


def _band_range(values: Any, seen: tuple[np.ndarray, np.ndarray] | None) -> tuple[np.ndarray, np.ndarray]:
    """The per-channel (min, max) of a parameter's values so far, this band's taken in."""
    a = np.asarray(values, dtype=np.float64)
    a = a.reshape(-1, a.shape[-1]) if a.ndim == 3 else a.reshape(-1, 1)
    lo, hi = a.min(axis=0), a.max(axis=0)
    return (lo, hi) if seen is None else (np.minimum(seen[0], lo), np.maximum(seen[1], hi))


def uniform_outputs(results: Sequence[Mapping[str, Any]], tolerance: float = UNIFORM_OUTPUT) -> set[str]:
    """The target parameters whose converted values are the same at every texel (within ``tolerance``,
    relative): a map of them carries nothing a constant does not, and a renderer that takes the parameter
    as a number only (Mitsuba 3's rough plastic ``alpha`` and ``int_ior``) refuses a map of it. A transform
    maps every quantity, so a uniform roughness used to become a constant alpha *map*."""
    out = set()
    for r in results:
        for name, (lo, hi) in r["ranges"].items():
            if np.all(hi - lo <= tolerance * np.maximum(1.0, np.abs(hi))):
                out.add(name)
    return out


def _drop_uniform(
    outputs: list[_Output], results: Sequence[Mapping[str, Any]], files: AtomicFiles, notes: list[str]
) -> list[_Output]:
    """The outputs to keep as maps: those of :func:`uniform_outputs` leave the group (their values go into
    the manifest as constants), with a note each. When every parameter is uniform, one map stays (a map set
    is maps; a colour one where there is one, as every renderer takes a colour as a map): a glTF whose only
    texture varied in alpha (ClearCoatTest's Partial_Coating) lost every map and its remap was refused
    with "maps/material.json binds no map"."""
    uniform = uniform_outputs(results)
    params = [o for o in outputs if o.param is not None]
    if params and all(o.param in uniform for o in params):
        keep = next((o for o in params if o.info.channels >= 3), params[0])
        uniform = uniform - {keep.param}
    for o in outputs:
        if o.param in uniform:
            files.discard(o.path)
            notes.append(f"{o.param} is the same at every texel: written as a constant, not a map")
    return [o for o in outputs if o.param not in uniform]


def _split(outputs: list[_Output], n: int) -> list[list[_Output]]:
    groups: list[list[_Output]] = [[] for _ in range(n)]
    load = [0.0] * n
    for o in sorted(outputs, key=lambda o: -o.cost):
        i = load.index(min(load))
        groups[i].append(o)
        load[i] += o.cost
    return [g for g in groups if g]


# ---------------------------------------------------------------------------------------------


def convert(
    map_set: MapSet,
    transforms: Transform | Sequence[Transform],
    out_dir: str | os.PathLike,
    tile_rows: int | None = None,
    workers: int = 2,
    progress: Callable[[int, int], None] | None = None,
    force: bool = False,
    out_format: str | None = None,
) -> ConvertReport:
    """Apply a transform (or a chain of them) to every texel of ``map_set``; write the target maps,
    ``outside_domain.png``, a copy of the normal map and ``material.json`` into ``out_dir``, all or
    nothing (:class:`~matremap.core.atomic.AtomicFiles`).

    ``tile_rows``: rows per band (default: about a million texels per band); ``workers``: processes
    (1 works in this process); ``progress(rows_done, rows)`` is called in this process;
    ``out_format``: a key of :data:`matremap.svbrdf.textures.OUT_FORMATS` to override the inputs' format.
    """
    start = time.perf_counter()
    ts = [transforms] if isinstance(transforms, Transform) else list(transforms)
    if not ts:
        raise MatremapError("no transform given; pass --transform T.json")
    t = ts[0] if len(ts) == 1 else Transform.chain(ts)
    notes = list(map_set.notes) + _check_transform(map_set, t)
    height, width = map_set.size
    rows = tile_rows or max(8, min(512, (1 << 20) // max(width, 1)))
    out = Path(out_dir)
    _check_out_dir(map_set, out)
    planned = _plan_outputs(map_set, t, out, out_format, notes)
    final_normal = out / map_set.normal.name if map_set.normal else None
    finals = [p for _, p, _ in planned] + ([final_normal] if final_normal else []) + [out / MANIFEST_NAME]
    files = _output_files(map_set, out, finals, force)
    with files:
        outputs = [
            _Output(name, path, str(files.stage(path)), info, cost=_cost(name, info)) for name, path, info in planned
        ]
        plan = _Plan(
            t.to_dict(),
            map_set.model,
            {k: str(v) for k, v in map_set.maps.items()},
            dict(map_set.info),
            _constants(map_set, t),
            (height, width),
            rows,
            constant_param(t),
        )
        results = _execute(plan, outputs, workers, progress)
        outside = results[0]["outside"]
        clipped, bounded = _clip_counts(results, outputs, t.target, notes)
        approximated = _write_constant(t, plan.constant, results[0], notes)
        kept = _drop_uniform(outputs, results, files, notes)
        doc = _manifest(map_set, t, kept, results[0]["first"], final_normal, outside)
        files.write_text(out / MANIFEST_NAME, json.dumps(doc, indent=1) + "\n")
        if map_set.normal and final_normal is not None:
            files.copy(map_set.normal, final_normal)
    texels = height * width
    if outside:
        warnings.warn(
            f"{outside} of {texels} texels ({100 * outside / texels:.1f}%) lie outside the transform's "
            f"training domain; {out / MASK_NAME} marks them",
            stacklevel=2,
        )
    return ConvertReport(
        texels,
        outside,
        files.destinations,
        time.perf_counter() - start,
        t.target,
        notes,
        clipped=clipped,
        bounded=bounded,
        approximated=approximated,
    )


def _output_files(map_set: MapSet, out: Path, finals: Sequence[Path], force: bool) -> AtomicFiles:
    """The all-or-nothing writer of ``finals`` in ``out``, refused when two share a name, one would overwrite an
    input, or (without ``force``) one exists."""
    if len({f.name for f in finals}) != len(finals):
        raise MatremapError(f"two outputs would share a name in {out}; rename the normal map")
    inputs = {f.resolve() for f in map_set.files}
    for f in finals:
        if f.resolve() in inputs:
            raise MatremapError(f"writing {f} would overwrite an input; choose another output folder")
    files = AtomicFiles(force, make_folders=True, exists_hint="choose an empty output folder or pass --force")
    for f in finals:
        files.check(f)
    return files


def _clip_counts(
    results: Sequence[Mapping[str, Any]], outputs: Sequence[_Output], target: str, notes: list[str]
) -> tuple[int, int]:
    """Values clipped to the files' range and values clipped to the target's bounds, with a note for
    each map or parameter concerned (appended to ``notes``)."""
    notes += _clipping_notes(results, outputs)
    clipped = sum(int(n) for r in results for n in r["clipped"].values())
    bounded = sum(int(n) for n in results[0]["bounded"].values())  # every group applies the transform
    notes += [
        f"{n} values of {name} lay beyond what {target} accepts and were clipped to its bounds"
        for name, n in results[0]["bounded"].items()
    ]
    return clipped, bounded


def _cost(name: str | None, info: ImageInfo) -> float:
    """The relative cost of writing one output (PNG encoding is the slow part)."""
    return info.channels * (4.0 if info.format == "png" else 1.0) if name else 0.3


def _plan_outputs(
    map_set: MapSet, t: Transform, out: Path, out_format: str | None, notes: list[str]
) -> list[tuple[str | None, Path, ImageInfo]]:
    """(target parameter or None for the domain mask, file, image format) of every map the transform
    drives; an IOR or absorption coefficient goes to float EXR (it does not fit an 8/16-bit file). A parameter
    written as one constant (:func:`constant_param`) has no map."""
    src, tgt = get_model(t.source), get_model(t.target)
    last = t.steps[-1] if t.method == "chain" else t
    height, width = map_set.size
    prefix = _prefix(map_set)
    planned: list[tuple[str | None, Path, ImageInfo]] = []
    any_info = next(iter(map_set.info.values()))
    metal = tgt.specialise(last.template).diffuse_only is None
    for q, m in last.mappings.items():
        name = target_param(tgt, q, metal)
        if name is None or m.get("kind") == "constant" or name == constant_param(t):
            continue
        srcs = [n for n in source_params(src, q) if n in map_set.info]
        base = (
            map_set.info[srcs[0]]
            if srcs
            else any_info.like(colorspace="srgb" if any_info.integer and q != "roughness" else "linear")
        )
        p = tgt.param(name)
        info = output_info(base.like(channels=p.channels, width=width, height=height, path=""), out_format)
        if out_format is None and info.integer and p.role == "fresnel" and p.bounds[1] > 1.0:
            info = output_info(info.like(colorspace="linear"), "exr")
            notes.append(f"{name} takes values above 1: written as float EXR")
        fname = f"{prefix}_{_CONVENTION[q] if q in _CONVENTION and name == target_param(tgt, q, metal) else name}"
        planned.append((name, out / (fname + info.suffix), info))
    planned.append((None, out / MASK_NAME, ImageInfo("png", "uint8", 1, width, height, "linear")))
    return planned


def _clipping_notes(results: Sequence[Mapping[str, Any]], outputs: Sequence[_Output]) -> list[str]:
    """A note for each map whose values were clipped to fit its file format."""
    clipped: dict[str, int] = {}
    for r in results:
        clipped.update(r["clipped"])
    notes = []
    for name, n in clipped.items():
        if n:
            o = next(o for o in outputs if o.param == name)
            notes.append(
                f"{n} values of {name} lay outside [0, 1] and were clipped in {o.path.name} "
                f"({o.info.pixel_type}); write a float format (out_format='exr') to keep them"
            )
    return notes


def _manifest(
    map_set: MapSet,
    t: Transform,
    outputs: Sequence[_Output],
    first: Mapping[str, Any],
    final_normal: Path | None,
    outside: int,
) -> dict[str, Any]:
    """``material.json``: the driven maps (an isotropic pair's follower reads its leader's), every other target
    parameter as a constant, provenance."""
    tgt = get_model(t.target)
    last = t.steps[-1] if t.method == "chain" else t
    constants: dict[str, Any] = dict(last.target_options)
    maps = {o.param: o.path for o in outputs if o.param}
    for follower, leader in tgt.isotropic:  # the one roughness map drives both of an isotropic pair
        if leader in maps:
            maps.setdefault(follower, maps[leader])
    for p in tgt.params:
        if p.name not in maps:
            v = first.get(p.name, last.template.get(p.name))
            constants[p.name] = v if np.ndim(v) == 0 or p.channels == 3 else float(np.ravel(v)[0])
    doc: dict[str, Any] = {"model": tgt.id, "maps": {k: v.name for k, v in maps.items()}}
    out_dir = next(iter(maps.values())).parent if maps else outputs[0].path.parent
    if final_normal:
        doc["normal"] = final_normal.name
    doc["params"] = constants
    doc["colorspace"] = {o.path.name: o.info.colorspace for o in outputs if o.param}
    doc["provenance"] = {
        "source": source_reference(map_set.root, out_dir),
        "source_model": map_set.model,
        "transform": t.describe(),
        "outside_domain": {"file": MASK_NAME, "texels": outside},
    }
    return doc


def source_reference(root: Path, out_dir: Path) -> str:
    """How a converted map set's provenance names its source folder: relative to the map set's own folder
    when the source lies beside it (a material file's maps unpacked into the same output, which is
    written in a staging folder and moved: an absolute path would point into the staging folder), else
    absolute."""
    root, out_dir = Path(root).resolve(), Path(out_dir).resolve()
    if out_dir.parent == root or out_dir.parent in root.parents:
        return os.path.relpath(root, out_dir)
    return str(root)


def _constants(map_set: MapSet, t: Transform) -> dict[str, Any]:
    c = dict(map_set.constants)
    for k, v in t.source_options.items():
        c.setdefault(k, v)
    return c


def _check_out_dir(map_set: MapSet, out: Path) -> None:
    o = out.resolve()
    if o == map_set.root.resolve():
        raise MatremapError(f"the output folder {out} is the input folder; choose another one")
    for f in map_set.files:
        if o in f.resolve().parents:
            raise MatremapError(f"the output folder {out} contains the input {f.name}; choose another one")
    if out.exists() and not out.is_dir():
        raise MatremapError(f"{out} exists and is not a folder; choose an output folder")


#: below this many texels one process converts faster than a pool (starting a spawned worker costs
#: about a second; measured on 2048^2 maps: 1.9 s in one process, 3.1 s on two)
PARALLEL_MIN_TEXELS = 8_000_000


def _worker_init(parent: int) -> None:
    """A worker process: Ctrl-C is its parent's to handle (which ends the workers), and it dies with its
    parent (Linux: PR_SET_PDEATHSIG), so a killed convert leaves no process writing into its staging."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if sys.platform.startswith("linux"):
        import ctypes

        with contextlib.suppress(OSError, AttributeError):
            ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL)  # 1: PR_SET_PDEATHSIG
    if os.getppid() != parent:  # the parent died before that took effect
        os._exit(1)


def _execute(plan: _Plan, outputs: list[_Output], workers: int, progress) -> list[dict[str, Any]]:
    if plan.size[0] * plan.size[1] < PARALLEL_MIN_TEXELS:
        workers = 1
    groups = _split(outputs, max(1, min(workers, len(outputs))))
    if len(groups) == 1:
        return [_run(plan, groups[0], progress=progress)]
    from matremap.sweep.executors import spawn_context

    # spawn, not fork: OpenImageIO keeps a thread pool that a forked child would inherit broken; Ctrl-C blocked
    # while a worker starts (it ignores it from its initializer on)
    ctx = spawn_context()
    pool = ctx.Pool(len(groups), initializer=_worker_init, initargs=(os.getpid(),))
    try:
        # the group that writes the mask reports first; progress is reported when workers finish
        pending = [pool.apply_async(_run, (plan, g)) for g in groups]
        results = [r.get() for r in pending]
    except BaseException:
        pool.terminate()  # an error or Ctrl-C: the workers stop now, not when their files are done
        pool.join()
        raise
    pool.close()
    pool.join()
    if progress is not None:
        progress(plan.size[0], plan.size[0])
    mask_group = next(i for i, g in enumerate(groups) if any(o.param is None for o in g))
    results.insert(0, results.pop(mask_group))
    return results


def convert_paths(
    maps: str | os.PathLike,
    transforms: Sequence[str | os.PathLike],
    out_dir: str | os.PathLike,
    model: str | None = None,
    **kwargs: Any,
) -> ConvertReport:
    """:func:`convert` from file names (what ``matremap convert`` calls)."""
    from matremap.svbrdf.textures import load_map_set

    ms = load_map_set(maps, model)
    return convert(ms, [Transform.load(Path(p)) for p in transforms], out_dir, **kwargs)
