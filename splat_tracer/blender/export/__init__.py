"""The Blender scene read into the render API: geometry, instances and the camera
(scene.py), materials, lamps, the world and the render settings (shading.py)."""
from .scene import camera_lens, camera_origin, camera_panorama, export_camera, export_scene  # noqa: F401  (the session's and viewport's entry points)
