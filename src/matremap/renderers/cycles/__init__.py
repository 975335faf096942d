"""Real Blender Cycles, in a worker process running bpy from a venv of its own: probe renders
(:mod:`.probe`), environment-lit renders of textured materials (:mod:`.environment`); :mod:`.worker` is
the script the worker runs."""

from matremap.renderers.cycles.probe import CyclesRenderer

__all__ = ["CyclesRenderer"]
