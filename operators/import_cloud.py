"""File > Import > Splat Point Cloud, and drag-and-drop of .ply files into the 3D viewport."""
from __future__ import annotations

import os

import bpy
from bpy_extras.io_utils import ImportHelper

from ..splat_tracer import core, ply, spacing
from ..splat_tracer.cloud_object import create_cloud_object


def load_cloud(path: str, k: int):
    """Reads and prepares one file; raises ply.CloudFileError with the file named.
    Returns (cloud, origin, local positions, radii, neighbourhood analysis)."""
    cloud = ply.read_ply(path)
    if len(cloud) < spacing.MIN_POINTS:  # refused before the neighbour search, which needs them
        usable = len(cloud) + cloud.merged_duplicates
        raise ply.CloudFileError(
            f"{path}: only {len(cloud)} distinct position{'s' if len(cloud) != 1 else ''} among its {usable:,} "
            f"usable points ({cloud.merged_duplicates:,} repeat an earlier one); at least {spacing.MIN_POINTS} "
            "are needed to size the splats")
    origin, local = core.local_frame(cloud.positions)
    try:
        hood = spacing.analyse(local, cloud.normals, k)
    except spacing.SpacingError as e:
        raise ply.CloudFileError(f"{path}: {e}") from None
    radii = cloud.radii if cloud.radii is not None else hood.spacing
    return cloud, origin, local, radii, hood


def import_notes(cloud, hood, k: int) -> list[str]:
    """What the import changed or found, one sentence each (the import's warnings)."""
    notes = []
    if cloud.dropped_normals:
        notes.append(f"{cloud.dropped_normals:,} points with a zero or non-finite normal were dropped")
    if cloud.merged_duplicates:
        notes.append(f"{cloud.merged_duplicates:,} points repeat the position of an earlier one and were merged "
                     f"into it (first: row {cloud.first_duplicate_row})")
    if hood.degenerate and cloud.radii is None:
        notes.append(f"{hood.degenerate} points share their position with {k}+ others; they got the median radius")
    return notes


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

    def paths(self) -> list[str]:
        if self.files and self.directory:
            return [os.path.join(self.directory, f.name) for f in self.files if f.name]
        return [self.filepath]

    def execute(self, context):
        # Read and check every file before creating anything: one bad file imports nothing.
        loaded = []
        for path in self.paths():
            try:
                loaded.append((path, *load_cloud(path, self.neighbours)))
            except (ply.CloudFileError, MemoryError) as e:
                self.report({"ERROR"}, str(e))
                return {"CANCELLED"}
        created = []
        try:
            for path, cloud, origin, local, radii, hood in loaded:
                name = os.path.splitext(os.path.basename(path))[0] or "Splats"
                obj = create_cloud_object(name, local, cloud.normals, radii, cloud.colours,
                                          location=tuple(origin), collection=context.collection)
                obj["splat_tracer_source"] = path
                obj.splat_tracer.closed = hood.closed_guess
                obj["splat_tracer_closed_guess"] = hood.describe()
                created.append(obj)
                notes = import_notes(cloud, hood, self.neighbours)
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
        total = sum(len(c[1]) for c in loaded)
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
