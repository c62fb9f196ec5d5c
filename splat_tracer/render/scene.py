"""Scenes of several objects for the core: meshes beside splat clouds, instances, materials,
lamps, a world."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, NamedTuple, Optional, Sequence

import numpy as np

from .. import _core
from ..util import matrices
from ..util.arrays import as_f32
from .camera import Camera, window_rect
from .method import Method
from .shading import LIGHT_FIELDS, MATERIAL_FIELDS, PASSES, Light, Material, RenderSettings, World
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


def native_scene(geometries: Sequence, rows: Sequence[InstanceRow], materials: Sequence, lights: Sequence,
                 threads: int = 0, programs: Optional[Sequence] = None) -> "_core.RenderScene":
    """The core's RenderScene over native geometries (SplatCloud._scene, Mesh._mesh), one
    row per instance, materials and lights as their pack() rows, and per material its node
    program (nodes.Program.native()) or None -- None for all: no programs. Nothing is checked
    here: RenderScene checks first, and the fuzz harness passes unchecked rows on purpose."""
    n = len(rows)
    col = lambda name, dtype, width=(): np.ascontiguousarray(
        np.array([getattr(r, name) for r in rows], dtype).reshape((n, *width)))
    return _core.RenderScene(
        list(geometries), col("geometry_index", np.int32), col("to_world", np.float32, (12,)),
        col("to_object", np.float32, (12,)), col("material_range", np.int32, (2,)), col("visibility", np.int32),
        col("holdout", np.uint8), col("pass_index", np.float32),
        np.ascontiguousarray(np.array(materials, np.float32).reshape(-1, len(MATERIAL_FIELDS))),
        np.ascontiguousarray(np.array(lights, np.float32).reshape(-1, len(LIGHT_FIELDS))),
        threads,
        # Only a scene with a catcher passes the column: one without is the core's as before.
        shadow_catcher=col("shadow_catcher", np.uint8) if any(r.shadow_catcher for r in rows) else None,
        # Only materials with node programs pay for them: without any, the core's path is as before.
        programs=programs if programs is not None and any(p is not None for p in programs) else None)


class Mesh:
    """A triangle mesh and its BVH: vertices (V,3), triangles (T,3) vertex indices, optional
    corner_normals (T,3,3) shading normals (smooth, flat and sharp edges as Blender's corner
    normals express them; None: flat), material_index (T,) slots and corner_uv (T,3,2), the
    UV map node programs read (None: 0). Immutable; share one Mesh between any number of
    instances."""

    def __init__(self, vertices, triangles, corner_normals=None, material_index=None, threads: int = 0,
                 corner_uv=None):
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
        self._mesh = _core.Mesh(v, t, n, m, threads, corner_uv=uv)

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
    see RenderScene.render)."""

    geometry: object
    matrix: tuple = ((1.0, 0.0, 0.0, 0.0), (0.0, 1.0, 0.0, 0.0), (0.0, 0.0, 1.0, 0.0), (0.0, 0.0, 0.0, 1.0))
    materials: tuple = (Material(),)
    visibility: frozenset = frozenset(RAY_VISIBILITY)
    holdout: bool = False
    pass_index: int = 0
    shadow_catcher: bool = False


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
                                    shadow_catcher=inst.shadow_catcher))
            materials.extend(mats)
        self.world = world
        self.lights = tuple(lights)
        # The shader AOVs the materials' AOV Output nodes write, numbered for the core.
        self.aov_names = tuple(sorted({name for m in materials if m.program is not None
                                       for name, _, _ in m.program.aovs}))
        keys = {name: i for i, name in enumerate(self.aov_names)}
        self._scene = native_scene(geometries, rows, [m.pack() for m in materials], [l.pack() for l in lights],
                                   threads, [m.program.native(keys) if m.program is not None else None
                                             for m in materials])
        self.geometry_count = len(geometries)
        self.shadow_catchers = sum(bool(r.shadow_catcher) for r in rows)  # instances that are shadow catchers

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
               packets: bool = True, aovs: Sequence[tuple] = (), aov_alpha_threshold: float = 0.5) -> FrameResult:
        """Renders `passes` (names from shading.PASSES; Combined always) of a window of the
        image (x0, y0, w, h; default all). progress(done, total) as for SplatCloud.render.
        packets: each sample's camera rays of 4x4 pixels found as one packet (False: ray by
        ray; the same image).

        With shadow-catcher instances, Combined is formed as Cycles forms it: the catcher is
        left out, and its shadow (its light with everything / its light with catchers only)
        becomes alpha on a transparent film (1 - the shadow's average, so that Alpha Over
        onto a photograph darkens it), or darkens the world behind it on an opaque film. With
        the "Shadow Catcher" pass asked for, Combined leaves the shadow out entirely (the
        catcher is a hole) and the pass holds it, to multiply the photograph by.

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
        unknown = set(passes) - set(PASSES)
        if unknown:
            raise ValueError(f"unknown passes {sorted(unknown)}; known: {sorted(PASSES)}")
        aovs = tuple((str(name), str(kind)) for name, kind in aovs)
        for name, kind in aovs:
            if kind not in AOV_CHANNELS or name in PASSES or name in ("Combined", *passes):
                raise ValueError(f"AOV {name!r}: a type in {sorted(AOV_CHANNELS)} and a name no other pass has")
        if len({name for name, _ in aovs}) != len(aovs):
            raise ValueError("AOV names must differ")
        kwargs, buffers = render_arguments(camera, width, height, settings, method, self.world, passes, window,
                                           aovs, self.aov_names, aov_alpha_threshold)
        done, counters = self._scene.render(**kwargs, threads=threads, progress=progress, tile_size=tile_size,
                                            packets=packets)
        return FrameResult(buffers, bool(done), counters)


# The core's keyword for each pass's buffer (Combined: "combined").
PASS_KEYWORDS = {"Combined": "combined", "Depth": "depth", "Normal": "normal", "DiffCol": "diffcol", "Emit": "emit",
                 "Shadow": "shadow", "IndexOB": "index", "Splat Count": "splat_count",
                 "Shadow Catcher": "shadow_catcher", "Position": "position", "IndexMA": "material_index",
                 "Mist": "mist", "Env": "environment"}


# A shader AOV's channels by its type (Blender's AOV.type): RGBA as Cycles registers a colour AOV.
AOV_CHANNELS = {"COLOR": 4, "VALUE": 1}


def render_arguments(camera: Camera, width: int, height: int, settings: RenderSettings, method: Method, world: World,
                     passes: Sequence[str] = ("Combined",), window: Optional[Sequence[int]] = None,
                     aovs: Sequence[tuple] = (), aov_names: Sequence[str] = (),
                     aov_alpha_threshold: float = 0.5) -> tuple[dict, dict]:
    """The keyword arguments of the core's RenderScene.render for a frame (all but threads,
    progress, tile_size and packets), and the zeroed buffers they write, by pass name (the
    AOVs' by theirs; aov_names: the scene's, RenderScene.aov_names). It
    checks only the window (before allocating): RenderScene.render checks its arguments
    first, and fuzz/fuzz_core.py passes unchecked ones on purpose, so that the fuzzed
    layout is the add-on's."""
    x0, y0, w, h = window_rect(window, width, height)
    buffers = {}
    for name in ("Combined", *passes):
        c = PASSES[name]
        buffers[name] = np.zeros((h, w) if c == 1 else (h, w, c), np.float32)
    local_from_camera, frustum, orthographic = camera.native()
    kwargs = dict(local_from_camera=local_from_camera, frustum=frustum, orthographic=orthographic, width=int(width),
                  height=int(height), window=(int(x0), int(y0), int(w), int(h)), settings=settings.pack(),
                  method=method, world=world.radiance(), film_transparent=bool(world.transparent),
                  lens=camera.lens.native() if camera.lens else None,
                  world_visibility=sum(RAY_VISIBILITY[k] for k in world.visibility))
    if "Mist" in passes:  # read by the Mist pass alone
        kwargs["mist_settings"] = world.mist()
    kwargs.update({PASS_KEYWORDS[name]: buf for name, buf in buffers.items()})
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
