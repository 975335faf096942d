"""Regression: compact transforms learned from a remapping database (paper §5.1, §5.3).

:mod:`.quantities` reads models in a common vocabulary (roughness, specular reflectance F0,
diffuse albedo); :mod:`.data` reads a sweep database as training data; :mod:`.parametric` learns
the paper's closed-form mapping, :mod:`.svr` the SVR baseline, and :mod:`.learners` is the one table
of those methods by name; :mod:`.transform` holds the JSON file format, application, reversal and
chaining; :mod:`.library` the shipped transforms and routes through them.
"""
