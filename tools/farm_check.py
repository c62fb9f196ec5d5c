"""Run before a render job on a farm node: fails the job unless Splat Tracer is the engine.

    blender -b job.blend --python tools/farm_check.py -f 1

A node without the extension (not installed, or installed but not enabled) would otherwise
render the file with another engine, silently: Blender keeps the engine's name in the file
but renders with its default engine when no add-on registers that name. This script sets
the engine of the scene to be rendered explicitly -- which Blender refuses when no add-on
registers it -- and exits Blender with status 1 (before `-f` is reached) if it cannot.
"""
import sys

import bpy

ENGINE = "SPLAT_TRACER"
scene = bpy.context.scene
try:
    scene.render.engine = ENGINE
except TypeError:  # "enum 'SPLAT_TRACER' not found in (...)": no add-on registers it
    enabled = [a.module for a in bpy.context.preferences.addons if a.module.endswith(".splat_tracer")]
    print(f"farm_check: Splat Tracer is {'enabled but its engine is missing' if enabled else 'not enabled'} in "
          f"this Blender {bpy.app.version_string}; install it with `blender --command extension install-file "
          "-r user_default -e splat_tracer-<version>-<platform>.zip`", file=sys.stderr)
    sys.exit(1)
print(f"farm_check: scene {scene.name!r} renders with Splat Tracer (Blender {bpy.app.version_string})")
