"""A/B comparison of two visibility settings on the current frame (the paper's image
differencing, Figs. 13-14): images A, B and their difference, in the UI or headless."""
from __future__ import annotations

import os

import bpy
import numpy as np

from ..splat_tracer import core
from ..splat_tracer.session import render_frame

_CHOICES = tuple((p, p.replace("_", " ").title(), f"The {p.replace('_', ' ').lower()} preset")
                 for p in core.PRESETS) + (("SCENE", "Scene Settings", "The scene's current visibility settings"),)
IMAGE_NAMES = ("Splat Compare A", "Splat Compare B", "Splat Compare Difference")
_TOGGLES = (("NONE", "None", "Compare the A and B settings"),
            ("use_wrong_hit_elimination", "Wrong Hit Elimination", "The scene's settings without and with it"),
            ("use_normal_interpolation", "Normal Interpolation", "The scene's settings without and with it"),
            ("use_far_phase", "Far Phase", "The scene's settings without and with it"),
            ("use_near_phase", "Near Phase", "The scene's settings without and with it"),
            ("use_nearest_centre", "Nearest Centre", "The scene's settings without and with it"))


def _method(choice: str, scene) -> core.Method:
    settings = scene.splat_tracer
    if choice == "SCENE":
        return settings.core_method()
    return core.Method.preset(choice, epsilon=settings.epsilon, kernel=settings.kernel,
                              crease_angle=settings.core_method().crease_angle)


def _store_image(name: str, rgba_top_first: np.ndarray) -> bpy.types.Image:
    h, w = rgba_top_first.shape[:2]
    image = bpy.data.images.get(name)
    if image is not None and (tuple(image.size) != (w, h) or not image.is_float):
        bpy.data.images.remove(image)
        image = None
    if image is None:
        image = bpy.data.images.new(name, w, h, alpha=True, float_buffer=True)
    image.pixels.foreach_set(np.ascontiguousarray(rgba_top_first[::-1], dtype=np.float32).ravel())
    image.update()
    return image


def difference_image(a: np.ndarray, b: np.ndarray, threshold: float) -> tuple[np.ndarray, np.ndarray]:
    """(RGBA difference image, mask of differing pixels). A pixel differs when any channel,
    alpha included, differs by more than `threshold`; its grey level is the largest channel
    difference, scaled so that the largest in the image is white."""
    delta = np.abs(a - b).max(axis=2)
    mask = delta > threshold
    scale = delta.max() if delta.max() > 0 else 1.0
    grey = delta / scale
    return np.dstack([grey, grey, grey, np.ones_like(grey)]).astype(np.float32), mask


class SPLAT_TRACER_OT_compare(bpy.types.Operator):
    """Render the current frame with two visibility settings and show A, B and their difference"""

    bl_idname = "splat_tracer.compare"
    bl_label = "Compare A/B"
    bl_options = {"REGISTER"}

    a: bpy.props.EnumProperty(name="A", items=_CHOICES, default="GENERAL",
                              description="Settings of image A (default: no visibility correction)")
    b: bpy.props.EnumProperty(name="B", items=_CHOICES, default="FULL",
                              description="Settings of image B (default: the full method)")
    toggle: bpy.props.EnumProperty(name="Toggle", items=_TOGGLES, default="NONE",
                                   description="Instead of A and B: the scene's settings with this switch off (A) "
                                               "and on (B)")
    shading: bpy.props.EnumProperty(
        name="Shading",
        items=(("HEADLIGHT", "Headlight", "Base colours lit from the eye: only what the visibility settings change "
                                          "differs, with no sampling noise"),
               ("SCENE", "Scene", "The scene's lamps, materials and world, as F12 renders them (the same samples "
                                  "and seed for A and B, so only what the settings change differs)")),
        default="HEADLIGHT", description="How A and B are lit",
    )
    threshold: bpy.props.FloatProperty(name="Threshold", default=1e-3, min=0.0,
                                       description="A pixel differs when a channel changes by more than this")
    directory: bpy.props.StringProperty(name="Save To", subtype="DIR_PATH", default="",
                                        description="When set, A, B and the difference are also saved here as PNG")
    differing_pixels: bpy.props.IntProperty(name="Differing Pixels", options={"SKIP_SAVE"},
                                            description="Result: how many pixels differ")

    @classmethod
    def poll(cls, context):
        return context.scene is not None and context.scene.camera is not None

    def execute(self, context):
        depsgraph = context.evaluated_depsgraph_get()
        scene = context.scene
        if self.toggle == "NONE":
            methods = [_method(choice, scene) for choice in (self.a, self.b)]
            names = (self.a, self.b)
        else:
            methods = [scene.splat_tracer.core_method(**{self.toggle: value}) for value in (False, True)]
            names = (f"{self.toggle} off", "on")
        try:
            headlight = True if self.shading == "HEADLIGHT" else None
            frames = [render_frame(depsgraph, m, use_border=False, headlight=headlight) for m in methods]
        except Exception as e:  # noqa: BLE001 - every failure is reported to the user
            self.report({"ERROR"}, f"Splat Tracer compare: {e}")
            return {"CANCELLED"}
        for line in frames[0].report.lines:
            self.report({"WARNING"}, f"Splat Tracer: {line}")
        a, b = (f.passes["Combined"] for f in frames)
        diff, mask = difference_image(a, b, self.threshold)
        images = [_store_image(name, pixels) for name, pixels in zip(IMAGE_NAMES, (a, b, diff))]
        if self.directory:
            os.makedirs(bpy.path.abspath(self.directory), exist_ok=True)
            for image, suffix in zip(images, ("a", "b", "difference")):
                image.filepath_raw = os.path.join(bpy.path.abspath(self.directory), f"compare_{suffix}.png")
                image.file_format = "PNG"
                image.save()
        self.differing_pixels = int(mask.sum())
        if context.area is not None and context.area.type == "IMAGE_EDITOR":
            context.area.spaces.active.image = images[2]
        self.report({"INFO"}, f"{self.differing_pixels:,} of {mask.size:,} pixels differ "
                              f"({100.0 * self.differing_pixels / mask.size:.2f} %) between {names[0]} and {names[1]}")
        return {"FINISHED"}
