"""File > Import > Splat Point Cloud, and drag-and-drop of .ply files into the 3D viewport."""
from __future__ import annotations

import os

import bpy
from bpy_extras.io_utils import ImportHelper

from ..splat_tracer import ply, prepare, spacing
from ..splat_tracer.cloud_object import create_cloud_object


def load_cloud(path: str, k: int, drop_outliers: bool = False) -> prepare.PreparedCloud:
    """Reads and prepares one file; raises ply.CloudFileError with the file named."""
    return prepare.prepare(ply.read_ply(path), path, k, drop_outliers)


class SPLAT_TRACER_OT_import_cloud(bpy.types.Operator, ImportHelper):
    """Import point clouds with normals as splat objects (one object per file)"""

    bl_idname = "splat_tracer.import_cloud"
    bl_label = "Import Splat Point Cloud"
    bl_options = {"REGISTER", "UNDO", "PRESET"}

    filename_ext = ".ply"
    filter_glob: bpy.props.StringProperty(default="*.ply", options={"HIDDEN"})
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

    def paths(self) -> list[str]:
        if self.files and self.directory:
            return [os.path.join(self.directory, f.name) for f in self.files if f.name]
        return [self.filepath]

    def execute(self, context):
        # Read and check every file before creating anything: one bad file imports nothing.
        loaded = []
        for path in self.paths():
            try:
                loaded.append((path, load_cloud(path, self.neighbours, self.outliers == "DROP")))
            except (ply.CloudFileError, MemoryError) as e:
                self.report({"ERROR"}, str(e))
                return {"CANCELLED"}
        created = []
        try:
            for path, prep in loaded:
                name = os.path.splitext(os.path.basename(path))[0] or "Splats"
                obj = create_cloud_object(name, prep.local, prep.cloud.normals, prep.radii, prep.cloud.colours,
                                          location=tuple(prep.origin), collection=context.collection)
                obj["splat_tracer_source"] = path
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


class SPLAT_TRACER_FH_ply(bpy.types.FileHandler):
    bl_idname = "SPLAT_TRACER_FH_ply"
    bl_label = "Splat point cloud"
    bl_import_operator = SPLAT_TRACER_OT_import_cloud.bl_idname
    bl_file_extensions = ".ply"

    @classmethod
    def poll_drop(cls, context):
        return context.area is not None and context.area.type == "VIEW_3D"


def menu_import(self, context):
    self.layout.operator(SPLAT_TRACER_OT_import_cloud.bl_idname, text="Splat Point Cloud (.ply)")
