"""File > Import > Splat Point Cloud, and drag-and-drop of point-cloud files into the 3D
viewport (PLY incl. Gaussian-splatting PLY, LAS/LAZ, E57, PCD, XYZ/PTS/TXT/CSV: the reader is
chosen by the file's content, splat_tracer/pointcloud/readers/); and Estimate Splat
Normals, which (re)estimates the normals and radii of existing cloud objects.

Both do their work (splat_tracer/pointcloud/importer.py, normals.py: no Blender data)
before they touch Blender's data, in one step at the end; an error or a cancel before then
leaves nothing, and one during it removes what it made. Run from the interface (the file
browser, drag-and-drop, the button), the work runs on a worker thread while a modal timer shows its
progress in the status bar and Esc cancels it. Run from a script (`bpy.ops...(filepath=...)`)
it runs synchronously: a progress bar on the cursor, or lines on the terminal in background
mode (`blender -b`).
"""
from __future__ import annotations

import os
import time

import bpy
from bpy_extras.io_utils import ImportHelper, axis_conversion, orientation_helper

from ..splat_tracer.blender.cloud_object import NORMAL, RADIUS, attribute_problem, create_cloud_object, mesh_positions
from ..splat_tracer.pointcloud import importer, normals, prepare, readers, spacing
from ..splat_tracer.pointcloud.cloud import CloudFileError
from ..splat_tracer.pointcloud.readers import ply
from ..splat_tracer.util.progress import Cancelled, Job, Steps, TerminalProgress, scaled

SCANNER = "scanner_position"  # point attribute: the scanner that saw the point (object-local)
# custom property: the file's origin in the object's own coordinates (where a single view's
# sensor sits), for Estimate Splat Normals' Automatic and File Origin
VIEWPOINT = "splat_tracer_file_origin"
_ORIENTATION_ITEMS = [
    ("AUTO", "Automatic", "Towards the scanner when the file knows it (E57, a PCD's VIEWPOINT); else by the cloud's shape, whatever "
                          "the format: a depth or stereo frame towards the file's origin, a terrain upward, "
                          "objects outward by visibility, else along the neighbour graph"),
    ("PROPAGATE", "Neighbour Graph", "Consistent along a minimum spanning tree of the neighbours, outward where "
                                     "the surface encloses a volume"),
    ("UP", "Upward", "Towards +Z (aerial scans); walls take their neighbours' side"),
    ("SCANNER", "Scanner", "Towards the scanner position of each point (E57 files, a PCD's VIEWPOINT); else Neighbour Graph"),
    ("ORIGIN", "File Origin", "Towards the file's origin (0, 0, 0): a depth-camera or stereo frame in its "
                              "sensor's coordinates"),
]
_TIMER_SECONDS = 0.1  # how often the modal operator looks at its worker's progress
# How long a cancel (Esc, or Blender ending the operator: cancel(), which blocks the main
# thread meanwhile) waits for the worker to stop: the work makes a progress call (where it
# stops) every fraction of a second (a LAS chunk: 0.05-0.25 s). A reader inside one library
# call that makes no progress call (plyfile, pye57) cannot be interrupted: after this wait
# it is abandoned, its daemon thread running on until the call returns; what it returns is
# only arrays (no Blender data), dropped with the job, so nothing of it reaches the scene.
_CANCEL_WAIT_SECONDS = 1.0
# What a failed or cancelled run reports, and which exceptions are the user's problem
# (reported) rather than a bug (raised).
_REPORTED = (CloudFileError, MemoryError, ValueError, Cancelled)


def _decimal(value: float) -> float:
    """A float property's value as the decimal the user typed: Blender stores it as float32,
    and 0.001 in float32 is 0.0010000000475, which moves a georeferenced coordinate of 5e9 mm
    by 0.24 m. The shortest decimal that gives the same float32 is what was meant."""
    import numpy as np

    return float(np.format_float_positional(np.float32(value), unique=True))


class _WindowProgress:
    """Blender's progress on the cursor (wm.progress_*), for synchronous runs with a window."""

    def __init__(self, wm):
        self.wm = wm
        wm.progress_begin(0, 100)

    def __call__(self, fraction: float, message: str) -> None:
        self.wm.progress_update(int(100 * fraction))

    def end(self) -> None:
        self.wm.progress_end()


class _Work:
    """An operator whose `work(progress)` (no Blender data) may run on a worker thread, and
    whose `finish(context, result)` (Blender data) then runs on the main thread; see the
    module's text. Subclasses set self.work in execute() and call self.run(context)."""

    use_job: bpy.props.BoolProperty(options={"HIDDEN", "SKIP_SAVE"}, default=False)
    _job = None
    _timer = None
    _cancelled_at = None  # time.monotonic() of the Esc that cancelled the job

    def run(self, context) -> set:
        if self.use_job and not bpy.app.background and context.window is not None:
            self.use_job = False  # a redo (Adjust Last Operation) re-runs synchronously
            wm = context.window_manager
            self._job = Job(self.work).start()
            self._timer = wm.event_timer_add(_TIMER_SECONDS, window=context.window)
            wm.progress_begin(0, 100)
            wm.modal_handler_add(self)
            return {"RUNNING_MODAL"}
        bar = None if bpy.app.background or context.window_manager is None else _WindowProgress(context.window_manager)
        try:
            result = self.work(TerminalProgress(self.bl_label) if bar is None else bar)
        except _REPORTED as e:
            return self._refused(e)
        finally:
            if bar is not None:
                bar.end()
        return self.finish(context, result)

    def _refused(self, error) -> set:
        self.report({"WARNING"} if isinstance(error, Cancelled) else {"ERROR"},
                    f"{self.bl_label}: cancelled, nothing was changed" if isinstance(error, Cancelled) else str(error))
        return {"CANCELLED"}

    def _status(self, context, text) -> None:
        if context.workspace is not None:
            context.workspace.status_text_set(text)

    def modal(self, context, event):
        job = self._job
        if event.type == "ESC" and event.value == "PRESS":
            job.cancel()  # the worker stops at its next progress call
            if self._cancelled_at is None:
                self._cancelled_at = time.monotonic()
            return {"RUNNING_MODAL"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        wm = context.window_manager
        if not job.done:
            if self._cancelled_at is not None and time.monotonic() - self._cancelled_at > _CANCEL_WAIT_SECONDS:
                self._end_modal(context)  # a worker that cannot be interrupted: abandoned
                return self._refused(Cancelled("cancelled"))
            wm.progress_update(int(100 * job.fraction))
            self._status(context, f"{self.bl_label}: {100 * job.fraction:.0f} % {job.message} (Esc to cancel)")
            return {"RUNNING_MODAL"}
        self._end_modal(context)
        try:
            result = job.result()
        except _REPORTED as e:
            return self._refused(e)
        return self.finish(context, result)

    def _end_modal(self, context) -> None:
        context.window_manager.event_timer_remove(self._timer)
        context.window_manager.progress_end()
        self._status(context, None)

    def cancel(self, context):  # Blender ends the operator (e.g. the file is closed): stop the worker
        if self._job is not None:
            self._job.cancel()
            self._job.wait(_CANCEL_WAIT_SECONDS)  # then abandoned (see _CANCEL_WAIT_SECONDS)
            self._end_modal(context)


def create_objects(context, loaded, notes_for, progress=None, consume: bool = False) -> list:
    """One object per (path, PreparedCloud). On any exception (a cancel through `progress`
    included) everything it created is removed -- objects, meshes, and the shared node group
    and material when this call made them -- and the exception re-raised. consume: each
    prepared cloud's per-point arrays are let go of (set to None) as Blender takes its copy
    of them, so that Blender's copies reuse their memory (the import operator: the prepared
    clouds are not used afterwards, and on an error they are dropped)."""
    before = {id_type: {x.as_pointer() for x in getattr(bpy.data, id_type)}
              for id_type in ("objects", "meshes", "node_groups", "materials")}
    created = []
    try:
        for i, (path, prep) in enumerate(loaded):
            if progress is not None:
                progress(i / len(loaded), f"creating {os.path.basename(path)}")
            name = os.path.splitext(os.path.basename(path))[0] or "Splats"
            attributes = dict(prep.cloud.attributes)
            if prep.cloud.scanners is not None:
                attributes[SCANNER] = prep.cloud.scanners - prep.origin

            def release(what: str, prep=prep, attributes=attributes) -> None:
                if what == "positions":
                    prep.local = None
                elif what == "radii":  # (a file's own radii stay: prep.cloud.radii says the file had them)
                    prep.radii = None
                elif what in ("normals", "colours"):
                    setattr(prep.cloud, what, None)
                else:
                    attributes.pop(what, None)
                    prep.cloud.attributes.pop(what, None)
                    if what == SCANNER:
                        prep.cloud.scanners = None

            obj = create_cloud_object(name, prep.local, prep.cloud.normals, prep.radii, prep.cloud.colours,
                                      location=tuple(prep.origin), collection=context.collection,
                                      attributes=attributes, release=release if consume else None)
            created.append(obj)
            obj["splat_tracer_source"] = path
            obj["splat_tracer_format"] = prep.cloud.format
            obj[VIEWPOINT] = [float(-v) for v in prep.origin]  # the file's (0, 0, 0) in the object's frame
            obj.splat_tracer.closed = prep.hood.closed_guess
            obj["splat_tracer_closed_guess"] = prep.hood.describe()
            notes = notes_for(prep)
            if notes:  # kept with the object: reports scroll away
                obj["splat_tracer_import_notes"] = "\n".join(notes)
        if progress is not None:
            progress(1.0, "created")
    except BaseException:
        for id_type in ("objects", "meshes", "node_groups", "materials"):  # users first, then what they use
            collection = getattr(bpy.data, id_type)
            for item in [x for x in collection if x.as_pointer() not in before[id_type]]:
                collection.remove(item)
        raise
    return created


@orientation_helper(axis_forward="Y", axis_up="Z")
class SPLAT_TRACER_OT_import_cloud(_Work, bpy.types.Operator, ImportHelper):
    """Import point clouds (PLY, Gaussian-splatting PLY, LAS/LAZ, E57, PCD, XYZ/PTS/TXT/CSV) as splat objects, one per file"""

    bl_idname = "splat_tracer.import_cloud"
    bl_label = "Import Splat Point Cloud"
    bl_options = {"REGISTER", "UNDO", "PRESET"}

    filename_ext = ".ply"
    filter_glob: bpy.props.StringProperty(default=";".join("*" + e for e in readers.EXTENSIONS), options={"HIDDEN"})
    files: bpy.props.CollectionProperty(type=bpy.types.OperatorFileListElement, options={"HIDDEN", "SKIP_SAVE"})
    directory: bpy.props.StringProperty(subtype="DIR_PATH", options={"HIDDEN", "SKIP_SAVE"})
    neighbours: bpy.props.IntProperty(
        name="Neighbours (k)",
        description="When a file has no radius, each splat's radius is the distance to its k-th nearest point",
        default=spacing.DEFAULT_K, min=1, max=64,
    )
    outliers: bpy.props.EnumProperty(
        name="Outliers",
        description="Points far from the rest of the cloud (e.g. a scanner's invalid returns at 0, 0, 0): "
                    "they never move the origin or the analysis; keep them as small splats, or leave them out",
        items=[("KEEP", "Keep", "Import them, with their radius limited; the import warns about them"),
               ("DROP", "Drop", "Leave them out; the import says how many")],
        default="KEEP",
    )
    normal_neighbours: bpy.props.IntProperty(
        name="Normal Neighbours",
        description="When a file has no normals, each is estimated from a plane fitted to this many nearest points",
        default=normals.DEFAULT_K, min=3, max=128,
    )
    orientation: bpy.props.EnumProperty(
        name="Orientation", description="Which side estimated normals (and Gaussian splats' normals) face",
        items=_ORIENTATION_ITEMS, default="AUTO",
    )
    columns: bpy.props.StringProperty(
        name="Columns",
        description="Text files (XYZ, PTS, TXT, CSV): what each column is, e.g. 'x y z i r g b' "
                    "(x y z, r g b [a] colour, nx ny nz normal, i intensity, _ skips); empty: from the header "
                    "or guessed",
        default="",
    )
    global_scale: bpy.props.FloatProperty(
        name="Scale", description="Multiply the file's coordinates (and radii) by this (e.g. 0.001 for millimetres)",
        default=1.0, min=1e-6, max=1e6, soft_min=0.001, soft_max=1000.0,
    )
    max_points: bpy.props.IntProperty(
        name="Point Budget", description="Import at most this many points of each file, left out evenly over "
                                         "space and the same on every import (0: all points)",
        default=0, min=0,
    )
    hole_free: bpy.props.BoolProperty(
        name="Close Gaps",
        description="Raise a splat's radius where the gap to its neighbours would leave a pinhole (to the largest "
                    "empty circle it lies on, at most 1.3 times its neighbour spacing)",
        default=True,
    )
    statistical_outliers: bpy.props.BoolProperty(
        name="Statistical Outlier Removal",
        description="Leave out points whose mean distance to their 20 nearest neighbours is far above the cloud's",
        default=False,
    )
    std_ratio: bpy.props.FloatProperty(
        name="Standard Deviations", description="Statistical outlier removal: how many standard deviations above "
                                                "the mean distance a point may lie", default=2.0, min=0.1, max=10.0,
    )

    def paths(self) -> list[str]:
        if self.files and self.directory:
            return [os.path.join(self.directory, f.name) for f in self.files if f.name]
        return [self.filepath]

    def import_options(self) -> importer.ImportOptions:
        axes = axis_conversion(from_forward=self.axis_forward, from_up=self.axis_up).to_3x3()
        return importer.ImportOptions(
            self.neighbours, self.outliers == "DROP", self.normal_neighbours, self.orientation, self.columns,
            [list(row) for row in axes], _decimal(self.global_scale), self.max_points,
            self.std_ratio if self.statistical_outliers else 0.0, hole_free=self.hole_free)

    def invoke(self, context, event):
        self.use_job = True
        # Dropped files (directory and files are set, and never remembered): confirm the options.
        if self.directory and len(self.files) or self.properties.is_property_set("filepath"):
            return self.invoke_popup(context)
        return ImportHelper.invoke(self, context, event)

    def execute(self, context):
        # Read and check every file before creating anything: one bad file imports nothing.
        paths, options = self.paths(), self.import_options()  # read here: properties belong to the main thread
        self.work = lambda progress: importer.load_many(paths, options, progress)
        return self.run(context)

    def finish(self, context, loaded) -> set:
        total = sum(len(prep.local) for _, prep in loaded)
        created = create_objects(context, loaded, lambda prep: prep.notes(self.neighbours), consume=True)
        for path, prep in loaded:
            for note in prep.notes(self.neighbours):
                self.report({"WARNING"}, f"{path}: {note}")
        for obj in context.view_layer.objects.selected:
            obj.select_set(False)
        for obj in created:
            obj.select_set(True)
        if created:
            context.view_layer.objects.active = created[-1]
        self.report({"INFO"}, f"Imported {total:,} splats from {len(created)} file(s)")
        return {"FINISHED"}


class SPLAT_TRACER_OT_estimate_normals(_Work, bpy.types.Operator):
    """(Re)estimate the normals and splat radii of the selected splat clouds from their points"""

    bl_idname = "splat_tracer.estimate_normals"
    bl_label = "Estimate Splat Normals"
    bl_options = {"REGISTER", "UNDO"}

    normal_neighbours: bpy.props.IntProperty(
        name="Normal Neighbours", description="Each normal is a plane fitted to this many nearest points",
        default=normals.DEFAULT_K, min=3, max=128)
    orientation: bpy.props.EnumProperty(name="Orientation", items=_ORIENTATION_ITEMS, default="AUTO")
    radii: bpy.props.BoolProperty(name="Radii", description="Also recompute each splat's radius from the "
                                  "distance to its k-th nearest point", default=True)
    neighbours: bpy.props.IntProperty(name="Radius Neighbours (k)", default=spacing.DEFAULT_K, min=1, max=64)
    hole_free: bpy.props.BoolProperty(
        name="Close Gaps",
        description="With Radii: raise a splat's radius where the gap to its neighbours would leave a pinhole",
        default=True,
    )

    @staticmethod
    def clouds(context):
        return [o for o in context.selected_objects if o.type == "MESH" and NORMAL in o.data.attributes]

    @classmethod
    def poll(cls, context):
        return bool(cls.clouds(context))

    def execute(self, context):
        import numpy as np

        jobs = []  # (name, points, scanners, mode, viewpoint): read here, on the main thread
        for obj in self.clouds(context):
            problem = self.attribute_problem(obj)
            if problem is not None:
                self.report({"ERROR"}, problem)
                return {"CANCELLED"}
            mesh = obj.data
            n = len(mesh.vertices)
            if n < normals.MIN_POINTS:
                self.report({"ERROR"}, f"{obj.name}: {n} points, too few to estimate normals")
                return {"CANCELLED"}
            co = mesh_positions(mesh).ravel()
            scanners = None
            if SCANNER in mesh.attributes:
                scanners = np.empty(n * 3, np.float32)
                mesh.attributes[SCANNER].data.foreach_get("vector", scanners)
                scanners = scanners.reshape(-1, 3).astype(np.float64)
            viewpoint = obj.get(VIEWPOINT)
            viewpoint = None if viewpoint is None else np.array(viewpoint[:3], np.float64)
            mode = prepare.resolve_orientation(self.orientation, scanners is not None, viewpoint is not None)
            jobs.append((obj.name, co.reshape(-1, 3).astype(np.float64), scanners, mode, viewpoint))
        normal_k, k, hole_free = self.normal_neighbours, self.neighbours, self.hole_free

        def work(progress):
            out = []
            for i, (name, points, scanners, mode, viewpoint) in enumerate(jobs):
                step = Steps(scaled(progress, i / len(jobs), (i + 1) / len(jobs), f"{name}: "),
                             {"normals": 3.0, "radii": 1.0})
                try:
                    tree = spacing.neighbour_tree(points)
                    result, known, cover = normals.estimate_and_orient(points, normal_k, mode, scanners, radius_k=k,
                                                                       tree=tree, progress=step("normals"),
                                                                       close_gaps=hole_free, viewpoint=viewpoint)
                    hood = spacing.analyse(points, result.normals, k, progress=step("radii"), tree=tree,
                                           known_spacing=known, close_gaps=hole_free, known_cover=cover)
                    radii = hood.covering if hood.covering is not None else hood.spacing
                except (ValueError, MemoryError) as e:
                    raise ValueError(f"{name}: {e}") from None
                out.append((name, result, hood, radii))
            return out

        self.work = work
        return self.run(context)

    def attribute_problem(self, obj):
        """Why the object's splat attributes cannot take the estimate (re-made with another
        type), naming object, attribute and the type wanted; None when they can. Checked
        before anything is written: a retyped attribute changes nothing."""
        wanted = [NORMAL] + ([RADIUS] if self.radii else [])
        problems = [p for p in (attribute_problem(obj.data.attributes, name) for name in wanted) if p]
        if not problems:
            return None
        return f"{obj.name}: {'; '.join(problems)}; nothing was changed"

    def finish(self, context, results) -> set:
        import numpy as np

        for name, result, hood, radii in results:  # the objects may be gone when a worker finishes
            obj = bpy.data.objects.get(name)
            if obj is None or obj.type != "MESH" or len(obj.data.vertices) != len(result.normals):
                self.report({"WARNING"}, f"{name}: changed while its normals were estimated; left as it was")
                continue
            problem = self.attribute_problem(obj)  # retyped while the worker ran
            if problem is not None:
                self.report({"WARNING"}, problem)
                continue
            mesh = obj.data
            mesh.attributes[NORMAL].data.foreach_set("vector", result.normals.ravel())
            if self.radii and RADIUS in mesh.attributes:
                cap = np.float32(prepare.RADIUS_CAP * np.percentile(hood.spacing, prepare.RADIUS_CAP_PERCENTILE))
                mesh.attributes[RADIUS].data.foreach_set("value", np.minimum(radii, cap))
            mesh.update()
            obj.splat_tracer.closed = hood.closed_guess
            obj["splat_tracer_closed_guess"] = hood.describe()
            ambiguous = int(result.ambiguous.sum())
            if ambiguous:
                self.report({"WARNING"}, f"{name}: {ambiguous:,} points' orientation was ambiguous")
        self.report({"INFO"}, f"Estimated normals of {', '.join(name for name, *_ in results)}")
        return {"FINISHED"}

    def invoke(self, context, event):
        self.use_job = True
        return self.execute(context)


class SPLAT_TRACER_FH_point_cloud(bpy.types.FileHandler):
    bl_idname = "SPLAT_TRACER_FH_point_cloud"
    bl_label = "Splat point cloud"
    bl_import_operator = SPLAT_TRACER_OT_import_cloud.bl_idname
    bl_file_extensions = ";".join(readers.EXTENSIONS)

    @classmethod
    def poll_drop(cls, context):
        return context.area is not None and context.area.type == "VIEW_3D"


def menu_import(self, context):
    self.layout.operator(SPLAT_TRACER_OT_import_cloud.bl_idname, text="Splat Point Cloud (.ply, .las, .laz, .e57, .pcd, .xyz, .pts, .csv)")
