"""The embedded renderer: pure numpy, deterministic bit for bit, no external program.

:mod:`.probe` draws batches of uniform materials under the probe's point lights; :mod:`.environment`
draws a textured object under an environment map; :mod:`.evaluators` holds each emulated model's
f * cos(theta_i) as a numpy function.
"""

from matremap.renderers.embedded.probe import EmbeddedRenderer

__all__ = ["EmbeddedRenderer"]
