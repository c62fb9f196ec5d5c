"""An image's pixels as Blender holds them, and the one rule by which they become scene
linear: for material Image Textures (nodes.py) and the world's Environment Textures
(world.py) alike.

The rule, measured with Blender 5.0.1 and Cycles (a 16-bit PNG and an EXR tagged sRGB, a
generated float image; Closest and Linear lookups in a material and in a world):
- A float image's `pixels` are scene linear whatever its colour space: Blender converts a
  float buffer when it loads it (a 16-bit PNG tagged sRGB reads decoded). Cycles renders
  those very values at pixel centres; when the image is tagged sRGB it interpolates them
  sRGB-encoded and decodes after (between pixels darker than a linear interpolation), so
  they are handed on re-encoded, to be decoded after interpolation.
- A byte image's `pixels` are its bytes / 255 in its colour space: sRGB ones are decoded
  after interpolation, as Cycles does; the linear spaces are used as they are.
- Another colour space (AgX Log, Filmic, ...) is not converted: bytes are read as sRGB,
  floats as scene linear (Blender converted them), said once.
"""
from __future__ import annotations

from typing import NamedTuple, Optional

import numpy as np

from ...util.colour import linear_to_srgb, srgb_to_linear

# The colour spaces read exactly: sRGB, and the linear ones that are the scene's linear
# space (Blender's default, Rec. 709) or data.
SRGB = ("sRGB",)
LINEAR = ("Linear Rec.709", "Linear", "Non-Color", "Raw", "Generic Data", "Linear Rec.709 (sRGB)")


class Pixels(NamedTuple):
    """(height, width, 4) float32 RGBA, bottom row first (Blender's order); the colour
    sRGB-encoded when `srgb` (to be decoded after interpolation, decode()), else scene linear."""
    values: np.ndarray
    srgb: bool


def read(image, say) -> Optional[Pixels]:
    """`image`'s pixels by the rule above (None when Blender has none: it cannot load it).
    `say(text)` reports, once per call, a colour space that is not read exactly."""
    if not _loaded(image):
        return None
    w, h = image.size
    channels = image.channels
    flat = np.empty(w * h * channels, np.float32)
    image.pixels.foreach_get(flat)
    px = flat.reshape(h, w, channels)
    if channels != 4:  # Blender's grey or RGB buffers: as RGBA, opaque
        rgb = px[..., :1].repeat(3, -1) if channels == 1 else px[..., :3]
        px = np.concatenate([rgb, np.ones((h, w, 1), np.float32)], axis=-1)
    space = image.colorspace_settings.name
    if space not in SRGB + LINEAR:
        say(f": image '{image.name}' is in the '{space}' colour space, read as "
            f"{'scene linear' if image.is_float else 'sRGB'}")
    if image.is_float:
        if space in SRGB:  # interpolated encoded, as Cycles does
            px[..., :3] = linear_to_srgb(px[..., :3])
            return Pixels(px, True)
        return Pixels(px, False)
    return Pixels(px, space not in LINEAR)


def decode(rgb: np.ndarray, srgb: bool) -> np.ndarray:
    """Colour looked up in Pixels.values (interpolated or not) -> scene linear. A negative
    encoded value (a float image's) decodes to 0, as Cycles' color_srgb_to_linear and the
    core's decoder (nodes/image.cpp) give it."""
    return srgb_to_linear(np.maximum(rgb, 0.0)) if srgb else rgb


def _loaded(image) -> bool:
    """Whether Blender has the image's pixels, asking it to load them (from disk or its packed
    copy) when it has not yet."""
    w, h = image.size
    if not w or not h:
        return False
    if image.source == "FILE" and not image.has_data:
        try:
            image.pixels[0]  # reading a pixel loads the buffer
        except (IndexError, RuntimeError):
            return False
        if not image.has_data:
            return False
    w, h = image.size
    return len(image.pixels) == w * h * image.channels > 0
