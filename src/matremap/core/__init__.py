"""The core of remapping: models and materials, the probe scene, optics, irradiance matching, the
fitter and image comparison. Nothing here knows a concrete renderer: a fit is handed
:class:`~matremap.renderers.base.Renderer` objects."""
