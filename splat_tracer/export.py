"""Blender scene -> core scene and camera.

Reads every visible evaluated point cloud that carries splat normals, through
`depsgraph.object_instances` (so modifiers, instancing and world matrices are honoured),
and the scene camera through Blender's own projection matrix (sensor fit, lens shift,
clipping, pixel aspect, orthographic scale).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import bpy
import numpy as np

from . import core
from .cloud_object import COLOUR, NORMAL, RADIUS


@dataclass
class ExportedScene:
    scene: core.Scene
    origin: np.ndarray            # float64 world position of the local frame's origin
    objects: int                  # number of clouds (instances) exported
    skipped: list = field(default_factory=list)  # names of point clouds without splat normals


def _read(attribute, key: str, width: int, n: int) -> np.ndarray:
    buf = np.empty(n * width, np.float32)
    attribute.data.foreach_get(key, buf)
    return buf.reshape(n, width) if width > 1 else buf


def _check_cloud(name: str, pos, nrm, rad) -> None:
    """Names the object and point for the errors the core would report by global index."""
    problems = (
        (~np.isfinite(pos).all(axis=1), "a position that is not finite"),
        (~(np.isfinite(nrm).all(axis=1) & (np.abs(nrm).max(axis=1) > 0)), "a zero or non-finite normal"),
        (~(np.isfinite(rad) & (rad > 0)), "a radius that is not a positive number"),
    )
    for bad, what in problems:
        if bad.any():
            raise ValueError(f"point cloud '{name}': point {int(np.flatnonzero(bad)[0])} has {what} "
                             f"({int(bad.sum())} such points)")


def _source(obj: bpy.types.Object) -> bpy.types.Object:
    """The original object of an evaluated one: where the user's settings live."""
    return obj.original if obj.original is not None else obj


def base_colour(obj: bpy.types.Object) -> np.ndarray:
    """Scene-linear RGB of a cloud without point colours: the active material's viewport
    colour when it has one, else the object's own viewport colour."""
    source = _source(obj)
    material = source.active_material
    rgba = material.diffuse_color if material is not None else source.color
    return np.array(rgba[:3], dtype=np.float32)


def export_scene(depsgraph: bpy.types.Depsgraph, radius_factor: float = 1.0, threads: int = 0) -> ExportedScene:
    clouds, skipped = [], []
    for inst in depsgraph.object_instances:
        obj = inst.object
        if obj.type != "POINTCLOUD":
            continue
        attrs = obj.data.attributes
        n = len(obj.data.points)
        if n == 0:
            continue
        if NORMAL not in attrs:
            skipped.append(obj.name)
            continue
        pos = _read(attrs["position"], "vector", 3, n).astype(np.float64)
        nrm = _read(attrs[NORMAL], "vector", 3, n)
        rad = _read(attrs[RADIUS] if RADIUS in attrs else attrs["radius"], "value", 1, n)
        col = _read(attrs[COLOUR], "color", 4, n)[:, :3] if COLOUR in attrs else np.tile(base_colour(obj), (n, 1))
        _check_cloud(obj.name, pos, nrm, rad)
        closed = bool(getattr(_source(obj), "splat_tracer", None) and _source(obj).splat_tracer.closed)
        clouds.append((np.array(inst.matrix_world, dtype=np.float64), pos, nrm, rad, col, closed))

    world_pos, normals, radii, colours, closed_flags = [], [], [], [], []
    for m, pos, nrm, rad, col, closed in clouds:
        lin = m[:3, :3]
        world_pos.append(pos @ lin.T + m[:3, 3])
        # Normals transform by the inverse transpose; discs scale by the cube root of the
        # volume scale (exact for uniform scale, a mean for a non-uniform one).
        nrm_w = nrm.astype(np.float64) @ np.linalg.inv(lin)
        normals.append(nrm_w / np.linalg.norm(nrm_w, axis=1, keepdims=True))
        radii.append(rad * abs(np.linalg.det(lin)) ** (1.0 / 3.0) * radius_factor)
        colours.append(col)
        closed_flags.append(np.full(len(pos), closed))
    if world_pos:
        origin, local = core.local_frame(np.concatenate(world_pos))
        arrays = (local, np.concatenate(normals), np.concatenate(radii), np.concatenate(colours),
                  np.concatenate(closed_flags))
    else:
        origin = np.zeros(3)
        arrays = (np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3)), False)
    return ExportedScene(core.Scene(*arrays, threads=threads), origin, len(clouds), skipped)


def export_camera(depsgraph: bpy.types.Depsgraph, width: int, height: int, origin) -> core.Camera:
    scene = depsgraph.scene
    if scene.camera is None:
        raise RuntimeError("the scene has no active camera")
    cam = scene.camera.evaluated_get(depsgraph)
    if cam.type != "CAMERA":
        raise RuntimeError(f"the active camera '{cam.name}' is not a camera object")
    if cam.data.type == "PANO":
        raise RuntimeError("panoramic cameras are not supported; use perspective or orthographic")
    r = scene.render
    projection = cam.calc_matrix_camera(depsgraph, x=width, y=height, scale_x=r.pixel_aspect_x,
                                        scale_y=r.pixel_aspect_y)
    return core.Camera.from_view_projection(projection, cam.matrix_world.normalized(), origin)
