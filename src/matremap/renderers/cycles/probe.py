"""The real Blender Cycles renderer (``bpy==5.0.1``), behind the same protocol as the embedded one.

``bpy`` 5.0.1 needs Python 3.11 and numpy < 2, so it lives in its own venv and runs in a persistent
worker process (:mod:`matremap.renderers.cycles.worker`) that this module talks to over a pipe.
Set it up with::

    python3.11 -m venv .venv-bpy && .venv-bpy/bin/pip install bpy==5.0.1

The worker's Python is ``$MATREMAP_BPY_PYTHON`` or else ``<repo>/.venv-bpy/bin/python``. Importing
this module starts nothing: the models are plain data; the worker starts on the first render.

The probe scene (see :mod:`matremap.core.scene`): the sphere is a one-point Cycles point cloud of the
scene's radius, which Cycles intersects as a true sphere (exact silhouette and normals; a smooth
512x256 UV sphere is 6e-5 relative off on a Lambertian sphere, 128x64 1e-3); a camera at (0, 0, d)
with the scene's full fov along x; one point light with ``shadow_soft_size = 0``, no soft falloff and
power P = 4 pi I W (radiant intensity I W/sr), moved to each scene light in turn and the renders
summed (Cycles samples one light per sample otherwise); CPU, 1 spp, ``filter_width = 0.01`` (one
ray through each pixel centre: deterministic, noise-free), no denoising, seed 0, no world, direct
light only. Pixels come back through a 32-bit uncompressed EXR.

=================  =========================================================================
model              Blender nodes (socket names are the parameter names)
=================  =========================================================================
cycles:glossy      Glossy BSDF (distribution GGX, BECKMANN, ASHIKHMIN_SHIRLEY, MULTI_GGX) + Diffuse
                   BSDF (Roughness 0) through an Add Shader; "Diffuse Color" is the Diffuse's Color
cycles:diffuse     Diffuse BSDF, Roughness 0
cycles:principled  Principled BSDF (multiscatter GGX by default): Base Color, Metallic,
                   Roughness, IOR, Specular IOR Level, Specular Tint
=================  =========================================================================
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from matremap.core.material import Material, SVMaterial
from matremap.core.scene import Scene
from matremap.dialects import cycles as cycles_dialect
from matremap.dialects.cycles import PRINCIPLED
from matremap.errors import MatremapError
from matremap.renderers.base import EnvironmentLight, EnvironmentRender, check_can_render, check_environment
from matremap.renderers.cycles.client import INSTALL_HINT, WorkerClient, bpy_available
from matremap.renderers.cycles.environment import CyclesEnvironmentRender

MODELS = tuple(spec.id for spec in cycles_dialect.MODELS)


class CyclesRenderer(WorkerClient):
    """The probe scene rendered by Blender Cycles in the bpy worker (``cycles:*`` models).

    ``timeout`` (seconds) bounds one request (see :class:`~matremap.renderers.cycles.client.WorkerClient`);
    ``geometry`` is ``"points"`` (true sphere) or ``"SxR"`` (smooth UV sphere).
    """

    name = "cycles"

    # -- protocol ----------------------------------------------------------------------------
    @classmethod
    def can_render(cls, model_id: str) -> bool:
        return model_id in MODELS

    @classmethod
    def environment_support(cls, model_id: str, geometry: str) -> str | None:
        """Cycles draws its own models on the sphere, when the bpy venv is set up."""
        if model_id not in MODELS:
            return f"Cycles does not draw {model_id}"
        if geometry != "sphere":
            return f"the Cycles renders are of the sphere only, not the {geometry}"
        return None if bpy_available() else INSTALL_HINT

    @classmethod
    def supports_textures(cls, model_id: str, param: str) -> bool:
        return True

    def prepare_environment(
        self, material: SVMaterial, light: EnvironmentLight, geometry: str, resolution: int, part: str
    ) -> EnvironmentRender:
        check_environment(self, material, geometry, resolution, part)
        return CyclesEnvironmentRender(material, light.env, resolution, part, self)

    def render(self, materials: Sequence[Material], scene: Scene) -> np.ndarray:
        """float32 [N, H, W, 3], linear radiance."""
        materials = list(materials)
        check_can_render(self, materials)
        res = scene.resolution
        if not materials:
            return np.zeros((0, res, res, 3), dtype=np.float32)
        request = {
            "op": "render",
            "scene": self.scene_dict(scene),
            "materials": [
                {
                    "model": m.model,
                    "options": dict(m.options),
                    "values": {k: [float(x) for x in v] for k, v in m.values.items()},
                }
                for m in materials
            ],
        }
        images = self.request(request)
        if images.shape != (len(materials), res, res, 3):
            raise MatremapError(f"the Cycles worker returned images of shape {images.shape}")
        self.renders += len(materials) * len(scene.lights)
        return images.astype(np.float32, copy=False)

    def render_pixels(self, materials: Sequence[Material], scene: Scene) -> np.ndarray:
        images = self.render(materials, scene)
        return np.take(images.reshape(len(images), -1, 3), scene.pixel_indices(), axis=1)

    def scene_dict(self, scene: Scene) -> dict[str, Any]:
        return {
            "resolution": scene.resolution,
            "fov": float(scene.effective_fov),
            "camera_distance": float(scene.camera_distance),
            "sphere_radius": float(scene.sphere_radius),
            "geometry": self.geometry,
            "lights": [
                {
                    "position": [float(x) for x in scene.light_position(lt)],
                    "intensity": float(scene.light_intensity(lt)),
                }
                for lt in scene.lights
            ],
        }


__all__ = [
    "CyclesRenderer",
    "INSTALL_HINT",
    "MODELS",
    "PRINCIPLED",
    "bpy_available",
]
