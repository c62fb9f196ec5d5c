"""File > Import > Splat Point Cloud, and drag-and-drop of point-cloud files into the 3D
viewport (PLY incl. Gaussian-splatting PLY, LAS/LAZ, E57, XYZ/PTS/TXT/CSV: the reader is
chosen by the file's content, splat_tracer/readers.py); and Estimate Splat Normals, which
(re)estimates the normals and radii of existing cloud objects."""
from __future__ import annotations

import os

import bpy
from bpy_extras.io_utils import ImportHelper

from ..splat_tracer import normals, ply, prepare, readers, spacing
from ..splat_tracer.cloud_object import NORMAL, RADIUS, create_cloud_object

SCANNER = "scanner_position"  # point attribute: the scanner that saw the point (object-local)
ORIENTATION_HINT = "splat_tracer_orientation"  # custom property: the file's own orientation mode
_ORIENTATION_ITEMS = [
    ("AUTO", "Automatic", "Towards the scanner when the file knows it (E57), upward for aerial data (LAS), "
                          "else along the neighbour graph"),
    ("PROPAGATE", "Neighbour Graph", "Consistent along a minimum spanning tree of the neighbours, outward where "
                                     "the surface encloses a volume"),
    ("UP", "Upward", "Towards +Z (aerial scans); walls take their neighbours' side"),
    ("SCANNER", "Scanner", "Towards the scanner position of each point (E57 files); else Neighbour Graph"),
]


def load_cloud(path: str, k: int, drop_outliers: bool = False, normal_k: int = normals.DEFAULT_K,
               orientation: str = "AUTO", columns: str = "") -> prepare.PreparedCloud:
    """Reads (any supported format) and prepares one file; raises ply.CloudFileError with the file named."""
    return prepare.prepare(readers.read_cloud(path, columns), path, k, drop_outliers,
                           normal_k=normal_k, orientation=orientation)


class SPLAT_TRACER_OT_import_cloud(bpy.types.Operator, ImportHelper):
    """Import point clouds (PLY, Gaussian-splatting PLY, LAS/LAZ, E57, XYZ/PTS/TXT/CSV) as splat objects, one per file"""

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

    def paths(self) -> list[str]:
        if self.files and self.directory:
            return [os.path.join(self.directory, f.name) for f in self.files if f.name]
        return [self.filepath]

    def execute(self, context):
        # Read and check every file before creating anything: one bad file imports nothing.
        loaded = []
        for path in self.paths():
            try:
                loaded.append((path, load_cloud(path, self.neighbours, self.outliers == "DROP", self.normal_neighbours,
                                                self.orientation, self.columns)))
            except (ply.CloudFileError, MemoryError) as e:
                self.report({"ERROR"}, str(e))
                return {"CANCELLED"}
        created = []
        try:
            for path, prep in loaded:
                name = os.path.splitext(os.path.basename(path))[0] or "Splats"
                attributes = dict(prep.cloud.attributes)
                if prep.cloud.scanners is not None:
                    attributes[SCANNER] = prep.cloud.scanners - prep.origin
                obj = create_cloud_object(name, prep.local, prep.cloud.normals, prep.radii, prep.cloud.colours,
                                          location=tuple(prep.origin), collection=context.collection,
                                          attributes=attributes)
                obj["splat_tracer_source"] = path
                obj["splat_tracer_format"] = prep.cloud.format
                obj[ORIENTATION_HINT] = prep.cloud.orientation
                obj.splat_tracer.closed = prep.hood.closed_guess
                obj["splat_tracer_closed_guess"] = prep.hood.describe()
                created.append(obj)
                notes = prep.notes(self.neighbours)
                for note in notes:
                    self.report({"WARNING"}, f"{path}: {note}")
                if notes:  # kept with the object: reports scroll away
                    obj["splat_tracer_import_notes"] = "\n".join(notes)
        except Exception:
            for obj in created:
                mesh = obj.data
                bpy.data.objects.remove(obj)
                bpy.data.meshes.remove(mesh)
            raise
        for obj in context.view_layer.objects.selected:
            obj.select_set(False)
        for obj in created:
            obj.select_set(True)
        if created:
            context.view_layer.objects.active = created[-1]
        total = sum(len(prep.local) for _, prep in loaded)
        self.report({"INFO"}, f"Imported {total:,} splats from {len(created)} file(s)")
        return {"FINISHED"}


class SPLAT_TRACER_OT_estimate_normals(bpy.types.Operator):
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

    @staticmethod
    def clouds(context):
        return [o for o in context.selected_objects if o.type == "MESH" and NORMAL in o.data.attributes]

    @classmethod
    def poll(cls, context):
        return bool(cls.clouds(context))

    def execute(self, context):
        import numpy as np

        done = []
        for obj in self.clouds(context):
            mesh = obj.data
            n = len(mesh.vertices)
            co = np.empty(n * 3, np.float32)
            mesh.vertices.foreach_get("co", co)
            points = co.reshape(-1, 3).astype(np.float64)
            scanners = None
            if SCANNER in mesh.attributes:
                scanners = np.empty(n * 3, np.float32)
                mesh.attributes[SCANNER].data.foreach_get("vector", scanners)
                scanners = scanners.reshape(-1, 3).astype(np.float64)
            mode = self.orientation
            if mode == "AUTO":
                mode = obj.get(ORIENTATION_HINT, "PROPAGATE")
            if mode == "SCANNER" and scanners is None:
                mode = "PROPAGATE"
            if n < normals.MIN_POINTS:
                self.report({"ERROR"}, f"{obj.name}: {n} points, too few to estimate normals")
                return {"CANCELLED"}
            try:
                axes = normals.estimate(points, self.normal_neighbours)
                result = normals.orient(points, axes, mode, scanners)
                hood = spacing.analyse(points, result.normals, self.neighbours)
            except (ValueError, MemoryError) as e:
                self.report({"ERROR"}, f"{obj.name}: {e}")
                return {"CANCELLED"}
            mesh.attributes[NORMAL].data.foreach_set("vector", result.normals.ravel())
            if self.radii and RADIUS in mesh.attributes:
                cap = np.float32(prepare.RADIUS_CAP * np.percentile(hood.spacing, prepare.RADIUS_CAP_PERCENTILE))
                mesh.attributes[RADIUS].data.foreach_set("value", np.minimum(hood.spacing, cap))
            mesh.update()
            obj.splat_tracer.closed = hood.closed_guess
            obj["splat_tracer_closed_guess"] = hood.describe()
            ambiguous = int(result.ambiguous.sum())
            if ambiguous:
                self.report({"WARNING"}, f"{obj.name}: {ambiguous:,} points' orientation was ambiguous")
            done.append(obj.name)
        self.report({"INFO"}, f"Estimated normals of {', '.join(done)}")
        return {"FINISHED"}


class SPLAT_TRACER_FH_ply(bpy.types.FileHandler):
    bl_idname = "SPLAT_TRACER_FH_ply"
    bl_label = "Splat point cloud"
    bl_import_operator = SPLAT_TRACER_OT_import_cloud.bl_idname
    bl_file_extensions = ";".join(readers.EXTENSIONS)

    @classmethod
    def poll_drop(cls, context):
        return context.area is not None and context.area.type == "VIEW_3D"


def menu_import(self, context):
    self.layout.operator(SPLAT_TRACER_OT_import_cloud.bl_idname, text="Splat Point Cloud (.ply, .las, .laz, .e57, .xyz, .pts, .csv)")
