"""Training data from a remapping database: source and target quantities, row by row."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from matremap.core.material import Material
from matremap.core.models import ModelSpec
from matremap.dialects import get_model
from matremap.errors import MatremapError
from matremap.regress import quantities as qty
from matremap.sweep.store import SweepStore


@dataclass
class TrainingData:
    """A sweep's rows as source quantities ``x`` and target quantities ``y`` (one row per point)."""

    source: ModelSpec
    target: ModelSpec
    source_options: dict[str, str]
    target_options: dict[str, str]
    x: dict[str, np.ndarray]  # source quantities: roughness [n], reflectance [n, 3], diffuse [n, 3]
    y: dict[str, np.ndarray]  # target quantities
    template: dict[str, Any]  # target parameter values not driven by quantities (as JSON values)
    provenance: dict[str, Any]
    source_template: dict[str, Any]  # source values the sweep held fixed (defaults for missing inputs)

    def __len__(self) -> int:
        return len(next(iter(self.x.values())))

    def too_few(self, need: int) -> MatremapError:
        """The error of a sweep that left fewer than ``need`` points to learn from, saying how many it fitted and how
        many the stability analysis left out (a target that cannot draw the source there fits it badly)."""
        used, rows = len(self), int(self.provenance.get("rows", len(self)))
        flagged = int(self.provenance.get("excluded_flagged", 0))
        why = (
            f"; {flagged} of its {rows} fits were left out as unstable or poor (the target does not draw this source "
            "well there: see matremap sweep-report on the sweep database; try another target model)"
            if flagged
            else ""
        )
        return MatremapError(f"{used} usable points: too few to learn a transform (need {need}){why}")

    def varies(self, name: str) -> bool:
        """Whether a source quantity takes more than one value in the data."""
        v = self.x.get(name)
        return v is not None and bool(np.ptp(v) > 1e-12)

    def subset(self, keep: np.ndarray) -> TrainingData:
        """The rows ``keep`` (indices or a boolean mask)."""
        return TrainingData(
            self.source,
            self.target,
            self.source_options,
            self.target_options,
            {k: v[keep] for k, v in self.x.items()},
            {k: v[keep] for k, v in self.y.items()},
            self.template,
            self.provenance,
            self.source_template,
        )


def holdout_split(n: int, holdout: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Row indices of ``n`` points split at random into training and held-out sets: round(holdout * n)
    held out (at least one), the same split for the same ``seed``."""
    idx = np.random.default_rng(seed).permutation(n)
    m = max(1, int(round(holdout * n)))
    return idx[m:], idx[:m]


def _values(spec: ModelSpec, params: list[dict[str, Any]]) -> dict[str, np.ndarray]:
    return {p.name: np.array([r[p.name] for r in params], dtype=float) for p in spec.params}


def load_training_data(db: str | Path, reverse: bool = False, exclude_flagged: bool = True) -> TrainingData:
    """Rows of a sweep database as quantities. ``reverse`` swaps source and target (learning the
    way back); ``exclude_flagged`` leaves out points the stability analysis flags."""
    from matremap.sweep.grid import Grid
    from matremap.sweep.run import SweepConfig
    from matremap.sweep.stability import LOSS_MAX, LOSS_MAX_BY_OBJECTIVE, analyse

    with SweepStore.open(db) as store:
        rows = store.rows()
        ok = [r for r in rows if r["status"] == "ok"]
        if not ok:
            raise MatremapError(f"{db} has no successful fits to learn from ({len(rows)} rows, all failed or none)")
        try:
            config = SweepConfig.from_dict(store.config)
            grid = Grid.from_dict(store.grid) if store.grid else None
        except (KeyError, TypeError, ValueError) as e:
            raise MatremapError(
                f"{db} holds no valid sweep configuration ({e}); was it made by matremap sweep?"
            ) from None
    flagged = 0
    if exclude_flagged and grid is not None:
        analysis = analyse(rows, grid, config)
        kept = [r for r in ok if not analysis.flags.get(r["key"])]
        flagged = len(ok) - len(kept)
        # every point flagged: learn from them all, but never from fits that found no match
        most = LOSS_MAX_BY_OBJECTIVE.get(config.objective, LOSS_MAX)
        ok = kept or [r for r in ok if r.get("loss") is None or float(r["loss"]) <= most]
        if not ok:
            raise MatremapError(
                f"{db}: every fit of the sweep found no match ({config.objective} loss above {most:g}): there is "
                f"nothing to learn a transform from; try --strategy simple, or another target model"
            )
    src_spec, tgt_spec = get_model(config.source.model), get_model(config.target)
    src_params = [r["source"] for r in ok]
    tgt_params = [r["target"] for r in ok]
    src_opts = {o: src_params[0][o] for o in src_spec.option_names}
    tgt_opts = {o: tgt_params[0][o] for o in tgt_spec.option_names}
    src_values = _values(src_spec, src_params)
    layers = layers_on(src_spec, src_values)
    x = qty.read(src_spec, src_values, layers)
    y = qty.read(tgt_spec, _values(tgt_spec, tgt_params), layers)
    template_src = config.source.to_dict()["params"]
    template_tgt = Material.create(tgt_spec.id, tgt_params[0]).to_dict()["params"]
    provenance = {
        "database": str(Path(db).name),
        "sweep": store_config_summary(config),
        "rows": len(rows),
        "used": len(ok),
        "excluded_flagged": flagged,
        "reverse": reverse,
    }
    if reverse:
        return TrainingData(tgt_spec, src_spec, tgt_opts, src_opts, y, x, template_src, provenance, template_tgt)
    return TrainingData(src_spec, tgt_spec, src_opts, tgt_opts, x, y, template_tgt, provenance, template_src)


def layers_on(spec: ModelSpec, values: dict[str, np.ndarray]) -> tuple[str, ...]:
    """The layers a sweep varies (on at some point, and one of its weight, colour or roughness not the same at every
    point): their quantities are learned too. A layer the sweep held (a textured material's uniform coat) stays a
    value of the transform's source template, which its application checks texels against
    (:meth:`~matremap.regress.transform.Transform.apply`)."""
    out = []
    for name, layer in qty.layer_params(spec).items():
        q = qty.read_layer(name, layer, values) if name in qty.LAYERS else {}
        if q and float(np.max(q[f"{name}_weight"])) > 0.0 and any(np.ptp(v, axis=0).max() > 1e-12 for v in q.values()):
            out.append(name)
    return tuple(out)


def store_config_summary(config: Any) -> dict[str, Any]:
    """The parts of a sweep configuration a transform's provenance records."""
    d = config.to_dict()
    return {k: d[k] for k in ("source", "target", "strategy", "scene", "renderers", "matremap", "objective") if k in d}
