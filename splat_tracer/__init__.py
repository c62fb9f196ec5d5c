"""splat_tracer: the renderer package.

Importing this package (or `splat_tracer.core`, `splat_tracer.ply`, `splat_tracer.spacing`)
needs no Blender: tests and benchmarks use the core from plain Python. The Blender-facing
modules (engine, export, properties, cloud_object) are imported only by register().
"""


def _blender_modules():
    from . import engine, properties
    return (properties, engine)


def register():
    for module in _blender_modules():
        module.register()


def unregister():
    for module in reversed(_blender_modules()):
        module.unregister()
