"""The main job: remap an SVBRDF map set (or a material file) from one model to another, end to end.

library route or sweep -> learn -> convert -> evaluate -> quality gate (paper §4-6):

1. a route through the shipped transform library when one covers the maps, else a sweep over the
   source parameters the maps actually hold (their ranges, roughness down to its mirror limit, the
   diffuse levels up to the brightest texel), fitted onto the target model on the probe scene;
2. a parametric transform learned from it, cached by everything that decides it, so a second run
   with the same maps and models reuses it;
3. the transform applied to every texel (:func:`matremap.svbrdf.convert.convert`); the same model in
   and out is the identity: the maps are copied, nothing is fitted;
4. source and result rendered under an environment map at several rotations and compared
   (:func:`matremap.svbrdf.evaluate.evaluate`), into a self-contained HTML report;
5. the quality gate (:mod:`matremap.svbrdf.quality`): colour, energy and structure of the renders, hue
   and flatness of the maps, texels outside the training domain. The result carries its verdict; the
   command line exits 3 when it failed (the files are written, the report says FAILED and why).

Everything that can be known before rendering is checked first (the target's renderer is installed and
draws the maps' parameters as textures, the output file can be written, the maps do not mix metal and
dielectric for a target that expresses only one). The output folder is written all or nothing
(:func:`matremap.core.atomic.staged_folder`): a failed run leaves nothing behind.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import time
import warnings
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from matremap import __version__, uniform_remap
from matremap.core.atomic import staged_folder
from matremap.core.envmap import resolve as resolve_envmap
from matremap.core.imageio import write_image, write_text
from matremap.core.locks import exclusive
from matremap.core.material import Material, SVMaterial
from matremap.core.models import microfacet_of
from matremap.core.scene import Scene, parse_probe
from matremap.dialects import get_model, list_models
from matremap.dialects.equivalence import Equivalence, equivalence
from matremap.dialects.mtlx import (
    LAYER_PARAMS,
    absorbed_layers,
    coat_tint,
    freed_layers,
    layer_textures,
    layers_on,
    opaque_share,
)
from matremap.errors import MatremapError, TransformChecksumError
from matremap.formats.confine import recorded_references
from matremap.regress import quantities as qty
from matremap.regress.transform import Transform
from matremap.renderers import renderer_for
from matremap.svbrdf import levels
from matremap.svbrdf.convert import MANIFEST_NAME, MASK_NAME, convert, source_reference
from matremap.svbrdf.evaluate import evaluate as evaluate_pair
from matremap.svbrdf.evaluate import parse_rotations
from matremap.svbrdf.mapstats import (
    LIBRARY_LIMIT,
    SAMPLE_LIMIT,
    TOLERANCE,
    MapSummary,
    render_side,
    summarise,
    with_medians,
)
from matremap.svbrdf.mixed import (
    Blend,
    Grid,
    Levels,
    Mixed,
    layer_levels,
    layer_parameter,
    mixed_parameter,
    remap_mixed,
    through_levels,
    transmission_parameter,
)
from matremap.svbrdf.quality import Check, Thresholds, Verdict, layer_checks, map_checks, sample
from matremap.svbrdf.textures import MapSet, load_map_set, map_values, read_image, texel_limit
from matremap.uniform_remap import ANISOTROPIC_PROBE_LIGHTS, complete_fix, partial_metal

#: grid points along the roughness and the specular axes of the sweep, and the diffuse levels
ROUGHNESS_POINTS, SPECULAR_POINTS, DIFFUSE_ONLY_POINTS = 10, 6, 8
#: points along a specular axis without a roughness axis beside it (a learner needs a few to spare)
ALONE_POINTS = 12


@dataclass
class RemapResult:
    transform: Path | None  # the cached transform file; None when the library served it
    cached: bool
    maps: Path
    report: Path | None
    outside: int
    texels: int
    mean_dssim: float | None
    seconds: dict[str, float] = field(default_factory=dict)
    #: the quality gate's verdict (its measures and thresholds)
    verdict: Verdict = field(default_factory=Verdict)
    #: the same model in and out: the maps were copied
    identity: bool = False
    #: the gate's checks of the uniform fits the maps were converted through, where the evaluation cannot see them
    #: (what a material lets through, at levels: :func:`~matremap.svbrdf.levels.checks`); part of ``verdict`` too
    fitted: list[Check] = field(default_factory=list)

    def moved(self, stage: Path, out: Path) -> RemapResult:
        """The result with its paths moved from the staging folder to the output folder."""

        def move(path: Path | None) -> Path | None:
            if path is None or stage not in path.parents:
                return path
            return out / path.relative_to(stage)

        return replace(self, maps=move(self.maps) or self.maps, report=move(self.report))


def cache_folders(job: RemapJob) -> list[Path]:
    """The cache folders a run reads and writes (matremap's cache, and the job's transform cache when it
    names its own): no output folder may be or hold one."""
    from matremap.core.diskcache import cache_dir

    return [cache_dir(), *([job.cache] if job.cache is not None else [])]


def default_cache() -> Path:
    """The transform cache: ``transforms/`` in matremap's private cache folder (created 0700, owner checked)."""
    from matremap.core.diskcache import private_cache_dir

    return private_cache_dir("transforms")


def load_arrays(map_set: MapSet, only: Collection[str] | None = None) -> tuple[dict[str, Any], np.ndarray | None]:
    """Every map of a set as parameter arrays (model units), constants as they are, and the
    normal map decoded to [-1, 1] (or None). ``only``: read just these parameters' maps (and no
    normal map). Whole maps in memory: :func:`remap` itself reads maps in bands
    (:func:`matremap.svbrdf.mapstats.summarise`)."""
    spec = map_set.spec
    params: dict[str, Any] = {k: v for k, v in map_set.constants.items() if k in spec.param_names}
    for name, path in map_set.maps.items():
        if only is not None and name not in only:
            continue
        image, _ = read_image(path, map_set.colorspace.get(name))
        params[name] = map_values(spec, name, image, path, 0)
    normal = None
    if map_set.normal is not None and only is None:
        from matremap.renderers.textured import decode_normal_map

        normal = decode_normal_map(read_image(map_set.normal, "linear", colour=False)[0])
    return params, normal


def sweep_grid(map_set: MapSet, summary: MapSummary, held: Mapping[str, float] | None = None) -> str:
    """A grid over the values the maps hold: the roughness and specular maps' ranges (grey; roughness
    down to its mirror limit when the maps reach it) and the diffuse level from 0 to the brightest texel,
    so that every texel lies inside the learned domain. ``summary``: the maps' exact ranges and samples
    (:func:`~matremap.svbrdf.mapstats.summarise`); ``held``: mapped parameters that are uniform."""
    spec = map_set.spec
    params, ranges = summary.sample(), summary.ranges()
    axes = []
    rp = qty.roughness_param(spec)
    if rp is not None and rp.name in map_set.maps:
        lo, hi = _range(ranges[rp.name], rp.bounds, floor=rp.bounds[0])
        axes.append(f"{rp.name}={lo!r}:{hi!r}:{ROUGHNESS_POINTS}")
    metal = spec.specialise({**map_set.constants, **params, **(held or {})}).diffuse_only is None
    if spec.reflectance is not None:
        # the parameter a map of F0 drives: k for conductors, a glTF metal's base colour or a glTF
        # dielectric's specular colour; its range is the one that covers the maps' F0 (which other maps,
        # such as a glTF specular strength, may scale)
        name = spec.reflectance.driven_param(metal)
        f0_range = _f0_axis(map_set, summary, held or {}, name)
        if f0_range is not None:
            lo, hi = f0_range
            axes.append(f"{name}={lo!r}:{hi!r}:{SPECULAR_POINTS if axes else ALONE_POINTS}")
    dp = qty.diffuse_param(spec)
    if dp is not None and dp.name in map_set.maps and not metal:
        lo, hi = _range(ranges[dp.name], dp.bounds, floor=1e-3)
        # two levels learn the diffuse mapping beside other axes; alone it needs enough points to learn from,
        # from the darkest texel (a diffuse-only source at 0 renders black, is refused, and the domain would
        # start at the next point, leaving the darkest texels outside it); so too under a partial metal, whose base
        # colour is its metal's F0 as well (usd-wg RoughnessTest: its darkest level, fitted poorly, was left out,
        # and with two levels nothing was learned of the colour)
        partial = partial_metal(spec.id, {**map_set.constants, **(held or {})}) is not None
        two = axes and not partial
        axes.append(f"{dp.name}=0.0;{hi!r}" if two else f"{dp.name}={lo!r}:{hi!r}:{DIFFUSE_ONLY_POINTS}")
    if not axes:
        raise MatremapError(f"the map set gives no roughness, specular or diffuse map of {spec.id} to remap")
    return ",".join(axes)


def base_values(map_set: MapSet, summary: MapSummary, held: Mapping[str, float]) -> dict[str, Any]:
    """The values a sweep's source starts from: the constants, the held values, and for each other map its
    median (per channel, from ``summary``), so that a map no axis sweeps is represented by its typical
    texel, not the model's default."""
    spec = map_set.spec
    summary = with_medians(map_set, summary)
    out: dict[str, Any] = {k: v for k, v in map_set.constants.items() if k not in map_set.maps}
    for name in map_set.maps:
        if name in held:
            continue
        p = spec.param(name)
        med = summary.stats[name].median
        lo, hi = p.bounds
        out[name] = (
            np.clip(med, lo, hi).tolist() if p.channels == 3 and np.ndim(med) else float(np.clip(np.mean(med), lo, hi))
        )
    return {**out, **held}


def _f0_axis(map_set: MapSet, summary: MapSummary, held: Mapping[str, float], name: str) -> tuple[float, float] | None:
    """The range of the parameter ``name`` that, with the sweep's base values for the others, spans the
    F0 the maps hold (their sample); None when F0 does not vary over the maps. Falls back to ``name``'s own
    map range."""
    spec = map_set.spec
    params = summary.sample()
    probe = next((np.asarray(v) for v in params.values() if np.ndim(v) >= 2), None)
    if probe is None:
        return None
    f0 = _quantity_sample(spec, {**map_set.constants, **params, **held}, sample(probe).shape[:2]).get("reflectance")
    bounds = spec.param(name).bounds
    if f0 is None or np.ptp(f0) <= 1e-6:
        return _range(summary.stats[name].range, bounds) if name in map_set.maps else None
    grey = np.asarray(f0, dtype=float).reshape(-1)  # every channel: the domain is checked per channel
    ends = np.array([[grey.min()] * 3, [grey.max()] * 3])
    try:
        base = Material.create(spec.id, base_values(map_set, summary, held))
        written = qty.write(spec, {"reflectance": ends}, {k: v for k, v in base.values.items()})
    except (MatremapError, ValueError):
        return _range(summary.stats[name].range, bounds) if name in map_set.maps else None
    values = np.asarray(written[name], dtype=float).reshape(2, -1).mean(axis=-1)
    return _range(values, bounds)


def _range(values: Any, bounds: tuple[float, float], floor: float = 1e-4) -> tuple[float, float]:
    """The values' range, padded by 2 % (at least a little), inside the parameter's bounds and not below
    ``floor``: a reflectance swept at exactly 0 renders black and cannot be fitted, while a small one can
    (roughness passes its own lower bound: a mirror is fitted where the probe resolves it)."""
    v = np.asarray(values, dtype=float)
    lo, hi = float(np.min(v)), float(np.max(v))
    pad = 0.02 * (hi - lo) if hi > lo else 0.05 * max(abs(hi), 1e-3)
    pad = max(pad, 0.5 * (MIN_AXIS - (hi - lo)))
    lo, hi = max(bounds[0], lo - pad, floor), min(bounds[1], hi + pad)
    return round(lo, 6), round(hi, 6)


#: the narrowest a sweep axis spans: a map that varies by less than 8-bit steps (a roughness of 0 to 5e-5, Khronos
#: TransmissionTest) swept over its own range gave fits that differ by noise alone, and a learned polynomial of
#: roughness with coefficients of 3e7
MIN_AXIS = 0.02


#: a map counts as uniform when all its texels are within this of one value (an 8-bit step is 1/255)
UNIFORM_TOLERANCE = TOLERANCE


def held_values(map_set: MapSet, summary: MapSummary, target: str) -> dict[str, float]:
    """The mapped parameters that change what the model's other parameters mean (a glTF ``metallic``),
    each held at its one value. Maps that mix values (metal and dielectric texels) cannot be remapped
    through one transform: refused, with the share of each (:func:`remap_into` converts such maps per
    texel instead, :mod:`matremap.svbrdf.mixed`)."""
    spec = map_set.spec
    held: dict[str, float] = {}
    for name, value, _ in spec.specialisations:
        if name not in map_set.maps:
            continue
        stats = summary.stats[name]
        lo, hi = stats.lo, stats.hi
        if hi - lo <= 2 * UNIFORM_TOLERANCE:
            held[name] = round(0.5 * (lo + hi), 6)
            continue
        counts = stats.specialisation
        share = counts.at_value / max(counts.texels, 1) if counts is not None else 0.0
        raise MatremapError(
            f"the {name} map of {map_set.root.name} mixes values ({name} {value:g} on {100 * share:.0f}% of the "
            f"texels, other values on the rest): {target} is remapped from one kind of material at a time; split "
            f"the material by its {name} map, or convert it to {spec.id} itself"
        )
    return held


def free_partial_metal(
    source: Material, job: RemapJob, fix: dict[str, Any], log: Callable[[str], None]
) -> tuple[RemapJob, dict[str, Any], dict[str, float]]:
    """:func:`matremap.uniform_remap.free_partial_metal` on a job: ``simple`` where a metalness is freed."""
    fix, start = uniform_remap.free_partial_metal(source, job.target, job.fix, fix, log)
    return (replace(job, strategy="simple") if start else job), fix, start


#: a library route is used when at most this fraction of the texels lie outside its training domain
LIBRARY_MAX_OUTSIDE = 0.01


def library_transform(
    map_set: MapSet,
    params: Mapping[str, Any],
    target: str,
    fix: Mapping[str, Any],
    log: Callable[[str], None],
    probes: Sequence[str] = ("point",),
    envmap: str = "builtin",
    within: np.ndarray | None = None,
) -> Transform | None:
    """A transform from the shipped library (direct or chained) that covers these maps, or None.
    ``params``: the maps' parameters, whole or a sample (strided here to at most
    :data:`~matremap.svbrdf.mapstats.LIBRARY_LIMIT` texels a side for the domain check); ``within``: the texels
    of that sample the result is used at (:func:`kind_job`; None: all). ``probes``: the
    kinds of probe a route may have been fitted under; when routes of several kinds cover the maps, the one
    whose result looks closest under ``envmap`` is taken (:func:`matremap.svbrdf.choice.best_transform`)."""
    from matremap.regress.library import describe_node, find_route, nearest_routes, node_key

    spec = map_set.spec
    held = {name: params[name] for name, _, _ in spec.specialisations if name in params}
    texels = {k: sample(v, LIBRARY_LIMIT) for k, v in params.items() if k in spec.param_names}
    covering = []
    for probe in probes:
        found = find_route(spec.id, map_set.options, target, fix, source_values=held, probe=probe)
        if found is None:
            continue
        _, outside = found.transform.apply(texels)
        if within is not None and np.shape(within) == np.shape(outside):
            outside = outside[within]
        share = float(np.mean(outside)) if np.size(outside) else 0.0
        if share > LIBRARY_MAX_OUTSIDE:
            log(f"library: {found.describe()} covers only {100 * (1 - share):.1f}% of the texels")
            continue
        covering.append((probe, found))
    if not covering:
        asked = describe_node(node_key(spec.id, map_set.options), defaults=True)
        near = nearest_routes(spec.id, map_set.options, target, fix)
        log(
            f"library: no route from {asked} to {describe_node(node_key(target, fix), defaults=True)} that covers "
            "the maps" + (f"; nearest: {'; '.join(near)}" if near else "") + "; sweeping"
        )
        return None
    probe, found = covering[0]
    if len(covering) > 1:
        from matremap.svbrdf.choice import best_transform

        choice = best_transform([r.transform for _, r in covering], spec.id, map_set.options, texels, envmap)
        probe, found = covering[choice.index]
        scores = ", ".join(f"{k} probe {v:.4f}" for (k, _), v in zip(covering, choice.scores, strict=True))
        log(f"library: routes fitted under several probes; mean 1-SSIM of the maps' texels under {envmap}: {scores}")
    log(f"library: {found.describe()}" + ("" if probe == "point" else f" (fitted under the {probe} probe)"))
    return found.transform


def transform_cache_path(cache: Path, config: Any, grid_text: str) -> Path:
    """Where the transform of a sweep is cached: named by its models and a digest of everything that decides
    it (the sweep's configuration with its probe and objective, the grid, matremap's version and results
    revision); ``cache`` is created."""
    from matremap.core.diskcache import RESULTS_REVISION

    key_doc = {"config": config.to_dict(), "grid": grid_text, "version": __version__, "revision": RESULTS_REVISION}
    key = hashlib.sha256(json.dumps(key_doc, sort_keys=True).encode()).hexdigest()[:16]
    cache.mkdir(parents=True, exist_ok=True)
    return cache / f"{config.source.model.replace(':', '-')}--{config.target.replace(':', '-')}-{key}.json"


def cached_transform(
    map_set: MapSet,
    summary: MapSummary,
    target: str,
    fix: Mapping[str, Any],
    strategy: str,
    cache: Path,
    workers: int | None,
    log: Callable[[str], None],
    scene: Scene | None = None,
    target_renderer: str = "embedded",
    objective: str = "l2",
) -> tuple[Transform, Path | None, bool]:
    """The transform for these maps (``summary``: their statistics) and models: from the cache, or swept
    and learned now (and cached, unless some of the sweep's fits failed: then the next run fits those
    again, from the sweep's database, instead of reusing a transform learned without them). Runs that need
    the same transform at once compute it once: the others wait for it (:func:`matremap.core.locks.exclusive`)."""
    from matremap.sweep.run import SweepConfig

    spec = map_set.spec
    held = held_values(map_set, summary, target)
    base = Material.create(spec.id, base_values(map_set, summary, held))
    grid_text = sweep_grid(map_set, summary, held)
    from matremap.renderers import renderer_for

    config = SweepConfig(
        source=base,
        target=get_model(target).id,
        fix=dict(fix),
        strategy=strategy,
        scene=scene or Scene(),
        source_renderer=renderer_for(spec.id),
        target_renderer=target_renderer,
        objective=objective,
    )
    path = transform_cache_path(cache, config, grid_text)
    waiting = partial(log, "transform: another run is computing the same transform; waiting for it")
    with exclusive(path.with_suffix(".lock"), on_wait=waiting):  # the second run takes the first's result
        return _cached_or_learned(path, config, grid_text, spec, workers, log)


def _cached_or_learned(
    path: Path, config: Any, grid_text: str, spec: Any, workers: int | None, log: Callable[[str], None]
) -> tuple[Transform, Path | None, bool]:
    """:func:`cached_transform` holding the transform's lock: the cached one at ``path``, else swept (resuming
    the sweep's database beside it), learned and cached."""
    from matremap.regress.transform import learn_transform
    from matremap.sweep.executors import make_executor
    from matremap.sweep.grid import parse_grid
    from matremap.sweep.run import describe, run_sweep
    from matremap.sweep.store import discard_if_damaged

    if path.is_file():
        try:
            t = Transform.load(path, require_checksum=True)
            log(f"transform: cached {path}")
            return t, path, True
        except TransformChecksumError as e:  # edited or damaged since it was written: not trusted
            log(f"note: {e}; recomputing it")
    db = path.with_suffix(".sqlite")
    discard_if_damaged(db, log)  # the cached sweep is resumed below: only when sound
    grid = parse_grid(grid_text, spec)
    log(f"sweep: {spec.id} -> {config.target}, {len(grid)} fits over {grid_text}; {config.scene.describe()}")
    from tqdm import tqdm

    with (
        make_executor(workers) as (executor, desc),
        tqdm(total=len(grid), unit="fit", desc="sweep", disable=None, leave=False) as bar,
    ):
        swept = run_sweep(
            config,
            grid,
            str(db),
            executor,
            progress=bar.update,
            executor_name=desc,
            on_start=bar.update,
            in_flight=2 * getattr(executor, "slots", 1),
        )
    log(f"sweep: {describe(swept)}")
    swept.raise_if_interrupted()
    transform = learn_transform(db)
    log(
        f"learn: {transform.describe()}, held-out RMSE "
        + ", ".join(f"{k} {v['heldout_rmse']:.3g}" for k, v in transform.errors.items() if "heldout_rmse" in v)
    )
    if swept.failed:  # learned without them: used for this run, not kept (the next run fits them again)
        log(f"note: {swept.failed} sweep point(s) failed; the transform is not cached, so the next run retries them")
        return transform, None, False
    transform.save(path, force=True)
    return transform, path, False


@dataclass
class RemapJob:
    """What a remap is asked to do, beside its input and output (see :func:`remap`)."""

    target: str
    fix: dict[str, Any] = field(default_factory=dict)
    strategy: str = "two-stage"
    envmap: str = "builtin"
    rotations: str = "0:360:6"
    resolution: int = 160
    lights: int = 128
    workers: int | None = None
    cache: Path | None = None
    evaluate: bool = True
    scene: Scene | None = None
    target_renderer: str | None = None
    library: bool = True
    thresholds: Thresholds = field(default_factory=Thresholds)
    #: the largest map (width x height) read; None: :data:`~matremap.svbrdf.textures.DEFAULT_MAX_TEXELS`
    max_texels: int | None = None
    #: the probe fits are made under (:func:`~matremap.core.scene.parse_probe`), or ``auto`` (see
    #: :func:`sweep_probe` and :func:`library_probes`); ignored when ``scene`` is given
    probe: str = "auto"
    #: what the fits make small; None: ``ssim`` under an environment probe, ``l2`` under the point probe
    objective: str | None = None
    #: the texels the result is used at, as a boolean mask over the maps' library sample (one kind of a map set
    #: blended per texel: a metal's transform need not cover the dielectric texels); None: all of them
    within: Any = None


def checked_job(job: RemapJob) -> RemapJob:
    """``job`` once its user-given values are known good for its target (each ``fix`` a parameter or option
    of the target, in its bounds or among its choices): refused here, before any fit, rather than by every
    fit of a sweep."""
    Material.create(job.target).with_params(job.fix)
    return job


def sweep_probe(job: RemapJob) -> tuple[Scene | None, str]:
    """The probe (None: the paper's default point probe) and objective a sweep for ``job`` fits under:
    ``auto`` sweeps under the point probe (an environment sweep costs about ten times as much); the
    objective defaults to ``ssim`` under an environment (docs/fitting.md has the measurements)."""
    scene = job.scene
    if scene is None and job.probe not in ("auto", "point"):
        scene = parse_probe(job.probe)
    objective = job.objective or ("ssim" if scene is not None and scene.environment is not None else "l2")
    return scene, objective


def library_probes(job: RemapJob) -> list[str]:
    """The kinds of probe a library route may have been fitted under for ``job``: both with ``auto`` (then
    the one that looks closest under the evaluation's environment is taken), the one asked for, or none
    for a probe of the user's own (point lights other than the headlight, or an environment file)."""
    if job.scene is not None or ":" in job.probe:
        return []
    kinds = ["point", "env"] if job.probe == "auto" else [job.probe]
    if job.objective is not None:  # only routes fitted under that objective
        kinds = [k for k in kinds if job.objective == ("l2" if k == "point" else "ssim")]
    return kinds


def staged_strategy(job: RemapJob, log: Callable[[str], None]) -> RemapJob:
    """The job with ``simple`` for a target whose specular part cannot be drawn alone (Mitsuba 3's
    principled: its metallic lobe takes the base colour), where a two- or three-stage fit would fit its
    specular stage to nothing."""
    spec = get_model(job.target)
    if job.strategy != "simple" and spec.specular_only is None and spec.diffuse_only is not None:
        log(f"strategy: simple ({job.target} has no specular-only render to fit a stage to)")
        return replace(job, strategy="simple")
    return job


def remap(
    maps: str | Path,
    source_model: str | None,
    target_model: str,
    out: str | Path,
    *,
    force: bool = False,
    write: str | None = None,
    log: Callable[[str], None] = print,
    **options: Any,
) -> RemapResult:
    """Remap the map set ``maps`` onto ``target_model``; write ``OUT/maps``, ``OUT/report``,
    ``OUT/transform.json``, ``OUT/verdict.json`` and, when ``write`` names one (``NAME.gltf``, ``.glb``,
    ``.mtlx``, ``.xml``, ...), a material file ``OUT/NAME`` holding the converted maps
    (:func:`matremap.formats.write_asset`), all or nothing.

    ``options`` are the fields of :class:`RemapJob`: ``fix``, ``strategy``, ``envmap``, ``rotations``,
    ``resolution``, ``lights``, ``workers``, ``cache``, ``evaluate``, ``scene`` (the sweep's probe; default
    the paper's headlight), ``target_renderer`` (e.g. "mitsuba3", "cycles"), ``library`` (first look for a
    route through the shipped transform library, used with the default probe, two-stage fits and default
    renderers when it covers the maps; otherwise sweep and learn, cached) and ``thresholds`` (the quality
    gate's), ``max_texels`` (the largest map read, checked on each file's header before any texel is
    decoded). The maps are read in bands (:func:`matremap.svbrdf.mapstats.summarise`,
    :func:`matremap.svbrdf.convert.convert`): memory does not grow with the map size. The result carries
    the gate's verdict; it is not raised here."""
    job = RemapJob(get_model(target_model).id, **{k: v for k, v in options.items() if v is not None or k == "scene"})
    checked_job(job)
    if write is not None:
        check_material_file_name(write, job.target)
    with texel_limit(job.max_texels):
        map_set = load_map_set(maps, source_model)
        job = same_distribution(job, map_set.model, map_set.options, log)
        out = Path(out)
        protected = [map_set.root, *map_set.files, *cache_folders(job)]
        with staged_folder(out, force, protected=protected, enclosing=[map_set.root]) as stage:
            result = remap_into(stage, map_set, job, log, title=f"{map_set.model} -> {job.target}: {Path(maps).name}")
            if write is not None:
                from matremap.formats import write_asset

                write_asset(stage / write, converted_set(stage / "maps", map_set.size), force=True)
    if write is not None:
        log(f"wrote {out / write}")
    return result.moved(stage, out)


#: format -> the family of models its writer takes (a format not listed is left to its writer to check)
WRITTEN_FAMILIES: dict[str, tuple[str, ...]] = {
    "gltf": ("gltf",),
    "mtlx": ("gltf", "mtlx"),
    "mitsuba-xml": ("mitsuba3",),
    "blend": ("cycles",),
}


def check_material_file_name(name: str, target: str) -> None:
    """Refuse, before any work, a material file name for a map set's remap (``--write``) that no writer
    takes, that the target's model cannot be written as, or that lies in the folders the remap fills."""
    from matremap.formats import WRITERS, format_for, written_models
    from matremap.formats.confine import output_inside

    output_inside(Path("."), name)
    fmt = format_for(name)
    families = WRITTEN_FAMILIES.get(fmt)
    if families is not None and target.split(":", 1)[0] not in families:
        fams = WRITTEN_FAMILIES.items()
        suffixes = [x for f, fam in fams if target.split(":", 1)[0] in fam for x in WRITERS[f][1]]
        held = " and ".join(f"{f}:*" for f in families)
        raise MatremapError(
            f"--write {name}: a {fmt} file holds {held} materials, not {target}"
            + (f"; write a {' or '.join(suffixes)} file instead" if suffixes else "; remap to a model it holds")
        )
    models = written_models(fmt)
    if get_model(target).id not in models:
        raise MatremapError(
            f"--write {name}: matremap writes {', '.join(models)} into a {fmt} file, not {target}; remap to one of "
            f"those, or leave out --write (the converted maps and OUT/material.json are written)"
        )
    if Path(name).parts[0] in ("maps", "report", "source"):
        raise MatremapError(
            f"--write {name}: OUT/{Path(name).parts[0]}/ holds the remap's own files; choose another name"
        )


def remap_into(
    folder: Path, map_set: MapSet, job: RemapJob, log: Callable[[str], None], title: str = ""
) -> RemapResult:
    """The remap of :func:`remap`, written into ``folder`` (a staging folder)."""
    t0 = time.perf_counter()
    seconds: dict[str, float] = {}
    job = staged_strategy(job, log)
    target = job.target
    target_renderer = job.target_renderer or renderer_for(target)
    angles = parse_rotations(job.rotations) if job.evaluate else []
    env = resolve_envmap(job.envmap) if job.evaluate else None
    side = render_side(job.resolution) if job.evaluate else None  # the renders read the maps downsampled
    summary = summarise(map_set, render_side=side)
    seconds["load"] = time.perf_counter() - t0
    t = time.perf_counter()
    identity = identity_route(map_set, target, job.fix)
    fitted: list[Check] = []  # the fits of materials converted as a few uniform ones (levels under transmission)
    conversion = _convert_maps(folder, map_set, summary, job, target_renderer, identity, log, seconds, fitted)
    texels, outside, clipped, constant, tpath, cached = conversion
    seconds["convert"] = time.perf_counter() - t
    result_set = converted_set(folder / "maps", map_set.size)
    result_summary = summarise(result_set, limits=(SAMPLE_LIMIT,), render_side=side)
    checks = [
        Check(
            "outside",
            outside / max(texels, 1),
            job.thresholds.outside,
            f"texels outside the training domain: {outside}",
        ),
        Check(
            "clamped",
            (clipped + constant) / max(texels * values_per_texel(result_set), 1),
            job.thresholds.clamped,
            _clamped_where(clipped, constant),
        ),
    ]
    checks += fitted
    checks += map_quality(map_set, summary.sample(), result_set, result_summary.sample(), job.thresholds)
    verdict, mean, html = Verdict(checks), None, None
    if job.evaluate:
        assert env is not None and summary.render is not None and result_summary.render is not None
        t = time.perf_counter()
        for note in summary.notes:
            log(f"note: {note}")
        evaluation = evaluate_pair(
            SVMaterial(map_set.model, summary.render, map_set.options, summary.render_normal),
            SVMaterial(result_set.model, result_summary.render, result_set.options, result_summary.render_normal),
            env,
            angles,
            folder / "report",
            resolution=job.resolution,
            lights=job.lights,
            title=title,
            thresholds=job.thresholds,
            checks=checks,
            domain_map=folder / "maps" / MASK_NAME,
            notes=fit_notes(folder / "transform.json", job.envmap, angles, log),
        )
        seconds["evaluate"] = time.perf_counter() - t
        verdict, mean, html = evaluation.verdict, float(evaluation.mean_full), folder / "report" / "report.html"
        log(
            f"evaluate: mean 1-SSIM {evaluation.mean_full:.4f} (specular only {evaluation.mean_specular:.4f}) "
            f"over {len(angles)} rotations"
        )
    write_text(folder / "verdict.json", json.dumps(verdict.to_dict(), indent=1) + "\n")
    seconds["total"] = time.perf_counter() - t0
    return RemapResult(
        tpath, cached, folder / "maps", html, outside, texels, mean, seconds, verdict, identity is not None, fitted
    )


def converted_set(folder: Path, size: tuple[int, int] = (0, 0)) -> MapSet:
    """The map set a conversion wrote into ``folder``; one whose every parameter came out uniform (a kind of a
    blend whose levels all agree: a glass with a texture of one value) as its constants, at the source's ``size``."""
    doc = json.loads((folder / MANIFEST_NAME).read_text())
    if doc.get("maps"):
        return load_map_set(folder)
    normal = folder / doc["normal"] if doc.get("normal") else None
    return MapSet(doc["model"], {}, folder, size, normal, dict(doc.get("params") or {}))


def _clamped_where(clipped: int, constant: int) -> str:
    """What the ``clamped`` measure counted: values clipped, and texels one constant stands for."""
    parts = [f"values clipped to the target's bounds or the files' range: {clipped}"] if clipped or not constant else []
    return "; ".join(parts + ([f"texels whose F0 one constant approximates: {constant}"] if constant else []))


def values_per_texel(map_set: MapSet) -> int:
    """The values a texel of ``map_set`` holds: a channel count per fitted parameter, map or constant (a
    transform writes each at every texel, a uniform one too; held ones such as a specular multiplier are the
    template's). The ``clamped`` measure's denominator: it counts values, three to an RGB texel; divided by
    the texels alone it read 1.7 or 2.5 for a "fraction"."""
    spec = map_set.spec
    names = {*map_set.maps, *(k for k in map_set.constants if k in spec.param_names)}
    return max(1, sum(spec.param(n).channels for n in names if n in spec.param_names and spec.param(n).fit))


def fit_notes(transform_file: Path, envmap: str, angles: Sequence[float], log: Callable[[str], None]) -> dict[str, str]:
    """The report's row on the light the applied transform was fitted under, and a warning when the
    evaluation turns the environment the fit was made under to one of the fit's own rotations (then the
    evaluation does not judge the transform on views held out from its fits)."""
    from matremap.regress.library import fitted_under

    if not transform_file.is_file():  # the identity or a per-texel blend: nothing was fitted as a whole
        return {}
    probes = fitted_under(Transform.load(transform_file))
    scene, objective = probes[0]
    notes = {"fitted under": f"{scene.describe()}; objective {objective}"}
    env = scene.environment
    judged = str(envmap) if str(envmap) in ("builtin", "constant") else os.path.abspath(envmap)
    if env is not None and env.env == judged and set(env.rotations) & {float(a) for a in angles}:
        shared = sorted(set(env.rotations) & {float(a) for a in angles})
        notes["held out"] = (
            f"no: the evaluation turns {envmap} to rotations the transform was fitted at ({shared}); choose others "
            "with --rotations to judge it on held-out views"
        )
        log(f"warning: {notes['held out']}")
    return notes


def _convert_maps(
    folder: Path,
    map_set: MapSet,
    summary: MapSummary,
    job: RemapJob,
    target_renderer: str,
    identity: Equivalence | None,
    log: Callable[[str], None],
    seconds: dict[str, float],
    fitted: list[Check],
) -> tuple[int, int, int, int, Path | None, bool]:
    """``folder/maps``: the maps copied (identity), blended per texel from each kind's conversion (maps
    that mix metal and dielectric, a material that lets light through at levels of its roughness), or converted
    through one transform. Returns (texels, texels outside the training domain, values clipped, texels whose F0 a
    parameter written as one constant approximates (:func:`matremap.svbrdf.convert.one_constant`), the transform
    file or None, whether it came from a cache); the time spent finding the transform goes to
    ``seconds["transform"]``; ``fitted`` receives the gate's checks of the levels' fits
    (:func:`~matremap.svbrdf.levels.checks`)."""
    target = job.target
    if identity is not None:
        log(f"identity: {_identity_words(identity)}: the maps are copied, nothing is fitted")
        copy_map_set(map_set, folder / "maps", identity)
        return int(np.prod(map_set.size)), 0, 0, 0, None, True
    # metal and dielectric texels first (a metal's kind lets no light through), then a transmission weight map (the
    # kinds with and without it), then a material letting light through at levels of its other maps
    mixed: Blend | None = mixed_parameter(map_set, summary) or transmission_parameter(map_set, summary)
    through = None if mixed is not None else through_levels(map_set, summary)
    mixed = mixed or through or layer_parameter(map_set, summary) or layer_levels(map_set, summary)
    if through is None and mixed is not None and mixed.layer is not None:  # a layer blended per texel
        job = hold_layer_numbers(map_set, summary, mixed, job, log)
    params = summary.sample()
    fits: dict[str, tuple[Material, Any]] = {}
    refined: list[levels.Axis] = []
    if through is not None:  # lets light through: fitted at levels of its roughness (or tint), refined where they part
        job = hold_constants(map_set, summary, through, job, log)
        mixed, refined = fit_levels(map_set, through, job, fits, log)
    if mixed is not None:  # metal and dielectric texels: blended per texel
        texels, outside = remap_mixed(
            folder,
            map_set,
            params,
            mixed,
            target,
            job.fix,
            lambda kind, kind_params: check_before_rendering(
                kind,
                kind_params,
                {},
                target,
                target_renderer,
                complete_fix(kind.model, {**kind.constants, **kind_params}, target, job.fix),
            ),
            lambda kind, out: convert_kind(kind, out, kind_job(job, mixed, kind, summary), log, fits, fitted),
            log,
        )
        if through is not None:
            assert isinstance(mixed, Levels | Grid)
            fitted += levels.checks(mixed, refined, job.thresholds, log)
        return texels, outside, 0, 0, None, False
    held = held_values(map_set, summary, target)
    # the maps' ranges stand for them where only their extremes matter (is any texel diffuse?)
    fix = complete_fix(map_set.model, {**map_set.constants, **summary.ranges(), **held}, target, job.fix)
    check_before_rendering(map_set, params, held, target, target_renderer, fix)
    t0 = time.perf_counter()
    fix, job = held_for_sweep(map_set, summary, held, fix, job, log)
    transform, tpath, cached = _transform_for(map_set, summary, fix, target_renderer, job, log)
    seconds["transform"] = time.perf_counter() - t0
    with warnings.catch_warnings():  # the outside-domain count is logged below
        warnings.simplefilter("ignore", UserWarning)
        report = convert(map_set, [transform], folder / "maps", workers=job.workers or 2)
    transform.save(folder / "transform.json", force=True)  # what was applied, with its provenance
    for note in report.notes:
        log(f"note: {note}")
    log(
        f"convert: {report.texels} texels"
        + (f"; {report.outside} outside the training domain (see maps/{MASK_NAME})" if report.outside else "")
    )
    # values the transform asked for beyond the target's bounds, and values beyond what the files hold
    clipped = int(report.clipped + report.bounded)
    return int(report.texels), int(report.outside), clipped, int(report.approximated), tpath, cached


def convert_kind(
    kind: MapSet,
    out: Path,
    job: RemapJob,
    log: Callable[[str], None],
    fits: dict[str, tuple[Material, Any]] | None = None,
    fitted: list[Check] | None = None,
) -> MapSet:
    """One kind of a map set blended per texel (:func:`~matremap.svbrdf.mixed.remap_mixed`), converted into
    ``out``: remapped as a map set, or, where no map is left (a uniform base under a coat mask, a level of a glass's
    roughness), fitted as one material (:func:`_fit_uniform`, its layers freed) whose values are the kind's
    constants; ``fits`` (kind -> source and fit) receives such a fit. ``fitted`` receives the gate's checks of what
    the evaluation cannot see: a kind that lets light through (a transmission map's glass kind), its fit on the
    transmission probe, or its own levels' (:func:`~matremap.svbrdf.levels.checks`)."""
    if kind.maps:
        nested = remap_into(out, kind, replace(job, evaluate=False), log)
        if fitted is not None:
            fitted += [replace(c, where=f"{kind.root.name}: {c.where}") for c in nested.fitted]
        return converted_set(nested.maps, kind.size)
    if fits is not None and kind.root.name in fits:  # fitted already (a level: svbrdf/levels.py)
        source, r = fits[kind.root.name]
    else:
        source = Material.create(kind.model, dict(kind.constants))
        r = _fit_kind(source, job, log)
        log(f"fit: {kind.root.name} as one material onto {job.target}, relative error {r.loss:.4f}")
        if fits is not None:
            fits[kind.root.name] = (source, r)
        if fitted is not None and "transmission" in layers_on(source.model, source.values):
            fitted += levels.probe_checks([(kind.root.name, r)], float(r.loss), kind.root.name, job.thresholds)
    out.mkdir(parents=True, exist_ok=False)
    params = r.target.to_dict()["params"]
    doc = {"model": r.target.model, "maps": {}, "params": params, "provenance": {"transform": f"fit ({r.loss:.4f})"}}
    write_text(out / "material.json", json.dumps(doc, indent=1) + "\n")
    return MapSet(r.target.model, {}, out, kind.size, kind.normal, params)


def kind_job(job: RemapJob, mixed: Blend, kind: MapSet, summary: MapSummary) -> RemapJob:
    """``job`` for one ``kind`` of the blend ``mixed`` (named by its folder), with where that kind contributes to
    the texels of the maps' library sample (:data:`~matremap.svbrdf.mapstats.LIBRARY_LIMIT`) as ``within``: the
    mask :func:`library_transform` judges a route's coverage on (a metal's route need not cover the dielectric
    texels: BoomBox's metal kind onto Cycles Principled read 45 % covered over all texels, 70 % where it is used)."""
    sampled = summary.sample(LIBRARY_LIMIT)
    values = {n: np.asarray(sampled[n], dtype=np.float32) for n in mixed.inputs if n in sampled}
    if len(values) < len(mixed.inputs) or kind.root.name not in mixed.kinds or np.ndim(values[mixed.name]) < 2:
        return job
    share = mixed.band_weights(values)[0][mixed.kinds.index(kind.root.name)]
    return replace(job, within=np.abs(share) > TOLERANCE)


def _fit_kind(source: Material, job: RemapJob, log: Callable[[str], None]) -> Any:
    """The fit of one uniform kind of a blended map set (:func:`convert_kind`): a layer colour the source has not
    held white (the kinds are blended: no colour one of them invents), a glass a dielectric, a partial metal's
    metalness freed."""
    white = {c: [1.0, 1.0, 1.0] for c in invented_colours(source, job.target) if c not in job.fix}
    job = replace(job, fix={**job.fix, **white})
    held = uniform_remap.choose_held(source, job.target, job.fix, log)
    job, fix, metal = (replace(job, strategy="simple") if held.start else job), held.fix, held.start
    # a layered model's kinds fitted alike, with the layer on or off (a sheen map's black level onto OpenPBR: 0.037
    # two-stage, 0.0068 three-stage); a glass's levels keep their one fit on the transmission probe
    alike = source.model in LAYER_PARAMS and "transmission" not in layers_on(source.model, source.values)
    return _fit_uniform(source, job, fix, log, metal, both=alike)[0]


def fit_levels(
    map_set: MapSet,
    through: Levels | Grid,
    job: RemapJob,
    fits: dict[str, tuple[Material, Any]],
    log: Callable[[str], None],
) -> tuple[Levels | Grid, list[levels.Axis]]:
    """``through`` fitted at its levels (each axis of a Grid with the other held at its typical value) and refined
    where a midpoint parts from them (:func:`~matremap.svbrdf.levels.refine`); the fits go into ``fits``. Returns
    the refined levels and each axis with its fits and midpoint errors, for the gate."""
    axes = through.axes if isinstance(through, Grid) else (through,)
    refined: list[levels.Axis] = []
    for axis in axes:
        others = through.others(axis) if isinstance(through, Grid) else {}
        axis_job = job
        if isinstance(through, Grid) and axis is through.tint and axis.per_channel:
            axis_job = crossing_numbers(map_set, through, job, log)
        fit_at = level_fits(map_set, axis, others, axis_job, fits, log)
        final, midpoints = levels.refine(axis, fit_at, log)
        refined.append((final, fit_at, midpoints))
    if isinstance(through, Grid):
        return Grid(refined[0][0], refined[1][0], through.corners), refined
    return refined[0][0], refined


def crossing_numbers(map_set: MapSet, grid: Grid, job: RemapJob, log: Callable[[str], None]) -> RemapJob:
    """``job`` with every number of the target held at one fit where a glass's :class:`Grid` crosses (its typical
    roughness and colour), for the fits of its colour's levels: the blend takes a texel's numbers from the roughness
    levels and only its colours from the colour's, so those must be fitted as colours alone. Left free, the black
    level of Khronos GlassHurricaneCandleHolder's glass was fitted as an opaque black dielectric (OpenPBR
    transmission_weight 0.0001, IOR 1.78, an arbitrary transmission_color (0, 0, 0.73)), and at its roughest black
    texel the blend wrote that colour under the roughness levels' transmission weight 1: 0.45 off."""
    spec = get_model(job.target)
    base = Material.create(map_set.model, {**map_set.constants, **grid.held})
    typical = grid.tint.typical or (1.0, 1.0, 1.0)
    source = levels.at(grid.tint, levels.at(grid.rough, base, grid.typical_roughness), typical)
    r = _fit_kind(source, job, log)
    values = r.target.to_dict()["params"]
    held = {p.name: values[p.name] for p in spec.params if p.channels == 1 and p.name not in job.fix}
    log(
        f"levels: {_listed(held)} held at the fit at the typical texel (roughness {grid.typical_roughness:.3g}, "
        f"colour {np.round(typical, 3).tolist()}; relative error {r.loss:.4f}) for the colour's levels"
    )
    return replace(job, fix={**job.fix, **held})


def level_fits(
    map_set: MapSet,
    through: Levels,
    others: Mapping[str, Any],
    job: RemapJob,
    fits: dict[str, tuple[Material, Any]],
    log: Callable[[str], None],
) -> levels.FitAt:
    """The fit of ``map_set`` at one level of ``through`` (the source at that level, its other maps held, and
    ``others``: a :class:`~matremap.svbrdf.mixed.Grid`'s other axis at its typical value), each made once and kept
    in ``fits`` under the kind's name (:func:`convert_kind` reuses it)."""
    base = Material.create(map_set.model, {**map_set.constants, **through.held, **others})

    def fit_at(value: float) -> tuple[Material, Any]:
        key = replace(through, levels=(value,)).kinds[0]
        if key not in fits:
            source = levels.at(through, base, value)
            r = _fit_kind(source, job, log)
            log(f"fit: {key} as one material onto {job.target}, relative error {r.loss:.4f}")
            fits[key] = (source, r)
        return fits[key]

    return fit_at


def hold_layer_numbers(
    map_set: MapSet, summary: MapSummary, layered: Blend, job: RemapJob, log: Callable[[str], None]
) -> RemapJob:
    """``job`` with target parameters held at one fit at the maps' typical texel (each map at its median) before a
    layer's maps are blended per texel (:func:`~matremap.svbrdf.mixed.layer_levels`, a weight map): those the
    target's file takes as numbers only (glTF's ior: the kinds' fits set them apart and the blend made a map of them,
    refused when written), and under a coat's colour levels every number the sweep does not map: the colour tints
    what passes through the coat, channel by channel, and moves none of them, but each level's fit would trade them
    against it (a Standard Surface copper coat coloured by an image onto OpenPBR: coat_weight 0.75 at coat_color
    0.95, and the coat's weight, roughness and the base's IOR became maps of that trade). Under a sheen's colour the
    base's numbers are held so, the sheen's own weight and roughness left free: its brightness is the layer's weight
    in some models (OpenPBR's fuzz_weight follows glTF's sheen colour, 0.003 to 0.71 over SheenCloth's five levels;
    the base's specular_ior, fitted per level, ran 1.50 to 1.33 and made a map a glTF output cannot hold); and so
    is the axis a Grid converts at (the layer's roughness) left free. Under a coat's colour the target's other colours
    the sweep does not map are held too (a base colour)."""
    from matremap.formats import written_constants
    from matremap.renderers.registry import texture_refusal

    spec = get_model(job.target)
    constant = [
        p.name
        for p in spec.params
        if p.name not in job.fix and (p.name in written_constants(spec.id) or texture_refusal(spec.id, [p.name]))
    ]
    tint = layered.tint if isinstance(layered, Grid) else layered
    per_channel = isinstance(tint, Levels) and tint.per_channel
    colour = isinstance(tint, Levels) and tint.colour
    if not constant and not colour:
        return job
    held_maps = held_values(map_set, summary, job.target)
    values_at = base_values(map_set, summary, held_maps)
    if isinstance(layered, Mixed):
        # a weight map's kinds are the material with the layer and without: the base's numbers are the bare base's
        # (glTF's ior fitted under a coat at the typical texel, 1.565 for a 1.5 dielectric, held over the bare kind
        # sent its sweep's roughness to 1 and a quarter of the texels outside; not held, a glTF output refused the
        # ior map the blend made)
        values_at[layered.name] = layered.value(layered.kinds[1])
    if isinstance(tint, Levels) and colour:  # the fit the levels' numbers are held at: at a grey, as every level is
        values_at[tint.name] = [float(tint.level_of(np.asarray(values_at[tint.name], dtype=float)))] * 3
    source = Material.create(map_set.spec.id, values_at)
    r = _fit_kind(source, job, log)
    values = r.target.to_dict()["params"]
    names = set(constant)
    if colour:
        metal = spec.specialise(values).diffuse_only is None
        mapped = {  # what the sweep maps the base maps onto (the quantities the maps vary)
            getattr(qty.roughness_param(spec), "name", None),
            getattr(qty.diffuse_param(spec), "name", None),
            spec.reflectance.driven_param(metal) if spec.reflectance is not None else None,
        }
        kind = {**{n: values[n] for n, _, _ in spec.specialisations if n in values}, **job.fix}  # a metal or not
        base_maps = set(map_set.maps) - set(layer_textures(map_set.model, map_set.maps))
        # no base map: every level is one uniform fit, and nothing is swept
        mapped = mapped - set(unswept_params(map_set, summary, held_maps, spec, kind)) if base_maps else set()
        own = LAYER_PARAMS.get(spec.id, {}).get(tint.layer or "")
        mapped.add(getattr(own, "colour", None))  # what the levels convert
        if isinstance(layered, Grid) or not per_channel:  # a sheen's weight and roughness follow its brightness
            mapped |= {getattr(own, "roughness", None), getattr(own, "weight", None)}
        # under a coat's colour, the colours too where the target's coat has one: a metal's colour under a coloured
        # coat is the same product either way (base_color x coat_color), and each level's fit split it differently (a
        # brass-like white metal under an image coat onto OpenPBR: coat_color 1.0, 0.33, 0.23, 0.64 at the roughness
        # levels, one level's sweep left 5 points); without one, each level absorbs the coat's colour into the base's
        coloured = per_channel and own is not None and own.colour is not None
        names |= {
            p.name
            for p in spec.params
            if p.name not in job.fix and p.name not in mapped and (p.channels == 1 or coloured)
        }
    held = {k: values[k] for k in spec.param_names if k in names and k in values}
    if held:
        why = f"{tint.name} varies; it moves none of them" if colour else f"{job.target} takes them as numbers only"
        log(f"levels: {_listed(held)} held at the fit at the typical texel, relative error {r.loss:.4f} ({why})")
    return replace(job, fix={**job.fix, **held})


def hold_constants(
    map_set: MapSet, summary: MapSummary, through: Levels | Grid, job: RemapJob, log: Callable[[str], None]
) -> RemapJob:
    """``job`` with the target's parameters that its renderers or its file format take only as constants (Mitsuba 3
    principled's ``specular`` and ``eta``, roughdielectric's ``int_ior``, glTF's ``ior``) held at the values one fit
    at the map's median gives, before a material is converted at the levels of ``through``: each level's fit would
    set them apart, and the blend would ask for a map of them (written to glTF, an ior map was refused after every
    fit). Under a colour's levels every number of the target is held so: a glass's tint moves none of them (fitted
    per level, OpenPBR's roughness, IOR and transmission weight became maps of fit noise)."""
    from matremap.formats import written_constants
    from matremap.renderers.registry import texture_refusal

    spec = get_model(job.target)
    constant = set(written_constants(spec.id))
    tint = isinstance(through, Levels) and through.per_channel  # a glass's colour alone: no number follows it
    names = [
        p.name
        for p in spec.params
        if p.name not in job.fix
        and (p.name in constant or texture_refusal(spec.id, [p.name]) or (tint and p.channels == 1))
    ]
    if not names:
        return job
    median = float(np.median(np.asarray(summary.sample()[through.name], dtype=float)))
    axis = through.rough if isinstance(through, Grid) else through
    others = through.others(axis) if isinstance(through, Grid) else {}
    base = Material.create(map_set.model, {**map_set.constants, **through.held, **others})
    r = _fit_kind(levels.at(axis, base, median), job, log)
    held = {n: r.target.to_dict()["params"][n] for n in names}
    log(
        f"levels: {_listed(held)} held at the fit at the median {through.name} {median:.3g} (relative error "
        f"{r.loss:.4f}): "
        f"{job.target} takes {'them' if len(held) > 1 else 'it'} as a constant only"
    )
    return replace(job, fix={**job.fix, **held})


def _listed(values: Mapping[str, Any], first: int = 4) -> str:
    """Parameter values for the log: the ``first`` few, and how many more."""
    shown = ", ".join(f"{k} {np.round(v, 4).tolist()}" for k, v in list(values.items())[:first])
    return shown + (f" and {len(values) - first} more" if len(values) > first else "")


def _transform_for(
    map_set: MapSet,
    summary: MapSummary,
    fix: Mapping[str, Any],
    target_renderer: str,
    job: RemapJob,
    log: Callable[[str], None],
) -> tuple[Transform, Path | None, bool]:
    """A library route that covers the maps, else the cached (or newly swept and learned) transform."""
    target = job.target
    probes = library_probes(job)
    if job.library and probes and target_renderer == renderer_for(target) and job.strategy == "two-stage":
        transform = library_transform(
            map_set,
            summary.sample(LIBRARY_LIMIT),
            target,
            fix,
            log,
            probes=probes,
            envmap=job.envmap,
            within=job.within,
        )
        if transform is not None:
            return transform, None, True
    elif job.library:
        log(
            "library: not used (its transforms are two-stage fits under the headlight or the built-in environment, "
            "each model drawn by its default renderer)"
        )
    scene, objective = sweep_probe(job)
    return cached_transform(
        map_set,
        summary,
        target,
        fix,
        job.strategy,
        job.cache or default_cache(),
        job.workers,
        log,
        scene,
        target_renderer,
        objective,
    )


def identity_route(map_set: MapSet, target: str, fix: Mapping[str, Any]) -> Equivalence | None:
    """The renaming that makes the remap the identity, or None: the same model, or a model the dialects
    show to be equal (:mod:`matremap.dialects.equivalence`) for these maps, and every fixed option as the
    maps have it (a fixed parameter value is a change, so it is not)."""
    eq = equivalence(map_set.model, target)
    if eq is None or eq.refusal(map_set.constants, map_set.maps, map_set.normal is not None) is not None:
        return None
    return eq if same_options(eq.rename(map_set.options), eq.target, fix) else None


def copy_map_set(map_set: MapSet, dest: Path, eq: Equivalence) -> None:
    """The map set copied byte for byte into ``dest``, with a manifest naming its maps in the target's
    terms (``eq``: the renaming onto an equal model)."""
    dest.mkdir(parents=True, exist_ok=False)
    names: dict[Path, str] = {}
    for f in [*map_set.maps.values(), *([map_set.normal] if map_set.normal else [])]:
        if f not in names:
            name = f.name if f.name not in names.values() else f"{len(names)}_{f.name}"
            shutil.copyfile(f, dest / name)
            names[f] = name
    doc: dict[str, Any] = {
        "model": eq.target,
        "maps": {eq.names[k]: names[f] for k, f in map_set.maps.items()},
        "params": eq.rename(map_set.constants),
        "colorspace": {names[f]: map_set.colorspace[k] for k, f in map_set.maps.items() if k in map_set.colorspace},
    }
    if map_set.normal:
        doc["normal"] = names[map_set.normal]
    source = source_reference(map_set.root, dest)
    doc["provenance"] = {"source": source, "source_model": map_set.model, "transform": "identity"}
    write_text(dest / "material.json", json.dumps(doc, indent=1) + "\n")


def check_before_rendering(
    map_set: MapSet,
    params: Mapping[str, Any],
    held: Mapping[str, float],
    target: str,
    target_renderer: str,
    fix: Mapping[str, Any],
) -> None:
    """What can be known before a sweep: the target's renderer draws it and is installed, and the
    renderers that draw the target take as textures the parameters that the maps' varying quantities
    (roughness, F0, diffuse albedo, read from the maps themselves) will drive, the target held as ``fix``
    says (metallic: a metal's F0 drives its base colour, a dielectric's its specular level). A parameter
    taken as one number only (Mitsuba 3 principled's ``specular``) is written as one constant, the median
    (:func:`matremap.svbrdf.convert.one_constant`), where the maps' F0 does not vary as the gate's ``flat``
    check counts it (:func:`~matremap.svbrdf.quality.varies`); where it does, the constant would fail that
    check, so it is refused here, before the sweep."""
    from matremap.renderers.registry import can_draw, get_renderer, texture_refusal
    from matremap.svbrdf.convert import target_param
    from matremap.svbrdf.quality import varies

    if not can_draw(target_renderer, target):
        raise MatremapError(f"renderer {target_renderer!r} cannot draw {target}; {renderer_for(target)!r} does")
    get_renderer(target_renderer)  # one that is not installed says so now, not after the sweep
    probe = next((np.asarray(v) for v in params.values() if np.ndim(v) >= 2), None)
    shape = sample(probe).shape[:2] if probe is not None else (1, 1)
    quantities = _quantity_sample(map_set.spec, {**map_set.constants, **params, **held}, shape)
    tgt = get_model(target)
    metal = tgt.specialise(fix).diffuse_only is None
    constant = tgt.reflectance.constant_param(metal) if tgt.reflectance is not None else None
    driven = []
    for q, values in quantities.items():
        name = target_param(tgt, q, metal)
        if name is None or np.ptp(np.asarray(values, dtype=float)) <= 1e-6:
            continue
        if name == constant and varies(values):
            raise MatremapError(f"{texture_refusal(target, [name])}, and {_varying_f0(values, name, target)}")
        if name != constant:
            driven.append(name)
    why = texture_refusal(target, driven)
    if why is not None:
        raise MatremapError(f"{why}, and the maps vary it; choose a target that takes it as a map")


def _varying_f0(f0: Any, name: str, target: str) -> str:
    """The refusal's reason: how the maps' F0 varies, and targets that take the parameter it drives as a map
    (those that express F0 as the target does first, a principled BSDF for a principled BSDF)."""
    from matremap.renderers.registry import texture_refusal
    from matremap.svbrdf.convert import target_param
    from matremap.svbrdf.quality import VARIES, luminance

    lo, hi = np.percentile(luminance(np.asarray(f0, dtype=float).reshape(-1, 3)), [5, 95])
    tgt = get_model(target)

    def order(m: Any) -> tuple[bool, bool, str]:
        return type(m.reflectance) is not type(tgt.reflectance), m.family != tgt.family, m.id

    others = [
        m.id
        for m in sorted(list_models(), key=order)
        if qty.diffuse_param(m) is not None
        and (driven := target_param(m, "reflectance", metal=False)) is not None
        and texture_refusal(m.id, [driven]) is None
    ]
    return (
        f"the maps' F0 varies ({lo:.3g} to {hi:.3g} over the middle 90% of the texels; the quality gate calls a "
        f"spread over {VARIES:g} varying): one {name} would flatten it; choose a target that takes it as a map"
        + (f", e.g. {' or '.join(others[:2])}" if others else "")
    )


def _quantity_sample(spec: Any, values: Mapping[str, Any], shape: tuple[int, ...]) -> dict[str, np.ndarray]:
    """The common-vocabulary quantities of sampled maps and broadcast constants."""
    arrays = {}
    for p in spec.params:
        v = np.asarray(values.get(p.name, p.default_array), dtype=float)
        if v.ndim >= 2:
            v = sample(v)
            if p.channels == 3 and v.ndim == 2:
                v = np.repeat(v[..., None], 3, axis=-1)
            elif p.channels == 1 and v.ndim == 3:
                v = v[..., 0]
        else:
            v = np.broadcast_to(v.reshape(-1)[: p.channels], (*shape, p.channels) if p.channels == 3 else shape)
        arrays[p.name] = v
    return qty.read(spec, arrays)


def map_quality(
    source: MapSet,
    source_params: Mapping[str, Any],
    target: MapSet,
    target_params: Mapping[str, Any],
    limits: Thresholds,
) -> list[Check]:
    """The map checks of the gate: hue and flatness of the diffuse albedo and F0, source against result, each
    as seen through a coloured coat (:func:`~matremap.dialects.mtlx.coat_tint`: a copper-tinted coat over a
    textured base is absorbed into a glTF base colour, whose hue then differs from the source's base map by
    25 degrees and is right), the diffuse as much of it as does not let light through
    (:func:`~matremap.dialects.mtlx.opaque_share`)."""
    probe = next((np.asarray(v) for v in source_params.values() if np.ndim(v) >= 2), None)
    shape = sample(probe).shape[:2] if probe is not None else (1, 1)
    sides = []
    for side, params in ((source, source_params), (target, target_params)):
        values = {**side.constants, **params}
        try:
            q = _quantity_sample(side.spec, values, shape)
        except (MatremapError, ValueError) as e:  # a quantity a model cannot read: no map checks, said so
            return [Check("map_checks", 0.0, 0.0, f"skipped: {e}")]
        sampled = {k: sample(v) for k, v in values.items()}
        tint = coat_tint(side.model, sampled)
        if tint is not None:  # a dielectric's F0 keeps its own (grey) hue: a target's cannot take the coat's
            metal = side.spec.specialise(values).diffuse_only is None
            q = {k: v * tint if k == "diffuse" or (k == "reflectance" and metal) else v for k, v in q.items()}
        opaque = opaque_share(side.model, sampled)
        if opaque is not None and "diffuse" in q:  # a glass's base colour is its tint, no diffuse one sees
            q["diffuse"] = q["diffuse"] * (opaque[..., None] if opaque.ndim else opaque)
        sides.append(q)
    layers = layer_checks(
        source.spec, {**source.constants, **source_params}, target.spec, {**target.constants, **target_params}, limits
    )
    return map_checks(sides[0], sides[1], limits) + layers


# ---------------------------------------------------------------------------------------------
# material files


@dataclass
class FileRemapResult:
    file: Path | None
    source_model: str
    target_model: str
    textured: bool
    remap: RemapResult | None = None
    material: Material | None = None
    loss: float | None = None
    notes: list[str] = field(default_factory=list)
    verdict: Verdict = field(default_factory=Verdict)


def default_suffix(target: str, source_format: str) -> str | None:
    """The file a target model's users read: glTF (or MaterialX when the input was one) for
    ``gltf:*``, MaterialX for ``mtlx:*``, Mitsuba 3 XML for ``mitsuba3:*``, a .blend for ``cycles:*``, USD
    (.usda) for ``usd:*``; None otherwise, or when no writer of that format takes the model."""
    from matremap.formats import format_for, written_models

    family = target.split(":", 1)[0]
    if family == "gltf":
        suffix = {"gltf": None, "mtlx": ".mtlx"}.get(source_format, ".gltf")
    else:
        suffix = {"mitsuba3": ".xml", "cycles": ".blend", "usd": ".usda", "mtlx": ".mtlx"}.get(family)
    if suffix is not None and get_model(target).id not in written_models(format_for(f"x{suffix}")):
        return None  # a model of the family no writer takes yet: its maps and material.json only
    return suffix


def remap_file(
    path: str | Path,
    target_model: str,
    out: str | Path,
    *,
    material: str | int | None = None,
    fix: Mapping[str, Any] | None = None,
    write: str | None = None,
    force: bool = False,
    log: Callable[[str], None] = print,
    **options: Any,
) -> FileRemapResult:
    """Remap one material of a glTF/.glb, MaterialX or Mitsuba XML file onto ``target_model`` and
    write it in the target's own format into ``out``, all or nothing (``write`` names the file; default:
    the input's name with the target format's suffix). A textured material goes through
    :func:`remap_into` (``out/source`` holds its maps as matremap reads them, ``out/maps`` the converted
    ones); a uniform one is fitted directly (copied when it is the identity). ``options`` are the fields
    of :class:`RemapJob`. The result carries the quality gate's verdict."""
    with texel_limit(options.get("max_texels")):  # checked on every header the readers open
        return _remap_file(path, target_model, out, material, fix, write, force, log, options)


def _remap_file(
    path: str | Path,
    target_model: str,
    out: str | Path,
    material: str | int | None,
    fix: Mapping[str, Any] | None,
    write: str | None,
    force: bool,
    log: Callable[[str], None],
    options: Mapping[str, Any],
) -> FileRemapResult:
    """:func:`remap_file`, inside its texel limit."""
    from matremap.formats import read_asset, write_asset

    p = Path(path)
    with recorded_references() as references:
        asset = read_asset(p, material)
    for note in asset.notes:
        log(f"note: {note}")
    target = get_model(target_model).id
    out = Path(out)
    if out.resolve() == p.resolve().parent:
        raise MatremapError(f"{out} is the input file's folder; choose another output folder")
    name = _output_name(p, target, asset.format, write, out, log)
    job = checked_job(
        RemapJob(target, dict(fix or {}), **{k: v for k, v in options.items() if v is not None or k == "scene"})
    )
    job = anisotropic_probe(job, asset.model, log)
    job = same_distribution(job, asset.model, asset.constants, log)
    kept = asset.format in ("gltf", "mitsuba-xml") and target == asset.model
    kept = kept and same_options(asset.constants, target, job.fix)
    if asset.lost and not kept:  # a material onto its own model keeps its layers; anything else loses them
        raise MatremapError(
            f"{p}: material {asset.name!r} carries its look in {'; '.join(asset.lost)}, which matremap does not "
            f"convert (a layer on a textured material, or one no model draws): converting the rest to {target} "
            "would be wrong, so it is not converted"
        )
    read = [p, *references, *(t.path for t in asset.textures.values() if not t.extracted), *cache_folders(job)]
    with staged_folder(out, force, protected=read) as stage:
        result = FileRemapResult(None, asset.model, target, asset.textured, notes=list(asset.notes))
        if asset.textured:
            if equivalence(asset.model, target) is not None:  # an identity copies the maps as they are
                asset.coverage = None
            before = len(asset.notes)
            source_dir = asset.to_map_set(stage / "source")
            for note in asset.notes[before:]:  # what reading the maps decided (the texels the surface shows)
                log(f"note: {note}")
                result.notes.append(note)
            result.remap = remap_into(stage, load_map_set(source_dir), job, log, title=f"{asset.model} -> {target}")
            result.verdict = result.remap.verdict
            produced: Any = converted_set(stage / "maps")
        else:
            produced = _remap_uniform(asset.material(), job, stage, result, log)
            if asset.normal is not None:
                produced = keep_normal(produced, asset, stage / "source", name is not None, log)
        if name is not None:
            # every writer gets the asset: a writer of the same format copies its document, any writer
            # carries what it has a slot for (asset.carried: emission, occlusion, opacity)
            before = len(asset.notes)
            result.file = write_asset(stage / name, produced, source=asset, force=True)
            for note in asset.notes[before:]:  # what the writer carried over or left behind
                log(f"note: {note}")
                result.notes.append(note)
        result.verdict = dropped_check(asset, result.verdict, kept, job.thresholds)
        write_text(stage / "verdict.json", json.dumps(result.verdict.to_dict(), indent=1) + "\n")
    if result.remap is not None:
        result.remap = result.remap.moved(stage, out)
    if result.file is not None:
        result.file = out / result.file.relative_to(stage)
        log(f"wrote {result.file}")
    return result


def dropped_check(asset: Any, verdict: Verdict, kept: bool, thresholds: Thresholds) -> Verdict:
    """``verdict`` with the gate's ``dropped`` check: the inputs of ``asset`` that change its look and that no model
    here converts (``asset.dropped``: an anisotropy, a subsurface, a thin film), which no render of the models can
    show, so that no other measure sees them lost; none when the file is copied onto its own model (``kept``: a glTF
    copy keeps its extensions). Before, OpenPBR's brushed aluminium (anisotropy 0.9) went onto glTF as an isotropic
    metal with a note and exit 0. ``--max-error dropped=N`` accepts N of them."""
    if kept or not asset.dropped:
        return verdict
    n = len(asset.dropped)
    where = f"left out: {', '.join(asset.dropped)} (no model here converts it; --max-error dropped={n} accepts)"
    return Verdict([*verdict.checks, Check("dropped", float(len(asset.dropped)), thresholds.dropped, where)])


def held_for_sweep(
    map_set: MapSet,
    summary: MapSummary,
    held: Mapping[str, float],
    fix: dict[str, Any],
    job: RemapJob,
    log: Callable[[str], None],
) -> tuple[dict[str, Any], RemapJob]:
    """``fix`` and ``job`` with the target values a sweep of maps holds, each fitted once at the maps' typical
    texel: a uniform partial metal's metalness (:func:`hold_partial_metal`), a uniform layer (:func:`hold_layers`)."""
    fix, job = hold_partial_metal(map_set, summary, held, fix, job, log)
    return hold_layers(map_set, summary, held, fix, job, log)


def hold_partial_metal(
    map_set: MapSet,
    summary: MapSummary,
    held: Mapping[str, float],
    fix: dict[str, Any],
    job: RemapJob,
    log: Callable[[str], None],
) -> tuple[dict[str, Any], RemapJob]:
    """``fix`` and ``job`` for the sweep of maps whose material is a uniform partial metal (its metalness one value
    strictly between 0 and 1, a colour texture beside it): the target's metalness, where the user left it open, is
    fitted once on the maps' typical texel (freed from the source's, :func:`free_partial_metal`) and held while the
    sweep fits the other maps under it, with the simple strategy (the base colour is both the diffuse and the
    metal's colour, which the staged strategies' parts split apart). Held at 0, as a material with a diffuse part is
    otherwise, usd-wg's RoughnessTest Const033 (UsdPreviewSurface metallic 0.6 over a colour texture) onto glTF
    failed: a dielectric cannot draw the bright coloured specular of the texture's lighter half (IOR at its bound
    5), those fits were left out, and 97 % of the texels fell outside the learned domain."""
    source = Material.create(map_set.spec.id, base_values(map_set, summary, held))
    free_job, free_fix, metal = free_partial_metal(source, job, fix, log)
    if not metal:
        return fix, job
    r, _ = _fit_uniform(source, free_job, free_fix, log, metal)
    values = {name: round(float(r.target.values[name][0]), 6) for name in metal}
    shown = ", ".join(f"{k} {v:g}" for k, v in values.items())
    log(
        f"partial metal: {shown} fitted at the maps' median texel (relative error {r.loss:.4f}), held while the sweep "
        "fits the other maps under it (simple strategy)"
    )
    return {**fix, **values}, replace(job, strategy="simple")


def hold_layers(
    map_set: MapSet,
    summary: MapSummary,
    held: Mapping[str, float],
    fix: dict[str, Any],
    job: RemapJob,
    log: Callable[[str], None],
) -> tuple[dict[str, Any], RemapJob]:
    """``fix`` and ``job`` for the sweep of maps under a uniform layer (a coat or sheen of one value over the
    whole material): the layer is a constant of the transform. It is fitted once, with the target's own layer
    freed and started at the source's (:func:`_fit_uniform`), on the source at the maps' typical texel (each map
    at its median, :func:`base_values`), and the target's fitted layer values are then held while the sweep fits
    the base maps under them, ``three-stage``: with a held coat a two-stage fit stops short (a gltf:pbr coat over
    a rough brown dielectric onto OpenPBR: 0.37 two-stage, 0.29 three-stage held at the source's coat, 0.006
    with the coat fitted first). A target without the layer absorbs it in each fit (noted; the gate judges
    the look). The library is not used: its transforms were learned on materials without layers."""
    on = layers_on(map_set.model, map_set.constants)
    if not on:
        return fix, job
    log(f"library: not used (its transforms were learned on materials without a {' or '.join(on)})")
    job = replace(job, library=False)
    source = Material.create(map_set.spec.id, base_values(map_set, summary, held))
    white = {c: [1.0, 1.0, 1.0] for c in invented_colours(source, job.target) if c not in job.fix}
    job, fix = replace(job, fix={**job.fix, **white}), {**fix, **white}
    free, _ = freed_layers(source.model, source.values, get_model(job.target), held=job.fix)
    staged = "three-stage" if job.strategy == "two-stage" else job.strategy
    sweep_job = staged_strategy(replace(job, strategy=staged), log)
    if not free:
        for note in absorbed_layers(source.model, source.values, job.target, {}):
            log(f"note: {note}")
        return fix, sweep_job
    r, _ = _fit_uniform(source, job, fix, log)
    spec = get_model(job.target)
    unswept = [n for n in unswept_params(map_set, summary, held, spec, fix) if n not in job.fix]
    values = {
        name: float(r.target.values[name][0]) if spec.param(name).channels == 1 else r.target.values[name].tolist()
        for name in [*free, *unswept]
    }
    shown = ", ".join(f"{k} {np.round(v, 3).tolist()}" for k, v in values.items())
    log(
        f"layers: {shown} fitted at the maps' median texel (relative error {r.loss:.4f}), held while the sweep "
        "fits the base maps under them"
    )
    return {**fix, **values}, sweep_job


def invented_colours(source: Material, target: str) -> list[str]:
    """The target's layer colours (a coat colour, a sheen tint) whose layer the source has with no colour (a glTF
    clear coat, a white coat): held white over maps. Freed, the fit at the typical texel may darken the coat
    instead of the base, and the held dark coat then leaves the brighter texels out of the base's range (the
    ClearcoatWicker onto Standard Surface: coat_color 0.33 grey, every texel outside the learned domain; held white,
    0.0014)."""
    from matremap.dialects.mtlx import LAYER_PARAMS, layer_colour

    own, theirs = LAYER_PARAMS.get(target, {}), LAYER_PARAMS.get(source.model, {})
    out = []
    for name, layer in own.items():
        if layer.colour is None or layer.weighted_colour or name not in theirs:
            continue
        if np.allclose(layer_colour(source.values, theirs[name]), 1.0):
            out.append(layer.colour)
    return out


def unswept_params(
    map_set: MapSet, summary: MapSummary, held: Mapping[str, float], target: Any, fix: Mapping[str, Any]
) -> list[str]:
    """The target's parameters for the quantities (roughness, F0, diffuse) that do not vary over the maps (no
    axis of :func:`sweep_grid`): under a held layer they are held too, at the value fitted at the maps' typical
    texel. Left free, a sweep under an OpenPBR coat moved the base's specular_ior to its bound 1 at most points
    (a glTF coat over F0 0.04: losses up to 0.27, 3 of 20 points usable)."""
    spec = map_set.spec
    axes = {a.split("=", 1)[0] for a in sweep_grid(map_set, summary, held).split(",")}
    metal = spec.specialise({**map_set.constants, **summary.sample(), **held}).diffuse_only is None
    sources = {
        "roughness": qty.roughness_param(spec),
        "diffuse": qty.diffuse_param(spec),
    }
    swept = {q for q, p in sources.items() if p is not None and p.name in axes}
    if spec.reflectance is not None and spec.reflectance.driven_param(metal) in axes:
        swept.add("reflectance")
    target_metal = target.specialise(fix).diffuse_only is None
    diffuse = qty.diffuse_param(target)
    names = {
        "roughness": getattr(qty.roughness_param(target), "name", None),
        "diffuse": getattr(diffuse, "name", None),
        "reflectance": target.reflectance.driven_param(target_metal) if target.reflectance is not None else None,
    }
    out = []
    for q, name in names.items():
        if q in swept or name is None or name in fix or not target.param(name).fit:
            continue
        if q == "reflectance" and diffuse is not None and name == diffuse.name and "diffuse" in swept:
            continue  # a base colour that is the diffuse too (a glTF metal's)
        out.append(name)
    return out


def keep_normal(material: Material, asset: Any, folder: Path, written: bool, log: Callable[[str], None]) -> Any:
    """A uniform result and the source's normal map (a uniform material has no place for it) as a map set of
    no maps, so that the written file keeps the normal map (it was dropped, with exit 0, for any target but
    the source's own format)."""
    if not written:
        log("note: the source's normal map is not kept: no material file is written for this target")
        return material
    normal = asset.normal_file(folder)
    log("note: the source's normal map is carried into the written file unchanged")
    return MapSet(material.model, {}, folder, normal=normal, constants=material.to_dict()["params"])


def anisotropic_probe(job: RemapJob, model: str, log: Callable[[str], None]) -> RemapJob:
    """``job`` with the probe of :data:`~matremap.uniform_remap.ANISOTROPIC_PROBE_LIGHTS` when a fit from ``model``
    sees two roughnesses (:func:`~matremap.uniform_remap.anisotropic_lights`) and no probe was given."""
    if job.scene is not None or uniform_remap.anisotropic_lights(model, job.target) is None:
        return job
    log(f"note: {model} is anisotropic: fitted under lights at {ANISOTROPIC_PROBE_LIGHTS} degrees (both roughnesses)")
    return replace(job, scene=Scene.probe(ANISOTROPIC_PROBE_LIGHTS))


#: the family of each microfacet distribution an option names: GGX drawn with its multiple scattering (Cycles'
#: multi_ggx) is GGX; Mitsuba 0.6's ``as`` is Cycles' ``ashikhmin_shirley``
DISTRIBUTION_FAMILY = {"multi_ggx": "ggx", "ashikhmin_shirley": "as"}


def same_distribution(job: RemapJob, model: str, options: Mapping[str, Any], log: Callable[[str], None]) -> RemapJob:
    """``job`` with the target's ``distribution`` option set to the source's microfacet distribution where the user
    left it open and the target's default is another one (:func:`~matremap.core.models.microfacet_of`): a glTF,
    UsdPreviewSurface or MaterialX material draws GGX, and Mitsuba 3's rough plastic and conductor default to
    Beckmann, whose lobe has no GGX tail (UsdPreviewSurface at roughness 1 onto Mitsuba 3's rough plastic: 0.38 as
    Beckmann, 0.015 as GGX). A target whose default is of the same family keeps it (Cycles' Principled BSDF:
    multi_ggx for a GGX source)."""
    spec = get_model(job.target)
    if "distribution" in job.fix or "distribution" not in spec.option_names:
        return job
    source = microfacet_of(get_model(model), options)
    option = spec.option("distribution")
    if source is None:
        return job
    family = DISTRIBUTION_FAMILY.get(source, source)
    if DISTRIBUTION_FAMILY.get(option.default, option.default) == family:
        return job
    same = [c for c in option.choices if DISTRIBUTION_FAMILY.get(c, c) == family]
    if not same:
        return job
    choice = source if source in same else same[0]
    log(
        f"note: {job.target} distribution={choice}, the source's microfacet distribution (its default is "
        f"{option.default}; --fix distribution={option.default} to keep it)"
    )
    return replace(job, fix={**job.fix, "distribution": choice})


def uniform_identity(source: Material, target: str, fix: Mapping[str, Any]) -> Equivalence | None:
    """The renaming that makes a uniform remap the identity (see :func:`identity_route`), or None."""
    eq = equivalence(source.model, target)
    if eq is None or eq.refusal({**source.values, **source.options}, (), False) is not None:
        return None
    return eq if same_options(eq.rename(source.options), eq.target, fix) else None


def _identity_words(eq: Equivalence) -> str:
    if eq.source == eq.target:
        return f"{eq.source} onto itself with the same options"
    return f"{eq.source} equals {eq.target} (renamed: the dialects draw the same BRDF)"


def same_options(values: Mapping[str, Any], model: str, fix: Mapping[str, Any]) -> bool:
    """Whether ``fix`` changes none of the model's options from ``values`` (and holds no parameter)."""
    spec = get_model(model)
    options = {o.name: str(values.get(o.name, o.default)) for o in spec.options}
    return all(k in options and str(v) == options[k] for k, v in fix.items())


def _output_name(
    p: Path, target: str, source_format: str, write: str | None, out: Path, log: Callable[[str], None]
) -> str | None:
    """The material file to write (checked now, before any work), or None when no format takes the target."""
    from matremap.formats import format_for

    if write is None:
        suffix = default_suffix(target, source_format) or None
        if suffix is None and source_format == "gltf" and get_model(target).id in ("gltf:metal-rough", "gltf:pbr"):
            suffix = p.suffix.lower()  # a glTF onto a glTF model: .gltf or .glb as it came
        name = f"{p.stem}{suffix}" if suffix else None
    else:
        from matremap.formats.confine import output_inside

        output_inside(out, write)  # a name like ../../x.gltf is refused: outputs stay under OUT
        check_material_file_name(write, target)  # a format that cannot hold the target fails now, not after the work
        name = write
    if name is not None:
        format_for(name)  # fails early on a suffix no writer takes
        if (out / name).resolve() == p.resolve():
            raise MatremapError(f"{out / name} would overwrite the input; choose another name")
    else:
        log(f"note: no material file format for {target}; writing its parameters only")
    return name


#: a layered fit further off than this (relative RMSE) started at the source's layer is tried again from the target's
#: defaults (Khronos SheenCloth's typical texel under a 0.33 sheen onto Standard Surface: 0.42 from the source's
#: sheen, 0.015 from Standard Surface's defaults)
RESTART_LOSS = 0.05


def _fit_uniform(
    source: Material,
    job: RemapJob,
    full_fix: dict[str, Any],
    log: Callable[[str], None],
    metal: Mapping[str, float] | None = None,
    both: bool = False,
) -> tuple[Any, RemapJob]:
    """The fit of a uniform remap (and the job with the strategy it used). A layer the source has and the target
    too is freed (:func:`~matremap.dialects.mtlx.freed_layers`, started at the source's) and fitted both
    three-stage and simple, the better kept: neither wins everywhere (measured, benchmarks/layered_remaps.py:
    three-stage takes a coat onto OpenPBR / glTF to 1e-4 where simple stops at 0.004-0.017; simple takes
    OpenPBR's fuzz onto Standard Surface's sheen to 0.045 where three-stage stops at 0.35). ``both``: so too
    without a layer (a level of a layer's map where it is off, blended with the levels where it is on)."""
    from matremap.uniform import fit

    target = job.target
    free, start = freed_layers(source.model, source.values, get_model(target), held=job.fix)
    layered = bool(free)
    free, start = free + list(metal or {}), {**start, **(metal or {})}  # a partial metal's metalness
    strategies = [job.strategy]
    if layered:
        log(
            f"layers: the source's layers are fitted with {target}'s ({', '.join(free)} freed, started at the source's)"
        )
    if (layered or both) and job.strategy == "two-stage":  # the layer refined jointly with the base, or all at once
        strategies = ["three-stage", "simple"]
    probe, objective = sweep_probe(job)

    def attempt(strategy: str, at: Mapping[str, Any]) -> tuple[Any, RemapJob]:
        staged = staged_strategy(replace(job, strategy=strategy), log)
        r = fit(
            source,
            target,
            target_renderer=staged.target_renderer,  # None: the model's own (uniform.fit)
            fix=full_fix,
            strategy=staged.strategy,
            scene=probe,
            free=free,
            start=at,
            objective=objective,
        )
        return r, staged

    best: Any = None
    for strategy in strategies:
        r, staged = attempt(strategy, start)
        if best is None or r.loss < best[0].loss:
            best = (r, staged)
        if staged.strategy == "simple":  # forced (staged_strategy): no second fit
            break
    if len(strategies) > 1:
        log(f"layers: kept the {best[1].strategy} fit (loss {best[0].loss:.4f})")
    if layered and best[0].loss > RESTART_LOSS and start:  # the source's layer may start in another basin
        r, staged = attempt(strategies[0], dict(metal or {}))
        log(
            f"layers: started at the source's layer the fit stopped at {best[0].loss:.4f}; from {target}'s defaults "
            f"at {r.loss:.4f}" + (" (kept)" if r.loss < best[0].loss else "")
        )
        if r.loss < best[0].loss:
            best = (r, staged)
    return best


def _remap_uniform(
    source: Material, job: RemapJob, stage: Path, result: FileRemapResult, log: Callable[[str], None]
) -> Material:
    """A uniform material: copied when the remap is the identity, else fitted; the gate measures the fit
    (its relative error, and colour and energy of the probe renders); ``material.json`` and
    ``compare.png`` (source | target | difference x10 on the probe) are written into ``stage``."""
    from matremap.core.fit import FitResult
    from matremap.uniform import comparison_strip

    target = job.target
    eq = uniform_identity(source, target, job.fix)
    if eq is not None:
        log(f"identity: {_identity_words(eq)}: copied, nothing is fitted")
        copied = Material.create(eq.target, eq.rename({**source.values, **source.options}))
        result.material, result.loss, result.verdict = copied, 0.0, Verdict([Check("fit_error", 0.0, 0.0, "identity")])
        write_text(stage / "material.json", json.dumps(copied.to_dict(), indent=1) + "\n")
        scene = job.scene or Scene()
        same = FitResult(
            source, copied, "identity", 0.0, 0, 0.0, 1.0, scene, renderer_for(source.model), renderer_for(eq.target)
        )
        write_image(stage / "compare.png", comparison_strip(same), force=True)
        return copied
    held = uniform_remap.choose_held(source, target, job.fix, log)
    r, job = _fit_uniform(source, replace(job, strategy=held.strategy or job.strategy), held.fix, log, held.start)
    for w in r.warnings:
        log(f"warning: {w}")
    measure = "relative L2 error" if r.objective == "l2" else f"{r.objective} loss"
    log(f"fit: {target} {json.dumps(r.target.to_dict()['params'])}; {measure} {r.loss:.4f}")
    result.material, result.loss, result.verdict = r.target, r.loss, uniform_remap.fit_verdict(r, job.thresholds)
    write_text(stage / "material.json", json.dumps(r.target.to_dict(), indent=1) + "\n")
    write_image(stage / "compare.png", comparison_strip(r), force=True)
    log("wrote compare.png (source | target | difference x10 on the probe)")
    return r.target
