"""The same clouds rendered inside Blender: by the add-on's SPLAT_TRACER engine (the real
F12 path: import, export, render, passes) and by Cycles rendering the cloud the way Blender
users do today (the importer's Mesh to Points spheres, 1 sample)."""
from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

_ready = False


def _blender(workdir: Path):
    global _ready
    from tools import dev_extension

    if not _ready:
        dev_extension.isolate_user_dirs(str(workdir / "blender_user"))
    import bpy

    if not _ready:
        dev_extension.enable_from_source(workdir)
        _ready = True
    return bpy


def render(engine: str, ply_path: Path, view: dict, width: int, height: int, workdir: Path, closed: bool,
           method: str = "FULL", lamp_power: float = 0.0, point_normals: bool = False, lamp_position=None) -> dict:
    """Renders the cloud in `ply_path` with `engine` ('SPLAT_TRACER' or 'CYCLES') from the
    camera `view` (Camera.look_at arguments). Returns wall seconds of the render call,
    the threads Blender was told to use, and top-row-first coverage, depth, normals and the
    Combined pass (H,W,4).
    lamp_power > 0: a point lamp of that power (W, radius 0) at the camera, and direct light
    only (no bounces); lamp_position: that lamp there instead (world coordinates). point_normals: Cycles shades the spheres with the points'
    `splat_normal` instead of the sphere's own normal (the file must have colours: that
    patches the importer's "Splat Cloud" material, which only coloured clouds get)."""
    bpy = _blender(workdir)
    from tests.support.blender_helpers import render_to_exr
    from mathutils import Matrix

    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    bpy.ops.splat_tracer.import_cloud(filepath=str(ply_path))
    obj = bpy.context.active_object
    obj.splat_tracer.closed = closed
    if point_normals:
        from tests.support.blender_helpers import extension_module

        cloud_object = extension_module("blender.cloud_object")
        material = next(m for m in bpy.data.materials if m.get(cloud_object.MATERIAL_TAG))
        nodes, links = material.node_tree.nodes, material.node_tree.links
        normal = nodes.new("ShaderNodeAttribute")
        normal.attribute_type = "GEOMETRY"
        normal.attribute_name = cloud_object.NORMAL
        bsdf = next(n for n in nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
        links.new(normal.outputs["Vector"], bsdf.inputs["Normal"])
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(cam)
    eye, target, up = (np.asarray(view[k], dtype=np.float64) for k in ("eye", "target", "up"))
    fwd = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(fwd, up)
    right /= np.linalg.norm(right)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = right, np.cross(right, fwd), -fwd, eye
    cam.matrix_world = Matrix(m.tolist())
    cam.data.sensor_fit, cam.data.sensor_height = "VERTICAL", 24.0
    cam.data.lens = 12.0 / math.tan(math.radians(view["fov_y"]) / 2)
    cam.data.clip_start, cam.data.clip_end = view["near"], view["far"]
    scene.camera = cam
    if lamp_power > 0:
        lamp = bpy.data.objects.new("Headlamp", bpy.data.lights.new("Headlamp", "POINT"))
        lamp.data.energy = lamp_power
        lamp.data.shadow_soft_size = 0.0
        lamp.location = tuple(eye) if lamp_position is None else tuple(float(x) for x in lamp_position)
        scene.collection.objects.link(lamp)
        scene.world = None  # no world light: the lamp alone
    scene.render.engine = engine
    scene.render.film_transparent = True
    if engine == "CYCLES":
        scene.cycles.device = "CPU"
        scene.cycles.samples = 1
        scene.cycles.use_denoising = False
        scene.cycles.pixel_filter_type = "BOX"
        scene.cycles.filter_width = 0.01  # sample the pixel centre, like the truth and our engine
        if lamp_power > 0:
            scene.cycles.max_bounces = 0  # direct light from the lamp only
    else:
        scene.splat_tracer.method = method
        scene.cycles.samples = 1  # the pixel centre, like the truth and the Cycles row
    t0 = time.perf_counter()
    out = render_to_exr(bpy, scene, workdir / f"{engine.lower()}.exr", width, height)
    seconds = time.perf_counter() - t0
    return {"seconds": seconds, "threads": scene.render.threads, "hit": out["depth"].ravel() < 1e9,
            "depth": out["depth"].ravel().astype(np.float64), "normal": out["normal"].reshape(-1, 3),
            "rgba": out["rgba"]}
