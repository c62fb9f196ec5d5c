"""Run in a fresh Python by test_dist.py: installs the zip the way a user does, renders.

    python install_and_render.py ZIP PLY OUTPUT.exr
"""
import importlib.machinery
import math
import sys

# Blender's own Python has neither scipy nor plyfile; this one (the venv's) has both. Hide
# them, so that the add-on can only find what the zip installed into the extensions'
# site-packages (else the test would pass with the venv's copies, whatever the zip holds).
HOST_SITE = [p for p in sys.path if p.endswith("site-packages")]


class HideHostPackages:
    def find_spec(self, name, path=None, target=None):
        if path is not None or name not in ("scipy", "plyfile"):
            return None
        spec = importlib.machinery.PathFinder.find_spec(name, [p for p in sys.path if p not in HOST_SITE])
        if spec is None:
            raise ModuleNotFoundError(f"No module named {name!r} outside the host's site-packages", name=name)
        return spec


sys.meta_path.insert(0, HideHostPackages())

import bpy  # noqa: E402

zip_path, ply_path, output = sys.argv[1:4]
bpy.ops.extensions.package_install_files(filepath=zip_path, repo="user_default", enable_on_install=True)
assert "bl_ext.user_default.splat_tracer" in bpy.context.preferences.addons, "extension not enabled"
bpy.ops.wm.read_homefile(use_empty=True)
bpy.ops.splat_tracer.import_cloud(filepath=ply_path)  # uses the bundled scipy and plyfile
import plyfile  # noqa: E402
import scipy  # noqa: E402

for module in (scipy, plyfile):
    assert "/.local/" in module.__file__ and not any(module.__file__.startswith(p) for p in HOST_SITE), module.__file__
print(f"bundled: scipy {scipy.__version__} plyfile {plyfile.__file__}")
scene = bpy.context.scene
cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
scene.collection.objects.link(cam)
cam.location, cam.rotation_euler = (0.0, -5.0, 0.0), (math.pi / 2, 0.0, 0.0)
scene.camera = cam
scene.render.engine = "SPLAT_TRACER"
scene.render.resolution_x, scene.render.resolution_y = 160, 120
scene.view_layers[0].use_pass_z = True
scene.render.image_settings.media_type = "MULTI_LAYER_IMAGE"
scene.render.image_settings.file_format = "OPEN_EXR_MULTILAYER"
scene.render.filepath = output
bpy.ops.render.render(write_still=True)
try:  # the add-on lives under bl_ext.*: no top-level name may leak from the zip
    import splat_tracer  # noqa: F401
    sys.exit("splat_tracer is importable as a top-level module")
except ModuleNotFoundError:
    pass
