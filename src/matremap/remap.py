"""The main job: remap an SVBRDF map set from one model to another, end to end.

sweep -> learn -> convert -> evaluate (paper §4-6):

1. a sweep over the source parameters the maps actually use (the roughness and specular maps'
   value ranges, and two diffuse levels), fitted onto the target model on the probe scene;
2. a parametric transform learned from it, cached by everything that decides it, so a second run
   with the same maps and models reuses it;
3. the transform applied to every texel (:func:`matremap.svbrdf.convert.convert`);
4. source and result rendered under an environment map at several rotations and compared with SSIM
   (:func:`matremap.svbrdf.evaluate.evaluate`), into a self-contained HTML report.
"""

from __future__ import annotations

import hashlib
import json
import time
import warnings
from collections.abc import Callable, Collection, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from matremap import __version__
from matremap.core.material import Material
from matremap.core.scene import Scene
from matremap.dialects import get_model
from matremap.errors import MatremapError
from matremap.regress import quantities as qty
from matremap.regress.transform import Transform
from matremap.svbrdf.textures import MapSet, load_map_set, map_values, read_image

#: grid points along the roughness and the specular axes of the sweep, and the diffuse levels
ROUGHNESS_POINTS, SPECULAR_POINTS, DIFFUSE_LEVELS = 10, 6, (0.0, 0.9)


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


def default_cache() -> Path:
    from matremap.core.diskcache import cache_dir

    return cache_dir() / "transforms"


def load_arrays(map_set: MapSet, only: Collection[str] | None = None) -> tuple[dict[str, Any], np.ndarray | None]:
    """Every map of a set as parameter arrays (model units), constants as they are, and the
    normal map decoded to [-1, 1] (or None). ``only``: read just these parameters' maps (and no
    normal map)."""
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


def sweep_grid(map_set: MapSet, params: Mapping[str, Any]) -> str:
    """A grid over the values the maps hold: roughness and specular ranges (grey), and two diffuse
    levels so that the diffuse mapping is learned too."""
    spec = map_set.spec
    axes = []
    rp = qty.roughness_param(spec)
    if rp is not None and rp.name in map_set.maps:
        lo, hi = _range(params[rp.name], rp.bounds)
        axes.append(f"{rp.name}={lo!r}:{hi!r}:{ROUGHNESS_POINTS}")
    metal = spec.specialise({**map_set.constants, **params}).diffuse_only is None  # e.g. glTF with metallic 1
    if spec.reflectance is not None:
        # the parameter a map of F0 drives: k for conductors, a glTF metal's base colour or a glTF
        # dielectric's specular colour
        name = spec.reflectance.driven_param(metal)
        if name in map_set.maps:
            lo, hi = _range(params[name], spec.param(name).bounds)
            axes.append(f"{name}={lo!r}:{hi!r}:{SPECULAR_POINTS}")
    dp = qty.diffuse_param(spec)
    if dp is not None and dp.name in map_set.maps and not metal:
        axes.append(f"{dp.name}={';'.join(repr(v) for v in DIFFUSE_LEVELS)}")
    if not axes:
        raise MatremapError(f"the map set gives no roughness, specular or diffuse map of {spec.id} to remap")
    return ",".join(axes)


def _range(values: Any, bounds: tuple[float, float]) -> tuple[float, float]:
    v = np.asarray(values, dtype=float)
    lo, hi = float(np.min(v)), float(np.max(v))
    pad = 0.02 * (hi - lo) if hi > lo else 0.05 * max(abs(hi), 1e-3)
    lo, hi = max(bounds[0], lo - pad, 1e-4), min(bounds[1], hi + pad)
    return round(lo, 6), round(hi, 6)


def complete_fix(source_model: str, values: Mapping[str, Any], target: str, fix: Mapping[str, Any]) -> dict[str, Any]:
    """The user's target fixes, plus a choice for each target parameter that decides what the
    target's parameters mean and that the user left open: a glTF ``metallic`` is 1 for a source
    without a diffuse part (a metal), else 0."""
    out = dict(fix)
    for name, value, _ in get_model(target).specialisations:
        if name not in out:
            out[name] = value if _no_diffuse(source_model, values) else 0.0
    return out


def _no_diffuse(model: str, values: Mapping[str, Any]) -> bool:
    spec = get_model(model)
    dp = qty.diffuse_param(spec)
    if dp is None or spec.specialise(values).diffuse_only is None:
        return True
    v = values.get(dp.name, spec.param(dp.name).default)
    return float(np.max(np.asarray(v, dtype=float))) <= 0.0


#: a library route is used when at most this fraction of the texels lie outside its training domain
LIBRARY_MAX_OUTSIDE = 0.01


def library_transform(
    map_set: MapSet, params: Mapping[str, Any], target: str, fix: Mapping[str, Any], log: Callable[[str], None]
) -> Transform | None:
    """A transform from the shipped library (direct or chained) that covers these maps, or None."""
    from matremap.regress.library import find_route

    spec = map_set.spec
    held = {name: params[name] for name, _, _ in spec.specialisations if name in params}
    found = find_route(spec.id, map_set.options, target, fix, source_values=held)
    if found is None:
        log(f"library: no route from {spec.id} to {target} with {_fmt_fix(fix)}; sweeping")
        return None
    transform = found.transform
    sample = {
        k: (np.asarray(v)[::4, ::4] if np.ndim(v) >= 2 else v) for k, v in params.items() if k in spec.param_names
    }
    _, outside = transform.apply(sample)
    share = float(np.mean(outside)) if np.size(outside) else 0.0
    if share > LIBRARY_MAX_OUTSIDE:
        log(f"library: {found.describe()} covers only {100 * (1 - share):.1f}% of the texels; sweeping instead")
        return None
    log(f"library: {found.describe()}")
    return transform


def _fmt_fix(fix: Mapping[str, Any]) -> str:
    return ", ".join(f"{k}={v}" for k, v in fix.items()) or "no fixed values"


def cached_transform(
    map_set: MapSet,
    params: Mapping[str, Any],
    target: str,
    fix: Mapping[str, Any],
    strategy: str,
    cache: Path,
    workers: int | None,
    log: Callable[[str], None],
    scene: Scene | None = None,
    target_renderer: str = "embedded",
) -> tuple[Transform, Path, bool]:
    """The transform for these maps and models: from the cache, or swept and learned now."""
    from matremap.regress.transform import learn_transform
    from matremap.sweep.executors import make_executor
    from matremap.sweep.grid import parse_grid
    from matremap.sweep.run import SweepConfig, describe, run_sweep

    spec = map_set.spec
    base = Material.create(spec.id, {k: v for k, v in map_set.constants.items() if k not in map_set.maps})
    grid_text = sweep_grid(map_set, params)
    from matremap.renderers import renderer_for

    config = SweepConfig(
        source=base,
        target=get_model(target).id,
        fix=dict(fix),
        strategy=strategy,
        scene=scene or Scene(),
        source_renderer=renderer_for(spec.id),
        target_renderer=target_renderer,
    )
    key_doc = {"config": config.to_dict(), "grid": grid_text, "version": __version__}
    key = hashlib.sha256(json.dumps(key_doc, sort_keys=True).encode()).hexdigest()[:16]
    cache.mkdir(parents=True, exist_ok=True)
    path = cache / f"{spec.id.replace(':', '-')}--{config.target.replace(':', '-')}-{key}.json"
    if path.is_file():
        log(f"transform: cached {path}")
        return Transform.load(path), path, True
    db = path.with_suffix(".sqlite")
    grid = parse_grid(grid_text, spec)
    log(f"sweep: {spec.id} -> {config.target}, {len(grid)} fits over {grid_text}")
    from tqdm import tqdm

    with (
        make_executor(workers) as (executor, desc),
        tqdm(total=len(grid), unit="fit", desc="sweep", disable=None, leave=False) as bar,
    ):
        summary = run_sweep(
            config,
            grid,
            str(db),
            executor,
            progress=bar.update,
            executor_name=desc,
            on_start=bar.update,
            in_flight=2 * getattr(executor, "slots", 1),
        )
    log(f"sweep: {describe(summary)}")
    transform = learn_transform(db)
    transform.save(path, force=True)
    log(
        f"learn: {transform.describe()}, held-out RMSE "
        + ", ".join(f"{k} {v['heldout_rmse']:.3g}" for k, v in transform.errors.items() if "heldout_rmse" in v)
    )
    return transform, path, False


def remap(
    maps: str | Path,
    source_model: str | None,
    target_model: str,
    out: str | Path,
    *,
    fix: Mapping[str, Any] | None = None,
    strategy: str = "two-stage",
    envmap: str = "builtin",
    rotations: str = "0:360:6",
    resolution: int = 160,
    lights: int = 128,
    workers: int | None = None,
    cache: Path | None = None,
    evaluate: bool = True,
    force: bool = False,
    scene: Scene | None = None,
    target_renderer: str | None = None,
    library: bool = True,
    log: Callable[[str], None] = print,
) -> RemapResult:
    """Remap the map set ``maps`` onto ``target_model``; write ``OUT/maps`` and ``OUT/report``.
    ``scene`` is the probe scene of the sweep (default: the paper's, with a headlight);
    ``target_renderer`` draws the target model in the sweep (e.g. "mitsuba3", "cycles").
    ``library``: first look for a route through the shipped transform library (used when the
    default probe, two-stage fits and the embedded renderer are asked for, and when it covers the
    maps' values); otherwise, or when it finds none, sweep and learn (cached)."""
    from matremap.core.envmap import resolve
    from matremap.svbrdf.convert import convert
    from matremap.svbrdf.evaluate import evaluate as run_evaluation
    from matremap.svbrdf.evaluate import parse_rotations

    t0 = time.perf_counter()
    seconds: dict[str, float] = {}
    map_set = load_map_set(maps, source_model)
    target = get_model(target_model).id
    from matremap.renderers import renderer_for

    target_renderer = target_renderer or renderer_for(target)
    out = Path(out)
    if out.exists() and any(out.iterdir()) and not force:
        raise MatremapError(f"{out} exists and is not empty; pass --force to write into it")
    root = Path(map_set.root).resolve()
    if out.resolve() == root or root in out.resolve().parents:
        raise MatremapError(f"{out} is inside the input folder {root}; choose another output folder")
    angles = parse_rotations(rotations) if evaluate else []
    env = resolve(envmap) if evaluate else None
    params, normal = load_arrays(map_set)
    seconds["load"] = time.perf_counter() - t0

    t = time.perf_counter()
    fix = complete_fix(map_set.model, {**map_set.constants, **params}, target, fix or {})
    transform = None
    if library and scene is None and target_renderer == renderer_for(target) and strategy == "two-stage":
        transform = library_transform(map_set, params, target, fix, log)
    elif library:
        log(
            "library: not used (its transforms are two-stage fits on the default probe, each model drawn by its "
            "default renderer)"
        )
    if transform is not None:
        tpath, cached = None, True
    else:
        transform, tpath, cached = cached_transform(
            map_set, params, target, fix, strategy, cache or default_cache(), workers, log, scene, target_renderer
        )
    seconds["transform"] = time.perf_counter() - t

    t = time.perf_counter()
    out.mkdir(parents=True, exist_ok=True)
    with warnings.catch_warnings():  # the outside-domain count is logged below
        warnings.simplefilter("ignore", UserWarning)
        report = convert(map_set, [transform], out / "maps", workers=workers or 2, force=force)
    transform.save(out / "transform.json", force=True)  # what was applied, with its provenance
    seconds["convert"] = time.perf_counter() - t
    log(
        f"convert: {report.texels} texels into {out / 'maps'}"
        + (f"; {report.outside} outside the training domain (see outside_domain.png)" if report.outside else "")
    )

    mean = None
    html = None
    if evaluate:
        t = time.perf_counter()
        result_set = load_map_set(out / "maps")
        target_params, target_normal = load_arrays(result_set)
        result = run_evaluation(
            (map_set.model, params, map_set.options, normal),
            (result_set.model, target_params, result_set.options, target_normal),
            env,
            angles,
            out / "report",
            resolution=resolution,
            lights=lights,
            force=force,
            title=f"{map_set.model} -> {result_set.model}: {Path(maps).name}",
        )
        seconds["evaluate"] = time.perf_counter() - t
        mean = float(result.mean_full)
        html = out / "report" / "report.html"
        log(
            f"evaluate: mean 1-SSIM {result.mean_full:.4f} (specular only {result.mean_specular:.4f}) over "
            f"{len(angles)} rotations; {html}"
        )
    seconds["total"] = time.perf_counter() - t0
    return RemapResult(tpath, cached, out / "maps", html, int(report.outside), int(report.texels), mean, seconds)


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


def default_suffix(target: str, source_format: str) -> str | None:
    """The file a target model's users read: glTF (or MaterialX when the input was one) for
    ``gltf:*``, Mitsuba 3 XML for ``mitsuba3:*``, a .blend for ``cycles:*``; None otherwise."""
    family = target.split(":", 1)[0]
    if family == "gltf":
        return {"gltf": None, "mtlx": ".mtlx"}.get(source_format, ".gltf")
    return {"mitsuba3": ".xml", "cycles": ".blend"}.get(family)


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
    write it in the target's own format into ``out`` (``write`` names the file; default: the
    input's name with the target format's suffix). A textured material goes through :func:`remap`
    (``out/source`` holds its maps as matremap reads them, ``out/maps`` the converted ones); a
    uniform one is fitted directly. ``options`` go to :func:`remap`."""
    from matremap.formats import format_for, read_asset, write_asset
    from matremap.renderers import renderer_for
    from matremap.uniform import fit

    p = Path(path)
    asset = read_asset(p, material)
    for note in asset.notes:
        log(f"note: {note}")
    target = get_model(target_model).id
    out = Path(out)
    if out.exists() and any(out.iterdir()) and not force:
        raise MatremapError(f"{out} exists and is not empty; pass --force to write into it")
    if out.resolve() == p.resolve().parent:
        raise MatremapError(f"{out} is the input file's folder; choose another output folder")
    if write is None:
        suffix = default_suffix(target, asset.format) or None
        if suffix is None and target.split(":", 1)[0] == "gltf":
            suffix = p.suffix.lower()
        name = f"{p.stem}{suffix}" if suffix else None
    else:
        name = write
    if name is not None:
        format_for(name)  # fails early on a suffix no writer takes
        if (out / name).resolve() == p.resolve():
            raise MatremapError(f"{out / name} would overwrite the input; choose another name")
    else:
        log(f"note: no material file format for {target}; writing its parameters only")
    result = FileRemapResult(None, asset.model, target, asset.textured, notes=list(asset.notes))
    if asset.textured:
        out.mkdir(parents=True, exist_ok=True)
        source_dir = asset.to_map_set(out / "source")
        result.remap = remap(source_dir, None, target, out, fix=fix, force=True, log=log, **options)
        produced: Any = load_map_set(out / "maps")
    else:
        source = asset.material()
        full_fix = complete_fix(source.model, qty.material_values(source), target, fix or {})
        r = fit(
            source,
            target,
            source_renderer=renderer_for(source.model),
            target_renderer=options.get("target_renderer") or renderer_for(target),
            fix=full_fix,
            strategy=options.get("strategy", "two-stage"),
        )
        for w in r.warnings:
            log(f"warning: {w}")
        log(f"fit: {target} {json.dumps(r.target.to_dict()['params'])}; relative L2 error {r.loss:.4f}")
        out.mkdir(parents=True, exist_ok=True)
        from matremap.core.imageio import write_text

        write_text(out / "material.json", json.dumps(r.target.to_dict(), indent=1) + "\n")
        from matremap.core.imageio import write_image
        from matremap.uniform import comparison_strip

        write_image(out / "compare.png", comparison_strip(r), force=True)  # source | target | difference x10
        log(f"wrote {out / 'compare.png'} (source | target | difference x10 on the probe)")
        result.material, result.loss = r.target, r.loss
        produced = r.target
    if name is not None:
        source_for_writer = asset if format_for(name) in ("gltf", "mtlx") and asset.format == format_for(name) else None
        result.file = write_asset(out / name, produced, source=source_for_writer, force=force)
        log(f"wrote {result.file}")
    return result
