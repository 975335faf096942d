"""Shared fixtures: the probe scene, the embedded renderer, the authors' published table."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

from matremap.core.scene import Scene
from matremap.renderers import get_renderer

# the authors' published Ward -> AS table, kept with its provenance in tests/data/README.md
REFERENCE = Path(__file__).resolve().parent / "data" / "reference" / "mitsuba-ward2mitsuba-as.csv"


@pytest.fixture(scope="session")
def scene() -> Scene:
    return Scene()


@pytest.fixture(scope="session")
def embedded():
    return get_renderer("embedded")


@pytest.fixture(scope="session")
def reference_rows() -> list[dict[str, float]]:
    """Rows of the Ward -> AS table published with the paper (tests/data/reference)."""
    with REFERENCE.open() as f:
        rows = [
            {k: float(r[k]) for k in ("alpha1", "specular1", "alpha2", "eta2")}
            for r in csv.DictReader(f, delimiter="\t")
        ]
    return sorted(rows, key=lambda r: (r["alpha1"], r["specular1"]))
