"""Motion blur from Blender's and Cycles' settings, read where Cycles reads them: the
shutter (Render > Motion Blur: `render.use_motion_blur`, `motion_blur_shutter`,
`motion_blur_position`, the Shutter Curve; Cycles' `rolling_shutter_type` and `_duration`;
the view layer's `use_motion_blur`) and each object's switches (Object > Motion Blur:
`object.cycles.use_motion_blur`, `motion_steps`). The camera's and each moving instance's
world matrices are sampled at the shutter's motion steps by evaluating the depsgraph at
subframes (RenderEngine.frame_set, as Cycles' sync does), then the frame is evaluated again
at its own time; the core interpolates between the steps at each camera ray's time
(render.scene.Instance.motion, render.camera.Camera.motion).

Only objects whose matrices differ between steps get motion: a scene where nothing moves is
exported exactly as with motion blur off (the same image, no time dimension).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np

from ...render import shading

# Cycles' largest Motion Steps (its property's soft and hard maximum).
MAX_MOTION_STEPS = 7
# Entries of the shutter curve read (Cycles samples it at 256 points too).
SHUTTER_CURVE_POINTS = 256


def motion_steps(obj, parent=None) -> int:
    """How many transforms over the shutter Cycles takes for an object (0: its motion blur is
    off): Cycles' object_motion_steps, 2^(steps - 1) x 2 + 1 for the object's Motion Steps
    (the larger of its own and its instancer's), an odd count so that one step falls on the
    frame's time, and a power of two apart so that steps of objects with different counts
    fall at the same times. Without the Cycles add-on: Cycles' defaults (on, 1 step: 3)."""
    def settings(o):
        c = getattr(o, "cycles", None)
        return (bool(getattr(c, "use_motion_blur", True)), int(getattr(c, "motion_steps", 1))) if c else (True, 1)

    use, steps = settings(obj)
    if parent is not None and parent != obj:
        parent_use, parent_steps = settings(parent)
        use &= parent_use
        steps = max(steps, parent_steps)
    if not use:
        return 0
    steps = min(max(1, steps), MAX_MOTION_STEPS)
    return (2 << (steps - 1)) + 1


def shutter_interval(scene) -> tuple[float, float]:
    """The shutter's opening and closing, in frames from the frame's time: Cycles'
    Motion Blur position (Start on the frame, Center around it, End before it)."""
    shutter = float(scene.render.motion_blur_shutter)
    # Blender's own since 4.x (scene.render); Cycles' before.
    position = getattr(scene.render, "motion_blur_position",
                       getattr(getattr(scene, "cycles", None), "motion_blur_position", "CENTER"))
    if position == "START":
        return 0.0, shutter
    if position == "END":
        return -shutter, 0.0
    return -0.5 * shutter, 0.5 * shutter


def shutter_curve(scene) -> Optional[np.ndarray]:
    """The Shutter Curve's openness at SHUTTER_CURVE_POINTS evenly spaced times over the
    shutter, or None when it is flat (a box shutter: Blender's default)."""
    curve = scene.render.motion_blur_shutter_curve
    curve.initialize()
    values = np.array([curve.evaluate(curve.curves[0], x) for x in np.linspace(0.0, 1.0, SHUTTER_CURVE_POINTS)])
    values = np.clip(values, 0.0, None)
    if not values.sum() > 0:
        return None
    return None if np.ptp(values) == 0 else values


def rolling_shutter(scene) -> Optional[float]:
    """Cycles' Rolling Shutter: its Duration when the type is Top (rows exposed from the
    top down), None for None (a global shutter)."""
    cycles = getattr(scene, "cycles", None)
    if getattr(cycles, "rolling_shutter_type", "NONE") != "TOP":
        return None
    return min(max(float(cycles.rolling_shutter_duration), 0.0), 1.0)


def instance_key(inst) -> tuple:
    """An instance of depsgraph.object_instances that is the same at every subframe: its
    object, and for an instanced one its instancer and persistent id."""
    obj = inst.object.original or inst.object
    if inst.is_instance:
        parent = inst.parent.original or inst.parent
        return (obj.name_full, parent.name_full, tuple(inst.persistent_id))
    return (obj.name_full,)


@dataclass
class Motion:
    """The transforms over the shutter: world matrices by instance_key (only of instances
    that move) and by camera object name (only of cameras that move: the scene camera, or a
    stereo/multi-view render's view cameras)."""

    objects: dict = field(default_factory=dict)
    cameras: dict = field(default_factory=dict)
    curve: Optional[np.ndarray] = None
    rolling: Optional[float] = None  # the rolling shutter's duration, None: a global shutter

    def of(self, inst) -> Optional[np.ndarray]:
        return self.objects.get(instance_key(inst)) if self.objects else None

    def camera_of(self, camera) -> Optional[np.ndarray]:
        """A camera object's world matrices (normalized) over the shutter, or None."""
        return self.cameras.get(camera.name_full) if camera is not None else None


def _may_deform(obj) -> bool:
    """Whether an object's points may move within the shutter (shape keys, or modifiers other
    than a splat cloud's own Mesh to Points): what transforms alone cannot blur."""
    data = getattr(obj, "data", None)
    if getattr(data, "shape_keys", None) is not None:
        return True
    return any(not (m.type == "NODES" and m.node_group is not None and m.node_group.name.startswith("Splat Points"))
               for m in getattr(obj, "modifiers", ()))


# Object types whose transforms are not blurred: lights are exported at the frame's time,
# cameras are read by name (the cameras rendered), empties only instance other objects.
_UNBLURRED_TYPES = ("LIGHT", "CAMERA", "EMPTY")


def _read_transforms(depsgraph, cameras: dict, keys=None) -> tuple[dict, dict, dict]:
    """The transforms at the depsgraph's current time, read one way for motion blur and the
    Vector pass: the instances' world matrices by instance_key (those in `keys`; None: every
    instance of a blurred type), the cameras' (by name) normalized world matrices and focal
    lengths."""
    objects = {}
    for inst in depsgraph.object_instances:
        if inst.object.type in _UNBLURRED_TYPES:
            continue
        key = instance_key(inst)
        if keys is None or key in keys:
            objects[key] = np.array(inst.matrix_world, np.float64)
    views, lenses = {}, {}
    for name, camera in cameras.items():
        evaluated = camera.evaluated_get(depsgraph)
        views[name] = np.array(evaluated.matrix_world.normalized(), np.float64)
        lenses[name] = float(evaluated.data.lens)
    return objects, views, lenses


def sample_motion(depsgraph, frame_set: Callable[[int, float], None], report: shading.Report,
                  cameras=None) -> Optional[Motion]:
    """The cameras' and the instances' transforms at the shutter's motion steps, or None when
    motion blur is off. cameras: the camera objects rendered (a multi-view render's view
    cameras); None: the scene camera. frame_set(frame, subframe) evaluates the depsgraph at
    another time (RenderEngine.frame_set); the frame's own time is evaluated again before
    returning."""
    scene = depsgraph.scene
    render = scene.render
    # Cycles blurs a view layer when both the scene's and the layer's Motion Blur are on.
    if not (render.use_motion_blur and getattr(depsgraph.view_layer, "use_motion_blur", True)
            and render.motion_blur_shutter > 0):
        return None
    open_, close = shutter_interval(scene)
    frame, subframe = scene.frame_current, scene.frame_subframe

    # Who takes how many steps: the camera and every instance with motion blur on.
    wanted = {}
    deforming = []
    for inst in depsgraph.object_instances:
        obj = inst.object
        if obj.type in _UNBLURRED_TYPES:
            continue
        steps = motion_steps(obj.original or obj, (inst.parent.original or inst.parent) if inst.is_instance else None)
        if steps:
            wanted[instance_key(inst)] = steps
            source = obj.original or obj
            if getattr(getattr(source, "cycles", None), "use_deform_motion", True) and _may_deform(source):
                deforming.append(source.name)
    if cameras is None:
        cameras = [scene.camera]
    # By name: a stereo render's two eyes share one camera, sampled once.
    cameras = {c.name_full: c for c in cameras if c is not None}
    camera_steps = {name: motion_steps(c) for name, c in cameras.items()}
    total = max([*camera_steps.values(), *wanted.values()], default=0)
    if total == 0:
        return Motion(curve=shutter_curve(scene), rolling=rolling_shutter(scene))

    times = np.linspace(open_, close, total)
    objects = {key: [None] * total for key in wanted}
    cam = {name: [None] * total for name in cameras}
    lens = {name: set() for name in cameras}

    def read(i):
        now, views, lenses = _read_transforms(depsgraph, cameras, objects)
        for key, m in now.items():
            objects[key][i] = m
        for name in cameras:
            cam[name][i] = views[name]
            lens[name].add(round(lenses[name], 6))

    # The frame's own time first, while the depsgraph is still evaluated there.
    at_frame = [i for i, t in enumerate(times) if t == 0.0]
    for i in at_frame:
        read(i)
    try:
        for i, t in enumerate(times):
            if i in at_frame:
                continue
            when = frame + subframe + float(t)
            whole = int(np.floor(when))
            frame_set(whole, when - whole)
            read(i)
    finally:
        frame_set(frame, subframe)

    motion = Motion(curve=shutter_curve(scene), rolling=rolling_shutter(scene))
    for key, mats in objects.items():
        if any(m is None for m in mats):
            continue  # not there at every step (appears or vanishes within the shutter): still
        mats = _thinned(mats, total, wanted[key])
        if any(not np.array_equal(m, mats[0]) for m in mats[1:]):
            motion.objects[key] = np.array(mats)
    for name, mats in cam.items():
        if camera_steps[name] and all(m is not None for m in mats):
            mats = _thinned(mats, total, camera_steps[name])
            if any(not np.array_equal(m, mats[0]) for m in mats[1:]):
                motion.cameras[name] = np.array(mats)
        if len(lens[name]) > 1:
            report.once(f"camera '{name}': its focal length changes within the shutter: the frame's is used "
                        "throughout (its position and rotation are blurred)")
    if deforming:
        names = ", ".join(f"'{n}'" for n in sorted(set(deforming))[:3]) + (" ..." if len(set(deforming)) > 3 else "")
        report.once(f"Deformation motion blur is not rendered ({names}): objects are blurred as wholes by their "
                    "transforms over the shutter; points that move within an object (shape keys, modifiers) "
                    "are rendered where they are at the frame's time")
    return motion


def _thinned(mats: list, total: int, steps: int) -> list:
    """An object's own steps of the shutter's `total` (both 2^k + 1: every stride-th)."""
    stride = (total - 1) // (steps - 1)
    return mats[::stride]


# Cycles' Vector pass (motion blur off): the motion from the frame to these frames, as
# Cycles' sync samples it for the pass (the previous and the next frame).
VECTOR_FRAMES = (-1, 1)


@dataclass
class FrameMotion:
    """How the instances and cameras move from the frame to the previous and the next frame:
    world-space (2, 4, 4) changes D with M(frame + k) = D[i] @ M(frame) for k in
    VECTOR_FRAMES, by instance_key and by camera object name; only what moves is kept."""

    objects: dict = field(default_factory=dict)
    cameras: dict = field(default_factory=dict)


def sample_frame_motion(depsgraph, frame_set: Callable[[int, float], None], report: shading.Report,
                        cameras=None) -> FrameMotion:
    """The instances' and cameras' changes to VECTOR_FRAMES (the Vector pass's), read by
    evaluating the depsgraph there with frame_set (RenderEngine.frame_set), as motion blur
    does; the frame's own time is evaluated again before returning. cameras: the camera
    objects rendered; None: the scene camera."""
    from ...util import matrices

    scene = depsgraph.scene
    frame, subframe = scene.frame_current, scene.frame_subframe
    cameras = {c.name_full: c for c in (cameras or [scene.camera]) if c is not None}
    deforming = set()

    def read():
        return _read_transforms(depsgraph, cameras)[:2]

    now = read()
    for inst in depsgraph.object_instances:
        source = inst.object.original or inst.object
        if inst.object.type not in _UNBLURRED_TYPES and _may_deform(source):
            deforming.add(source.name)
    others = []
    try:
        for k in VECTOR_FRAMES:
            frame_set(frame + k, subframe)
            others.append(read())
    finally:
        frame_set(frame, subframe)

    def changes(kind: int) -> dict:
        out = {}
        for key, m in now[kind].items():
            steps = [other[kind].get(key) for other in others]
            if any(s is None for s in steps) or all(np.array_equal(s, m) for s in steps):
                continue  # still, or not there at another frame (appears, vanishes): no motion
            try:
                inverse = matrices.inverse(m)
            except np.linalg.LinAlgError:
                continue  # scaled to zero: not rendered (export/scene.py says it)
            out[key] = np.array([np.einsum("ij,jk->ik", s, inverse) for s in steps])
        return out

    if deforming:
        names = ", ".join(f"'{n}'" for n in sorted(deforming)[:3]) + (" ..." if len(deforming) > 3 else "")
        report.once(f"Vector pass: deformation is not captured ({names}): objects move as wholes by their "
                    "transforms between frames; points that move within an object (shape keys, modifiers) "
                    "are taken as still")
    return FrameMotion(changes(0), changes(1))


def _in_local_frame(change: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """World-space changes (..., 4, 4) as changes of the local frame at `origin` (p_local =
    p_world - origin): the same rotation, the translation R o + t - o."""
    local = np.array(change, np.float64)
    local[..., :3, 3] += np.einsum("...ij,j->...i", local[..., :3, :3], origin) - origin
    return local


def _raster(camera, local_from_camera: np.ndarray, points: np.ndarray, width: int, height: int) -> np.ndarray:
    """Cycles' raster coordinates (pixels, x right, y up from the image's bottom) of (n, 3)
    local-frame points seen by `camera`'s projection from `local_from_camera`."""
    from ...util import matrices

    m = matrices.inverse(local_from_camera)
    p = points @ m[:3, :3].T + m[:3, 3]
    if camera.orthographic:
        s = p[:, :2]
    else:
        with np.errstate(divide="ignore", invalid="ignore"):
            s = p[:, :2] / -p[:, 2:3]
    left, right, bottom, top = camera.frustum
    return (s - (left, bottom)) / (right - left, top - bottom) * (width, height)


def vector_pass(position: np.ndarray, instance: np.ndarray, keys: list, motion: FrameMotion, camera,
                camera_name: str, origin, width: int, height: int) -> np.ndarray:
    """Cycles' Vector pass (motion blur off) of a render: (h, w, 4), per pixel the camera's
    first hit's screen-space motion in pixels, as Cycles' primitive_motion_vector: x, y its
    position at the previous frame minus at this one, z, w at this one minus at the next
    (both point the opposite way to the motion; Blender's Vector Blur reads them so); 0
    where nothing is hit. position: (h, w, 3) first hits in the local frame at `origin`;
    instance: (h, w) their instance + 1 (the core's "Instance" pass); keys: instance_key
    of each instance; camera: the frame's (render.camera.Camera), its object's motion by
    camera_name. A panoramic camera gives 0 (the caller says it)."""
    origin = np.asarray(origin, np.float64)
    ids = np.asarray(instance).astype(np.int64).ravel()
    hit = ids > 0
    out = np.zeros(position.shape[:2] + (4,), np.float32)
    if not hit.any() or not keys or camera.panorama is not None:
        return out
    points = np.asarray(position, np.float64).reshape(-1, 3)[hit]
    ids = ids[hit] - 1
    # Per instance, its changes to the previous and the next frame (identity: still).
    changes = np.broadcast_to(np.eye(4), (len(keys), 2, 4, 4)).copy()
    for i, key in enumerate(keys):
        change = motion.objects.get(key)
        if change is not None:
            changes[i] = _in_local_frame(change, origin)
    eye = camera.local_from_camera
    eye_change = motion.cameras.get(camera_name)
    eyes = ([eye, eye] if eye_change is None
            else [np.einsum("ij,jk->ik", c, eye) for c in _in_local_frame(eye_change, origin)])
    centre = _raster(camera, eye, points, width, height)
    c = changes[np.clip(ids, 0, len(keys) - 1)]
    moved = [np.einsum("nij,nj->ni", c[:, k, :3, :3], points) + c[:, k, :3, 3] for k in range(2)]
    before = _raster(camera, eyes[0], moved[0], width, height)
    after = _raster(camera, eyes[1], moved[1], width, height)
    vector = np.concatenate([before - centre, centre - after], axis=1)
    flat = out.reshape(-1, 4)
    flat[np.flatnonzero(hit)] = np.nan_to_num(vector, nan=0.0, posinf=0.0, neginf=0.0)
    return out
