"""Fits as generators of render requests, answered one at a time or many in lockstep (issue 17).

A fit (:func:`matremap.core.fit.fit_steps`) never calls a renderer: whenever it needs images it yields a
:class:`RenderRequest` (a renderer, materials, the probe scene) and is sent back their sphere pixels,
float [N, P, 3] in ``scene.pixel_indices()`` order (:func:`matremap.renderers.base.render_pixels`). Its
``return`` value is the fit's result. This is the ask/tell form of an optimiser, written with Python
generators rather than threads.

:func:`run` answers one generator's requests as they come (the classic one-fit-at-a-time loop).
:func:`lockstep` runs many generators together: at each step it collects the requests of every live
generator, renders them per (renderer, scene) in one batched call (identical materials rendered once,
batches cut at the renderer's ``batch_size``), and hands each generator its images. A sweep then makes
about as many render calls as its slowest fit makes requests, instead of the sum over its fits. Since
every renderer draws each material independently of the others in a batch, a fit's result is the same
whichever way it is driven.

A render call that fails is retried request by request, and the error is thrown into the generators
whose own request fails (a fit that cannot be rendered fails alone), except
:class:`~matremap.errors.RendererUnavailable`, which stops everything: the environment, not a fit, is at fault.
"""

from __future__ import annotations

from collections.abc import Callable, Generator, Hashable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np

from matremap.errors import RendererUnavailable
from matremap.renderers.base import render_pixels

if TYPE_CHECKING:
    from matremap.core.material import Material
    from matremap.core.scene import Scene
    from matremap.renderers.base import Renderer

T = TypeVar("T")


@dataclass(frozen=True, eq=False)
class RenderRequest:
    """Images a fit needs: each material drawn by ``renderer`` on ``scene``'s probe."""

    renderer: Renderer
    materials: tuple[Material, ...]
    scene: Scene


#: a fit (or anything that renders) in ask/tell form: yields requests, is sent pixels, returns T
Steps = Generator[RenderRequest, np.ndarray, T]


def run(steps: Generator[RenderRequest, np.ndarray, T]) -> T:
    """Drive one generator to its end, rendering each request as it comes; returns its value."""
    try:
        request = next(steps)
        while True:
            pixels = render_pixels(request.renderer, list(request.materials), request.scene)
            request = steps.send(pixels)
    except StopIteration as done:
        return done.value


def material_key(m: Material) -> Hashable:
    """Two materials with equal keys render the same image (same model, options and values)."""
    return (m.model, tuple(sorted(m.options.items())), tuple((k, v.tobytes()) for k, v in sorted(m.values.items())))


@dataclass
class Stats:
    """What a :func:`lockstep` run rendered: render calls, images asked for and images drawn (after
    identical materials were merged)."""

    calls: int = 0
    requested: int = 0
    rendered: int = 0


def lockstep(
    jobs: Sequence[Generator[RenderRequest, np.ndarray, Any]],
    stats: Stats | None = None,
    render: Callable[[Renderer, list[Material], Scene], np.ndarray] = render_pixels,
) -> list[Any]:
    """Run ``jobs`` together (see the module docstring); returns each one's value, or the exception it
    raised (a :class:`RendererUnavailable` from a render call is raised). ``stats`` counts the work."""
    stats = stats if stats is not None else Stats()
    results: list[Any] = [None] * len(jobs)
    waiting: dict[int, RenderRequest] = {}

    def advance(i: int, send: Any) -> None:
        """Step job i with ``send`` (None to start it, images, or an exception to throw in)."""
        try:
            if isinstance(send, BaseException):
                request = jobs[i].throw(send)
            else:
                request = jobs[i].send(send)
        except StopIteration as done:
            results[i] = done.value
            waiting.pop(i, None)
            return
        except RendererUnavailable:
            raise
        except Exception as e:  # the job failed: its exception is its result
            results[i] = e
            waiting.pop(i, None)
            return
        waiting[i] = request

    for i in range(len(jobs)):
        advance(i, None)
    while waiting:
        groups: dict[tuple[int, Any], list[int]] = {}
        for i, request in waiting.items():
            groups.setdefault((id(request.renderer), request.scene), []).append(i)
        for members in groups.values():
            for i, answer in _answer(members, waiting, stats, render).items():
                advance(i, answer)
    return results


def _answer(
    members: list[int],
    waiting: dict[int, RenderRequest],
    stats: Stats,
    render: Callable[[Renderer, list[Material], Scene], np.ndarray],
) -> dict[int, Any]:
    """The images of each member's request (or the exception its own request raises), rendered together."""
    first = waiting[members[0]]
    renderer, scene = first.renderer, first.scene
    unique: dict[Hashable, int] = {}
    order: list[Material] = []
    where: dict[int, list[int]] = {}
    for i in members:
        rows = []
        for m in waiting[i].materials:
            key = material_key(m)
            if key not in unique:
                unique[key] = len(order)
                order.append(m)
            rows.append(unique[key])
        where[i] = rows
    stats.requested += sum(len(rows) for rows in where.values())
    size = max(1, int(getattr(renderer, "batch_size", 64)))
    try:
        parts = []
        for start in range(0, len(order), size):
            stats.calls += 1
            parts.append(render(renderer, order[start : start + size], scene))
        if len(parts) == 1:  # one call (at most batch_size images): its pixels, not a copy
            pixels = parts[0]
        else:
            pixels = np.concatenate(parts) if parts else np.zeros((0, scene.pixel_indices().size, 3), np.float32)
        stats.rendered += len(order)
    except RendererUnavailable:
        raise
    except Exception as e:
        if len(members) == 1:  # the request itself fails: the fit hears of it
            return {members[0]: e}
        out: dict[int, Any] = {}
        for i in members:  # find whose request fails, render the others
            out.update(_answer([i], waiting, stats, render))
        return out
    out = {}
    for i, rows in where.items():  # a view when a request's images are consecutive (no copy)
        consecutive = rows == list(range(rows[0], rows[0] + len(rows))) if rows else True
        out[i] = pixels[rows[0] : rows[0] + len(rows)] if (rows and consecutive) else pixels[rows]
    return out


__all__ = ["RenderRequest", "Stats", "Steps", "lockstep", "material_key", "run"]
