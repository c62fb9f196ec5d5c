"""Scenes of several objects for the core: meshes beside splat clouds, instances, materials,
lamps, a world."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, NamedTuple, Optional, Sequence

import numpy as np

from .. import _core
from . import cryptomatte
from ..util import matrices
from ..util.arrays import as_f32
from .camera import Camera, window_rect
from .method import Method
from .nodes import MAX_OBJECT_ATTRIBUTES, OBJECT_INFO_FLOATS, attribute_layout, columns_of, object_attribute_layout
from .shading import (LIGHT_FIELDS, LIGHT_GROUP_PREFIX, LIGHT_PASSES, MATERIAL_FIELDS, MAX_LIGHT_GROUPS, PASSES, Light,
                      Material, RenderSettings, World)
from .splats import MAX_COORDINATE, SplatCloud

RAY_VISIBILITY = {"camera": 1, "diffuse": 2, "glossy": 4, "transmission": 8, "shadow": 16}


def transform_problem(matrix) -> Optional[str]:
    """Why the core cannot place geometry by this 4x4 object-to-local matrix (a phrase for a
    report: "its transform is ..."), or None when it can. The core traces each instance in
    object space through the inverse, so the matrix must be invertible, and both it and
    its inverse within the core's coordinate limit as float32 (an object scaled to 0 along
    an axis has no inverse; one scaled by 1e-20 has one beyond the limit)."""
    m = np.asarray(matrix, np.float64).reshape(4, 4)
    if not np.isfinite(m).all():
        return "its transform is not finite"
    if abs(np.linalg.det(m[:3, :3])) < 1e-300:
        return "its transform is singular (scaled to 0 along an axis)"
    inv = matrices.inverse(m)
    limit = np.float32(MAX_COORDINATE)
    if not np.abs(m[:3].astype(np.float32)).max() <= limit:
        return f"its transform places or scales it beyond the renderer's limit ({MAX_COORDINATE:.0e})"
    if not np.abs(inv[:3].astype(np.float32)).max() <= limit:
        return f"its scale is too close to 0 (the inverse transform exceeds the renderer's limit, {MAX_COORDINATE:.0e})"
    return None


class InstanceRow(NamedTuple):
    """One instance as the core's RenderScene takes it: a column each (no defaults, so that
    a new column is filled wherever rows are built, fuzz/fuzz_core.py included)."""

    geometry_index: int    # into the geometries
    to_world: np.ndarray   # 12: the first three rows of the 4x4 object-to-local matrix
    to_object: np.ndarray  # 12: the same of its inverse
    material_range: tuple  # (first, count) of its slots in the materials
    visibility: int        # RAY_VISIBILITY bits
    holdout: bool
    pass_index: float
    shadow_catcher: bool
    motion: Optional[np.ndarray]  # (S, 12): to_world at S evenly spaced times over the shutter; None: still


def native_scene(geometries: Sequence, rows: Sequence[InstanceRow], materials: Sequence, lights: Sequence,
                 threads: int = 0, programs: Optional[Sequence] = None,
                 object_values: Optional[np.ndarray] = None) -> "_core.RenderScene":
    """The core's RenderScene over native geometries (SplatCloud._scene, Mesh._mesh), one
    row per instance, materials and lights as their pack() rows, and per material its node
    program (nodes.Program.native()) or None -- None for all: no programs. Nothing is checked
    here: RenderScene checks first, and the fuzz harness passes unchecked rows on purpose.
    object_values: (n, k) per instance what its programs read of it (Object Info, object
    attributes: nodes.OBJECT_INFO), or None when no program reads any."""
    n = len(rows)
    col = lambda name, dtype, width=(): np.ascontiguousarray(
        np.array([getattr(r, name) for r in rows], dtype).reshape((n, *width)))
    # Motion blur: the moving instances' steps in one table, each instance's (first, count).
    # Only a scene where something moves passes them: a still one is the core's as before.
    motion = motion_range = None
    if any(r.motion is not None for r in rows):
        steps = [np.asarray(r.motion, np.float64).reshape(-1, 12) if r.motion is not None else np.empty((0, 12))
                 for r in rows]
        counts = np.array([len(s) for s in steps], np.int64)
        motion = np.ascontiguousarray(np.concatenate(steps), np.float64)
        motion_range = np.ascontiguousarray(np.stack([np.cumsum(counts) - counts, counts], axis=1), np.int32)
    return _core.RenderScene(
        list(geometries), col("geometry_index", np.int32), col("to_world", np.float32, (12,)),
        col("to_object", np.float32, (12,)), col("material_range", np.int32, (2,)), col("visibility", np.int32),
        col("holdout", np.uint8), col("pass_index", np.float32),
        np.ascontiguousarray(np.array(materials, np.float32).reshape(-1, len(MATERIAL_FIELDS))),
        np.ascontiguousarray(np.array(lights, np.float32).reshape(-1, len(LIGHT_FIELDS))),
        threads,
        # Only a scene with a catcher passes the column: one without is the core's as before.
        shadow_catcher=col("shadow_catcher", np.uint8) if any(r.shadow_catcher for r in rows) else None,
        motion=motion, motion_range=motion_range,
        # Only materials with node programs pay for them: without any, the core's path is as before.
        programs=programs if programs is not None and any(p is not None for p in programs) else None,
        object_values=None if object_values is None else np.ascontiguousarray(object_values, np.float32))


class Mesh:
    """A triangle mesh and its BVH: vertices (V,3), triangles (T,3) vertex indices, optional
    corner_normals (T,3,3) shading normals (smooth, flat and sharp edges as Blender's corner
    normals express them; None: flat), material_index (T,) slots and corner_uv (T,3,2), the
    UV map node programs and the UV pass read (None: 0). corner_attributes (T,3,k): the
    attributes the scene's node programs read (Attribute node) at each triangle corner, laid out
    for `attribute_layout` as a SplatCloud's are (splats.SplatCloud), interpolated over the
    triangle. Immutable; share one Mesh between any number of instances."""

    def __init__(self, vertices, triangles, corner_normals=None, material_index=None, threads: int = 0,
                 corner_uv=None, corner_attributes=None, attribute_layout: tuple = ()):
        v = as_f32(vertices, "vertices", (-1, 3))
        t = np.asarray(triangles)
        if t.size and not np.issubdtype(t.dtype, np.integer):
            raise TypeError(f"triangles must hold integer vertex indices, got dtype {t.dtype}")
        if t.size and (t.min() < 0 or t.max() >= len(v)):
            raise ValueError(f"triangles index vertices outside 0..{len(v) - 1}")
        t = np.ascontiguousarray(t.reshape(-1, 3), dtype=np.int32)
        n = None if corner_normals is None else as_f32(np.asarray(corner_normals).reshape(-1, 3, 3), "corner_normals",
                                                     (len(t), 3, 3))
        m = None if material_index is None else np.ascontiguousarray(material_index, dtype=np.int32)
        uv = None if corner_uv is None else as_f32(np.asarray(corner_uv).reshape(-1, 3, 2), "corner_uv", (len(t), 3, 2))
        self.attribute_layout = tuple(attribute_layout) if corner_attributes is not None else ()
        attr = None
        if corner_attributes is not None:
            k = sum(w for _, w in self.attribute_layout)
            attr = as_f32(np.asarray(corner_attributes).reshape(-1, 3, k), "corner_attributes", (len(t), 3, k))
        self._mesh = _core.Mesh(v, t, n, m, threads, corner_uv=uv, corner_attributes=attr)

    def __len__(self) -> int:
        return self._mesh.size


@dataclass(frozen=True)
class Instance:
    """One placement of a geometry (a SplatCloud or a Mesh) in the scene's local frame.

    matrix: 4x4 object-to-local transform (any affine: scale, shear, mirror). materials: the
    object's slots (a cloud uses the first). visibility: ray kinds that see it (keys of
    RAY_VISIBILITY; default all). holdout: camera rays that see it get alpha 0.
    pass_index: the Object Index pass value. shadow_catcher: it receives the other
    instances' shadows and reflections but is left out of Combined (Cycles' shadow catcher;
    see RenderScene.render). motion: motion blur -- the 4x4 object-to-local matrix at S >= 2
    evenly spaced times over the shutter (the first at its opening), interpolated between
    them as Cycles does (translation and stretch linearly, rotation by slerp) at each camera
    ray's time; None (default): it does not move, and costs nothing. `matrix` stays the
    frame's own (mesh lights and the camera's inside test use it). name, asset: its object's
    and asset's names in the Cryptomatte passes (render/cryptomatte.py; asset "" : the
    object's name)."""

    geometry: object
    matrix: tuple = ((1.0, 0.0, 0.0, 0.0), (0.0, 1.0, 0.0, 0.0), (0.0, 0.0, 1.0, 0.0), (0.0, 0.0, 0.0, 1.0))
    materials: tuple = (Material(),)
    visibility: frozenset = frozenset(RAY_VISIBILITY)
    holdout: bool = False
    pass_index: int = 0
    shadow_catcher: bool = False
    motion: Optional[tuple] = None
    name: str = ""
    asset: str = ""
    light_group: str = ""  # its emission's light group (Object > Shading > Light Group; "": none)
    # What Object Info gives of it: location (world space: the local frame's origin added
    # back), colour (RGBA: Object > Viewport Display > Color), pass index, random (0..1) --
    # empty: its matrix's translation, white, pass_index, 0.
    object_info: tuple = ()
    # Attribute nodes of type object, instancer or view layer: ((type, name), (r, g, b, a))
    # pairs; a pair its materials read and it lacks is 0, as Cycles gives a missing one.
    object_attributes: tuple = ()


def _object_values(inst: Instance, slots: dict) -> np.ndarray:
    """An instance's row of object values (nodes.OBJECT_INFO, then its attributes by `slots`)."""
    info = np.asarray(inst.object_info, np.float64).ravel()
    if info.size == 0:
        location = np.asarray(inst.matrix, np.float64).reshape(4, 4)[:3, 3]
        info = np.array([*location, 1.0, 1.0, 1.0, 1.0, float(inst.pass_index), 0.0])
    if info.size != OBJECT_INFO_FLOATS:
        raise ValueError(f"instance '{inst.name}': object_info must hold {OBJECT_INFO_FLOATS} values, got {info.size}")
    row = np.zeros(OBJECT_INFO_FLOATS + 4 * len(slots), np.float64)
    row[:OBJECT_INFO_FLOATS] = info
    for key, value in inst.object_attributes:
        if tuple(key) in slots:
            first = OBJECT_INFO_FLOATS + 4 * slots[tuple(key)]
            row[first:first + 4] = np.asarray(value, np.float64).ravel()[:4]
    if not np.isfinite(row).all():
        raise ValueError(f"instance '{inst.name}': object values must be finite")
    return row.astype(np.float32)


class FrameResult(NamedTuple):
    passes: dict      # pass name -> (h, w[, c]) float32 array, top row first
    completed: bool   # False when progress() asked to stop
    counters: dict    # rays traced by kind, and the queries' work; samples_reached (the most any pixel
                      # took: below the samples when the time limit cut), samples_taken (over all
                      # pixels), time_limited


class RenderScene:
    """Instances of clouds and meshes with their materials, the lamps and the world: what a
    Blender frame is, for the core. Geometry is referenced, not copied: a hundred instances
    of one cloud cost one BVH. Build a new RenderScene when instances, materials or lamps
    change (cheap: only the top-level tree over the instances is built)."""

    def __init__(self, instances: Sequence[Instance], lights: Sequence[Light] = (), world: World = World(),
                 threads: int = 0):
        # Wrong types are refused here with a TypeError naming them, not left to fail later
        # as an AttributeError deep in pack() (or, for the world, only at render time).
        if not isinstance(world, World):
            raise TypeError(f"world must be a shading.World, got {type(world).__name__}")
        for light in lights:
            if not isinstance(light, Light):
                raise TypeError(f"lights must be shading.Light objects, got {type(light).__name__}")
        geometries, index_of = [], {}
        rows = []
        materials = []
        # Cryptomatte's names: (object, asset) per instance, one per material-table entry.
        self.instance_names, self.material_names = [], []
        for inst in instances:
            if not isinstance(inst, Instance):
                raise TypeError(f"instances must be scene.Instance objects, got {type(inst).__name__}")
            geo = inst.geometry
            native = geo._scene if isinstance(geo, SplatCloud) else geo._mesh if isinstance(geo, Mesh) else None
            if native is None:
                raise TypeError(f"instance geometry must be a splats.SplatCloud or scene.Mesh, "
                                f"got {type(geo).__name__}")
            if id(native) not in index_of:
                index_of[id(native)] = len(geometries)
                geometries.append(native)
            m = np.asarray(inst.matrix, np.float64).reshape(4, 4)
            problem = transform_problem(m)
            if problem is not None:
                raise ValueError(f"instance matrix must be finite and invertible: {problem}")
            inv = matrices.inverse(m)
            motion = None
            if inst.motion is not None:
                motion = np.asarray(inst.motion, np.float64)
                if motion.ndim != 3 or motion.shape[1:] != (4, 4) or len(motion) < 2:
                    raise ValueError(f"instance motion must be at least two 4x4 matrices, got shape {motion.shape}")
                for step in motion:
                    problem = transform_problem(step)
                    if problem is not None:
                        raise ValueError(f"instance motion matrices must be finite and invertible: {problem}")
                motion = motion[:, :3].reshape(-1, 12)
            unknown = set(inst.visibility) - set(RAY_VISIBILITY)
            if unknown:
                raise ValueError(f"unknown ray visibility {sorted(unknown)}; use {sorted(RAY_VISIBILITY)}")
            mats = tuple(inst.materials) or (Material(),)
            for mat in mats:
                if not isinstance(mat, Material):
                    raise TypeError(f"instance materials must be shading.Material objects, got {type(mat).__name__}")
            rows.append(InstanceRow(geometry_index=index_of[id(native)], to_world=m[:3].ravel(),
                                    to_object=inv[:3].ravel(), material_range=(len(materials), len(mats)),
                                    visibility=sum(RAY_VISIBILITY[k] for k in inst.visibility),
                                    holdout=inst.holdout, pass_index=inst.pass_index,
                                    shadow_catcher=inst.shadow_catcher, motion=motion))
            materials.extend(mats)
            self.instance_names.append((inst.name, inst.asset or inst.name))
            self.material_names.extend(m.name for m in mats)
        self.world = world
        self.lights = tuple(lights)
        # The shader AOVs the materials' AOV Output nodes write, numbered for the core.
        self.aov_names = tuple(sorted({name for m in materials if m.program is not None
                                       for name, _, _ in m.program.aovs}))
        keys = {name: i for i, name in enumerate(self.aov_names)}
        # The point attributes the programs read, in the one layout every cloud carries them in.
        self.attribute_layout = attribute_layout([m.program for m in materials])
        for inst in instances:
            layout = getattr(inst.geometry, "attribute_layout", ())
            if layout and layout != self.attribute_layout:
                raise ValueError(f"instance '{inst.name}': its geometry carries the attributes {layout}, "
                                 f"the materials read {self.attribute_layout}")
        columns = columns_of(self.attribute_layout)
        self.instance_light_groups = tuple(inst.light_group for inst in instances)
        programs = [m.program for m in materials]
        self.object_attribute_layout = object_attribute_layout(programs)
        slots = {key: i for i, key in enumerate(self.object_attribute_layout[:MAX_OBJECT_ATTRIBUTES])}
        # Only a scene whose programs read their instance's values carries them.
        object_values = None
        if any(p is not None and p.reads_object() for p in programs):
            object_values = np.stack([_object_values(inst, slots) for inst in instances])
        self._scene = native_scene(geometries, rows, [m.pack() for m in materials], [l.pack() for l in lights],
                                   threads, [p.native(keys, columns, slots) if p is not None else None
                                             for p in programs], object_values)
        self.geometry_count = len(geometries)
        self.shadow_catchers = sum(bool(r.shadow_catcher) for r in rows)  # instances that are shadow catchers
        self.moving = sum(r.motion is not None for r in rows)  # instances that move over the shutter

    def mesh_lights(self) -> list:
        """The emissive mesh triangles sampled as lights, as (instance index, triangle index,
        probability of being picked) -- power-weighted: area (in the scene) x luminance of the
        emission x alpha. A material whose emission_sampling samples no side, an instance
        hidden from both diffuse and glossy rays, and clouds are not among them."""
        return self._scene.mesh_lights()

    def render(self, camera: Camera, width: int, height: int, settings: RenderSettings = RenderSettings(),
               method: Method = Method(), passes: Sequence[str] = ("Combined",),
               window: Optional[Sequence[int]] = None, threads: int = 0,
               progress: Optional[Callable[[int, int], bool]] = None, tile_size: int = 32,
               packets: bool = True, shutter_curve=None, rolling_shutter: Optional[float] = None,
               cryptomatte_levels: int = 6, light_groups: Sequence[str] = (), aovs: Sequence[tuple] = (),
               aov_alpha_threshold: float = 0.5) -> FrameResult:
        """Renders `passes` (names from shading.PASSES; Combined always) of a window of the
        image (x0, y0, w, h; default all). progress(done, total) as for SplatCloud.render.
        packets: each sample's camera rays of 4x4 pixels found as one packet (False: ray by
        ray; the same image). shutter_curve: motion blur's shutter curve, the shutter's
        openness at evenly spaced times from its opening to its closing (>= 2 values, >= 0, not
        all 0; Blender's Shutter Curve); None: a box shutter. Camera rays get a time in the
        shutter only where something moves (an instance's or the camera's `motion`).
        rolling_shutter: Cycles' rolling shutter (rows exposed from top to bottom), its
        duration in [0, 1] (a row's exposure as a share of the shutter; 0: an instant);
        None: off (a global shutter).

        With shadow-catcher instances, Combined is formed as Cycles forms it: the catcher is
        left out, and its shadow (its light with everything / its light with catchers only)
        becomes alpha on a transparent film (1 - the shadow's average, so that Alpha Over
        onto a photograph darkens it), or darkens the world behind it on an opaque film. With
        the "Shadow Catcher" pass asked for, Combined leaves the shadow out entirely (the
        catcher is a hole) and the pass holds it, to multiply the photograph by.

        The Cryptomatte passes (cryptomatte.KINDS) are (h, w, 2 slots) arrays of (id,
        coverage) pairs, cryptomatte.slots_of(cryptomatte_levels) of them, sorted by coverage;
        the ids are those of the instances' name and asset and the materials' name.


        light_groups: group names (at most shading.MAX_LIGHT_GROUPS); each gets a pass
        "Combined_<name>" holding the light of the lamps, emissive instances and world whose
        light_group is that name (Cycles' light groups: the groups sum to Combined less what
        belongs to none).

        aovs: the view layer's shader AOVs, (name, "COLOR" or "VALUE") each, returned among
        the passes under their names ((h, w, 4) RGBA or (h, w)): what the materials' AOV Output
        nodes of that name write on the camera ray's surfaces up to the first whose alpha
        reaches aov_alpha_threshold (Cycles' view-layer Alpha Threshold), averaged over the
        samples; 0 where nothing writes it. Costs nothing unless a material writes one."""
        for value, kind, name in ((camera, Camera, "camera"), (settings, RenderSettings, "settings"),
                                  (method, Method, "method")):
            if not isinstance(value, kind):
                raise TypeError(f"{name} must be a {kind.__name__}, got {type(value).__name__}")
        if isinstance(passes, str):
            raise TypeError("passes must be a sequence of pass names, not one string")
        unknown = set(passes) - set(PASSES) - set(cryptomatte.KINDS)
        if unknown:
            raise ValueError(f"unknown passes {sorted(unknown)}; known: {sorted(PASSES) + list(cryptomatte.KINDS)}")
        if isinstance(light_groups, str):
            raise TypeError("light_groups must be a sequence of group names, not one string")
        aovs = tuple((str(name), str(kind)) for name, kind in aovs)
        taken = {"Combined", *PASSES, *cryptomatte.KINDS, *passes, *(LIGHT_GROUP_PREFIX + g for g in light_groups)}
        for name, kind in aovs:
            if kind not in AOV_CHANNELS or name in taken:
                raise ValueError(f"AOV {name!r}: a type in {sorted(AOV_CHANNELS)} and a name no other pass has")
        if len({name for name, _ in aovs}) != len(aovs):
            raise ValueError("AOV names must differ")
        ids = None
        if set(passes) & set(cryptomatte.KINDS):
            ids = (np.array([[cryptomatte.name_id(n) for n in pair] for pair in self.instance_names],
                            np.float32).reshape(-1, 2),
                   # The core's table has its default material when no instance brings one.
                   np.array([cryptomatte.name_id(n) for n in self.material_names or [Material().name]], np.float32))
        kwargs, buffers = render_arguments(camera, width, height, settings, method, self.world, passes, window,
                                           cryptomatte_ids=ids, cryptomatte_levels=cryptomatte_levels,
                                           aovs=aovs, aov_names=self.aov_names,
                                           aov_alpha_threshold=aov_alpha_threshold)
        if light_groups:
            kwargs.update(self._light_group_arguments(light_groups, buffers, *buffers["Combined"].shape[:2]))
        if shutter_curve is not None:
            kwargs["shutter_table"] = shutter_table(shutter_curve)
        if rolling_shutter is not None:
            if not 0.0 <= rolling_shutter <= 1.0:
                raise ValueError(f"rolling_shutter must be a duration in [0, 1], got {rolling_shutter!r}")
            kwargs["rolling_shutter_duration"] = float(rolling_shutter)
        done, counters = self._scene.render(**kwargs, threads=threads, progress=progress, tile_size=tile_size,
                                            packets=packets)
        return FrameResult(buffers, bool(done), counters)

    def _light_group_arguments(self, groups: Sequence[str], buffers: dict, h: int, w: int) -> dict:
        """The core's light-group keywords, and each group's pass added to `buffers`."""
        groups = list(dict.fromkeys(groups))
        if len(groups) > MAX_LIGHT_GROUPS:
            raise ValueError(f"at most {MAX_LIGHT_GROUPS} light groups, got {len(groups)}")
        planes = np.zeros((len(groups), h, w, 3), np.float32)
        for i, name in enumerate(groups):
            buffers[LIGHT_GROUP_PREFIX + name] = planes[i]
        index = {name: i for i, name in enumerate(groups)}
        of = lambda name: index.get(name, -1) if name else -1  # noqa: E731
        return dict(light_groups=planes,
                    light_group_lamps=np.array([of(l.light_group) for l in self.lights], np.int32),
                    light_group_instances=np.array([of(g) for g in self.instance_light_groups], np.int32),
                    light_group_world=of(self.world.light_group))


# Entries of the shutter curve's inverse CDF the core interpolates (Cycles' shutter table has
# 256 as well: finer than a curve drawn by hand).
SHUTTER_TABLE_SIZE = 256


def shutter_table(curve) -> np.ndarray:
    """The shutter time (0 opens, 1 closes) of evenly spaced uniform numbers: the inverse of
    the CDF of `curve`, the shutter's openness at evenly spaced times (piecewise linear), as
    Cycles samples its shutter curve."""
    w = np.asarray(curve, np.float64).ravel()
    if w.size < 2 or not np.isfinite(w).all() or (w < 0).any() or not w.sum() > 0:
        raise ValueError("shutter_curve must be >= 2 finite values >= 0, not all 0")
    # CDF of the piecewise linear openness, on a grid 16 times finer than the table (so that
    # the table's linear steps follow the CDF's curvature inside each of the curve's pieces).
    x = np.linspace(0.0, 1.0, 16 * SHUTTER_TABLE_SIZE)
    w = np.interp(x, np.linspace(0.0, 1.0, w.size), w)
    cdf = np.concatenate([[0.0], np.cumsum((w[1:] + w[:-1]) * 0.5)])
    cdf /= cdf[-1]
    u = np.linspace(0.0, 1.0, SHUTTER_TABLE_SIZE)
    # Flat (closed) stretches of the CDF are never sampled: interp takes the first x of a
    # repeated CDF value, which is where the openness ends.
    keep = np.concatenate([[True], np.diff(cdf) > 0])
    return np.clip(np.interp(u, cdf[keep], x[keep]), 0.0, 1.0).astype(np.float32)


# The core's keyword for each pass's buffer (Combined: "combined").
PASS_KEYWORDS = {"Combined": "combined", "Depth": "depth", "Normal": "normal", "DiffCol": "diffcol", "Emit": "emit",
                 "Shadow": "shadow", "IndexOB": "index", "Splat Count": "splat_count",
                 "Shadow Catcher": "shadow_catcher", "Position": "position", "IndexMA": "material_index",
                 "Mist": "mist", "Env": "environment", "AO": "ao", "UV": "uv",
                 "Instance": "instance"}


# A shader AOV's channels by its type (Blender's AOV.type): RGBA as Cycles registers a colour AOV.
AOV_CHANNELS = {"COLOR": 4, "VALUE": 1}


def render_arguments(camera: Camera, width: int, height: int, settings: RenderSettings, method: Method, world: World,
                     passes: Sequence[str] = ("Combined",), window: Optional[Sequence[int]] = None,
                     cryptomatte_ids: Optional[tuple] = None, cryptomatte_levels: int = 6,
                     aovs: Sequence[tuple] = (), aov_names: Sequence[str] = (),
                     aov_alpha_threshold: float = 0.5) -> tuple[dict, dict]:
    """The keyword arguments of the core's RenderScene.render for a frame (all but threads,
    progress, tile_size and packets), and the zeroed buffers they write, by pass name (the
    AOVs' by theirs; aov_names: the scene's, RenderScene.aov_names). It
    checks only the window (before allocating): RenderScene.render checks its arguments
    first, and fuzz/fuzz_core.py passes unchecked ones on purpose, so that the fuzzed
    layout is the add-on's. cryptomatte_ids: (instance ids (instances, 2), material ids),
    needed when a Cryptomatte pass is asked for (RenderScene.render makes them)."""
    x0, y0, w, h = window_rect(window, width, height)
    buffers = {}
    slots = cryptomatte.slots_of(cryptomatte_levels)
    for name in ("Combined", *passes):
        if name in LIGHT_PASSES and name != "DiffCol":
            continue  # a plane of the light passes' buffer, below
        if name in cryptomatte.KINDS:
            buffers[name] = np.zeros((h, w, 2 * slots), np.float32)
            continue
        c = PASSES[name]
        buffers[name] = np.zeros((h, w) if c == 1 else (h, w, c), np.float32)
    local_from_camera, frustum, orthographic = camera.native()
    kwargs = dict(local_from_camera=local_from_camera, frustum=frustum, orthographic=orthographic, width=int(width),
                  height=int(height), window=(int(x0), int(y0), int(w), int(h)), settings=settings.pack(),
                  method=method, world=world.radiance(), film_transparent=bool(world.transparent),
                  lens=camera.lens.native() if camera.lens else None,
                  world_visibility=sum(RAY_VISIBILITY[k] for k in world.visibility))
    if world.environment is not None:  # a uniform world passes nothing more: the call is as before
        kwargs["world_map"] = world.world_map()
    if camera.motion is not None:  # motion blur: the camera over the shutter
        kwargs["camera_motion"] = np.ascontiguousarray(np.asarray(camera.motion, np.float64)[:, :3].reshape(-1, 12))
    if "Mist" in passes:  # read by the Mist pass alone
        kwargs["mist_settings"] = world.mist()
    # Read by the AO pass and by Ambient Occlusion nodes whose Distance is 0 (Cycles' global
    # radius): a setting, which changes nothing else.
    kwargs["ao_distance"] = float(world.ao_distance)
    light = [name for name in LIGHT_PASSES if name in passes and name != "DiffCol"]
    if light:
        # All nine planes or none (the direct and indirect passes are divided by the colours'
        # sums); the passes asked for are views of it. DiffCol keeps its own buffer (the
        # integrator's colour there is the same).
        planes = np.zeros((len(LIGHT_PASSES), h, w, 3), np.float32)
        kwargs["light"] = planes
        for name in light:
            buffers[name] = planes[LIGHT_PASSES.index(name)]
    kwargs.update({PASS_KEYWORDS[name]: buf for name, buf in buffers.items() if name in PASS_KEYWORDS})
    if any(kind in buffers for kind in cryptomatte.KINDS):
        kwargs["cryptomatte"] = (*(buffers.get(kind) for kind in cryptomatte.KINDS), slots, *cryptomatte_ids)
    # The AOVs some material writes share one buffer, each a view of its channels; the others
    # stay zeros the core never sees (nothing to write: no cost).
    written = [(name, AOV_CHANNELS[kind]) for name, kind in aovs if name in aov_names]
    channels = sum(c for _, c in written)
    block = np.zeros((h, w, channels), np.float32) if written else None
    layout, first = np.full((len(aov_names), 2), -1, np.int32), 0
    for name, kind in aovs:
        c = AOV_CHANNELS[kind]
        if block is not None and name in aov_names:
            layout[list(aov_names).index(name)] = (first, c)
            buffers[name] = block[..., first] if c == 1 else block[..., first:first + c]
            first += c
        else:
            buffers[name] = np.zeros((h, w) if c == 1 else (h, w, c), np.float32)
    if block is not None:
        kwargs["aov"] = (block, layout, float(aov_alpha_threshold))
    return kwargs, buffers
