"""Evaluating a remapped SVBRDF: renders under a turning environment, SSIM maps, an HTML report.

For each rotation of the environment, the source and the target material are rendered on the
evaluation geometry (:mod:`matremap.renderers.embedded.environment`), in full and specular only. Each pair is
compared with scikit-image's SSIM on the linear HDR images, as the paper does (data range: the
source image's), giving an SSIM map and the mean 1 - SSIM over the object's pixels (the paper's
SSIM plots over rotations). Everything goes to one folder: sRGB PNGs of the renders, colour-mapped
1 - SSIM maps, a plot against rotation, ``results.json`` and ``report.html``, a single file with
every image embedded.
"""

from __future__ import annotations

import base64
import html
import io
import json
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from matremap.core.envmap import EnvMap, directional_lights
from matremap.core.imageio import atomic_output, linear_to_srgb
from matremap.core.models import get_model, white_reference
from matremap.errors import MatremapError
from matremap.renderers.embedded.environment import GEOMETRIES, SVBRDFRender, object_mask

PARTS = ("full", "specular")

#: 1 - SSIM colour maps span [0, SSIM_MAP_MAX]
SSIM_MAP_MAX = 1.0


@dataclass(frozen=True)
class SVMaterial:
    """A spatially varying material: a model, its parameter maps (or constants), its options and
    an optional tangent-space normal map in [-1, 1]."""

    model: str
    params: Mapping[str, Any]
    options: Mapping[str, str] = field(default_factory=dict)
    normal: np.ndarray | None = None

    @classmethod
    def of(cls, m: Any) -> SVMaterial:
        """From an SVMaterial, a (model, params, options, normal) tuple (options and normal may be
        left out) or a mapping with those keys."""
        if isinstance(m, SVMaterial):
            return m
        if isinstance(m, Mapping):
            return cls(m["model"], m.get("params", {}), m.get("options") or {}, m.get("normal"))
        if isinstance(m, (tuple, list)) and 2 <= len(m) <= 4:
            model, params, *rest = m
            options = rest[0] if rest else {}
            normal = rest[1] if len(rest) > 1 else None
            return cls(model, params, options or {}, normal)
        raise MatremapError("a material to evaluate is (model, params, options, normal_map)")


@dataclass
class EvaluationResult:
    rotations: list[float]
    #: mean 1 - SSIM over the object's pixels, per rotation
    dssim_full: list[float]
    dssim_specular: list[float]
    #: 1 - SSIM of skimage's whole-image mean (background included), per rotation
    dssim_full_image: list[float]
    dssim_specular_image: list[float]
    irradiance_scale: float
    out_dir: Path
    report: Path
    files: list[Path]

    @property
    def mean_full(self) -> float:
        return float(np.mean(self.dssim_full))

    @property
    def mean_specular(self) -> float:
        return float(np.mean(self.dssim_specular))

    def to_dict(self) -> dict[str, Any]:
        return {
            "rotations": self.rotations,
            "dssim_full": self.dssim_full,
            "dssim_specular": self.dssim_specular,
            "dssim_full_image": self.dssim_full_image,
            "dssim_specular_image": self.dssim_specular_image,
            "mean_dssim_full": self.mean_full,
            "mean_dssim_specular": self.mean_specular,
            "irradiance_scale": self.irradiance_scale,
            "report": str(self.report),
        }


# ---------------------------------------------------------------------------------------------
# helpers


def parse_rotations(text: str) -> list[float]:
    """``START:STOP:COUNT`` (stop exclusive, COUNT evenly spaced angles in degrees), or a
    comma-separated list of angles, or one angle. ``0:360:12`` -> 0, 30, ..., 330."""
    s = str(text).strip()
    if not s:
        raise MatremapError("--rotations is empty; give START:STOP:COUNT (e.g. 0:360:12) or angles 0,90,180")
    if ":" in s:
        parts = s.split(":")
        if len(parts) != 3:
            raise MatremapError(f"--rotations {s!r}: expected START:STOP:COUNT, e.g. 0:360:12")
        try:
            start, stop = float(parts[0]), float(parts[1])
        except ValueError:
            raise MatremapError(f"--rotations {s!r}: START and STOP must be angles in degrees") from None
        try:
            count = int(parts[2])
        except ValueError:
            raise MatremapError(f"--rotations {s!r}: COUNT must be a whole number of rotations") from None
        if not (math.isfinite(start) and math.isfinite(stop)):
            raise MatremapError(f"--rotations {s!r}: START and STOP must be finite")
        if count < 1:
            raise MatremapError(f"--rotations {s!r}: COUNT must be at least 1")
        if count > 1 and stop == start:
            raise MatremapError(f"--rotations {s!r}: START equals STOP, so the {count} rotations would be the same")
        step = (stop - start) / count
        return [start + k * step for k in range(count)]
    out = []
    for item in s.split(","):
        try:
            v = float(item)
        except ValueError:
            raise MatremapError(
                f"--rotations {s!r}: {item.strip()!r} is not an angle; give START:STOP:COUNT or angles 0,90,180"
            ) from None
        if not math.isfinite(v):
            raise MatremapError(f"--rotations {s!r}: angles must be finite")
        out.append(v)
    return out


def ssim_map(source: np.ndarray, target: np.ndarray) -> tuple[float, np.ndarray]:
    """SSIM of two linear HDR images [H, W, 3] (scikit-image, ``channel_axis=-1``, data range of
    the source; of the target if the source is flat, else 1). Returns (skimage's mean SSIM, the
    SSIM map [H, W] averaged over channels)."""
    try:
        from skimage.metrics import structural_similarity
    except ImportError:  # pragma: no cover - a dependency of the evaluate command
        raise MatremapError("evaluate needs scikit-image: pip install scikit-image") from None
    s = np.asarray(source, dtype=np.float64)
    t = np.asarray(target, dtype=np.float64)
    if s.shape != t.shape:
        raise MatremapError(f"cannot compare images of shapes {s.shape} and {t.shape}")
    data_range = float(s.max() - s.min())
    if not data_range > 0.0:
        data_range = float(t.max() - t.min())
    if not data_range > 0.0:
        data_range = 1.0
    mssim, full = structural_similarity(s, t, data_range=data_range, channel_axis=-1, full=True)
    return float(mssim), full.mean(axis=-1)


def tonemap(image: np.ndarray, exposure: float) -> np.ndarray:
    """Linear HDR -> 8-bit sRGB after scaling by ``exposure`` (values above 1 clip)."""
    return np.round(linear_to_srgb(np.asarray(image, dtype=np.float64) * exposure) * 255.0).astype(np.uint8)


def _exposure(image: np.ndarray, mask: np.ndarray) -> float:
    """A scale that maps the 99th percentile of the object's luminance to 0.9."""
    v = image[mask].max(axis=-1) if mask.any() else image.reshape(-1, 3).max(axis=-1)
    p = float(np.percentile(v, 99.0)) if v.size else 0.0
    return 0.9 / p if p > 0.0 else 1.0


def _colormap(values: np.ndarray, vmax: float = SSIM_MAP_MAX) -> np.ndarray:
    from matplotlib import colormaps

    x = np.clip(np.asarray(values, dtype=float) / vmax, 0.0, 1.0)
    return np.round(colormaps["magma"](x)[..., :3] * 255.0).astype(np.uint8)


def _png_bytes(rgb8: np.ndarray) -> bytes:
    """Encode an 8-bit RGB image as PNG."""
    from matremap.core.imageio import png_bytes

    return png_bytes(rgb8)


def _write_bytes(path: Path, data: bytes) -> None:
    with atomic_output(path) as tmp, open(tmp, "wb") as f:
        f.write(data)


def _plot(rotations: Sequence[float], full: Sequence[float], spec: Sequence[float]) -> bytes:
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6.0, 3.6), dpi=100)
    ax = fig.add_subplot()
    ax.plot(rotations, full, "o-", label="full")
    ax.plot(rotations, spec, "s--", label="specular only")
    ax.set_xlabel("environment rotation (degrees)")
    ax.set_ylabel("mean 1 - SSIM (object pixels)")
    ax.set_ylim(bottom=0.0)
    ax.grid(True, alpha=0.3)
    ax.legend()
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()


def _colorbar() -> bytes:
    ramp = np.tile(np.linspace(0.0, SSIM_MAP_MAX, 256)[None, :], (12, 1))
    return _png_bytes(_colormap(ramp))


class _MitsubaRender:
    """A material drawn by real Mitsuba 3 (``mitsuba3:*`` models) under the environment map itself,
    with the interface of :class:`SVBRDFRender` (the discrete lights are not used)."""

    label = "Mitsuba 3"

    def __init__(
        self,
        model: str,
        params: Mapping[str, Any],
        options: Mapping[str, str],
        geometry: str,
        resolution: int,
        part: str,
        normal: np.ndarray | None,
        env: EnvMap,
    ) -> None:
        if geometry != "sphere":
            raise MatremapError(f"{model} is drawn by Mitsuba 3, which renders the sphere only; use --geometry sphere")
        from matremap.renderers.mitsuba3.environment import render_svbrdf_mitsuba3

        self._render = render_svbrdf_mitsuba3
        self.args = (model, params, options, env)
        self.resolution, self.part, self.normal = resolution, part, normal

    def render_at(self, directions: np.ndarray, intensities: np.ndarray, rotation: float) -> np.ndarray:
        model, params, options, env = self.args
        return self._render(
            model,
            params,
            options,
            env,
            rotation_deg=rotation,
            resolution=self.resolution,
            part=self.part,
            normal_map=self.normal,
        )


class _CyclesRender:
    """A material drawn by real Blender Cycles (``cycles:glossy``, ``cycles:diffuse``) through the bpy
    worker (:func:`~matremap.renderers.cycles.environment.render_svbrdf_cycles`, 64 spp, seed 0) under the
    environment map itself, with the interface of :class:`SVBRDFRender` (the discrete lights are not
    used). The parameters are checked here, before anything renders."""

    def __init__(
        self,
        model: str,
        params: Mapping[str, Any],
        options: Mapping[str, str],
        resolution: int,
        part: str,
        normal: np.ndarray | None,
        env: EnvMap,
    ) -> None:
        from matremap.renderers.cycles.environment import DEFAULT_SPP, render_svbrdf_cycles
        from matremap.renderers.embedded.environment import _check_params, check_normal_map

        opts = _check_params(get_model(model), params, options)
        self._render = render_svbrdf_cycles
        self.args = (model, params, opts, env)
        self.resolution, self.part = resolution, part
        self.normal = None if normal is None else check_normal_map(normal)
        self.label = f"Blender Cycles (bpy worker, {DEFAULT_SPP} spp)"

    def render_at(self, directions: np.ndarray, intensities: np.ndarray, rotation: float) -> np.ndarray:
        model, params, options, env = self.args
        return self._render(
            model,
            params,
            options,
            env,
            rotation_deg=rotation,
            resolution=self.resolution,
            part=self.part,
            normal_map=self.normal,
        )


class _EmbeddedRender(SVBRDFRender):
    label = "embedded emulation"

    def render_at(self, directions: np.ndarray, intensities: np.ndarray, rotation: float) -> np.ndarray:
        return self.render(directions, intensities)


def _cycles_fallback(model: str, why: str) -> None:
    import warnings

    warnings.warn(
        f"{model} is drawn with matremap's embedded emulation of Cycles, not with Blender Cycles: {why}",
        RuntimeWarning,
        stacklevel=3,
    )


def _prepare(
    model: str,
    params: Mapping[str, Any],
    options: Mapping[str, str],
    geometry: str,
    resolution: int,
    part: str,
    normal: np.ndarray | None,
    env: EnvMap,
    real: bool = True,
) -> Any:
    """The renderer of a material: real Mitsuba 3 and real Blender Cycles for their own models, else
    the embedded one. ``cycles:glossy`` / ``cycles:diffuse`` fall back to their embedded emulation,
    with a warning, where real Cycles cannot draw them (no bpy venv, or not the sphere); ``real=False``
    asks for the emulation outright."""
    spec = get_model(model)
    if spec.family == "mitsuba3":
        return _MitsubaRender(model, params, options, geometry, resolution, part, normal, env)
    if spec.family == "cycles" and real:
        from matremap.renderers.cycles.environment import MODELS as CYCLES_SVBRDF
        from matremap.renderers.cycles.probe import INSTALL_HINT, bpy_available

        if spec.id in CYCLES_SVBRDF:
            if geometry != "sphere":
                _cycles_fallback(model, f"the Cycles renders are of the sphere only, not the {geometry}")
            elif not bpy_available():
                _cycles_fallback(model, INSTALL_HINT)
            else:
                return _CyclesRender(model, params, options, resolution, part, normal, env)
    return _EmbeddedRender(model, params, options, geometry, resolution, part, normal)


def _irradiance_scale(source: SVMaterial, target: SVMaterial, env: EnvMap, lights: int) -> float:
    """Scale that brings source renders to the target family's irradiance units (1 in the same
    family): least-squares ratio of white Lambertian references rendered under ``env``. Cycles'
    reference is its embedded emulation, noise free and in the same units as real Cycles (5e-7 apart
    on the probe; the mean brightness of Cycles' environment renders is within 0.03 % of it)."""
    fs, ft = get_model(source.model).family, get_model(target.model).family
    if fs == ft:
        return 1.0
    d, i = directional_lights(env, lights, 0.0)
    imgs = []
    for fam in (fs, ft):
        ref = white_reference(fam)
        r = _prepare(
            ref.model,
            {k: v for k, v in ref.values.items()},
            dict(ref.options),
            "sphere",
            32,
            "full",
            None,
            env,
            real=False,
        )
        imgs.append(r.render_at(d, i, 0.0).astype(float))
    denom = float(np.sum(imgs[0] * imgs[0]))
    if not denom > 0.0:
        raise MatremapError(f"irradiance matching failed: the white reference of {fs} renders black")
    return float(np.sum(imgs[0] * imgs[1]) / denom)


# ---------------------------------------------------------------------------------------------


def evaluate(
    source: Any,
    target: Any,
    env: EnvMap,
    rotations: Sequence[float],
    out_dir: str | os.PathLike,
    geometry: str = "sphere",
    resolution: int = 256,
    force: bool = False,
    lights: int = 256,
    match_irradiance: bool = True,
    title: str | None = None,
) -> EvaluationResult:
    """Render ``source`` and ``target`` (see :meth:`SVMaterial.of`) under ``env`` at each rotation,
    full and specular only, compare them with SSIM and write PNGs, ``results.json`` and a
    self-contained ``report.html`` into ``out_dir`` (created if missing; an existing report is
    only replaced with ``force``). When the materials come from different renderer families, the
    source renders are scaled into the target's irradiance units first (``match_irradiance``)."""
    src, tgt = SVMaterial.of(source), SVMaterial.of(target)
    rotations = [float(r) for r in rotations]
    if not rotations:
        raise MatremapError("no rotations to evaluate")
    if geometry not in GEOMETRIES:
        raise MatremapError(f"unknown geometry {geometry!r}; use one of {', '.join(GEOMETRIES)}")
    if not isinstance(resolution, int) or not 16 <= resolution <= 4096:
        raise MatremapError(f"the resolution must be an integer in [16, 4096], got {resolution!r}")
    out = Path(out_dir)
    if not out.parent.exists():
        raise MatremapError(f"cannot write to {out}: folder {out.parent} does not exist")
    if out.exists() and not out.is_dir():
        raise MatremapError(f"{out} exists and is not a folder")
    report = out / "report.html"
    if report.exists() and not force:
        raise MatremapError(f"{report} already exists; pass --force to overwrite it")

    # prepare everything (validates both materials) before writing anything
    prepared = {
        (who, part): _prepare(m.model, m.params, m.options, geometry, resolution, part, m.normal, env)
        for who, m in (("source", src), ("target", tgt))
        for part in PARTS
    }
    scale = _irradiance_scale(src, tgt, env, lights) if match_irradiance else 1.0
    mask = object_mask(geometry, resolution)
    out.mkdir(exist_ok=True)
    img_dir = out / "images"
    img_dir.mkdir(exist_ok=True)

    files: list[Path] = []
    embedded: dict[str, str] = {}

    def emit(name: str, data: bytes) -> None:
        path = img_dir / name
        _write_bytes(path, data)
        files.append(path)
        embedded[name] = "data:image/png;base64," + base64.b64encode(data).decode("ascii")

    dssim = {p: [] for p in PARTS}
    dssim_img = {p: [] for p in PARTS}
    exposure: dict[str, float] = {}
    # a part whose overrides change nothing (a conductor's specular part) is the full render: reuse it
    same_as_full = {
        who: get_model(m.model).part_overrides("specular", m.params) == {}
        for who, m in (("source", src), ("target", tgt))
    }
    for k, rot in enumerate(rotations):
        d, i = directional_lights(env, lights, rot)
        drawn: dict[tuple[str, str], np.ndarray] = {}
        for part in PARTS:
            for who in ("source", "target"):
                key = (who, "full" if part == "specular" and same_as_full[who] else part)
                if key not in drawn:
                    drawn[key] = prepared[key].render_at(d, i, rot)
                drawn[(who, part)] = drawn[key]
            s_img = drawn[("source", part)]
            if scale != 1.0:
                s_img = (s_img.astype(np.float64) * scale).astype(np.float32)
            t_img = drawn[("target", part)]
            mssim, smap = ssim_map(s_img, t_img)
            dmap = 1.0 - smap
            dssim[part].append(float(dmap[mask].mean()) if mask.any() else float(1.0 - mssim))
            dssim_img[part].append(float(1.0 - mssim))
            if part not in exposure:  # one exposure per part for the whole report (the first source)
                exposure[part] = _exposure(s_img, mask)
            emit(f"r{k:03d}_{part}_source.png", _png_bytes(tonemap(s_img, exposure[part])))
            emit(f"r{k:03d}_{part}_target.png", _png_bytes(tonemap(t_img, exposure[part])))
            emit(f"r{k:03d}_{part}_dssim.png", _png_bytes(_colormap(np.where(mask, dmap, 0.0))))
    emit("dssim_vs_rotation.png", _plot(rotations, dssim["full"], dssim["specular"]))
    emit("colorbar.png", _colorbar())

    result = EvaluationResult(
        rotations=rotations,
        dssim_full=dssim["full"],
        dssim_specular=dssim["specular"],
        dssim_full_image=dssim_img["full"],
        dssim_specular_image=dssim_img["specular"],
        irradiance_scale=scale,
        out_dir=out,
        report=report,
        files=files,
    )
    info = {
        "source": _describe(src),
        "target": _describe(tgt),
        "environment": f"{env.name} ({env.width} x {env.height})",
        "geometry": f"{geometry}, {resolution} x {resolution} pixels",
        "lights": f"{lights} directional lights importance-sampled from the environment",
        "renderers": f"source: {prepared[('source', 'full')].label}, target: {prepared[('target', 'full')].label}",
        "irradiance": f"source scaled by {scale:.6g}" if scale != 1.0 else "same renderer family (no scaling)",
        "exposure": ", ".join(f"{p} x{exposure[p]:.4g}" for p in PARTS),
    }
    results_json = out / "results.json"
    with atomic_output(results_json) as tmp, open(tmp, "w") as f:
        json.dump({**result.to_dict(), "settings": info}, f, indent=2)
    files.append(results_json)
    text = _html(result, embedded, info, title or f"matremap evaluation: {src.model} \u2192 {tgt.model}")
    with atomic_output(report) as tmp, open(tmp, "w", encoding="utf-8") as f:
        f.write(text)
    return result


def _describe(m: SVMaterial) -> str:
    parts = []
    for name, v in m.params.items():
        a = np.asarray(v)
        parts.append(f"{name}=map {a.shape[1]}x{a.shape[0]}" if a.ndim >= 2 else f"{name}={np.round(a, 4).tolist()}")
    parts += [f"{k}={v}" for k, v in m.options.items()]
    if m.normal is not None:
        parts.append(f"normal map {np.asarray(m.normal).shape[1]}x{np.asarray(m.normal).shape[0]}")
    return f"{m.model}" + (f" ({', '.join(parts)})" if parts else "")


_CSS = """
body { font-family: system-ui, sans-serif; margin: 1.5em; color: #222; background: #fff; }
h1 { font-size: 1.4em; } h2 { font-size: 1.15em; margin-top: 1.6em; }
table { border-collapse: collapse; margin: 0.5em 0; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: right; }
th { background: #f3f3f3; } td.l, th.l { text-align: left; }
figure { display: inline-block; margin: 0.2em; text-align: center; }
figure img { display: block; width: 160px; height: 160px; image-rendering: pixelated; background: #000; }
figcaption { font-size: 0.8em; color: #555; }
.row { margin-bottom: 0.6em; } .row h3 { font-size: 0.95em; margin: 0.4em 0; }
img.plot { max-width: 100%; }
"""

# counts the images that decoded (for people and for the headless-browser test)
_SCRIPT = """
window.addEventListener('load', function () {
  var imgs = document.images, ok = 0;
  for (var i = 0; i < imgs.length; i++) { if (imgs[i].complete && imgs[i].naturalWidth > 0) ok++; }
  document.body.setAttribute('data-images-loaded', ok + '/' + imgs.length);
});
"""


def _html(result: EvaluationResult, images: Mapping[str, str], info: Mapping[str, str], title: str) -> str:
    e = html.escape

    def img(name: str, alt: str, cls: str = "") -> str:
        c = f' class="{cls}"' if cls else ""
        return f'<img{c} src="{images[name]}" alt="{e(alt)}">'

    rows = []
    for k, (rot, f, s, fi, si) in enumerate(
        zip(
            result.rotations,
            result.dssim_full,
            result.dssim_specular,
            result.dssim_full_image,
            result.dssim_specular_image,
            strict=True,
        )
    ):
        rows.append(
            f"<tr><td>{k}</td><td>{rot:g}</td><td>{f:.5f}</td><td>{s:.5f}</td><td>{fi:.5f}</td><td>{si:.5f}</td></tr>"
        )
    settings = "".join(f'<tr><th class="l">{e(k)}</th><td class="l">{e(v)}</td></tr>' for k, v in info.items())
    figures = []
    for k, rot in enumerate(result.rotations):
        cells = []
        for part in PARTS:
            for what, label in (("source", "source"), ("target", "target"), ("dssim", "1 \u2212 SSIM")):
                name = f"r{k:03d}_{part}_{what}.png"
                cap = f"{label}, {part}"
                cells.append(
                    f"<figure>{img(name, f'{cap}, rotation {rot:g}')}<figcaption>{e(cap)}</figcaption></figure>"
                )
        figures.append(
            f'<div class="row"><h3>rotation {rot:g}\u00b0 \u2014 1 \u2212 SSIM full {result.dssim_full[k]:.4f}, '
            f"specular {result.dssim_specular[k]:.4f}</h3>{''.join(cells)}</div>"
        )
    return f"""<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>{e(title)}</title>
<style>{_CSS}</style>
</head>
<body>
<h1>{e(title)}</h1>
<table>{settings}</table>
<h2>Mean 1 &minus; SSIM</h2>
<p>SSIM (scikit-image, 7&times;7 window, on linear HDR renders, data range of the source render) between
the source and the target under the environment turned about the vertical axis. Per rotation: the mean of
1&nbsp;&minus;&nbsp;SSIM over the object's pixels, and over the whole image (background included).
Lower is better; 0 means identical.</p>
<table>
<tr><th>#</th><th>rotation (&deg;)</th><th>full</th><th>specular only</th><th>full, whole image</th>
<th>specular, whole image</th></tr>
{"".join(rows)}
<tr><th class="l" colspan="2">mean</th><th>{result.mean_full:.5f}</th><th>{result.mean_specular:.5f}</th>
<th>{float(np.mean(result.dssim_full_image)):.5f}</th><th>{float(np.mean(result.dssim_specular_image)):.5f}</th></tr>
</table>
<h2>1 &minus; SSIM against rotation</h2>
{img("dssim_vs_rotation.png", "mean 1 - SSIM against environment rotation", "plot")}
<h2>Renders and SSIM maps</h2>
<p>Renders are tone-mapped to sRGB with one exposure per part (source and target alike); the
1&nbsp;&minus;&nbsp;SSIM maps use this scale, from 0 to {SSIM_MAP_MAX:g}:<br>
{img("colorbar.png", "colour scale of the 1 - SSIM maps")}</p>
{"".join(figures)}
<script>{_SCRIPT}</script>
</body>
</html>
"""
