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

import contextvars
import os

import numpy as np

from ...render import nodes
from ...render.nodes import Builder, ProgramTooLarge  # noqa: F401 (raised through compile_shader)
from ..cloud_object import COLOUR as CLOUD_COLOUR
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
# The scene frame being exported (export_at), which picks an image sequence's frame; None
# before any export. A context variable: the viewport and a final render export in their own
# threads, each at its own frame.
_FRAME: contextvars.ContextVar = contextvars.ContextVar("splat_tracer_frame", default=None)


def export_at(frame: int) -> None:
    """Node trees compiled from now on in this thread are read at scene frame `frame`
    (image sequences); the scene export calls it first."""
    _FRAME.set(int(frame))
# Sky Textures baked for materials: {id(model): (model, Image)}, the last few settings.
_SKY_IMAGES: dict = {}


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

    def __init__(self, say, object_space=None, material_index: float = 0.0):
        self.b = Builder()
        self.material_index = float(material_index)  # the material's pass index (Object Info)
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
        result.update(self._lazy(node, {"Parametric": "PARAMETRIC"}))
        if node.outputs["Tangent"].is_linked:  # Cycles': radial about Z of the generated coordinates
            result[node.outputs["Tangent"].identifier] = self._tangent_of("RADIAL_Z")
        # Derived by the export from the mesh as Cycles derives them (render/mesh_attributes.py),
        # read as attributes: a cloud has neither and reads 0, as Cycles reads a missing one.
        for name, attribute in (("Pointiness", nodes.POINTINESS), ("Random Per Island", nodes.RANDOM_PER_ISLAND)):
            if node.outputs[name].is_linked:
                result[node.outputs[name].identifier] = self.b.attribute(attribute, 1)[1]
        return result

    def _tangent_of(self, kind: str, given: int = 0) -> int:
        out = self.b.register(width=3)
        self.b.emit("TANGENT", out, nodes.TANGENT_KINDS.index(kind), given)
        return out

    def _tangent(self, node, stack):
        """The Tangent node: radial about an axis, or a UV map's tangent, per triangle
        (Cycles interpolates MikkTSpace tangents: the same on flat faces) -- the active
        render map's from the mesh, another map's carried as an attribute."""
        if node.direction_type == "RADIAL":
            return self._ids(node, {"Tangent": self._tangent_of("RADIAL_" + node.axis)})
        if node.uv_map:
            given, _ = self.b.attribute(nodes.TANGENT_OF + node.uv_map, 3)
            return self._ids(node, {"Tangent": self._tangent_of("OBJECT_VECTOR", given)})
        return self._ids(node, {"Tangent": self._tangent_of("UV_MAP")})

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
        name = node.layer_name
        if name in ("", CLOUD_COLOUR):
            return self._point_data(node, False)
        # A named colour attribute, read as the Attribute node reads one (any domain, byte or
        # float); its Alpha from the attribute's transparency, which a geometry lacking it
        # reads as 0. A usual colour name also still means a cloud's own colours (clouds do
        # not carry those names as attributes: scene.py), as it did before.
        own = name in COLOUR_ATTRIBUTE_NAMES
        result = {}
        colour = None
        if any(s.is_linked for s in node.outputs if s.name == "Color"):
            colour, _ = self.b.attribute(name, 3)
            if own:
                summed, unused = self.b.register(width=3), self.b.register()
                self.b.emit("VECTOR_MATH", summed, unused, colour, self.b.global_("POINT_COLOUR"), colour,
                            self.const(1.0, 1), nodes.VECTOR_OPS.index("ADD"))
                colour = summed
        if any(s.is_linked for s in node.outputs if s.name == "Alpha"):
            _, transparency = self.b.attribute(nodes.TRANSPARENCY_OF + name, 1)
            alpha = self.b.register()
            base = self.b.global_("POINT_ALPHA") if own else self.const(1.0, 1)
            self.b.emit("MATH", alpha, base, transparency, transparency, nodes.MATH_OPS.index("SUBTRACT"), 0)
            result.update(self._ids(node, {"Alpha": alpha}))
        if colour is not None:
            result.update(self._ids(node, {"Color": colour}))
        return result

    def _object_info(self, node, stack):
        """Object Info: the instance's own values (export/object_info.py), read only where
        linked; Material Index is the material's pass index, as Cycles gives it."""
        result = {}
        for s in node.outputs:
            if not s.is_linked:
                continue
            if s.name in nodes.OBJECT_INFO:
                result[s.identifier] = self.b.object_info(s.name)
            elif s.name == "Material Index":
                result[s.identifier] = self.const(self.material_index, 1)
        return result

    def _light_path(self, node, stack):
        """Light Path: what the ray that met the point is (the integrator's word, per ray)."""
        first = self.b.light_path()
        result = {}
        for s in node.outputs:
            if s.name in nodes.LIGHT_PATH:
                result[s.identifier] = first + nodes.LIGHT_PATH.index(s.name)
            elif s.name == "Portal Depth":  # no portals here: Cycles' count is 0 without them
                result[s.identifier] = self.const(0.0, 1)
        return result

    def _object_attribute(self, node):
        """An Attribute node of type object, instancer or view layer: the instance's value
        (export/object_info.py looks it up as Cycles does); Fac the colour's average."""
        rgba = self.b.object_attribute(node.attribute_type, node.attribute_name)
        fac = self.convert(rgba, "VECTOR", 1)
        return self._ids(node, {"Color": rgba, "Vector": rgba, "Fac": fac, "Alpha": rgba + 3})

    def _attribute(self, node, stack):
        if node.attribute_type in ("OBJECT", "INSTANCER", "VIEW_LAYER"):
            return self._object_attribute(node)
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
        if node.data_type == "FLOAT_VECTOR":
            return self._map_range_vector(node, stack)
        if node.data_type != "FLOAT":
            raise Unsupported(node, f"{node.data_type.lower()} mapping")
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

    def _map_range_vector(self, node, stack):
        """Map Range in vector mode: per component (native VECTOR_MAP_RANGE, Cycles'
        svm_node_vector_map_range, which divides safely and clamps only linear and stepped)."""
        vectors = [s for s in node.inputs if s.type == "VECTOR"]
        value = self.input(next(s for s in vectors if s.name == "Vector"), 3, stack)
        params = self.b.register(width=3)  # 15 consecutive registers
        for _ in range(4):
            self.b.register(width=3)
        for k, name in enumerate(("From Min", "From Max", "To Min", "To Max", "Steps")):
            socket = next(s for s in vectors if s.name == name)
            self.b.emit("COPY", params + 3 * k, self.input(socket, 3, stack), 3)
        out = self.b.register(width=3)
        self.b.emit("VECTOR_MAP_RANGE", out, value, params, nodes.MAP_RANGE_MODES.index(node.interpolation_type),
                    int(node.clamp))
        return {next(s for s in node.outputs if s.name == "Vector" and s.type == "VECTOR").identifier: out}

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
        table, span, extrapolate = self._curve_table(node.mapping, True)
        fac, colour = self._in(node, "Fac", 1, stack), self._in(node, "Color", 3, stack)
        out = self.b.register(width=3)
        self.b.emit("CURVES", out, fac, colour, table, _TABLE_ROWS, span, extrapolate)
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
        if mode in ("HSV", "HSL"):
            hsv = self.b.register(width=3)
            self.b.emit(f"RGB_TO_{mode}", hsv, v)
            v = hsv
        elif mode != "RGB":
            raise Unsupported(node, f"{mode} mode")
        # The three outputs are the vector's own registers.
        return {s.identifier: v + k for k, s in enumerate(node.outputs[:3])}

    def _combine(self, node, stack, mode="RGB"):
        x, y, z = (self.input(node.inputs[k], 1, stack) for k in range(3))
        out = self.b.register(width=3)
        self.b.emit("COMBINE", out, x, y, z)
        if mode in ("HSV", "HSL"):
            rgb = self.b.register(width=3)
            self.b.emit(f"{mode}_TO_RGB", rgb, out)
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
        if node.space == "TANGENT" and node.uv_map:
            self.say(f": the Normal Map's UV map '{node.uv_map}' is not read; its tangents are the active render "
                     f"UV map's")
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
        # The two nearby points move the position-dependent globals only (ShaderGlobals::bump):
        # what else the height reads is the same at all three points, and adds no slope.
        still = [what for what, read in (
            ("an attribute (an Attribute, Color Attribute or named UV Map node, Pointiness, Random Per Island)",
             lambda row: row[0] == nodes.OPS.index("ATTRIBUTE")),
            ("Geometry > Parametric",
             lambda row: row[0] == nodes.OPS.index("GLOBAL") and row[2] == nodes.GLOBALS.index("PARAMETRIC")),
            ("an Ambient Occlusion node (its rays leave from the shading point)",
             lambda row: row[0] == nodes.OPS.index("AMBIENT_OCCLUSION")))
            if any(read(row) for row in self.b.code[first:])]
        if still:
            self.say(f": the Bump's height reads {' and '.join(still)}, which is not offset along the surface: "
                     f"it adds no slope")
        self.b.emit("BUMP", out, h, strength, distance, normal, first, int(node.invert))
        return {node.outputs[0].identifier: out}

    def _blackbody(self, node, stack):
        out = self.b.register(width=3)
        self.b.emit("BLACKBODY", out, self._in(node, "Temperature", 1, stack))
        return {node.outputs[0].identifier: out}

    def _curve_table(self, mapping, combined: bool):
        """A curve mapping baked as Cycles bakes it: _TABLE_ROWS rows (r, g, b, 0) over the
        range of the curves' points (x from the lowest point to the highest, across curves),
        each channel its curve -- for RGB Curves (`combined`) after the combined curve. Returns
        (table register, range register (min, max), extrapolate): beyond the range Cycles goes
        on along the end rows' slope when the mapping's extension is Extrapolated, else holds."""
        mapping.initialize()
        curves = mapping.curves
        used = list(curves)[:4 if combined else 3]
        xs = [float(p.location[0]) for c in used for p in c.points]
        lo, hi = (min(xs), max(xs)) if xs else (0.0, 1.0)
        rows = []
        for i in range(_TABLE_ROWS):
            x = lo + (hi - lo) * i / (_TABLE_ROWS - 1)
            if combined:
                x = mapping.evaluate(curves[3], x)
            # One curve (Float Curve): the same in all three channels.
            rows.append([mapping.evaluate(used[min(k, len(used) - 1)], x) for k in range(3)] + [0.0])
        return self.b.table(rows), self.b.register((lo, hi, 0.0), 3), int(mapping.extend == "EXTRAPOLATED")

    def _curve_float(self, node, stack):
        """Float Curve: the value through the curve, mixed by Factor (Cycles' svm_node_curve)."""
        table, span, extrapolate = self._curve_table(node.mapping, False)
        fac, value = self._in(node, "Factor", 1, stack), self._in(node, "Value", 1, stack)
        vector, out = self.b.register(width=3), self.b.register(width=3)
        self.b.emit("COMBINE", vector, value, value, value)
        self.b.emit("CURVES", out, fac, vector, table, _TABLE_ROWS, span, extrapolate)
        return {node.outputs[0].identifier: out}

    def _curve_vec(self, node, stack):
        """Vector Curves: each component through its curve (X, Y, Z), mixed by Fac."""
        table, span, extrapolate = self._curve_table(node.mapping, False)
        out = self.b.register(width=3)
        self.b.emit("CURVES", out, self._in(node, "Fac", 1, stack), self._in(node, "Vector", 3, stack), table,
                    _TABLE_ROWS, span, extrapolate)
        return {node.outputs[0].identifier: out}

    def _vector_rotate(self, node, stack):
        kind = nodes.VECTOR_ROTATE_TYPES.index(node.rotation_type)
        euler = kind == nodes.VECTOR_ROTATE_TYPES.index("EULER_XYZ")
        zero, out = self.const((0, 0, 0), 3), self.b.register(width=3)
        vector, center = self._in(node, "Vector", 3, stack), self._in(node, "Center", 3, stack)
        axis = self._in(node, "Axis", 3, stack) if node.rotation_type == "AXIS_ANGLE" else zero
        angle = self.const(0.0, 1) if euler else self._in(node, "Angle", 1, stack)
        rotation = self._in(node, "Rotation", 3, stack) if euler else zero
        self.b.emit("VECTOR_ROTATE", out, vector, center, axis, angle, rotation, kind + 5 * int(node.invert))
        return {node.outputs[0].identifier: out}

    def _normal(self, node, stack):
        """Normal node: its own direction (normalised) and the dot product with the input's
        normalised direction (Cycles' svm_node_normal)."""
        d = np.asarray(node.outputs["Normal"].default_value, np.float64)[:3]
        length = float(np.linalg.norm(d))
        direction = self.const(d / length if length > 0 else d, 3)
        result = {node.outputs["Normal"].identifier: direction}
        if node.outputs["Dot"].is_linked:
            n, unused, dot = self.b.register(width=3), self.b.register(), self.b.register()
            one = self.const(1.0, 1)
            self.b.emit("VECTOR_MATH", n, unused, self._in(node, "Normal", 3, stack), n, n, one,
                        nodes.VECTOR_OPS.index("NORMALIZE"))
            self.b.emit("VECTOR_MATH", self.b.register(width=3), dot, direction, n, n, one,
                        nodes.VECTOR_OPS.index("DOT_PRODUCT"))
            result[node.outputs["Dot"].identifier] = dot
        return result

    def _wavelength(self, node, stack):
        out = self.b.register(width=3)
        self.b.emit("WAVELENGTH", out, self._in(node, "Wavelength", 1, stack))
        return {node.outputs[0].identifier: out}

    def _vect_transform(self, node, stack):
        """Vector Transform between world, object and camera space, as Cycles' (a normal by
        the inverse transpose, normalised; a vector without translation). Object space is
        the shaded object's, at the shading point (native OBJECT_SPACE); world space is
        reached from the render's local frame through object_space(None); camera space is
        Cycles' (+Z along the view) of the scene's camera."""
        kind = nodes.VECTOR_TRANSFORM_TYPES.index(node.vector_type)
        v = self._in(node, "Vector", 3, stack)
        src, dst = node.convert_from, node.convert_to
        if src == dst:
            return {node.outputs[0].identifier: v}
        to_world = np.asarray(self.object_space(None), np.float64) if self.object_space is not None else np.eye(4)
        camera = None
        if "CAMERA" in (src, dst):
            cam = getattr(self.object_space, "camera", None)
            if cam is None:
                raise Unsupported(node, "camera space without a scene camera")
            camera = self._camera_to_world(cam)
        # Cycles goes through world space: from the source to world, then to the target.
        if src == "CAMERA":
            v = self._affine(v, camera, kind)
        elif src == "OBJECT":
            v = self._object_space(v, kind, True)
            v = self._affine(v, to_world, kind)
        if dst == "CAMERA":
            v = self._affine(v, np.linalg.inv(camera), kind)
        elif dst == "OBJECT":
            v = self._affine(v, np.linalg.inv(to_world), kind)
            v = self._object_space(v, kind, False)
        return {node.outputs[0].identifier: v}

    def _camera_to_world(self, cam):
        """Cycles' camera-to-world matrix of a camera object: its world matrix without scale,
        Z flipped (Cycles' camera space looks along +Z)."""
        m = np.array(cam.matrix_world, np.float64)
        norms = np.linalg.norm(m[:3, :3], axis=0)
        m[:3, :3] /= np.where(norms > 0, norms, 1.0)
        return m @ np.diag((1.0, 1.0, -1.0, 1.0))

    def _affine(self, v: int, matrix, kind: int) -> int:
        """A point, vector or normal (kind, VECTOR_TRANSFORM_TYPES) through a 4x4 affine map;
        nothing emitted for the identity."""
        m = np.asarray(matrix, np.float64)
        if kind == 2:  # a normal: the inverse transpose, no translation, normalised
            m = np.eye(4)
            m[:3, :3] = np.linalg.inv(np.asarray(matrix, np.float64)[:3, :3]).T
        elif kind == 1:
            m = m.copy()
            m[:3, 3] = 0.0
        if np.allclose(m, np.eye(4), rtol=0, atol=1e-12):
            return v
        out = self.b.register(width=3)
        self.b.emit("TRANSFORM", out, v, self.b.table(m[:3]))
        if kind == 2:
            unit = self.b.register(width=3)
            self.b.emit("VECTOR_MATH", unit, self.b.register(), out, out, out, self.const(1.0, 1),
                        nodes.VECTOR_OPS.index("NORMALIZE"))
            return unit
        return out

    def _object_space(self, v: int, kind: int, to_world: bool) -> int:
        out = self.b.register(width=3)
        self.b.emit("OBJECT_SPACE", out, v, kind + 3 * int(to_world))
        return out

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
        if image is not None and image.source not in ("FILE", "GENERATED", "TILED", "SEQUENCE"):
            raise Unsupported(node, f"{image.source.lower()} images")
        colour, alpha = self.b.register(width=3), self.b.register()
        tiles = _tile_pixels(image, self.say) if image is not None and image.source == "TILED" else None
        if image is not None and image.source == "SEQUENCE":
            number, texture = _sequence_pixels(node, image, self.say)
            if texture is None:
                what = f"image sequence '{image.name}' has no readable frame {number}"
                return self._missing_image(node, what, colour, alpha)
        else:
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

    def _tex_sky(self, node, stack):
        """Sky Texture in a material: the sky baked once per settings into an equirectangular
        image (render/sky.py sky_image), looked up at the Vector's direction as the
        Environment Texture is (unlinked: the generated coordinates, Cycles' default for it)."""
        from ...render import sky
        from .world import _sky_model

        model = _sky_model(node)
        width = sky.MATERIAL_SKY_WIDTH
        # The sun disc is left out: Cycles tests it by the angle of the raw vector (which, with
        # the disc on, Blender makes the generated coordinates: not a unit vector), which a
        # lookup by elevation and azimuth cannot reproduce.
        if isinstance(model, sky.Sky) and model.sun_disc and model.size > 0 and model.intensity > 0:
            self.say(": the Sky Texture's sun disc is not drawn in a material (the sky is)")
        key = id(model)
        if key not in _SKY_IMAGES or _SKY_IMAGES[key][0] is not model:
            while len(_SKY_IMAGES) >= 4:
                _SKY_IMAGES.pop(next(iter(list(_SKY_IMAGES))), None)  # (another thread may take it first)
            _SKY_IMAGES[key] = (model, nodes.Image(sky.sky_image(model, width)))
        image = _SKY_IMAGES[key][1]
        socket = next(s for s in node.inputs if s.name == "Vector")
        # Blender makes the Vector unavailable while a sun disc is on: a link to it is ignored.
        if socket.enabled:
            vector = self._vector_or(node, stack)
        else:
            vector = self.b.global_("GENERATED")
        vector = self._sky_direction(vector)
        uv, colour, alpha = self.b.register(width=3), self.b.register(width=3), self.b.register()
        self.b.emit("IMAGE_PROJECT", uv, vector, nodes.IMAGE_PROJECTIONS.index("EQUIRECTANGULAR"))
        self.b.emit("IMAGE", colour, alpha, uv, self.b.image(image), nodes.INTERPOLATIONS.index("Linear"),
                    nodes.EXTENSIONS.index("REPEAT"))
        return self._ids(node, {"Color": colour})

    def _sky_direction(self, vector: int) -> int:
        """The direction Cycles' Sky Texture reads from a vector it does not normalise: the
        elevation asin(z) of its z clamped to -1..1, the azimuth atan2(y, x) (Cycles'
        direction_to_spherical), as a unit vector for the equirectangular lookup."""
        math_op = nodes.MATH_OPS.index
        x, y, z = vector, vector + 1, vector + 2  # a vector's components are consecutive registers
        one, minus_one = self.const(1.0, 1), self.const(-1.0, 1)
        zc, zz, h, phi, c, s_, hx, hy = (self.b.register() for _ in range(8))
        self.b.emit("CLAMP", zc, z, minus_one, one, 0)
        self.b.emit("MATH", zz, zc, zc, zc, math_op("MULTIPLY"), 0)
        self.b.emit("MATH", h, one, zz, zz, math_op("SUBTRACT"), 0)
        self.b.emit("MATH", h, h, h, h, math_op("SQRT"), 0)
        self.b.emit("MATH", phi, y, x, x, math_op("ARCTAN2"), 0)
        self.b.emit("MATH", c, phi, phi, phi, math_op("COSINE"), 0)
        self.b.emit("MATH", s_, phi, phi, phi, math_op("SINE"), 0)
        self.b.emit("MATH", hx, h, c, c, math_op("MULTIPLY"), 0)
        self.b.emit("MATH", hy, h, s_, s_, math_op("MULTIPLY"), 0)
        out = self.b.register(width=3)
        self.b.emit("COMBINE", out, hx, hy, zc)
        return out

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

    def _tex_gabor(self, node, stack):
        """Gabor Texture, 2-D or 3-D (native nodes/gabor.h); unlinked Vector: Generated."""
        vector = self._vector_or(node, stack)
        # Two inputs are named Orientation: an angle (2-D) and a direction (3-D); each type reads one.
        params = self._params(node, stack, ("Scale", "Frequency", "Anisotropy"), extra=(0.0,))
        three_d = node.gabor_type == "3D"
        angle, direction = (next(s for s in node.inputs if s.name == "Orientation" and s.type == t)
                            for t in ("VALUE", "VECTOR"))
        if three_d:
            orientation = self.input(direction, 3, stack)
        else:
            orientation = self.const((0, 0, 1), 3)
            self.b.emit("COPY", params + 3, self.input(angle, 1, stack), 1)
        out = self.b.register(width=3)  # value, phase, intensity
        self.b.emit("GABOR", out, vector, params, orientation, int(three_d))
        return self._ids(node, {"Value": out, "Phase": out + 1, "Intensity": out + 2})

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
    texture = _texture(read, image.is_float, image.alpha_mode)
    # Keep only the current version of each image (its old pixels are garbage).
    # (A snapshot of the keys: the viewport's and a final render's threads both read images.)
    for old in [k for k in list(_IMAGES) if k[:2] == key[:2]]:
        _IMAGES.pop(old, None)
    _IMAGES[key] = texture
    return texture


def _texture(read: images.Pixels, is_float: bool, alpha_mode: str):
    """images.Pixels as the core's nodes.Image, in the image's Alpha mode."""
    pixels = read.values
    if alpha_mode == "NONE":  # Cycles ignores the image's alpha
        pixels[..., 3] = 1.0
    if is_float:
        return nodes.Image(pixels, srgb=read.srgb)
    # kept as the bytes they are (a quarter of the floats)
    return nodes.Image(np.clip(np.rint(pixels * 255.0), 0, 255).astype(np.uint8), srgb=read.srgb)


# Images read from files rather than from Blender's image (UDIM tiles after the first, the
# frames of sequences: _file_pixels), by what identifies their pixels.
_FILES: dict = {}


def _file_pixels(image, slot, path: str, say):
    """The nodes.Image of the file at `path` read for `image` (its colour space and alpha
    mode; images.read_file, which creates no Blender image: safe within a render), or None
    when it cannot be read. Kept while the file is unchanged; one file per (image, slot) is
    kept: a tile number, or a sequence node's current frame."""
    try:
        stamp = (os.path.getmtime(path), os.path.getsize(path))
    except OSError:
        return None
    key = (image.name_full, slot, path, stamp, image.colorspace_settings.name, image.alpha_mode)
    if key not in _FILES:
        read = images.read_file(path, image.colorspace_settings.name, image.name, say, image.alpha_mode)
        for old in [k for k in list(_FILES) if k[:2] == key[:2]]:  # a snapshot: another thread may add
            _FILES.pop(old, None)
        _FILES[key] = _texture(read, read.is_float, image.alpha_mode) if read is not None else None
    return _FILES[key]


def _tile_pixels(image, say) -> list:
    """A UDIM (tiled) image's tiles as [(tile number, nodes.Image or None)]: the first tile
    from the image's own pixels (what Blender holds, painted or packed alike), the others
    from their files (the image's path with its <UDIM> or <UVTILE> token filled), read as
    Blender would load them (_file_pixels). A tile that cannot be read (not saved, packed,
    missing) is None: magenta, as Cycles renders a tile it cannot load -- said once."""
    import bpy

    out, missing = [], []
    for k, tile in enumerate(image.tiles):
        number = int(tile.number)
        if k == 0:
            out.append((number, _image_pixels(image, say)))
            if out[-1][1] is None:
                missing.append(number)
            continue
        u, v = (number - 1001) % 10, (number - 1001) // 10
        path = image.filepath_raw.replace("<UDIM>", str(number)).replace("<UVTILE>", f"u{u + 1}_v{v + 1}")
        path = bpy.path.abspath(path, library=image.library)
        texture = None
        if path != bpy.path.abspath(image.filepath_raw, library=image.library):
            texture = _file_pixels(image, number, path, say)
        if texture is None:
            missing.append(number)
        out.append((number, texture))
    if missing:
        say(f": image '{image.name}' tile{'s' if len(missing) > 1 else ''} {', '.join(map(str, missing))} "
            f"could not be read (not saved to a file?); rendered magenta, as Cycles does")
    return out


def _sequence_pixels(node, image, say) -> tuple:
    """(frame number, nodes.Image or None) of an image sequence at the frame being exported:
    the frame Cycles renders (sequence_frame of the node's Image User at the scene frame; Blender's
    own frame_current outside an export), read from its file (_file_pixels). A packed sequence
    is not read (None)."""
    import bpy

    user, frame = node.image_user, _FRAME.get()
    number = sequence_frame(user, frame) if frame is not None else int(user.frame_current)
    if image.packed_file is not None or len(image.packed_files):
        say(f": image sequence '{image.name}' is packed; its frames are read from files only")
        return number, None
    path = bpy.path.abspath(sequence_path(image.filepath_raw, number), library=image.library)
    # One frame kept per node (each Image User picks its own frame).
    return number, _file_pixels(image, ("frame", node.id_data.name_full, node.name), path, say)


def sequence_frame(user, frame: int) -> int:
    """The frame of an image sequence an Image User shows at scene frame `frame`, by Blender's
    rule (BKE_image_user_frame_get): counted from Start Frame (the user's first is 1),
    wrapped over Frames when Cyclic, else held at 0 before it and at Frames after, then
    moved by Offset. Frames 0: frame 0, as Blender."""
    count = int(user.frame_duration)
    if count <= 0:
        return 0
    n = int(frame) - int(user.frame_start) + 1
    if user.use_cyclic:
        n = n % count or count  # 1..count
    return min(max(n, 0), count) + int(user.frame_offset)


def sequence_path(path: str, number: int) -> str:
    """An image sequence's path at frame `number`, as Blender numbers it (BLI_path_sequence_*):
    the last run of digits in the file name before its extension holds the frame, padded to
    as many digits; a name without digits gets the number before its extension."""
    cut = max(path.rfind("/"), path.rfind("\\")) + 1
    name = path[cut:]
    dot = name.rfind(".")
    end = dot if dot > 0 else len(name)
    last = end
    while last > 0 and not name[last - 1].isdigit():
        last -= 1
    first = last
    while first > 0 and name[first - 1].isdigit():
        first -= 1
    if first == last:  # no digits: Blender writes the number unpadded ("" for 0, as C's %.0d)
        first = last = end
    digits = str(abs(number)).zfill(last - first) if (number or last > first) else ""
    return path[:cut] + name[:first] + ("-" if number < 0 else "") + digits + name[last:]


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


def compile_shader(node, say, skip=(), aovs=(), object_space=None, material_index: float = 0.0) -> tuple:
    """(Program or None, the input sockets it drives) for a shader node's linked inputs
    (those in SHADER_INPUTS, but not the sockets in `skip`, which the constant path reads)
    and for AOV Output nodes: `aovs`, (AOV name, width, the node's Color or Value socket)
    each. None when nothing needs a program: such a material costs nothing more to render.
    node: None when nothing feeds the Material Output (AOVs only). object_space,
    material_index: see Compiler."""
    fields = SHADER_INPUTS.get(node.type, {}) if node is not None else {}
    compiler = Compiler(say, object_space, material_index)
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
