"""A World's node tree -> an equirectangular environment image (the world baked once per
change, cached by content), for shading.World.environment.

The world is a function of the direction alone, so its node tree is evaluated here in numpy
at the directions of an image's pixel centres, once, and the core looks the image up and
samples it as a light. What the bake reads:
- Background and Emission (Color x Strength), Mix Shader (its Factor), Add Shader.
- Environment Texture: Equirectangular and Mirror Ball; Closest, and Linear for the other
  interpolations (Cubic and Smart are approximated by Linear, said once); its image read
  as material images are (images.py: one rule for colour spaces; sRGB decoded after
  interpolation, as Cycles does).
- Vectors: Texture Coordinate (Generated, Object without an object, Normal: the direction,
  as Cycles gives them in a world), Mapping (Point, Texture, Vector, Normal with Location,
  Euler XYZ Rotation and Scale), unlinked: the direction.
- Light Path > Is Camera Ray: the tree is evaluated twice, for camera rays and for the
  others; when the two differ the camera gets its own image (the usual trick of a visible
  backdrop other than the light).
- RGB and Value nodes. Anything else linked falls back to the socket's default value, said
  once with the node's name.
- Sky Texture: Single and Multiple Scattering from their physical model as Cycles computes
  them (render/sky.py: every setting of the node), the sun disc drawn, or its power spread
  over the pixels that carry it when it is smaller than a few pixels of the bake (said once);
  Preetham and Hosek-Wilkie from their analytic functions (render/sky.py: LegacySky).
The image is as large as the largest Environment Texture image (at most MAX_WIDTH wide), so
that an equirectangular HDRI without mapping is baked pixel for pixel; BAKE_WIDTH otherwise.
"""
from __future__ import annotations

import hashlib
import math
from typing import Optional

import numpy as np

from . import images as _images
from .sockets import fmt as _fmt

BAKE_WIDTH = 1024  # a procedural world's image: 1024 x 512, ~0.35 degree a pixel
MAX_WIDTH = 4096   # an HDRI wider than this is baked at this width (4096 x 2048: 100 MB in the core)
_BLOCK = 1 << 16   # directions evaluated at once: bounds the bake's temporary arrays to some 10 MB
_CACHE_SIZE = 2    # bakes kept: the world being edited and the one before it (undo)
_cache: dict = {}
BAKED_NODES = ("TEX_ENVIRONMENT", "TEX_SKY", "LIGHT_PATH")  # what makes a world vary: baked


def _unit_directions(width: int, height: int, rows: range = None) -> np.ndarray:
    """The directions of an equirectangular image's pixel centres, (rows, width, 3), row 0
    at the nadir: shading.World.environment's layout (Cycles' orientation)."""
    u = (np.arange(width) + 0.5) / width
    v = ((np.arange(height) if rows is None else np.asarray(rows)) + 0.5) / height
    phi = (0.5 - u)[None, :] * 2.0 * np.pi
    elevation = (v - 0.5)[:, None] * np.pi
    c = np.cos(elevation)
    return np.stack(np.broadcast_arrays(c * np.cos(phi), c * np.sin(phi), np.sin(elevation) + 0 * phi), axis=-1)


def _euler_xyz(rotation) -> np.ndarray:
    """Blender's Euler XYZ rotation matrix: Rz @ Ry @ Rx."""
    x, y, z = (float(a) for a in rotation)
    cx, sx, cy, sy, cz, sz = math.cos(x), math.sin(x), math.cos(y), math.sin(y), math.cos(z), math.sin(z)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


class _Bake:
    """One evaluation of a world's tree at `directions` (N, 3), for camera rays or not."""

    def __init__(self, sockets, upstream, directions: np.ndarray, camera: bool, images: dict, grid=None):
        self.sockets, self.upstream = sockets, upstream
        self.grid = grid  # (width, height) of the equirectangular image being baked, or None
        self.d, self.camera, self.images = directions, camera, images
        self.uses_camera = False  # whether Is Camera Ray was read

    # Shaders -> radiance (N, 3).
    def shader(self, socket) -> np.ndarray:
        source = self.upstream(socket)
        if source is None:
            return np.zeros((len(self.d), 3))
        node = source[0]
        if node.type in ("BACKGROUND", "EMISSION"):
            return self.colour(node.inputs["Color"]) * self.value(node.inputs["Strength"])[:, None]
        if node.type == "MIX_SHADER":
            fac = np.clip(self.value(node.inputs[0]), 0.0, 1.0)[:, None]
            return (1.0 - fac) * self.shader(node.inputs[1]) + fac * self.shader(node.inputs[2])
        if node.type == "ADD_SHADER":
            return self.shader(node.inputs[0]) + self.shader(node.inputs[1])
        self.sockets.say(f": the '{node.bl_label}' shader '{node.name}' is not supported in a world; rendered black")
        return np.zeros((len(self.d), 3))

    # Values -> (N,) and colours -> (N, 3).
    def value(self, socket) -> np.ndarray:
        out = self._linked(socket)
        if out is None:
            return np.full(len(self.d), float(socket.default_value))
        return out if out.ndim == 1 else out @ np.array([0.2126, 0.7152, 0.0722])  # a colour into a value: its luminance

    def colour(self, socket) -> np.ndarray:
        out = self._linked(socket)
        if out is None:
            return np.broadcast_to(np.array(socket.default_value[:3], np.float64), (len(self.d), 3))
        return out if out.ndim == 2 else np.repeat(out[:, None], 3, axis=1)

    def _linked(self, socket) -> Optional[np.ndarray]:
        """What feeds an input: its node's output evaluated, or None (unlinked, or a node the
        bake does not know: the input's default value, said once)."""
        source = self.upstream(socket)
        if source is None:
            return None
        node, output = source
        if node.type == "TEX_ENVIRONMENT":
            return self.environment(node, output.name)
        if node.type == "TEX_SKY":
            return self.sky(node)
        if node.type == "LIGHT_PATH" and output.name == "Is Camera Ray":
            self.uses_camera = True
            return np.full(len(self.d), 1.0 if self.camera else 0.0)
        if node.type == "RGB":
            return np.broadcast_to(np.array(output.default_value[:3], np.float64), (len(self.d), 3))
        if node.type == "VALUE":
            return np.full(len(self.d), float(output.default_value))
        self.sockets.say(f": {socket.name} is driven by a '{node.bl_label}' node ('{node.name}'), which the world "
                         f"bake does not evaluate; using the default value {_fmt(socket.default_value)}")
        return None

    # Vectors -> (N, 3).
    def vector(self, socket) -> np.ndarray:
        source = self.upstream(socket)
        if source is None:
            return self.d
        node, output = source
        if node.type == "TEX_COORD" and output.name in ("Generated", "Normal", "Object") and \
                not (output.name == "Object" and node.object is not None):
            return self.d
        if node.type == "MAPPING":
            return self.mapping(node)
        self.sockets.say(f": the {output.name} output of '{node.bl_label}' ('{node.name}') is not evaluated "
                         f"in a world; the view direction is used instead")
        return self.d

    def mapping(self, node) -> np.ndarray:
        v = self.vector(node.inputs["Vector"])
        kind = node.vector_type

        def const(name):
            if self.upstream(node.inputs[name]) is not None:
                self.sockets.say(f": the Mapping's {name} is driven by a node; using its default value")
            return np.array(node.inputs[name].default_value[:3], np.float64) if name in node.inputs else np.zeros(3)
        rot = _euler_xyz(const("Rotation"))
        scale = const("Scale") if "Scale" in node.inputs else np.ones(3)
        loc = const("Location") if "Location" in node.inputs else np.zeros(3)
        # Blender's Mapping node (its documented definitions).
        if kind == "POINT":
            return (v * scale) @ rot.T + loc
        if kind == "TEXTURE":
            with np.errstate(divide="ignore", invalid="ignore"):
                return np.nan_to_num(((v - loc) @ rot) / scale)
        if kind == "VECTOR":
            return (v * scale) @ rot.T
        with np.errstate(divide="ignore", invalid="ignore"):  # NORMAL
            n = np.nan_to_num((v / scale) @ rot.T)
        return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)

    def environment(self, node, output: str) -> np.ndarray:
        image = node.image
        if image is None:  # Cycles' missing image colour
            return np.broadcast_to(np.array([1.0, 0.0, 1.0]), (len(self.d), 3)) if output == "Color" \
                else np.zeros(len(self.d))
        pixels = self.images[image.name]
        v = self.vector(node.inputs["Vector"])
        length = np.maximum(np.linalg.norm(v, axis=1), 1e-30)
        d = v / length[:, None]
        if node.projection == "MIRROR_BALL":
            # The inverse of the mirror ball's mapping (a sphere seen from -y): the point of the
            # ball whose reflection goes towards d, on the ball's image plane (x, z).
            b = d - np.array([0.0, 1.0, 0.0])
            div = 2.0 * np.sqrt(np.maximum(-0.5 * b[:, 1], 0.0))
            with np.errstate(divide="ignore", invalid="ignore"):
                b = np.where(div[:, None] > 0, b / div[:, None], b)
            u, w = 0.5 * (b[:, 0] + 1.0), 0.5 * (b[:, 2] + 1.0)
        else:
            u = 0.5 - np.arctan2(d[:, 1], d[:, 0]) / (2.0 * np.pi)
            w = 0.5 + np.arctan2(d[:, 2], np.hypot(d[:, 0], d[:, 1])) / np.pi
        rgba = _sample(pixels.values, u, w, node.interpolation == "Closest")
        rgba[:, :3] = _images.decode(rgba[:, :3], pixels.srgb)
        if node.interpolation in ("Cubic", "Smart"):
            self.sockets.say(f": the Environment Texture '{node.name}' uses {node.interpolation} interpolation; "
                             f"baked with Linear")
        return rgba[:, :3] if output == "Color" else rgba[:, 3]


    def sky(self, node) -> np.ndarray:
        """The Sky Texture from its model (render/sky.py): the sky as Cycles' table gives it,
        and the sun's disc -- drawn with its limb darkening when it spans a few pixels of the
        bake, else its power spread over the pixels that carry it (see _sun_pixels)."""
        vector = next((s for s in node.inputs if s.name == "Vector"), None)  # not found by key in bpy 5.0
        d = self.d if vector is None or self.upstream(vector) is None else self.vector(vector)
        d = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-30)
        model = _sky_model(node)
        out = model.sky(d)
        if not model.sun_disc or self.grid is None:
            return out
        width, height = self.grid
        texel = math.pi / height
        if model.size / 2 >= _DRAWN_SUN_TEXELS * texel:
            return out + model.sun_radiance(d)
        power = model.sun_power()
        if not power.any():
            return out
        pixels, solid_angle = _sun_pixels(self.grid, tuple(model.sun_direction), model.size / 2)
        self.sockets.say(f": the Sky Texture's sun disc ({math.degrees(model.size):.2g} degrees) is smaller than "
                         f"{_DRAWN_SUN_TEXELS:g} pixels of the baked {width} x {height} image; its light is spread "
                         f"over the {math.degrees(2 * pixels):.2g} degrees that carry it (the same power; no limb "
                         f"darkening seen)")
        inside = np.einsum("ij,j->i", d, model.sun_direction) >= math.cos(pixels)
        out[inside] = out[inside] + power / solid_angle
        return out


# A sun disc at least this many bake pixels in radius is drawn pixel by pixel (its limb seen);
# a smaller one is its power over the pixels it covers: what lights the scene is the same.
_DRAWN_SUN_TEXELS = 2.0
_SKY_MODELS: dict = {}  # the last few Sky models by settings: one per bake, not one per block of rows


def _sky_model(node):
    """render.sky.Sky (Single and Multiple Scattering) or render.sky.LegacySky (Preetham,
    Hosek-Wilkie) for a Sky Texture node's settings, kept for the bake's next block of rows."""
    from ...render.sky import LegacySky, Sky

    kind = node.sky_type
    if kind in ("PREETHAM", "HOSEK_WILKIE"):
        key = (kind, tuple(float(c) for c in node.sun_direction), float(node.turbidity), float(node.ground_albedo))

        def make():
            return LegacySky(kind, key[1], key[2], key[3])
    else:
        key = (kind, float(node.sun_elevation), float(node.sun_rotation), float(node.altitude),
               float(node.air_density), float(node.aerosol_density), float(node.ozone_density),
               bool(node.sun_disc), float(node.sun_size), float(node.sun_intensity))

        def make():
            return Sky(multiple=kind == "MULTIPLE_SCATTERING", sun_elevation=key[1], sun_rotation=key[2],
                       altitude=key[3], air=key[4], aerosol=key[5], ozone=key[6], sun_disc=key[7],
                       sun_size=key[8], sun_intensity=key[9])
    if key not in _SKY_MODELS:
        while len(_SKY_MODELS) >= 4:
            _SKY_MODELS.pop(next(iter(_SKY_MODELS)))
        _SKY_MODELS[key] = make()
    return _SKY_MODELS[key]


def _sun_pixels(grid, sun, radius):
    """(angular radius, solid angle) of the pixels of the (width, height) equirectangular grid
    that carry the sun: those whose centres are within the disc, widened to 0.75 pixel so that a
    disc smaller than a pixel still has one. Its irradiance is spread over their solid angle."""
    width, height = grid
    reach = max(radius, 0.75 * math.pi / height)
    d = _unit_directions(width, height)
    cell = (2 * math.pi / width) * (math.pi / height) * np.cos(((np.arange(height) + 0.5) / height - 0.5) * np.pi)
    inside = np.einsum("hwj,j->hw", d, np.array(sun)) >= math.cos(reach)
    return reach, float((inside * cell[:, None]).sum()) or 1.0


def _sample(pixels: np.ndarray, u: np.ndarray, v: np.ndarray, closest: bool) -> np.ndarray:
    """An image (height, width, 4; row 0 at the bottom, as Blender's) at texture coordinates
    (u, v): Closest (clamped in v), or Linear between pixel centres; wrapping in u, and in v
    too when Linear, as Cycles' Environment Texture does (its images repeat: within half a
    pixel of a pole it blends the top and bottom rows)."""
    h, w = pixels.shape[:2]
    if closest:
        x = np.floor(u * w).astype(np.int64) % w
        y = np.clip(np.floor(v * h).astype(np.int64), 0, h - 1)
        return pixels[y, x]
    fx, fy = u * w - 0.5, v * h - 0.5
    x0, y0 = np.floor(fx), np.floor(fy)
    tx, ty = (fx - x0)[:, None], (fy - y0)[:, None]
    x0 = x0.astype(np.int64) % w
    x1 = (x0 + 1) % w
    y1 = (y0.astype(np.int64) + 1) % h
    y0 = y0.astype(np.int64) % h
    return ((pixels[y0, x0] * (1 - tx) + pixels[y0, x1] * tx) * (1 - ty)
            + (pixels[y1, x0] * (1 - tx) + pixels[y1, x1] * tx) * ty)


# Node properties (not sockets) that change what a bake gives.
_KEYED_PROPERTIES = ("projection", "interpolation", "vector_type", "blend_type", "data_type", "target",
                     "is_active_output", "object", "sky_type", "sun_disc", "sun_size", "sun_intensity",
                     "sun_elevation", "sun_rotation", "altitude", "air_density", "aerosol_density", "ozone_density",
                     "turbidity", "ground_albedo", "sun_direction")


def _tree_key(tree, images) -> str:
    """The content of a node tree and its images: what a bake depends on."""
    h = hashlib.sha1()
    for node in tree.nodes:
        h.update(repr((node.bl_idname, node.name, node.mute)).encode())
        for attr in _KEYED_PROPERTIES:
            h.update(repr(getattr(node, attr, None)).encode())
        for socket in node.inputs:
            value = getattr(socket, "default_value", None)
            h.update(repr((socket.identifier, tuple(value) if hasattr(value, "__len__") else value)).encode())
        for socket in node.outputs:
            value = getattr(socket, "default_value", None)
            h.update(repr(tuple(value) if hasattr(value, "__len__") else value).encode())
    for link in tree.links:
        h.update(repr((link.from_node.name, link.from_socket.identifier, link.to_node.name, link.to_socket.identifier,
                       link.is_muted, link.is_valid)).encode())
    for image in images:
        h.update(repr((image.name, image.filepath_raw, tuple(image.size), image.source, image.is_dirty,
                       image.colorspace_settings.name, image.packed_file.size if image.packed_file else 0)).encode())
    return h.hexdigest()


def varying_nodes(output) -> list:
    """The unmuted nodes of BAKED_NODES that feed `output` (through any links): what makes the
    world vary with the direction or the ray."""
    seen, stack, found = set(), [output], []
    while stack:
        node = stack.pop()
        for socket in node.inputs:
            for link in socket.links:
                if link.is_muted or not link.is_valid or link.from_node.name in seen:
                    continue
                seen.add(link.from_node.name)
                stack.append(link.from_node)
                if link.from_node.type in BAKED_NODES and not link.from_node.mute:
                    found.append(link.from_node)
    return found


class _Said:
    """Collects what a bake says, so that a cached bake says it again in the next report."""

    def __init__(self, sockets):
        self.sockets, self.lines = sockets, []

    def say(self, text: str) -> None:
        if text not in self.lines:
            self.lines.append(text)
        self.sockets.say(text)


def bake(tree, output, sockets, upstream) -> dict:
    """The world's tree feeding `output` as shading.World fields: `colour` (strength 1) alone
    when it depends neither on the direction nor on the ray (the core's uniform path, as
    before), else also `environment` and `camera_environment` (None: the same). `sockets`: a
    shading._Sockets for the report; `upstream`: its _upstream. Cached by content."""
    env_nodes = varying_nodes(output)
    images = [n.image for n in env_nodes if n.type == "TEX_ENVIRONMENT" and n.image is not None]
    key = _tree_key(tree, images)
    if key in _cache:
        result, lines = _cache[key]
        for line in lines:
            sockets.say(line)
        return result
    said = _Said(sockets)
    result = _bake(tree, output, said, upstream, env_nodes, images)
    while len(_cache) >= _CACHE_SIZE:
        _cache.pop(next(iter(_cache)))
    _cache[key] = (result, said.lines)
    return result


def _bake(tree, output, sockets, upstream, env_nodes, images) -> dict:
    if not env_nodes:  # uniform: one direction tells
        colour = _Bake(sockets, upstream, np.array([[0.0, 0.0, 1.0]]), False, {}).shader(output.inputs["Surface"])[0]
        return dict(colour=tuple(max(float(c), 0.0) for c in colour))
    pixels = {}
    for image in images:
        px = _images.read(image, sockets.say)
        if px is None:
            sockets.say(f": image '{image.name}' has no pixels; rendered as Cycles' missing-image pink")
            px = _images.Pixels(np.tile(np.array([1.0, 0.0, 1.0, 1.0], np.float32), (2, 2, 1)), False)
        pixels[image.name] = px
    sky = any(n.type == "TEX_SKY" for n in env_nodes)
    # An sRGB image interpolated is a curve between its pixels (Cycles decodes after
    # interpolating): baked finely, not pixel for pixel, so that the core's own linear
    # interpolation of the bake follows it.
    encoded = any(n.type == "TEX_ENVIRONMENT" and n.image is not None and n.interpolation != "Closest"
                  and pixels[n.image.name].srgb for n in env_nodes)
    width = max([px.values.shape[1] for px in pixels.values()] + [BAKE_WIDTH if sky or encoded else 8])
    if width > MAX_WIDTH:
        sockets.say(f": an image {width} pixels wide is baked at {MAX_WIDTH} (point-sampled: a sun a pixel wide "
                    f"may lose some of its light)")
    width = min(max(width, 8), MAX_WIDTH)
    height = max(width // 2, 4)
    light = np.empty((height * width, 3), np.float32)
    camera = None
    step = max(1, _BLOCK // width)  # rows at a time
    for r0 in range(0, height, step):
        rows = range(r0, min(r0 + step, height))
        block = _unit_directions(width, height, rows).reshape(-1, 3)
        at = slice(r0 * width, rows.stop * width)
        light_bake = _Bake(sockets, upstream, block, False, pixels, (width, height))
        light[at] = light_bake.shader(output.inputs["Surface"])
        if light_bake.uses_camera:
            if camera is None:
                camera = np.empty((height * width, 3), np.float32)
            camera[at] = _Bake(sockets, upstream, block, True, pixels, (width, height)).shader(
                output.inputs["Surface"])
    if camera is not None and np.array_equal(camera, light):
        camera = None

    def image_of(a):
        a = np.nan_to_num(np.maximum(a, 0.0), posinf=0.0).astype(np.float32).reshape(height, width, 3)
        return np.ascontiguousarray(a)
    light_image = image_of(light)
    if camera is None and np.all(light_image == light_image[:1, :1]):  # uniform after all (nothing linked)
        return dict(colour=tuple(float(c) for c in light_image[0, 0]))
    return dict(colour=tuple(float(c) for c in light_image.reshape(-1, 3).mean(0)), environment=light_image,
                camera_environment=None if camera is None else image_of(camera))
