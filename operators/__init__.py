"""Operators: importing clouds (File > Import, drag-and-drop), A/B comparison (still images,
and the viewport's live A/B)."""
import bpy

from . import ab_viewport
from .compare import SPLAT_TRACER_OT_compare
from .import_cloud import (SPLAT_TRACER_FH_point_cloud, SPLAT_TRACER_OT_estimate_normals,
                           SPLAT_TRACER_OT_import_cloud, menu_import)

classes = (SPLAT_TRACER_OT_import_cloud, SPLAT_TRACER_OT_estimate_normals, SPLAT_TRACER_FH_point_cloud,
           SPLAT_TRACER_OT_compare) + ab_viewport.classes


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.TOPBAR_MT_file_import.append(menu_import)
    ab_viewport.register_keymap()


def unregister():
    ab_viewport.unregister_keymap()
    bpy.types.TOPBAR_MT_file_import.remove(menu_import)
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
