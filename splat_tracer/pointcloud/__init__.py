"""The point-cloud pipeline, without Blender: a file read into a PointCloud (cloud.py) by
the reader its content names (readers/), then prepared for rendering (prepare.py: frame,
outliers, spacing.py's radii and closed guess, normals.py's estimation and orientation),
all driven by importer.py. The neighbour search and graph work run in the compiled core
(neighbours.py, graph.py).

Never imports bpy nor the render API (splat_tracer.render): what it produces is plain
arrays, which the Blender layer stores on an object."""
