"""Real Mitsuba 3 (``pip install mitsuba``): probe renders (:mod:`.probe`) and environment-lit renders
of textured materials (:mod:`.environment`). Mitsuba itself is imported only when first used."""

from matremap.renderers.mitsuba3.probe import Mitsuba3Renderer

__all__ = ["Mitsuba3Renderer"]
