"""MaterialX node graphs evaluated onto texture maps (the values a renderer sees at each texel).

Sources: the MaterialX Standard Nodes specification v1.39 (``documents/Specification/
MaterialX.StandardNodes.md``): ``image`` (§Texture Nodes: "the lower-left corner of an image mapping to
the (0,0) UV coordinate"; a node type with more channels than the file gets 0 in the extra channels,
except a fourth channel, which is 1; the first N channels otherwise), address modes and filter types
(§Texture Node Notes), ``constant``, ``texcoord``, the math nodes (``add``, ``subtract``, ``multiply``,
``divide``, ``min``, ``max``, ``clamp``, ``dotproduct``), ``mix`` ("Fm + B(1-m)"), ``dot`` (a no-op),
``switch`` (input floor(which)+1, clamped to 1-10), ``extract``, ``separate2/3/4``, ``combine2/3/4``,
``convert`` (§convert: N to M channels copies, drops or pads with 0 and a fourth channel of 1; a
scalar fills every channel), ``rgbtohsv`` / ``hsvtorgb`` (Foley & van Dam's hexcone, H and S in
[0, 1]), ``rotate2d``. Swizzle nodes of older documents arrive here as ``extract`` / ``separate`` +
``combine`` (MaterialX's reader upgrades them to 1.39).

Nodes that MaterialX's standard data library implements as node graphs are evaluated through those
graphs, exactly as the library defines them: ``tiledimage`` (``libraries/stdlib/stdlib_ng.mtlx``:
texcoord x uvtiling - uvoffset, / realworldimagesize x realworldtilesize, then a periodic ``image``),
``place2d`` (the same file: SRT = -pivot, / scale, rotate2d, -offset, +pivot; TRS = -pivot, -offset,
rotate2d, / scale, +pivot, picked by ``switch``), ``gltf_image``, ``gltf_colorimage``,
``gltf_normalmap`` (``libraries/bxdf/gltf_pbr.mtlx``: a ``place2d`` with pivot (0, 1) and the inverse
scale, rotation and offset, then ``image`` x ``factor``). ``rotate2d`` follows the library's code
(``stdlib/genglsl/mx_rotate_vector2.glsl``: (x, y) -> (c x + s y, -s x + c y)), which every MaterialX
renderer runs.

An input is evaluated in two passes. The *probe* (a 16 x 16 grid, image files read for their headers
only) checks every node, finds whether the input varies over the surface at all (a graph of
constants folds into a value), and measures how densely each image is sampled: the output map is as
large as the largest image feeding the input times its tiling (the UV derivatives of its lookup),
capped at :data:`MAX_SIDE` per side (the cap is said in a note). The *bake* evaluates the graph at
that size: UV is MaterialX's texture space, (0, 0) at the lower left (:mod:`matremap.formats.bake`'s
``"bottom-left"`` origin), images are decoded to linear before filtering and sampled bilinearly
between texel centres by :func:`matremap.formats.bake.sample` with the node's wrap modes (periodic ->
repeat, clamp, mirror; constant -> the node's ``default`` outside [0, 1]); ``closest`` takes the
nearest texel; ``cubic`` is read as linear (noted). Any other node is refused with its category, its
name and the shader input it feeds.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

from matremap.errors import MatremapError, not_a_file, shorten
from matremap.formats.bake import MAX_SIDE, border_cover, sample_file, texel_grid

#: channels of the MaterialX data types the evaluator handles
CHANNELS = {"float": 1, "integer": 1, "boolean": 1, "vector2": 2, "vector3": 3, "color3": 3, "vector4": 4, "color4": 4}
#: the probe grid's side
PROBE = 16
#: the side of a map baked from a graph that varies over UV without reading any image
PROCEDURAL_SIDE = 1024
#: how deep connections (to a node, a nodegraph or an interface input) may nest before the graph is refused
#: (a cycle, or a hostile document); evaluation recurses, with the room this depth needs
MAX_DEPTH = 1000
#: the most Python frames one connection takes while evaluating (port, input, a node and its inputs)
FRAMES_PER_HOP = 12
#: MaterialX address mode -> :mod:`matremap.formats.bake` wrap mode
WRAP = {"periodic": "repeat", "clamp": "clamp", "mirror": "mirror", "constant": "border"}
SRGB = ("srgb_texture",)
LINEAR = ("", "lin_rec709", "raw", "none", "linear")

Value = Any  # np.ndarray (uniform [C] or varying [H, W, C]) | str | FileRef


@dataclass(frozen=True)
class FileRef:
    """A ``filename`` input: the file (confined, resolved with ``fileprefix``), its text, and the
    colour space in effect on it (``colorspace`` inheritance applied)."""

    path: Path
    text: str
    colorspace: str


@dataclass(frozen=True)
class PlainImage:
    """An image file a shader input reads as it is stored: the file, the channels it takes (None:
    all), how it is decoded ("srgb"/"linear"), the factor it is multiplied by, and its size (H, W)."""

    file: FileRef
    channels: tuple[int, ...] | None
    colorspace: str
    factor: float | tuple[float, ...]
    size: tuple[int, int]


#: the inputs of the image nodes a plain texture may have, at the values that leave the image as stored
PLAIN_IDENTITY: dict[str, dict[str, tuple[float, ...]]] = {
    "image": {},
    "tiledimage": {
        "uvtiling": (1.0, 1.0),
        "uvoffset": (0.0, 0.0),
        "realworldimagesize": (1.0, 1.0),
        "realworldtilesize": (1.0, 1.0),
    },
    "gltf_image": {"scale": (1.0, 1.0), "rotate": (0.0,), "offset": (0.0, 0.0)},
    "gltf_normalmap": {"scale": (1.0, 1.0), "rotate": (0.0,), "offset": (0.0, 0.0)},
}


@dataclass
class ImageUse:
    """An image the probe saw: its file, size (height, width) and the map size that keeps every
    texel of it as the graph samples it (tiling included)."""

    path: Path
    size: tuple[int, int]
    need: tuple[int, int]


@dataclass
class Analysis:
    """What the probe found for one input: ``constant`` (its value, when it does not vary over the
    surface), the images it reads, and the size to bake it at (with the reason, for the note)."""

    constant: np.ndarray | None
    images: list[ImageUse]
    size: tuple[int, int]
    capped: bool = False


@dataclass
class Scope:
    """Where names resolve while evaluating: ``graph`` holds the nodes that ``nodename`` names (the
    document, a nodegraph, or a library node's implementation graph); ``interface`` gives the value
    of an ``interfacename`` (the nodegraph's inputs, or the instance node's inputs)."""

    graph: Any
    interface: Callable[[str, str], Value] | None
    label: str
    owner: tuple[Any, Scope] | None = None  # for a library definition: the node it implements, and its scope
    #: interface values already evaluated (name, type) -> value, while the scope is being evaluated
    given: dict[tuple[str, str], Value] = field(default_factory=dict)
    #: (node name, output) -> how many connections in the graph read it; None until counted
    readers: dict[tuple[str, str], int] | None = None


@dataclass
class _Pass:
    size: tuple[int, int]
    probe: bool
    memo: dict[tuple[int, str, str], Value] = field(default_factory=dict)
    #: memo key -> how many more reads of it are expected (it is dropped after the last)
    left: dict[tuple[int, str, str], int] = field(default_factory=dict)
    uses: list[ImageUse] = field(default_factory=list)
    scopes: list[Scope] = field(default_factory=list)
    depth: int = 0


def parse_value(text: str, typ: str, where: str) -> Value:
    """A value string of MaterialX type ``typ`` as a float array of its channels (strings as they are)."""
    if typ in ("string", "filename"):
        return text
    if typ == "boolean":
        return np.array([1.0 if text.strip().lower() == "true" else 0.0])
    n = CHANNELS.get(typ)
    if n is None:
        raise MatremapError(f"{where}: values of type {typ!r} are not supported")
    try:
        nums = [float(x) for x in text.replace(",", " ").split()]
    except ValueError:
        raise MatremapError(f"{where}: value {shorten(text)!r} is not a {typ}") from None
    if len(nums) == 1 and n > 1:
        nums = nums * n
    if len(nums) != n or not all(math.isfinite(x) for x in nums):
        raise MatremapError(f"{where}: value {shorten(text)!r} is not a {typ} ({n} finite number(s))")
    return np.array(nums, dtype=np.float64)


def zero(typ: str) -> Value:
    """MaterialX's __zero__ of a type."""
    return "" if typ in ("string", "filename") else np.zeros(CHANNELS.get(typ, 1))


def fit_channels(value: np.ndarray, n: int) -> np.ndarray:
    """``value`` with ``n`` channels by the rule of ``image`` and ``convert`` (Standard Nodes 1.39):
    the first ``n`` channels; missing ones 0, except a fourth channel, which is 1; one channel fills all."""
    c = value.shape[-1]
    if c == n:
        return value
    if c == 1:
        return np.repeat(value, n, axis=-1)
    if c > n:
        return value[..., :n]
    pad = [np.zeros_like(value[..., :1])] * (n - c)
    if n == 4:
        pad[-1] = np.ones_like(value[..., :1])
    return np.concatenate([value, *pad], axis=-1)


def _uniform(v: Value, what: str) -> float:
    arr = np.asarray(v, dtype=np.float64)
    if arr.ndim != 1:
        raise MatremapError(f"{what} must be uniform (the same everywhere), not a texture")
    return float(arr[0])


class GraphEvaluator:
    """Evaluates the node graphs of one MaterialX document (see the module docstring).

    ``doc``: the document with MaterialX's standard library set as its data library; ``resolve``
    (text, what) -> the confined path of a file a ``file`` input names; ``notes``: where decisions go.
    Image files are read in bands each time a bake samples them (:func:`~matremap.formats.bake.sample_file`)."""

    def __init__(self, doc: Any, path: Path, resolve: Callable[[str, str], Path], notes: list[str]) -> None:
        self.doc, self.path, self.resolve, self.notes = doc, path, resolve, notes
        self.doc_scope = Scope(doc, None, "the document")
        self._pass = _Pass((PROBE, PROBE), True)
        self._feeding = ""

    # -- the two passes ------------------------------------------------------------------------

    def analyse(self, root: Callable[[], Value], feeding: str) -> Analysis:
        """Probe ``root`` (a function evaluating the input in the current pass): its constant value, or the
        images it reads and the size to bake it at. Raises MatremapError naming any unsupported node."""
        self._start(_Pass((PROBE, PROBE), True), feeding)
        with np.errstate(all="ignore"), deep_stack():
            value = self._array(root(), feeding)
        uses = self._pass.uses
        if value.ndim == 1:
            return Analysis(value, uses, (1, 1))
        if not uses:
            return Analysis(None, uses, (PROCEDURAL_SIDE, PROCEDURAL_SIDE))
        h = max(u.need[0] for u in uses)
        w = max(u.need[1] for u in uses)
        capped = h > MAX_SIDE or w > MAX_SIDE
        return Analysis(None, uses, (min(h, MAX_SIDE), min(w, MAX_SIDE)), capped)

    def bake(self, root: Callable[[], Value], feeding: str, size: tuple[int, int]) -> np.ndarray:
        """``root`` evaluated on a map of ``size`` (height, width): linear float32 [H, W, C]."""
        self._start(_Pass(size, False), feeding)
        with np.errstate(all="ignore"), deep_stack():
            value = self._array(root(), feeding)
        return np.ascontiguousarray(np.broadcast_to(value, (*size, value.shape[-1])), dtype=np.float32)

    def _start(self, p: _Pass, feeding: str) -> None:
        self._pass, self._feeding = p, feeding

    def _array(self, v: Value, feeding: str) -> np.ndarray:
        if not isinstance(v, np.ndarray):
            raise MatremapError(f"{self.path}: {feeding} is connected to a string or file output, not a value")
        return v

    # -- ports and inputs ----------------------------------------------------------------------

    def port(self, el: Any, typ: str, scope: Scope) -> Value:
        """The value of an input or output element ``el`` in ``scope``: its interface input, the node or
        nodegraph output it connects to, or its own value. Refused past :data:`MAX_DEPTH` nested connections."""
        if self._pass.depth >= MAX_DEPTH:
            raise MatremapError(
                f"{self.path}: the graph feeding {self._feeding} nests connections deeper than {MAX_DEPTH} (or "
                f"loops); matremap evaluates graphs up to {MAX_DEPTH} connections deep"
            )
        self._pass.depth += 1
        try:
            return self._port(el, typ, scope)
        finally:
            self._pass.depth -= 1

    def _port(self, el: Any, typ: str, scope: Scope) -> Value:
        iface = el.getAttribute("interfacename")
        if iface:
            if scope.interface is None:
                raise MatremapError(f"{self.path}: {el.getNamePath()} names interface input {iface!r} outside a graph")
            return scope.interface(iface, typ)
        graph_name = el.getAttribute("nodegraph")
        if graph_name:
            graph = self.doc.getNodeGraph(graph_name)
            if graph is None:
                raise MatremapError(f"{self.path}: {el.getNamePath()} names nodegraph {graph_name!r}, which is missing")
            return self.graph_output(graph, el.getAttribute("output"), typ)
        node_name = el.getAttribute("nodename")
        if node_name:
            node = scope.graph.getNode(node_name)
            if node is None:
                raise MatremapError(f"{self.path}: {el.getNamePath()} names node {node_name!r}, which is missing")
            return self.node_output(node, el.getAttribute("output"), scope)
        if typ == "filename":
            return self._file(el)
        return parse_value(el.getValueString(), typ or el.getType(), f"{self.path}: {el.getNamePath()}")

    def graph_output(self, graph: Any, output: str, typ: str) -> Value:
        """Output ``output`` (the first when empty) of a document-level nodegraph."""
        out = graph.getOutput(output) if output else (graph.getOutputs() or [None])[0]
        if out is None:
            raise MatremapError(f"{self.path}: nodegraph {graph.getName()!r} has no output {output!r}")
        scope = self.graph_scope(graph)
        try:
            return self.port(out, typ or out.getType(), scope)
        finally:
            scope.given.clear()  # its interface values are not read again

    def graph_scope(self, graph: Any) -> Scope:
        """The scope of a document-level nodegraph: its nodes, and its own inputs as its interface."""

        def interface(name: str, typ: str) -> Value:
            return self._given(scope, name, typ, lambda: self._graph_interface(graph, name, typ))

        scope = Scope(graph, interface, f"nodegraph {graph.getName()!r}")
        self._pass.scopes.append(scope)
        return scope

    def _graph_interface(self, graph: Any, name: str, typ: str) -> Value:
        inp = graph.getInput(name)
        if inp is None:
            raise MatremapError(f"{self.path}: nodegraph {graph.getName()!r} has no input {name!r}")
        return self.port(inp, typ or inp.getType(), self.doc_scope)

    def input(self, node: Any, name: str, typ: str, scope: Scope) -> Value:
        """Input ``name`` of ``node``: its value or connection, else its node definition's default (a
        ``defaultgeomprop`` of UV0 is the texture coordinates)."""
        inp = node.getInput(name)
        if inp is not None and (
            inp.getValueString()
            or inp.getAttribute("nodename")
            or inp.getAttribute("nodegraph")
            or inp.getAttribute("interfacename")
        ):
            return self.port(inp, typ or inp.getType(), scope)
        nd = node.getNodeDef()
        ndi = nd.getActiveInput(name) if nd is not None else None
        if ndi is None:
            return zero(typ)
        prop = ndi.getDefaultGeomPropString()
        if prop:
            if prop != "UV0":
                self.refuse(node, scope, f"its {name} input defaults to the geometry's {prop}")
            return self.texcoord(ndi.getType())
        text = ndi.getValueString()
        return parse_value(text, ndi.getType(), f"{self.path}: {nd.getName()}.{name}") if text else zero(ndi.getType())

    def string(self, node: Any, name: str, scope: Scope) -> str:
        v = self.input(node, name, "string", scope)
        return v if isinstance(v, str) else ""

    def texcoord(self, typ: str = "vector2") -> np.ndarray:
        """MaterialX texture coordinates at the texel centres of the pass's map: (0, 0) at the lower left."""
        s, t = texel_grid(self._pass.size)
        uv = np.stack([s, 1.0 - t], axis=-1)
        return fit_channels(uv, CHANNELS.get(typ, 2)) if typ == "vector3" else uv

    def _file(self, el: Any) -> FileRef:
        text = el.getResolvedValueString()
        if not text:
            raise MatremapError(f"{self.path}: {el.getNamePath()} names no file; set its file input")
        path = self.resolve(text, f"{el.getParent().getName()!r} file")
        return FileRef(path, text, (el.getActiveColorSpace() or "").strip())

    # -- nodes ---------------------------------------------------------------------------------

    def node_output(self, node: Any, output: str, scope: Scope) -> Value:
        """Output ``output`` of ``node`` (its only output when empty), memoised per pass."""
        memo, left = self._pass.memo, self._pass.left
        key = (id(scope), node.getNamePath(), output or "")
        if key in memo:
            value = memo[key]
            left[key] -= 1
            if left[key] <= 0:  # its last reader: a texture is not held longer than it is needed
                del memo[key], left[key]
            return value
        primitive = PRIMITIVES.get(node.getCategory())
        value = primitive(self, node, output, scope) if primitive else self._expand(node, output, scope)
        readers = self._readers(scope).get((node.getName(), output or ""), 1)
        if readers > 1:
            memo[key], left[key] = value, readers - 1
        return value

    def _readers(self, scope: Scope) -> dict[tuple[str, str], int]:
        """How many connections of ``scope``'s graph read each (node, output): a value read once is not
        kept (a long chain holds one texture at a time), one read more often is kept until its last read."""
        if scope.readers is None:
            counts: dict[tuple[str, str], int] = {}
            graph = scope.graph
            ports = [p for n in graph.getNodes() for p in n.getInputs()] + list(graph.getOutputs())
            if graph is self.doc:
                ports += [p for g in graph.getNodeGraphs() for p in g.getInputs()]
            for p in ports:
                name = p.getAttribute("nodename")
                if name:
                    k = (name, p.getAttribute("output"))
                    counts[k] = counts.get(k, 0) + 1
            scope.readers = counts
        return scope.readers

    def _given(self, scope: Scope, name: str, typ: str, evaluate: Callable[[], Value]) -> Value:
        """Interface input ``name`` of ``scope``, evaluated once while the scope is evaluated."""
        key = (name, typ)
        if key not in scope.given:
            scope.given[key] = evaluate()
        return scope.given[key]

    def _expand(self, node: Any, output: str, scope: Scope) -> Value:
        """A node that MaterialX's library implements as a node graph, evaluated through that graph."""
        import MaterialX as mx

        nd = node.getNodeDef()
        impl = nd.getImplementation() if nd is not None else None
        if not isinstance(impl, mx.NodeGraph):
            self.refuse(node, scope)
        out = impl.getOutput(output) if output else (impl.getOutputs() or [None])[0]
        if out is None:
            raise MatremapError(f"{self.path}: node {node.getName()!r} has no output {output!r}")
        inner = Scope(impl, None, "its library definition", (node, scope))
        inner.interface = self._instance(node, scope, inner)
        self._pass.scopes.append(inner)
        try:
            return self.port(out, out.getType(), inner)
        finally:
            inner.given.clear()  # its interface values are not read again

    def _instance(self, node: Any, scope: Scope, inner: Scope | None = None) -> Callable[[str, str], Value]:
        """The interface of a library node's implementation graph ``inner``: the instance node's inputs
        (evaluated once while ``inner`` is, when given)."""

        def interface(name: str, typ: str) -> Value:
            if inner is None:
                return self.input(node, name, typ, scope)
            return self._given(inner, name, typ, lambda: self.input(node, name, typ, scope))

        return interface

    def refuse(self, node: Any, scope: Scope, why: str = "") -> NoReturn:
        """Refuse ``node`` in one line naming the document's node that leads to it (the node itself, or the
        library node whose definition uses it) and the shader input it feeds."""
        inner = ""
        while scope.owner is not None:  # up to the node the document itself holds
            inner = inner or f"; its library definition uses a {node.getCategory()!r} node"
            node, scope = scope.owner
        where = "" if scope.graph is self.doc else f" in {scope.label}"
        raise MatremapError(
            f"{self.path}: {self._feeding} is fed by a {node.getCategory()!r} node ({node.getName()!r}{where}"
            + inner
            + f"{': ' + why if why else ''}), which matremap cannot evaluate; it evaluates "
            + f"{', '.join(SUPPORTED)} (bake the graph into an image)"
        )

    # -- structure: plain textures and normal maps ------------------------------------------------

    def upstream(self, el: Any, scope: Scope) -> tuple[Any, str, Scope] | None:
        """The (node, output, scope) that element ``el`` connects to, through nodegraph outputs and
        ``dot`` nodes; None for a value or an interface input."""
        for _ in range(MAX_DEPTH):
            graph_name = el.getAttribute("nodegraph")
            if graph_name:
                graph = self.doc.getNodeGraph(graph_name)
                out = None
                if graph is not None:
                    output = el.getAttribute("output")
                    out = graph.getOutput(output) if output else (graph.getOutputs() or [None])[0]
                if out is None:
                    return None
                el, scope = out, self.graph_scope(graph)
                continue
            node_name = el.getAttribute("nodename")
            node = scope.graph.getNode(node_name) if node_name else None
            if node is None:
                return None
            if node.getCategory() == "dot" and node.getInput("in") is not None:
                el = node.getInput("in")
                continue
            return node, el.getAttribute("output"), scope
        return None

    def plain_image(self, el: Any, feeding: str) -> PlainImage | None:
        """The image file ``el`` reads as it is stored, when it does: an ``image``, ``tiledimage`` or
        ``gltf_image`` node at UV0 with no transform (tiling 1, offset 0, ...), optionally behind an
        ``extract`` or ``separate`` node that picks one channel; None for anything else."""
        with deep_stack():
            return self._plain_image(el, feeding)

    def _plain_image(self, el: Any, feeding: str) -> PlainImage | None:
        self._start(_Pass((PROBE, PROBE), True), feeding)
        found = self.upstream(el, self.doc_scope)
        if found is None:
            return None
        node, output, scope = found
        channel = None
        if node.getCategory() == "extract" or node.getCategory().startswith("separate"):
            try:
                channel = self._picked(node, output, scope)
            except MatremapError:
                return None
            inner = node.getInput("in")
            found = self.upstream(inner, scope) if inner is not None else None
            if found is None:
                return None
            node, output, scope = found
        return self._plain_node(node, scope, channel)

    def _picked(self, node: Any, output: str, scope: Scope) -> int:
        if node.getCategory() == "extract":
            return int(_uniform(_in(self, node, "index", scope), "index"))
        name = output[-1:] if output.startswith("out") else ""
        return "rgba".find(name) if name in "rgba" else "xyzw".find(name)

    def _plain_node(self, node: Any, scope: Scope, channel: int | None) -> PlainImage | None:
        from matremap.svbrdf.textures import image_info

        identity = PLAIN_IDENTITY.get(node.getCategory())
        if identity is None or node.getInput("texcoord") is not None:
            return None
        for name, want in identity.items():
            inp = node.getInput(name)
            if inp is not None and (inp.getAttribute("nodename") or inp.getAttribute("nodegraph")):
                return None
            v = self.input(node, name, "", scope)
            if not isinstance(v, np.ndarray) or v.ndim != 1 or not np.allclose(v, want, rtol=0, atol=1e-12):
                return None
        f = self.input(node, "file", "filename", scope)
        n = CHANNELS.get(node.getType(), 0)
        if not isinstance(f, FileRef) or not f.path.is_file() or n == 0 or (channel is not None and channel >= n):
            return None
        info = image_info(f.path, "linear", colour=False)
        if info.channels < n and (channel is None or channel >= info.channels):
            return None  # the spec pads missing channels with 0: not the file as it is
        factor: Any = 1.0
        nd = node.getNodeDef()
        if nd is not None and nd.getActiveInput("factor") is not None:
            fv = _in(self, node, "factor", scope)
            if fv.ndim != 1:
                return None
            factor = float(fv[channel]) if channel is not None and fv.size > 1 else tuple(float(x) for x in fv)
            factor = factor[0] if isinstance(factor, tuple) and len(factor) == 1 else factor
        cs = self.colorspace(f, node.getType(), node.getName())
        return PlainImage(f, None if channel is None else (channel,), cs, factor, (info.height, info.width))

    def normal_map(self, el: Any, feeding: str) -> tuple[Callable[[], Value], PlainImage | None] | None:
        """The encoded tangent-space normal map (values in [0, 1]) feeding a shader's normal input
        through a ``normalmap`` node (or a library node built on one, ``gltf_normalmap``): a function
        evaluating it (``scale`` applied to x and y, Standard Nodes 1.39 §normalmap) and, when the
        map is an image file used as it is, that image. None when nothing is connected."""
        with deep_stack():
            return self._normal_map(el, feeding)

    def _normal_map(self, el: Any, feeding: str) -> tuple[Callable[[], Value], PlainImage | None] | None:
        self._start(_Pass((PROBE, PROBE), True), feeding)
        found = self.upstream(el, self.doc_scope)
        for _ in range(MAX_DEPTH):
            if found is None:
                return None
            node, output, scope = found
            if node.getCategory() == "normalmap":
                return self._normal_root(node, scope)
            plain = self._plain_node(node, scope, None) if node.getCategory() == "gltf_normalmap" else None
            import MaterialX as mx

            nd = node.getNodeDef()
            impl = nd.getImplementation() if nd is not None else None
            if not isinstance(impl, mx.NodeGraph):
                self.refuse(node, scope, "only a normalmap node (or gltf_normalmap) gives a normal map")
            out = impl.getOutput(output) if output else (impl.getOutputs() or [None])[0]
            inner = Scope(impl, self._instance(node, scope), "its library definition", (node, scope))
            self._pass.scopes.append(inner)
            found = self.upstream(out, inner) if out is not None else None
            if plain is not None and found is not None and found[0].getCategory() == "normalmap":
                root, _ = self._normal_root(found[0], found[2])
                return root, plain
        return None

    def _normal_root(self, node: Any, scope: Scope) -> tuple[Callable[[], Value], PlainImage | None]:
        inp = node.getInput("in")
        plain = self.plain_image(inp, self._feeding) if inp is not None else None
        self._start(self._pass, self._feeding)

        def root() -> np.ndarray:
            enc = np.asarray(self.input(node, "in", "vector3", scope), dtype=np.float64)
            scale = np.asarray(self.input(node, "scale", "", scope), dtype=np.float64).reshape(-1)
            if np.allclose(scale, 1.0):
                return enc
            n = enc * 2.0 - 1.0
            xy = n[..., :2] * (scale if scale.size == 2 else scale[:1])
            n = np.concatenate([xy, n[..., 2:3]], axis=-1)
            n = n / np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-12)
            return n * 0.5 + 0.5

        scale = np.asarray(self.input(node, "scale", "", scope), dtype=np.float64).reshape(-1)
        return root, plain if np.allclose(scale, 1.0) else None

    # -- images ---------------------------------------------------------------------------------

    def image(self, node: Any, scope: Scope) -> np.ndarray:
        """An ``image`` node sampled at its texcoord (see the module docstring)."""
        typ = node.getType()
        if typ not in CHANNELS:
            self.refuse(node, scope, f"an image of type {typ}")
        n = CHANNELS[typ]
        f = self.input(node, "file", "filename", scope)
        if not isinstance(f, FileRef):
            raise MatremapError(f"{self.path}: image node {node.getName()!r} names no file; set its file input")
        uv = np.broadcast_to(np.asarray(self.input(node, "texcoord", "vector2", scope)), (*self._pass.size, 2))
        s, t = uv[..., 0], 1.0 - uv[..., 1]
        modes = [self.string(node, k, scope) or "periodic" for k in ("uaddressmode", "vaddressmode")]
        for m in modes:
            if m not in WRAP:
                raise MatremapError(f"{self.path}: image node {node.getName()!r} has address mode {m!r}")
        default = fit_channels(np.asarray(self.input(node, "default", typ, scope), dtype=np.float64), n)
        filt = self.string(node, "filtertype", scope) or "linear"
        if self._pass.probe:
            return self._probe_image(f, node, n, s, t)
        from matremap.svbrdf.textures import image_info

        cs = self.colorspace(f, typ, node.getName())
        info = image_info(f.path, cs, colour=cs == "srgb")
        h, w = info.height, info.width
        if filt == "closest":  # the centre of the texel each lookup falls in
            s, t = (np.floor(s * w) + 0.5) / w, (np.floor(t * h) + 0.5) / h
        wrap = (WRAP[modes[0]], WRAP[modes[1]])
        # the file read in bands (memory: the map's, not the image's), its channels fitted to the node's type
        # (fit_image) after sampling: a padded 0 samples to 0, a padded 1 to the weight of the taps inside
        out = sample_file(f.path, cs, s, t, wrap, 0.0, channels=list(range(min(n, info.channels))))
        cover = border_cover((h, w), s, t, wrap) if "border" in wrap or n == 4 > info.channels else None
        if n > info.channels:
            pad = np.zeros((*out.shape[:-1], n - info.channels), np.float32)
            if n == 4:
                pad[..., -1:] = cover
            out = np.concatenate([out, pad], axis=-1)
        out = out.astype(np.float64)
        if cover is not None and "border" in wrap:  # outside [0, 1] the default, blended as the bilinear taps fall
            out = out + (1.0 - cover) * default
        return out

    def _probe_image(self, f: FileRef, node: Any, n: int, s: np.ndarray, t: np.ndarray) -> np.ndarray:
        """The probe's stand-in for an image: zeros, after checking the file and recording the map size
        that keeps each of its texels (its size times the UV derivatives of the lookup)."""
        from matremap.svbrdf.textures import image_info

        if not f.path.is_file() and f.path.exists():
            raise MatremapError(f"{self.path}: {not_a_file(f.path, f'texture {shorten(f.text)} for {self._feeding}')}")
        if not f.path.is_file():
            raise MatremapError(
                f"{self.path}: texture {shorten(f.text)} for {self._feeding} not found at {f.path}; put it beside "
                f"the document or fix its file input"
            )
        self.colorspace(f, node.getType(), node.getName())
        info = image_info(f.path, "linear", colour=False)
        h, w = info.height, info.width
        p = self._pass.size[0]
        ds = np.abs(np.diff(s, axis=1)) * p, np.abs(np.diff(t, axis=1)) * p  # d/d(output s)
        dt = np.abs(np.diff(s, axis=0)) * p, np.abs(np.diff(t, axis=0)) * p  # d/d(output t)
        need_w = float(np.max(np.hypot(w * ds[0], h * ds[1]))) if ds[0].size else w
        need_h = float(np.max(np.hypot(w * dt[0], h * dt[1]))) if dt[0].size else h
        need = (max(1, math.ceil(need_h - 1e-6)), max(1, math.ceil(need_w - 1e-6)))
        self._pass.uses.append(ImageUse(f.path, (h, w), need))
        return np.zeros((*self._pass.size, n))

    def colorspace(self, f: FileRef, typ: str, node_name: str) -> str:
        """How a file is decoded for a node of type ``typ``: sRGB for a colour type tagged srgb_texture,
        else linear (MaterialX transforms colour data only)."""
        cs = f.colorspace.lower()
        if cs not in SRGB and cs not in LINEAR:
            raise MatremapError(
                f"{self.path}: texture {Path(f.text).name} has colour space {f.colorspace!r}; matremap reads "
                f"srgb_texture and lin_rec709 (raw) textures, convert it to one of these"
            )
        if cs in SRGB and not typ.startswith("color"):
            note = (
                f"{Path(f.text).name}: {f.colorspace} ignored on {typ} node {node_name!r} "
                f"(MaterialX transforms colour data only)"
            )
            if note not in self.notes:
                self.notes.append(note)
            return "linear"
        return "srgb" if cs in SRGB else "linear"


@contextmanager
def deep_stack() -> Iterator[None]:
    """Room on Python's stack for an evaluation :data:`MAX_DEPTH` connections deep (the interpreter's
    recursion limit raised for the moment, never lowered; evaluation is plain Python calls, which take
    no C stack)."""
    depth = 0
    frame: Any = sys._getframe()
    while frame is not None and depth < 100_000:
        frame, depth = frame.f_back, depth + 1
    before = sys.getrecursionlimit()
    sys.setrecursionlimit(max(before, depth + MAX_DEPTH * FRAMES_PER_HOP + 200))
    try:
        yield
    finally:
        sys.setrecursionlimit(before)


def fit_image(img: np.ndarray, n: int) -> np.ndarray:
    """An image's channels fitted to a node type of ``n`` channels (Standard Nodes 1.39, ``image``):
    the first n; missing ones 0, except a fourth channel, which is 1 (a grey file read as color3 is red)."""
    c = img.shape[-1]
    if c >= n:
        return img[..., :n]
    pad = np.zeros((*img.shape[:2], n - c), img.dtype)
    if n == 4:
        pad[..., -1] = 1.0
    return np.concatenate([img, pad], axis=-1)


# ---------------------------------------------------------------------------------------------
# Primitive nodes: (evaluator, node, output name, scope) -> value


def _in(ev: GraphEvaluator, node: Any, name: str, scope: Scope) -> np.ndarray:
    nd = node.getNodeDef()
    ndi = nd.getActiveInput(name) if nd is not None else None
    typ = ndi.getType() if ndi is not None else (node.getInput(name).getType() if node.getInput(name) else "float")
    v = ev.input(node, name, typ, scope)
    if not isinstance(v, np.ndarray):
        raise MatremapError(f"{ev.path}: input {name} of {node.getName()!r} is not a number")
    return v


def _binary(op: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> Callable[..., np.ndarray]:
    def evaluate(ev: GraphEvaluator, node: Any, output: str, scope: Scope) -> np.ndarray:
        return np.asarray(op(_in(ev, node, "in1", scope), _in(ev, node, "in2", scope)))

    return evaluate


def _mix(ev: GraphEvaluator, node: Any, output: str, scope: Scope) -> np.ndarray:
    m = _in(ev, node, "mix", scope)
    return _in(ev, node, "fg", scope) * m + _in(ev, node, "bg", scope) * (1.0 - m)


def _clamp(ev: GraphEvaluator, node: Any, output: str, scope: Scope) -> np.ndarray:
    return np.minimum(np.maximum(_in(ev, node, "in", scope), _in(ev, node, "low", scope)), _in(ev, node, "high", scope))


def _dotproduct(ev: GraphEvaluator, node: Any, output: str, scope: Scope) -> np.ndarray:
    return np.sum(_in(ev, node, "in1", scope) * _in(ev, node, "in2", scope), axis=-1, keepdims=True)


def _passthrough(ev: GraphEvaluator, node: Any, output: str, scope: Scope) -> Value:
    return ev.input(node, "in", node.getType(), scope)


def _constant(ev: GraphEvaluator, node: Any, output: str, scope: Scope) -> Value:
    return ev.input(node, "value", node.getType(), scope)


def _texcoord(ev: GraphEvaluator, node: Any, output: str, scope: Scope) -> np.ndarray:
    index = int(_uniform(_in(ev, node, "index", scope), f"{ev.path}: texcoord {node.getName()!r} index"))
    if index != 0:
        ev.refuse(node, scope, f"UV set {index} (a map set holds UV set 0 only)")
    return ev.texcoord(node.getType())


def _image(ev: GraphEvaluator, node: Any, output: str, scope: Scope) -> np.ndarray:
    return ev.image(node, scope)


def _extract(ev: GraphEvaluator, node: Any, output: str, scope: Scope) -> np.ndarray:
    v = _in(ev, node, "in", scope)
    index = int(_uniform(_in(ev, node, "index", scope), f"{ev.path}: extract {node.getName()!r} index"))
    if not 0 <= index < v.shape[-1]:
        raise MatremapError(f"{ev.path}: extract {node.getName()!r} index {index} is beyond its {v.shape[-1]} channels")
    return v[..., index : index + 1]


def _separate(ev: GraphEvaluator, node: Any, output: str, scope: Scope) -> np.ndarray:
    v = _in(ev, node, "in", scope)
    name = output[-1:] if output.startswith("out") else ""
    index = "rgba".find(name) if name in "rgba" else "xyzw".find(name)
    if not name or not 0 <= index < v.shape[-1]:
        raise MatremapError(f"{ev.path}: {node.getCategory()} {node.getName()!r} has no output {output!r}")
    return v[..., index : index + 1]


def _combine(ev: GraphEvaluator, node: Any, output: str, scope: Scope) -> np.ndarray:
    count = int(node.getCategory()[-1])
    parts = [_in(ev, node, f"in{i}", scope) for i in range(1, count + 1)]
    shape = np.broadcast_shapes(*(p.shape[:-1] for p in parts))
    return np.concatenate([np.broadcast_to(p, (*shape, p.shape[-1])) for p in parts], axis=-1)


def _convert(ev: GraphEvaluator, node: Any, output: str, scope: Scope) -> np.ndarray:
    n = CHANNELS.get(node.getType())
    if n is None:
        ev.refuse(node, scope, f"a conversion to {node.getType()}")
    return fit_channels(_in(ev, node, "in", scope), int(n or 1))


def _switch(ev: GraphEvaluator, node: Any, output: str, scope: Scope) -> Value:
    which = _uniform(_in(ev, node, "which", scope), f"{ev.path}: switch {node.getName()!r} which")
    index = min(max(math.floor(which) + 1, 1), 10)
    return ev.input(node, f"in{index}", node.getType(), scope)


def _rotate2d(ev: GraphEvaluator, node: Any, output: str, scope: Scope) -> np.ndarray:
    v = _in(ev, node, "in", scope)
    a = np.radians(_in(ev, node, "amount", scope)[..., :1])
    c, s = np.cos(a), np.sin(a)
    x, y = v[..., :1], v[..., 1:2]
    return np.concatenate([c * x + s * y, -s * x + c * y], axis=-1)


def _rgbtohsv(ev: GraphEvaluator, node: Any, output: str, scope: Scope) -> np.ndarray:
    v = _in(ev, node, "in", scope)
    return np.concatenate([rgb_to_hsv(v[..., :3]), v[..., 3:]], axis=-1)


def _hsvtorgb(ev: GraphEvaluator, node: Any, output: str, scope: Scope) -> np.ndarray:
    v = _in(ev, node, "in", scope)
    return np.concatenate([hsv_to_rgb(v[..., :3]), v[..., 3:]], axis=-1)


def _normalmap(ev: GraphEvaluator, node: Any, output: str, scope: Scope) -> Any:
    return ev.refuse(node, scope, "its output is a world-space normal, read only on a shader's normal input")


def rgb_to_hsv(rgb: np.ndarray) -> np.ndarray:
    """RGB -> HSV (Foley & van Dam's hexcone; H and S in [0, 1]), per texel of [..., 3]."""
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    mx, mn = np.max(rgb, axis=-1), np.min(rgb, axis=-1)
    d = mx - mn
    s = np.where(mx > 0, d / np.where(mx > 0, mx, 1.0), 0.0)
    safe = np.where(d > 0, d, 1.0)
    h = np.where(mx == r, (g - b) / safe, np.where(mx == g, 2.0 + (b - r) / safe, 4.0 + (r - g) / safe)) / 6.0
    h = np.where(s > 0, np.where(h < 0, h + 1.0, h), 0.0)
    return np.stack([h, s, mx], axis=-1)


def hsv_to_rgb(hsv: np.ndarray) -> np.ndarray:
    """HSV -> RGB (Foley & van Dam's hexcone; H wraps, S below 1e-4 is grey), per texel of [..., 3]."""
    h, s, v = hsv[..., 0], hsv[..., 1], hsv[..., 2]
    h6 = 6.0 * (h - np.floor(h))
    i = np.trunc(h6)
    f = h6 - i
    p, q, t = v * (1 - s), v * (1 - s * f), v * (1 - s * (1 - f))
    table = [(v, t, p), (q, v, p), (p, v, t), (p, q, v), (t, p, v), (v, p, q)]
    out = [np.select([i == k for k in range(5)], [row[c] for row in table[:5]], table[5][c]) for c in range(3)]
    grey = s < 1e-4
    return np.stack([np.where(grey, v, o) for o in out], axis=-1)


PRIMITIVES: dict[str, Callable[..., Value]] = {
    "image": _image,
    "constant": _constant,
    "texcoord": _texcoord,
    "add": _binary(np.add),
    "subtract": _binary(np.subtract),
    "multiply": _binary(np.multiply),
    "divide": _binary(np.divide),
    "min": _binary(np.minimum),
    "max": _binary(np.maximum),
    "mix": _mix,
    "clamp": _clamp,
    "dotproduct": _dotproduct,
    "dot": _passthrough,
    "extract": _extract,
    "separate2": _separate,
    "separate3": _separate,
    "separate4": _separate,
    "combine2": _combine,
    "combine3": _combine,
    "combine4": _combine,
    "convert": _convert,
    "switch": _switch,
    "rotate2d": _rotate2d,
    "rgbtohsv": _rgbtohsv,
    "hsvtorgb": _hsvtorgb,
    "normalmap": _normalmap,
}
#: what the evaluator reads, for messages: its primitives and the library graphs built on them
SUPPORTED = (
    *(k for k in PRIMITIVES if k != "normalmap"),
    "tiledimage",
    "place2d",
    "gltf_image",
    "gltf_colorimage",
    "normalmap (on a normal input)",
)

__all__ = [
    "CHANNELS",
    "MAX_SIDE",
    "PRIMITIVES",
    "PROBE",
    "PROCEDURAL_SIDE",
    "SUPPORTED",
    "Analysis",
    "FileRef",
    "GraphEvaluator",
    "ImageUse",
    "Scope",
    "fit_channels",
    "fit_image",
    "hsv_to_rgb",
    "parse_value",
    "rgb_to_hsv",
    "zero",
]
