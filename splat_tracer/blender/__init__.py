"""The Blender layer: the render engine (engine.py: final and viewport renders; viewport.py,
session.py), the scene's export to the render API (export/), the settings (properties.py)
and the cloud object (cloud_object.py). With the top-level operators/ and ui/, the only code
that imports bpy; it uses splat_tracer.pointcloud and splat_tracer.render, never the other
way round."""
