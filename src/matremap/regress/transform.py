"""Transforms: learned source -> target mappings as JSON files, applied to arrays of any shape.

A transform file is plain JSON (loading one never runs code)::

    {"schema": "matremap.transform/1", "method": "parametric" | "svr" | "chain",
     "source": {"model": ..., "options": {...}}, "target": {"model": ..., "options": {...}},
     "mappings": {"roughness": {...}, "reflectance": {...}, "diffuse": {...}},
     "template": {target parameters not driven by a mapping},
     "domain": {"roughness": [lo, hi], "reflectance": [lo, hi], "diffuse": [lo, hi]},
     "errors": {quantity: {"heldout_rmse": ..., ...}}, "provenance": {...}}

A chain holds its steps instead of mappings (``"steps": [transform, ...]``). Quantities are
explained in :mod:`.quantities`; mapping forms in :mod:`.parametric` and :mod:`.svr`.

Every field is checked on load (:mod:`.schema`: finite bounded coefficients, their counts, known
options and quantities). :meth:`Transform.save` adds ``"checksum": "sha256:..."`` over the rest of the
content; loading verifies it, and cached and shipped transforms must carry one, so a file edited after
it was written is never used as if it had been learned. A hand-written transform without one still
loads when given explicitly.
"""

from __future__ import annotations

import json
import time
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from matremap import __version__
from matremap.core.models import ModelSpec
from matremap.dialects import get_model
from matremap.errors import MatremapError, TransformChecksumError
from matremap.regress import quantities as qty
from matremap.regress import schema
from matremap.regress.learners import LEARNERS, evaluate_mapping, get_learner

SCHEMA = "matremap.transform/1"
#: the ``method`` of a transform file: a learner's name, or a chain of transforms
METHODS = (*LEARNERS, "chain")
#: relative slack on the training domain before an input counts as outside it
DOMAIN_SLACK = 1e-6
#: texels per chunk when applying to large arrays
CHUNK = 1 << 16
#: a layer parameter no mapping reads counts as the value its sweep held when within this of it
LAYER_TOLERANCE = 0.01

if TYPE_CHECKING:
    from matremap.regress.data import TrainingData


@dataclass
class Transform:
    method: str
    source: str
    target: str
    source_options: dict[str, str] = field(default_factory=dict)
    target_options: dict[str, str] = field(default_factory=dict)
    mappings: dict[str, dict[str, Any]] = field(default_factory=dict)
    template: dict[str, Any] = field(default_factory=dict)
    source_template: dict[str, Any] = field(default_factory=dict)
    domain: dict[str, list[float]] = field(default_factory=dict)
    errors: dict[str, dict[str, float | None]] = field(default_factory=dict)
    provenance: dict[str, Any] = field(default_factory=dict)
    steps: list[Transform] = field(default_factory=list)

    # -- JSON ----------------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {
            "schema": SCHEMA,
            "method": self.method,
            "source": {"model": self.source, "options": self.source_options},
            "target": {"model": self.target, "options": self.target_options},
            "domain": self.domain,
            "errors": self.errors,
            "provenance": self.provenance,
        }
        if self.method == "chain":
            d["steps"] = [s.to_dict() for s in self.steps]
        else:
            d["mappings"] = self.mappings
            d["template"] = self.template
            d["source_template"] = self.source_template
        return d

    def save(self, path: str | Path, force: bool = False) -> Path:
        """Write the transform as JSON with its checksum (:func:`.schema.checksum`); a transform that
        would not load back (a NaN coefficient) is refused before anything is written."""
        from matremap.core.imageio import check_output, write_text

        p = check_output(path, force, (".json",))
        write_text(p, json.dumps(self.sealed(), indent=1) + "\n")
        return p

    def sealed(self) -> dict[str, Any]:
        """:meth:`to_dict` as it reads back from JSON, validated, with its ``checksum``."""
        doc = json.loads(json.dumps(self.to_dict()))
        Transform.from_dict(doc, f"transform {self.describe()}")
        return {**doc, "checksum": schema.checksum(doc)}

    @classmethod
    def from_dict(cls, d: Any, where: str = "transform", require_checksum: bool = False) -> Transform:
        """Validate (:mod:`.schema`) and build; every problem is one MatremapError naming it. A ``checksum``
        field is verified (a mismatch is :class:`TransformChecksumError`); ``require_checksum``: its
        absence is one too (cached and shipped transforms)."""
        d = schema.obj(d, where)
        unknown = set(d) - schema.KEYS
        if unknown:
            raise MatremapError(f"{where}: unknown keys {', '.join(sorted(unknown))}")
        if "checksum" in d or require_checksum:
            stored = d.get("checksum")
            if stored is None:
                raise TransformChecksumError(f"{where} carries no checksum, so its content cannot be trusted")
            if stored != schema.checksum(d):
                raise TransformChecksumError(
                    f"{where} was changed after it was written (its content does not match its checksum)"
                )
        if d.get("schema") != SCHEMA:
            raise MatremapError(f"{where}: schema {d.get('schema')!r} is not {SCHEMA!r}; relearn it with this version")
        method = d.get("method")
        if method not in METHODS:
            raise MatremapError(f"{where}: method {method!r} is not one of {', '.join(METHODS)}")
        source, source_options = schema.side(d, "source", where)
        target, target_options = schema.side(d, "target", where)
        t = cls(
            method,
            source.id,
            target.id,
            source_options,
            target_options,
            domain=schema.domain(d.get("domain", {}), where),
            errors=schema.errors(d.get("errors", {}), where),
            provenance=dict(schema.obj(d.get("provenance", {}), f"{where}: 'provenance'")),
        )
        if method == "chain":
            steps = schema.steps_list(d, where)
            t.steps = [cls.from_dict(s, f"{where} step {i + 1}") for i, s in enumerate(steps)]
            linked = cls.chain(t.steps)  # the steps link up
            if (linked.source, linked.target) != (t.source, t.target):
                raise MatremapError(f"{where}: the chain runs {linked.describe()}, not {t.source} -> {t.target}")
            return t
        mappings = schema.obj(d.get("mappings"), f"{where}: 'mappings'")
        if not mappings:
            raise MatremapError(f"{where}: 'mappings' is empty")
        for name, m in mappings.items():
            schema.mapping(name, m, source, target, where)
        template = dict(schema.obj(d.get("template"), f"{where}: 'template'"))
        missing = [p.name for p in target.params if p.name not in template and p.fit]
        if missing:
            raise MatremapError(f"{where}: template lacks target parameters {', '.join(missing)}")
        # a held parameter the model gained after the transform was learned: the renderer held it at its default
        template.update({p.name: p.default for p in target.params if p.name not in template})
        schema.values(target, template, f"{where}: template")
        source_template = schema.obj(d.get("source_template", {}), f"{where}: 'source_template'")
        schema.values(source, source_template, f"{where}: source_template")
        t.mappings, t.template = {k: dict(v) for k, v in mappings.items()}, dict(template)
        t.source_template = dict(source_template)
        return t

    @classmethod
    def load(cls, path: str | Path, require_checksum: bool = False) -> Transform:
        """Read and validate a transform file (see :meth:`from_dict` for ``require_checksum``)."""
        from matremap.core.documents import read_document

        return cls.from_dict(read_document(path, "transform"), str(path), require_checksum)

    # -- application ----------------------------------------------------------------------------
    def apply(
        self, values: Mapping[str, Any], clipped: dict[str, int] | None = None
    ) -> tuple[dict[str, np.ndarray], np.ndarray]:
        """Map source parameter arrays (scalars [...], RGB [..., 3]; missing ones take the values
        the training sweep held them at) to target parameter arrays; also return a boolean [...]
        array that is True where an input lies outside the training domain. ``clipped`` (parameter ->
        count) adds up the output values clipped to the target's bounds (:func:`quantities.write`)."""
        src = get_model(self.source)
        arrays = _complete(src, values, self.source_template)
        shape = _shape(src, arrays)
        n = int(np.prod(shape))
        if n <= CHUNK:
            return self._apply(arrays, shape, clipped)
        # large inputs (texture maps) in cache-sized chunks of texels: same results, less memory traffic;
        # a uniform input (a broadcast template value) stays a broadcast view of one element
        flat = {k: _flatten(a, shape, n) for k, a in arrays.items()}
        out: dict[str, np.ndarray] = {}
        outside = np.empty(n, dtype=bool)
        for start in range(0, n, CHUNK):
            part = slice(start, min(start + CHUNK, n))
            m = part.stop - part.start
            chunk = {
                k: (a[part] if a.shape[0] == n else np.broadcast_to(a[0], (m, *a.shape[1:]))) for k, a in flat.items()
            }
            o, off = self._apply(chunk, (m,), clipped)
            outside[part] = off
            for k, a in o.items():
                if k not in out:
                    if qty.uniform(a):  # a template value: keep it a broadcast view
                        out[k] = np.broadcast_to(a[0], (n, *a.shape[1:]))
                        continue
                    out[k] = np.empty((n, *a.shape[1:]), dtype=a.dtype)
                if out[k].flags.writeable:
                    out[k][part] = a
        return {k: a.reshape(*shape, *a.shape[1:]) for k, a in out.items()}, outside.reshape(shape)

    def _apply(
        self, arrays: dict[str, np.ndarray], shape: tuple[int, ...], clipped: dict[str, int] | None = None
    ) -> tuple[dict[str, np.ndarray], np.ndarray]:
        if self.method == "chain":
            out, outside = self.steps[0].apply(arrays, clipped)
            for step in self.steps[1:]:
                out, o = step.apply(out, clipped)
                outside = outside | o
            return out, outside
        src = get_model(self.source)
        x = qty.read(src, arrays, self.layers)
        outside = self._unmapped_layers(src, arrays, shape)
        for name, v in x.items():
            # two reductions settle the common case: everything finite and inside the domain
            probe = v[:1] if qty.uniform(v) else v
            vmin, vmax = float(np.min(probe)) if probe.size else 0.0, float(np.max(probe)) if probe.size else 0.0
            lo, hi = self.domain.get(name, (-np.inf, np.inf))
            slack = DOMAIN_SLACK * max(abs(hi), abs(lo), 1.0) if np.isfinite([lo, hi]).all() else 0.0
            if np.isfinite(vmin) and np.isfinite(vmax) and lo - slack <= vmin and vmax <= hi + slack:
                continue
            if not np.all(np.isfinite(probe)):
                raise MatremapError(f"{self.source} input {name} holds NaN or infinite values; fix or mask them first")
            off = (v < lo - slack) | (v > hi + slack)
            # roughness is one value per element, the others one per channel: or the channel columns
            # (any(axis=-1) over 3 channels is several times slower); a uniform input's mask (shape
            # (), or (3,) before its columns are taken) broadcasts over the elements
            scalar = qty.is_scalar(name)
            for col in [off] if scalar or off.ndim == 0 else [off[..., c] for c in range(off.shape[-1])]:
                outside |= col
        y = {}
        for name, m in self.mappings.items():
            used = _inputs(m, x)
            if shape and shape[0] > 1 and used and all(qty.uniform(x[k]) for k in used):
                # the same input everywhere (a constant map): evaluate once, broadcast the result
                one = evaluate_mapping(m, {k: v[:1] for k, v in x.items()})
                y[name] = np.broadcast_to(one, (shape[0], *one.shape[1:]))
            else:
                y[name] = evaluate_mapping(m, x)
            self._check_finite(name, y[name])
        return qty.write(get_model(self.target), y, self.template, clipped, self._slack()), outside

    @property
    def layers(self) -> frozenset[str]:
        """The source's layers whose quantities the transform maps (those its training domain names)."""
        return frozenset(filter(None, (qty.layer_of(k) for k in self.domain)))

    def _unmapped_layers(self, src: ModelSpec, arrays: Mapping[str, np.ndarray], shape: tuple[int, ...]) -> np.ndarray:
        """Where a layer the transform does not map differs from the layer its sweep held (:attr:`source_template`):
        outside the training domain. A transform learned on bare materials says nothing of a coated texel, and one
        learned under a held coat (a textured material's sweep) nothing of another coat."""
        outside = np.zeros(shape, dtype=bool)
        for name, layer in qty.layer_params(src).items():
            if name in self.layers:
                continue
            held = qty.read_layer(name, layer, _complete(src, {}, self.source_template))
            here = qty.read_layer(name, layer, arrays)
            for q, v in here.items():
                if q != f"{name}_weight" and float(held[f"{name}_weight"]) <= 0.0:
                    continue  # a layer held off: its colour and roughness draw nothing
                off = np.abs(v - held[q]) > LAYER_TOLERANCE
                outside |= off if qty.is_scalar(q) else np.any(off, axis=-1)
        return outside

    def _slack(self) -> dict[str, float]:
        """Each quantity's held-out RMSE (its training RMSE where nothing was held out): how far past a
        bound the mapping may land by its own error (:func:`quantities.write`)."""
        out = {}
        for name, e in self.errors.items():
            value = e.get("heldout_rmse")
            value = e.get("train_rmse") if value is None else value
            if value is not None and np.isfinite(value):
                out[name] = float(value)
        return out

    def _check_finite(self, name: str, a: np.ndarray) -> None:
        """Refuse a mapping's output holding NaN or infinity (a second line of defence behind the
        schema: NaN in an 8-bit map would silently become 0)."""
        probe = a[:1] if qty.uniform(a) else a
        if probe.size and not (np.isfinite(np.min(probe)) and np.isfinite(np.max(probe))):
            raise MatremapError(
                f"transform {self.describe()} gave NaN or infinite {name} values for finite inputs; "
                f"its {name} mapping is broken: relearn it (matremap learn) or use another transform"
            )

    # -- composition -----------------------------------------------------------------------------
    @classmethod
    def chain(cls, transforms: Sequence[Transform]) -> Transform:
        """A then B then ...: models must link up (A's target is B's source, same options)."""
        if len(transforms) < 2:
            raise MatremapError("a chain needs at least two transforms")
        steps: list[Transform] = []
        for t in transforms:
            steps += t.steps if t.method == "chain" else [t]
        for a, b in zip(steps, steps[1:], strict=False):
            if a.target != b.source:
                raise MatremapError(
                    f"cannot chain: {a.source} -> {a.target} is followed by {b.source} -> {b.target}; "
                    f"the models must link up"
                )
            clash = {
                k for k in set(a.target_options) & set(b.source_options) if a.target_options[k] != b.source_options[k]
            }
            if clash:
                k = sorted(clash)[0]
                raise MatremapError(
                    f"cannot chain: {a.target} with {k}={a.target_options[k]} is followed by a "
                    f"transform trained on {k}={b.source_options[k]}"
                )
        errors = {f"step {i + 1}": {k: v.get("heldout_rmse") for k, v in s.errors.items()} for i, s in enumerate(steps)}
        return cls(
            "chain",
            steps[0].source,
            steps[-1].target,
            steps[0].source_options,
            steps[-1].target_options,
            domain=steps[0].domain,
            errors=errors,
            steps=steps,
            provenance={
                "chained": [f"{s.source} -> {s.target} ({s.method})" for s in steps],
                "created": time.strftime("%Y-%m-%dT%H:%M:%S"),
                "matremap": __version__,
            },
        )

    def describe(self) -> str:
        if self.method == "chain":
            return " -> ".join([self.steps[0].source] + [s.target for s in self.steps]) + " (chain)"
        return f"{self.source} -> {self.target} ({self.method})"


def _flatten(a: np.ndarray, shape: tuple[int, ...], n: int) -> np.ndarray:
    """``a`` with its element axes ``shape`` flattened into one axis of length n; an array holding
    one value for every element (a broadcast) becomes length 1 instead, without a copy."""
    k = len(shape)
    if a.shape[:k] != shape:  # given without the element axes: one value for all
        return np.asarray(a)[None]
    if k and all(s == 0 for s in a.strides[:k]):
        return a[(0,) * k][None]
    return a.reshape(n, *a.shape[k:])


def _inputs(mapping: Mapping[str, Any], available: Iterable[str]) -> list[str]:
    """The source quantities a mapping reads."""
    if mapping["kind"] == "svr":
        return list(mapping["inputs"])
    if mapping["kind"] == "k_alpha":
        return ["reflectance", "roughness"] if mapping.get("roughness", True) else ["reflectance"]
    if mapping["kind"] == "constant":
        return []
    return [mapping["input"]] if "input" in mapping else list(available)


def _complete(spec: ModelSpec, values: Mapping[str, Any], defaults: Mapping[str, Any]) -> dict[str, np.ndarray]:
    unknown = set(values) - set(spec.param_names) - set(spec.option_names)
    if unknown:
        raise MatremapError(f"{spec.id} has no parameter {sorted(unknown)[0]!r}")
    arrays = {k: qty.as_floats(v) for k, v in values.items() if k in spec.param_names}
    shape = _shape(spec, arrays)
    out = {}
    for p in spec.params:
        if p.name in arrays:
            a = arrays[p.name]
            # an RGB array carries a trailing channel axis; one shaped like the scalars is grey
            if p.channels == 3 and (a.ndim == 0 or a.shape[-1] != 3 or (shape and a.shape == shape)):
                a = np.repeat(a[..., None], 3, axis=-1)
            out[p.name] = a
        else:
            d = np.asarray(defaults.get(p.name, p.default), dtype=float)
            out[p.name] = np.broadcast_to(d, (*shape, 3) if p.channels == 3 else shape)
    return out


def _shape(spec: ModelSpec, arrays: Mapping[str, np.ndarray]) -> tuple[int, ...]:
    """The leading (per-element) shape: the broadcast of the scalar parameters' shapes and the RGB ones'
    without their channel axis (a constant next to a map takes the map's shape)."""
    channels = {p.name: p.channels for p in spec.params}
    shapes = []
    for k, a in arrays.items():
        if channels.get(k) == 1:
            shapes.append(a.shape)
        elif channels.get(k) == 3:
            shapes.append(a.shape[:-1] if a.ndim and a.shape[-1] == 3 else a.shape)
    return tuple(np.broadcast_shapes(*shapes)) if shapes else ()


# ---------------------------------------------------------------------------------------------
def learn_transform(
    db: str | Path,
    method: str = "parametric",
    reverse: bool = False,
    holdout: float = 0.2,
    seed: int = 0,
    exclude_flagged: bool = True,
) -> Transform:
    """Learn a transform from a sweep database (``reverse``: the target -> source direction)."""
    from matremap.regress.data import load_training_data

    get_learner(method)  # an unknown method fails before the database is read
    return transform_from_data(
        load_training_data(db, reverse=reverse, exclude_flagged=exclude_flagged), method, holdout, seed
    )


def training_domain(x: Mapping[str, np.ndarray], mappings: Mapping[str, Mapping[str, Any]]) -> dict[str, list[float]]:
    """The range of each source quantity the transform answers for: the training data's, except that a
    quantity read only through the origin -- by ``scale`` mappings (target = c * source: a Lambertian albedo) or as
    the F0 a ``k_alpha`` mapping scales (target F0 = k(alpha) * source F0) -- reaches down to 0, where every such
    mapping is exact (a black albedo is black in every renderer, a black F0 channel reflects nothing). Without it, a
    sweep whose darkest point was dropped (a high *relative* loss where only a dim specular lobe is left to fit) made
    every texel with one black channel count as outside: the sweep's F0 axis starts above 0 (a black metal renders
    black, refused), and Khronos SheenChair's peacock velvet, a metal of base colour (0, 0.094, 0.099), read wholly
    outside."""
    domain = {name: [float(np.min(v)), float(np.max(v))] for name, v in x.items()}
    for name, rng in domain.items():
        readers = [m for m in mappings.values() if name in _inputs(m, x)]
        through_origin = all(
            m["kind"] == "scale" or (m["kind"] == "k_alpha" and m.get("input") == name) for m in readers
        )
        if readers and through_origin and rng[0] > 0.0:
            rng[0] = 0.0
    return domain


def transform_from_data(
    data: TrainingData, method: str = "parametric", holdout: float = 0.2, seed: int = 0
) -> Transform:
    """Learn a transform from training data in memory (:class:`.data.TrainingData`, e.g. a subset)."""
    mappings = get_learner(method)(data, holdout=holdout, seed=seed)
    domain = training_domain(data.x, mappings)
    errors: dict[str, dict[str, float | None]] = {}
    for name, m in mappings.items():
        pred = evaluate_mapping(m, data.x)
        errors[name] = {"train_rmse": float(np.sqrt(np.mean((pred - data.y[name]) ** 2)))}
        if "heldout_rmse" in m:
            errors[name]["heldout_rmse"] = m["heldout_rmse"]
    return Transform(
        method,
        data.source.id,
        data.target.id,
        data.source_options,
        data.target_options,
        mappings,
        data.template,
        data.source_template,
        domain,
        errors,
        {
            **data.provenance,
            "created": time.strftime("%Y-%m-%dT%H:%M:%S"),
            "matremap": __version__,
            "holdout": holdout,
            "seed": seed,
        },
    )
