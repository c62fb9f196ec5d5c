"""Settings stored in .blend files: scene.splat_tracer."""
import bpy


class SplatTracerSceneSettings(bpy.types.PropertyGroup):
    __slots__ = ()  # Blender 5 warns about registered classes that allow arbitrary attributes

    radius_factor: bpy.props.FloatProperty(
        name="Radius Factor",
        description="Scales every splat radius at render time (1: each disc reaches its neighbours' centres)",
        default=1.0, min=0.01, soft_min=0.25, soft_max=4.0, precision=3,
    )


classes = (SplatTracerSceneSettings,)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.Scene.splat_tracer = bpy.props.PointerProperty(type=SplatTracerSceneSettings)


def unregister():
    del bpy.types.Scene.splat_tracer
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
