"""What an instance's node programs read of its object: Object Info and the Attribute node's
object, instancer and view-layer types, as Cycles gives them (render/nodes.py OBJECT_INFO).

Cycles sets these once per object (blender/object.cpp) and its shaders read them per
instance: Location (the instance's world translation), Color and Alpha (Object > Viewport
Display > Color), Object Index (the pass index), Random (from the object's name, or for an
instanced copy Blender's own per-instance random id). Attribute names are custom properties
or RNA paths, looked up on the object and then its data-block (Attribute node docs).
"""
from __future__ import annotations

import numpy as np

from ...render import mesh_attributes


def _hash_string(text: str) -> int:
    """Cycles' hash_string: a multiplicative hash of the name's bytes (UTF-8), 32-bit, each
    byte unsigned (a non-ASCII name matches Cycles 5.0.1 so; read as signed it does not)."""
    h = 0
    for byte in text.encode("utf-8"):
        h = (h * 37 + byte) & 0xFFFFFFFF
    return h


def hash_uint2(kx: int, ky: int) -> int:
    """Cycles' hash_uint2: lookup3 of two 32-bit words."""
    return int(mesh_attributes.lookup3(kx, ky))


def random_of(inst, obj) -> float:
    """Object Info's Random for a depsgraph instance: Cycles' random_id over the 32-bit
    range (an instanced copy: Blender's per-instance random_id; an object itself: the hash of
    its name), in float32 as Cycles stores it."""
    if inst.is_instance:
        rid = int(inst.random_id) & 0xFFFFFFFF
    else:
        rid = hash_uint2(_hash_string(obj.name), 0)
    return float(np.float32(np.float32(rid) * np.float32(1.0 / 0xFFFFFFFF)))


def object_info(inst, obj, matrix_world, pass_index: int) -> tuple:
    """The 9 values of render/nodes.py OBJECT_INFO for an instance: world location, colour,
    alpha, pass index, random."""
    colour = tuple(float(c) for c in obj.color)
    location = np.asarray(matrix_world, np.float64)[:3, 3]
    return (*map(float, location), *colour[:3], colour[3], float(pass_index), random_of(inst, obj))


def _as_rgba(value):
    """A property's value as Cycles takes it: a number (int, float, bool) is (v, v, v, 1), 1-4
    numbers fill (x, y, z, w) over (0, 0, 0, 1); anything else is not an attribute (None)."""
    if isinstance(value, (bool, int, float)):
        v = float(value)
        return (v, v, v, 1.0)
    try:
        values = [float(v) for v in value]
    except (TypeError, ValueError):
        return None
    if not 1 <= len(values) <= 4:
        return None
    out = [0.0, 0.0, 0.0, 1.0]
    out[:len(values)] = values
    return tuple(out)


def _lookup(block, name: str):
    """A custom property of `block` named `name`, else the RNA path `name` on it (custom
    properties first, as Cycles looks them up); None when neither is a usable value."""
    if block is None:
        return None
    try:
        if name in block.keys():
            found = block[name]
            value = _as_rgba(found.to_list() if hasattr(found, "to_list") else found)
            if value is not None:
                return value
    except (TypeError, AttributeError):
        pass
    try:
        found = block.path_resolve(name)
    except (ValueError, TypeError, AttributeError):
        return None
    return _as_rgba(found)


def attribute(kind: str, name: str, obj, parent, view_layer, scene) -> tuple:
    """(r, g, b, a) of an Attribute node of type `kind` ("OBJECT", "INSTANCER", "VIEW_LAYER")
    for an instance of `obj` (`parent`: its instancer, None when it is no instance); all 0
    when not found, as Cycles gives it."""
    if kind == "VIEW_LAYER":
        chain = (view_layer, scene, getattr(scene, "world", None))
    elif kind == "INSTANCER" and parent is not None:
        chain = (parent, getattr(parent, "data", None), obj, getattr(obj, "data", None))
    else:
        chain = (obj, getattr(obj, "data", None))
    for block in chain:
        value = _lookup(block, name)
        if value is not None and all(np.isfinite(value)):
            return value
    return (0.0, 0.0, 0.0, 0.0)
