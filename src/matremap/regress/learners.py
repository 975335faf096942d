"""The regression methods a transform is learned with: one table from method name to learner.

A learner turns :class:`.data.TrainingData` into mappings, one plain-JSON object per target
quantity; :func:`evaluate_mapping` applies a mapping, whichever method made it. ``matremap learn
--method``, :func:`.transform.learn_transform` and :func:`.transform.transform_from_data` all read
:data:`LEARNERS`, so a new method is one entry here (and its mapping kinds in :func:`evaluate_mapping`).

The learners import their modules when first called: the table is read when the command line is
built, and SciPy / scikit-learn need not load for that.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Protocol

from matremap.errors import MatremapError

if TYPE_CHECKING:
    import numpy as np

    from matremap.regress.data import TrainingData


class Learner(Protocol):
    """Fits mappings for every quantity the target speaks from training data; ``holdout`` is the
    fraction of points held out to choose forms or hyper-parameters, ``seed`` fixes that split."""

    def __call__(self, data: TrainingData, holdout: float = 0.2, seed: int = 0) -> dict[str, dict[str, Any]]: ...


def learn_parametric(data: TrainingData, holdout: float = 0.2, seed: int = 0) -> dict[str, dict[str, Any]]:
    """The paper's closed-form mappings (:mod:`.parametric`)."""
    from matremap.regress.parametric import learn

    return learn(data, holdout=holdout, seed=seed)


def learn_svr(data: TrainingData, holdout: float = 0.2, seed: int = 0) -> dict[str, dict[str, Any]]:
    """The SVR baseline (:mod:`.svr`; needs scikit-learn)."""
    from matremap.regress.svr import learn

    return learn(data, holdout=holdout, seed=seed)


#: regression method name -> learner (the ``method`` of a transform file, ``matremap learn --method``)
LEARNERS: dict[str, Learner] = {"parametric": learn_parametric, "svr": learn_svr}


def get_learner(method: str) -> Learner:
    """The learner of a method name; an unknown name is a MatremapError naming the choices."""
    try:
        return LEARNERS[method]
    except KeyError:
        raise MatremapError(f"unknown method {method!r}; choose {' or '.join(LEARNERS)}") from None


def evaluate_mapping(mapping: dict[str, Any], x: dict[str, np.ndarray]) -> np.ndarray:
    """Apply one learned mapping (any method's, chosen by its ``kind``) to source quantities ``x``."""
    if mapping["kind"] == "svr":
        from matremap.regress.svr import evaluate as svr_evaluate

        return svr_evaluate(mapping, x)
    from matremap.regress.parametric import evaluate

    return evaluate(mapping, x)
