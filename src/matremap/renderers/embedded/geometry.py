"""Local shading geometry: the cosines a BRDF needs, as numpy arrays.

Conventions (as in dialects.md): ``i`` is the direction to the light, ``o`` the direction to the
viewer, ``n`` the normal, ``H = i + o`` the unnormalised half vector and ``h = H/|H|``.
Everything is derived from three cosines (n.i, n.o, i.o), which is all an isotropic BRDF depends on;
an anisotropic one also needs the directions' components along the surface's tangent ``s`` (dp/du) and
bitangent ``t = n x s`` (Mitsuba's shading frame), given when the scene knows them (``frame``).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from functools import cached_property

import numpy as np


@dataclass(frozen=True, eq=False)
class LocalGeometry:
    cos_i: np.ndarray
    cos_o: np.ndarray
    i_dot_o: np.ndarray
    #: (i.s, i.t, o.s, o.t): light and view directions along the tangent and bitangent, or None
    frame: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None
    #: the alpha a mirror is drawn with (:func:`~matremap.renderers.embedded.microfacet.drawn_alpha`): 0 under
    #: point lights, which never reach a mirror's delta lobe (it is zero); the narrowest lobe (1e-4) where the
    #: renderer samples the mirror direction (an environment render's mirror samples)
    mirror_alpha: float = 0.0

    @cached_property
    def h_len2(self) -> np.ndarray:
        """|H|^2 = |i + o|^2 = 2 + 2 i.o"""
        return np.maximum(2.0 + 2.0 * self.i_dot_o, 1e-30)

    @cached_property
    def h_z(self) -> np.ndarray:
        """n.H (unnormalised)."""
        return self.cos_i + self.cos_o

    @cached_property
    def cos_h(self) -> np.ndarray:
        """n.h, cosine of the half-vector angle."""
        return self.h_z / np.sqrt(self.h_len2)

    @cached_property
    def i_dot_h(self) -> np.ndarray:
        """i.h = o.h = |H| / 2."""
        return 0.5 * np.sqrt(self.h_len2)

    @cached_property
    def tan2_h(self) -> np.ndarray:
        """tan^2 of the half-vector angle: (|H|^2 - H_z^2) / H_z^2."""
        hz2 = self.h_z * self.h_z
        return np.maximum(self.h_len2 - hz2, 0.0) / hz2

    @cached_property
    def cos_reflect(self) -> np.ndarray:
        """o . R(i), R(i) the mirror direction of i about n: 2 (n.i)(n.o) - i.o."""
        return 2.0 * self.cos_i * self.cos_o - self.i_dot_o

    @cached_property
    def tan2_i(self) -> np.ndarray:
        return tan2(self.cos_i)

    @cached_property
    def tan2_o(self) -> np.ndarray:
        return tan2(self.cos_o)

    @cached_property
    def tan_i(self) -> np.ndarray:
        return np.sqrt(self.tan2_i)

    @cached_property
    def tan_o(self) -> np.ndarray:
        return np.sqrt(self.tan2_o)

    @cached_property
    def schlick_weight(self) -> np.ndarray:
        """(1 - i.h)^5, the angular factor of Schlick's Fresnel."""
        m = 1.0 - np.minimum(self.i_dot_h, 1.0)
        m2 = m * m
        return m2 * m2 * m

    @cached_property
    def lambert(self) -> np.ndarray:
        """cos_i / pi: a Lambertian BRDF of albedo 1 times the cosine."""
        return self.cos_i / np.pi

    @cached_property
    def log_cos_h(self) -> np.ndarray:
        with np.errstate(divide="ignore"):
            return np.log(np.maximum(self.cos_h, 0.0))


def tan2(cos: np.ndarray) -> np.ndarray:
    c2 = cos * cos
    return np.maximum(1.0 - c2, 0.0) / c2


def from_directions(wi: np.ndarray, wo: np.ndarray, normal: np.ndarray | None = None) -> LocalGeometry:
    """Geometry of unit light / view directions [..., 3] about a normal (default +z); the
    arrays have the leading shape of the directions (evaluate with parameters shaped [N, C, 1, 1]
    for directions [L, P], or [N, C, 1] for directions [P])."""
    wi = np.asarray(wi, dtype=float)
    wo = np.asarray(wo, dtype=float)
    n = np.array([0.0, 0.0, 1.0]) if normal is None else np.asarray(normal, dtype=float)
    return LocalGeometry(
        cos_i=np.sum(wi * n, axis=-1),
        cos_o=np.sum(wo * n, axis=-1),
        i_dot_o=np.sum(wi * wo, axis=-1),
    )


def direction(theta_deg: float, phi_deg: float = 0.0) -> np.ndarray:
    """Unit vector at polar angle theta from +z and azimuth phi (degrees)."""
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


#: f(params, options, geometry) -> f * cos(theta_i); params are [N, C, 1, 1] (C = 1 or 3 channels),
#: geometry arrays [L, P] (lights, pixels), the result broadcasts to [N, C, L, P]
Evaluator = Callable[[Mapping[str, np.ndarray], Mapping[str, str], LocalGeometry], np.ndarray]
