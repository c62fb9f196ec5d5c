"""Blender scene -> core RenderScene and camera.

Walks `depsgraph.object_instances` (modifiers, collection and Geometry Nodes instancing,
world matrices, the view layer's collections all honoured) and turns:
- point clouds carrying splat normals into splat geometry (SplatCloud),
- meshes (and curves, text, surfaces, metaballs through their evaluated mesh) into Mesh,
- lamps into shading.Light, materials into shading.Material (export/shading.py),
into instances: each unique geometry is read and built once and shared by all its
instances, and kept across frames by the session's cache (session.py), keyed by content.

Everything is placed in one local frame whose float64 origin is the camera's position, so
that single-precision coordinates are finest where the viewer is (georeferenced scenes).
"""
from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field
from typing import Optional

import bpy
import numpy as np

from ...render import mesh_attributes, nodes, shading
from ...render.camera import Camera, Lens, Panorama
from ...render.scene import RAY_VISIBILITY, Instance, Mesh, RenderScene, transform_problem
from ...render.splats import MAX_COORDINATE, SplatCloud
from ...util import matrices, resources
from ...util.columns import finite_rows, nonzero_rows, rows_within
from .motion import instance_key
from ..cloud_object import ATTRIBUTE_TYPES, COLOUR, NORMAL, RADIUS, attribute_problem, mesh_positions
from . import nodes as export_nodes
from . import object_info
from . import shading as export_shading
from .nodes import COLOUR_ATTRIBUTE_NAMES

# Object types that evaluate to a mesh a ray tracer can render (Cycles renders them too).
_MESH_LIKE = {"MESH", "CURVE", "SURFACE", "FONT", "META", "CURVES"}
# Types that render nothing in any engine: skipped without a word.
_NOTHING_TO_RENDER = {"CAMERA", "EMPTY", "ARMATURE", "LATTICE", "SPEAKER", "LIGHT_PROBE", "LIGHTPROBE"}


@dataclass
class ExportedScene:
    render_scene: RenderScene
    origin: np.ndarray                 # float64 world position of the local frame's origin
    instances: int = 0
    clouds: int = 0                    # cloud instances
    closed_clouds: int = 0             # of those, the ones marked Closed Surface (the far phase acts on them)
    meshes: int = 0                    # mesh instances
    splats: int = 0                    # in the unique cloud geometry
    triangles: int = 0                 # in the unique mesh geometry
    lights: int = 0
    emission: bool = False             # some material emits light
    report: shading.Report = field(default_factory=shading.Report)
    # export/motion.py instance_key of each of render_scene's instances, in its order (the
    # Vector pass finds a pixel's instance's motion by it).
    keys: list = field(default_factory=list)


def _read(attribute, key: str, width: int, n: int) -> np.ndarray:
    buf = np.empty(n * width, np.float32)
    attribute.data.foreach_get(key, buf)
    return buf.reshape(n, width) if width > 1 else buf


def _digest(*parts) -> bytes:
    """Content key of a geometry: what it is made of, not where Blender keeps it (evaluated
    datablocks are new objects on every evaluation). SHA-1 for speed (about 1 GB/s), not
    for security: a collision would only mean a stale cache entry."""
    h = hashlib.sha1()
    for p in parts:
        if isinstance(p, np.ndarray):
            h.update(str((p.dtype.str, p.shape)).encode())
            h.update(np.ascontiguousarray(p).data)
        else:
            h.update(repr(p).encode())
    return h.digest()


def _source(obj: bpy.types.Object) -> bpy.types.Object:
    """The original object of an evaluated one: where the user's settings live."""
    return obj.original if obj.original is not None else obj


def _valid_points(name: str, pos, nrm, rad, col, alpha, radius_factor: float, report: shading.Report) -> np.ndarray:
    """Mask of the points that can be splats. The others (a vertex added in Edit Mode has a
    zero normal and radius; a NaN colour; a vertex or a radius, after the Radius Factor,
    beyond the core's limit) are left out and counted in the report, never failing the
    whole render."""
    limit = MAX_COORDINATE
    with np.errstate(invalid="ignore", over="ignore"):
        scaled = rad * np.float32(radius_factor)
        finite = finite_rows(pos)
        problems = [
            (~finite, "a position that is not finite"),
            (finite & ~rows_within(pos, limit), f"a position beyond the renderer's limit ({limit:.0e})"),
            (~(finite_rows(nrm) & nonzero_rows(nrm)), "a zero or non-finite normal"),
            (~(np.isfinite(rad) & (rad > 0)), "a radius that is not a positive number"),
            (np.isfinite(rad) & (rad > 0) & ~(scaled <= limit),
             f"a radius beyond the renderer's limit ({limit:.0e}) after the Radius Factor ({radius_factor:g})"),
        ]
        if col is not None:
            bad = ~finite_rows(col)
            if alpha is not None:
                bad |= ~np.isfinite(alpha)
            problems.append((bad, "a colour that is not finite"))
    ok = np.ones(len(pos), bool)
    for bad, what in problems:
        if bad.any():
            report.once(f"point cloud '{name}': {int(bad.sum())} points have {what} "
                        f"(first: point {int(np.flatnonzero(bad)[0])}); they are not rendered")
            ok &= ~bad
    return ok


def _cloud_arrays(obj, attrs, n: int, radius_factor: float, report: shading.Report):
    """(positions, normals, radii, colours or None, alphas or None, mask of the points kept) of a
    point cloud or of a vertex-only mesh carrying the splat attributes, invalid points left out. Alphas only when
    some point is not opaque. None (said in the report) when the splat attributes are missing
    or of another type: the object is left out, the frame renders."""
    rad_name = RADIUS if RADIUS in attrs else "radius"
    if rad_name not in attrs:
        report.once(f"point cloud '{obj.name}' has splat normals but no radius attribute ('{RADIUS}'); not rendered")
        return None
    problems = [attribute_problem(attrs, NORMAL), attribute_problem(attrs, rad_name, ATTRIBUTE_TYPES[RADIUS])]
    if any(problems):
        report.once(f"point cloud '{obj.name}': {'; '.join(p for p in problems if p)}; not rendered")
        return None
    pos = _read(attrs["position"], "vector", 3, n)
    nrm = _read(attrs[NORMAL], "vector", 3, n)
    rad_attr = attrs[rad_name]
    rad = _read(rad_attr, "value", 1, n)
    col = alpha = None
    if COLOUR in attrs:
        c = attrs[COLOUR]
        if c.data_type in ("FLOAT_COLOR", "BYTE_COLOR") and c.domain == "POINT":
            rgba = _read(c, "color", 4, n)
            col = np.ascontiguousarray(rgba[:, :3])
            if (rgba[:, 3] < 1.0).any():
                alpha = np.ascontiguousarray(np.clip(rgba[:, 3], 0.0, 1.0))
        else:
            report.once(f"point cloud '{obj.name}': attribute '{COLOUR}' is {c.data_type} on {c.domain}, "
                        "not a point colour; ignored")
    ok = _valid_points(obj.name, pos, nrm, rad, col, alpha, radius_factor, report)
    if not ok.all():
        keep = (lambda a: None if a is None else a[ok])
        pos, nrm, rad, col, alpha = pos[ok], nrm[ok], rad[ok], keep(col), keep(alpha)
    return pos, nrm, rad, col, alpha, ok


# How a point attribute's values are read (foreach_get key, floats per point): the numeric
# types a Blender attribute can have; a 2-D vector is padded with 0, a colour drops its alpha.
_ATTRIBUTE_READS = {"FLOAT": ("value", 1), "INT": ("value", 1), "INT8": ("value", 1), "BOOLEAN": ("value", 1),
                    "FLOAT_VECTOR": ("vector", 3), "FLOAT2": ("vector", 2), "INT32_2D": ("value", 2),
                    "FLOAT_COLOR": ("color", 4), "BYTE_COLOR": ("color", 4)}


def _point_attributes(obj, attrs, n, layout: tuple, report: shading.Report, domains=("POINT",)) -> dict:
    """{name: (n, 3) float32} of the attributes `layout` names that the geometry has on one of
    `domains` (n: that domain's size; with several, n is {domain: size} and the keys are
    (domain, name)), a float filling all three components (nodes.py Compiler._attribute reads
    three). A name it lacks is left out (read as 0, as Cycles reads a missing attribute); one
    on another domain or of a type without numbers is said and left out too."""
    values = {}
    kind = "point cloud" if domains == ("POINT",) else "mesh"
    for name, _ in layout:
        transparency = name.startswith(nodes.TRANSPARENCY_OF)
        a = attrs.get(name[len(nodes.TRANSPARENCY_OF):] if transparency else name)
        if a is None or (transparency and a.data_type not in ("FLOAT_COLOR", "BYTE_COLOR")):
            continue  # the Color Attribute's Alpha of something not a colour: as a missing one
        read = _ATTRIBUTE_READS.get(a.data_type)
        if read is None or a.domain not in domains:
            report.once(f"{kind} '{obj.name}': attribute '{name}' is {a.data_type} on {a.domain}, not a "
                        f"number on its {' or '.join(d.lower() for d in domains)}s; its Attribute nodes read 0")
            continue
        size = n[a.domain] if isinstance(n, dict) else n
        v = _attribute_values(a, read, size, alpha=transparency)
        values[(a.domain, name) if isinstance(n, dict) else name] = 1.0 - v if transparency else v
    return values


def _attribute_values(a, read, n: int, alpha: bool = False) -> np.ndarray:
    """An attribute's values as (n, 3) float32 (a float in every component, NaN as 0); with
    `alpha`, a colour's alpha in every component."""
    key, width = read
    buf = np.empty(n * width, np.int32 if a.data_type == "INT32_2D" else np.float32)
    a.data.foreach_get(key, buf)
    v = buf.astype(np.float32).reshape(n, width)
    if alpha:
        v, width = v[:, 3:4], 1
    out = np.zeros((n, 3), np.float32)
    if width == 1:
        out[:] = v
    else:
        out[:, :min(width, 3)] = v[:, :3]
    return np.nan_to_num(out, nan=0.0, posinf=0.0, neginf=0.0)


def _corner_attributes(obj, mesh, layout: tuple, report: shading.Report):
    """(T, 3, k) float32: the attributes `layout` names at each loop triangle's corners, from
    the vertex, face or face-corner domain (Blender's; an edge's is said and reads 0), laid
    out as nodes.attribute_columns does; None for no layout."""
    nt = len(mesh.loop_triangles)
    if not layout or nt == 0:  # nothing read, or nothing to carry it (the mesh is left out)
        return None
    tris, loops, faces = (np.empty(nt * 3, np.int32), np.empty(nt * 3, np.int32), np.empty(nt, np.int32))
    mesh.loop_triangles.foreach_get("vertices", tris)
    mesh.loop_triangles.foreach_get("loops", loops)
    mesh.loop_triangles.foreach_get("polygon_index", faces)
    sizes = {"POINT": len(mesh.vertices), "CORNER": len(mesh.loops), "FACE": len(mesh.polygons)}
    read = _point_attributes(obj, mesh.attributes, sizes, layout, report, domains=tuple(sizes))
    index = {"POINT": tris, "CORNER": loops, "FACE": np.repeat(faces, 3)}
    values = {name: v[index[domain]] for (domain, name), v in read.items()}
    names = {name for name, _ in layout}
    if nodes.POINTINESS in names:  # per vertex, as Cycles derives it at export
        normals = np.empty(len(mesh.vertices) * 3, np.float32)
        mesh.vertex_normals.foreach_get("vector", normals)
        positions, edges = mesh_positions(mesh), _edges(mesh)
        per_vertex = _derived(("pointiness", positions, normals, edges),
                              lambda: mesh_attributes.pointiness(positions, normals, edges))
        values[nodes.POINTINESS] = per_vertex[tris]
    for name in names:  # a named UV map's tangent, per triangle (object space)
        layer = mesh.uv_layers.get(name[len(nodes.TANGENT_OF):]) if name.startswith(nodes.TANGENT_OF) else None
        if layer is not None:
            flat = np.empty(len(mesh.loops) * 2, np.float32)
            layer.uv.foreach_get("vector", flat)
            per_triangle = mesh_attributes.uv_tangents(mesh_positions(mesh)[tris].reshape(nt, 3, 3),
                                                       flat.reshape(-1, 2)[loops].reshape(nt, 3, 2))
            values[name] = np.repeat(per_triangle, 3, axis=0)
    if nodes.RANDOM_PER_ISLAND in names:  # per triangle, from its first corner's vertex
        edges, first = _edges(mesh), tris[::3]
        per_triangle = _derived(("islands", len(mesh.vertices), edges, first),
                                lambda: mesh_attributes.random_per_island(len(mesh.vertices), edges, first))
        values[nodes.RANDOM_PER_ISLAND] = np.repeat(per_triangle, 3)
    return nodes.attribute_columns(layout, values, nt * 3).reshape(nt, 3, sum(w for _, w in layout))


# Pointiness and islands of the last few meshes, by content: about a second per 100 000
# vertices, not to be paid again on every frame of an unchanged mesh.
_DERIVED: dict = {}


def _derived(key: tuple, make):
    digest = _digest(*key)
    if digest not in _DERIVED:
        while len(_DERIVED) >= 8:
            _DERIVED.pop(next(iter(list(_DERIVED))), None)  # (another thread may take it first)
        _DERIVED[digest] = make()
    return _DERIVED[digest]


def _edges(mesh) -> np.ndarray:
    """(E, 2) vertex indices of a mesh's edges, in Blender's stored order."""
    edges = np.empty(len(mesh.edges) * 2, np.int32)
    mesh.edges.foreach_get("vertices", edges)
    return edges.reshape(-1, 2)


def _mesh_arrays(mesh: bpy.types.Mesh):
    """(vertices, triangles, corner normals (T,3,3), material indices, corner UVs (T,3,2) of
    the UV map Cycles renders with (the active render one), or None without one) of an
    evaluated mesh."""
    mesh.calc_loop_triangles()
    nv, nt = len(mesh.vertices), len(mesh.loop_triangles)
    verts = mesh_positions(mesh).ravel()
    tris = np.empty(nt * 3, np.int32)
    mesh.loop_triangles.foreach_get("vertices", tris)
    loops = np.empty(nt * 3, np.int32)
    mesh.loop_triangles.foreach_get("loops", loops)
    corner = np.empty(len(mesh.loops) * 3, np.float32)
    mesh.corner_normals.foreach_get("vector", corner)  # smooth, flat and sharp edges resolved
    normals = corner.reshape(-1, 3)[loops].reshape(nt, 3, 3)
    mats = np.empty(nt, np.int32)
    mesh.loop_triangles.foreach_get("material_index", mats)
    layer = next((uv for uv in mesh.uv_layers if uv.active_render), None)
    uv = None
    if layer is not None and len(mesh.loops):
        flat = np.empty(len(mesh.loops) * 2, np.float32)
        layer.uv.foreach_get("vector", flat)
        uv = np.nan_to_num(flat.reshape(-1, 2)[loops].reshape(nt, 3, 2), nan=0.0, posinf=0.0, neginf=0.0)
    return verts.reshape(nv, 3), tris.reshape(nt, 3), normals, mats, uv


def _materials(slots: list, cache: dict, report: shading.Report, aovs: dict, object_space=None) -> tuple:
    """Blender materials (an object's slots, see _slot_materials) as shading.Material (one
    default for none). aovs: the view layer's (export_shading.view_layer_aovs);
    object_space: _object_space's."""
    out = []
    for m in slots or [None]:
        key = m.name_full if m is not None else None
        if key not in cache:
            cache[key] = export_shading.material_of(m, report, aovs, object_space)
        out.append(cache[key])
    return tuple(out)


def _slot_materials(obj) -> list:
    """The Blender materials of the object's slots (None for an empty slot)."""
    if obj.material_slots:
        blender_mats = [slot.material for slot in obj.material_slots]
    else:
        blender_mats = list(getattr(obj.data, "materials", ()) or ())
    # Geometry Nodes' Mesh to Points drops the mesh's materials: a splat cloud's evaluated
    # slots are empty, and the user's material is on the original object's slot.
    original = _source(obj).material_slots
    blender_mats = [m if m is not None or i >= len(original) else original[i].material
                    for i, m in enumerate(blender_mats)]
    return blender_mats


class _Frame:
    """The state of one export: the geometry memo and the report."""

    def __init__(self, geometry_cache, radius_factor: float, threads: int, report: shading.Report):
        self.cache = geometry_cache
        self.radius_factor = radius_factor
        self.threads = threads
        self.report = report
        self.by_pointer = {}   # evaluated data pointer -> (geometry, kind) within this frame
        self.closed = set()    # id() of the closed clouds' geometry
        self.materials = {}
        self.splats = self.triangles = 0
        self.want_uv = False   # the UV pass is on (meshes always carry their UV map: node programs read it)
        self.attribute_layout = ()  # the point attributes the materials read (nodes.attribute_layout)
        self.object_space = None  # _object_space: for node trees naming another object

    def cloud(self, obj, attrs, n: int):
        """The splat geometry of a cloud object (built once per content)."""
        closed = bool(getattr(_source(obj), "splat_tracer", None) and _source(obj).splat_tracer.closed)
        arrays = _cloud_arrays(obj, attrs, n, self.radius_factor, self.report)
        if arrays is None:
            return None
        pos, nrm, rad, col, alpha, ok = arrays
        if len(pos) == 0:
            self.report.once(f"point cloud '{obj.name}': none of its {n:,} points can be rendered; not rendered")
            return None
        layout = self.attribute_layout
        # The usual colour names are the points' own colour on a cloud (a Color Attribute
        # node naming one reads it as POINT_COLOUR), not carried again.
        values = {k: v[ok] for k, v in _point_attributes(obj, attrs, n, layout, self.report).items()
                  if k.removeprefix(nodes.TRANSPARENCY_OF) not in COLOUR_ATTRIBUTE_NAMES}
        columns = nodes.attribute_columns(layout, values, len(pos))
        key = ("cloud", _digest(pos, nrm, rad, col, alpha, closed, self.radius_factor, layout, columns))
        geometry = self._cached(key, f"point cloud '{obj.name}' ({len(pos):,} splats)",
                                len(pos) * resources.BYTES_PER_SPLAT,
                                lambda: SplatCloud(pos, nrm, rad * self.radius_factor, col, closed=closed,
                                                   threads=self.threads, alphas=alpha, attributes=columns,
                                                   attribute_layout=layout))
        self.splats += self._first_use(key, geometry)
        if closed:
            self.closed.add(id(geometry))
        return geometry

    def _cached(self, key, what: str, needed_bytes: int, make):
        """The geometry under `key`, built by make() when the cache lacks it -- after checking
        that the build fits in memory (resources.check names `what` when it does not)."""
        def build():
            resources.check(what, needed_bytes)
            return make()

        return self.cache.get(key, build)[0]

    def _first_use(self, key, geometry) -> int:
        """The geometry's size the first time this frame uses it (instances share it), else 0."""
        if key in self.cache.counted:
            return 0
        self.cache.counted.add(key)
        return len(geometry)

    def mesh(self, obj):
        mesh = obj.data if obj.type == "MESH" else None
        temporary = False
        if mesh is None:
            try:
                mesh = obj.to_mesh()
                temporary = True
            except RuntimeError:
                mesh = None
        if mesh is None:
            return None
        try:
            verts, tris, normals, mats, uv = _mesh_arrays(mesh)
            attrs = _corner_attributes(obj, mesh, self.attribute_layout, self.report)
        finally:
            if temporary:
                obj.to_mesh_clear()
        verts, tris, normals, mats, uv, attrs = self._usable_triangles(obj.name, verts, tris, normals, mats, uv, attrs)
        if len(tris) == 0:
            return None
        layout = self.attribute_layout if attrs is not None else ()
        key = ("mesh", _digest(verts, tris, normals, mats, *(() if uv is None else (uv,)),
                               *(() if attrs is None else (layout, attrs))))
        geometry = self._cached(key, f"mesh '{obj.name}' ({len(tris):,} triangles)",
                                len(tris) * resources.BYTES_PER_TRIANGLE,
                                lambda: Mesh(verts, tris, normals, mats, threads=self.threads, corner_uv=uv,
                                             corner_attributes=attrs, attribute_layout=layout))
        self.triangles += self._first_use(key, geometry)
        return geometry

    def _usable_triangles(self, name: str, verts, tris, normals, mats, uv=None, attrs=None):
        """The mesh without the triangles that touch a vertex the core cannot hold (not
        finite, or beyond its limit: a NaN from a driver or a modifier), which are counted
        in the report; the rest of the mesh renders. Those vertices are set to 0, as the
        core checks every vertex, used or not."""
        bad = ~rows_within(verts, MAX_COORDINATE)
        if not bad.any():
            return verts, tris, normals, mats, uv, attrs
        touching = bad[tris].any(axis=1)
        self.report.once(f"mesh '{name}': {int(bad.sum())} vertices are not finite or beyond the renderer's limit "
                         f"({MAX_COORDINATE:.0e}) (first: vertex {int(np.flatnonzero(bad)[0])}); the "
                         f"{int(touching.sum())} triangles using them are not rendered")
        keep = ~touching
        verts = verts.copy()
        verts[bad] = 0.0
        return (verts, tris[keep], normals[keep], mats[keep], None if uv is None else uv[keep],
                None if attrs is None else attrs[keep])

    def geometry(self, obj):
        """(geometry or None, 'cloud' | 'mesh'), memoised by the evaluated datablock."""
        data = obj.data
        pointer = data.as_pointer() if data is not None else None
        if pointer is not None and pointer in self.by_pointer:
            return self.by_pointer[pointer]
        result = (None, None)
        if obj.type == "POINTCLOUD":
            n = len(data.points)
            if n and NORMAL in data.attributes:
                result = (self.cloud(obj, data.attributes, n), "cloud")
            elif n:
                self.report.once(f"point cloud '{obj.name}' has no splat normals ('{NORMAL}'); not rendered")
        elif obj.type == "MESH" and NORMAL in data.attributes and len(data.polygons) == 0 and len(data.vertices):
            # A splat cloud whose Mesh-to-Points modifier (or its node group) was removed:
            # still a cloud, rendered from its vertices, and the user is told.
            self.report.once(f"object '{obj.name}' carries splats but no longer evaluates to a point cloud (its "
                             "'Splat Points' modifier is missing or changed); rendering its vertices as splats")
            result = (self.cloud(obj, data.attributes, len(data.vertices)), "cloud")
        elif obj.type in _MESH_LIKE:
            if obj.type == "MESH" and NORMAL in data.attributes and len(data.vertices):
                # A splat cloud given faces (Edit Mode) without its modifier: Cycles renders
                # the faces, and so does this engine; the splats they leave out are said.
                self.report.once(f"object '{obj.name}' carries splats but evaluates to a mesh with "
                                 f"{len(data.polygons):,} faces (its 'Splat Points' modifier is missing or changed): "
                                 f"rendered as that mesh; the splats of its {len(data.vertices):,} vertices are "
                                 "not rendered")
            result = (self.mesh(obj), "mesh")
        if pointer is not None:
            self.by_pointer[pointer] = result
        return result


def export_scene(depsgraph: bpy.types.Depsgraph, geometry_cache, origin, radius_factor: float = 1.0,
                 threads: int = 0, report: shading.Report | None = None, motion=None) -> ExportedScene:
    """The depsgraph's view layer as a RenderScene in the local frame at `origin`. motion:
    the transforms over the shutter (export/motion.py's Motion), or None (no motion blur)."""
    report = report if report is not None else shading.Report()
    origin = np.asarray(origin, np.float64)
    export_nodes.export_at(depsgraph.scene.frame_current)  # image sequences show this frame's image
    frame = _Frame(geometry_cache, radius_factor, threads, report)
    view_layer = depsgraph.view_layer
    aovs = export_shading.view_layer_aovs(view_layer)
    frame.want_uv = bool(getattr(view_layer, "use_pass_uv", False))
    instances, lights, keys = [], [], []
    counts = {"cloud": 0, "mesh": 0, "closed": 0}
    frame.object_space = _object_space(depsgraph, origin)
    frame.attribute_layout = _attribute_layout(depsgraph, frame, report, aovs)
    for inst in depsgraph.object_instances:
        obj = inst.object
        matrix = np.array(inst.matrix_world, dtype=np.float64)
        matrix[:3, 3] -= origin
        if obj.type == "LIGHT":
            light = export_shading.light_of(obj, matrix, report)
            if light is not None:
                lights.append(light)
            continue
        if obj.type in _NOTHING_TO_RENDER:
            continue
        if obj.type not in _MESH_LIKE and obj.type != "POINTCLOUD":
            report.once(f"object '{obj.name}' ({obj.type.lower()}) is not rendered: Splat Tracer renders point "
                        "clouds, meshes and lamps")
            continue
        geometry, kind = frame.geometry(obj)
        if geometry is None:
            continue
        problem = transform_problem(matrix)
        if problem is not None:
            # An object scaled to 0 (a step of an animation, a flattened plane) is left out,
            # and the rest of the frame renders.
            report.once(f"object '{obj.name}': {problem}; not rendered")
            continue
        parent = inst.parent if inst.is_instance else None
        vis = export_shading.object_visibility(obj, view_layer, parent)
        slots = _slot_materials(obj)
        materials = _materials(slots, frame.materials, report, aovs, frame.object_space)
        if kind == "cloud" and all(m is None for m in slots) and geometry_has_colours(obj):
            # A cloud without any material (imported before clouds got one): its own colours.
            materials = (shading.Material(use_point_colour=True),)
        if kind == "cloud" and frame.want_uv:
            report.once(f"view layer '{view_layer.name}': the UV pass is 0 on point clouds (a scan has no UV map; "
                        "meshes show theirs)")
        if kind == "cloud" and materials[0].emission_sides:
            report.once(f"point cloud '{obj.name}' emits light: its emission lights the scene only where rays "
                        "happen to meet it (noisier than Cycles); an emissive cloud is not sampled as a light, "
                        "an emissive mesh is")
        steps = motion.of(inst) if motion is not None else None
        if steps is not None:
            steps = steps.copy()
            steps[:, :3, 3] -= origin
            problem = next((p for p in map(transform_problem, steps) if p is not None), None)
            if problem is not None:
                report.once(f"object '{obj.name}': within the shutter {problem}; rendered without motion blur")
                steps = None
            elif kind == "mesh" and any(any(c > 0 for c in m.emission) for m in materials):
                report.once(f"object '{obj.name}' emits light and moves: its surface is blurred, but the light it "
                            "casts comes from where it is at the frame's time")
        keys.append(instance_key(inst))
        instances.append(Instance(
            geometry, matrix, materials,
            visibility=frozenset(k for k in RAY_VISIBILITY if vis[k]), holdout=vis["holdout"],
            pass_index=_source(obj).pass_index, shadow_catcher=vis["shadow_catcher"], motion=steps, name=obj.name,
            asset=asset_name(obj), light_group=getattr(_source(obj), "lightgroup", ""),
            **_object_values(inst, obj, parent, materials, depsgraph)))
        counts[kind] += 1
        counts["closed"] += id(geometry) in frame.closed
    render_scene = RenderScene(instances, lights, export_shading.world_of(depsgraph.scene, report),
                               threads=threads)
    left_out = render_scene.object_attribute_layout[nodes.MAX_OBJECT_ATTRIBUTES:]
    if left_out:
        report.once(f"the materials read more than {nodes.MAX_OBJECT_ATTRIBUTES} object, instancer or view-layer "
                    f"attributes; these read 0: {', '.join(name for _, name in left_out)}")
    emission = any(any(c > 0 for c in m.emission) for m in frame.materials.values())
    return ExportedScene(render_scene, origin, len(instances), counts["cloud"], counts["closed"], counts["mesh"],
                         frame.splats, frame.triangles, len(lights), emission, report, keys)


def _object_values(inst, obj, parent, materials, depsgraph) -> dict:
    """Instance's object_info and object_attributes: what the node programs of its materials
    read of its object (Object Info; Attribute nodes of type object, instancer or view layer:
    export/object_info.py), looked up while the depsgraph instance is valid (its iterator
    reuses it); nothing when no program reads any."""
    programs = [m.program for m in materials if m.program is not None]
    if not any(p.reads_object() for p in programs):
        return {}
    info = object_info.object_info(inst, obj, np.array(inst.matrix_world, np.float64), _source(obj).pass_index)
    keys = nodes.object_attribute_layout(programs)
    values = tuple((key, object_info.attribute(*key, obj, parent, depsgraph.view_layer, depsgraph.scene))
                   for key in keys)
    return {"object_info": info, "object_attributes": values}


def _object_space(depsgraph, origin):
    """obj -> the 4x4 map from the local frame at `origin` into the object's space, the
    object as this depsgraph evaluates it (at the frame's time); NaN where its transform
    cannot be inverted (scaled to 0). None -> the map into world space (nodes.Compiler)."""

    def object_space(obj):
        if obj is None:
            to_world = np.eye(4)
            to_world[:3, 3] = origin
            return to_world
        world = np.array(obj.evaluated_get(depsgraph).matrix_world, np.float64)
        world[:3, 3] -= origin
        try:
            return np.linalg.inv(world)
        except np.linalg.LinAlgError:
            return np.full((4, 4), np.nan)

    # The scene's camera as evaluated (Vector Transform's camera space), None without one.
    camera = depsgraph.scene.camera
    object_space.camera = camera.evaluated_get(depsgraph) if camera is not None else None
    return object_space


def _attribute_layout(depsgraph, frame: _Frame, report: shading.Report, aovs: dict) -> tuple:
    """The attributes the materials of the scene's clouds and meshes read
    (nodes.attribute_layout), which every cloud and mesh then carries: only those (none
    without an Attribute node). The materials are compiled here once (frame.materials keeps
    them for the instances)."""
    programs, seen = [], set()
    for inst in depsgraph.object_instances:
        obj = inst.object
        # Instances of one geometry share its slots (an object's own geometry and the point
        # cloud its Geometry Nodes make are two, with slots of their own).
        key = (obj.name, obj.type, obj.data.as_pointer() if obj.data is not None else 0)
        if (obj.type == "POINTCLOUD" or obj.type in _MESH_LIKE) and key not in seen:
            seen.add(key)
            programs += [m.program for m in _materials(_slot_materials(obj), frame.materials, report, aovs,
                                                       frame.object_space)]
    layout = nodes.attribute_layout(programs)
    left_out = sorted(set(nodes.attributes_read(programs)) - {name for name, _ in layout})
    if left_out:
        report.once(f"the materials read more point attributes than the renderer carries ({len(layout)} of them, "
                    f"by name); {', '.join(nodes.attribute_label(n) for n in left_out)} "
                    f"{'reads' if len(left_out) == 1 else 'read'} 0")
    return layout


def asset_name(obj) -> str:
    """Cryptomatte's asset of an object, as Cycles names it: its top-level parent's name (its
    own without a parent). An instance is named by the object it instances (Cycles' object
    name), whose parents are followed, not the instancer's."""
    while obj.parent is not None:
        obj = obj.parent
    return obj.name


def geometry_has_colours(obj) -> bool:
    data = obj.data
    return data is not None and hasattr(data, "attributes") and COLOUR in data.attributes


def camera_frustum(data, width: int, height: int, aspect_x: float = 1.0, aspect_y: float = 1.0,
                   shift_x: Optional[float] = None) -> tuple:
    """(left, right, bottom, top) of a Blender camera's image (render.camera.Camera's
    frustum) at width x height pixels of pixel aspect aspect_x : aspect_y, in double, as
    Blender's view plane (BKE_camera_params_compute_viewplane): the sensor fit chooses the
    side the sensor (and the orthographic scale) spans, the shift moves the image by that
    side's length, and the other side follows the image's aspect. shift_x: a stereo eye's
    horizontal shift (Blender's, with the off-axis eye's shift added) instead of the camera's."""
    size_x, size_y = width * aspect_x, height * aspect_y
    fit = data.sensor_fit if data.sensor_fit != "AUTO" else ("HORIZONTAL" if size_x >= size_y else "VERTICAL")
    # The sensor side is chosen by the camera's own setting (AUTO uses its width), even when
    # AUTO fits it to the image's height.
    sensor = data.sensor_height if data.sensor_fit == "VERTICAL" else data.sensor_width
    span = data.ortho_scale if data.type == "ORTHO" else sensor / data.lens  # at unit distance
    y_scale = aspect_y / aspect_x  # a pixel's height in units of its width
    side = width if fit == "HORIZONTAL" else y_scale * height  # the fitted side, in pixel widths
    pixel = span / side
    half_w, half_h = 0.5 * width * pixel, 0.5 * y_scale * height * pixel
    dx, dy = (data.shift_x if shift_x is None else shift_x) * span, data.shift_y * span
    return (dx - half_w, dx + half_w, dy - half_h, dy + half_h)


@dataclass(frozen=True)
class View:
    """One view of a stereo or multi-view render, as Blender's RenderEngine gives it after
    active_view_set(name): the view's camera object (Multi-View: the camera with the view's
    suffix), its model matrix (camera_model_matrix: Stereo 3D moves and, for Toe-in, turns
    the camera by the eye's half of the interocular distance) and its horizontal lens shift
    (camera_shift_x: Off-Axis adds the eye's shift towards the convergence plane)."""
    name: str
    camera: object
    matrix: object  # mathutils.Matrix, 4x4
    shift_x: float


def export_camera(depsgraph: bpy.types.Depsgraph, width: int, height: int, origin,
                  view: Optional[View] = None, motion=None) -> Camera:
    """The scene camera (or a stereo/multi-view render's `view`) from its parameters, in
    double (not from calc_matrix_camera's float32 projection, which loses clipping ranges of
    about 1e8 and more). motion: the transforms over the shutter (export/motion.py's
    Motion), or None; a view's camera moves as its camera object does, the eye keeping its
    place relative to it (camera_model_matrix's offset at the frame's time)."""
    scene = depsgraph.scene
    if view is not None:
        cam = view.camera.evaluated_get(depsgraph)
    elif scene.camera is None:
        raise RuntimeError("the scene has no active camera")
    else:
        cam = scene.camera.evaluated_get(depsgraph)
    if cam.type != "CAMERA":
        raise RuntimeError(f"the active camera '{cam.name}' is not a camera object")
    data = cam.data
    r = scene.render
    panorama = None
    if data.type == "PANO":
        frustum, panorama = camera_panorama(cam, width, height, r.pixel_aspect_x, r.pixel_aspect_y,
                                            None if view is None else view.shift_x)
    if not data.clip_start < data.clip_end:
        raise RuntimeError(f"camera '{cam.name}': Clip Start ({data.clip_start:g}) must be less than Clip End "
                           f"({data.clip_end:g})")
    rigid = (cam.matrix_world if view is None else view.matrix).normalized()
    # A camera scaled to zero on an axis (itself, by a parent or by an animation) has no
    # view direction or no image along it: normalized() leaves that axis zero. (mathutils'
    # determinant, not numpy's: see util/matrices.py on BLAS threads.)
    if not abs(rigid.to_3x3().determinant()) > 1e-6:
        scale = tuple(round(v, 6) for v in cam.matrix_world.to_scale())
        raise RuntimeError(f"camera '{cam.name}' is scaled to zero (world scale {scale}): it has no view "
                           "direction or image there; give it a non-zero scale on every axis")
    if panorama is None:
        frustum = camera_frustum(data, width, height, r.pixel_aspect_x, r.pixel_aspect_y,
                                 None if view is None else view.shift_x)
    steps = motion.camera_of(cam.original) if motion is not None else None
    if steps is not None and view is not None:
        # The eye's offset from its camera object (Stereo 3D's interocular shift and Toe-in
        # turn) is fixed in the camera's frame: each step is the camera's there, times it.
        # In double, without BLAS (util/matrices.py; einsum unoptimised is numpy's own loop).
        offset = np.einsum("ij,jk->ik", matrices.inverse(np.array(cam.matrix_world.normalized(), np.float64)),
                           np.array(rigid, np.float64))
        steps = np.einsum("sij,jk->sik", steps, offset)
    return Camera.from_frustum(np.array(rigid, dtype=np.float64), frustum, (data.clip_start, data.clip_end),
                               data.type == "ORTHO", origin, camera_lens(cam, depsgraph), panorama, steps)


def camera_panorama(cam, width: int, height: int, aspect_x: float = 1.0, aspect_y: float = 1.0,
                    shift_x: Optional[float] = None) -> tuple:
    """A panoramic camera's (u, v) window and render.camera.Panorama, read as Cycles'
    blender/camera.cpp reads them: the window is the unit square moved by the lens shift,
    the equisolid fisheye's sensor is fitted to the image (Panorama.equisolid_sensor). The
    panorama types Splat Tracer does not build are refused, naming the camera and type."""
    data = cam.data
    kind = data.panorama_type
    if kind == "EQUIRECTANGULAR":
        panorama = Panorama(kind, (data.longitude_min, data.longitude_max, data.latitude_min, data.latitude_max))
    elif kind == "FISHEYE_EQUIDISTANT":
        panorama = Panorama(kind, (data.fisheye_fov,))
    elif kind == "FISHEYE_EQUISOLID":
        sensor = Panorama.equisolid_sensor(data.sensor_width, data.sensor_height, data.sensor_fit,
                                           width * aspect_x, height * aspect_y)
        panorama = Panorama(kind, (data.fisheye_lens, data.fisheye_fov, *sensor))
    elif kind == "MIRRORBALL":
        panorama = Panorama(kind)
    else:
        name = kind.replace("_", " ").title()
        raise RuntimeError(f"camera '{cam.name}': the panorama type '{name}' is not rendered by Splat Tracer; use an "
                           "equirectangular, fisheye (equidistant or equisolid) or mirror ball panorama, or a "
                           "perspective or orthographic camera")
    sx = data.shift_x if shift_x is None else shift_x
    return (sx, 1.0 + sx, data.shift_y, 1.0 + data.shift_y), panorama


def camera_lens(cam, depsgraph: bpy.types.Depsgraph) -> Optional[Lens]:
    """The camera's Depth of Field (camera.data.dof) as Cycles reads it, or None when it is
    off (a pinhole): Lens.from_fstop's aperture, Blender's blades, rotation and ratio, and
    the focus distance or the focus object's (or bone's) distance along the view axis."""
    data = cam.data
    dof = data.dof
    if not dof.use_dof:
        return None
    return Lens.from_fstop(dof.aperture_fstop, data.lens, focus_distance(cam, depsgraph), dof.aperture_blades,
                           dof.aperture_rotation, dof.aperture_ratio, orthographic=data.type == "ORTHO")


def focus_distance(cam, depsgraph: bpy.types.Depsgraph) -> float:
    """Cycles' blender_camera_focal_distance: the Focus Distance, or with a Focus Object the
    distance from the camera to its origin (to its bone's head with a Focus Bone) along
    the camera's view axis. In double from Blender's matrices (a scene far from the world
    origin keeps its precision), without numpy's BLAS (util/matrices.py)."""
    dof = cam.data.dof
    target = dof.focus_object
    if target is None:
        return float(dof.focus_distance)
    target = target.evaluated_get(depsgraph)
    point = target.matrix_world.translation
    if target.pose is not None and dof.focus_subtarget:
        bone = target.pose.bones.get(dof.focus_subtarget)
        if bone is not None:
            point = target.matrix_world @ bone.head  # the bone's matrix's translation: its head
    m = cam.matrix_world
    axis = [float(m[r][2]) for r in range(3)]
    length = math.sqrt(sum(a * a for a in axis))
    offset = [float(m[r][3]) - float(point[r]) for r in range(3)]
    return abs(sum(a * o for a, o in zip(axis, offset))) / length if length > 0 else float(dof.focus_distance)


def camera_origin(depsgraph: bpy.types.Depsgraph) -> np.ndarray:
    """The local frame's origin: the camera position rounded to float32 (so that it can be
    stored and subtracted exactly), or the world origin without a camera."""
    cam = depsgraph.scene.camera
    if cam is None:
        return np.zeros(3)
    p = np.array(cam.evaluated_get(depsgraph).matrix_world.translation, dtype=np.float64)
    return p.astype(np.float32).astype(np.float64)
