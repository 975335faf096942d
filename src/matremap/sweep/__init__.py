"""Parameter sweeps: grids, executors (local processes, Dask), the resumable SQLite store, the sweep
itself, stability flags and sweep reports."""

from matremap.sweep.run import SweepConfig, run_sweep

__all__ = ["SweepConfig", "run_sweep"]
