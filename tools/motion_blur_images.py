"""Renders the motion-blur images of the docs: the demo scene (tools/demo.py) with Suzanne
(a splat cloud) moving to the right and the camera panning a little, Render > Motion Blur on
(a whole-frame shutter, centred), with Splat Tracer and with Cycles from the same settings.

    python -m tools.motion_blur_images --output docs/motion-blur.png --cycles docs/motion-blur_cycles.png
"""
from __future__ import annotations

import argparse
from pathlib import Path

from tools import demo, dev_extension


def animate(bpy, scene):
    """Suzanne moves 1.2 units a frame to the right (linear keys); the camera pans 0.2."""
    def keys(obj, frames):
        for frame, x in frames:
            obj.location.x = x
            obj.keyframe_insert("location", index=0, frame=frame)
        action = obj.animation_data.action
        curves = action.fcurves if hasattr(action, "fcurves") else [
            fc for layer in action.layers for strip in layer.strips for bag in strip.channelbags for fc in bag.fcurves]
        for fc in curves:
            for key in fc.keyframe_points:
                key.interpolation = "LINEAR"
    keys(bpy.data.objects["Suzanne"], ((1, -1.2), (3, 1.2)))
    cam = scene.camera
    keys(cam, ((1, cam.location.x - 0.2), (3, cam.location.x + 0.2)))
    scene.frame_set(2)
    scene.render.use_motion_blur = True
    scene.render.motion_blur_shutter = 1.0
    scene.render.motion_blur_position = "CENTER"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--output", default="motion-blur.png")
    ap.add_argument("--cycles", default=None)
    ap.add_argument("--width", type=int, default=320)
    ap.add_argument("--height", type=int, default=240)
    ap.add_argument("--samples", type=int, default=32)
    args = ap.parse_args(argv)
    demo.BUILD.mkdir(parents=True, exist_ok=True)
    dev_extension.isolate_user_dirs(str(demo.BUILD / "blender_user"))
    import bpy

    dev_extension.enable_from_source(demo.BUILD)
    scene, _ = demo.build_scene(bpy, 2, args.width, args.height)
    animate(bpy, scene)
    scene.cycles.samples = scene.cycles.preview_samples = args.samples
    seconds = demo.render(bpy, scene, "SPLAT_TRACER", Path(args.output).resolve())
    print(f"motion blur: Splat Tracer {seconds:.2f} s -> {args.output}")
    if args.cycles:
        scene.cycles.use_denoising = False
        scene.cycles.use_adaptive_sampling = False
        scene.cycles.device = "CPU"
        seconds = demo.render(bpy, scene, "CYCLES", Path(args.cycles).resolve())
        print(f"motion blur: Cycles {seconds:.2f} s -> {args.cycles}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
