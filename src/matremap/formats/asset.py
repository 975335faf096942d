"""A material read from a file (glTF, MaterialX, Mitsuba XML): a model, constants and textures.

Readers (one module per format) turn a file into a :class:`MaterialAsset`: the matremap model it
speaks, its uniform parameter values in that model's units, and the textures that drive parameters
(a file, the channels to take from it, its colour space, the factor the format multiplies it by).
:meth:`MaterialAsset.to_map_set` turns the textured parameters into a plain map set (one file per
parameter, a ``material.json``) that the rest of matremap converts and evaluates; a uniform asset
is a :class:`~matremap.core.material.Material`.
"""

from __future__ import annotations

import json
import os
import shutil
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from matremap.core.material import Material
from matremap.dialects import get_model
from matremap.errors import MatremapError

if TYPE_CHECKING:
    from matremap.core.models import ParamSpec


@dataclass(frozen=True)
class TextureRef:
    """A texture driving one parameter.

    ``channels``: the image channels to take (``(2,)`` for the blue channel of a packed map), or
    None for all; ``colorspace``: how the file's values are encoded ("srgb" or "linear");
    ``scale``: a factor (scalar or RGB) the format multiplies the texture by (glTF's factors);
    ``extracted``: the file is matremap's own copy in its cache (an image stored inside a .glb or a
    ``data:`` URI), not a file of the asset, so a map set copies it instead of pointing at it;
    ``bake``: when the renderer does not sample ``path`` as it is stored (a texture transform, a wrap
    mode, a node graph or a procedural texture), a callable returning what it sees at each texel of
    the map, as linear float32 ``[H, W, C]`` before ``channels`` and ``scale`` are applied (see
    :mod:`matremap.formats.bake`); ``path`` is then the file the values come from (or the document,
    for a procedural texture), for messages and cache keys.
    """

    path: Path
    channels: tuple[int, ...] | None = None
    colorspace: str = "linear"
    scale: float | tuple[float, ...] = 1.0
    extracted: bool = False
    bake: Callable[[], np.ndarray] | None = field(default=None, compare=False)

    @property
    def plain_factor(self) -> bool:
        """Whether the format's factor leaves the texture as it is."""
        return bool(np.all(np.asarray(self.scale, dtype=float) == 1.0))

    @property
    def plain(self) -> bool:
        """Whether the file can be used as the map itself (all channels, no factor, not baked)."""
        return self.channels is None and self.plain_factor and self.bake is None


@dataclass(frozen=True)
class CarriedInput:
    """An input no model remaps but a writer can carry into the target file as it is.

    Readers fill :attr:`MaterialAsset.carried` under these keys (linear values, the format's factor
    already in ``value``):

    * ``"emission"``: ``value`` the emitted radiance colour (RGB, strength multiplied in), ``texture``
      an RGB texture it multiplies;
    * ``"occlusion"``: ``texture`` an ambient-occlusion map (its first channel, or ``channels``),
      ``value`` its strength;
    * ``"opacity"``: ``value`` the opacity factor in [0, 1], ``texture`` a texture it multiplies (the
      alpha channel of a base-colour texture names it in ``channels``); ``settings`` ``mode``
      (``"blend"`` or ``"mask"``) and ``cutoff`` (for mask);

    ``settings`` holds whatever else the format says of it. A writer whose format has the slot writes
    it; one that has not adds a note naming what was left behind.
    """

    value: float | tuple[float, ...] | None = None
    texture: TextureRef | None = None
    settings: Mapping[str, Any] = field(default_factory=dict)


#: a surface showing at least this share of its textures counts as showing them all
FULL_COVERAGE = 0.98
#: maps up to this many texels are filled where the surface does not show them (read whole: 16M texels)
FILL_TEXELS = 4096 * 4096


@dataclass
class MaterialAsset:
    """One material of a file, in a matremap model's terms.

        ``constants``: parameter values and options (model units); a parameter named in ``textures``
        is textured and its constant, if any, is ignored. ``document`` keeps whatever the reader parsed,
        for writers that copy the input with a new material. ``notes`` are the reader's decisions and
        the inputs it skipped, for the user to see. ``carried``: inputs passed on unchanged to a writer
    (emission, occlusion, opacity: :class:`CarriedInput`). ``lost``: inputs that carry the look and that no
        matremap model has (a coloured coat, transmission, sheen): such a material is copied onto its own
        model but not converted to another (see :func:`matremap.remap.remap_file`). ``dropped``: inputs that
        change the look and that no model here converts (an anisotropy, a subsurface, a thin film), as
        ``name=value``: the rest is converted, and the quality gate's ``dropped`` check fails it, naming them,
        unless the file is copied onto its own format with them (:func:`matremap.remap.dropped_check`).
    """

    path: Path
    format: str
    name: str
    model: str
    constants: dict[str, Any] = field(default_factory=dict)
    textures: dict[str, TextureRef] = field(default_factory=dict)
    normal: TextureRef | None = None
    notes: list[str] = field(default_factory=list)
    document: Any = None
    index: int = 0
    lost: list[str] = field(default_factory=list)
    carried: dict[str, CarriedInput] = field(default_factory=dict)
    dropped: list[str] = field(default_factory=list)
    #: the texels the material's surface shows (the UV triangles of the glTF primitives or USD faces drawn with it:
    #: :class:`~matremap.formats.uv_coverage.Coverage`, its ``mask(size)``), None where every texel counts
    coverage: Any = None

    @property
    def textured(self) -> bool:
        return bool(self.textures)

    def material(self) -> Material:
        """The asset as a uniform material (its textures, if any, are not included)."""
        spec = get_model(self.model)
        known = set(spec.param_names) | set(spec.option_names)
        return Material.create(spec.id, {k: v for k, v in self.constants.items() if k in known})

    def to_map_set(self, workdir: str | os.PathLike) -> Path:
        """Write the textured parameters as a map set in ``workdir`` (one image per parameter,
        channels picked and factors multiplied in, a ``material.json``); returns the folder.

        A texture of the asset used as it is (all channels, factor 1) is referenced where it lies, not
        copied; one matremap extracted into its cache is copied into ``workdir``, so that the manifest
        never points into the cache.
        """
        if not self.textures:
            raise MatremapError(f"{self.path}: material {self.name!r} has no textures; use it as a uniform material")
        spec = get_model(self.model)
        out = Path(workdir)
        out.mkdir(parents=True, exist_ok=True)
        maps: dict[str, str] = {}
        colorspace: dict[str, str] = {}
        sizes: dict[str, tuple[int, int]] = {}
        for name, ref in self.textures.items():
            maps[name], colorspace[name], sizes[name] = self._map_file(spec.param(name), ref, out)
        if len(set(sizes.values())) > 1:
            detail = ", ".join(f"{k} {w}x{h}" for k, (h, w) in sizes.items())
            raise MatremapError(
                f"{self.path}: material {self.name!r} has textures of different sizes ({detail}); "
                f"resize them to one size"
            )
        manifest: dict[str, Any] = {
            "model": spec.id,
            "maps": maps,
            "params": {k: _jsonable(v) for k, v in self.constants.items() if k not in self.textures},
            "colorspace": colorspace,
            "provenance": {"file": str(self.path), "material": self.name, "format": self.format},
        }
        if self.normal is not None:
            manifest["normal"] = self._kept_file(self.normal, "normal", out)
        if self.coverage is not None and sizes:
            self._fill_uncovered(spec, out, maps, colorspace, next(iter(sizes.values())))
        (out / "material.json").write_text(json.dumps(manifest, indent=1))
        return out

    def _fill_uncovered(
        self, spec: Any, out: Path, maps: dict[str, str], colorspace: dict[str, str], size: tuple[int, int]
    ) -> None:
        """Rewrite ``maps`` (the manifest's files, in ``out``) with the texels the surface does not show
        (:attr:`coverage`) filled from the nearest it shows, and say so in :attr:`notes`: what no triangle shows
        then neither decides a conversion (the typical texel, the ranges swept, metal and dielectric shares) nor
        fails its checks. Skipped where the surface shows nearly all of them, and past :data:`FILL_TEXELS`."""
        from matremap.formats.uv_coverage import covered_share, fill_uncovered
        from matremap.svbrdf.textures import ImageInfo, read_image, write_image_like

        mask = self.coverage.mask(size)
        share = covered_share(mask)
        if mask is None or share >= FULL_COVERAGE:
            return
        if size[0] * size[1] > FILL_TEXELS:
            self.notes.append(
                f"the material's triangles show {100 * share:.0f}% of its {size[1]}x{size[0]} textures; maps this "
                "large are read whole (what no triangle shows counts too)"
            )
            return
        for name, f in list(maps.items()):
            path = Path(f) if Path(f).is_absolute() else out / f
            p = spec.param(name)
            image, _ = read_image(path, colorspace[name], colour=p.channels == 3 and p.role != "other")
            filled = fill_uncovered(image, mask)
            fname = f"{name.replace(' ', '_')}_shown.exr"
            h, w, c = filled.shape
            write_image_like(out / fname, filled, ImageInfo("exr", "float", c, w, h, "linear"), force=True)
            maps[name], colorspace[name] = fname, "linear"
        self.notes.append(
            f"the material's triangles show {100 * share:.0f}% of its textures (an atlas shared with other materials, "
            "or unused space): the texels they do not show are filled from the nearest they show, so that only what "
            "the surface shows decides the conversion and its checks"
        )

    def normal_file(self, workdir: str | os.PathLike) -> Path | None:
        """The asset's normal map as a file a writer can use: the texture itself, or (extracted or baked)
        a copy written into ``workdir``; None without one."""
        if self.normal is None:
            return None
        out = Path(workdir)
        out.mkdir(parents=True, exist_ok=True)
        return out / self._kept_file(self.normal, "normal", out)

    def _map_file(self, p: ParamSpec, ref: TextureRef, out: Path) -> tuple[str, str, tuple[int, int]]:
        """(the manifest's file, its colour space, (height, width)) of the map of parameter ``p``:
        the texture's own file when it can be used as it is, else its values (channels picked, the
        factor multiplied in, clipped to the parameter's bounds) written to ``out`` as linear EXR (a file
        band by band: memory does not grow with its size)."""
        from matremap.svbrdf.textures import ImageInfo, image_info, transform_image, write_image_like

        name = p.name
        fname = f"{name.replace(' ', '_')}.exr"
        if ref.bake is None and not ref.path.is_file():
            raise MatremapError(
                f"{self.path}: texture {ref.path} for {name} not found; put it beside the file or fix its uri"
            )
        if ref.bake is None:
            header = image_info(ref.path, ref.colorspace, colour=False)
            whole = ref.channels is None or tuple(ref.channels) == tuple(range(header.channels))
            if ref.plain_factor and whole and (p.channels == 3 or header.channels == 1):
                return self._kept_file(ref, name, out), ref.colorspace, (header.height, header.width)
            size = transform_image(ref.path, ref.colorspace, out / fname, lambda band: self._factored(p, ref, band))
            return fname, "linear", size
        image = np.asarray(ref.bake(), dtype=np.float32)
        if not np.all(np.isfinite(image)):
            raise MatremapError(f"{self.path}: the texture baked for {name} has non-finite values")
        image = self._factored(p, ref, np.atleast_3d(image))
        h, w, c = image.shape
        write_image_like(out / fname, image, ImageInfo("exr", "float", c, w, h, "linear"), force=True)
        return fname, "linear", image.shape[:2]

    def _factored(self, p: ParamSpec, ref: TextureRef, image: np.ndarray) -> np.ndarray:
        """The values of ``p`` in ``image`` ([H, W, C], or a band of rows): channels picked, the factor
        multiplied in, clipped to the parameter's bounds."""
        name = p.name
        image = self._picked_channels(p, ref, image)
        scale = np.asarray(ref.scale, dtype=np.float32).reshape(-1)
        if scale.size not in (1, image.shape[-1]):  # an RGB factor on picked channels: their factors
            if ref.channels is None or max(ref.channels) >= scale.size:
                raise MatremapError(
                    f"{self.path}: {name}: a factor of {scale.size} values does not fit a "
                    f"texture of {image.shape[-1]} channel(s)"
                )
            scale = scale[list(ref.channels)]
        return np.clip((image * scale).astype(np.float32), *p.bounds)

    @staticmethod
    def _kept_file(ref: TextureRef, name: str, out: Path) -> str:
        """The manifest's entry for a texture used as it is: its own file (absolute), or, for a copy
        matremap extracted into its cache, a copy of it in ``out`` (relative); a baked one (a
        transformed normal map) is written to ``out`` as linear EXR of its code values."""
        if ref.bake is not None:
            from matremap.svbrdf.textures import ImageInfo, write_image_like

            image = np.atleast_3d(np.asarray(ref.bake(), dtype=np.float32))
            fname = f"{name.replace(' ', '_')}.exr"
            h, w, c = image.shape
            write_image_like(out / fname, image, ImageInfo("exr", "float", c, w, h, "linear"), force=True)
            return fname
        if not ref.extracted:
            return str(ref.path.resolve())
        fname = f"{name.replace(' ', '_')}{ref.path.suffix.lower()}"
        shutil.copyfile(ref.path, out / fname)
        return fname

    @staticmethod
    def _picked_channels(p: ParamSpec, ref: TextureRef, image: np.ndarray) -> np.ndarray:
        """The channels of ``image`` that drive ``p``: those ``ref`` names, else as many as ``p`` has."""
        if ref.channels is not None:
            if max(ref.channels) >= image.shape[-1]:
                raise MatremapError(
                    f"{ref.path}: has {image.shape[-1]} channel(s); {p.name} needs channel {max(ref.channels)}"
                )
            return image[..., list(ref.channels)]
        if p.channels == 1:
            return image[..., :1]
        if image.shape[-1] == 1:
            return np.repeat(image, 3, axis=-1)
        if image.shape[-1] > 3:
            return image[..., :3]
        return image


def _jsonable(v: Any) -> Any:
    if isinstance(v, np.ndarray):
        return v.tolist() if v.size > 1 else float(v.reshape(-1)[0])
    if isinstance(v, Mapping):
        return {k: _jsonable(x) for k, x in v.items()}
    return v
