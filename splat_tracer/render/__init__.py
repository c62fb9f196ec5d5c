"""The render API over the compiled core, without Blender: the method (method.py), splat
clouds (splats.py: SplatCloud), scenes of meshes and instances with lamps, materials and a
world (scene.py, shading.py), cameras (camera.py), and the A/B comparison with its colour
difference (ab.py, difference.py).

Never imports bpy nor the point-cloud pipeline (splat_tracer.pointcloud): it takes arrays."""
