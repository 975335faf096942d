"""Spectra given as wavelength:value lists, converted to linear sRGB as Mitsuba 3's RGB variants do.

Source: Mitsuba 3.9 ``src/core/spectrum.cpp`` (``spectrum_list_to_srgb``) and ``src/core/properties.cpp``
(which calls it for a ``<spectrum>`` of wavelength-value pairs in RGB variants: ``d65`` for everything
but emitters, ``bounded`` unless the parameter is an emitter's or an unbounded one such as a
conductor's ``eta``/``k``). The method:

1. 1000 wavelengths evenly spaced over [360, 830] nm; those outside the list's first and last
   wavelength are skipped (no extrapolation);
2. at each, the list is interpolated linearly and multiplied by the CIE 1931 2-degree colour-matching
   functions and, for reflectances, by the CIE D65 illuminant divided by 98.99741751876255 (both
   tabulated at 5 nm and interpolated linearly, as Mitsuba does);
3. the sum times 470 nm / 1000 / 106.7502593994140625 (Mitsuba's ``MI_CIE_Y_NORMALIZATION``) is XYZ,
   turned into linear sRGB by Mitsuba's matrix (``xyz_to_srgb`` in ``include/mitsuba/core/spectrum.h``);
4. bounded results are clipped to [0, 1], unbounded ones to >= 0.

The tables come from colour-science: ``MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]`` and
``SDS_ILLUMINANTS["D65"]`` sampled at 5 nm (CIE 015:2018's tables; D65 from 785 to 830 nm, which
colour-science's D65 does not list, from its CIE D-series basis at the D65 chromaticity, as the CIE
extends it). tests/test_mitsuba_spectra.py compares the result with Mitsuba 3.9.1's own conversion.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache

import numpy as np

from matremap.errors import MatremapError

CIE_MIN, CIE_MAX = 360.0, 830.0
#: Mitsuba's MI_CIE_Y_NORMALIZATION and MI_CIE_D65_NORMALIZATION
Y_NORMALIZATION = 1.0 / 106.7502593994140625
D65_NORMALIZATION = 1.0 / 98.99741751876255
#: XYZ -> linear sRGB (Rec. 709 primaries, D65 white), Mitsuba's ``xyz_to_srgb``
XYZ_TO_SRGB = np.array(
    [[3.240479, -1.537150, -0.498535], [-0.969256, 1.875991, 0.041556], [0.055648, -0.204043, 1.057311]]
)
_STEPS = 1000


@lru_cache(maxsize=1)
def _tables() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(wavelengths every 5 nm from 360 to 830, CMFs [95, 3], D65 [95])."""
    import colour

    grid = np.arange(CIE_MIN, CIE_MAX + 1.0, 5.0)
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    xyz = np.asarray(cmfs[grid], dtype=float)
    d65 = colour.SDS_ILLUMINANTS["D65"]
    listed = grid[grid <= d65.wavelengths[-1]]
    xy = colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"]
    series = colour.sd_CIE_illuminant_D_series(xy)
    illuminant = np.concatenate([np.asarray(d65[listed], float), np.asarray(series[grid[len(listed) :]], float)])
    return grid, xyz, illuminant


def parse_pairs(text: str) -> tuple[np.ndarray, np.ndarray] | None:
    """``"400:0.1, 500:0.2"`` as (wavelengths, values); None when ``text`` holds no ``:`` pair.
    Raises on a malformed list (Mitsuba needs increasing wavelengths)."""
    parts = text.replace(",", " ").split()
    if not any(":" in p for p in parts):
        return None
    try:
        pairs = [tuple(float(x) for x in p.split(":")) for p in parts]
    except ValueError:
        raise MatremapError(f"spectrum {text!r} is not a list of wavelength:value pairs") from None
    if any(len(p) != 2 for p in pairs) or len(pairs) < 2:
        raise MatremapError(f"spectrum {text!r} needs at least two wavelength:value pairs")
    w = np.array([p[0] for p in pairs])
    v = np.array([p[1] for p in pairs])
    if not (np.all(np.isfinite(w)) and np.all(np.isfinite(v))) or np.any(np.diff(w) <= 0):
        raise MatremapError(f"spectrum {text!r}: wavelengths must be finite and increasing, values finite")
    return w, v


def parse_spd(text: str) -> tuple[np.ndarray, np.ndarray]:
    """A spectrum file (Mitsuba's ``.spd``: "wavelength value" per line, ``#`` comments)."""
    rows = []
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            rows.append(line.replace(",", " ").split())
    try:
        w = np.array([float(r[0]) for r in rows])
        v = np.array([float(r[1]) for r in rows])
    except (ValueError, IndexError):
        raise MatremapError("a spectrum file must hold 'wavelength value' lines") from None
    if len(w) < 2 or not (np.all(np.isfinite(w)) and np.all(np.isfinite(v))) or np.any(np.diff(w) <= 0):
        raise MatremapError("a spectrum file needs two or more finite lines with increasing wavelengths")
    return w, v


def spectrum_to_srgb(
    wavelengths: Sequence[float] | np.ndarray,
    values: Sequence[float] | np.ndarray,
    bounded: bool = True,
    d65: bool = True,
) -> np.ndarray:
    """Linear sRGB of a spectrum given at ``wavelengths`` (nm), by Mitsuba 3's method (module doc)."""
    wl = np.asarray(wavelengths, dtype=float)
    vals = np.asarray(values, dtype=float)
    grid, cmf, illum = _tables()
    w = CIE_MIN + np.arange(_STEPS) / (_STEPS - 1) * (CIE_MAX - CIE_MIN)
    w = w[(w >= wl[0]) & (w <= wl[-1])]
    v = np.interp(w, wl, vals)
    weight = v * (np.interp(w, grid, illum) * D65_NORMALIZATION if d65 else 1.0)
    xyz = np.stack([np.interp(w, grid, cmf[:, c]) for c in range(3)], axis=-1)
    total = (xyz * weight[:, None]).sum(axis=0) * (CIE_MAX - CIE_MIN) * Y_NORMALIZATION / _STEPS
    rgb = XYZ_TO_SRGB @ total
    return np.clip(rgb, 0.0, 1.0) if bounded else np.maximum(rgb, 0.0)


__all__ = ["parse_pairs", "parse_spd", "spectrum_to_srgb"]
