"""Renderer backends behind one protocol with two faces (:mod:`.base`): probe renders of material
batches and environment-lit renders of textured materials. Each backend is a subpackage (:mod:`.embedded`,
:mod:`.mitsuba3`, :mod:`.cycles`); :mod:`.registry` finds them by name and maps a model to its renderer;
:mod:`.textured` is the evaluation scene they all draw."""

from matremap.renderers.base import EnvironmentLight, EnvironmentRender, Renderer
from matremap.renderers.registry import (
    environment_renderer_for,
    get_renderer,
    register_renderer,
    renderer_for,
    renderer_names,
    resolve_renderer,
)

__all__ = [
    "EnvironmentLight",
    "EnvironmentRender",
    "Renderer",
    "environment_renderer_for",
    "get_renderer",
    "register_renderer",
    "renderer_for",
    "renderer_names",
    "resolve_renderer",
]
