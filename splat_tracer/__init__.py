"""splat_tracer: the renderer package, in three layers.

- pointcloud/: the point-cloud pipeline (readers, preparation, the import), no Blender;
- render/: the render API over the compiled core (_core), no Blender;
- blender/: the render engine, the scene export, properties and the cloud object (bpy);
- util/: helpers the two Blender-free layers share.
The rule is blender -> {pointcloud, render} -> native core; pointcloud and render never
import each other, and neither imports bpy, so tests and benchmarks use them from plain
Python. The Blender layer is imported only by register().
"""


def _blender_modules():
    from .blender import engine, properties
    return (properties, engine)


def register():
    for module in _blender_modules():
        module.register()


def unregister():
    for module in reversed(_blender_modules()):
        module.unregister()
