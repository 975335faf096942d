"""The registry of renderer backends, and the one map from a model to the renderer that draws it.

Backends are registered by name with a factory; the built-in ones (``embedded``, ``mitsuba3``,
``cycles``) are imported only when first asked for, so listing models needs no Mitsuba or Blender.
:func:`renderer_for` is the one place that decides which renderer draws a model by default (probe
face); :func:`environment_renderer_for` does the same for environment renders, preferring the real
renderer of a model and falling back to the embedded emulation, with a warning, where it cannot.
"""

from __future__ import annotations

import difflib
import inspect
import warnings
from collections.abc import Callable, Iterable

from matremap.errors import MatremapError
from matremap.renderers.base import Renderer

_FACTORIES: dict[str, Callable[[], Renderer]] = {}
_INSTANCES: dict[str, Renderer] = {}
EMBEDDED = "embedded"


def register_renderer(name: str, factory: Callable[[], Renderer]) -> None:
    """Make a renderer available by name (the factory is called once, on first use)."""
    _FACTORIES[name] = factory
    _INSTANCES.pop(name, None)


def _load_builtin() -> None:
    if EMBEDDED not in _FACTORIES:
        from matremap.renderers.embedded import EmbeddedRenderer

        register_renderer(EMBEDDED, EmbeddedRenderer)
    if "mitsuba3" not in _FACTORIES:
        from matremap.renderers.mitsuba3 import Mitsuba3Renderer  # imports Mitsuba itself only when used

        register_renderer("mitsuba3", Mitsuba3Renderer)
    if "cycles" not in _FACTORIES:
        from matremap.renderers.cycles import CyclesRenderer  # bpy runs in a worker process of its own venv

        register_renderer("cycles", CyclesRenderer)


def renderer_names() -> list[str]:
    """The registered renderer names, sorted."""
    _load_builtin()
    return sorted(_FACTORIES)


def get_renderer(name: str | Renderer | None = None) -> Renderer:
    """A renderer by name (default: the embedded one); renderer objects pass through."""
    if name is None:
        name = EMBEDDED
    if not isinstance(name, str):
        return name
    _load_builtin()
    if name not in _FACTORIES:
        near = difflib.get_close_matches(name, list(_FACTORIES), n=2)
        hint = f"; did you mean {' or '.join(near)}?" if near else f"; known renderers: {', '.join(sorted(_FACTORIES))}"
        raise MatremapError(f"unknown renderer {name!r}{hint}")
    if name not in _INSTANCES:
        _INSTANCES[name] = _FACTORIES[name]()
    return _INSTANCES[name]


def _capabilities(name: str) -> Renderer:
    """What answers a renderer's capability queries: its class when the factory is a class that
    answers them (so asking needs neither Mitsuba nor Blender installed), else the renderer itself."""
    factory = _FACTORIES[name]
    on_class = isinstance(factory, type) and isinstance(
        inspect.getattr_static(factory, "can_render", None), (classmethod, staticmethod)
    )
    return factory if on_class else get_renderer(name)  # type: ignore[return-value]


def can_draw(name: str, model_id: str) -> bool:
    """Whether the renderer registered as ``name`` draws the model, asked without starting it (so
    without Mitsuba or Blender installed)."""
    _load_builtin()
    if name not in _FACTORIES:
        get_renderer(name)  # raises with the known names
    return bool(_capabilities(name).can_render(model_id))


def texture_refusal(model_id: str, params: Iterable[str]) -> str | None:
    """None when every renderer that draws the model takes each of ``params`` as a texture map; else
    the first refusal, naming the renderer and the parameter (asked without starting a renderer)."""
    _load_builtin()
    names = [n for n in sorted(_FACTORIES) if _capabilities(n).can_render(model_id)]
    for name in names:
        for param in params:
            if not _capabilities(name).supports_textures(model_id, param):
                return f"{name} takes {param} of {model_id} as a constant, not a texture map"
    return None


def _real_renderers(model_id: str) -> list[str]:
    """The names of the registered renderers other than the embedded one that draw the model."""
    _load_builtin()
    return [n for n in sorted(_FACTORIES) if n != EMBEDDED and _capabilities(n).can_render(model_id)]


def renderer_for(model_id: str) -> str:
    """The renderer that draws a model by default in fits: the embedded one when it emulates the
    model (deterministic and fast), else the real renderer that draws it (``mitsuba3:*`` -> mitsuba3)."""
    from matremap.dialects import get_model

    get_model(model_id)  # an unknown id raises with the nearest known ones
    if get_renderer(EMBEDDED).can_render(model_id):
        return EMBEDDED
    real = _real_renderers(model_id)
    if not real:
        raise MatremapError(f"no renderer draws model {model_id}")
    return real[0]


def resolve_renderer(name: str | Renderer | None, model_id: str) -> Renderer:
    """``name`` as a renderer; None means the model's default renderer (:func:`renderer_for`)."""
    return get_renderer(renderer_for(model_id) if name is None else name)


def environment_renderer_for(model_id: str, geometry: str, real: bool = True) -> Renderer:
    """The renderer that draws a textured material of the model under an environment: the model's real
    renderer when it can (installed, and the geometry is one it draws), else the embedded emulation with
    a warning naming why. ``real=False`` prefers the emulation where there is one (noise free: irradiance
    references). Raises, with the reason, when nothing can."""
    embedded = get_renderer(EMBEDDED)
    emulated = embedded.environment_support(model_id, geometry) is None
    if emulated and not real:
        return embedded
    reasons = []
    for name in _real_renderers(model_id):
        why = _capabilities(name).environment_support(model_id, geometry)
        if why is None:
            return get_renderer(name)
        reasons.append(why)
    if emulated:
        if reasons:
            warnings.warn(
                f"{model_id} is drawn with matremap's embedded emulation, not with its renderer: {reasons[0]}",
                RuntimeWarning,
                stacklevel=3,
            )
        return embedded
    if reasons:  # its renderer cannot and nothing emulates it: not installed (raised here) or not that geometry
        get_renderer(_real_renderers(model_id)[0])
        raise MatremapError(reasons[0])
    raise MatremapError(f"no renderer draws {model_id} on the {geometry}")


__all__ = [
    "can_draw",
    "environment_renderer_for",
    "get_renderer",
    "register_renderer",
    "renderer_for",
    "renderer_names",
    "resolve_renderer",
    "texture_refusal",
]
