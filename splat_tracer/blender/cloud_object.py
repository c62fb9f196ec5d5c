"""The Blender object that carries a splat cloud.

A vertex-only mesh with point attributes (`splat_normal`, `splat_radius`, optional
`splat_color`) and a Geometry Nodes "Mesh to Points" modifier: the viewport shows the
points at their splat radius, and the evaluated object is a point cloud that keeps every
attribute, which is what the render engine reads. Python cannot resize a PointCloud
datablock, which is why the stored geometry is a mesh. The node group also gives clouds that
carry `splat_color` the "Splat Cloud" material, so that Cycles and EEVEE show the point
colours too.
"""
from __future__ import annotations

from typing import Callable, Optional

import bpy
import numpy as np

NORMAL = "splat_normal"
RADIUS = "splat_radius"
COLOUR = "splat_color"
NODE_GROUP_TAG = "splat_tracer_points"  # custom property marking our node group
# 1: Mesh to Points only. 2: also Set Material ("Splat Cloud") where `splat_color` exists.
# Objects in older files keep the group they were made with, which still renders.
NODE_GROUP_VERSION = 2
MATERIAL_TAG = "splat_tracer_material"  # custom property marking our material
MATERIAL_VERSION = 2  # 1: Base Color from splat_color; 2: its alpha into Alpha too
MATERIAL_NAME = "Splat Cloud"
# The type each splat attribute must have, on points: what the renderer reads and Estimate
# Splat Normals writes. A user can re-make one with another type (Attribute > Convert).
ATTRIBUTE_TYPES = {NORMAL: "FLOAT_VECTOR", RADIUS: "FLOAT"}
# A mesh's vertex positions as its "position" attribute: foreach_get/foreach_set on it copy
# the array at once, while MeshVertex.co goes through RNA a vertex at a time (10M vertices:
# 0.01 s against 0.5-0.7 s).
POSITION = "position"


def attribute_problem(attributes, name: str, data_type: Optional[str] = None) -> Optional[str]:
    """Why the attribute `name` (when present) cannot be read or written as a splat
    attribute -- "attribute 'splat_radius' must be FLOAT on points, not INT on POINT" --
    or None when it can. data_type: the type wanted (default: ATTRIBUTE_TYPES[name])."""
    attr = attributes.get(name)
    wanted = data_type or ATTRIBUTE_TYPES[name]
    if attr is None or (attr.data_type == wanted and attr.domain == "POINT"):
        return None
    return f"attribute '{name}' must be {wanted} on points, not {attr.data_type} on {attr.domain}"


def mesh_positions(mesh: bpy.types.Mesh) -> np.ndarray:
    """(N, 3) float32 vertex positions of a mesh."""
    out = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.attributes[POSITION].data.foreach_get("vector", out)
    return out.reshape(-1, 3)


def cloud_material() -> bpy.types.Material:
    """The shared "Splat Cloud" material, created on first use: a Principled BSDF whose Base
    Color and Alpha are the points' `splat_color` and its alpha (an Attribute node), so
    Cycles and EEVEE show the point colours, and see-through points are see-through."""
    for material in bpy.data.materials:
        if material.get(MATERIAL_TAG) == MATERIAL_VERSION:
            return material
    material = bpy.data.materials.new(MATERIAL_NAME)
    material[MATERIAL_TAG] = MATERIAL_VERSION
    if bpy.app.version < (5, 0, 0):
        material.use_nodes = True  # always on (and deprecated) from Blender 5.0
    nodes, links = material.node_tree.nodes, material.node_tree.links
    nodes.clear()
    colour = nodes.new("ShaderNodeAttribute")
    colour.attribute_type = "GEOMETRY"
    colour.attribute_name = COLOUR
    shader = nodes.new("ShaderNodeBsdfPrincipled")
    output = nodes.new("ShaderNodeOutputMaterial")
    links.new(colour.outputs["Color"], shader.inputs["Base Color"])
    links.new(colour.outputs["Alpha"], shader.inputs["Alpha"])  # the points' own alpha (1: opaque)
    links.new(shader.outputs["BSDF"], output.inputs["Surface"])
    colour.location, shader.location, output.location = (-300, 0), (0, 0), (300, 0)
    return material


def points_node_group() -> bpy.types.NodeTree:
    """The shared "Mesh to Points" node group, created on first use. Points of a mesh that
    has `splat_color` get the "Splat Cloud" material; without colours they keep none, so
    Cycles shows its default grey rather than a missing attribute's black."""
    for group in bpy.data.node_groups:
        if group.get(NODE_GROUP_TAG) == NODE_GROUP_VERSION:
            return group
    group = bpy.data.node_groups.new("Splat Points", "GeometryNodeTree")
    group[NODE_GROUP_TAG] = NODE_GROUP_VERSION
    group.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    group.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    nodes, links = group.nodes, group.links
    inp = nodes.new("NodeGroupInput")
    out = nodes.new("NodeGroupOutput")
    to_points = nodes.new("GeometryNodeMeshToPoints")
    to_points.mode = "VERTICES"
    radius = nodes.new("GeometryNodeInputNamedAttribute")
    radius.data_type = "FLOAT"
    radius.inputs["Name"].default_value = RADIUS
    # Cycles shades a missing attribute black: only clouds that carry colours get the material.
    # The switch needs one value, not a field: the sum of `Exists` over the points (a sum, as
    # the statistic's min/max would sort every point on each evaluation).
    has_colour = nodes.new("GeometryNodeInputNamedAttribute")
    has_colour.data_type = "FLOAT_COLOR"
    has_colour.inputs["Name"].default_value = COLOUR
    count = nodes.new("GeometryNodeAttributeStatistic")
    set_material = nodes.new("GeometryNodeSetMaterial")
    set_material.inputs["Material"].default_value = cloud_material()
    switch = nodes.new("GeometryNodeSwitch")
    switch.input_type = "GEOMETRY"
    links.new(inp.outputs[0], to_points.inputs["Mesh"])
    links.new(radius.outputs["Attribute"], to_points.inputs["Radius"])
    links.new(to_points.outputs["Points"], set_material.inputs["Geometry"])
    links.new(to_points.outputs["Points"], count.inputs["Geometry"])
    links.new(has_colour.outputs["Exists"], count.inputs["Attribute"])
    links.new(count.outputs["Sum"], switch.inputs["Switch"])  # float to bool: sum > 0
    links.new(to_points.outputs["Points"], switch.inputs["False"])
    links.new(set_material.outputs["Geometry"], switch.inputs["True"])
    links.new(switch.outputs[0], out.inputs[0])
    inp.location, radius.location, to_points.location, out.location = (-400, 0), (-400, -150), (-150, 0), (500, 0)
    has_colour.location, count.location, set_material.location, switch.location = \
        (-150, -250), (100, -200), (100, 0), (300, 0)
    return group


def _add_attribute(mesh, name: str, values: np.ndarray) -> None:
    """A point attribute from an (N,) int or float array or an (N,3) float array."""
    values = np.asarray(values)
    if values.ndim == 2:
        mesh.attributes.new(name, "FLOAT_VECTOR", "POINT").data.foreach_set(
            "vector", np.ascontiguousarray(values, np.float32).ravel())
    elif np.issubdtype(values.dtype, np.integer):
        mesh.attributes.new(name, "INT", "POINT").data.foreach_set("value", np.ascontiguousarray(values, np.int32))
    else:
        mesh.attributes.new(name, "FLOAT", "POINT").data.foreach_set("value", np.ascontiguousarray(values, np.float32))


def create_cloud_object(name: str, local_positions: np.ndarray, normals: np.ndarray, radii: np.ndarray,
                        colours=None, location=(0.0, 0.0, 0.0), collection=None,
                        attributes=None, release: Optional[Callable[[str], None]] = None) -> bpy.types.Object:
    """Creates and links the object; on any failure removes what it created and re-raises.
    attributes: further point attributes, name -> (N,) int/float or (N,3) float array.
    release: called with "positions", "normals", "radii", "colours" or an attribute's name
    once that array is in Blender, for the caller to let go of its own reference: Blender's
    next copies then take the memory it freed (10M points: 440 MB or more of fresh pages
    otherwise, first touched one 4 KiB page at a time)."""
    mesh = obj = None
    done = release or (lambda what: None)
    try:
        mesh = bpy.data.meshes.new(name)
        n = len(local_positions)
        mesh.vertices.add(n)
        mesh.attributes[POSITION].data.foreach_set("vector", np.ascontiguousarray(local_positions, np.float32).ravel())
        local_positions = None
        done("positions")
        mesh.attributes.new(NORMAL, "FLOAT_VECTOR", "POINT").data.foreach_set(
            "vector", np.ascontiguousarray(normals, np.float32).ravel())
        normals = None
        done("normals")
        mesh.attributes.new(RADIUS, "FLOAT", "POINT").data.foreach_set(
            "value", np.ascontiguousarray(radii, np.float32))
        radii = None
        done("radii")
        if colours is not None:
            mesh.attributes.new(COLOUR, "FLOAT_COLOR", "POINT").data.foreach_set(
                "color", np.ascontiguousarray(colours, np.float32).ravel())
            colours = None
            done("colours")
        for attr_name in list(attributes or {}):
            _add_attribute(mesh, attr_name, attributes[attr_name])
            done(attr_name)
        mesh.update()
        obj = bpy.data.objects.new(name, mesh)
        obj.location = location
        modifier = obj.modifiers.new("Splat Points", "NODES")
        modifier.node_group = points_node_group()
        (collection or bpy.context.scene.collection).objects.link(obj)
        return obj
    except BaseException:
        if obj is not None:
            bpy.data.objects.remove(obj)
        if mesh is not None:
            bpy.data.meshes.remove(mesh)
        raise
