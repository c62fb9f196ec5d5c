"""Blender shader-node trees -> node programs (render/nodes.py) the core runs per shading point.

The compiler walks back from a shader's linked inputs (Base Color, Roughness, ...), through
reroutes, muted nodes (their internal links) and node groups (nested: a Group Input reads the
group node's input, in the group that holds it), writing one instruction per node output
reached (each once, however many links read it). Definitions are Blender's (see
docs/nodes.md: which nodes are exact, approximate or unsupported).

A node it cannot compile makes the input it feeds keep its unlinked value (the socket's
default value), said once in the report naming the material and the node.
"""
from __future__ import annotations

import numpy as np

from ...render import nodes
from ...render.nodes import Builder, ProgramTooLarge  # noqa: F401 (raised through compile_shader)
from . import images
from .sockets import live_link as _live_link

# Cycles bakes Color Ramps and RGB Curves into tables of this many rows (its RAMP_TABLE_SIZE),
# read linearly between rows: baking the same table reads the ramp exactly as Cycles does.
_TABLE_ROWS = 256
_VECTORS = ("VECTOR", "RGBA")  # socket types held in three registers (colours drop alpha)
# Attribute names read as the points' own colour: the importer's, and the usual names of a
# colour attribute. Another name (a scan's intensity, classification, ...) is read from the
# geometry as a point attribute (Compiler._attribute).
COLOUR_ATTRIBUTE_NAMES = ("", "splat_color", "Col", "Color", "color", "colour", "Colour", "Cd", "rgb", "RGB", "rgba", "RGBA")
# What Cycles renders for an image it cannot load (its missing-texture colour): magenta.
MISSING_IMAGE = (1.0, 0.0, 1.0)
# Images read from Blender, by what identifies their pixels (see _image_pixels).
_IMAGES: dict = {}


class Unsupported(Exception):
    """A node (or a node's option) the compiler does not handle."""

    def __init__(self, node, what: str = ""):
        super().__init__(what)
        self.node, self.what = node, what


class Compiler:
    """Compiles one material's node inputs into one Program. `say(text)`: a report line.
    object_space(obj): the 4x4 map from the render's local frame (scene.py: world space
    less a float64 origin) into a Blender object's space at the frame's time, or for None
    into world space; object_space itself None where it is not known (a lamp's tree: its
    positions are read in the local frame)."""

    def __init__(self, say, object_space=None):
        self.b = Builder()
        self.say = say
        self.object_space = object_space
        self.memo: dict = {}
        self.consts: dict = {}
        self.bump_depth = 0  # Bump nodes being compiled within one another

    # ---------------------------------------------------------------- sockets and links

    def const(self, value, width: int) -> int:
        key = (width, tuple(np.round(np.ravel(value)[:width], 9)) if width == 3 else float(value))
        if key not in self.consts:
            self.consts[key] = self.b.register(value, width)
        return self.consts[key]

    def source(self, socket, stack: tuple):
        """(node, output socket, stack) feeding an input socket, through reroutes, muted
        nodes and group boundaries; None when nothing is."""
        link = _live_link(socket)
        while link is not None:
            node, out = link.from_node, link.from_socket
            if node.type == "REROUTE":
                link = _live_link(node.inputs[0])
            elif node.mute:
                passed = next((l for l in node.internal_links if l.to_socket == out), None)
                link = _live_link(passed.from_socket) if passed is not None else None
            elif node.type == "GROUP_INPUT":
                if not stack:
                    return None
                group = stack[-1]
                outer = next((s for s in group.inputs if s.identifier == out.identifier), None)
                if outer is None:
                    return None
                stack = stack[:-1]
                socket = outer
                link = _live_link(outer)
                if link is None:
                    return ("DEFAULT", outer, stack)
            else:
                return node, out, stack
        return None

    def input(self, socket, width: int, stack: tuple = ()) -> int:
        """The register (width 1 or 3) holding an input socket's value."""
        found = self.source(socket, stack)
        if found is None or found[0] == "DEFAULT":
            default = (found[1] if found else socket)
            return self.default(default, width)
        node, out, inner = found
        try:
            reg, kind = self.output(node, out, inner)
        except Unsupported as e:
            label = e.node.bl_label + (f" ({e.what})" if e.what else "")
            value = np.ravel(np.asarray(getattr(socket, "default_value", 0.0), np.float64))[:3]
            shown = f"{value[0]:.3g}" if value.size == 1 else "(" + ", ".join(f"{v:.3g}" for v in value) + ")"
            if socket.name == "Normal" and getattr(socket, "hide_value", False):  # unlinked: the surface's
                self.say(f": the '{label}' node is not supported; Normal is the surface's own")
            else:
                self.say(f": the '{label}' node is not supported; {socket.name} uses its unlinked value {shown}")
            return self.default(socket, width)
        return self.convert(reg, kind, width)

    def default(self, socket, width: int) -> int:
        value = getattr(socket, "default_value", 0.0)
        if width == 3:
            v = np.ravel(np.asarray(value, np.float64))
            return self.const(v[:3] if v.size >= 3 else np.repeat(v[:1] if v.size else [0.0], 3), 3)
        v = np.ravel(np.asarray(value, np.float64))
        if v.size >= 3:  # a colour or vector read as a float: as the link below converts
            return self.const(float(v[:3].mean()), 1)
        return self.const(float(v[0]) if v.size else 0.0, 1)

    def convert(self, reg: int, kind: str, width: int) -> int:
        """Blender's implicit conversions: a colour read as a float is its luminance, a
        vector its average; a float read as a vector fills all three."""
        have = 3 if kind in _VECTORS else 1
        if have == width:
            return reg
        if width == 1:
            out = self.b.register()
            if kind == "RGBA":
                self.b.emit("RGB_TO_BW", out, reg)
            else:
                vec_out = self.b.register(width=3)
                self.b.emit("VECTOR_MATH", vec_out, out, reg, self.const((1 / 3, 1 / 3, 1 / 3), 3), reg,
                            self.const(1.0, 1), nodes.VECTOR_OPS.index("DOT_PRODUCT"))
            return out
        out = self.b.register(width=3)
        self.b.emit("COMBINE", out, reg, reg, reg)
        return out

    # ---------------------------------------------------------------- nodes

    def output(self, node, socket, stack: tuple):
        """(register, socket type) of a node's output socket, compiling the node once."""
        key = (node.as_pointer(), tuple(g.as_pointer() for g in stack))
        if key not in self.memo:
            if node.type == "GROUP":
                self.memo[key] = self._group(node, stack)
            else:
                handler = getattr(self, "_" + node.type.lower(), None)
                if handler is None:
                    raise Unsupported(node)
                try:
                    self.memo[key] = handler(node, stack)
                except (KeyError, AttributeError, ValueError, IndexError, StopIteration, TypeError) as e:
                    # A node this Blender version lays out unlike the one the compiler was
                    # written for (a renamed socket or option): skip it, don't fail the frame.
                    raise Unsupported(node, f"{type(e).__name__}: {e}") from e
        outputs = self.memo[key]
        if socket.identifier not in outputs:
            raise Unsupported(node, f"its {socket.name} output")
        return outputs[socket.identifier], socket.type

    def _group(self, node, stack):
        tree = node.node_tree
        if tree is None:
            raise Unsupported(node, "no node group")
        outs = [n for n in tree.nodes if n.type == "GROUP_OUTPUT"]
        out_node = next((n for n in outs if n.is_active_output), outs[0] if outs else None)
        if out_node is None:
            raise Unsupported(node, "no Group Output")
        result = {}
        for s in node.outputs:
            inner = next((i for i in out_node.inputs if i.identifier == s.identifier), None)
            if inner is not None and s.type in ("VALUE", "INT", "BOOLEAN", "VECTOR", "RGBA"):
                result[s.identifier] = self.input(inner, 3 if s.type in _VECTORS else 1, stack + (node,))
        return result

    def _in(self, node, name, width, stack):
        """An input by index or name; by name among all sockets, unavailable ones included
        (Blender hides some by the node's options, and lookup by name skips those)."""
        if isinstance(name, int):
            socket = node.inputs[name]
        elif isinstance(name, str):
            # By name or identifier: Blender 5 renamed some (Fac -> Factor, Bright -> Brightness)
            # and kept the old names as identifiers.
            socket = next((s for s in node.inputs if s.name == name), None) or \
                next((s for s in node.inputs if s.identifier == name), None)
            if socket is None:
                raise KeyError(f"no input '{name}'")
        else:
            socket = name
        return self.input(socket, width, stack)

    def _by_id(self, node, identifier):
        return next(s for s in node.inputs if s.identifier == identifier)

    def _vector_or(self, node, stack, default_global="GENERATED", name="Vector"):
        """A texture's Vector input, or the default coordinates where nothing is linked."""
        socket = next(s for s in node.inputs if s.name == name or s.identifier == name)
        if self.source(socket, stack) is None:
            return self.b.global_(default_global)
        return self.input(socket, 3, stack)

    # Output names that changed between Blender versions (Blender 5: textures' Fac is Factor).
    _ALIASES = {"Fac": ("Fac", "Factor")}

    def _ids(self, node, values: dict):
        """{output identifier: register} for the outputs named (those the node has)."""
        result = {}
        for name, reg in values.items():
            for alias in self._ALIASES.get(name, (name,)):
                socket = next((s for s in node.outputs if s.name == alias), None)
                if socket is not None:
                    result[socket.identifier] = reg
        return result

    # Inputs
    def _value(self, node, stack):
        return self._ids(node, {"Value": self.b.register(float(node.outputs[0].default_value))})

    def _rgb(self, node, stack):
        return self._ids(node, {"Color": self.b.register(tuple(node.outputs[0].default_value[:3]), 3)})

    def _tex_coord(self, node, stack):
        other = getattr(node, "object", None)
        if other is not None and node.outputs["Object"].is_linked:
            result = self._tex_coord_of(node, other)
            rest = self._lazy(node, {"Generated": "GENERATED", "Normal": "OBJECT_NORMAL", "UV": "UV",
                                     "Reflection": "REFLECTION", "Camera": "CAMERA", "Window": "WINDOW"})
            return {**rest, **result}
        out = {"Generated": "GENERATED", "Normal": "OBJECT_NORMAL", "UV": "UV", "Object": "OBJECT",
               "Reflection": "REFLECTION", "Camera": "CAMERA", "Window": "WINDOW"}
        return self._lazy(node, out)

    def _tex_coord_of(self, node, other):
        """Texture Coordinate's Object output with another object chosen: the point in that
        object's space, as Cycles gives it (the object where it is at the frame's time: Cycles'
        node holds that one transform, motion blur or not)."""
        if self.object_space is None:
            raise Unsupported(node, f"Object from '{other.name}' here")
        matrix = np.asarray(self.object_space(other), np.float64)
        if matrix.shape != (4, 4) or not np.isfinite(matrix).all():
            raise Unsupported(node, f"Object from '{other.name}': its transform cannot be inverted")
        return {node.outputs["Object"].identifier: self._position_in(matrix)}

    def _position_in(self, matrix) -> int:
        """The shading position mapped by a 4x4 affine `matrix` from the local frame."""
        out = self.b.register(width=3)
        self.b.emit("TRANSFORM", out, self.b.global_("POSITION"), self.b.table(np.asarray(matrix)[:3]))
        return out

    def _world_position(self) -> int:
        """The shading position in world space, as Cycles' P is (the local frame's origin
        added back: nothing to add when it is the world's)."""
        to_world = np.asarray(self.object_space(None), np.float64) if self.object_space is not None else None
        if to_world is None or np.array_equal(to_world, np.eye(4)):
            return self.b.global_("POSITION")
        return self._position_in(to_world)

    def _lazy(self, node, names: dict):
        """Globals for the node's outputs that something reads (unread ones cost nothing)."""
        result = {}
        for s in node.outputs:
            if s.name in names and s.is_linked:
                result[s.identifier] = self.b.global_(names[s.name])
        return result

    def _new_geometry(self, node, stack):
        result = self._lazy(node, {"Normal": "NORMAL", "True Normal": "TRUE_NORMAL", "Incoming": "INCOMING"})
        if node.outputs["Position"].is_linked:
            result[node.outputs["Position"].identifier] = self._world_position()
        if node.outputs["Backfacing"].is_linked:
            result[node.outputs["Backfacing"].identifier] = self.b.global_("BACKFACING")
        return result

    def _uvmap(self, node, stack):
        if getattr(node, "from_instancer", False):
            raise Unsupported(node, "From Instancer")
        if not node.uv_map:  # the active render map, which meshes carry
            return self._ids(node, {"UV": self.b.global_("UV")})
        # Another map: read by name as the geometry's (corner-domain, 2-D) attribute it is,
        # (u, v, 0); a geometry without it reads 0, as Cycles reads a missing map.
        uv, _ = self.b.attribute(node.uv_map, 3)
        return self._ids(node, {"UV": uv})

    def _point_data(self, node, fac: bool):
        colour = self.b.global_("POINT_COLOUR")
        result = {s.identifier: colour for s in node.outputs if s.name in ("Color", "Vector")}
        alpha = self.b.global_("POINT_ALPHA")
        result.update({s.identifier: alpha for s in node.outputs if s.name == "Alpha"})
        for s in node.outputs:
            if fac and s.name in ("Fac", "Factor"):
                result[s.identifier] = self.convert(colour, "VECTOR", 1)
        return result

    def _vertex_color(self, node, stack):
        return self._point_data(node, False)

    def _attribute(self, node, stack):
        if node.attribute_type != "GEOMETRY":
            raise Unsupported(node, f"{node.attribute_type.lower()} attributes")
        if node.attribute_name in COLOUR_ATTRIBUTE_NAMES:
            return self._point_data(node, True)
        # Three floats whatever the attribute's type, which the geometry decides (the export
        # fills a float into all three, scene.py _point_attributes): a float's Color and
        # Vector are its value in each component and its Fac the value, a vector's or
        # colour's Fac their average -- Cycles' Attribute node either way. Alpha: 1, as
        # Cycles gives it for anything but a colour attribute's.
        colour, fac = self.b.attribute(node.attribute_name, 3)
        return self._ids(node, {"Color": colour, "Vector": colour, "Fac": fac, "Alpha": self.const(1.0, 1)})

    # Math and colour
    def _math(self, node, stack):
        a, b, c = (self._in(node, i, 1, stack) for i in range(3))
        out = self.b.register()
        self.b.emit("MATH", out, a, b, c, nodes.MATH_OPS.index(node.operation), int(node.use_clamp))
        return {node.outputs[0].identifier: out}

    def _vect_math(self, node, stack):
        vecs = [s for s in node.inputs if s.type == "VECTOR"]
        a, b, c = (self.input(vecs[i], 3, stack) for i in range(3))
        scale = self._in(node, "Scale", 1, stack)
        v, f = self.b.register(width=3), self.b.register()
        self.b.emit("VECTOR_MATH", v, f, a, b, c, scale, nodes.VECTOR_OPS.index(node.operation))
        return self._ids(node, {"Vector": v, "Value": f})

    def _mix(self, node, stack):
        kind = node.data_type
        if kind not in ("FLOAT", "VECTOR", "RGBA"):
            raise Unsupported(node, f"{kind.lower()} mixing")
        out_socket = next(s for s in node.outputs if s.enabled)
        suffix = {"FLOAT": "Float", "VECTOR": "Vector", "RGBA": "Color"}[kind]
        width = 1 if kind == "FLOAT" else 3
        a = self.input(self._by_id(node, f"A_{suffix}"), width, stack)
        b = self.input(self._by_id(node, f"B_{suffix}"), width, stack)
        non_uniform = kind == "VECTOR" and node.factor_mode == "NON_UNIFORM"
        fac = self.input(self._by_id(node, "Factor_Vector" if non_uniform else "Factor_Float"),
                         3 if non_uniform else 1, stack)
        out = self.b.register(width=width)
        if kind == "FLOAT":
            self.b.emit("MIX_FLOAT", out, fac, a, b, int(node.clamp_factor))
        elif kind == "VECTOR":
            self.b.emit("MIX_VECTOR", out, fac, a, b, int(node.clamp_factor), int(non_uniform))
        else:
            self.b.emit("MIX_COLOUR", out, fac, a, b, nodes.BLENDS.index(node.blend_type), int(node.clamp_factor),
                        int(node.clamp_result))
        return {out_socket.identifier: out}

    def _mix_rgb(self, node, stack):  # the legacy MixRGB node
        fac, a, b = self._in(node, "Fac", 1, stack), self._in(node, "Color1", 3, stack), self._in(node, "Color2", 3, stack)
        out = self.b.register(width=3)
        self.b.emit("MIX_COLOUR", out, fac, a, b, nodes.BLENDS.index(node.blend_type), 1, int(node.use_clamp))
        return {node.outputs[0].identifier: out}

    def _map_range(self, node, stack):
        if node.data_type != "FLOAT":
            raise Unsupported(node, "vector mapping")
        value = self._in(node, "Value", 1, stack)
        params = self.b.register(width=1)  # five consecutive registers: from/to min/max, steps
        for _ in range(4):
            self.b.register()
        names = ("From Min", "From Max", "To Min", "To Max", "Steps")
        float_inputs = [s for s in node.inputs if s.type == "VALUE"]
        for k, name in enumerate(names):
            socket = next(s for s in float_inputs if s.name == name)
            self.b.emit("COPY", params + k, self.input(socket, 1, stack), 1)
        out = self.b.register()
        self.b.emit("MAP_RANGE", out, value, params, nodes.MAP_RANGE_MODES.index(node.interpolation_type),
                    int(node.clamp))
        return {next(s for s in node.outputs if s.name == "Result" and s.type == "VALUE").identifier: out}

    def _clamp(self, node, stack):
        v, lo, hi = (self._in(node, n, 1, stack) for n in ("Value", "Min", "Max"))
        out = self.b.register()
        self.b.emit("CLAMP", out, v, lo, hi, 1 if node.clamp_type == "RANGE" else 0)
        return {node.outputs[0].identifier: out}

    def _valtorgb(self, node, stack):  # Color Ramp
        ramp = node.color_ramp
        rows = [tuple(ramp.evaluate(i / (_TABLE_ROWS - 1))) for i in range(_TABLE_ROWS)]
        table = self.b.table(rows)
        fac = self._in(node, "Fac", 1, stack)
        colour, alpha = self.b.register(width=3), self.b.register()
        self.b.emit("RAMP", colour, alpha, fac, table, _TABLE_ROWS, int(ramp.interpolation != "CONSTANT"))
        return self._ids(node, {"Color": colour, "Alpha": alpha})

    def _curve_rgb(self, node, stack):
        mapping = node.mapping
        mapping.initialize()
        lo, hi = float(mapping.clip_min_x), float(mapping.clip_max_x)
        if not mapping.use_clip:
            lo, hi = 0.0, 1.0
        curves = mapping.curves  # R, G, B, and the combined curve, which each channel's curve follows
        rows = []
        for i in range(_TABLE_ROWS):
            x = lo + (hi - lo) * i / (_TABLE_ROWS - 1)
            rows.append([mapping.evaluate(curves[k], mapping.evaluate(curves[3], x)) for k in range(3)] + [0.0])
        table = self.b.table(rows)
        span = self.b.register((lo, hi, 0.0), 3)
        fac, colour = self._in(node, "Fac", 1, stack), self._in(node, "Color", 3, stack)
        out = self.b.register(width=3)
        self.b.emit("CURVES", out, fac, colour, table, _TABLE_ROWS, span)
        return {node.outputs[0].identifier: out}

    def _hue_sat(self, node, stack):
        h, s, v, f = (self._in(node, n, 1, stack) for n in ("Hue", "Saturation", "Value", "Fac"))
        colour = self._in(node, "Color", 3, stack)
        out = self.b.register(width=3)
        self.b.emit("HUE_SAT_VAL", out, h, s, v, f, colour)
        return {node.outputs[0].identifier: out}

    def _invert(self, node, stack):
        out = self.b.register(width=3)
        self.b.emit("INVERT", out, self._in(node, "Fac", 1, stack), self._in(node, "Color", 3, stack))
        return {node.outputs[0].identifier: out}

    def _brightcontrast(self, node, stack):
        out = self.b.register(width=3)
        self.b.emit("BRIGHT_CONTRAST", out, self._in(node, "Color", 3, stack), self._in(node, "Bright", 1, stack),
                    self._in(node, "Contrast", 1, stack))
        return {node.outputs[0].identifier: out}

    def _gamma(self, node, stack):
        out = self.b.register(width=3)
        self.b.emit("GAMMA", out, self._in(node, "Color", 3, stack), self._in(node, "Gamma", 1, stack))
        return {node.outputs[0].identifier: out}

    def _rgbtobw(self, node, stack):
        out = self.b.register()
        self.b.emit("RGB_TO_BW", out, self._in(node, "Color", 3, stack))
        return {node.outputs[0].identifier: out}

    def _separate(self, node, stack, name, mode="RGB"):
        v = self._in(node, name, 3, stack)
        if mode == "HSV":
            hsv = self.b.register(width=3)
            self.b.emit("RGB_TO_HSV", hsv, v)
            v = hsv
        elif mode != "RGB":
            raise Unsupported(node, f"{mode} mode")
        # The three outputs are the vector's own registers.
        return {s.identifier: v + k for k, s in enumerate(node.outputs[:3])}

    def _combine(self, node, stack, mode="RGB"):
        x, y, z = (self.input(node.inputs[k], 1, stack) for k in range(3))
        out = self.b.register(width=3)
        self.b.emit("COMBINE", out, x, y, z)
        if mode == "HSV":
            rgb = self.b.register(width=3)
            self.b.emit("HSV_TO_RGB", rgb, out)
            out = rgb
        elif mode != "RGB":
            raise Unsupported(node, f"{mode} mode")
        return {node.outputs[0].identifier: out}

    def _separate_color(self, node, stack):
        return self._separate(node, stack, "Color", node.mode)

    def _combine_color(self, node, stack):
        return self._combine(node, stack, node.mode)

    def _sepxyz(self, node, stack):
        return self._separate(node, stack, "Vector")

    def _combxyz(self, node, stack):
        return self._combine(node, stack)

    def _seprgb(self, node, stack):
        return self._separate(node, stack, "Image")

    def _combrgb(self, node, stack):
        return self._combine(node, stack)

    def _mapping(self, node, stack):
        v = self._in(node, "Vector", 3, stack)
        kind = node.vector_type
        loc = self._in(node, "Location", 3, stack) if kind in ("POINT", "TEXTURE") else self.const((0, 0, 0), 3)
        rot, scale = self._in(node, "Rotation", 3, stack), self._in(node, "Scale", 3, stack)
        out = self.b.register(width=3)
        self.b.emit("MAPPING", out, v, loc, rot, scale, nodes.MAPPINGS.index(kind))
        return {node.outputs[0].identifier: out}

    def _fresnel(self, node, stack):
        out = self.b.register()
        normal = self._vector_or(node, stack, "NORMAL", "Normal")
        self.b.emit("FRESNEL", out, self._in(node, "IOR", 1, stack), normal)
        return {node.outputs[0].identifier: out}

    def _layer_weight(self, node, stack):
        fresnel, facing = self.b.register(), self.b.register()
        normal = self._vector_or(node, stack, "NORMAL", "Normal")
        self.b.emit("LAYER_WEIGHT", fresnel, facing, self._in(node, "Blend", 1, stack), normal)
        return self._ids(node, {"Fresnel": fresnel, "Facing": facing})

    def _normal_map(self, node, stack):
        if node.space not in nodes.NORMAL_MAP_SPACES:
            raise Unsupported(node, f"{node.space.replace('_', ' ').lower()} space")
        out = self.b.register(width=3)
        self.b.emit("NORMAL_MAP", out, self._in(node, "Color", 3, stack), self._in(node, "Strength", 1, stack),
                    nodes.NORMAL_MAP_SPACES.index(node.space))
        return {node.outputs[0].identifier: out}

    def _bump(self, node, stack):
        """Blender's Bump node. Its height is compiled afresh into rows of its own (no node
        shared with what came before), which the core runs again at two nearby points of
        the surface to find the height's slope."""
        strength, distance = self._in(node, "Strength", 1, stack), self._in(node, "Distance", 1, stack)
        normal = self._vector_or(node, stack, "NORMAL", "Normal")
        out = self.b.register(width=3)
        height = node.inputs["Height"]
        if self.source(height, stack) is None:  # a constant height has no slope
            self.b.emit("COPY", out, normal, 3)
            return {node.outputs[0].identifier: out}
        if self.bump_depth >= nodes.MAX_BUMP_DEPTH:
            raise Unsupported(node, f"more than {nodes.MAX_BUMP_DEPTH} Bump nodes within one another")
        outer, first = self.memo, len(self.b.code)
        self.memo, self.bump_depth = {}, self.bump_depth + 1
        try:
            h = self.input(height, 1, stack)
        finally:
            self.memo, self.bump_depth = outer, self.bump_depth - 1
        self.b.emit("BUMP", out, h, strength, distance, normal, first, int(node.invert))
        return {node.outputs[0].identifier: out}

    def _blackbody(self, node, stack):
        out = self.b.register(width=3)
        self.b.emit("BLACKBODY", out, self._in(node, "Temperature", 1, stack))
        return {node.outputs[0].identifier: out}

    def _ambient_occlusion(self, node, stack):
        """Cycles' Ambient Occlusion node: the core traces its rays from the shading point
        (ShadingQueries in nodes/program.h)."""
        colour, ao = self.b.register(width=3), self.b.register()
        normal = self._vector_or(node, stack, "NORMAL", "Normal")
        samples = min(max(int(node.samples), 1), nodes.MAX_AO_SAMPLES)
        distance = node.inputs["Distance"]
        # Distance 0 and unlinked: Cycles reaches as far as World > Light Settings > Distance.
        world = self.source(distance, stack) is None and float(distance.default_value) == 0.0
        self.b.emit("AMBIENT_OCCLUSION", colour, ao, self._in(node, "Color", 3, stack),
                    self.input(distance, 1, stack), normal, samples,
                    int(node.inside) | (2 if node.only_local else 0) | (4 if world else 0))
        return self._ids(node, {"Color": colour, "AO": ao})

    def _wireframe(self, node, stack):
        out = self.b.register()
        if node.use_pixel_size:
            self.say(f": the {node.bl_label}'s Pixel Size is the camera's pixel footprint at each point, also "
                     "on reflected and refracted rays (Cycles widens it along the path)")
        self.b.emit("WIREFRAME", out, self._in(node, "Size", 1, stack), int(node.use_pixel_size))
        return self._ids(node, {"Fac": out})

    def _bevel(self, node, stack):
        """Cycles' Bevel node: the core traces rays to the point's own mesh around it."""
        out = self.b.register(width=3)
        socket = next(s for s in node.inputs if s.name == "Normal")
        linked = self.source(socket, stack) is not None
        normal = self.input(socket, 3, stack) if linked else self.b.global_("NORMAL")
        samples = min(max(int(node.samples), 1), nodes.MAX_AO_SAMPLES)
        self.say(f": the {node.bl_label} node keeps the nearest 4 surfaces along each of its rays (Cycles: a "
                 "random 4 of all)")
        self.b.emit("BEVEL", out, self._in(node, "Radius", 1, stack), normal, samples, int(linked))
        return {node.outputs[0].identifier: out}

    # Textures
    def _tex_image(self, node, stack):
        image = node.image
        if image is not None and image.source not in ("FILE", "GENERATED", "TILED"):
            raise Unsupported(node, f"{image.source.lower()} images")
        colour, alpha = self.b.register(width=3), self.b.register()
        tiles = _tile_pixels(image, self.say) if image is not None and image.source == "TILED" else None
        texture = _image_pixels(image, self.say) if image is not None and tiles is None else None
        if texture is None and not tiles:
            what = f"image '{image.name}' could not be loaded" if image is not None else "an Image Texture has no image"
            return self._missing_image(node, what, colour, alpha)
        vector = self._vector_or(node, stack, "UV")
        modes = (self._interpolation(node), nodes.EXTENSIONS.index(node.extension))
        if node.projection == "BOX":
            if tiles:  # Cycles' box projection reads the image's first tile alone
                texture = next((t for number, t in tiles if number == 1001 and t is not None), None)
                if texture is None:
                    return self._missing_image(node, f"image '{image.name}' has no tile 1001 loaded", colour, alpha)
            blend = self.const(float(node.projection_blend), 1)
            self.b.emit("IMAGE_BOX", colour, alpha, vector, self.b.image(texture), *modes, blend)
            return self._ids(node, {"Color": colour, "Alpha": alpha})
        if node.projection in nodes.IMAGE_PROJECTIONS:
            projected = self.b.register(width=3)
            self.b.emit("IMAGE_PROJECT", projected, vector, nodes.IMAGE_PROJECTIONS.index(node.projection))
            vector = projected
        if tiles:
            rows = [(number, self.b.image(t) if t is not None else -1) for number, t in tiles]
            self.b.emit("IMAGE_TILES", colour, alpha, vector, self.b.table(rows), len(rows), *modes)
        else:
            self.b.emit("IMAGE", colour, alpha, vector, self.b.image(texture), *modes)
        return self._ids(node, {"Color": colour, "Alpha": alpha})

    def _missing_image(self, node, what: str, colour: int, alpha: int) -> dict:
        """An image node's outputs where there is no image to read: magenta, said."""
        self.say(f": {what}; rendered magenta, as Cycles does")
        self.b.emit("COPY", colour, self.const(MISSING_IMAGE, 3), 3)
        self.b.emit("COPY", alpha, self.const(1.0, 1), 1)
        return self._ids(node, {"Color": colour, "Alpha": alpha})

    def _interpolation(self, node) -> int:
        """An image node's interpolation (nodes.INTERPOLATIONS index); Smart is Cubic, said."""
        if node.interpolation == "Smart":
            self.say(f": the {node.bl_label}'s Smart interpolation is rendered as Cubic")
            return nodes.INTERPOLATIONS.index("Cubic")
        return nodes.INTERPOLATIONS.index(node.interpolation)

    def _tex_environment(self, node, stack):
        """Environment Texture in a material: the image at the direction of its Vector --
        unlinked, the world position (Cycles' default for it), as seen from the world's
        origin. Read with Repeat, as Cycles reads an environment image."""
        image = node.image
        if image is not None and image.source not in ("FILE", "GENERATED"):
            raise Unsupported(node, f"{image.source.lower()} images")
        colour, alpha = self.b.register(width=3), self.b.register()
        texture = _image_pixels(image, self.say) if image is not None else None
        if texture is None:
            what = (f"image '{image.name}' could not be loaded" if image is not None
                    else "an Environment Texture has no image")
            return self._missing_image(node, what, colour, alpha)
        socket = node.inputs["Vector"]
        vector = self.input(socket, 3, stack) if self.source(socket, stack) is not None else self._world_position()
        uv = self.b.register(width=3)
        self.b.emit("IMAGE_PROJECT", uv, vector, nodes.IMAGE_PROJECTIONS.index(node.projection))
        self.b.emit("IMAGE", colour, alpha, uv, self.b.image(texture), self._interpolation(node),
                    nodes.EXTENSIONS.index("REPEAT"))
        return self._ids(node, {"Color": colour, "Alpha": alpha})

    def _tex_checker(self, node, stack):
        vector = self._vector_or(node, stack)
        colour, fac = self.b.register(width=3), self.b.register()
        self.b.emit("CHECKER", colour, fac, vector, self._in(node, "Color1", 3, stack),
                    self._in(node, "Color2", 3, stack), self._in(node, "Scale", 1, stack))
        return self._ids(node, {"Color": colour, "Fac": fac})

    def _tex_gradient(self, node, stack):
        vector = self._vector_or(node, stack)
        colour, fac = self.b.register(width=3), self.b.register()
        self.b.emit("GRADIENT", colour, fac, vector, nodes.GRADIENTS.index(node.gradient_type))
        return self._ids(node, {"Color": colour, "Fac": fac})

    def _tex_noise(self, node, stack):
        dims = {"1D": 1, "2D": 2, "3D": 3, "4D": 4}.get(node.noise_dimensions)
        kind = getattr(node, "noise_type", "FBM")
        if dims is None:
            raise Unsupported(node, f"{node.noise_dimensions} noise")
        if kind not in nodes.NOISE_TYPES:
            raise Unsupported(node, f"{kind.replace('_', ' ').lower()} noise")
        # Only the inputs this dimension and type read are compiled (the others stay 0), as in
        # Cycles: W in 1-D and 4-D, Offset for the ridged, hybrid and hetero terrain types, Gain
        # for ridged and hybrid; the Vector not in 1-D.
        used = ["Scale", "Detail", "Roughness", "Lacunarity", "Distortion"]
        used += ["W"] if dims in (1, 4) else []
        used += ["Offset"] if kind in ("RIDGED_MULTIFRACTAL", "HYBRID_MULTIFRACTAL", "HETERO_TERRAIN") else []
        used += ["Gain"] if kind in ("RIDGED_MULTIFRACTAL", "HYBRID_MULTIFRACTAL") else []
        vector = self._vector_or(node, stack) if dims > 1 else self.const((0, 0, 0), 3)
        params = self.b.register()
        for _ in nodes.NOISE_PARAMS[1:]:
            self.b.register()
        for name in used:
            self.b.emit("COPY", params + nodes.NOISE_PARAMS.index(name), self._in(node, name, 1, stack), 1)
        fac, colour = self.b.register(), self.b.register(width=3)
        flags = int(getattr(node, "normalize", True)) | 2 * int(node.outputs["Color"].is_linked)
        self.b.emit("NOISE", fac, colour, vector, params, dims, nodes.NOISE_TYPES.index(kind), flags)
        return self._ids(node, {"Fac": fac, "Color": colour})

    def _params(self, node, stack, names, extra=()):
        """Consecutive registers holding the float inputs `names`, then the constants `extra`
        (a block operand: allocated together, before any input's own registers)."""
        first = self.b.register()
        for _ in names[1:]:
            self.b.register()
        for value in extra:
            self.b.register(float(value))
        for k, name in enumerate(names):
            self.b.emit("COPY", first + k, self._in(node, name, 1, stack), 1)
        return first

    def _tex_voronoi(self, node, stack):
        dimensions = int(node.voronoi_dimensions[0])  # "1D" .. "4D"
        # 1-D reads only W, 2-D and 3-D only the vector: what is not read is a constant.
        vector = self.b.register((0.0, 0.0, 0.0), 3) if dimensions == 1 else self._vector_or(node, stack)
        w = self._in(node, "W", 1, stack) if dimensions in (1, 4) else self.b.register(0.0)
        params = self._params(node, stack, ("Scale", "Detail", "Roughness", "Lacunarity", "Smoothness", "Exponent",
                                            "Randomness"), extra=(float(bool(getattr(node, "normalize", False))),))
        out = self.b.register(width=9)  # distance, colour, position, w, radius (native Voronoi)
        self.b.emit("VORONOI", out, vector, w, params, nodes.VORONOI_METRICS.index(node.distance),
                    nodes.VORONOI_FEATURES.index(node.feature), dimensions - 1)
        return self._ids(node, {"Distance": out, "Color": out + 1, "Position": out + 4, "W": out + 7,
                                "Radius": out + 8})

    def _tex_wave(self, node, stack):
        if node.wave_type == "BANDS":
            kind = "BANDS_" + node.bands_direction
        else:
            kind = "RINGS_" + node.rings_direction
        vector = self._vector_or(node, stack)
        params = self._params(node, stack, ("Scale", "Distortion", "Detail", "Detail Scale", "Detail Roughness"))
        fac, colour = self.b.register(), self.b.register(width=3)
        self.b.emit("WAVE", fac, vector, params, self._in(node, "Phase Offset", 1, stack), nodes.WAVE_KINDS.index(kind),
                    nodes.WAVE_PROFILES.index(node.wave_profile))
        self.b.emit("COMBINE", colour, fac, fac, fac)
        return self._ids(node, {"Fac": fac, "Color": colour})

    def _tex_magic(self, node, stack):
        vector = self._vector_or(node, stack)
        colour, fac = self.b.register(width=3), self.b.register()
        self.b.emit("MAGIC", colour, fac, vector, self._in(node, "Scale", 1, stack),
                    self._in(node, "Distortion", 1, stack), min(max(int(node.turbulence_depth), 0), 10))
        return self._ids(node, {"Color": colour, "Fac": fac})

    def _tex_brick(self, node, stack):
        vector = self._vector_or(node, stack)
        colours = self.b.register(width=3)
        self.b.register(width=3), self.b.register(width=3)
        for k, name in enumerate(("Color1", "Color2", "Mortar")):
            self.b.emit("COPY", colours + 3 * k, self._in(node, name, 3, stack), 3)
        params = self._params(node, stack, ("Scale", "Mortar Size", "Mortar Smooth", "Bias", "Brick Width",
                                            "Row Height"), extra=(node.offset, node.squash))
        colour, fac = self.b.register(width=3), self.b.register()
        self.b.emit("BRICK", colour, fac, vector, colours, params, min(max(int(node.offset_frequency), 0), 99),
                    min(max(int(node.squash_frequency), 0), 99))
        return self._ids(node, {"Color": colour, "Fac": fac})

    def _tex_white_noise(self, node, stack):
        dims = {"1D": 1, "2D": 2, "3D": 3}.get(node.noise_dimensions)
        if dims is None:
            raise Unsupported(node, f"{node.noise_dimensions} noise")
        socket = node.inputs["W"] if dims == 1 else node.inputs["Vector"]
        vector = self.input(socket, 3, stack)  # W (1-D) fills all three: the first is read
        value, colour = self.b.register(), self.b.register(width=3)
        self.b.emit("WHITE_NOISE", value, colour, vector, dims)
        return self._ids(node, {"Value": value, "Color": colour})


def _image_pixels(image, say):
    """An image's pixels as a nodes.Image (None when Blender cannot load it), read by
    images.read's rule once and kept while its identity, size, colour space and alpha mode
    stay (re-read every frame while it has unsaved changes: being painted)."""
    settings = image.colorspace_settings.name
    key = (image.name_full, image.as_pointer(), tuple(image.size), image.is_float, settings, image.alpha_mode,
           image.filepath_raw, image.packed_file is not None)
    if key in _IMAGES and not image.is_dirty:
        return _IMAGES[key]
    read = images.read(image, say)
    if read is None:
        return None
    pixels = read.values
    if image.alpha_mode == "NONE":  # Cycles ignores the image's alpha
        pixels[..., 3] = 1.0
    if image.is_float:
        texture = nodes.Image(pixels, srgb=read.srgb)
    else:  # kept as the bytes they are (a quarter of the floats)
        texture = nodes.Image(np.clip(np.rint(pixels * 255.0), 0, 255).astype(np.uint8), srgb=read.srgb)
    # Keep only the current version of each image (its old pixels are garbage).
    for old in [k for k in _IMAGES if k[:2] == key[:2]]:
        del _IMAGES[old]
    _IMAGES[key] = texture
    return texture


# UDIM tiles read from their files (see _tile_pixels), by what identifies their pixels.
_TILES: dict = {}


def _tile_pixels(image, say) -> list:
    """A UDIM (tiled) image's tiles as [(tile number, nodes.Image or None)]: the first tile
    from the image's own pixels (what Blender holds, painted or packed alike), the others
    from their files (the image's path with its <UDIM> or <UVTILE> token filled), read
    through a temporary image in the same colour space and alpha mode. A tile that cannot
    be read (not saved, packed, missing) is None: magenta, as Cycles renders a tile it
    cannot load -- said once. Tiles are read once and kept while their file is unchanged."""
    import os

    import bpy

    out, missing = [], []
    for k, tile in enumerate(image.tiles):
        number = int(tile.number)
        if k == 0:
            if not image.has_data:
                _try_load(image)
            out.append((number, _image_pixels(image, say)))
            if out[-1][1] is None:
                missing.append(number)
            continue
        u, v = (number - 1001) % 10, (number - 1001) // 10
        path = image.filepath_raw.replace("<UDIM>", str(number)).replace("<UVTILE>", f"u{u + 1}_v{v + 1}")
        path = bpy.path.abspath(path, library=image.library)
        if path == bpy.path.abspath(image.filepath_raw, library=image.library) or not os.path.isfile(path):
            out.append((number, None))
            missing.append(number)
            continue
        settings = image.colorspace_settings.name
        key = (image.name_full, number, path, os.path.getmtime(path), settings, image.alpha_mode)
        if key not in _TILES:
            texture = None
            try:
                temp = bpy.data.images.load(path, check_existing=False)
            except RuntimeError:  # a file Blender cannot read: the tile is missing
                temp = None
            if temp is not None:
                try:
                    temp.colorspace_settings.name = settings
                    temp.alpha_mode = image.alpha_mode
                    texture = _image_pixels(temp, say)
                    for old in [k for k in _IMAGES if k[:2] == (temp.name_full, temp.as_pointer())]:
                        del _IMAGES[old]  # the temporary image's pixels live on here, not there
                finally:
                    bpy.data.images.remove(temp)
            for old in [k for k in _TILES if k[:2] == key[:2]]:
                del _TILES[old]
            _TILES[key] = texture
        if _TILES[key] is None:
            missing.append(number)
        out.append((number, _TILES[key]))
    if missing:
        say(f": image '{image.name}' tile{'s' if len(missing) > 1 else ''} {', '.join(map(str, missing))} "
            f"could not be read (not saved to a file?); rendered magenta, as Cycles does")
    return out


def _try_load(image) -> bool:
    """Asks Blender to load the image (from disk or its packed copy); whether it has pixels."""
    try:
        image.pixels[0]  # reading a pixel loads the buffer
    except (IndexError, RuntimeError):
        return False
    return bool(image.has_data) and image.size[0] > 0


# Which inputs of each shader feed which material field (the engine's Material fields).
SHADER_INPUTS = {
    "BSDF_PRINCIPLED": {"base_colour": "Base Color", "metallic": "Metallic", "roughness": "Roughness", "ior": "IOR",
                        "transmission": "Transmission Weight", "alpha": "Alpha",
                        "specular_level": "Specular IOR Level", "emission": ("Emission Color", "Emission Strength"),
                        "normal": "Normal"},
    "BSDF_DIFFUSE": {"base_colour": "Color", "normal": "Normal"},
    "BSDF_GLOSSY": {"base_colour": "Color", "roughness": "Roughness", "normal": "Normal"},
    "BSDF_METALLIC": {"base_colour": "Base Color", "roughness": "Roughness", "normal": "Normal"},
    "BSDF_GLASS": {"base_colour": "Color", "roughness": "Roughness", "ior": "IOR", "normal": "Normal"},
    "BSDF_REFRACTION": {"base_colour": "Color", "roughness": "Roughness", "ior": "IOR", "normal": "Normal"},
    "EMISSION": {"emission": ("Color", "Strength")},
}


def compile_shader(node, say, skip=(), aovs=(), object_space=None) -> tuple:
    """(Program or None, the input sockets it drives) for a shader node's linked inputs
    (those in SHADER_INPUTS, but not the sockets in `skip`, which the constant path reads)
    and for AOV Output nodes: `aovs`, (AOV name, width, the node's Color or Value socket)
    each. None when nothing needs a program: such a material costs nothing more to render.
    node: None when nothing feeds the Material Output (AOVs only). object_space: see
    Compiler."""
    fields = SHADER_INPUTS.get(node.type, {}) if node is not None else {}
    compiler = Compiler(say, object_space)
    driven = []
    for field, names in fields.items():
        if isinstance(names, tuple):  # emission: colour x strength
            colour, strength = (node.inputs[n] for n in names)
            if not any(compiler.source(s, ()) is not None for s in (colour, strength)):
                continue
            c, s = compiler.input(colour, 3), compiler.input(strength, 1)
            out = compiler.b.register(width=3)
            compiler.b.emit("SCALE", out, c, s)
            compiler.b.output(field, out)
            driven += [colour, strength]
            continue
        if names not in node.inputs:
            continue
        socket = node.inputs[names]
        if socket in skip or compiler.source(socket, ()) is None:
            continue
        compiler.b.output(field, compiler.input(socket, nodes.OUTPUTS[field]))
        driven.append(socket)
    compile_aovs(compiler, aovs)
    if not driven and not aovs:
        return None, []
    return compiler.b.program(), driven


def compile_aovs(compiler: Compiler, aovs) -> None:
    """AOV Output nodes into the compiler's program: `aovs` as compile_shader takes them."""
    for name, width, socket in aovs:
        # Cycles compiles the input the view layer's AOV type reads (Color or Value).
        reg = compiler.input(socket, width)
        colour, value = (reg, compiler.const(0.0, 1)) if width == 3 else (compiler.const((0, 0, 0), 3), reg)
        compiler.b.aov(name, colour, value)
