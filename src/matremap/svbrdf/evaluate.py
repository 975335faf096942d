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
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from matremap.core.calibrate import irradiance_ratio, same_units
from matremap.core.envmap import EnvMap
from matremap.core.imageio import atomic_output, linear_to_srgb
from matremap.core.material import SVMaterial, white_reference
from matremap.dialects import get_model
from matremap.errors import MatremapError
from matremap.renderers.base import EnvironmentLight, EnvironmentRender, check_environment_args
from matremap.renderers.registry import environment_renderer_for
from matremap.renderers.textured import object_mask
from matremap.svbrdf.gloss import View, gloss_checks
from matremap.svbrdf.quality import Check, Thresholds, Verdict, image_checks

PARTS = ("full", "specular")

#: 1 - SSIM colour maps span [0, SSIM_MAP_MAX]
SSIM_MAP_MAX = 1.0


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
    #: the quality gate: the image measures, 1 - SSIM and any checks the caller added
    verdict: Verdict = field(default_factory=Verdict)

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
            # beside results.json: a relative name stays true when the folder moves (from staging into OUT)
            "report": self.report.name,
            "verdict": self.verdict.to_dict(),
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


#: the report shows the outside-domain map at most this many texels a side
DOMAIN_MAP_SIDE = 1024


def _domain_png(path: Path) -> bytes:
    """The outside-domain map for the report: the file as it is, or, when it is larger than
    :data:`DOMAIN_MAP_SIDE`, a block white wherever one of its texels is (read in bands)."""
    from matremap.svbrdf.textures import MapReader

    with MapReader(path, "linear", colour=False) as r:
        h, w = r.info.height, r.info.width
        k = math.ceil(max(h, w) / DOMAIN_MAP_SIDE)
        if k == 1:
            return path.read_bytes()
        rows: list[np.ndarray] = []
        step = k * max(1, (1 << 20) // (w * k))
        for y0 in range(0, h, step):
            band = r.read_rows(y0, min(h, y0 + step))[..., 0] > 0.5
            pad = (-band.shape[0] % k, -w % k)
            band = np.pad(band, ((0, pad[0]), (0, pad[1])))
            rows.append(np.asarray(band.reshape(band.shape[0] // k, k, -1, k).any(axis=(1, 3))))
    return _png_bytes(np.where(np.concatenate(rows), 255, 0).astype(np.uint8)[..., None])


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


def prepare(
    material: SVMaterial, light: EnvironmentLight, geometry: str, resolution: int, part: str, real: bool = True
) -> EnvironmentRender:
    """``material`` prepared for environment renders by the renderer that draws it
    (:func:`~matremap.renderers.registry.environment_renderer_for`: its real renderer where it can, else
    the embedded emulation with a warning; ``real=False`` asks for the emulation outright)."""
    renderer = environment_renderer_for(material.model, geometry, real=real)
    return renderer.prepare_environment(material, light, geometry, resolution, part)


def highlight_part(material: SVMaterial) -> str:
    """The render a material's highlight image is made from (:mod:`matremap.svbrdf.gloss`): its specular-only part;
    for a model without one, its diffuse-only part (taken from the full render); the full render of a model
    without a diffuse part."""
    model = get_model(material.model)
    if model.part_overrides("specular", material.params) is not None:
        return "specular"
    if model.part_overrides("diffuse", material.params) is not None:
        return "diffuse"
    return "full"


def highlight_image(full: np.ndarray, part: np.ndarray, kind: str) -> np.ndarray:
    """The highlight image of a view from its full render and the ``kind`` of part :func:`highlight_part` chose."""
    if kind == "diffuse":
        return np.maximum(np.asarray(full, dtype=np.float32) - np.asarray(part, dtype=np.float32), 0.0)
    return np.asarray(part)


def irradiance_scale_under(light: EnvironmentLight, source_model: str, target_model: str) -> float:
    """Scale that brings source renders to the target's irradiance units under ``light`` (1 when they
    share a renderer family, :func:`~matremap.core.calibrate.same_units`): least-squares ratio of the
    white Lambertian references drawn by the embedded renderer, noise free and in each family's units
    (the mean brightness of Cycles' environment renders is within 0.03 % of its emulation's), both under the
    directional lights alone (a Lambertian needs no mirror samples; both references then see the same light)."""
    if same_units(source_model, target_model):
        return 1.0
    light = replace(light, mirror_samples=0)
    families = [get_model(m).family for m in (source_model, target_model)]
    images = []
    for family in families:
        ref = white_reference(family)
        white = SVMaterial(ref.model, dict(ref.values), dict(ref.options))
        images.append(prepare(white, light, "sphere", 32, "full", real=False).render(0.0))
    return irradiance_ratio(images[0], images[1], families[0])


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
    thresholds: Thresholds | None = None,
    checks: Sequence[Check] = (),
    domain_map: Path | None = None,
    notes: Mapping[str, str] | None = None,
) -> EvaluationResult:
    """Render ``source`` and ``target`` (see :meth:`SVMaterial.of`) under ``env`` at each rotation,
    full and specular only, compare them with SSIM and write PNGs, ``results.json`` and a
    self-contained ``report.html`` into ``out_dir`` (created if missing; an existing report is
    only replaced with ``force``). When the materials come from different renderer families, the
    source renders are scaled into the target's irradiance units first (``match_irradiance``).

    The result carries a :class:`~matremap.svbrdf.quality.Verdict`: ``checks`` the caller measured (e.g.
    on the maps), the full renders' luminance and CIEDE2000 measures and the mean 1 - SSIM, each against
    ``thresholds`` (default :class:`~matremap.svbrdf.quality.Thresholds`); the report opens with it.
    ``domain_map``: a PNG marking the texels outside the transform's training domain, shown in the report.
    ``notes``: more rows for the report's settings table (e.g. the light the transform was fitted under)."""
    src, tgt = SVMaterial.of(source), SVMaterial.of(target)
    rotations = [float(r) for r in rotations]
    if not rotations:
        raise MatremapError("no rotations to evaluate")
    check_environment_args(geometry, resolution, "full")
    out = _check_out_dir(Path(out_dir), force)
    light = EnvironmentLight(env, lights)
    # prepare everything (validates both materials) before writing anything
    materials = {"source": src, "target": tgt}
    kinds = {who: highlight_part(m) for who, m in materials.items()}
    needed = {(who, part) for who in materials for part in ("full", kinds[who])}
    prepared = {key: prepare(materials[key[0]], light, geometry, resolution, key[1]) for key in sorted(needed)}
    scale = irradiance_scale_under(light, src.model, tgt.model) if match_irradiance else 1.0
    mask = object_mask(geometry, resolution)
    images = _ReportImages(out / "images")
    comparison = _Comparison(mask, scale)
    from tqdm import tqdm  # a real renderer takes seconds per view: say how far it is (on a terminal)

    views = tqdm(rotations, desc="evaluate", unit="rotation", disable=None, leave=False)
    for k, rot in enumerate(views):
        drawn = {key: prepared[key].render(rot) for key in sorted(needed)}
        full = {who: drawn[(who, "full")] for who in materials}
        shown = {who: highlight_image(full[who], drawn[(who, kinds[who])], kinds[who]) for who in materials}
        comparison.add(k, "full", full["source"], full["target"], images)
        comparison.add(k, "specular", shown["source"], shown["target"], images)
    images.emit("dssim_vs_rotation.png", _plot(rotations, comparison.dssim["full"], comparison.dssim["specular"]))
    verdict = comparison.verdict(checks, thresholds or Thresholds())
    images.emit("colorbar.png", _colorbar())
    if domain_map is not None and domain_map.is_file():
        images.emit("outside_domain.png", _domain_png(domain_map))

    result = EvaluationResult(
        rotations=rotations,
        dssim_full=comparison.dssim["full"],
        dssim_specular=comparison.dssim["specular"],
        dssim_full_image=comparison.dssim_image["full"],
        dssim_specular_image=comparison.dssim_image["specular"],
        irradiance_scale=scale,
        out_dir=out,
        report=out / "report.html",
        files=images.files,
        verdict=verdict,
    )
    info = _settings(src, tgt, env, geometry, resolution, lights, prepared, scale, comparison.exposure)
    info.update(notes or {})
    _write_results(result, info, images, title or f"matremap evaluation: {src.model} \u2192 {tgt.model}")
    return result


def _settings(
    src: SVMaterial,
    tgt: SVMaterial,
    env: EnvMap,
    geometry: str,
    resolution: int,
    lights: int,
    prepared: Mapping[tuple[str, str], EnvironmentRender],
    scale: float,
    exposure: Mapping[str, float],
) -> dict[str, str]:
    """The report's settings table (also in results.json)."""
    return {
        "source": _describe(src),
        "target": _describe(tgt),
        "environment": f"{env.name} ({env.width} x {env.height})",
        "geometry": f"{geometry}, {resolution} x {resolution} pixels",
        "lights": (
            f"{lights} directional lights importance-sampled from the environment (embedded renderer), and "
            f"{EnvironmentLight.mirror_samples} samples about each pixel's mirror direction"
        ),
        "renderers": f"source: {prepared[('source', 'full')].label}, target: {prepared[('target', 'full')].label}",
        "irradiance": f"source scaled by {scale:.6g}" if scale != 1.0 else "same renderer family (no scaling)",
        "exposure": ", ".join(f"{p} x{exposure[p]:.4g}" for p in PARTS),
    }


def _check_out_dir(out: Path, force: bool) -> Path:
    """The evaluation folder, checked before anything renders."""
    if not out.parent.exists():
        raise MatremapError(f"cannot write to {out}: folder {out.parent} does not exist")
    if out.exists() and not out.is_dir():
        raise MatremapError(f"{out} exists and is not a folder")
    if (out / "report.html").exists() and not force:
        raise MatremapError(f"{out / 'report.html'} already exists; pass --force to overwrite it")
    return out


class _ReportImages:
    """The report's PNGs: written to a folder and kept as data URIs for the self-contained HTML."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self.files: list[Path] = []
        self.embedded: dict[str, str] = {}

    def emit(self, name: str, data: bytes) -> None:
        self.folder.mkdir(parents=True, exist_ok=True)
        path = self.folder / name
        _write_bytes(path, data)
        self.files.append(path)
        self.embedded[name] = "data:image/png;base64," + base64.b64encode(data).decode("ascii")


class _Comparison:
    """SSIM of source and target renders per part and rotation, and the pictures of each."""

    def __init__(self, mask: np.ndarray, scale: float) -> None:
        self.mask, self.scale = mask, scale
        self.dssim: dict[str, list[float]] = {p: [] for p in PARTS}
        self.dssim_image: dict[str, list[float]] = {p: [] for p in PARTS}
        self.exposure: dict[str, float] = {}
        #: (where, source, target) of the full renders, for the colour and energy measures
        self.full_pairs: list[tuple[str, np.ndarray, np.ndarray]] = []
        #: the highlight images of each view (:func:`highlight_image`), source and target
        self.highlights: list[tuple[np.ndarray, np.ndarray]] = []

    def verdict(self, checks: Sequence[Check], limits: Thresholds) -> Verdict:
        """The gate: the caller's checks, the full renders' colour and energy, the highlights and HDR-FLIP, and the
        mean 1 - SSIM."""
        return Verdict([*checks, *self.checks(limits)])

    def checks(self, limits: Thresholds) -> list[Check]:
        """The image measures of the gate (without the caller's)."""
        dssim = Check("dssim", float(np.mean(self.dssim["full"])), limits.dssim, "mean over rotations")
        views = [
            View(where, s, t, hs, ht) for (where, s, t), (hs, ht) in zip(self.full_pairs, self.highlights, strict=True)
        ]
        return [*image_checks(self.full_pairs, self.mask, limits), *gloss_checks(views, self.mask, limits), dssim]

    def add(self, k: int, part: str, s_img: np.ndarray, t_img: np.ndarray, images: _ReportImages) -> None:
        if self.scale != 1.0:
            s_img = (s_img.astype(np.float64) * self.scale).astype(np.float32)
        mssim, smap = ssim_map(s_img, t_img)
        dmap = 1.0 - smap
        if part == "full":
            self.full_pairs.append((f"full render, rotation {k}", s_img, t_img))
        else:
            self.highlights.append((s_img, t_img))
        mask = self.mask
        self.dssim[part].append(float(dmap[mask].mean()) if mask.any() else float(1.0 - mssim))
        self.dssim_image[part].append(float(1.0 - mssim))
        if part not in self.exposure:  # one exposure per part for the whole report (the first source)
            self.exposure[part] = _exposure(s_img, mask)
        images.emit(f"r{k:03d}_{part}_source.png", _png_bytes(tonemap(s_img, self.exposure[part])))
        images.emit(f"r{k:03d}_{part}_target.png", _png_bytes(tonemap(t_img, self.exposure[part])))
        images.emit(f"r{k:03d}_{part}_dssim.png", _png_bytes(_colormap(np.where(mask, dmap, 0.0))))


def _write_results(result: EvaluationResult, info: Mapping[str, str], images: _ReportImages, title: str) -> None:
    results_json = result.out_dir / "results.json"
    with atomic_output(results_json) as tmp, open(tmp, "w") as f:
        json.dump({**result.to_dict(), "settings": dict(info)}, f, indent=2)
    result.files.append(results_json)
    text = _html(result, images.embedded, info, title)
    with atomic_output(result.report) as tmp, open(tmp, "w", encoding="utf-8") as f:
        f.write(text)


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
.verdict { padding: 0.4em 1em; margin: 0.8em 0; border-left: 6px solid; }
.verdict.passed { border-color: #2a7; background: #effaf3; }
.verdict.failed { border-color: #c33; background: #fdeeee; }
tr.bad td { color: #b00; font-weight: bold; }
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


def _domain_html(images: Mapping[str, str], e: Any) -> str:
    """The per-texel map of texels outside the training domain (white), when there is one."""
    if "outside_domain.png" not in images:
        return ""
    return (
        "<h2>Texels outside the training domain</h2><p>White texels lie outside what the transform was "
        f'learned on.</p><img class="plot" src="{images["outside_domain.png"]}" alt="{e("texels outside the domain")}">'
    )


def _verdict_html(verdict: Verdict) -> str:
    """The quality gate at the top of the report: PASSED or FAILED and every measure."""
    e = html.escape
    cls = "passed" if verdict.passed else "failed"
    rows = "".join(
        f'<tr class="{"ok" if c.passed else "bad"}"><td class="l">{e(c.name)}</td><td>{c.value:.4g}</td>'
        f'<td>{c.threshold:.4g}</td><td class="l">{e(c.where)}</td></tr>'
        for c in verdict.checks
    )
    return (
        f'<div class="verdict {cls}"><p><b>{e(verdict.line())}</b></p>'
        f"<table><tr><th>measure</th><th>value</th><th>threshold</th><th>where</th></tr>{rows}</table></div>"
    )


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
{_verdict_html(result.verdict)}
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
{_domain_html(images, e)}
<h2>Renders and SSIM maps</h2>
<p>Renders are tone-mapped to sRGB with one exposure per part (source and target alike); the
1&nbsp;&minus;&nbsp;SSIM maps use this scale, from 0 to {SSIM_MAP_MAX:g}:<br>
{img("colorbar.png", "colour scale of the 1 - SSIM maps")}</p>
{"".join(figures)}
<script>{_SCRIPT}</script>
</body>
</html>
"""
