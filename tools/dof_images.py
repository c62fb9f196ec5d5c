"""Renders the depth-of-field pair of docs/user-guide.md: one scene with the camera's Depth of
Field on, by Splat Tracer and by Cycles at equal samples (issue 25: "README/docs show a
depth-of-field ... render beside Cycles'").

    python -m tools.dof_images                  (writes docs/depth-of-field.png and
                                                 docs/depth-of-field_cycles.png, prints both times)

The scene: Suzanne's scan (a cloud, as tools/demo.py makes it) in focus; a mesh sphere before
it, near the camera, and a cloud sphere far behind it, both out of focus; a checkered floor
whose tiles show the blur growing with the distance from the plane in focus. A sun and a sky
as in the demo; diffuse materials only, so that the two images differ by the depth of field's
blur and the clouds' shape (discs here, Mesh to Points spheres in Cycles), not by caustics.
Both engines render with the same settings: SAMPLES samples, adaptive sampling and denoising
off, the camera's Depth of Field as an artist sets it for Cycles.
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
from pathlib import Path

from tools import demo, dev_extension

BUILD = dev_extension.REPO_ROOT / "build" / "dof_images"
DOCS = dev_extension.REPO_ROOT / "docs"
SAMPLES = 64
# The camera: 50 mm at f/0.5 focused on Suzanne 4 m away. An f-stop this open is what makes the
# blur plain at 320x240: the sphere 1.9 m before the plane of focus blurs over about 11 px,
# the ball 8 m away over about 6 px (circle of confusion = aperture x focal length x
# |distance - focus| / (distance x (focus - focal length)), on a 36 mm sensor).
LENS_MM, FSTOP, FOCUS = 50.0, 0.5, 4.0


def build_scene(bpy, width: int, height: int):
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    positions, normals = demo.suzanne_cloud(bpy, 3)
    clouds = [("Suzanne", positions * 0.5 + (0.0, 0.0, 0.5), normals, (0.8, 0.42, 0.2, 1)),  # 1.4 m wide
              ("Far Ball", *demo.sphere_cloud(20_000, 0.6, (1.3, 4.0, 0.6)), (0.2, 0.6, 0.25, 1))]
    for name, pos, nrm, colour in clouds:
        demo.import_cloud(bpy, BUILD, name, pos, nrm,
                          demo.principled(bpy, name, **{"Base Color": colour, "Roughness": 0.5}))
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.35, location=(-0.45, -2.1, 0.35), segments=48, ring_count=24)
    near = bpy.context.active_object
    near.name = "Near Sphere"
    bpy.ops.object.shade_smooth()
    near.data.materials.append(demo.principled(bpy, "Blue", **{"Base Color": (0.15, 0.3, 0.8, 1), "Roughness": 0.4}))
    demo.checker_floor(bpy, 24.0, 24)

    demo.sun_and_sky(bpy, scene)

    # Looking along +Y, a little down.
    cam = demo.add_camera(bpy, scene, (0.0, -FOCUS, 0.8), (88, 0, 0), LENS_MM, width, height)
    dof = cam.data.dof
    dof.use_dof = True
    dof.focus_distance = FOCUS
    dof.aperture_fstop = FSTOP
    demo.equal_samples(scene, SAMPLES)
    scene.cycles.diffuse_bounces = 1  # the same light paths for both engines (as the demo)
    return scene


def main(argv=None) -> int:
    global SAMPLES
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--output", default=str(DOCS / "depth-of-field.png"))
    ap.add_argument("--cycles", default=str(DOCS / "depth-of-field_cycles.png"))
    ap.add_argument("--width", type=int, default=320)
    ap.add_argument("--height", type=int, default=240)
    ap.add_argument("--samples", type=int, default=SAMPLES, help="samples per pixel, for both engines")
    ap.add_argument("--runs", type=int, default=1,
                    help="renders of each engine, alternating (the machine's load falls on both alike): "
                         "median and spread of the wall times")
    args = ap.parse_args(argv)
    SAMPLES = args.samples

    BUILD.mkdir(parents=True, exist_ok=True)
    dev_extension.isolate_user_dirs(str(BUILD / "blender_user"))
    import bpy

    dev_extension.enable_from_source(BUILD)
    scene = build_scene(bpy, args.width, args.height)
    setting = (f"{args.width}x{args.height}, {SAMPLES} samples, {LENS_MM:g} mm at f/{FSTOP:g} focused at "
               f"{FOCUS:g} m")
    engines = (("SPLAT_TRACER", "Splat Tracer", args.output), ("CYCLES", "Cycles (the clouds as spheres)", args.cycles))
    times = {engine: [] for engine, _, _ in engines}
    for _ in range(max(1, args.runs)):
        for engine, _, output in engines:
            times[engine].append(demo.render(bpy, scene, engine, Path(output).resolve()))
    for engine, label, output in engines:
        t = times[engine]
        spread = f" (median of {len(t)}, {min(t):.2f}-{max(t):.2f})" if len(t) > 1 else ""
        print(f"dof_images: {label}, {setting}: {statistics.median(t):.2f} s{spread} -> {output}")
    print(f"dof_images: load average (1, 5, 15 min) {', '.join(f'{x:.1f}' for x in os.getloadavg())} "
          f"on {os.cpu_count()} CPUs")
    return 0


if __name__ == "__main__":
    sys.exit(main())
