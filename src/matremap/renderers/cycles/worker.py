"""The Blender Cycles worker: a persistent process that imports ``bpy`` and renders the probe scene.

Run by :class:`matremap.renderers.cycles.probe.CyclesRenderer` with the Python of a separate venv that
has ``bpy==5.0.1`` (``bpy`` pins numpy < 2, so it cannot share the main venv). This file imports
nothing from matremap: it is run as a script.

Protocol (binary, over the worker's stdin/stdout):

* request: 4-byte big-endian length, then that many bytes of UTF-8 JSON,
  ``{"op": "render", "scene": {...}, "materials": [{"model", "options", "values"}, ...]}``
  or ``{"op": "ping"}`` / ``{"op": "quit"}``, or ``{"op": "svbrdf", ...}`` (a textured sphere under an
  environment map, arrays passed as ``.npy`` files in ``dir``: see ``matremap.renderers.cycles.environment``),
  ``{"op": "write_blend", ...}`` (save a material on a UV sphere as a .blend: see
  ``matremap.formats.blend``), ``{"op": "inspect_blend", "path"}`` (what a .blend's materials and
  objects hold, as JSON) or ``{"op": "render_blend", "path", "scene"}`` (the probe scene's camera and
  lights around the object named ``sphere`` of a .blend, with its own material);
* reply: 4-byte big-endian length, then JSON ``{"ok": true, "nbytes": n}`` followed by ``n`` bytes
  of a ``.npy`` file (float32 [N, H, W, 3]), or ``{"ok": true, "info": {...}}`` with no payload
  (``write_blend``, ``inspect_blend``), or ``{"ok": false, "error": "..."}``.

Blender prints to stdout (``Saved: ...`` after each ``write_still``, and more from C code), so the
reply channel is a duplicate of the original fd 1 and fd 1 itself is pointed at stderr before
``bpy`` is imported.
"""

from __future__ import annotations

import io
import json
import math
import os
import struct
import sys
import tempfile
import traceback

# -- the channel: keep fd 1 for replies only, send everything else printed to stderr ---------------
_CHANNEL = os.fdopen(os.dup(1), "wb", buffering=0)
os.dup2(2, 1)
sys.stdout = sys.stderr

# this file's directory holds matremap's cycles.py, which would shadow Blender's `cycles` add-on
_HERE = os.path.dirname(os.path.abspath(__file__))
sys.path[:] = [p for p in sys.path if os.path.abspath(p or os.curdir) != _HERE]

import bpy  # noqa: E402
import numpy as np  # noqa: E402

DISTRIBUTIONS = {
    "ggx": "GGX",
    "beckmann": "BECKMANN",
    "ashikhmin_shirley": "ASHIKHMIN_SHIRLEY",
    "multi_ggx": "MULTI_GGX",
}


def _read_exact(f, n: int) -> bytes | None:
    buf = b""
    while len(buf) < n:
        chunk = f.read(n - len(buf))
        if not chunk:
            return None
        buf += chunk
    return buf


def _send(header: dict, payload: bytes = b"") -> None:
    data = json.dumps(header).encode()
    _CHANNEL.write(struct.pack(">I", len(data)) + data + payload)


class Probe:
    """The probe scene in Blender: rebuilt when the scene description changes."""

    def __init__(self) -> None:
        self.key: str | None = None
        # the client's scratch folder (it removes it, and a later run removes a killed run's)
        self.tmp = os.environ.get("MATREMAP_CYCLES_SCRATCH") or tempfile.mkdtemp(prefix="matremap-cycles-")
        self.materials: dict[str, tuple] = {}

    # -- scene ---------------------------------------------------------------------------------
    def build(self, s: dict) -> None:
        key = json.dumps(s, sort_keys=True)
        if key == self.key:
            return
        bpy.ops.wm.read_factory_settings(use_empty=True)
        self.materials = {}
        scene = bpy.context.scene
        self.res = _probe_settings(scene, s)
        self.sphere = self._sphere(float(s["sphere_radius"]), s.get("geometry", "points"))
        scene.collection.objects.link(self.sphere)
        if s.get("geometry", "points") == "points":
            scene.collection.objects.link(_occluder(float(s["sphere_radius"])))
        self.light, self.lights = _probe_light(scene, s)
        self.key = key

    def _sphere(self, radius: float, geometry: str):
        if geometry == "points":
            obj, self.set_material_node = _point_sphere("sphere", radius)
            return obj
        segments, rings = (int(x) for x in geometry.split("x")) if "x" in geometry else (512, 256)
        self.set_material_node = None
        bpy.ops.mesh.primitive_uv_sphere_add(segments=segments, ring_count=rings, radius=radius)
        obj = bpy.context.active_object
        for c in list(obj.users_collection):
            c.objects.unlink(obj)
        obj.data.shade_smooth()
        return obj

    # -- materials ---------------------------------------------------------------------------------
    def material(self, model: str, options: dict):
        key = json.dumps([model, options], sort_keys=True)
        hit = self.materials.get(key)
        if hit is not None:
            return hit
        mat = bpy.data.materials.new(key[:60])
        mat.use_nodes = True
        nt = mat.node_tree
        for n in list(nt.nodes):
            nt.nodes.remove(n)
        sockets, _ = _material_nodes(nt, model, options)
        hit = (mat, sockets)
        self.materials[key] = hit
        return hit

    def assign(self, mat) -> None:
        if self.set_material_node is not None:
            if self.set_material_node.inputs["Material"].default_value != mat:
                self.set_material_node.inputs["Material"].default_value = mat
        else:
            if self.sphere.data.materials:
                if self.sphere.data.materials[0] != mat:
                    self.sphere.data.materials[0] = mat
            else:
                self.sphere.data.materials.append(mat)

    # -- rendering ---------------------------------------------------------------------------------
    def render(self, request: dict) -> np.ndarray:
        self.build(request["scene"])
        res = self.res
        mats = request["materials"]
        out = np.zeros((len(mats), res, res, 3), dtype=np.float32)
        path = os.path.join(self.tmp, "render.exr")
        scene = bpy.context.scene
        for i, m in enumerate(mats):
            mat, sockets = self.material(m["model"], m.get("options", {}))
            for name, socket in sockets.items():
                v = m["values"][name]
                if socket.type == "RGBA":
                    rgb = [float(x) for x in v] * (3 if len(v) == 1 else 1)
                    socket.default_value = (*rgb, 1.0)
                else:
                    socket.default_value = float(v[0])
            self.assign(mat)
            out[i] = _render_lights(scene, self.light, self.lights, res, path)
        return out


def _point_sphere(name: str, radius: float):
    """A point cloud of one point, which Cycles intersects as a true sphere (exact normals), and the Set
    Material node that gives it its material."""
    mesh = bpy.data.meshes.new(f"{name}_vertex")
    mesh.from_pydata([(0.0, 0.0, 0.0)], [], [])
    obj = bpy.data.objects.new(name, mesh)
    tree = bpy.data.node_groups.new(f"{name}_to_points", "GeometryNodeTree")
    tree.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    n_in = tree.nodes.new("NodeGroupInput")
    n_out = tree.nodes.new("NodeGroupOutput")
    to_points = tree.nodes.new("GeometryNodeMeshToPoints")
    to_points.inputs["Radius"].default_value = radius
    set_material = tree.nodes.new("GeometryNodeSetMaterial")
    tree.links.new(n_in.outputs[0], to_points.inputs["Mesh"])
    tree.links.new(to_points.outputs["Points"], set_material.inputs["Geometry"])
    tree.links.new(set_material.outputs["Geometry"], n_out.inputs[0])
    mod = obj.modifiers.new("to_points", "NODES")
    mod.node_group = tree
    return obj, set_material


#: the occluder's radius, relative to the probe sphere's
OCCLUDER_SCALE = 1.0 - 1e-6


def _occluder(radius: float):
    """An opaque sphere just inside the point-cloud probe sphere, unseen by the camera: Cycles skips a shadow
    ray's own primitive, and the probe sphere is one primitive, so without it a light below a pixel's horizon
    would reach a transmissive material (glass) straight through the sphere. A shadow ray towards a light
    above the horizon moves away from the centre and never meets it; one below is blocked unless it passes
    within sqrt(2e-5) rad (0.26 degrees) of the tangent plane."""
    obj, _ = _point_sphere("occluder", radius * OCCLUDER_SCALE)
    obj.visible_camera = False
    return obj


def _probe_settings(scene, s: dict) -> int:
    """Cycles set up for the probe scene (CPU, 1 spp through pixel centres, direct light only, no
    world, EXR output) and its camera; returns the resolution."""
    scene.render.engine = "CYCLES"
    cy = scene.cycles
    cy.device = "CPU"
    cy.samples = 1
    cy.use_adaptive_sampling = False
    cy.use_denoising = False
    cy.seed = 0
    cy.use_animated_seed = False
    cy.filter_width = 0.01
    cy.film_exposure = 1.0
    cy.max_bounces = 0  # direct light only: the probe sphere is convex
    cy.light_sampling_threshold = 0.0  # no stochastic termination of dim light samples
    cy.sample_clamp_direct = 0.0
    cy.sample_clamp_indirect = 0.0
    if hasattr(cy, "use_light_tree"):
        cy.use_light_tree = False
    scene.render.use_persistent_data = True
    res = int(s["resolution"])
    scene.render.resolution_x = res
    scene.render.resolution_y = res
    scene.render.resolution_percentage = 100
    scene.render.film_transparent = False
    scene.render.use_compositing = False
    scene.render.use_sequencer = False
    scene.world = None  # black background, no environment light
    _exr_output(scene)
    _add_camera(bpy, scene, s)
    return res


def _probe_light(scene, s: dict):
    """One point light, moved and re-powered per scene light (renders are summed): Cycles samples one
    light per sample, which would make multi-light renders noisy. Returns (object, [(position, power)])."""
    light_data = bpy.data.lights.new("light", type="POINT")
    light_data.shadow_soft_size = 0.0
    if hasattr(light_data, "use_soft_falloff"):
        light_data.use_soft_falloff = False
    light_data.color = (1.0, 1.0, 1.0)
    light = bpy.data.objects.new("light", light_data)
    scene.collection.objects.link(light)
    lights = [(tuple(map(float, lt["position"])), 4.0 * math.pi * float(lt["intensity"])) for lt in s["lights"]]
    return light, lights


def _render_lights(scene, light, lights, res: int, path: str) -> np.ndarray:
    """The sum of one render per (position, power) of the light -> float32 [res, res, 3]."""
    out = np.zeros((res, res, 3), dtype=np.float32)
    for pos, power in lights:
        light.location = pos
        light.data.energy = power
        out += _render_still(scene, path, res)
    return out


def _render_still(scene, path: str, res: int) -> np.ndarray:
    """Render ``scene`` to the EXR ``path`` and read it back: linear RGB float32 [res, res, 3], top row first."""
    scene.render.filepath = path
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(path, check_existing=False)
    try:
        buf = np.empty(res * res * 4, dtype=np.float32)
        img.pixels.foreach_get(buf)
    finally:
        bpy.data.images.remove(img)
    return buf.reshape(res, res, 4)[::-1, :, :3]


# -- SVBRDF renders under an environment map (op "svbrdf"; see matremap.renderers.cycles.environment) --------


def _float_image(name: str, arr: np.ndarray, repeat: bool = False):
    """A linear (Non-Color) float image from an array [h, w, 3], row 0 at the top."""
    a = np.asarray(arr, dtype=np.float32)
    h, w = a.shape[:2]
    rgba = np.ones((h, w, 4), dtype=np.float32)
    rgba[..., :3] = a[::-1]  # Blender stores the bottom row first
    img = bpy.data.images.new(name, w, h, alpha=True, float_buffer=True)
    img.colorspace_settings.name = "Non-Color"
    img.pixels.foreach_set(rgba.ravel())
    img.update()
    return img


def _uv_sphere(radius: float, segments: int, rings: int):
    """A smooth UV sphere with its pole along +y and the embedded renderer's UVs:
    u = 0.5 + atan2(x, z) / 2 pi, v (from the top) = acos(y / r) / pi; Blender's v = 1 - that."""
    # built from arrays: bpy.ops.mesh.primitive_uv_sphere_add takes 17 s at 512x256
    S, R = segments, rings
    theta = math.pi * np.arange(1, R) / R
    phi = 2.0 * math.pi * np.arange(S) / S
    st = np.sin(theta)[:, None]
    ring = radius * np.stack(np.broadcast_arrays(st * np.sin(phi), np.cos(theta)[:, None], st * np.cos(phi)), -1)
    verts = np.concatenate([[(0.0, radius, 0.0), (0.0, -radius, 0.0)], ring.reshape(-1, 3)])

    def vid(k, j):  # ring k in 1..R-1, segment j (mod S)
        return 2 + (k - 1) * S + np.mod(j, S)

    j = np.arange(S)
    top = np.stack([np.zeros(S, dtype=np.int64), vid(1, j), vid(1, j + 1)], -1)
    bottom = np.stack([vid(R - 1, j), np.ones(S, dtype=np.int64), vid(R - 1, j + 1)], -1)
    k = np.arange(1, R - 1)[:, None]
    quads = np.stack([vid(k, j), vid(k + 1, j), vid(k + 1, j + 1), vid(k, j + 1)], -1).reshape(-1, 4)
    loops = np.concatenate([top.ravel(), quads.ravel(), bottom.ravel()])
    sizes = np.concatenate([np.full(S, 3), np.full(len(quads), 4), np.full(S, 3)])
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    mesh = bpy.data.meshes.new("sphere")
    mesh.vertices.add(len(verts))
    mesh.vertices.foreach_set("co", verts.astype(np.float32).ravel())
    mesh.loops.add(len(loops))
    mesh.loops.foreach_set("vertex_index", loops.astype(np.int32))
    mesh.polygons.add(len(sizes))
    mesh.polygons.foreach_set("loop_start", starts.astype(np.int32))
    mesh.update(calc_edges=True)
    obj = bpy.data.objects.new("sphere", mesh)
    bpy.context.scene.collection.objects.link(obj)
    co_flat = np.empty(len(mesh.vertices) * 3)
    mesh.vertices.foreach_get("co", co_flat)
    co = co_flat.reshape(-1, 3)
    vi = np.empty(len(mesh.loops), dtype=np.int64)
    mesh.loops.foreach_get("vertex_index", vi)
    start = np.empty(len(mesh.polygons), dtype=np.int64)
    total = np.empty(len(mesh.polygons), dtype=np.int64)
    mesh.polygons.foreach_get("loop_start", start)
    mesh.polygons.foreach_get("loop_total", total)
    face_of_loop = np.repeat(np.arange(len(start)), total)
    centre = np.zeros((len(start), 3))
    np.add.at(centre, face_of_loop, co[vi])
    centre /= total[:, None]
    uc = 0.5 + np.arctan2(centre[:, 0], centre[:, 2]) / (2.0 * math.pi)
    p = co[vi]
    u = 0.5 + np.arctan2(p[:, 0], p[:, 2]) / (2.0 * math.pi)
    ucl = uc[face_of_loop]
    u = ucl + (np.mod(u - ucl + 0.5, 1.0) - 0.5)  # unwrap across the seam at the back
    pole = np.hypot(p[:, 0], p[:, 2]) < 1e-9 * radius
    u = np.where(pole, ucl, u)
    v = np.arccos(np.clip(p[:, 1] / radius, -1.0, 1.0)) / math.pi
    if not mesh.uv_layers:
        mesh.uv_layers.new(name="UVMap")
    uv = mesh.uv_layers.active
    uv.data.foreach_set("uv", np.stack([u, 1.0 - v], axis=-1).astype(np.float32).ravel())
    mesh.shade_smooth()
    mesh.update()
    return obj, uv.name


def _exr_output(scene) -> None:
    """Linear float pixels: 32-bit uncompressed EXR, no view transform, no exposure."""
    im = scene.render.image_settings
    im.file_format = "OPEN_EXR"
    im.color_depth = "32"
    im.exr_codec = "NONE"
    im.color_mode = "RGBA"
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    scene.view_settings.look = "None"


def _add_camera(bpy, scene, s: dict) -> None:
    """The probe camera: at (0, 0, d) looking down -z, +y up (Blender's default camera orientation),
    the scene's field of view across the image width."""
    cam_data = bpy.data.cameras.new("camera")
    cam_data.type = "PERSP"
    cam_data.sensor_fit = "HORIZONTAL"
    cam_data.angle = math.radians(float(s["fov"]))
    cam_data.clip_start = 1e-3
    cam_data.clip_end = 10.0 * (float(s["camera_distance"]) + float(s["sphere_radius"]))
    cam = bpy.data.objects.new("camera", cam_data)
    cam.location = (0.0, 0.0, float(s["camera_distance"]))
    cam.rotation_euler = (0.0, 0.0, 0.0)
    scene.collection.objects.link(cam)
    scene.camera = cam


def _svbrdf_settings(scene, spp: int, seed: int, res: int) -> None:
    """Cycles settings of the environment renders: CPU, ``spp`` samples, fixed seed, one ray through each
    pixel centre, direct light only, transparent (black) background."""
    scene.render.engine = "CYCLES"
    cy = scene.cycles
    cy.device = "CPU"
    cy.samples = int(spp)
    cy.use_adaptive_sampling = False
    cy.use_denoising = False
    cy.seed = int(seed)
    cy.use_animated_seed = False
    cy.filter_width = 0.01  # one ray through each pixel centre, as the embedded renderer
    cy.film_exposure = 1.0
    cy.max_bounces = 0  # direct light only: the sphere is convex
    cy.sample_clamp_direct = 0.0
    cy.sample_clamp_indirect = 0.0
    scene.render.use_persistent_data = False
    scene.render.resolution_x = res
    scene.render.resolution_y = res
    scene.render.resolution_percentage = 100
    scene.render.film_transparent = True  # black background (RGB 0 where alpha is 0)
    scene.render.use_compositing = False
    scene.render.use_sequencer = False


def _svbrdf_material(request: dict, uv_name: str, load):
    """The textured material: the model's nodes, an Image Texture per map (Linear, Extend; scalars
    through the red channel), constants on the other sockets, and the tangent-space normal map."""
    mat = bpy.data.materials.new("svbrdf")
    mat.use_nodes = True
    nt = mat.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    sockets, bsdfs = _material_nodes(nt, request["model"], request.get("options", {}))
    uvmap = nt.nodes.new("ShaderNodeUVMap")
    uvmap.uv_map = uv_name

    def texture(name, arr):
        node = nt.nodes.new("ShaderNodeTexImage")
        node.image = _float_image(name, arr if arr.ndim == 3 else np.repeat(arr[..., None], 3, axis=2))
        node.interpolation = "Linear"
        node.extension = "EXTEND"
        nt.links.new(uvmap.outputs["UV"], node.inputs["Vector"])
        return node

    for name, socket in sockets.items():
        if name in request["textures"]:
            node = texture(name, load("tex_" + request["textures"][name]))
            if socket.type == "RGBA":
                nt.links.new(node.outputs["Color"], socket)
            else:  # a scalar: the red channel (R = G = B)
                sep = nt.nodes.new("ShaderNodeSeparateColor")
                nt.links.new(node.outputs["Color"], sep.inputs["Color"])
                nt.links.new(sep.outputs["Red"], socket)
        else:
            v = request["consts"][name]
            if socket.type == "RGBA":
                socket.default_value = (*([float(x) for x in v] * (3 if len(v) == 1 else 1)), 1.0)
            else:
                socket.default_value = float(v[0])
    if request.get("normal_map"):
        node = texture("normal_map", load("normal_map"))  # (n + 1) / 2, tangent space, y up
        nmap = nt.nodes.new("ShaderNodeNormalMap")
        nmap.space = "TANGENT"
        nmap.uv_map = uv_name
        nt.links.new(node.outputs["Color"], nmap.inputs["Color"])
        for b in bsdfs:
            nt.links.new(nmap.outputs["Normal"], b.inputs["Normal"])
    return mat


def _environment_world(radiance: np.ndarray, rotation_deg: float):
    """The world: Blender's equirectangular lookup of e = M R_y(-rotation) d, with M = (-z, -x, y), puts
    Blender's u on matremap's u and Blender's up (z) on matremap's +y."""
    world = bpy.data.worlds.new("env")
    world.use_nodes = True
    wt = world.node_tree
    for n in list(wt.nodes):
        wt.nodes.remove(n)
    wout = wt.nodes.new("ShaderNodeOutputWorld")
    bg = wt.nodes.new("ShaderNodeBackground")
    bg.inputs["Strength"].default_value = 1.0
    env = wt.nodes.new("ShaderNodeTexEnvironment")
    env.image = _float_image("env", radiance)
    env.interpolation = "Linear"
    env.projection = "EQUIRECTANGULAR"
    coords = wt.nodes.new("ShaderNodeTexCoord")
    a = math.radians(-float(rotation_deg))
    c, si = math.cos(a), math.sin(a)
    # d' = R_y(a) d: x' = c x + s z, y' = y, z' = -s x + c z
    rows = ((si, 0.0, -c), (-c, 0.0, -si), (0.0, 1.0, 0.0))  # (-z', -x', y')
    comb = wt.nodes.new("ShaderNodeCombineXYZ")
    for k, row in enumerate(rows):
        dot = wt.nodes.new("ShaderNodeVectorMath")
        dot.operation = "DOT_PRODUCT"
        dot.inputs[1].default_value = row
        wt.links.new(coords.outputs["Generated"], dot.inputs[0])
        wt.links.new(dot.outputs["Value"], comb.inputs[k])
    wt.links.new(comb.outputs["Vector"], env.inputs["Vector"])
    wt.links.new(env.outputs["Color"], bg.inputs["Color"])
    wt.links.new(bg.outputs["Background"], wout.inputs["Surface"])
    return world


def render_svbrdf(request: dict, tmp: str) -> np.ndarray:
    """One textured sphere under an environment map -> float32 [1, res, res, 3]."""
    s = request["scene"]
    res = int(s["resolution"])
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    _svbrdf_settings(scene, request["spp"], request["seed"], res)
    _exr_output(scene)
    _add_camera(bpy, scene, s)

    def load(name):
        return np.load(os.path.join(request["dir"], name + ".npy"))

    segments, rings = (int(x) for x in request.get("geometry", "512x256").split("x"))
    sphere, uv_name = _uv_sphere(float(s["sphere_radius"]), segments, rings)
    sphere.data.materials.append(_svbrdf_material(request, uv_name, load))
    if sphere.name not in scene.collection.objects:
        scene.collection.objects.link(sphere)
    scene.world = _environment_world(load("env"), request["rotation_deg"])
    return _render_still(scene, os.path.join(tmp, "svbrdf.exr"), res)[None].copy()


# -- .blend files (ops "write_blend", "inspect_blend", "render_blend"; see matremap.formats.blend) ------


#: the Principled BSDF inputs the cycles:principled dialect sets (its parameter names)
PRINCIPLED_SOCKETS = (
    "Base Color",
    "Metallic",
    "Roughness",
    "IOR",
    "Specular IOR Level",
    "Specular Tint",
    "Coat Weight",
    "Coat Roughness",
    "Coat IOR",
    "Coat Tint",
    "Sheen Weight",
    "Sheen Roughness",
    "Sheen Tint",
    "Transmission Weight",
)


def _material_nodes(nt, model: str, options: dict) -> tuple[dict, list]:
    """Build a model's BSDF nodes into an emptied node tree, wired to a Material Output; returns
    (parameter name -> input socket, the BSDF nodes that take a normal)."""
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    out.location = (400, 0)
    if model == "cycles:principled":
        p = nt.nodes.new("ShaderNodeBsdfPrincipled")
        p.distribution = DISTRIBUTIONS[options.get("distribution", "multi_ggx")]
        nt.links.new(p.outputs[0], out.inputs["Surface"])
        sockets = {n: p.inputs[n] for n in PRINCIPLED_SOCKETS}
        return sockets, [p]
    if model == "cycles:glossy":
        glossy = nt.nodes.new("ShaderNodeBsdfGlossy")
        glossy.distribution = DISTRIBUTIONS[options.get("distribution", "ggx")]
        glossy.location = (0, 150)
        diffuse = nt.nodes.new("ShaderNodeBsdfDiffuse")
        diffuse.inputs["Roughness"].default_value = 0.0
        diffuse.location = (0, -150)
        add = nt.nodes.new("ShaderNodeAddShader")
        add.location = (200, 0)
        nt.links.new(glossy.outputs[0], add.inputs[0])
        nt.links.new(diffuse.outputs[0], add.inputs[1])
        nt.links.new(add.outputs[0], out.inputs["Surface"])
        return (
            {
                "Color": glossy.inputs["Color"],
                "Roughness": glossy.inputs["Roughness"],
                "Diffuse Color": diffuse.inputs["Color"],
            },
            [glossy, diffuse],
        )
    if model == "cycles:diffuse":
        diffuse = nt.nodes.new("ShaderNodeBsdfDiffuse")
        diffuse.inputs["Roughness"].default_value = 0.0
        nt.links.new(diffuse.outputs[0], out.inputs["Surface"])
        return {"Color": diffuse.inputs["Color"]}, [diffuse]
    raise ValueError(f"the Cycles worker cannot build model {model}")


def _set_socket(socket, v) -> None:
    if socket.type == "RGBA":
        socket.default_value = (*([float(x) for x in v] * (3 if len(v) == 1 else 1)), 1.0)
    else:
        socket.default_value = float(v[0])


def write_blend(request: dict) -> dict:
    """A new file holding one material (``name``) on a smooth UV sphere (the SVBRDF renders' sphere:
    pole along +y, matremap's UVs) and the probe camera; image textures are packed into the file."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    s = request["scene"]
    scene.render.resolution_x = scene.render.resolution_y = int(s["resolution"])
    _add_camera(bpy, scene, s)
    segments, rings = (int(x) for x in request.get("geometry", "128x64").split("x"))
    sphere, uv_name = _uv_sphere(float(s["sphere_radius"]), segments, rings)

    mat = bpy.data.materials.new(request["name"])
    mat.use_nodes = True
    nt = mat.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    sockets, bsdfs = _material_nodes(nt, request["model"], request.get("options", {}))
    y = 300
    uvmap = None

    def texture(label: str, tex: dict):
        nonlocal y, uvmap
        if uvmap is None:
            uvmap = nt.nodes.new("ShaderNodeUVMap")
            uvmap.uv_map = uv_name
            uvmap.location = (-900, 0)
        img = bpy.data.images.load(tex["path"], check_existing=False)
        img.name = label
        img.colorspace_settings.name = tex["colorspace"]
        img.pack()
        node = nt.nodes.new("ShaderNodeTexImage")
        node.name = node.label = label
        node.image = img
        node.interpolation = "Linear"
        node.extension = "EXTEND"
        node.location = (-600, y)
        y -= 300
        nt.links.new(uvmap.outputs["UV"], node.inputs["Vector"])
        return node

    for name, socket in sockets.items():
        if name in request["textures"]:
            node = texture(name, request["textures"][name])
            nt.links.new(node.outputs["Color"], socket)
        elif name in request["consts"]:
            _set_socket(socket, request["consts"][name])
    if request.get("normal"):
        node = texture("Normal", request["normal"])
        nmap = nt.nodes.new("ShaderNodeNormalMap")
        nmap.space = "TANGENT"
        nmap.uv_map = uv_name
        nmap.location = (-250, y + 300)
        nt.links.new(node.outputs["Color"], nmap.inputs["Color"])
        for b in bsdfs:
            nt.links.new(nmap.outputs["Normal"], b.inputs["Normal"])
    sphere.data.materials.append(mat)
    bpy.context.preferences.filepaths.save_version = 0  # no ".blend1" backup of the file replaced
    bpy.ops.wm.save_as_mainfile(filepath=request["path"], check_existing=False, compress=True, copy=True)
    return {"material": mat.name, "object": sphere.name, "vertices": len(sphere.data.vertices)}


def _value(v):
    try:
        return [float(x) for x in v]
    except TypeError:
        return float(v) if isinstance(v, (int, float)) else str(v)


def inspect_blend(request: dict) -> dict:
    """What a .blend holds: per material its nodes (type, settings, unlinked input values, image
    colour space and packing) and links; per mesh object its material slots and UV layers."""
    bpy.ops.wm.open_mainfile(filepath=request["path"])
    materials = {}
    for mat in bpy.data.materials:
        if mat.node_tree is None:
            continue
        nodes = {}
        for n in mat.node_tree.nodes:
            d = {
                "type": n.bl_idname,
                "inputs": {
                    i.identifier: _value(i.default_value)
                    for i in n.inputs
                    if not i.is_linked and hasattr(i, "default_value")
                },
            }
            for attr in ("distribution", "space", "uv_map", "interpolation", "extension"):
                if hasattr(n, attr):
                    d[attr] = getattr(n, attr)
            if getattr(n, "image", None) is not None:
                img = n.image
                d["image"] = {
                    "name": img.name,
                    "colorspace": img.colorspace_settings.name,
                    "packed": img.packed_file is not None,
                    "size": list(img.size),
                }
            nodes[n.name] = d
        links = [
            [lk.from_node.name, lk.from_socket.identifier, lk.to_node.name, lk.to_socket.identifier]
            for lk in mat.node_tree.links
        ]
        materials[mat.name] = {"nodes": nodes, "links": links}
    objects = {
        o.name: {
            "type": o.type,
            "materials": [m.name for m in o.data.materials if m is not None],
            "uv_layers": [uv.name for uv in o.data.uv_layers],
            "vertices": len(o.data.vertices),
        }
        for o in bpy.data.objects
        if o.type == "MESH"
    }
    return {"materials": materials, "objects": objects}


def render_blend(request: dict, tmp: str) -> np.ndarray:
    """Open a .blend and render its object ``sphere`` (with the file's own material) in the probe
    set-up: the probe camera and point lights, Cycles as for the probe -> float32 [1, res, res, 3]."""
    bpy.ops.wm.open_mainfile(filepath=request["path"])
    scene = bpy.context.scene
    for o in list(scene.objects):  # keep the sphere only: the probe brings its own camera and lights
        if o.name != "sphere":
            bpy.data.objects.remove(o)
    if "sphere" not in scene.objects:
        raise ValueError(f"{request['path']} has no object named 'sphere'")
    s = request["scene"]
    res = _probe_settings(scene, s)
    light, lights = _probe_light(scene, s)
    return _render_lights(scene, light, lights, res, os.path.join(tmp, "blend.exr"))[None]


def main() -> int:
    probe = Probe()
    stdin = sys.stdin.buffer
    _send({"ok": True, "ready": True, "blender": bpy.app.version_string})
    while True:
        head = _read_exact(stdin, 4)
        if head is None:
            return 0
        (n,) = struct.unpack(">I", head)
        body = _read_exact(stdin, n)
        if body is None:
            return 0
        try:
            request = json.loads(body)
            op = request.get("op")
            if op == "quit":
                _send({"ok": True})
                return 0
            if op == "ping":
                _send({"ok": True, "pid": os.getpid()})
                continue
            if op in ("svbrdf", "write_blend", "inspect_blend", "render_blend"):
                probe.key = None  # these replace Blender's data: the probe scene is rebuilt on its next request
                probe.materials = {}
            if op in ("write_blend", "inspect_blend"):
                _send({"ok": True, "info": (write_blend if op == "write_blend" else inspect_blend)(request)})
                continue
            if op == "svbrdf":
                images = render_svbrdf(request, probe.tmp)
            elif op == "render_blend":
                images = render_blend(request, probe.tmp)
            elif op == "render":
                images = probe.render(request)
            else:
                raise ValueError(f"unknown request {op!r}")
            f = io.BytesIO()
            np.save(f, images)
            payload = f.getvalue()
            _send({"ok": True, "nbytes": len(payload)}, payload)
        except Exception as e:  # reported to the parent, which raises MatremapError
            traceback.print_exc()
            _send({"ok": False, "error": f"{type(e).__name__}: {e}"})


if __name__ == "__main__":
    sys.exit(main())
