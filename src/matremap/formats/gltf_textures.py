"""glTF textures as the renderer samples them: samplers' wrap modes, KHR_texture_transform, UV sets.

References: glTF 2.0 (Khronos, 2.0.1) §3.8.4 "Samplers" (``wrapS`` / ``wrapT``: 10497 REPEAT, the default,
33648 MIRRORED_REPEAT, 33071 CLAMP_TO_EDGE; UV origin at the top left of the image, §3.8.4.2),
§3.9.3 "Additional Textures" (the normal texture is in tangent space, +X right and +Y up in the image),
§5.29 ``textureInfo.texCoord`` (the UV set ``TEXCOORD_<n>``); the KHR_texture_transform README (ratified):
``offset``, ``rotation`` and ``scale`` turn the UV at which a surface is shaded into the UV at which the
image is read, ``uv' = T * R * S * uv``; its ``texCoord`` overrides the textureInfo's.

The rotation's direction: "rotate the UVs by this many radians counter-clockwise around the origin. This
is equivalent to a similar rotation of the image clockwise" -- with the image's ``v`` pointing down, the
lookup's linear part is ``[[cos r, sin r], [-sin r, cos r]]`` (row-major). That is what the README's
example means ("offset [0, 1], rotation pi/2, scale 0.5: the lower left quadrant of the image, rotated
clockwise 90 degrees") and what Khronos' TextureTransformTest reference renders (its "Rotation" quad's
arrow ends on the green marker, not on the red "opposite direction" one); it is :func:`bake.rotate`
of ``-r``.

A map set has one UV set and no transforms, so a texture read through a transform (or a wrap mode that
the transform makes matter) is *baked*: :class:`~matremap.formats.asset.TextureRef.bake` returns the
image as the renderer sees it at each texel of ``[0, 1]^2`` of its UV set (:mod:`matremap.formats.bake`,
bilinear, wrap modes honoured, sRGB decoded before filtering). A transformed normal map is also
*turned*: its stored x and y are tangent-space components along the image's axes, which the transform
turns against the mesh's tangent frame (the frame follows the untransformed UVs: glTF §3.7.2.1 TANGENT,
"XYZ vertex tangents" of TEXCOORD_0's u direction), so the baked normal is expressed in the untransformed
frame: ``xy_mesh = F N(A^-1) F xy`` with ``A`` the transform's linear part, ``N`` normalising its
columns (the tangent and bitangent of the transformed UVs, as renderers that derive the frame from the
UVs' derivatives use them) and ``F = diag(1, -1)`` for the +Y-up storage.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from matremap.core.imageio import oiio_name, srgb_to_linear
from matremap.errors import MatremapError
from matremap.formats.bake import UVTransform, bake_file, rotate, scale, texels_needed, translate
from matremap.formats.gltf_container import is_index

TRANSFORM = "KHR_texture_transform"
#: sampler wrap enums (§3.8.4, §5.26) -> matremap.formats.bake's wrap modes
WRAP_MODES = {10497: "repeat", 33648: "mirror", 33071: "clamp"}


def as_dict(value: Any) -> dict[str, Any]:
    """A JSON value that should be an object, or {} when it is not one."""
    return value if isinstance(value, dict) else {}


def finite_numbers(value: Any, size: int) -> list[float] | None:
    """``value`` as ``size`` finite floats (a number when ``size`` is 1), or None when it is not that."""
    vals = value if isinstance(value, list) else [value]
    if len(vals) != size or not all(
        isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in vals
    ):
        return None
    return [float(v) for v in vals]


def transform_matrix(path: Path, where: str, ext: Any) -> tuple[np.ndarray | None, int | None]:
    """The lookup matrix of a KHR_texture_transform object (None when it is the identity) and its
    ``texCoord`` override (None when absent); malformed values are refused naming ``where``."""
    if not isinstance(ext, dict):
        raise MatremapError(f"{path}: {where}.{TRANSFORM} is not an object; fix the file")
    got: dict[str, list[float]] = {}
    for key, size, default in (("offset", 2, [0.0, 0.0]), ("rotation", 1, [0.0]), ("scale", 2, [1.0, 1.0])):
        value = finite_numbers(ext[key], size) if key in ext else default
        if value is None:
            what = "a number" if size == 1 else f"{size} numbers"
            raise MatremapError(f"{path}: {where}.{TRANSFORM}.{key} must be {what}, got {ext[key]!r}; fix the file")
        got[key] = value
    uv = ext.get("texCoord")
    if uv is not None and not is_index(uv):
        raise MatremapError(f"{path}: {where}.{TRANSFORM}.texCoord must be a UV set index, got {uv!r}; fix the file")
    m = translate(*got["offset"]) @ rotate(-got["rotation"][0]) @ scale(*got["scale"])
    if abs(np.linalg.det(m[:2, :2])) < 1e-12:
        raise MatremapError(f"{path}: {where}.{TRANSFORM}.scale {got['scale']} collapses the texture; fix the file")
    return (None if np.allclose(m, np.eye(3), rtol=0, atol=1e-12) else m), uv


def sampler_wrap(path: Path, doc: dict[str, Any], texture: dict[str, Any], where: str) -> tuple[str, str]:
    """The wrap modes (along u, v) of a texture's sampler (REPEAT without one); unknown enums are refused."""
    if "sampler" not in texture:
        return ("repeat", "repeat")
    index = texture["sampler"]
    samplers = doc.get("samplers")
    if not is_index(index) or not isinstance(samplers, list) or index >= len(samplers):
        raise MatremapError(f"{path}: {where} uses sampler {index!r}, which the file does not have; fix the file")
    sampler = as_dict(samplers[index])
    modes = []
    for key in ("wrapS", "wrapT"):
        value = sampler.get(key, 10497)
        if isinstance(value, bool) or not isinstance(value, int) or value not in WRAP_MODES:
            raise MatremapError(
                f"{path}: samplers[{index}].{key} is {value!r}; glTF allows 10497 (repeat), 33648 (mirrored "
                f"repeat) and 33071 (clamp to edge); fix the file"
            )
        modes.append(WRAP_MODES[value])
    return modes[0], modes[1]


@dataclass(frozen=True)
class SlotTexture:
    """One textureInfo of a material, resolved: ``slot`` names it (``baseColorTexture``,
    ``KHR_materials_clearcoat.clearcoatTexture``), ``path`` its image file with ``channels`` channels,
    ``uv_set`` the UV set it is looked up with (after a transform's override), ``wrap`` its sampler's
    modes, ``transform`` the KHR_texture_transform lookup (None when absent or the identity),
    ``extracted`` whether the file is matremap's copy of an image stored inside the glTF, ``size`` the image's
    (height, width)."""

    slot: str
    path: Path
    channels: int
    uv_set: int
    wrap: tuple[str, str]
    transform: np.ndarray | None
    extracted: bool = False
    size: tuple[int, int] = (0, 0)

    @property
    def need(self) -> tuple[int, int]:
        """The map size that keeps each of its texels as its transform lays them on the UVs (a texture tiled
        7 times needs 7 times its size; :func:`~matremap.formats.bake.texels_needed`), not capped."""
        return self.size if self.transform is None else texels_needed(self.size, self.transform)

    @property
    def uv_transform(self) -> UVTransform:
        m = np.eye(3) if self.transform is None else self.transform
        return UVTransform(m, "top-left", self.wrap)


def read_code_values(path: Path) -> np.ndarray:
    """An 8- or 16-bit image's code values in [0, 1], float32 [H, W, C], colour not premultiplied by alpha
    (PNG stores unassociated alpha; OpenImageIO would otherwise premultiply on read)."""
    import OpenImageIO as oiio

    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    inp = oiio.ImageInput.open(oiio_name(path), config)
    if inp is None:
        raise MatremapError(f"cannot read {path}: {oiio.geterror().strip()}; re-export it as PNG or JPEG")
    try:
        spec = inp.spec()
        pixels = inp.read_image(0, 0, 0, spec.nchannels, oiio.FLOAT)
    finally:
        inp.close()
    if pixels is None:
        raise MatremapError(f"cannot read {path}: the image is corrupt; re-export it")
    return np.asarray(pixels, dtype=np.float32).reshape(spec.height, spec.width, spec.nchannels)


def colour_channels(n: int) -> list[int]:
    """The colour channels of an image of ``n`` channels (grey or RGB; alpha excluded)."""
    return [0] if n in (1, 2) else [0, 1, 2]


def linear_values(path: Path, srgb: bool) -> np.ndarray:
    """An image's linear values [H, W, C]: colour channels decoded from sRGB when ``srgb``, alpha as stored."""
    image = read_code_values(path)
    if srgb:
        cols = colour_channels(image.shape[-1])
        image[..., cols] = srgb_to_linear(image[..., cols]).astype(np.float32)
    return image


def baked(tex: SlotTexture, srgb: bool, size: tuple[int, int] | None = None) -> Callable[[], np.ndarray]:
    """A bake callable: the image of ``tex`` (linear) as its transform and sampler show it on [0, 1]^2
    of its UV set, at ``size`` (the image's own by default), sampled bilinearly as glTF's linear filter does; the
    file is read in bands (:func:`~matremap.formats.bake.bake_file`), so memory is the map's, not the image's. The
    colour channels are what it is for when ``srgb`` (an alpha channel is decoded with them and not used)."""

    def bake() -> np.ndarray:
        return bake_file(tex.path, "srgb" if srgb else "linear", tex.uv_transform, size)

    return bake


def normal_frame(matrix: np.ndarray) -> np.ndarray:
    """The 2x2 matrix taking a normal map's stored (x, y) read through lookup ``matrix`` to the
    untransformed tangent frame (module docstring: ``F N(A^-1) F``)."""
    inv = np.linalg.inv(np.asarray(matrix, dtype=float)[:2, :2])
    inv = inv / np.linalg.norm(inv, axis=0, keepdims=True)
    flip = np.diag([1.0, -1.0])
    return flip @ inv @ flip


def baked_normal(tex: SlotTexture, size: tuple[int, int] | None = None) -> Callable[[], np.ndarray]:
    """A bake callable for a transformed (or resampled) normal map: its code values (x, y, z in [0, 1]) as the
    transform shows them at ``size`` (the image's own by default), x and y turned into the untransformed frame
    (see :func:`normal_frame`), renormalised."""

    def bake() -> np.ndarray:
        codes = bake_file(tex.path, "linear", tex.uv_transform, size)[..., :3]
        if codes.shape[-1] < 3:
            raise MatremapError(f"{tex.path}: a normal map needs 3 channels, it has {codes.shape[-1]}")
        n = codes.astype(np.float64) * 2.0 - 1.0
        if tex.transform is not None:
            n[..., :2] = n[..., :2] @ normal_frame(tex.transform).T
        n /= np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-12)
        return ((n + 1.0) / 2.0).astype(np.float32)

    return bake


__all__ = [
    "TRANSFORM",
    "WRAP_MODES",
    "SlotTexture",
    "as_dict",
    "baked",
    "baked_normal",
    "colour_channels",
    "finite_numbers",
    "linear_values",
    "normal_frame",
    "read_code_values",
    "sampler_wrap",
    "transform_matrix",
]
