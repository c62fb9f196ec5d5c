"""Mix and Add Shaders with linked inputs -> node-program rows that blend per shading point.

shading.py blends a Mix or Add Shader's branches into one set of material parameters
(`shading._combine`: alpha-weighted sums, opacity-weighted means over the reflecting branches,
summed emission; the lobes kept apart where the branches' metallic differ). When a Fac or an
input of a branch is linked, that blend cannot be done once at export: here the branches'
linked inputs are compiled (export/nodes.py) and the very same blend is written as Math,
Vector Math, Mix and Scale rows, run at every shading point. Values that are constant
(unlinked sockets) are folded here, so a field that no link reaches keeps the constant path
(the material's own value, no output row).

A value is a constant (a float, or a 3-tuple) or a _Reg (a register of the program).
"""
from __future__ import annotations

from typing import Callable, NamedTuple

from ...render import nodes as program
from . import nodes
from .sockets import live_link, upstream


def specular_strength(*args, **kw):
    """shading.specular_strength (imported late: shading.py imports this module)."""
    from .shading import specular_strength as strength
    return strength(*args, **kw)

MIX_SHADERS = ("MIX_SHADER", "ADD_SHADER")


class _Reg(NamedTuple):
    index: int
    width: int


def _upstream_node(socket):
    """The node feeding a shader socket (sockets.upstream), None when nothing does."""
    found = upstream(socket)
    return found[0] if found is not None else None


class _Blender:
    """Writes the blend of shading._combine into a Compiler's program, folding constants."""

    def __init__(self, compiler: nodes.Compiler, leaf_fields: Callable, defaults: dict, is_bsdf: str):
        self.c, self.b = compiler, compiler.b
        self.leaf_fields, self.defaults, self.is_bsdf = leaf_fields, defaults, is_bsdf
        self.driven: list = []  # the sockets compiled (their default values stand in silently)
        self.normals = False    # whether some branch's Normal is linked: then the normals are blended
        self.surface_normal = None

    # ------------------------------------------------------------ values

    def _value(self, reg: int, width: int):
        """A compiled input's value: the constant itself when the compiler gave a constant
        register (an input it fell back to the unlinked value of), else the register."""
        if reg in self.c.consts.values():
            data = self.b.data[reg:reg + width]
            return float(data[0]) if width == 1 else tuple(float(v) for v in data)
        return _Reg(reg, width)

    def _reg(self, value, width: int) -> int:
        return value.index if isinstance(value, _Reg) else self.c.const(value, width)

    @staticmethod
    def _width(value) -> int:
        return value.width if isinstance(value, _Reg) else (3 if isinstance(value, tuple) else 1)

    def _math(self, op: str, a, b, clamp: bool = False):
        out = self.b.register()
        self.b.emit("MATH", out, self._reg(a, 1), self._reg(b, 1), self._reg(0.0, 1), program.MATH_OPS.index(op),
                    int(clamp))
        return _Reg(out, 1)

    def mul(self, a, b):
        """a x b: scalars, or a colour (a) times a scalar (b)."""
        if not isinstance(a, _Reg) and not isinstance(b, _Reg):
            return tuple(float(x) * float(b) for x in a) if isinstance(a, tuple) else float(a) * float(b)
        zero = (0.0, 0.0, 0.0) if self._width(a) == 3 else 0.0
        if (not isinstance(a, _Reg) and a == zero) or (not isinstance(b, _Reg) and b == 0.0):
            return zero
        if not isinstance(b, _Reg) and b == 1.0:
            return a
        if not isinstance(a, _Reg) and self._width(a) == 1 and a == 1.0:
            return b
        if self._width(a) == 3:
            out = self.b.register(width=3)
            self.b.emit("SCALE", out, self._reg(a, 3), self._reg(b, 1))
            return _Reg(out, 3)
        return self._math("MULTIPLY", a, b)

    def add(self, a, b):
        if not isinstance(a, _Reg) and not isinstance(b, _Reg):
            return tuple(float(x) + float(y) for x, y in zip(a, b)) if isinstance(a, tuple) else float(a) + float(b)
        width = self._width(a)
        zero = (0.0, 0.0, 0.0) if width == 3 else 0.0
        if not isinstance(a, _Reg) and a == zero:
            return b
        if not isinstance(b, _Reg) and b == zero:
            return a
        if width == 1:
            return self._math("ADD", a, b)
        out, unused = self.b.register(width=3), self.b.register()
        self.b.emit("VECTOR_MATH", out, unused, self._reg(a, 3), self._reg(b, 3), self._reg(a, 3),
                    self.c.const(1.0, 1), program.VECTOR_OPS.index("ADD"))
        return _Reg(out, 3)

    def total(self, values):
        out = None
        for v in values:
            out = v if out is None else self.add(out, v)
        return out

    def ratio_or(self, total, weight, default):
        """total / weight where weight > 0, else `default` (shading._combine's rule)."""
        if not isinstance(weight, _Reg):
            return self.mul(total, 1.0 / weight) if weight > 0 else default
        # MATH DIVIDE is Blender's safe division (0 where weight is 0): the mix then picks the default.
        quotient = self.mul(total, self._math("DIVIDE", 1.0, weight))
        positive = self._math("GREATER_THAN", weight, 0.0)
        width = self._width(default)
        out = self.b.register(width=width)
        if width == 1:
            self.b.emit("MIX_FLOAT", out, positive.index, self._reg(default, 1), self._reg(quotient, 1), 0)
        else:
            self.b.emit("MIX_VECTOR", out, positive.index, self._reg(default, 3), self._reg(quotient, 3), 0, 0)
        return _Reg(out, width)

    def positive(self, value):
        if not isinstance(value, _Reg):
            return 1.0 if value > 0 else 0.0
        return self._math("GREATER_THAN", value, 0.0)

    # ------------------------------------------------------------ shaders

    def _input(self, node, name: str, width: int):
        socket = node.inputs[name]
        self.driven.append(socket)
        return self._value(self.c.input(socket, width), width)

    def _fields(self, node, linked: dict) -> dict:
        """shading's constant fields of a shader (node None: nothing connected), `linked`
        replacing some; is_bsdf as 1 or 0 and a normal (0: none) for the blend."""
        fields = {**self.defaults, self.is_bsdf: True, **self.leaf_fields(node), **linked}
        fields[self.is_bsdf] = 1.0 if fields[self.is_bsdf] else 0.0
        fields.setdefault("normal", (0.0, 0.0, 0.0))
        return fields

    def _leaf(self, node) -> dict:
        """A shader's fields: shading's constant reading, its linked inputs compiled."""
        inputs = nodes.SHADER_INPUTS[node.type]
        linked = {}
        for field, names in inputs.items():
            if isinstance(names, tuple):  # emission: colour x strength
                if any(live_link(node.inputs[n]) is not None for n in names):
                    linked[field] = self.mul(self._input(node, names[0], 3), self._input(node, names[1], 1))
            elif names in node.inputs and live_link(node.inputs[names]) is not None:
                linked[field] = self._input(node, names, program.OUTPUTS[field])
        if self.normals and "normal" in inputs and "normal" not in linked:
            # The surface's own normal where this BSDF's is not tilted (one GLOBAL row for all).
            if self.surface_normal is None:
                self.surface_normal = _Reg(self.b.global_("NORMAL"), 3)
            linked["normal"] = self.surface_normal
        return self._fields(node, linked)

    def shader(self, node) -> dict:
        """shading._shader, per shading point, for the node feeding a shader socket."""
        if node is None or node.type not in MIX_SHADERS:
            if node is not None and node.type in nodes.SHADER_INPUTS:
                return self._leaf(node)
            return self._fields(node, {})  # nothing connected, Transparent, an unsupported shader
        first, second = (self.shader(_upstream_node(s)) for s in node.inputs if s.type == "SHADER")
        if node.type == "ADD_SHADER":
            return self.combine([(1.0, first), (1.0, second)], 2.0)
        fac_socket = node.inputs[0]
        if live_link(fac_socket) is not None:
            self.driven.append(fac_socket)
            fac = self._value(self.c.input(fac_socket, 1), 1)
        else:
            fac = float(fac_socket.default_value)
        # Cycles saturates a Mix Shader's factor.
        if isinstance(fac, _Reg):
            fac = self._math("ADD", fac, 0.0, clamp=True)
            return self.combine([(self._math("SUBTRACT", 1.0, fac), first), (fac, second)], 1.0)
        fac = min(max(fac, 0.0), 1.0)
        return self.combine([(1.0 - fac, first), (fac, second)], 1.0)

    def weigh(self, weights, values, total_weight: float):
        """The sum of weights[i] x values[i]. The weights sum to `total_weight` (Mix: 1, Add: 2),
        so values that are all one constant sum to it times that, whatever the weights are at
        a point: a field no link reaches stays a constant, and no row is written for it."""
        if all(not isinstance(v, _Reg) for v in values) and all(v == values[0] for v in values):
            return self.mul(values[0], total_weight)
        return self.total(self.mul(v, w) for w, v in zip(weights, values))

    def combine(self, branches, total_weight: float) -> dict:
        """shading._combine (see its docstring there), per shading point: `branches` is
        [(weight, fields)], the weights summing to total_weight. Branches of weight 0 add
        nothing, as there they are left out."""
        d, bsdf = self.defaults, self.is_bsdf
        weights = [w for w, _ in branches]
        fields = [f for _, f in branches]
        alpha = self.weigh(weights, [f["alpha"] for f in fields], total_weight)
        alpha = min(alpha, 1.0) if not isinstance(alpha, _Reg) else self._math("MINIMUM", alpha, 1.0)
        out = {"alpha": alpha, "emission": self.weigh(weights, [f["emission"] for f in fields], total_weight)}
        # Weighed by the opaque share w x alpha: the values times alpha, then weighed by w.
        for key in ("base_colour", "specular_level"):
            total = self.weigh(weights, [self.mul(f[key], f["alpha"]) for f in fields], total_weight)
            out[key] = self.ratio_or(total, alpha, d[key])
        # A reflecting branch's share: its opaque share where it is a BSDF (is_bsdf: 1 or 0).
        share = [self.mul(f["alpha"], f[bsdf]) for f in fields]
        weight = self.weigh(weights, share, total_weight)
        for key in ("metallic", "roughness", "ior", "transmission", "normal"):
            total = self.weigh(weights, [self.mul(f[key], r) for r, f in zip(share, fields)], total_weight)
            # The normals are weighed alike; their sum is the normal (the core normalises it).
            out[key] = total if key == "normal" else self.ratio_or(total, weight, d[key])
        self._split_lobes(weights, fields, total_weight, alpha, share, out)
        # A blend reflects where a branch of positive weight does. The weights are never all 0.
        flags = [f[bsdf] for f in fields]
        if all(not isinstance(x, _Reg) and x == flags[0] for x in flags):
            out[bsdf] = flags[0]
        else:
            out[bsdf] = 0.0
            for w, flag in zip(weights, flags):
                here = self.mul(self.positive(w), flag)
                if isinstance(here, _Reg) or isinstance(out[bsdf], _Reg):
                    out[bsdf] = here if out[bsdf] == 0.0 else self._math("MAXIMUM", out[bsdf], here)
                else:
                    out[bsdf] = max(out[bsdf], here)
        return out

    def _arith(self, op: str, a, b):
        """a op b for scalars (constants folded): the ops shading.specular_strength takes."""
        if not isinstance(a, _Reg) and not isinstance(b, _Reg):
            return {"ADD": a + b, "SUBTRACT": a - b, "MULTIPLY": a * b, "DIVIDE": a / b if b else 0.0}[op]
        return self.mul(a, b) if op == "MULTIPLY" else self.add(a, b) if op == "ADD" else self._math(op, a, b)

    def _split_lobes(self, weights, fields, total_weight: float, alpha, share, out: dict) -> None:
        """shading._split_lobes, per shading point: where the branches' metallic are not one
        constant (a diffuse and a glossy), the metallic share's own colour, the dielectric
        share's colour, specular level, IOR and transmission, and the roughness weighed by
        specular strength, replacing `out`'s one-lobe blend."""
        metals = [f["metallic"] for f in fields]
        if all(not isinstance(m, _Reg) and m == metals[0] for m in metals) and all(
                f.get("metal_colour") is None for f in fields):
            return
        if any(f.get("use_point_colour") and (isinstance(f["metallic"], _Reg) or f["metallic"] > 0) for f in fields):
            return
        metal = out["metallic"]
        own = [f["metal_colour"] if f.get("metal_colour") is not None else f["base_colour"] for f in fields]
        # A reflecting branch's metallic share, opaque share x metallic.
        metal_share = [self.mul(r, f["metallic"]) for r, f in zip(share, fields)]
        total = self.weigh(weights, [self.mul(c, k) for c, k in zip(own, metal_share)], total_weight)
        blended_base = out["base_colour"]
        out["metal_colour"] = self.ratio_or(total, self.mul(alpha, metal), blended_base)
        # The dielectric share: the opaque share less the metallic one (black branches count).
        dielectric = [self._arith("SUBTRACT", f["alpha"], k) for f, k in zip(fields, metal_share)]
        rest = self.mul(alpha, self._arith("SUBTRACT", 1.0, metal))
        for key in ("base_colour", "specular_level"):
            total = self.weigh(weights, [self.mul(f[key], d) for f, d in zip(fields, dielectric)], total_weight)
            out[key] = self.ratio_or(total, rest, out[key])
        reflecting = [self._arith("SUBTRACT", r, k) for r, k in zip(share, metal_share)]
        weight = self.weigh(weights, reflecting, total_weight)
        for key in ("ior", "transmission"):
            total = self.weigh(weights, [self.mul(f[key], d) for f, d in zip(fields, reflecting)], total_weight)
            out[key] = self.ratio_or(total, weight, out[key])
        ops = tuple(lambda a, b, op=op: self._arith(op, a, b) for op in ("MULTIPLY", "ADD", "SUBTRACT", "DIVIDE"))
        strength = [self.mul(r, specular_strength(f["metallic"], f["transmission"], f["ior"], f["specular_level"],
                                                  ops)) for r, f in zip(share, fields)]
        weight = self.weigh(weights, strength, total_weight)
        total = self.weigh(weights, [self.mul(f["roughness"], k) for f, k in zip(fields, strength)], total_weight)
        out["roughness"] = self.ratio_or(total, weight, out["roughness"])


def _leaves(node):
    """The shader nodes under a Mix or Add Shader tree (the node itself when it is none)."""
    if node is None:
        return
    if node.type in MIX_SHADERS:
        for s in node.inputs:
            if s.type == "SHADER":
                yield from _leaves(_upstream_node(s))
    else:
        yield node


def _linked_inputs(node):
    """The linked inputs of a shader node that a program may compile (nodes.SHADER_INPUTS)."""
    for names in nodes.SHADER_INPUTS.get(node.type, {}).values():
        for name in names if isinstance(names, tuple) else (names,):
            if name in node.inputs and live_link(node.inputs[name]) is not None:
                yield node.inputs[name]


def _mixes(node):
    if node is not None and node.type in MIX_SHADERS:
        yield node
        for s in node.inputs:
            if s.type == "SHADER":
                yield from _mixes(_upstream_node(s))


def needs_program(node, direct: Callable) -> bool:
    """Whether a Mix or Add Shader `node` has a linked Fac (its own or a nested one's) or a
    linked shader input that the constant path cannot read (`direct(socket)`: one it reads,
    the points' colour or alpha straight into a colour or an alpha)."""
    if any(m.type == "MIX_SHADER" and live_link(m.inputs[0]) is not None for m in _mixes(node)):
        return True
    return any(not direct(s) for leaf in _leaves(node) for s in _linked_inputs(leaf))


def compile_mix(node, say, leaf_fields: Callable, defaults: dict, is_bsdf: str, aovs=(), object_space=None,
                material_index: float = 0.0) -> tuple:
    """(Program, the sockets it drives) for a Mix or Add Shader `node` whose Fac or branches
    have linked inputs (needs_program): its outputs are the blended fields some link reaches.
    leaf_fields(node): shading's constant fields of a shader node (None: nothing connected);
    defaults: the Material's; is_bsdf: the key marking a reflecting branch. Raises
    nodes.ProgramTooLarge as compile_shader does."""
    compiler = nodes.Compiler(say, object_space, material_index)
    blender = _Blender(compiler, leaf_fields, defaults, is_bsdf)
    blender.normals = any(s.name == "Normal" for leaf in _leaves(node) for s in _linked_inputs(leaf))
    fields = blender.shader(node)
    for name in program.OUTPUTS:
        if isinstance(fields.get(name), _Reg):
            compiler.b.output(name, fields[name].index)
    nodes.compile_aovs(compiler, aovs)
    return compiler.b.program(), blender.driven
