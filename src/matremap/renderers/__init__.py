"""Renderer backends behind one protocol (see :mod:`matremap.renderers.base`)."""

from matremap.renderers.base import Renderer, get_renderer, register_renderer, renderer_names

__all__ = ["Renderer", "get_renderer", "register_renderer", "renderer_names"]
