"""Samples about the mirror direction: environment renders of lobes narrower than the lights' spacing.

An environment drawn as a few hundred directional lights (:func:`~matremap.core.envmap.directional_lights`)
shades a glossy lobe narrower than the lights' spacing wrongly, and a mirror black: its lobe falls between the
lights. Each pixel therefore also takes ``K`` directions about its mirror direction ``r = 2 (n.v) n - v``,
spread log-uniformly in their angle ``theta`` to ``r`` (``THETA_MIN`` to ``THETA_MAX``) and evenly in azimuth
(a golden-angle sequence, the same pattern at every pixel in a frame that turns with ``r``), so that a lobe of
any width from the microfacet models' smallest (alpha = 1e-4) to about a radian gets samples. The density of
these directions over the sphere is

    p_B(w) = 1 / (2 pi sin(theta) theta ln(THETA_MAX / THETA_MIN)),   THETA_MIN <= theta <= THETA_MAX.

The lights and these samples are combined by multiple importance sampling with the balance heuristic
(Veach and Guibas 1995, "Optimally Combining Sampling Techniques for Monte Carlo Rendering", eq. 7): each
direction ``w`` of either set contributes ``f cos L(w) / (N_L p_L(w) + N_B p_B(w))``, with ``p_L`` the lights'
density (:meth:`~matremap.core.envmap.EnvMap.light_density`). The estimate stays unbiased; where the lights
resolve the integrand (diffuse and rough lobes) they keep most of the weight, where they do not (near ``r``
of a glossy lobe, whose ``p_B`` is large) the mirror samples take it.
"""

from __future__ import annotations

import math

import numpy as np

#: angles to the mirror direction the samples span (rad): from a hundredth of the narrowest microfacet lobe
#: (2 alpha at alpha = 1e-4) up to a radian, past which the lights resolve every lobe
THETA_MIN, THETA_MAX = 1e-6, 1.0
#: the golden angle's fraction of a turn, for evenly spread azimuths
GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0


def mirror_directions(normals: np.ndarray, views: np.ndarray) -> np.ndarray:
    """Mirror directions ``r = 2 (n.v) n - v`` [p, 3] of unit normals and view directions [p, 3]."""
    return 2.0 * np.sum(normals * views, axis=-1, keepdims=True) * normals - views


def pattern(count: int) -> tuple[np.ndarray, np.ndarray]:
    """The per-pixel pattern: angles to the mirror direction ``theta`` [K] (log-uniform strata, centred) and
    azimuths ``phi`` [K] (golden-angle sequence)."""
    k = np.arange(count)
    theta = THETA_MIN * (THETA_MAX / THETA_MIN) ** ((k + 0.5) / count)
    phi = 2.0 * math.pi * np.mod(k * GOLDEN, 1.0)
    return theta, phi


def density_at(theta: np.ndarray) -> np.ndarray:
    """p_B (per steradian) of the mirror samples at angle ``theta`` to the mirror direction (0 outside
    [THETA_MIN, THETA_MAX])."""
    t = np.clip(theta, THETA_MIN, THETA_MAX)
    p = 1.0 / (2.0 * math.pi * np.sin(t) * t * math.log(THETA_MAX / THETA_MIN))
    return np.where((theta >= THETA_MIN) & (theta <= THETA_MAX), p, 0.0)


def density(directions: np.ndarray, mirror: np.ndarray) -> np.ndarray:
    """p_B [L, p] of shared unit ``directions`` [L, 3] about each pixel's mirror direction [p, 3]."""
    cos_t = np.clip(directions @ mirror.T, -1.0, 1.0)
    out = np.zeros_like(cos_t)
    near = cos_t >= math.cos(THETA_MAX)  # only those within the cone have a density; arccos only there
    out[near] = density_at(np.arccos(cos_t[near]))
    return out


def samples(mirror: np.ndarray, tangent: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray]:
    """``count`` directions [K, p, 3] about each pixel's unit mirror direction [p, 3] and their density p_B
    [K] (the same at every pixel). The frame turns with ``r``: its first axis is ``tangent`` [p, 3] (a
    direction that varies smoothly over the image, e.g. the surface's dp/du) made orthogonal to ``r``."""
    theta, phi = pattern(count)
    t1 = tangent - np.sum(tangent * mirror, axis=-1, keepdims=True) * mirror
    length = np.linalg.norm(t1, axis=-1, keepdims=True)
    # where the tangent runs along r (never on the sphere's visible pixels), any axis orthogonal to r
    fallback = np.cross(mirror, np.where(np.abs(mirror[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]]))
    t1 = np.where(length > 1e-6, t1 / np.maximum(length, 1e-12), fallback / np.linalg.norm(fallback, axis=-1)[:, None])
    t2 = np.cross(mirror, t1)
    st = np.sin(theta)[:, None, None]
    d = (
        np.cos(theta)[:, None, None] * mirror[None]
        + (st * np.cos(phi)[:, None, None]) * t1[None]
        + (st * np.sin(phi)[:, None, None]) * t2[None]
    )
    return d, density_at(theta)
