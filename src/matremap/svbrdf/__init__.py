"""Spatially varying materials: texture map sets, their conversion texel by texel, and their evaluation
under an environment map."""
