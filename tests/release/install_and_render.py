"""Run in a fresh Python with bpy (test_dist.py, test_blender_versions.py): installs the zip the way a
user or a farm does, imports clouds with the installed add-on and renders.

    python install_and_render.py --install ZIP [--via operator|cli]      install only
    python install_and_render.py [--install ZIP] --output OUT.exr CLOUD [CLOUD ...]

Run by its path from outside the repository (never `python -m` from the root): the process
must find only the add-on the zip installed, not this checkout's splat_tracer.

--via operator (default): Preferences > Install from Disk (`extensions.package_install_files`).
--via cli: what `blender --command extension install-file -r user_default -e ZIP` runs (the
    handler Blender's bl_pkg registers for `--command extension`), which also saves the
    preferences so that the next Blender started on the node has the add-on enabled.
With --output and no --install the process stands for the next Blender started on a farm
node: it reads the preferences the install saved, runs tools/farm_check.py as `blender -b
-P` would, imports every CLOUD (the first is rendered alone; the others, e.g. LAZ and E57,
only have to import through the bundled readers), and renders to a multilayer EXR with all
the passes the engine writes.
"""
import argparse
import importlib.machinery
import math
import runpy
import sys
from pathlib import Path

TOOLS = Path(__file__).resolve().parents[2] / "tools"
# What the zip bundles (its wheels' modules). The caller's site-packages may have them too
# (the development venv has all): they are hidden, so that the add-on can only find what
# the zip installed into the extensions' site-packages.
# (typing_extensions, bundled for pydantic, is not hidden: Blender's own modules may use it.)
BUNDLED = ("plyfile", "laspy", "lazrs", "pye57", "pyquaternion", "pypcd4", "pydantic", "pydantic_core",
           "annotated_types", "typing_inspection", "lzf")
# Not bundled and not used by the add-on (its k-nearest neighbours and the normals'
# spanning tree are in the core), but in the development venv for the tests: hidden the
# same way, so that an import of it by the add-on fails here as in a Blender without it.
UNBUNDLED = ("scipy",)
HOST_SITE = [p for p in sys.path if p.endswith("site-packages")]


class HideHostPackages:
    def find_spec(self, name, path=None, target=None):
        if path is not None or name not in BUNDLED + UNBUNDLED:
            return None
        spec = importlib.machinery.PathFinder.find_spec(name, [p for p in sys.path if p not in HOST_SITE])
        if spec is None:
            raise ModuleNotFoundError(f"No module named {name!r} outside the host's site-packages", name=name)
        return spec


sys.meta_path.insert(0, HideHostPackages())

import bpy  # noqa: E402

ap = argparse.ArgumentParser()
ap.add_argument("--install", metavar="ZIP")
ap.add_argument("--via", choices=("operator", "cli"), default="operator")
ap.add_argument("--output", metavar="OUT.exr")
ap.add_argument("clouds", nargs="*")
args = ap.parse_args()

if args.install:
    if args.via == "cli":
        status = sys.modules["bl_pkg"].cli_extension(["install-file", "-r", "user_default", "-e", args.install])
        assert status == 0, f"`extension install-file` returned {status}"
    else:
        bpy.ops.extensions.package_install_files(filepath=args.install, repo="user_default", enable_on_install=True)
    assert "bl_ext.user_default.splat_tracer" in bpy.context.preferences.addons, "extension not enabled"
    print(f"installed with the {args.via} into Blender {bpy.app.version_string} "
          f"(online access: {bpy.app.online_access})")
elif args.output:
    # A new Blender reads userpref.blend at start-up and enables the add-ons it lists; the
    # bpy module starts from factory preferences instead, so read them here. bpy 4.2 as a
    # module crashes in wm.read_userpref (it reloads the UI's icon textures without a GPU
    # context: a segfault in GPU_texture_create_2d, the module build's bug, not Blender's
    # start-up path); there the add-on the preferences list is enabled by addon_utils, as
    # start-up does for each one listed.
    if bpy.app.version >= (4, 5, 0):
        bpy.ops.wm.read_userpref()
    else:
        import addon_utils

        addon_utils.enable("bl_ext.user_default.splat_tracer", default_set=True)
if not args.output:
    sys.exit(0)

bpy.ops.wm.read_homefile(use_empty=True)
runpy.run_path(str(TOOLS / "farm_check.py"), run_name="__main__")  # exits 1 if the engine is missing
for path in args.clouds:
    before = set(bpy.data.objects)
    bpy.ops.splat_tracer.import_cloud(filepath=path)  # radii (and normals where missing) by the core's k-NN
    (obj,) = set(bpy.data.objects) - before
    print(f"imported {Path(path).suffix}: {len(obj.data.vertices)} points")
    if path != args.clouds[0]:
        bpy.data.objects.remove(obj)
for name in BUNDLED:
    if name in sys.modules:  # each imported module comes from the extensions' site-packages
        origin = sys.modules[name].__file__
        assert "/extensions/.local/" in Path(origin).as_posix(), origin  # as_posix: "\\" on Windows
        assert not any(origin.startswith(p) for p in HOST_SITE), origin
        version = getattr(sys.modules[name], "__version__", "")  # pye57's is a module
        print(f"bundled: {name} {version if isinstance(version, str) else '?'} {origin}")
print(f"numpy: {sys.modules['numpy'].__version__}")

scene = bpy.context.scene
cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
scene.collection.objects.link(cam)
cam.location, cam.rotation_euler = (0.0, -5.0, 0.0), (math.pi / 2, 0.0, 0.0)
scene.camera = cam
scene.render.resolution_x, scene.render.resolution_y = 160, 120
layer = scene.view_layers[0]
for switch in ("use_pass_z", "use_pass_normal", "use_pass_diffuse_color", "use_pass_object_index"):
    setattr(layer, switch, True)
if hasattr(scene.render.image_settings, "media_type"):  # Blender 5.0+; before, the format alone
    scene.render.image_settings.media_type = "MULTI_LAYER_IMAGE"
scene.render.image_settings.file_format = "OPEN_EXR_MULTILAYER"
scene.render.image_settings.color_depth = "32"
scene.render.filepath = args.output
bpy.ops.render.render(write_still=True)  # no light at all: the headlight
print(f"rendered with {scene.render.engine} in Blender {bpy.app.version_string}")

# Again lit, through what the engine reads of a scene (lamps, world nodes, materials, Cycles'
# settings): a sun whose light travels along +X (lighting the sphere's left half as the
# camera sees it) and a dim grey world. Written next to OUTPUT as <name>_lit.exr.
sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
sun.data.energy = 3.0  # W/m^2
sun.rotation_euler = (0.0, -math.pi / 2, 0.0)  # its -Z axis onto +X
scene.collection.objects.link(sun)
scene.world = bpy.data.worlds.new("World")
if bpy.app.version < (5, 0, 0):
    scene.world.use_nodes = True  # always on (and deprecated) from Blender 5.0
background = next(n for n in scene.world.node_tree.nodes if n.type == "BACKGROUND")
background.inputs["Color"].default_value = (0.05, 0.05, 0.05, 1.0)
scene.cycles.samples = 4  # enough for the left/right comparison, and quick
scene.render.filepath = str(Path(args.output).with_name(Path(args.output).stem + "_lit.exr"))
bpy.ops.render.render(write_still=True)
print(f"rendered lit with {scene.render.engine}")
for name in UNBUNDLED:  # after imports of every format and two renders
    print(f"{name}: {'imported' if name in sys.modules else 'not imported'}")
try:  # the add-on lives under bl_ext.*: no top-level name may leak from the zip
    import splat_tracer  # noqa: F401
    sys.exit("splat_tracer is importable as a top-level module")
except ModuleNotFoundError:
    pass
