"""The transform library: learned transforms shipped with matremap, and routes through them.

Each library entry is a parametric transform (JSON, :mod:`matremap.regress.transform`) learned
from a sweep between two models; :data:`PAIRS` says which sweeps (source template, target fixes,
grid, renderer), and ``tools/make_transform_library.py`` runs them and writes the files into
``matremap/regress/transforms/``. Each sweep gives two entries: the forward transform and the reverse one
learned from the same database (paper §5: a renderer that can only be a source still gets
remappings out of it).

A *node* of the library is a model with the options its transforms were trained on and the values
of the parameters that change what its parameters mean (a glTF material's ``metallic``).
:func:`route` finds the chain of entries with the fewest steps (then the least accumulated
held-out error) from a source node to a target node.
"""

from __future__ import annotations

import heapq
import json
import sys
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from functools import cached_property, lru_cache
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from matremap.dialects import get_model
from matremap.errors import MatremapError, TransformChecksumError
from matremap.regress import schema
from matremap.regress.transform import Transform

if TYPE_CHECKING:
    from matremap.core.scene import Scene

LIBRARY_DIR = Path(__file__).with_name("transforms")
#: the longest chain a route may take
MAX_STEPS = 4


@dataclass(frozen=True)
class Pair:
    """One library sweep: ``source`` (model id and the options/constants of its template) onto
    ``target`` with ``fix``, over ``grid`` (the sweep grid's command-line form)."""

    name: str
    source: str
    target: str
    grid: str
    source_params: Mapping[str, Any] = field(default_factory=dict)
    fix: Mapping[str, Any] = field(default_factory=dict)
    free: tuple[str, ...] = ()
    renderer: str = "embedded"
    source_renderer: str = "embedded"
    reverse: bool = True
    #: also learn from points the stability analysis flags (see the pairs that set it for why)
    keep_flagged: bool = False
    #: the probe its fits are made under (:func:`matremap.core.scene.parse_probe`; ``point``: the paper's
    #: headlight) and what they make small (:mod:`matremap.core.objective`)
    probe: str = "point"
    objective: str = "l2"


@dataclass(frozen=True)
class _Base:
    """A model with a metal/dielectric base, as the library's base-layer pairs sweep it: its id, options, and the
    names of its metalness, roughness, base colour and dielectric IOR."""

    model: str
    options: Mapping[str, Any]
    metalness: str
    roughness: str
    colour: str
    ior: str


_BASES = {
    "gltf": _Base("gltf:metal-rough", {}, "metallic", "roughness", "baseColor", "ior"),
    "openpbr": _Base("mtlx:open_pbr_surface", {}, "base_metalness", "specular_roughness", "base_color", "specular_ior"),
    "standardsurface": _Base(
        "mtlx:standard_surface", {}, "metalness", "specular_roughness", "base_color", "specular_IOR"
    ),
    "cyclesprincipled": _Base(
        "cycles:principled", {"distribution": "multi_ggx"}, "Metallic", "Roughness", "Base Color", "IOR"
    ),
}


def _base_pair(source: str, target: str, kind: str) -> Pair:
    """The library sweep of one kind (``dielectric``, ``metal``) of ``source``'s base onto ``target``'s (keys of
    :data:`_BASES`): roughness from 0.05 to 1 and the base colour (and a dielectric's IOR) over their ranges."""
    s, t, metal = _BASES[source], _BASES[target], 1.0 if kind == "metal" else 0.0
    grid = f"{s.roughness}=0.05:1:8," + (f"{s.colour}=0.05:1:8" if metal else f"{s.colour}=0:1:5,{s.ior}=1.3:1.8:3")
    return Pair(
        f"{source}-{kind}-{target}",
        s.model,
        t.model,
        grid,
        source_params={**s.options, s.metalness: metal},
        fix={**t.options, t.metalness: metal},
        reverse=False,
        keep_flagged=True,
    )


_WARD_GRID = "alpha=0.03:0.7:10,specularReflectance=0.02:0.5:6,diffuseReflectance=0;0.5"
_ALPHA_F0 = "alpha=0.03:0.9:10,F0=0.02:0.9:6,diffuseReflectance=0;0.5"
_CYCLES_GRID = "Roughness=0.15:0.95:10,Color=0.02:0.9:6,Diffuse Color=0;0.5"

#: the sweeps the library is made of (``tools/make_transform_library.py`` runs them)
PAIRS: tuple[Pair, ...] = (
    Pair("ward-as", "mitsuba06:ward", "mitsuba06:pbr", _WARD_GRID, fix={"distribution": "as"}),
    Pair("ward-ggx", "mitsuba06:ward", "mitsuba06:pbr", _WARD_GRID, fix={"distribution": "ggx"}),
    # Mitsuba 0.6's default Ward variant, the one the examples (and the README's main job) use
    Pair(
        "wardclassic-as",
        "mitsuba06:ward",
        "mitsuba06:pbr",
        _WARD_GRID,
        source_params={"variant": "ward"},
        fix={"distribution": "as"},
    ),
    Pair(
        "wardclassic-ggx",
        "mitsuba06:ward",
        "mitsuba06:pbr",
        _WARD_GRID,
        source_params={"variant": "ward"},
        fix={"distribution": "ggx"},
    ),
    # wardclassic-as fitted under the built-in environment with the SSIM objective (issue 18): remap --probe
    # auto takes whichever of the two looks closer under the light the maps will be seen in
    Pair(
        "wardclassic-as-env",
        "mitsuba06:ward",
        "mitsuba06:pbr",
        _WARD_GRID,
        source_params={"variant": "ward"},
        fix={"distribution": "as"},
        probe="env",
        objective="ssim",
        # its reverse learns AS -> Ward to held-out RMSE 0.027 roughness, 0.038 reflectance (the SSIM optimum is
        # flatter than the L2 one): the headlight's as-wardclassic serves that direction
        reverse=False,
    ),
    Pair(
        "blender27ward-ward",
        "blender27:ward",
        "mitsuba06:ward",
        "specular_slope=0.03:0.4:10,specular_color=0.02:0.5:6,diffuse_color=0;0.5",
        source_params={"specular_intensity": 1.0, "diffuse_intensity": 1.0},
    ),
    Pair("ward-cycles", "mitsuba06:ward", "cycles:glossy", _WARD_GRID, fix={"distribution": "ggx"}),
    Pair(
        "as-cycles",
        "mitsuba06:pbr",
        "cycles:glossy",
        _ALPHA_F0,
        source_params={"distribution": "as"},
        fix={"distribution": "ggx"},
    ),
    Pair(
        "ggx-cycles",
        "mitsuba06:pbr",
        "cycles:glossy",
        _ALPHA_F0,
        source_params={"distribution": "ggx"},
        fix={"distribution": "ggx"},
    ),
    Pair(
        "ward-gltf-metal",
        "mitsuba06:ward",
        "gltf:metal-rough",
        "alpha=0.03:0.7:10,specularReflectance=0.02:0.98:6",
        source_params={"diffuseReflectance": 0.0},
        fix={"metallic": 1.0},
    ),
    Pair(
        "ward-gltf-dielectric",
        "mitsuba06:ward",
        "gltf:metal-rough",
        "alpha=0.03:0.7:10,specularReflectance=0.02:0.3:6,diffuseReflectance=0.1;0.6",
        fix={"metallic": 0.0},
    ),
    Pair(
        "plastic-gltf-dielectric",
        "mitsuba06:roughplastic",
        "gltf:metal-rough",
        "alpha=0.03:0.7:10,intIOR=1.3:2.0:6,diffuseReflectance=0.1;0.6",
        source_params={"distribution": "ggx"},
        fix={"metallic": 0.0},
    ),
    Pair(
        "ggx-gltf-metal",
        "mitsuba06:pbr",
        "gltf:metal-rough",
        "alpha=0.03:0.9:10,F0=0.03:0.98:6",
        source_params={"distribution": "ggx"},
        fix={"metallic": 1.0},
    ),
    Pair(
        "conductor-cycles",
        "mitsuba06:roughconductor",
        "cycles:glossy",
        "alpha=0.03:0.9:10,k=0.4:14:6",
        source_params={"distribution": "ggx", "eta": 1.0},
        fix={"distribution": "ggx"},
    ),
    Pair(
        "conductor-gltf-metal",
        "mitsuba06:roughconductor",
        "gltf:metal-rough",
        "alpha=0.03:0.9:10,k=0.4:14:6",
        source_params={"distribution": "ggx", "eta": 1.0},
        fix={"metallic": 1.0},
    ),
    # measured with the real renderers
    Pair(
        "mitsuba3conductor-gltf-metal",
        "mitsuba3:roughconductor",
        "gltf:metal-rough",
        "alpha=0.03:0.9:10,k=0.4:14:6",
        source_params={"distribution": "ggx", "eta": 1.0},
        fix={"metallic": 1.0},
        source_renderer="mitsuba3",
    ),
    Pair(
        "ward-cyclesprincipled",
        "mitsuba06:ward",
        "cycles:principled",
        _WARD_GRID.replace(":10,", ":6,"),
        fix={"distribution": "ggx"},
        renderer="cycles",
    ),
    # what users bring (issue 20): the README's examples into glTF, and the real-asset corpus's textured glTF
    # materials into Cycles' Principled BSDF at its default distribution. Not into Mitsuba 3's rough plastic (shipped
    # until 2026-11-27): its coat darkens the diffuse with roughness, which one diffuse scale cannot follow (held-out
    # 0.019; Khronos BoxTextured through it failed the gate at luminance 0.69, swept for its own maps it passes at
    # 1 - SSIM 0.029; the greysphere calibration chained through it failed, swept passes at 0.047), and relearned
    # with today's coupled fits, which turn the coat down where a rough specular reads as diffuse under the
    # headlight, its roughness held out at 0.13: swept per material instead
    Pair(
        "wardclassic-gltf-dielectric",
        "mitsuba06:ward",
        "gltf:metal-rough",
        "alpha=0.03:0.7:10,specularReflectance=0.02:0.5:6,diffuseReflectance=0;0.6",
        source_params={"variant": "ward"},
        fix={"metallic": 0.0},
    ),
    Pair(
        "cycles-gltf-metal",
        "cycles:glossy",
        "gltf:metal-rough",
        "Roughness=0.15:0.95:10,Color=0.03:0.98:6",
        source_params={"distribution": "ggx"},
        fix={"metallic": 1.0},
    ),
    # the layered models' base layers (issue 16), swept from the source side (no reverse: the forward domain is the
    # grid, so that roughness 1 -- glTF's default, and the corpus's -- is inside; there the target's fit lands on its
    # own roughness bound, the same alpha = 1, which the stability analysis flags; that bound is the answer, so those
    # points are kept): glTF dielectrics and metals (F0 through the base colour, held-out 0.016) into OpenPBR,
    # Standard Surface and Cycles Principled, their dielectrics back onto glTF, Cycles Principled's metals too (0.017),
    # and Standard Surface <-> OpenPBR (the ASWF's successor to it). Not OpenPBR's and Standard Surface's metals back
    # onto glTF: the F82 metal's F0 held out at 0.023, above the library's 0.02 (swept on demand). No transform has a
    # layer: a textured layered material is swept for its own maps.
    *(
        _base_pair(source, target, kind)
        for source, target, kinds in (
            ("gltf", "cyclesprincipled", ("dielectric", "metal")),
            ("gltf", "openpbr", ("dielectric", "metal")),
            ("gltf", "standardsurface", ("dielectric", "metal")),
            ("openpbr", "gltf", ("dielectric",)),
            ("standardsurface", "gltf", ("dielectric",)),
            ("cyclesprincipled", "gltf", ("dielectric", "metal")),
            ("standardsurface", "openpbr", ("dielectric", "metal")),
            ("openpbr", "standardsurface", ("dielectric", "metal")),
        )
        for kind in kinds
    ),
)


# ---------------------------------------------------------------------------------------------
# nodes and entries


def node_key(model: str, options: Mapping[str, Any], values: Mapping[str, Any] | None = None) -> tuple:
    """A library node: the model, its options, and the values of the parameters its spec
    specialises on (``metallic`` of a glTF material), as given in ``values``."""
    spec = get_model(model)
    opts = {o.name: str(options.get(o.name, o.default)) for o in spec.options}
    held = []
    for name, _, _ in spec.specialisations:
        v = (values or {}).get(name)
        held.append((name, None if v is None else float(np.mean(np.asarray(v, dtype=float)))))
    return (spec.id, tuple(sorted(opts.items())), tuple(held))


def describe_node(key: tuple, defaults: bool = False) -> str:
    """``model (option=value, ...)``: the options that differ from the model's defaults, or all of them
    with ``defaults`` (so that a Ward ``variant=ward`` reads differently from ``variant=balanced``)."""
    model, opts, held = key
    spec = get_model(model)
    shown = [f"{k}={v}" for k, v in opts if defaults or v != spec.option(k).default] + [
        f"{k}={v:g}" for k, v in held if v is not None
    ]
    return model + (f" ({', '.join(shown)})" if shown else "")


@dataclass(frozen=True)
class Entry:
    """A library transform and where it leads."""

    name: str
    path: Path
    transform: Transform

    @cached_property  # routes ask for these in their inner loop
    def source(self) -> tuple:
        t = self.transform
        return node_key(t.source, t.source_options, t.source_template)

    @cached_property
    def target(self) -> tuple:
        t = self.transform
        return node_key(t.target, t.target_options, t.template)

    @cached_property
    def probe(self) -> str:
        """The probe its sweep fitted under: ``point``, ``env`` or ``mixed`` (:attr:`Scene.kind`)."""
        return probe_of(self.transform)

    @cached_property
    def objective(self) -> str:
        """What its sweep's fits made small (``l2`` for transforms that do not say)."""
        return objective_of(self.transform)

    @cached_property
    def error(self) -> float:
        """The largest held-out RMSE of its mappings (quantity units: roughness, F0, albedo)."""
        errs = [v.get("heldout_rmse") for v in self.transform.errors.values()]
        return float(max((e for e in errs if e is not None), default=0.0))


def fitted_under(t: Transform) -> list[tuple[Scene, str]]:
    """The probe scene and the objective of each sweep behind ``t`` (one per step of a chain); the paper's
    point probe and L2 where a provenance does not say (transforms learned before probes had a choice)."""
    from matremap.core.scene import Scene

    out = []
    for step in t.steps or [t]:
        sweep = step.provenance.get("sweep")
        doc = sweep.get("scene") if isinstance(sweep, dict) else None
        try:
            scene = Scene.from_dict(doc) if isinstance(doc, dict) else Scene()
        except (TypeError, ValueError, KeyError, MatremapError):
            scene = Scene()
        objective = sweep.get("objective", "l2") if isinstance(sweep, dict) else "l2"
        out.append((scene, str(objective)))
    return out


def probe_of(t: Transform) -> str:
    """The kind of probe a transform's sweeps fitted under: ``point``, ``env`` or ``mixed``."""
    return fitted_under(t)[0][0].kind


def objective_of(t: Transform) -> str:
    """The objective a transform's sweeps fitted under (``l2`` when its provenance does not say)."""
    return fitted_under(t)[0][1]


@lru_cache(maxsize=4)
def _load(directory: str) -> tuple[Entry, ...]:
    d = Path(directory)
    if not d.is_dir():
        return ()
    out = []
    for p in sorted(d.glob("*.json")):
        try:
            out.append(Entry(p.stem, p, Transform.load(p, require_checksum=True)))
        except TransformChecksumError as e:
            raise TransformChecksumError(f"the transform library is damaged: {e}; reinstall matremap") from None
    return tuple(out)


def seal(paths: Iterable[str | Path]) -> list[Path]:
    """Store (or renew) the checksum of transform files written by hand or by an older matremap, after
    checking their content; the rest of each file is kept as it is. Returns the files rewritten."""
    from matremap.core.documents import read_document
    from matremap.core.imageio import write_text

    changed = []
    for p in map(Path, paths):
        doc = read_document(p, "transform")
        content = {k: v for k, v in schema.obj(doc, str(p)).items() if k != "checksum"}
        Transform.from_dict(content, str(p))
        sealed = {**content, "checksum": schema.checksum(content)}
        if sealed != doc:
            write_text(p, json.dumps(sealed, indent=1) + "\n")
            changed.append(p)
    _load.cache_clear()
    return changed


def entries(directory: str | Path | None = None) -> tuple[Entry, ...]:
    """Every transform of the library (``directory``: another library folder)."""
    return _load(str(directory or LIBRARY_DIR))


def listing(directory: str | Path | None = None) -> list[dict[str, Any]]:
    """The library as rows for ``matremap transforms``."""
    rows = []
    for e in entries(directory):
        t = e.transform
        rows.append(
            {
                "name": e.name,
                "source": describe_node(e.source, defaults=True),
                "target": describe_node(e.target, defaults=True),
                "method": t.method,
                "heldout_rmse": {k: v.get("heldout_rmse") for k, v in t.errors.items()},
                "domain": t.domain,
                "renderers": _renderers(t),
                "probe": e.probe,
                "objective": e.objective,
            }
        )
    return rows


def _renderers(t: Transform) -> dict[str, str]:
    """Which renderer drew each side of a transform's sweep (swapped for a reverse transform)."""
    sweep, library = t.provenance.get("sweep"), t.provenance.get("library")
    r = sweep.get("renderers") if isinstance(sweep, dict) else None
    r = {k: str(v) for k, v in r.items()} if isinstance(r, dict) else {}
    if isinstance(library, dict) and library.get("reverse"):
        r = {"source": r.get("target", "embedded"), "target": r.get("source", "embedded")}
    return r


# ---------------------------------------------------------------------------------------------
# routes


@dataclass
class Route:
    """A chain of library entries, each one's target node the next one's source."""

    steps: list[Entry]

    @property
    def transform(self) -> Transform:
        ts = [e.transform for e in self.steps]
        return ts[0] if len(ts) == 1 else Transform.chain(ts)

    @property
    def error(self) -> float:
        """Accumulated held-out error: the root of the summed squares of the steps' errors (errors of
        independent steps, each in the quantity units of its own step)."""
        return float(np.sqrt(sum(e.error**2 for e in self.steps)))

    def describe(self) -> str:
        nodes = [describe_node(self.steps[0].source)] + [describe_node(e.target) for e in self.steps]
        return (
            " -> ".join(nodes) + f"  ({len(self.steps)} step{'s' * (len(self.steps) > 1)}, "
            f"accumulated held-out RMSE {self.error:.3g}; " + ", ".join(e.name for e in self.steps) + ")"
        )


def _matches(node: tuple, want: tuple) -> bool:
    """Whether a library node serves a wanted node: same model and options; held values equal where
    the wanted one names them."""
    if node[0] != want[0] or node[1] != want[1]:
        return False
    return all(
        w is None or (v is not None and abs(v - w) < 1e-9) for (_, v), (_, w) in zip(node[2], want[2], strict=True)
    )


def route(
    source: tuple, target: tuple, directory: str | Path | None = None, max_steps: int = MAX_STEPS, probe: str = "point"
) -> Route | None:
    """The shortest chain of library transforms from ``source`` to ``target`` (node keys, see
    :func:`node_key`; ties broken by accumulated error) among those fitted under ``probe``, or None."""
    lib = tuple(e for e in entries(directory) if e.probe == probe)
    heap: list[tuple[int, float, int, list[Entry]]] = []
    counter = 0
    for e in lib:
        if _matches(e.source, source):
            heapq.heappush(heap, (1, e.error**2, counter, [e]))
            counter += 1
    seen: set[tuple] = set()
    while heap:
        n, err2, _, path = heapq.heappop(heap)
        end = path[-1].target
        if _matches(end, target):
            return Route(path)
        if end in seen or n >= max_steps:
            continue
        seen.add(end)
        for e in lib:
            if e.source == end and e not in path:
                heapq.heappush(heap, (n + 1, err2 + e.error**2, counter, [*path, e]))
                counter += 1
    return None


def find_route(
    source_model: str,
    source_options: Mapping[str, Any],
    target_model: str,
    fix: Mapping[str, Any],
    directory: str | Path | None = None,
    source_values: Mapping[str, Any] | None = None,
    probe: str = "point",
) -> Route | None:
    """The route for remapping ``source_model`` (with its options, and ``source_values`` for the
    parameters its spec specialises on) onto ``target_model`` with the user's ``fix`` (options and
    held values), through transforms fitted under ``probe``."""
    return route(
        node_key(source_model, source_options, source_values or source_options),
        node_key(target_model, fix, fix),
        directory,
        probe=probe,
    )


def nearest_routes(
    source_model: str,
    source_options: Mapping[str, Any],
    target_model: str,
    fix: Mapping[str, Any],
    count: int = 3,
    directory: str | Path | None = None,
) -> list[str]:
    """When :func:`find_route` finds nothing: the library transforms closest to what was asked, every
    option shown (the same two models first, then the same source model, then the same target model),
    so that a message can say which option kept each one out."""
    source_model, target_model = get_model(source_model).id, get_model(target_model).id

    def rank(e: Entry) -> int:
        same = (e.source[0] == source_model, e.target[0] == target_model)
        return {(True, True): 0, (True, False): 1, (False, True): 2}.get(same, 3)

    close = sorted((e for e in entries(directory) if rank(e) < 3), key=lambda e: (rank(e), e.error))
    return [
        f"{e.name}: {describe_node(e.source, defaults=True)} -> {describe_node(e.target, defaults=True)}"
        for e in close[:count]
    ]


# ---------------------------------------------------------------------------------------------
# building


def build_pair(
    pair: Pair,
    out_dir: str | Path,
    workers: int | None = None,
    size: int | None = None,
    log: Callable[[str], None] = print,
) -> list[Path]:
    """Sweep one pair and write its transform(s) into ``out_dir``; returns the files written."""
    from matremap.core.material import Material
    from matremap.core.scene import Scene, parse_probe
    from matremap.regress.transform import learn_transform
    from matremap.sweep.executors import make_executor
    from matremap.sweep.grid import parse_grid
    from matremap.sweep.run import SweepConfig, describe, run_sweep

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    source = Material.create(pair.source, dict(pair.source_params))
    scene = parse_probe(pair.probe, resolution=size) if pair.probe != "point" or size else Scene()
    config = SweepConfig(
        source=source,
        target=pair.target,
        fix=dict(pair.fix),
        free=pair.free,
        strategy="two-stage",
        scene=scene,
        source_renderer=pair.source_renderer,
        target_renderer=pair.renderer,
        objective=pair.objective,
    )
    grid = parse_grid(pair.grid, source.spec)
    db = out / f".{pair.name}.sqlite"
    with make_executor(workers) as (executor, desc):
        summary = run_sweep(
            config, grid, str(db), executor, executor_name=desc, in_flight=2 * getattr(executor, "slots", 1)
        )
    log(f"{pair.name}: {describe(summary)}")
    summary.raise_if_interrupted()
    written = []
    directions = [(False, pair.name)] + ([(True, reverse_name(pair.name))] if pair.reverse else [])
    for reverse, name in directions:
        t = learn_transform(db, reverse=reverse, exclude_flagged=not pair.keep_flagged)
        t.provenance["library"] = {"pair": pair.name, "grid": pair.grid, "reverse": reverse}
        path = out / f"{name}.json"
        t.save(path, force=True)
        written.append(path)
        log(
            f"  {name}: {t.describe()}; held-out RMSE "
            + ", ".join(f"{k} {v['heldout_rmse']:.3g}" for k, v in t.errors.items() if "heldout_rmse" in v)
        )
    db.unlink(missing_ok=True)
    for extra in ("-wal", "-shm"):
        Path(str(db) + extra).unlink(missing_ok=True)
    _load.cache_clear()
    return written


#: the name suffixes of library transforms fitted under another probe than the point probe
PROBE_SUFFIXES = ("-env", "-mixed")


def reverse_name(name: str) -> str:
    """The library name of a pair's reverse transform: ``ward-as`` -> ``as-ward``, ``ward-as-env`` ->
    ``as-ward-env``."""
    suffix = next((x for x in PROBE_SUFFIXES if name.endswith(x)), "")
    a, sep, b = name[: len(name) - len(suffix)].partition("-")
    return (f"{b}-{a}" if sep else f"{name}-reverse") + suffix


def max_prediction_difference(a: Transform, b: Transform, samples: int = 200, seed: int = 0) -> dict[str, float]:
    """How far two transforms of the same models disagree inside ``a``'s training domain: the largest
    absolute difference of each target quantity over random inputs."""
    from matremap.regress import quantities as qty

    rng = np.random.default_rng(seed)
    spec = get_model(a.source)
    x = {}
    for name, (lo, hi) in a.domain.items():
        shape = (samples,) if name == "roughness" else (samples, 3)
        x[name] = rng.uniform(lo, hi, shape)
    template = {**{p.name: p.default for p in spec.params}, **a.source_template}  # parameters added since: defaults
    values = qty.write(spec, x, template)
    ya, _ = a.apply(values)
    yb, _ = b.apply(values)
    tspec = get_model(a.target)
    qa, qb = qty.read(tspec, ya), qty.read(tspec, yb)
    return {k: float(np.max(np.abs(qa[k] - qb[k]))) for k in qa}


__all__ = [
    "LIBRARY_DIR",
    "PAIRS",
    "Entry",
    "Pair",
    "Route",
    "build_pair",
    "entries",
    "find_route",
    "listing",
    "node_key",
    "reverse_name",
    "route",
    "seal",
]


if __name__ == "__main__":  # python -m matremap.regress.library seal [FILE ...]: renew the shipped checksums
    if sys.argv[1:2] != ["seal"]:
        sys.exit("usage: python -m matremap.regress.library seal [TRANSFORM.json ...] (default: the library)")
    files = [Path(a) for a in sys.argv[2:]] or sorted(LIBRARY_DIR.glob("*.json"))
    for f in seal(files):
        print(f"sealed {f}")
