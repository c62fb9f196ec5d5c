"""The Blender object that carries a splat cloud.

A vertex-only mesh with point attributes (`splat_normal`, `splat_radius`, optional
`splat_color`) and a Geometry Nodes "Mesh to Points" modifier: the viewport shows the
points at their splat radius, and the evaluated object is a point cloud that keeps every
attribute, which is what the render engine reads. Python cannot resize a PointCloud
datablock, which is why the stored geometry is a mesh.
"""
from __future__ import annotations

import bpy
import numpy as np

NORMAL = "splat_normal"
RADIUS = "splat_radius"
COLOUR = "splat_color"
NODE_GROUP_TAG = "splat_tracer_points"  # custom property marking our node group
NODE_GROUP_VERSION = 1


def points_node_group() -> bpy.types.NodeTree:
    """The shared "Mesh to Points" node group, created on first use."""
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
    links.new(inp.outputs[0], to_points.inputs["Mesh"])
    links.new(radius.outputs["Attribute"], to_points.inputs["Radius"])
    links.new(to_points.outputs["Points"], out.inputs[0])
    inp.location, radius.location, to_points.location, out.location = (-400, 0), (-400, -150), (-150, 0), (100, 0)
    return group


def create_cloud_object(name: str, local_positions: np.ndarray, normals: np.ndarray, radii: np.ndarray,
                        colours=None, location=(0.0, 0.0, 0.0), collection=None) -> bpy.types.Object:
    """Creates and links the object; on any failure removes what it created and re-raises."""
    mesh = obj = None
    try:
        mesh = bpy.data.meshes.new(name)
        n = len(local_positions)
        mesh.vertices.add(n)
        mesh.vertices.foreach_set("co", np.ascontiguousarray(local_positions, np.float32).ravel())
        mesh.attributes.new(NORMAL, "FLOAT_VECTOR", "POINT").data.foreach_set(
            "vector", np.ascontiguousarray(normals, np.float32).ravel())
        mesh.attributes.new(RADIUS, "FLOAT", "POINT").data.foreach_set(
            "value", np.ascontiguousarray(radii, np.float32))
        if colours is not None:
            mesh.attributes.new(COLOUR, "FLOAT_COLOR", "POINT").data.foreach_set(
                "color", np.ascontiguousarray(colours, np.float32).ravel())
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
