"""Helpers both Blender-free layers share (pointcloud/ and render/): progress and
cancellation, 4x4 matrices, column-wise work on numpy arrays in blocks, memory queries and
the input checks in front of the compiled core. Nothing here imports bpy, the render API
or the point-cloud pipeline."""
