"""Frame time of a lit scene, beside Cycles in the same run, and what each skip saves.

    python -m benchmarks.frame_time [--quick] [--output DIR]

The scene: the bunny's 35,947-point vertex cloud (the paper's cloud; a 36k-point sphere when
../shared is absent) standing on a mesh floor, one sun lamp with shadows, a grey sky. Both
engines render it through Blender (import, export, render, EXR written), at 1 and 16
samples per pixel, 640x480 (320x240 with --quick); Cycles renders the same cloud the way
Blender users do today: the importer's Mesh to Points spheres, denoising off.

Then the skips (issue #7): the same frame with the features a scene does not use left out,
with the core's own counters beside the time, to show that a scene pays only for what it
uses: no lamp (no shadow rays), an open cloud (no far phase), flat splats (no
interpolation), and with every pass enabled (pass work only when asked for).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from benchmarks import meshes

HERE = Path(__file__).resolve().parent


def bunny_cloud():
    path = meshes.SHARED_MESHES / "stanford-bunny.obj"
    if path.is_file():
        v, t = meshes.read_obj(path)
        c, n = meshes.vertex_cloud(v, t)
        return "bunny vertex cloud", c, n
    v, t = meshes.icosphere(6)
    c, n = meshes.vertex_cloud(v, t)
    return "icosphere stand-in (no ../shared)", c, n


def build(bpy, ply_path: Path, centres: np.ndarray):
    """The scene: cloud on a floor under a sun, a sky, a camera framing the cloud."""
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    bpy.ops.splat_tracer.import_cloud(filepath=str(ply_path))
    cloud = bpy.context.active_object
    lo, hi = centres.min(axis=0), centres.max(axis=0)
    size = float(np.max(hi - lo))
    bpy.ops.mesh.primitive_plane_add(size=6 * size, location=(float((lo[0] + hi[0]) / 2),
                                                              float((lo[1] + hi[1]) / 2), float(lo[2])))
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    sun.data.energy = 3.0
    sun.data.angle = math.radians(3.0)
    sun.rotation_euler = (math.radians(35), 0.0, math.radians(40))
    scene.collection.objects.link(sun)
    scene.world = bpy.data.worlds.new("World")
    scene.world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.3, 0.35, 0.4, 1.0)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(cam)
    centre = (lo + hi) / 2
    eye = centre + size * np.array([0.9, -2.2, 0.9])
    fwd = (centre - eye) / np.linalg.norm(centre - eye)
    from mathutils import Vector

    cam.location = Vector(eye.tolist())
    cam.rotation_euler = Vector(fwd.tolist()).to_track_quat("-Z", "Y").to_euler()
    cam.data.lens = 45
    scene.camera = cam
    scene.view_settings.view_transform = "Standard"
    scene.cycles.device = "CPU"
    scene.cycles.use_denoising = False
    scene.cycles.use_adaptive_sampling = False
    scene.cycles.diffuse_bounces = 1  # the same light paths for both engines
    return scene, cloud, sun


def frame(bpy, scene, engine: str, samples: int, path: Path, session) -> dict:
    from tests.support.blender_helpers import render_to_exr

    scene.render.engine = engine
    scene.cycles.samples = samples
    t0 = time.perf_counter()
    render_to_exr(bpy, scene, path, *scene_size(scene), passes=False)
    seconds = time.perf_counter() - t0
    stats = dict(session.HISTORY[-1]) if engine == "SPLAT_TRACER" else {}
    return {"engine": engine, "samples": samples, "seconds": seconds, "stats": stats}


def read_rgb(path: Path) -> np.ndarray:
    import OpenEXR

    exr = OpenEXR.File(str(path), separate_channels=True)
    channels = {}
    for part in exr.parts:
        channels.update(part.channels)
    names = sorted(k for k in channels if k.endswith("Combined.R") or k.endswith("Combined.G") or
                   k.endswith("Combined.B"))
    return np.stack([channels[n].pixels for n in names], axis=-1).astype(np.float64)


def scene_size(scene):
    return scene.render.resolution_x, scene.render.resolution_y


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="320x240, one round (CI)")
    ap.add_argument("--output", default=str(HERE / "results"))
    args = ap.parse_args(argv)
    out_dir = Path(args.output)
    out_dir.mkdir(parents=True, exist_ok=True)
    work = HERE.parent / "build" / "frame_time"
    work.mkdir(parents=True, exist_ok=True)

    from tools import dev_extension

    dev_extension.isolate_user_dirs(str(work / "blender_user"))
    import bpy

    dev_extension.enable_from_source(work)
    from tests.support.blender_helpers import extension_module
    from splat_tracer.pointcloud.readers import ply

    session = extension_module("blender.session")
    name, centres, normals = bunny_cloud()
    ply_path = work / "cloud.ply"
    ply.write_ply(str(ply_path), centres, normals)
    scene, cloud, sun = build(bpy, ply_path, centres)
    # The paper treats its bunny cloud as closed (the far phase applies); the importer's guess
    # calls it open because of the holes in its base.
    cloud.splat_tracer.closed = True
    width, height = (320, 240) if args.quick else (640, 480)
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = width, height, 100

    def median_frames(label: str, samples: int, rounds: int) -> list:
        """Each engine's frame of median wall time over `rounds` rounds, the engines
        interleaved (a change in the shared machine's load then falls on both)."""
        runs = {"SPLAT_TRACER": [], "CYCLES": []}
        for _ in range(rounds):
            for engine, got in runs.items():
                got.append(frame(bpy, scene, engine, samples, work / f"{engine}_{samples}.exr", session))
        out = []
        for engine, got in runs.items():
            r = sorted(got, key=lambda f: f["seconds"])[len(got) // 2] | {"case": label, "rounds": rounds}
            out.append(r)
            print(f"{label}: {engine:13s} {samples:2d} spp: {r['seconds']:.2f} s (median of {rounds})", flush=True)
        return out

    # 1-sample frames take a fraction of a second: medians of 5 rounds; 16 samples: one.
    rows = median_frames("scene", 1, 1 if args.quick else 5) + median_frames("scene", 16, 1)
    # The floor under any frame through Blender: the same camera, world and resolution with
    # every object hidden (the render pipeline, the film, the EXR; for Cycles its session).
    hidden = [ob for ob in scene.objects if ob.type != "CAMERA" and not ob.hide_render]
    for ob in hidden:
        ob.hide_render = True
    rows += median_frames("nothing to render (camera and world only)", 1, 1 if args.quick else 5)
    for ob in hidden:
        ob.hide_render = False

    # What each skip saves: the same 1-sample frame with a feature the scene does not use.
    skips = []

    def skip_row(label: str):
        # Best of three: these frames take a fraction of a second, and the machine's timing
        # varies by about +-25 % from one run to the next.
        r = min((frame(bpy, scene, "SPLAT_TRACER", 1, work / "skip.exr", session) for _ in range(3)),
                key=lambda f: f["stats"]["render_seconds"])
        s = r["stats"]
        skips.append({"case": label, "seconds": r["seconds"], "render_seconds": s["render_seconds"],
                      "shadow_rays": s["shadow_rays"], "layer_queries": s["layer_queries"],
                      "far_rejections": s["far_rejections"], "interpolations": s["interpolations"],
                      "diffuse_rays": s["diffuse_rays"]})
        print(f"skip: {label:40s} {r['seconds']:.2f} s  {s['render_seconds']:.3f} s rendering", flush=True)

    skip_row("full scene (lamp, closed cloud, interpolation)")
    sun.hide_render = True
    skip_row("no lamp (sky only)")
    sun.hide_render = False
    cloud.splat_tracer.closed = False
    skip_row("cloud marked open (no far phase)")
    cloud.splat_tracer.closed = True
    scene.splat_tracer.use_normal_interpolation = False
    skip_row("flat splats (no interpolation)")
    scene.splat_tracer.method = "FULL"
    layer = scene.view_layers[0]
    for prop in ("use_pass_z", "use_pass_normal", "use_pass_diffuse_color", "use_pass_emit", "use_pass_shadow",
                 "use_pass_object_index"):
        setattr(layer, prop, True)
    layer.splat_tracer.use_pass_splat_count = True
    skip_row("every pass enabled")

    # Sky light: diffuse bounces or ambient occlusion, against a converged Cycles render of the
    # same sky-lit scene (sun hidden): error of the floor and cloud per time.
    sun.hide_render = True
    for prop in ("use_pass_z", "use_pass_normal", "use_pass_diffuse_color", "use_pass_emit", "use_pass_shadow",
                 "use_pass_object_index"):
        setattr(layer, prop, False)
    layer.splat_tracer.use_pass_splat_count = False
    reference_samples = 64 if args.quick else 256
    ref = frame(bpy, scene, "CYCLES", reference_samples, work / "sky_reference.exr", session)
    reference = read_rgb(work / "sky_reference.exr")
    sky = []
    for mode, ao in (("diffuse bounce", False), ("ambient occlusion, 1 ray", True), ("ambient occlusion, 4 rays", True)):
        scene.splat_tracer.sky_light = "AO" if ao else "BOUNCE"
        scene.splat_tracer.ao_samples = 4 if "4" in mode else 1
        r = frame(bpy, scene, "SPLAT_TRACER", 16, work / "sky.exr", session)
        img = read_rgb(work / "sky.exr")
        err = float(np.mean(np.abs(img - reference)) / np.mean(reference))
        bias = float(np.mean(img) / np.mean(reference) - 1)
        sky.append({"mode": mode, "samples": 16, "seconds": r["seconds"], "render_seconds": r["stats"]["render_seconds"],
                    "mean_abs_error": err, "brightness_bias": bias})
        print(f"sky light: {mode:28s} {r['seconds']:.2f} s, error {100 * err:.1f} %, bias {100 * bias:+.1f} %")
    scene.splat_tracer.sky_light = "BOUNCE"

    report = {"cloud": name, "splats": len(centres), "size": [width, height], "threads": scene.render.threads,
              "frames": [{k: v for k, v in r.items() if k != "stats"} | {
                  "render_seconds": r["stats"].get("render_seconds"), "build_seconds": r["stats"].get("build_seconds")}
                  for r in rows], "skips": skips, "sky_light": sky,
              "sky_reference": {"samples": reference_samples, "seconds": ref["seconds"]}}
    (out_dir / "frame_time.json").write_text(json.dumps(report, indent=1))
    lines = [f"# Frame time: {name} ({len(centres):,} splats) on a mesh floor, one sun with shadows, sky light",
             "", f"{width}x{height}, 2 threads, wall time of `bpy.ops.render.render` (export, build, render, EXR);",
             f"1-sample frames: the median of {rows[0]['rounds']} round(s), the engines interleaved.",
             "", "| scene | engine | samples | frame (s) | of which rendering (s) |", "|---|---|---:|---:|---:|"]
    for r in rows:
        rs = r["stats"].get("render_seconds")
        lines.append(f"| {r['case']} | {'Splat Tracer' if r['engine'] == 'SPLAT_TRACER' else 'Cycles (points as spheres)'}"
                     f" | {r['samples']} | {r['seconds']:.3f} | {'' if rs is None else f'{rs:.3f}'} |")
    lines += ["", "## What each skip saves (1 sample)", "",
              "| case | frame (s) | rendering (s) | shadow rays | layer queries | far-phase rejections | "
              "interpolated points |", "|---|---:|---:|---:|---:|---:|---:|"]
    for s in skips:
        lines.append(f"| {s['case']} | {s['seconds']:.2f} | {s['render_seconds']:.3f} | {s['shadow_rays']:,} | "
                     f"{s['layer_queries']:,} | {s['far_rejections']:,} | {s['interpolations']:,} |")
    lines += ["", f"## Sky light: diffuse bounce or ambient occlusion (16 samples; sun hidden)", "",
              f"Error: mean absolute difference from Cycles at {reference_samples} samples "
              f"({ref['seconds']:.1f} s), relative to its mean; bias: mean brightness against it.", "",
              "| sky light | frame (s) | rendering (s) | error | bias |", "|---|---:|---:|---:|---:|"]
    for s in sky:
        lines.append(f"| {s['mode']} | {s['seconds']:.2f} | {s['render_seconds']:.2f} | "
                     f"{100 * s['mean_abs_error']:.1f} % | {100 * s['brightness_bias']:+.1f} % |")
    (out_dir / "frame_time.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
