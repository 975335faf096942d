"""matremap: image-based remapping of material parameters between renderers and shading models.

Follows Sztrajman, Krivanek, Wilkie, Weyrich, "Image-based remapping of spatially-varying
material appearance", JCGT 8(4), 2019.
"""

__version__ = "0.1.0"

from matremap.core.material import Material
from matremap.core.scene import PointLight, Scene
from matremap.dialects import get_model, list_models
from matremap.errors import MatremapError


def fit(*args, **kwargs):  # thin lazy wrapper
    from matremap.uniform import fit as _fit

    return _fit(*args, **kwargs)


fit.__doc__ = "Uniform remapping with renderers resolved by name; see :func:`matremap.uniform.fit`."

__all__ = ["Material", "MatremapError", "PointLight", "Scene", "__version__", "fit", "get_model", "list_models"]
