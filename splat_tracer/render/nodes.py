"""Shader-node programs: a material's node tree as the native evaluator runs it.

Blender-free: `blender/export/nodes.py` walks a node tree and writes the program through a
`Builder`; the core (`native/nodes/program.h`, whose enumerations these tuples mirror: keep
both in step) runs it at every shading point a ray meets, secondary rays included. The idea
is Cycles' SVM: compiled once per material at export, a flat list of instructions over a
register file of floats (a colour or a vector takes three consecutive registers).

Instruction: (opcode, operands...) padded to WIDTH int32. Operands are register indices,
enumeration values (an index into one of the tuples below) or, for tables, a register offset
and a row count. `data`: every register's initial value (constants, unlinked sockets, tables).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Sequence

import numpy as np

WIDTH = 8            # int32 per instruction (native kNodeWidth)
MAX_REGISTERS = 4096  # native kMaxNodeRegisters: a larger program is refused at export
MAX_BUMP_DEPTH = 3   # native kMaxBumpDepth: Bump nodes within a Bump's height, each level 3x the cost
MAX_AO_SAMPLES = 128  # native kMaxAoSamples: the Ambient Occlusion node's Samples (Blender's limit)

# Opcodes, in the native Op order; the operand layout of each is in program.h.
OPS = ("GLOBAL", "COPY", "MATH", "VECTOR_MATH", "MIX_FLOAT", "MIX_VECTOR", "MIX_COLOUR", "MAP_RANGE", "CLAMP",
       "RAMP", "HUE_SAT_VAL", "INVERT", "BRIGHT_CONTRAST", "GAMMA", "RGB_TO_BW", "COMBINE", "RGB_TO_HSV",
       "HSV_TO_RGB", "MAPPING", "CHECKER", "GRADIENT", "FRESNEL", "LAYER_WEIGHT", "NOISE", "WHITE_NOISE", "SCALE",
       "CURVES", "IMAGE", "VORONOI", "WAVE", "MAGIC", "NORMAL_MAP", "BRICK", "BLACKBODY", "BUMP", "ATTRIBUTE",
       "IMAGE_PROJECT", "IMAGE_BOX", "IMAGE_TILES", "TRANSFORM", "VECTOR_ROTATE", "RGB_TO_HSL", "HSL_TO_RGB",
       "WAVELENGTH", "OBJECT_SPACE", "VECTOR_MAP_RANGE", "GABOR", "OBJECT_VALUE", "LIGHT_PATH",
       "TANGENT", "AMBIENT_OCCLUSION", "WIREFRAME", "BEVEL")
# The most point-attribute floats a scene's programs read (native kMaxPointAttributes): a
# float attribute takes one, a vector or colour three.
MAX_POINT_ATTRIBUTES = 12
# An instance's own values as OBJECT_VALUE reads them (native ShaderGlobals::object_values):
# Object Info's outputs at these offsets (offset, width), then RGBA per object attribute
# (Attribute node of type object, instancer or view layer) in the scene's order, at most
# MAX_OBJECT_ATTRIBUTES (native kObjectInfoFloats, kMaxObjectAttributes).
OBJECT_INFO = {"Location": (0, 3), "Color": (3, 3), "Alpha": (6, 1), "Object Index": (7, 1), "Random": (8, 1)}
OBJECT_INFO_FLOATS = 9
MAX_OBJECT_ATTRIBUTES = 16
# Light Path's outputs in the order LIGHT_PATH writes them (native kLightPathFloats).
LIGHT_PATH = ("Is Camera Ray", "Is Shadow Ray", "Is Diffuse Ray", "Is Glossy Ray", "Is Singular Ray",
              "Is Reflection Ray", "Is Transmission Ray", "Is Volume Scatter Ray", "Ray Length", "Ray Depth",
              "Diffuse Depth", "Glossy Depth", "Transparent Depth", "Transmission Depth")
# Attributes the export derives from a mesh, as Cycles does, for the nodes that read them
# (read like a named attribute; a geometry without them -- a cloud -- reads 0, as Cycles
# reads a missing one). The leading dot keeps them apart from a user's attribute names,
# which Blender keeps for its own.
POINTINESS = ".splat_tracer.pointiness"            # Geometry > Pointiness (render/mesh_attributes.py)
RANDOM_PER_ISLAND = ".splat_tracer.random_per_island"  # Geometry > Random Per Island
# A colour attribute's transparency (1 - alpha), named by this prefix and the attribute's
# name: the Color Attribute node's Alpha, 0 where the geometry lacks it.
TRANSPARENCY_OF = ".splat_tracer.transparency:"
# A UV map's tangent per triangle (object space), named by this prefix and the map's name:
# the Tangent node naming a map other than the active render one; 0 where the mesh lacks it.
TANGENT_OF = ".splat_tracer.tangent:"
# What a program reads at the shading point (native Global), all vec3 registers.
GLOBALS = ("POSITION", "NORMAL", "TRUE_NORMAL", "INCOMING", "OBJECT", "OBJECT_NORMAL", "GENERATED", "UV",
           "POINT_COLOUR", "POINT_ALPHA", "REFLECTION", "BACKFACING", "CAMERA", "WINDOW", "PARAMETRIC")
# The material inputs a program may drive (native Output), with their widths.
OUTPUTS = {"base_colour": 3, "metallic": 1, "roughness": 1, "ior": 1, "transmission": 1, "alpha": 1,
           "emission": 3, "specular_level": 1, "normal": 3,
           "metal_colour": 3}
# Blender's identifiers, in the order the core numbers them.
MATH_OPS = ("ADD", "SUBTRACT", "MULTIPLY", "DIVIDE", "MULTIPLY_ADD", "POWER", "LOGARITHM", "SQRT", "INVERSE_SQRT",
            "ABSOLUTE", "EXPONENT", "MINIMUM", "MAXIMUM", "LESS_THAN", "GREATER_THAN", "SIGN", "COMPARE",
            "SMOOTH_MIN", "SMOOTH_MAX", "ROUND", "FLOOR", "CEIL", "TRUNC", "FRACT", "MODULO", "FLOORED_MODULO",
            "WRAP", "SNAP", "PINGPONG", "SINE", "COSINE", "TANGENT", "ARCSINE", "ARCCOSINE", "ARCTANGENT",
            "ARCTAN2", "SINH", "COSH", "TANH", "RADIANS", "DEGREES")
VECTOR_OPS = ("ADD", "SUBTRACT", "MULTIPLY", "DIVIDE", "MULTIPLY_ADD", "CROSS_PRODUCT", "PROJECT", "REFLECT",
              "REFRACT", "FACEFORWARD", "DOT_PRODUCT", "DISTANCE", "LENGTH", "SCALE", "NORMALIZE", "ABSOLUTE",
              "POWER", "SIGN", "MINIMUM", "MAXIMUM", "FLOOR", "CEIL", "FRACTION", "MODULO", "WRAP", "SNAP", "SINE",
              "COSINE", "TANGENT")
BLENDS = ("MIX", "DARKEN", "MULTIPLY", "BURN", "LIGHTEN", "SCREEN", "DODGE", "ADD", "OVERLAY", "SOFT_LIGHT",
          "LINEAR_LIGHT", "DIFFERENCE", "EXCLUSION", "SUBTRACT", "DIVIDE", "HUE", "SATURATION", "COLOR", "VALUE")
MAP_RANGE_MODES = ("LINEAR", "STEPPED", "SMOOTHSTEP", "SMOOTHERSTEP")
GRADIENTS = ("LINEAR", "QUADRATIC", "EASING", "DIAGONAL", "RADIAL", "QUADRATIC_SPHERE", "SPHERICAL")
MAPPINGS = ("POINT", "TEXTURE", "VECTOR", "NORMAL")
INTERPOLATIONS = ("Closest", "Linear", "Cubic")  # Image Texture (native ImageInterpolation)
EXTENSIONS = ("REPEAT", "EXTEND", "CLIP", "MIRROR")  # Image Texture (native ImageExtension)
# IMAGE_PROJECT's kinds: Image Texture's projections that remap the vector, then Environment
# Texture's (of the vector's direction).
IMAGE_PROJECTIONS = ("SPHERE", "TUBE", "EQUIRECTANGULAR", "MIRROR_BALL")
VORONOI_METRICS = ("EUCLIDEAN", "MANHATTAN", "CHEBYSHEV", "MINKOWSKI")
VORONOI_FEATURES = ("F1", "F2", "SMOOTH_F1", "DISTANCE_TO_EDGE", "N_SPHERE_RADIUS")  # native VoronoiFeature
WAVE_KINDS = ("BANDS_X", "BANDS_Y", "BANDS_Z", "BANDS_DIAGONAL", "RINGS_X", "RINGS_Y", "RINGS_Z", "RINGS_SPHERICAL")
WAVE_PROFILES = ("SIN", "SAW", "TRI")
NORMAL_MAP_SPACES = ("TANGENT", "OBJECT", "WORLD")
# Vector Rotate's rotation_type (native VectorRotate kind; + 5 when inverted).
VECTOR_ROTATE_TYPES = ("AXIS_ANGLE", "X_AXIS", "Y_AXIS", "Z_AXIS", "EULER_XYZ")
# Vector Transform's vector_type (native ObjectSpace kind; + 3 towards the render's frame).
VECTOR_TRANSFORM_TYPES = ("POINT", "VECTOR", "NORMAL")
# TANGENT's kinds: the Tangent node's radial directions about an axis of the generated
# coordinates (Geometry > Tangent is RADIAL_Z), and the UV map's tangent.
# OBJECT_VECTOR: an object-space tangent given in the third operand (a named map's, read as
# an attribute), taken to the scene as Cycles takes a UV tangent.
TANGENT_KINDS = ("RADIAL_X", "RADIAL_Y", "RADIAL_Z", "UV_MAP", "OBJECT_VECTOR")
# Noise Texture: Blender's noise_type identifiers (native NoiseType), and the node's inputs in
# the order of the NOISE instruction's register block (native NoiseParams).
NOISE_TYPES = ("FBM", "MULTIFRACTAL", "RIDGED_MULTIFRACTAL", "HYBRID_MULTIFRACTAL", "HETERO_TERRAIN")
NOISE_PARAMS = ("Scale", "Detail", "Roughness", "Lacunarity", "Distortion", "W", "Offset", "Gain")

# The shading point as run_nodes takes it: these vec3s, then point_alpha, backfacing and
# tangent_sign. tangent: the UV map's (unit, perpendicular to surface_normal, the surface's
# normal before it is turned towards the viewer). bump_dx, bump_dy: the Bump node's two offset
# points, relative to this one (every position-dependent global moves by them alike; u, v by
# their x, y).
GLOBAL_FIELDS = ("P", "N", "Ng", "I", "object", "object_normal", "generated", "uv", "point_colour", "tangent",
                 "surface_normal", "bump_dx", "bump_dy")
_GLOBAL_FLOATS = 3 * len(GLOBAL_FIELDS) + 3


class Image:
    """An image's pixels for the core: (height, width, 4) RGBA, bottom row first (Blender's
    order): uint8 colour bytes or float32 values, sRGB-encoded when `srgb` (decoded to scene
    linear after interpolation, as Cycles does with sRGB images, byte or float), else linear
    (bytes: values x 255). Compared by identity: one Image is held once by the core however
    many programs use it."""

    def __init__(self, pixels, srgb: bool = False):
        p = np.ascontiguousarray(pixels)
        if p.dtype not in (np.uint8, np.float32) or p.ndim != 3 or p.shape[2] != 4 or not p.size:
            raise ValueError(f"image pixels must be (h, w, 4) uint8 or float32, got {p.dtype} {p.shape}")
        self.pixels, self.srgb = p, bool(srgb)
        self.native = (p, self.srgb)  # one object, so that the core recognises it when shared

    @property
    def nbytes(self) -> int:
        return int(self.pixels.nbytes)


@dataclass(frozen=True)
class Program:
    """One material's compiled node tree: `code` (rows of WIDTH ints), `data` (initial
    registers), `outputs` (per OUTPUTS entry, the register holding it or -1). Hashable, so
    that a Material holding it stays a value."""

    code: tuple
    data: tuple
    outputs: tuple
    images: tuple = ()  # Image objects, by the index IMAGE instructions give
    # AOV Output nodes: (AOV name, Color register (3 wide), Value register), written on the
    # camera ray's surfaces into the view layer's AOV of that name (native shade/aov.h).
    aovs: tuple = ()
    # The point attributes its Attribute nodes read: (name, width) in the order their
    # ATTRIBUTE instructions number them (width 1: float, 3: vector or colour).
    attributes: tuple = ()
    # The object attributes its Attribute nodes of type object, instancer or view layer read:
    # (type, name) in the order their OBJECT_VALUE instructions number them.
    object_attributes: tuple = ()

    def native(self, aov_keys: Optional[dict] = None, attribute_columns: Optional[dict] = None,
               object_slots: Optional[dict] = None) -> tuple:
        """(code, data, outputs, images[, aovs]) as the core takes them; aovs: (k, 3) int32
        rows (key, colour, value) for the AOV Output nodes whose name aov_keys numbers.
        attribute_columns: {name: first column} of the scene's point attributes
        (attribute_layout); without it the program's own order (columns_of). object_slots:
        {(type, name): slot} of the scene's object attributes (object_attribute_layout);
        without it the program's own order."""
        code = np.array(self.code, np.int32).reshape(-1, WIDTH)
        if self.attributes:
            columns = attribute_columns if attribute_columns is not None else columns_of(self.attributes)
            for i in np.flatnonzero(code[:, 0] == OPS.index("ATTRIBUTE")):
                # A name the scene's clouds do not carry (past the limit): a column no point has, 0.
                code[i, 3] = columns.get(self.attributes[code[i, 3]][0], MAX_POINT_ATTRIBUTES)
        if self.object_attributes and object_slots is not None:
            never = OBJECT_INFO_FLOATS + 4 * MAX_OBJECT_ATTRIBUTES  # no instance carries it: reads 0
            for i in np.flatnonzero((code[:, 0] == OPS.index("OBJECT_VALUE")) & (code[:, 2] >= OBJECT_INFO_FLOATS)):
                key = self.object_attributes[(code[i, 2] - OBJECT_INFO_FLOATS) // 4]
                slot = object_slots.get(key, MAX_OBJECT_ATTRIBUTES)
                code[i, 2] = OBJECT_INFO_FLOATS + 4 * slot if slot < MAX_OBJECT_ATTRIBUTES else never
        out = (code, np.array(self.data, np.float32),
               np.array(self.outputs, np.int32), tuple(image.native for image in self.images))
        rows = [(aov_keys[name], c, v) for name, c, v in self.aovs if aov_keys and name in aov_keys]
        return out + (np.array(rows, np.int32).reshape(-1, 3),) if rows else out

    def reads_object(self) -> bool:
        """Whether the program reads its instance's values (Object Info, object attributes)."""
        return OPS.index("OBJECT_VALUE") in (row[0] for row in self.code)

    def writes_only_aovs(self) -> bool:
        """Whether the program drives no material input (it exists for its AOV Output nodes)."""
        return all(o < 0 for o in self.outputs)

    def drives(self, name: str) -> bool:
        return self.outputs[list(OUTPUTS).index(name)] >= 0


class ProgramTooLarge(ValueError):
    pass


def columns_of(attributes) -> dict:
    """{name: first column} for (name, width) pairs laid out one after another."""
    columns, first = {}, 0
    for name, width in attributes:
        if name not in columns:
            columns[name] = first
            first += width
    return columns


def attributes_read(programs) -> dict:
    """{name: width} of the point attributes the programs read (a name read both as a float
    and as a colour: the wider)."""
    widths = {}
    for program in programs:
        if program is not None:
            for name, width in program.attributes:
                widths[name] = max(widths.get(name, 0), width)
    return widths


def attribute_layout(programs) -> tuple:
    """The point attributes a scene's programs read, as the clouds carry them: (name, width)
    sorted by name, each once, as many as fit in MAX_POINT_ATTRIBUTES floats (the others read
    0: attributes_read tells which were left out)."""
    layout, used = [], 0
    # The user's own names first: the ones the export derives (POINTINESS, ...) after them.
    for name, width in sorted(attributes_read(programs).items(), key=lambda item: (_is_derived(item[0]), item[0])):
        if used + width <= MAX_POINT_ATTRIBUTES:
            layout.append((name, width))
            used += width
    return tuple(layout)


def _is_derived(name: str) -> bool:
    return name in (POINTINESS, RANDOM_PER_ISLAND) or name.startswith((TRANSPARENCY_OF, TANGENT_OF))


def attribute_label(name: str) -> str:
    """How the render report names an attribute a program reads: the user's own by its name,
    one the export derives by what it is."""
    if name == POINTINESS:
        return "Geometry > Pointiness"
    if name == RANDOM_PER_ISLAND:
        return "Geometry > Random Per Island"
    if name.startswith(TRANSPARENCY_OF):
        return f"the alpha of colour attribute {name[len(TRANSPARENCY_OF):]!r}"
    if name.startswith(TANGENT_OF):
        return f"the tangent of UV map {name[len(TANGENT_OF):]!r}"
    return f"attribute {name!r}"


def object_attribute_layout(programs) -> tuple:
    """The object attributes ((type, name), sorted) a scene's programs read: each instance
    carries their values in this order (the first MAX_OBJECT_ATTRIBUTES; the others read 0)."""
    return tuple(sorted({key for p in programs if p is not None for key in p.object_attributes}))


def attribute_columns(layout, values: dict, n: int) -> Optional[np.ndarray]:
    """The (n, k) float32 array a cloud carries for `layout` (attribute_layout), from its
    `values` ({name: (n,) or (n, 3) array}); a name it lacks is 0, as a missing attribute
    is in Cycles (a float read from a vector: its components' average). None for no layout."""
    if not layout:
        return None
    out = np.zeros((n, sum(w for _, w in layout)), np.float32)
    first = 0
    for name, width in layout:
        if name in values:
            v = np.asarray(values[name], np.float32).reshape(n, -1)
            if width == 1:
                out[:, first] = v.mean(axis=1)
            else:
                out[:, first:first + 3] = v[:, :3] if v.shape[1] >= 3 else v[:, :1]
        first += width
    return out


class Builder:
    """Writes a Program: registers (constants or results), instructions, outputs."""

    def __init__(self):
        self.code: list = []
        self.data: list = []
        self.outputs = {name: -1 for name in OUTPUTS}
        self.images: list = []
        self.aovs: list = []
        self.attributes: list = []
        self.object_attributes: list = []

    def image(self, image: Image) -> int:
        """The index of an image in this program (added once)."""
        for i, known in enumerate(self.images):
            if known is image:
                return i
        self.images.append(image)
        return len(self.images) - 1

    def register(self, value=0.0, width: int = 1) -> int:
        """A new register (width 1 or 3) holding `value` until written."""
        values = np.broadcast_to(np.asarray(value, np.float64).ravel()[:width] if np.ndim(value) else value, (width,))
        first = len(self.data)
        self.data.extend(float(v) for v in values)
        if len(self.data) > MAX_REGISTERS:
            raise ProgramTooLarge(f"more than {MAX_REGISTERS} registers")
        return first

    def table(self, rows) -> int:
        """Read-only rows (e.g. RGBA stops) laid out flat in the registers; their offset."""
        flat = np.asarray(rows, np.float64).ravel()
        first = len(self.data)
        self.data.extend(float(v) for v in flat)
        if len(self.data) > MAX_REGISTERS:
            raise ProgramTooLarge(f"more than {MAX_REGISTERS} registers")
        return first

    def emit(self, op: str, *operands: int) -> None:
        if len(operands) > WIDTH - 1:
            raise ValueError(f"{op}: too many operands")
        self.code.append((OPS.index(op), *(int(o) for o in operands), *([0] * (WIDTH - 1 - len(operands)))))

    def global_(self, name: str) -> int:
        out = self.register(width=3)
        self.emit("GLOBAL", out, GLOBALS.index(name))
        return out

    def attribute(self, name: str, width: int) -> tuple:
        """A point attribute (width 1: float, 3: vector or colour) as Cycles' Attribute node
        gives it: (colour/vector register, fac register)."""
        if width not in (1, 3):
            raise ValueError(f"attribute width must be 1 or 3, got {width}")
        entry = (str(name), width)
        if entry not in self.attributes:
            self.attributes.append(entry)
        colour, fac = self.register(width=3), self.register()
        self.emit("ATTRIBUTE", colour, fac, self.attributes.index(entry), width)
        return colour, fac

    def object_info(self, name: str) -> int:
        """One of Object Info's outputs (OBJECT_INFO) of the instance being shaded."""
        first, width = OBJECT_INFO[name]
        out = self.register(width=width)
        self.emit("OBJECT_VALUE", out, first, width)
        return out

    def object_attribute(self, kind: str, name: str) -> int:
        """An object, instancer or view-layer attribute (`kind`) of the instance being shaded:
        a 4-wide register block (R, G, B, A)."""
        key = (str(kind), str(name))
        if key not in self.object_attributes:
            self.object_attributes.append(key)
        out = self.register(width=4)
        self.emit("OBJECT_VALUE", out, OBJECT_INFO_FLOATS + 4 * self.object_attributes.index(key), 4)
        return out

    def light_path(self) -> int:
        """Light Path's outputs (LIGHT_PATH order) for the ray that met the point: the first register."""
        out = self.register(width=len(LIGHT_PATH))
        self.emit("LIGHT_PATH", out)
        return out

    def output(self, name: str, reg: int) -> None:
        self.outputs[name] = reg

    def aov(self, name: str, colour: int, value: int) -> None:
        """An AOV Output node: its Color (a 3-wide register) and Value into the AOV `name`."""
        self.aovs.append((str(name), int(colour), int(value)))

    def program(self) -> Program:
        return Program(tuple(self.code), tuple(self.data), tuple(self.outputs[n] for n in OUTPUTS), tuple(self.images),
                       tuple(self.aovs), tuple(self.attributes), tuple(self.object_attributes))


def run(program: Program, n: int = 1, point_alpha=1.0, backfacing=0.0, tangent_sign=1.0, attributes=None,
        **globals_) -> np.ndarray:
    """The registers after running `program` at n shading points (n, len(data)): each of
    GLOBAL_FIELDS given as (3,) or (n, 3) (default 0), point_alpha and backfacing as scalars
    or (n,); attributes: {name: (n,) or (n, 3) values} the points carry (a name the program
    reads and they lack is 0). For tests and tools: renders run programs inside the core."""
    from .. import _core

    unknown = set(globals_) - set(GLOBAL_FIELDS)
    if unknown:
        raise ValueError(f"unknown shading-point fields {sorted(unknown)}; use {GLOBAL_FIELDS}")
    g = np.zeros((n, _GLOBAL_FLOATS), np.float32)
    for k, name in enumerate(GLOBAL_FIELDS):
        if name in globals_:
            g[:, 3 * k:3 * k + 3] = np.broadcast_to(np.asarray(globals_[name], np.float32), (n, 3))
    g[:, -3] = point_alpha
    g[:, -2] = backfacing
    g[:, -1] = tangent_sign
    out = np.zeros((n, len(program.data)), np.float32)
    layout = attribute_layout([program])
    code, data, outputs, images = program.native(attribute_columns=columns_of(layout))
    values = {k: np.broadcast_to(np.asarray(v, np.float32), (n,)) if np.ndim(v) == 0 else v
              for k, v in (attributes or {}).items()}
    columns = attribute_columns(layout, values, n)
    if columns is None:
        _core.run_nodes(code, data, outputs, images, g, out)
    else:
        _core.run_nodes(code, data, outputs, images, g, out, columns)
    return out
