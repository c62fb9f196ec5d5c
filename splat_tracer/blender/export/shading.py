"""Blender materials, lamps, world and render settings -> the plain contract in shading.py.

Pure reading: nothing here renders or changes the file. Whatever the engine cannot render
is approximated, and said once in a `shading.Report` line that names the datablock.

Where a node tree has outputs for several engines, the one Cycles uses is read (an output
whose target is 'CYCLES' beats 'ALL', the active one beats the others): Splat Tracer is a
ray tracer, and a scene lit for Cycles should render alike.

Materials are read from their node tree, following the Material Output's Surface input:
- Principled BSDF: Base Color, Metallic, Roughness, IOR, Specular IOR Level, Transmission
  Weight, Alpha, Emission Color x Emission Strength (the names since Blender 4.0).
- Diffuse BSDF (no specular), Glossy BSDF (metallic), Metallic BSDF, Glass BSDF
  (transmission with its IOR), Refraction BSDF (transmission, no reflection), Emission
  (emission only, black surface), Transparent BSDF (alpha 0).
- Mix and Add Shader (approximated, said once per material): each branch weighs w (Mix:
  1 - factor and factor; Add: 1 and 1). Emission is the weighted sum and alpha the summed
  opaque share k = w x alpha (at most 1), which is exact. Base colour and specular level
  are the k-weighted sum over the branches divided by that alpha: an Emission or unlinked
  branch (a black surface) darkens them, a Transparent one does not count, and Add adds
  the reflectances. Metallic, roughness, IOR and transmission are the k-weighted mean over
  the branches that are BSDFs. The point-colour flags are on when a weighted branch has them.
  Where the BSDFs' metallic differ (a Diffuse and a Glossy) the lobes are kept apart as
  Cycles sums the closures (_split_lobes): the metallic lobe gets its own colour.
- A Base Color (or a BSDF's Color) fed by a Color Attribute or an Attribute node (any
  name; through reroutes) means the points' own colours; an Alpha fed by such a node's
  Alpha output means the points' own alpha.
Other links into the inputs of a material's shader are compiled into a node program
(export/nodes.py) the core runs at each shading point; under Mix and Add Shaders, with a
Mix's linked Fac, the blend above is made there per shading point too (export/shader_mix.py).
Any other link into a socket the engine reads falls back to that socket's default value.
"""
from __future__ import annotations

import dataclasses
import math
import struct
import zlib

import bpy
import numpy as np

from ...render import shading
from ...render.splats import MAX_COORDINATE
from . import nodes, shader_mix
from .sockets import fmt as _fmt, upstream as _upstream
from . import world as export_world

# The output target this renderer reads (see the module docstring).
_TARGET = "CYCLES"
# From Blender 5.0, Material.use_nodes and World.use_nodes are deprecated and always on
# (setting them has no effect): node trees are read whatever the flag says.
_ALWAYS_NODES = bpy.app.version >= (5, 0, 0)
# What Cycles renders for a surface without a shader (no output, nothing linked): black.
_BLACK = dict(base_colour=(0.0, 0.0, 0.0), specular_level=0.0)
# Marks the shader fields of a branch that reflects light (a BSDF), for Mix and Add.
_IS_BSDF = "_bsdf"
# Smallest IOR passed on: the contract needs a positive one (IOR < 1 is valid: a bubble).
_MIN_IOR = 1e-3
# Principled BSDF lobes the engine does not render, by the socket that turns each on.
_PRINCIPLED_EXTRAS = {"Subsurface Weight": "subsurface", "Coat Weight": "coat", "Sheen Weight": "sheen",
                      "Anisotropic": "anisotropy", "Thin Film Thickness": "thin film"}
# Node types whose outputs are per-point data (Color Attribute, Attribute).
_POINT_DATA_NODES = ("VERTEX_COLOR", "ATTRIBUTE")


# --------------------------------------------------------------------------------------
# Node-tree helpers.

def _node_tree(idblock):
    """The node tree Blender renders `idblock` (a material or world) with, or None when it
    uses its viewport settings instead (no tree; `use_nodes` off before Blender 5.0)."""
    tree = idblock.node_tree
    if tree is None or (not _ALWAYS_NODES and not idblock.use_nodes):
        return None
    return tree


def _output_node(tree, node_type: str):
    """The output node of `node_type` that Cycles renders (Blender's ntreeShaderOutputNode):
    a 'CYCLES' target beats 'ALL', then the active output beats the others."""
    best, best_rank = None, None
    for node in tree.nodes:
        target = getattr(node, "target", "ALL")
        if node.type != node_type or target not in ("ALL", _TARGET):
            continue
        rank = (target == _TARGET, bool(node.is_active_output))
        if best is None or rank > best_rank:
            best, best_rank = node, rank
    return best


def _is_point_data(source, output: str) -> bool:
    """Whether `source` (from _upstream) is the `output` socket of a per-point attribute."""
    if source is None:
        return False
    node, socket = source
    if node.type not in _POINT_DATA_NODES or socket.name != output:
        return False
    # An Attribute naming another attribute (a scan's intensity) is that attribute, read by a
    # node program, not the points' colour.
    # A Color Attribute naming another layer (a mesh's colour attribute) is read by a program.
    if node.type == "VERTEX_COLOR":
        return node.layer_name in ("", nodes.CLOUD_COLOUR)
    return node.attribute_type == "GEOMETRY" and node.attribute_name in nodes.COLOUR_ATTRIBUTE_NAMES


class _Sockets:
    """Reads socket values of one datablock's nodes. A linked socket it cannot follow falls
    back to its default value, said once in the report."""

    def __init__(self, kind: str, name: str, report: shading.Report):
        self.prefix = f"{kind} '{name}'"
        self.report = report
        self.compiled = []  # sockets a node program drives: their defaults stand in silently

    def say(self, text: str) -> None:
        self.report.once(f"{self.prefix}{text}")

    def _default(self, node, name):
        """The default value of an input (by name, or the socket itself)."""
        socket = node.inputs[name] if isinstance(name, str) else name
        source = _upstream(socket)
        if source is not None and socket not in self.compiled:
            self.say(f": {socket.name} is driven by a '{source[0].bl_label}' node; "
                     f"using its default value {_fmt(socket.default_value)}")
        return socket.default_value

    def value(self, node, name) -> float:
        return float(self._default(node, name))

    def colour(self, node, name: str) -> tuple:
        return tuple(float(c) for c in self._default(node, name)[:3])

    def point_colour(self, node, name: str) -> tuple:
        """(colour, True) when the points' colours feed the socket, else (colour, False)."""
        socket = node.inputs[name]
        if _is_point_data(_upstream(socket), "Color"):
            return tuple(float(c) for c in socket.default_value[:3]), True
        return self.colour(node, name), False

    def point_alpha(self, node, name: str) -> tuple:
        """(1, True) when the points' alpha feeds the socket (it replaces the value), else
        (value, False)."""
        if _is_point_data(_upstream(node.inputs[name]), "Alpha"):
            return 1.0, True
        return self.value(node, name), False

    @staticmethod
    def linked_inputs(node, names) -> list:
        """Which of the named inputs of `node` have something connected."""
        return [name for name in names if name in node.inputs and _upstream(node.inputs[name]) is not None]


# --------------------------------------------------------------------------------------
# Materials. Each shader reader returns a dict of shading.Material fields (unset: the
# contract's defaults), so that Mix and Add can blend them before the Material is made.
# Emission Sampling and the name are the material's, not a shader's: material_of sets them.

_DEFAULTS = {f.name: f.default for f in shading.Material.__dataclass_fields__.values()
             if f.name not in ("emission_sampling", "program", "name")}


def _principled(node, sockets: _Sockets) -> dict:
    base, point_colour = sockets.point_colour(node, "Base Color")
    alpha, point_alpha = sockets.point_alpha(node, "Alpha")
    emission = sockets.colour(node, "Emission Color")
    strength = sockets.value(node, "Emission Strength")
    extras = [label for name, label in _PRINCIPLED_EXTRAS.items()
              if name in node.inputs and (node.inputs[name].default_value > 0 or sockets.linked_inputs(node, [name]))]
    if extras:
        sockets.say(f": the Principled BSDF's {', '.join(extras)} {'is' if len(extras) == 1 else 'are'} ignored")
    return dict(base_colour=base, metallic=sockets.value(node, "Metallic"),
                roughness=sockets.value(node, "Roughness"), ior=sockets.value(node, "IOR"),
                transmission=sockets.value(node, "Transmission Weight"), alpha=alpha,
                emission=tuple(c * strength for c in emission),
                specular_level=sockets.value(node, "Specular IOR Level"),
                use_point_colour=point_colour, use_point_alpha=point_alpha)


def _diffuse(node, sockets: _Sockets) -> dict:
    base, point_colour = sockets.point_colour(node, "Color")
    return dict(base_colour=base, specular_level=0.0, use_point_colour=point_colour)


def _glossy(node, sockets: _Sockets, colour: str = "Color") -> dict:
    base, point_colour = sockets.point_colour(node, colour)
    return dict(base_colour=base, metallic=1.0, roughness=sockets.value(node, "Roughness"),
                use_point_colour=point_colour)


def _glass(node, sockets: _Sockets) -> dict:
    base, point_colour = sockets.point_colour(node, "Color")
    return dict(base_colour=base, transmission=1.0, ior=sockets.value(node, "IOR"),
                roughness=sockets.value(node, "Roughness"), use_point_colour=point_colour)


def _refraction(node, sockets: _Sockets) -> dict:
    return {**_glass(node, sockets), "specular_level": 0.0}


def _emission(node, sockets: _Sockets) -> dict:
    strength = sockets.value(node, "Strength")
    return dict(_BLACK, emission=tuple(c * strength for c in sockets.colour(node, "Color")))


def _transparent(node, sockets: _Sockets) -> dict:
    if sockets.colour(node, "Color") != (1.0, 1.0, 1.0):
        sockets.say(": a tinted Transparent BSDF is rendered fully transparent (untinted)")
    return dict(alpha=0.0)


_SHADERS = {
    "BSDF_PRINCIPLED": _principled,
    "BSDF_DIFFUSE": _diffuse,
    "BSDF_GLOSSY": _glossy,
    "BSDF_METALLIC": lambda node, sockets: _glossy(node, sockets, "Base Color"),
    "BSDF_GLASS": _glass,
    "BSDF_REFRACTION": _refraction,
    "EMISSION": _emission,
    "BSDF_TRANSPARENT": _transparent,
}
_LINEAR = ("base_colour", "specular_level")        # k-weighted sums (see the module docstring)
_AVERAGED = ("metallic", "roughness", "ior", "transmission")  # k-weighted means over the BSDFs


def _combine(branches) -> dict:
    """Mix or Add of shader fields: `branches` is [(weight, fields)] (module docstring)."""
    branches = [(w, {**_DEFAULTS, _IS_BSDF: True, **f}) for w, f in branches if w > 0]
    if not branches:
        return dict(_BLACK, **{_IS_BSDF: False})
    opaque = [w * f["alpha"] for w, f in branches]
    alpha = min(sum(opaque), 1.0)
    out = {"alpha": alpha, _IS_BSDF: any(f[_IS_BSDF] for _, f in branches),
           "emission": tuple(sum(w * f["emission"][i] for w, f in branches) for i in range(3))}
    for key in _LINEAR:
        total = sum(k * np.asarray(f[key], np.float64) for k, (_, f) in zip(opaque, branches))
        value = total / alpha if alpha > 0 else np.asarray(_DEFAULTS[key], np.float64)
        out[key] = tuple(float(c) for c in value) if value.ndim else float(value)
    reflecting = [(k, f) for k, (_, f) in zip(opaque, branches) if f[_IS_BSDF] and k > 0]
    weight = sum(k for k, _ in reflecting)
    for key in _AVERAGED:
        out[key] = sum(k * f[key] for k, f in reflecting) / weight if weight > 0 else _DEFAULTS[key]
    for key in ("use_point_colour", "use_point_alpha"):
        out[key] = any(f[key] for _, f in branches)
    out.update(_split_lobes(opaque, branches, alpha, out))
    return out


def specular_strength(metallic, transmission, ior, specular_level, ops=None):
    """How much a shader's specular lobes reflect at normal incidence: the metallic share (1),
    the glass share (its Fresnel, taken as 1: glass is all specular) and the opaque dielectric's
    f0 (the IOR's, times 2 x Specular IOR Level, as the core's Lobes). `ops`: (mul, add, sub,
    div) for values that may be program registers (shader_mix.py), else plain arithmetic."""
    mul, add, sub, div = ops or (lambda a, b: a * b, lambda a, b: a + b, lambda a, b: a - b, lambda a, b: a / b)
    r = div(sub(ior, 1.0), add(ior, 1.0))
    f0 = mul(mul(r, r), mul(specular_level, 2.0))
    dielectric = add(transmission, mul(sub(1.0, transmission), f0))
    return add(metallic, mul(sub(1.0, metallic), dielectric))


def _split_lobes(opaque, branches, alpha: float, blended: dict) -> dict:
    """Where the reflecting branches' metallic differ (a diffuse and a glossy), the fields that
    keep their lobes apart, as Cycles sums the closures: the metallic share's own colour
    (metal_colour) and the dielectric share's (base_colour, and its specular level, IOR and
    transmission), each weighed by its branches' share, so that alpha x metallic x
    metal_colour and alpha x (1 - metallic) x base_colour are the branches' sums. The one
    roughness is weighed by each branch's specular strength: a diffuse (no specular) leaves
    the glossy's own. {} (the one blended lobe, every other material) otherwise, or where a
    metallic branch reads the points' colours (they replace the base colour only). A branch
    that is such a split already (a nested Mix) is split again, keeping its metal colour."""
    reflecting = [(k, f) for k, (_, f) in zip(opaque, branches) if f[_IS_BSDF] and k > 0]
    if len({f["metallic"] for _, f in reflecting}) < 2 and all(f.get("metal_colour") is None for _, f in branches):
        return {}
    if any(f["use_point_colour"] and f["metallic"] > 0 for _, f in reflecting):
        return {}
    metal = blended["metallic"]
    out = {}
    own = lambda f: f["metal_colour"] if f.get("metal_colour") is not None else f["base_colour"]  # noqa: E731
    if alpha * metal > 0:
        total = sum(k * f["metallic"] * np.asarray(own(f), np.float64) for k, f in reflecting)
        out["metal_colour"] = tuple(float(c) for c in total / (alpha * metal))
    # Emission and unlinked branches (black, not BSDFs) count in the dielectric share as before.
    dielectric = [(k * (1.0 - (f["metallic"] if f[_IS_BSDF] else 0.0)), f) for k, (_, f) in zip(opaque, branches)]
    if alpha * (1.0 - metal) > 0:
        for key in ("base_colour", "specular_level"):
            total = sum(d * np.asarray(f[key], np.float64) for d, f in dielectric)
            value = total / (alpha * (1.0 - metal))
            out[key] = tuple(float(c) for c in value) if value.ndim else float(value)
    weight = sum(d for d, f in dielectric if f[_IS_BSDF])
    if weight > 0:
        for key in ("ior", "transmission"):
            out[key] = sum(d * f[key] for d, f in dielectric if f[_IS_BSDF]) / weight
    strengths = [(k * specular_strength(f["metallic"], f["transmission"], f["ior"], f["specular_level"]), f)
                 for k, f in reflecting]
    weight = sum(s for s, _ in strengths)
    if weight > 0:
        out["roughness"] = sum(s * f["roughness"] for s, f in strengths) / weight
    return out


def _shader(socket, sockets: _Sockets) -> dict:
    """The shader fields (Material fields, and _IS_BSDF) of what feeds a shader socket."""
    source = _upstream(socket)
    if source is None:
        return dict(_BLACK, **{_IS_BSDF: False})
    node = source[0]
    if node.type in ("MIX_SHADER", "ADD_SHADER"):
        sockets.say(": Mix and Add Shaders are approximated by blending their shaders' parameters")
        first, second = (_shader(s, sockets) for s in node.inputs if s.type == "SHADER")
        if node.type == "ADD_SHADER":
            return _combine([(1.0, first), (1.0, second)])
        factor = min(max(sockets.value(node, node.inputs[0]), 0.0), 1.0)
        return _combine([(1.0 - factor, first), (factor, second)])
    return _shader_node(node, sockets)


def _shader_node(node, sockets: _Sockets) -> dict:
    """_shader's fields of one shader node, not a Mix or Add (None: nothing connected)."""
    if node is None:
        return dict(_BLACK, **{_IS_BSDF: False})
    reader = _SHADERS.get(node.type)
    if reader is None:
        sockets.say(f": the '{node.bl_label}' shader is not supported; using a default grey material")
        return {}
    return {_IS_BSDF: node.type not in ("EMISSION", "BSDF_TRANSPARENT"), **reader(node, sockets)}


def _clamped(fields: dict, sockets: _Sockets) -> shading.Material:
    """The Material for shader fields, held to the contract's ranges (as Cycles clamps). A
    value that is not finite (a NaN a driver or a script put in a socket) is the field's
    default, and an emission beyond the renderer's limit is clamped to it, each said: one
    material never fails the frame."""
    f = {**_DEFAULTS, **fields}
    for key, value in f.items():
        if value is None:  # metal_colour: the base colour's
            continue
        if not isinstance(value, bool) and not all(math.isfinite(float(c)) for c in np.ravel(value)):
            sockets.say(f": {key.replace('_', ' ')} {_fmt(value)} is not finite; using {_fmt(_DEFAULTS[key])}")
            f[key] = _DEFAULTS[key]
    if max(f["emission"]) > MAX_COORDINATE:
        sockets.say(f": an emission of {_fmt(f['emission'])} is beyond the renderer's limit; clamped to "
                    f"{MAX_COORDINATE:.0e}")
        f["emission"] = tuple(min(float(c), MAX_COORDINATE) for c in f["emission"])
    unit = lambda v: min(max(float(v), 0.0), 1.0)  # noqa: E731
    return shading.Material(
        base_colour=tuple(max(float(c), 0.0) for c in f["base_colour"]), metallic=unit(f["metallic"]),
        roughness=unit(f["roughness"]), ior=max(float(f["ior"]), _MIN_IOR), transmission=unit(f["transmission"]),
        alpha=unit(f["alpha"]), emission=tuple(max(float(c), 0.0) for c in f["emission"]),
        specular_level=max(float(f["specular_level"]), 0.0), use_point_colour=bool(f["use_point_colour"]),
        use_point_alpha=bool(f["use_point_alpha"]),
        metal_colour=None if f["metal_colour"] is None else tuple(max(float(c), 0.0) for c in f["metal_colour"]))


def _viewport_material(bl_material, sockets: _Sockets) -> shading.Material:
    """A material without nodes: its viewport display settings, as Cycles renders it."""
    sockets.say(" does not use nodes; using its viewport display colour, metallic and roughness")
    return _clamped(dict(base_colour=tuple(bl_material.diffuse_color[:3]), metallic=bl_material.metallic,
                         roughness=bl_material.roughness), sockets)


def material_of(bl_material, report: shading.Report, aovs: dict | None = None,
                object_space=None) -> shading.Material:
    """The engine's Material for a Blender material (None, an empty slot: default grey).
    aovs: the view layer's shader AOVs to write, name -> "COLOR" or "VALUE" (view_layer_aovs):
    the material's AOV Output nodes naming one are compiled, the others cost nothing.
    object_space(obj): the local frame into an object's space, for a Texture Coordinate
    node naming another object (nodes.Compiler; None: such a node is said and left out).

    Reads the node tree Cycles would render (see the module docstring for what maps to
    what). Without an output for Cycles, or with nothing in its Surface, the material is
    black, as in Cycles; Volume and Displacement are ignored (a material with only a Volume
    is fully transparent: its volume is not rendered). Every approximation is said
    once in `report`. Emission Sampling (Material > Settings) is read where Cycles keeps it."""
    if bl_material is None:
        return shading.Material()
    material = _surface_material(bl_material, report, aovs or {}, object_space)
    sampling = _emission_sampling(bl_material)
    if sampling == "AUTO" and material.program is not None and material.program.drives("emission"):
        # The core samples it by its program's estimate (mesh_lights.h): Auto is Cycles' choice.
        sampling = _auto_sampling_of_nodes(bl_material)
    return dataclasses.replace(material, emission_sampling=sampling, pass_index=bl_material.pass_index,
                               name=bl_material.name)


def _emission_sampling(bl_material) -> str:
    """Cycles' Emission Sampling of the material (AUTO where there is none to read)."""
    value = getattr(getattr(bl_material, "cycles", None), "emission_sampling", "AUTO")
    return value if value in shading.EMISSION_SAMPLING else "AUTO"


def _auto_sampling_of_nodes(bl_material) -> str:
    """Cycles' Auto for an emission its nodes drive: Shader::estimate_emission's estimate of
    what feeds the Surface (_emission_estimate), both sides sampled when it exceeds
    AUTO_EMISSION_THRESHOLD in a channel, none otherwise."""
    tree = _node_tree(bl_material)
    output = _output_node(tree, "OUTPUT_MATERIAL") if tree is not None else None
    estimate = _emission_estimate(output.inputs["Surface"]) if output is not None else (0.0,) * 3
    return "FRONT_BACK" if max(estimate) > shading.AUTO_EMISSION_THRESHOLD else "NONE"


def _emission_estimate(socket) -> tuple:
    """Cycles' estimate of the emission of what feeds a shader socket, per channel: an
    Emission's or Principled BSDF's colour x strength, a linked input counting as 1; an Add
    Shader sums its two; a Mix Shader weighs them by a constant Fac and sums them when the
    Fac is linked (a texture may pick either)."""
    source = _upstream(socket)
    if source is None:
        return (0.0,) * 3
    node = source[0]
    if node.type in ("MIX_SHADER", "ADD_SHADER"):
        first, second = (_emission_estimate(s) for s in node.inputs if s.type == "SHADER")
        weights = (1.0, 1.0)
        if node.type == "MIX_SHADER" and _upstream(node.inputs[0]) is None:
            fac = min(max(float(node.inputs[0].default_value), 0.0), 1.0)
            weights = (1.0 - fac, fac)
        return tuple(weights[0] * a + weights[1] * b for a, b in zip(first, second))
    names = nodes.SHADER_INPUTS.get(node.type, {}).get("emission")
    if names is None:
        return (0.0,) * 3
    colour, strength = (node.inputs[n] for n in names)
    c = (1.0,) * 3 if _upstream(colour) is not None else tuple(abs(float(v)) for v in colour.default_value[:3])
    k = 1.0 if _upstream(strength) is not None else abs(float(strength.default_value))
    return tuple(v * k for v in c)


def _surface_material(bl_material, report: shading.Report, aovs: dict, object_space=None) -> shading.Material:
    """material_of's reading of the node tree (or the viewport settings)."""
    sockets = _Sockets("material", bl_material.name, report)
    tree = _node_tree(bl_material)
    if tree is None:
        return _viewport_material(bl_material, sockets)
    output = _output_node(tree, "OUTPUT_MATERIAL")
    if output is None:
        sockets.say(" has no Material Output; rendered black, as Cycles does")
        return _clamped(_BLACK, sockets)
    source = _upstream(output.inputs["Surface"])
    volume_only = source is None and "Volume" in output.inputs and _upstream(output.inputs["Volume"]) is not None
    ignored = sockets.linked_inputs(output, [s.name for s in output.inputs
                                            if s.name != "Surface" and not (volume_only and s.name == "Volume")])
    if ignored:
        sockets.say(f": {', '.join(ignored)} {'is' if len(ignored) == 1 else 'are'} ignored")
    if volume_only:
        # Cycles renders the volume inside a surface that is not there. Volumes are not
        # rendered here: the surface stays absent (fully transparent), never a black box.
        sockets.say(": only a Volume shader is connected; the volume is not rendered, the object is transparent")
        return _clamped(dict(_BLACK, alpha=0.0), sockets)
    if source is None:
        sockets.say(": nothing is connected to the Material Output's Surface; rendered black, as Cycles does")
    program = _program(source[0] if source is not None else None, sockets, _aov_outputs(tree, aovs, sockets),
                       object_space, float(getattr(bl_material, "pass_index", 0)))
    material = _clamped(_shader(output.inputs["Surface"], sockets), sockets)
    if not _bump_correction(bl_material):
        material = dataclasses.replace(material, bump_correction=False)
    return dataclasses.replace(material, program=program) if program is not None else material


def view_layer_aovs(view_layer) -> dict:
    """The view layer's shader AOVs as material_of takes them: name -> "COLOR" or "VALUE"
    (those Blender marks as conflicting left out, as Cycles leaves them)."""
    return {aov.name: aov.type for aov in getattr(view_layer, "aovs", ()) if aov.is_valid}


def _aov_outputs(tree, aovs: dict, sockets: _Sockets) -> list:
    """(name, width, socket) for the tree's AOV Output nodes that write an AOV of the view
    layer: the Color input for a colour AOV, the Value input for a value AOV, as Cycles
    compiles them. Inside node groups they are not found (said)."""
    if not aovs:
        return []
    found = []
    for node in tree.nodes:
        if node.type == "OUTPUT_AOV" and not node.mute and node.aov_name in aovs:
            colour = aovs[node.aov_name] == "COLOR"
            found.append((node.aov_name, 3 if colour else 1, node.inputs["Color" if colour else "Value"]))
        elif node.type == "GROUP" and node.node_tree is not None and any(
                n.type == "OUTPUT_AOV" for n in node.node_tree.nodes):
            sockets.say(f": the AOV Output nodes inside the node group '{node.node_tree.name}' are not evaluated")
    return found


def _bump_correction(bl_material) -> bool:
    """Cycles' Bump Map Correction (Material > Settings; on where there is none to read): the
    core applies the bump shadowing term where nodes drive the normal only with it on."""
    return bool(getattr(getattr(bl_material, "cycles", None), "use_bump_map_correction", True))


def _program(shader, sockets: _Sockets, aovs=(), object_space=None, material_index: float = 0.0):
    """The node program for the linked inputs of the material's shader (None: nothing feeds
    the Material Output) and its AOV Output nodes (_aov_outputs), or None (nothing needs
    one). Colour Attribute and Attribute nodes linked straight into the colour or alpha keep
    the constant path (the points' own colours; no program to run)."""
    inputs = shader.inputs if shader is not None else ()
    direct = [s for s in inputs if _reads_points(s)]
    try:
        if shader is not None and shader.type in shader_mix.MIX_SHADERS:
            if not shader_mix.needs_program(shader, lambda s: s.node.type != "EMISSION" and _reads_points(s)):
                return _program(None, sockets, aovs, object_space, material_index)  # a constant blend (AOVs only)
            # The shader readers' own lines are said when _shader reads the tree next; the
            # readers here only give the constant fields the blend starts from.
            quiet = _Sockets("material", "", shading.Report())
            program, driven = shader_mix.compile_mix(shader, sockets.say, lambda node: _shader_node(node, quiet),
                                                     _DEFAULTS, _IS_BSDF, aovs=aovs, object_space=object_space,
                                                     material_index=material_index)
        else:
            program, driven = nodes.compile_shader(shader, sockets.say, skip=direct, aovs=aovs,
                                                   object_space=object_space, material_index=material_index)
    except nodes.ProgramTooLarge as e:
        sockets.say(f": the node tree is too large to evaluate ({e}); linked inputs use their unlinked values")
        return None
    sockets.compiled = driven
    return program


# --------------------------------------------------------------------------------------
# Lamps.

def _reads_points(socket) -> bool:
    """Whether the constant path reads a shader input as the points' own colour or alpha (a
    Color Attribute or Attribute node linked straight into a colour or an alpha)."""
    if socket.name in ("Base Color", "Color"):
        return _is_point_data(_upstream(socket), "Color")
    return socket.name == "Alpha" and _is_point_data(_upstream(socket), "Alpha")


def _unit(v) -> tuple:
    v = np.asarray(v, np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):  # an axis scaled to 0: NaN, see _within_limits
        return tuple(float(c) for c in v / np.linalg.norm(v))


def _has_custom_nodes(light) -> bool:
    """Whether a lamp's node tree does more than the default: one Emission node (white,
    strength 1) into the Light Output."""
    if not light.use_nodes or light.node_tree is None:
        return False
    tree = light.node_tree
    if sorted(n.type for n in tree.nodes) != ["EMISSION", "OUTPUT_LIGHT"] or len(tree.links) != 1:
        return True
    emission = next(n for n in tree.nodes if n.type == "EMISSION")
    return (tuple(emission.inputs["Color"].default_value[:3]) != (1.0, 1.0, 1.0)
            or emission.inputs["Strength"].default_value != 1.0)


def _lamp_emission(light, position, direction, say):
    """The colour x strength of a lamp's node tree, as Cycles multiplies it into the lamp's
    colour and power: the Emission shader feeding the Light Output, its Color and Strength
    evaluated once by the node evaluator (constant nodes, Blackbody, RGB, Value, Math, ...
    fold to one colour). A texture or geometry input (varying over the lamp) is read at the
    lamp's centre, said once. None where the tree is the default one or is not read (said)."""
    if not _has_custom_nodes(light):
        return None
    output = _output_node(light.node_tree, "OUTPUT_LIGHT")
    source = _upstream(output.inputs["Surface"]) if output is not None else None
    if source is None or source[0].type != "EMISSION":
        say("its node tree is ignored (only an Emission shader into the Light Output is read)")
        return None
    emission = source[0]
    colour = np.array(emission.inputs["Color"].default_value[:3], np.float64)
    colour = colour * float(emission.inputs["Strength"].default_value)
    try:
        program, _ = nodes.compile_shader(emission, lambda text: say("node tree" + text))
    except nodes.ProgramTooLarge as e:
        say(f"its node tree is too large to evaluate ({e}); the Emission's unlinked values are used")
        program = None
    if program is None:
        return colour
    from ...render import nodes as programs

    program = _as_lamp_light(program, say)
    reads = {programs.GLOBALS[row[2]] for row in np.array(program.code).reshape(-1, programs.WIDTH)
             if row[0] == programs.OPS.index("GLOBAL")}
    if reads:
        say(f"its node tree varies over the lamp ({', '.join(sorted(g.lower() for g in reads))}); "
            f"its colour at the lamp's centre is used")
    regs = programs.run(program, P=position, N=direction, Ng=direction, I=direction, object_normal=(0, 0, 1),
                        generated=(0.5, 0.5, 0.5), surface_normal=direction)
    out = program.outputs[list(programs.OUTPUTS).index("emission")]
    value = np.asarray(regs[0, out:out + 3], np.float64)
    return np.where(np.isfinite(value), np.maximum(value, 0.0), 0.0)


def _as_lamp_light(program, say):
    """A lamp's program as Cycles evaluates it for the light the lamp sends: Light Path with
    PATH_RAY_EMISSION alone (every output 0: its LIGHT_PATH rows become no-ops, leaving their
    registers at 0); Object Info and object attributes have no instance here (0, said)."""
    from ...render import nodes as programs

    code = np.array(program.code, np.int32).reshape(-1, programs.WIDTH)
    if (code[:, 0] == programs.OPS.index("OBJECT_VALUE")).any():
        say("its node tree's Object Info and object attributes read 0 (a lamp is no instance here)")
    # Nodes that read a surface: the tree runs once at the lamp's centre, with no geometry.
    surface = [label for op, label in (("AMBIENT_OCCLUSION", "Ambient Occlusion reads 1"),
                                       ("WIREFRAME", "Wireframe reads 0"), ("BEVEL", "Bevel keeps the normal"),
                                       ("ATTRIBUTE", "geometry attributes read 0"))
               if (code[:, 0] == programs.OPS.index(op)).any()]
    if surface:
        say(f"its node tree is evaluated with no surface: {', '.join(surface)}")
    rows = code[:, 0] == programs.OPS.index("LIGHT_PATH")
    if not rows.any():
        return program
    code[rows, 0] = programs.OPS.index("COPY")
    code[rows, 2], code[rows, 3] = code[rows, 1], 1  # a register onto itself
    code[rows, 4:] = 0
    return dataclasses.replace(program, code=tuple(map(tuple, code.tolist())))


# Cycles' default (and largest useful) Max Bounces of a lamp or the world: below it, the limit acts.
_LIGHT_MAX_BOUNCES = 1024


def _report_lamp_extras(obj, light, say) -> None:
    """One line each for what the engine ignores on a lamp."""
    linking = getattr(obj, "light_linking", None)
    if linking is not None and (linking.receiver_collection is not None or linking.blocker_collection is not None):
        say("light linking is ignored")
    if light.type != "SUN" and not getattr(light, "normalize", True):
        say("'Normalize' off is ignored (rendered as if on)")
    factors = [label for prop, label in (("diffuse_factor", "Diffuse"), ("specular_factor", "Glossy"),
                                         ("transmission_factor", "Transmission"))
               if getattr(light, prop, 1.0) != 1.0]
    if factors:
        say(f"its {'/'.join(factors)} influence is ignored (rendered as 1)")
    bounces = getattr(getattr(light, "cycles", None), "max_bounces", _LIGHT_MAX_BOUNCES)
    if bounces < _LIGHT_MAX_BOUNCES:
        say(f"its Max Bounces ({bounces}) is ignored: the scene's bounce limits apply")


def _area_fields(light, matrix: np.ndarray, say) -> dict:
    """Shape and sizes of an area lamp, scaled by the lamp object's X and Y axes. A square
    or disk scaled unevenly becomes a rectangle or ellipse."""
    scale_x, scale_y = (float(np.linalg.norm(matrix[:3, i])) for i in (0, 1))
    square = light.shape in ("SQUARE", "DISK")
    size_x = light.size * scale_x
    size_y = (light.size if square else light.size_y) * scale_y
    shape = light.shape
    if square and not math.isclose(size_x, size_y, rel_tol=1e-6):
        shape = "RECTANGLE" if light.shape == "SQUARE" else "ELLIPSE"
    if light.spread < math.pi * (1 - 1e-6):
        say(f"a spread of {math.degrees(light.spread):.3g} degrees is ignored (rendered as 180)")
    return dict(shape=shape, size=size_x, size_y=size_y)


def light_of(obj_eval, matrix_world, report: shading.Report) -> shading.Light | None:
    """The engine's Light for a lamp object (None for any other object).

    `matrix_world`: the lamp's 4x4 world matrix in the scene's local frame (float64).
    Power: energy x 2^exposure (W; W/m^2 for a sun), colour x the blackbody colour when
    'Temperature' is on x its node tree's emission (_lamp_emission), as in Cycles. Position: the matrix translation; direction: its -Z
    column; u_axis: its X column; area sizes scale with the X and Y columns' lengths.
    Portals emit nothing and give None."""
    if obj_eval.type != "LIGHT":
        return None
    light = obj_eval.data
    say = lambda text: report.once(f"light '{obj_eval.name}': {text}")  # noqa: E731
    if light.type == "AREA" and getattr(getattr(light, "cycles", None), "is_portal", False):
        say("portals are ignored")
        return None
    _report_lamp_extras(obj_eval, light, say)
    m = np.asarray(matrix_world, np.float64)
    colour = np.array(light.color[:3], np.float64)
    if getattr(light, "use_temperature", False):
        colour = colour * np.array(light.temperature_color[:3], np.float64)
    emission = _lamp_emission(light, m[:3, 3], _unit(-m[:3, 2]), say)
    if emission is not None:
        colour = colour * emission
    fields = dict(type=light.type, colour=tuple(float(c) for c in colour),
                  power=max(float(light.energy) * 2.0 ** getattr(light, "exposure", 0.0), 0.0),
                  position=tuple(float(c) for c in m[:3, 3]), direction=_unit(-m[:3, 2]), u_axis=_unit(m[:3, 0]),
                  cast_shadow=bool(light.use_shadow),
                  # Only point and spot lamps have Soft Falloff; Cycles' area lamps have none.
                  soft_falloff=bool(getattr(light, "use_soft_falloff", False)))
    if light.type in ("POINT", "SPOT"):
        fields["radius"] = float(light.shadow_soft_size)
    if light.type == "SPOT":
        fields.update(spot_size=float(light.spot_size), spot_blend=float(light.spot_blend))
    elif light.type == "SUN":
        fields["angle"] = float(light.angle)
    elif light.type == "AREA":
        fields.update(_area_fields(light, m, say))
    fields.update(visible_camera=bool(getattr(obj_eval, "visible_camera", True)),
                  visible_glossy=bool(getattr(obj_eval, "visible_glossy", True)),
                  visible_transmission=bool(getattr(obj_eval, "visible_transmission", True)),
                  light_group=getattr(obj_eval, "lightgroup", ""))
    if not _within_limits(light.type, fields, say):
        return None
    return shading.Light(**fields)


def _within_limits(kind: str, fields: dict, say) -> bool:
    """Brings a lamp's fields within what the core can hold, in place, saying what changed:
    a power or size beyond the coordinate limit is clamped to it (it lights the scene as
    brightly as anything can); a lamp placed beyond it, or whose axes an object scale of 0
    removed, is left out (False). The frame renders either way."""
    limit = MAX_COORDINATE
    if not all(abs(c) <= limit for c in fields["position"]):
        if kind != "SUN":
            say(f"its position is beyond the renderer's limit ({limit:.0e}); not rendered")
            return False
        fields["position"] = (0.0, 0.0, 0.0)  # a sun shines the same from anywhere
    for axis in ("direction", "u_axis"):
        if not all(math.isfinite(c) for c in fields[axis]):
            if kind == "POINT" or (axis == "u_axis" and kind != "AREA"):
                fields.pop(axis)  # unused by this kind of lamp: the contract's default
                continue
            say("its transform is singular (scaled to 0 along an axis); not rendered")
            return False
    # The core holds colour x power: the brightest channel decides.
    peak = max(max(fields["colour"]), 1e-30)
    if fields["power"] * peak > limit:
        clamped = limit / peak * (1 - 1e-6)  # below the limit after rounding to float32
        say(f"a power of {fields['power']:.3g} is beyond the renderer's limit; clamped to {clamped:.3g}")
        fields["power"] = clamped
    for key in ("radius", "size", "size_y"):
        if fields.get(key, 0.0) > limit:
            say(f"a {key.replace('_', ' ')} of {fields[key]:.3g} is beyond the renderer's limit; "
                f"clamped to {limit:.0e}")
            fields[key] = limit
    return True


# --------------------------------------------------------------------------------------
# World.

def _background(node, sockets: _Sockets) -> tuple:
    """(colour, strength) of a Background (or Emission) node of the world."""
    return sockets.colour(node, "Color"), sockets.value(node, "Strength")


def world_visibility(world, report: shading.Report) -> frozenset:
    """The ray kinds that see the world: Cycles' World > Settings > Ray Visibility
    (world.cycles_visibility, there when the Cycles add-on is on; else all). Volume Scatter
    has no rays here (no volumes) and is said once when turned off."""
    vis = getattr(world, "cycles_visibility", None)
    if vis is None:
        return frozenset(shading.WORLD_RAYS)
    if not getattr(vis, "scatter", True):
        report.once(f"world '{world.name}': Ray Visibility > Volume Scatter is ignored (no volumes are rendered)")
    return frozenset(k for k in shading.WORLD_RAYS if getattr(vis, k))


def world_of(scene, report: shading.Report) -> shading.World:
    """The engine's World: the Background feeding the World Output Cycles renders (its
    colour and strength), or the world's viewport colour without nodes; black without a
    world. Transparency is Film > Transparent; which rays see it, the world's Ray
    Visibility."""
    transparent = bool(scene.render.film_transparent)
    world = scene.world
    if world is None:
        return shading.World(colour=(0.0, 0.0, 0.0), strength=1.0, transparent=transparent)
    sockets = _Sockets("world", world.name, report)
    bounces = getattr(getattr(world, "cycles", None), "max_bounces", _LIGHT_MAX_BOUNCES)
    if bounces < _LIGHT_MAX_BOUNCES:
        report.once(f"world '{world.name}': its Max Bounces ({bounces}) is ignored: the scene's bounce limits apply")
    if not getattr(getattr(world, "cycles", None), "use_shadows", True):  # Blender 5.2's World > Shadows
        report.once(f"world '{world.name}': Shadows off is not honoured: the world's light casts shadows")
    mist = world.mist_settings  # read by the Mist pass only
    film = dict(transparent=transparent, visibility=world_visibility(world, report), mist_start=float(mist.start),
                mist_depth=max(float(mist.depth), 0.0), mist_falloff=mist.falloff,
                # Read by the AO pass and the light groups' passes only.
                ao_distance=max(float(world.light_settings.distance), 0.0),
                light_group=getattr(world, "lightgroup", ""))
    viewport = shading.World(colour=tuple(world.color[:3]), strength=1.0, **film)
    tree = _node_tree(world)
    if tree is None:
        return viewport
    output = _output_node(tree, "OUTPUT_WORLD")
    source = _upstream(output.inputs["Surface"]) if output is not None else None
    if source is None:
        sockets.say(": nothing is connected to a World Output's Surface; rendered black, as Cycles does")
        return shading.World(colour=(0.0, 0.0, 0.0), strength=1.0, **film)
    if sockets.linked_inputs(output, ["Volume"]):
        sockets.say(": Volume is ignored")
    if source[0].type in ("MIX_SHADER", "ADD_SHADER") or export_world.varying_nodes(output):
        # A world that varies with the direction or the ray: baked into an image (world.py).
        # A plain Background keeps the uniform path below, as before.
        try:
            fields = export_world.bake(tree, output, sockets, _upstream)
        except Exception as error:  # noqa: BLE001 -- skip, don't refuse: the frame renders
            sockets.say(f": its node tree could not be baked ({type(error).__name__}: {error}); "
                        f"using the world's viewport colour")
            return viewport
        return shading.World(strength=1.0, **fields, **film)
    if source[0].type not in ("BACKGROUND", "EMISSION"):
        sockets.say(f": the '{source[0].bl_label}' shader is not supported; using the world's viewport colour")
        return viewport
    colour, strength = _background(source[0], sockets)
    return shading.World(colour=tuple(max(float(c), 0.0) for c in colour), strength=max(strength, 0.0), **film)


# --------------------------------------------------------------------------------------
# Render settings and object visibility.

_BOUNCES = {"max_bounces": "max_bounces", "diffuse_bounces": "diffuse_bounces",
            "glossy_bounces": "glossy_bounces", "transmission_bounces": "transmission_bounces",
            "transparent_bounces": "transparent_max_bounces"}  # RenderSettings field: Cycles property
_MAX_BOUNCES = 1024  # the contract's limit (Cycles' own)
_FILTER_WIDTH = (0.01, 10.0)  # pixels: the contract's range (Blender allows 0..500)


def _seed(cycles, frame: int) -> int:
    """Cycles' seed; with 'Animated Seed', mixed with the frame so the noise changes per
    frame (any mix does: the pattern is this engine's own, not Cycles')."""
    if not cycles.use_animated_seed:
        return int(cycles.seed)
    return zlib.crc32(struct.pack("<ii", int(cycles.seed), int(frame)))


def render_settings_of(scene, viewport: bool = False) -> shading.RenderSettings:
    """The engine's RenderSettings. Samples and noise control are Cycles' (the one place
    they are kept, so a scene set up for Cycles samples the same way): Samples or, for the
    viewport, Viewport Samples; adaptive sampling (Noise Threshold, Min Samples: the render's
    or the viewport's), Time Limit (renders only, as in Cycles), Clamp Direct/Indirect and
    Filter Glossy; so are the filter, bounces and seed. With the Cycles add-on off, the
    engine's own legacy Samples and none of the rest (the contract's defaults and
    Blackman-Harris). Shadow and AO samples are the engine's own; the filter width is
    Blender's."""
    settings = scene.splat_tracer
    width = min(max(float(scene.render.filter_size), _FILTER_WIDTH[0]), _FILTER_WIDTH[1])
    fields = dict(samples=int(settings.samples), shadow_samples=int(settings.shadow_samples), filter_width=width,
                  pixel_filter="BLACKMAN_HARRIS", sky_ao=settings.sky_light == "AO",
                  ao_samples=int(settings.ao_samples))
    cycles = getattr(scene, "cycles", None)
    if cycles is not None:
        fields["pixel_filter"] = cycles.pixel_filter_type
        fields.update({key: min(int(getattr(cycles, prop)), _MAX_BOUNCES) for key, prop in _BOUNCES.items()})
        fields["seed"] = _seed(cycles, scene.frame_current)
        fields.update(sampling_of(cycles, viewport))
    return shading.RenderSettings(**fields)


_MAX_SAMPLES = 1 << 16  # RenderSettings' limit; Cycles' Viewport Samples 0 (no limit) reads as this


def sampling_of(cycles, viewport: bool = False) -> dict:
    """RenderSettings fields from Cycles' Sampling and Light Paths panels (scene.cycles)."""
    prefix = "preview_" if viewport else ""
    samples = int(cycles.preview_samples if viewport else cycles.samples)
    return dict(
        samples=min(samples, _MAX_SAMPLES) if samples > 0 else _MAX_SAMPLES,
        adaptive=bool(getattr(cycles, f"use_{prefix}adaptive_sampling")),
        adaptive_threshold=max(float(getattr(cycles, f"{prefix}adaptive_threshold")), 0.0),
        adaptive_min_samples=min(max(int(getattr(cycles, f"{prefix}adaptive_min_samples")), 0), _MAX_SAMPLES),
        time_limit=0.0 if viewport else max(float(cycles.time_limit), 0.0),
        clamp_direct=max(float(cycles.sample_clamp_direct), 0.0),
        clamp_indirect=max(float(cycles.sample_clamp_indirect), 0.0),
        filter_glossy=max(float(cycles.blur_glossy), 0.0))


_RAYS = ("camera", "diffuse", "glossy", "transmission", "shadow")


def _in_layer(obj, view_layer, getter: str) -> bool:
    """A view-layer flag of the object's collections (holdout_get, indirect_only_get). They
    find an evaluated object only in the evaluated view layer (depsgraph.view_layer_eval),
    and an original one only in the original: both are asked, so either layer works."""
    candidates = [obj] + ([obj.original] if obj.original is not None and obj.original != obj else [])
    return any(getattr(o, getter)(view_layer=view_layer) for o in candidates)


def _holdout(obj, view_layer) -> bool:
    """The object's holdout (its own, or its collection's in the view layer)."""
    return bool(obj.is_holdout) or _in_layer(obj, view_layer, "holdout_get")


def object_visibility(obj_eval, view_layer, parent=None) -> dict:
    """Ray visibility of an object: {'camera', 'diffuse', 'glossy', 'transmission',
    'shadow': bool (Object Properties > Visibility > Ray Visibility), 'holdout': bool (the
    object's Holdout, or its collection's Holdout in `view_layer`), 'shadow_catcher': bool
    (Visibility > Mask > Shadow Catcher)}.

    `parent`: for an instance (depsgraph.object_instances, is_instance), the object that
    instances it: as in Cycles, a ray sees the instance only if it sees the parent too, and
    the parent's holdout holds it out and its Shadow Catcher makes it one. A collection set
    to Indirect Only in the view layer hides the objects it holds (the instancer's, for an
    instance) from camera rays unless they are held out -- Cycles' rule."""
    flags = {ray: bool(getattr(obj_eval, f"visible_{ray}")) for ray in _RAYS}
    flags["holdout"] = _holdout(obj_eval, view_layer)
    flags["shadow_catcher"] = bool(obj_eval.is_shadow_catcher)
    if parent is not None and parent != obj_eval:
        outer = object_visibility(parent, view_layer)
        flags = {key: (flags[key] or outer[key]) if key in _EITHER else (flags[key] and outer[key]) for key in flags}
    elif not flags["holdout"] and _in_layer(obj_eval, view_layer, "indirect_only_get"):
        flags["camera"] = False
    return flags


_EITHER = ("holdout", "shadow_catcher")  # an instance has these if it or its instancer has them
