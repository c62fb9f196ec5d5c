"""A/B comparison of two visibility settings on the current frame (the paper's image
differencing, Figs. 13-14): images A, B and their difference, in the UI or headless.

A and B are rendered like F12 (the render border honoured, cropped when the scene crops) and
saved through the scene's colour management; the Difference image is the fixed perceptual
scale of splat_tracer/render/difference.py between what A and B show, with its legend
below it."""
from __future__ import annotations

import contextlib
import os
import tempfile

import bpy
import numpy as np

from ..splat_tracer.blender.session import render_frame
from ..splat_tracer.render import ab, difference
from ..splat_tracer.render.method import PRESETS, SWITCHES, Method

_CHOICES = tuple((p, p.replace("_", " ").title(), f"The {p.replace('_', ' ').lower()} preset")
                 for p in PRESETS) + (("SCENE", "Scene Settings", "The scene's current visibility settings"),)
IMAGE_NAMES = ("Splat Compare A", "Splat Compare B", "Splat Compare Difference")
# One item per switch of the switch table; the identifiers are the switches' properties.
_TOGGLES = (("NONE", "None", "Compare the A and B settings"),) + tuple(
    (switch.prop, switch.label, "The scene's settings without and with it") for switch in SWITCHES)


def _method(choice: str, scene) -> Method:
    settings = scene.splat_tracer
    if choice == "SCENE":
        return settings.core_method()
    return Method.preset(choice, epsilon=settings.epsilon, kernel=settings.kernel,
                         crease_angle=settings.core_method().crease_angle)


def _store_image(name: str, rgba_top_first: np.ndarray, float_buffer: bool = True) -> bpy.types.Image:
    """An image of these pixels: float (scene-linear, shown through the view transform) or
    byte (display values, stored and saved as they are)."""
    h, w = rgba_top_first.shape[:2]
    image = bpy.data.images.get(name)
    if image is not None and (tuple(image.size) != (w, h) or image.is_float != float_buffer):
        bpy.data.images.remove(image)
        image = None
    if image is None:
        image = bpy.data.images.new(name, w, h, alpha=True, float_buffer=float_buffer)
    image.pixels.foreach_set(np.ascontiguousarray(rgba_top_first[::-1], dtype=np.float32).ravel())
    image.update()
    return image


@contextlib.contextmanager
def _png_output(scene):
    """The scene's output set to 8-bit RGBA PNG following the scene's colour management, for
    the duration (restored after, whatever happens)."""
    settings = scene.render.image_settings
    # Restored in this order: the media type decides which file formats are allowed.
    keys = ("media_type", "file_format", "color_mode", "color_depth", "color_management")
    saved = [(k, getattr(settings, k)) for k in keys if hasattr(settings, k)]
    try:
        for key, value in (("media_type", "IMAGE"), ("file_format", "PNG"), ("color_mode", "RGBA"),
                           ("color_depth", "8"), ("color_management", "FOLLOW_SCENE")):
            if hasattr(settings, key):
                setattr(settings, key, value)
        yield
    finally:
        for key, value in saved:
            setattr(settings, key, value)


def _save_as_render(image, scene, path: str) -> np.ndarray:
    """Saves a scene-linear image as an 8-bit PNG through the scene's colour management (view
    transform, look, exposure, gamma, display: what the Image Editor shows of a render) and
    returns those display values, (h, w, 4) in 0..1, top row first."""
    with _png_output(scene):
        image.save_render(path, scene=scene)
    saved = bpy.data.images.load(path, check_existing=False)
    try:
        w, h = saved.size
        buf = np.empty(w * h * 4, np.float32)
        saved.pixels.foreach_get(buf)  # a byte image: its stored (display) values, unconverted
    finally:
        bpy.data.images.remove(saved)
    return buf.reshape(h, w, 4)[::-1]


def difference_of(display_a: np.ndarray, display_b: np.ndarray, linear_a: np.ndarray, linear_b: np.ndarray,
                  threshold: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(RGBA difference image with its legend, ΔE per pixel, mask of differing pixels).

    The image is the fixed perceptual scale (splat_tracer/render/difference.py) of the ΔE
    between the display values of A and B seen over black; a pixel *differs* when any scene-linear
    channel, alpha included, changes by more than `threshold` (which also counts differences
    too small to see)."""
    over_black = lambda d: d[..., :3] * d[..., 3:4]  # noqa: E731 - straight alpha in a PNG
    image, de = difference.difference_image(over_black(display_a), over_black(display_b))
    return image, de, np.abs(linear_a - linear_b).max(axis=2) > threshold


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
            # Not denoised: the comparison is of the two methods' surfaces, which a denoiser
            # would smooth alike.
            frames = [render_frame(depsgraph, m, headlight=headlight, denoised=False) for m in methods]
        except Exception as e:  # noqa: BLE001 - every failure is reported to the user
            self.report({"ERROR"}, f"Splat Tracer compare: {e}")
            return {"CANCELLED"}
        for line in frames[0].report.lines:
            self.report({"WARNING"}, f"Splat Tracer: {line}")
        a, b = (_placed(f, scene.render) for f in frames)
        images = [_store_image(name, pixels) for name, pixels in zip(IMAGE_NAMES[:2], (a, b))]
        for image in images:
            image.use_view_as_render = True  # the Image Editor shows them as it shows a render
        directory = bpy.path.abspath(self.directory) if self.directory else None
        with tempfile.TemporaryDirectory(prefix="splat_compare_") as scratch:
            if directory:
                os.makedirs(directory, exist_ok=True)
            folder = directory or scratch
            display = [_save_as_render(image, scene, os.path.join(folder, f"compare_{suffix}.png"))
                       for image, suffix in zip(images, ("a", "b"))]
        diff, de, mask = difference_of(*display, a, b, self.threshold)
        diff_image = _store_image(IMAGE_NAMES[2], diff, float_buffer=False)
        if directory:
            diff_image.filepath_raw = os.path.join(directory, "compare_difference.png")
            diff_image.file_format = "PNG"
            diff_image.save()
        stats = frames[0].stats
        notes = ab.ineffective_differences(*methods, clouds=stats["clouds"], closed_clouds=stats["closed_clouds"],
                                           headlight=stats["headlight"])
        x0, y0, w, h = frames[0].window
        total = w * h  # the pixels rendered: the border's, when one is set
        self.differing_pixels = int(mask.sum())
        visible = int((de >= difference.VISIBLE).sum())
        diff_image["splat_tracer_differing_pixels"] = self.differing_pixels
        diff_image["splat_tracer_visible_pixels"] = visible
        diff_image["splat_tracer_notes"] = "\n".join(notes)
        if context.area is not None and context.area.type == "IMAGE_EDITOR":
            context.area.spaces.active.image = diff_image
        for note in notes:
            self.report({"WARNING"}, f"Splat Tracer compare: {note}")
        border = " inside the render border" if scene.render.use_border else ""
        self.report({"INFO"}, f"{self.differing_pixels:,} of {total:,} pixels{border} differ "
                              f"({100.0 * self.differing_pixels / total:.2f} %), {visible:,} visibly "
                              f"(dE >= {difference.VISIBLE:g}), between {names[0]} and {names[1]}")
        return {"FINISHED"}


def _placed(frame, render) -> np.ndarray:
    """A frame's Combined pass as Blender shows a render: the border's pixels alone when it
    is cropped to the border, else in place in the full frame (transparent around it)."""
    pixels = frame.passes["Combined"]
    if not render.use_border or render.use_crop_to_border:
        return pixels
    x0, y0, w, h = frame.window
    full = np.zeros((frame.height, frame.width, 4), np.float32)
    full[y0:y0 + h, x0:x0 + w] = pixels
    return full
