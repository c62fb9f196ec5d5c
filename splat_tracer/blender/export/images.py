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
DATA = ("Non-Color", "Raw", "Generic Data")  # of LINEAR: values, not colours


class Pixels(NamedTuple):
    """(height, width, 4) float32 RGBA, bottom row first (Blender's order); the colour
    sRGB-encoded when `srgb` (to be decoded after interpolation, decode()), else scene linear.
    `is_float`: a float image (else bytes / 255)."""
    values: np.ndarray
    srgb: bool
    is_float: bool = False


def read(image, say) -> Optional[Pixels]:
    """`image`'s pixels by the rule above (None when Blender has none: it cannot load it).
    `say(text)` reports, once per call, a colour space that is not read exactly."""
    if not _loaded(image):
        return None
    w, h = image.size
    channels = image.channels
    flat = np.empty(w * h * channels, np.float32)
    image.pixels.foreach_get(flat)
    return _by_rule(flat.reshape(h, w, channels), image.is_float, image.colorspace_settings.name, image.name, say)


def _by_rule(px: np.ndarray, is_float: bool, space: str, name: str, say) -> Pixels:
    """Pixels as Blender holds them ((h, w, channels), bottom row first) -> Pixels."""
    h, w, channels = px.shape
    if channels != 4:  # Blender's grey or RGB buffers: as RGBA, opaque
        rgb = px[..., :1].repeat(3, -1) if channels == 1 else px[..., :3]
        px = np.concatenate([rgb, np.ones((h, w, 1), np.float32)], axis=-1)
    if space not in SRGB + LINEAR:
        say(f": image '{name}' is in the '{space}' colour space, read as "
            f"{'scene linear' if is_float else 'sRGB'}")
    if is_float:
        if space in SRGB:  # interpolated encoded, as Cycles does
            px[..., :3] = linear_to_srgb(px[..., :3])
            return Pixels(px, True, True)
        return Pixels(px, False, True)
    return Pixels(px, space not in LINEAR)


def read_file(path: str, space: str, name: str, say, alpha_mode: str = "STRAIGHT") -> Optional[Pixels]:
    """The image file at `path` (a UDIM tile, a frame of a sequence) read as Blender would
    load it into an image in colour space `space`, then by the rule above -- without
    creating a Blender image: this runs inside a render, where adding and removing IDs is not
    thread-safe. Read with OpenImageIO, which Blender ships (and loads these files with);
    None when the file cannot be read or OpenImageIO is not there.

    What Blender's load does, measured with Blender 5.0.1 (its `pixels` beside these, for
    8-bit PNG, JPEG and Targa, 16-bit PNG and TIFF, float EXR): an 8-bit file gives its
    stored bytes, alpha straight; a deeper one becomes floats converted from `space` to
    scene linear with alpha premultiplied (a straight-alpha file's colour decoded then
    multiplied by alpha; a premultiplied one's divided by alpha first), except in a data
    space (Non-Color), where the values are left as stored. Which of the two the file is
    comes from the image's Alpha mode (`alpha_mode`), as Blender loads it: Straight and
    Premultiplied as said, Channel Packed decoded without touching alpha, None decoded with
    alpha 1; an 8-bit file in a colour space gets alpha 1 under None, and its colour divided
    by alpha (held to 1) under Premultiplied (measured, Blender 5.0.1)."""
    oiio = _oiio()
    if oiio is None:
        say(f": image '{name}': Blender's OpenImageIO module is not available to read '{path}'")
        return None
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)  # the values as stored, as Blender takes them
    source = oiio.ImageInput.open(path, config)
    if source is None:
        oiio.geterror()  # taken, so that OpenImageIO does not print it at exit: the caller says it
        return None
    try:
        spec = source.spec()
        channels = min(spec.nchannels, 4)
        is_float = spec.format != oiio.TypeDesc("uint8")
        px = source.read_image(0, 0, 0, channels, "float")
        if px is None:
            source.geterror()
    finally:
        source.close()
    if px is None or getattr(px, "ndim", 0) != 3 or not px.size:
        return None
    px = np.ascontiguousarray(px[::-1], np.float32)  # bottom row first, as Blender holds it
    if channels == 2:  # grey and alpha
        px = np.concatenate([px[..., :1].repeat(3, -1), px[..., 1:]], axis=-1)
    colour = space not in DATA  # Blender leaves data (non-colour) values alone
    if is_float and px.shape[2] == 4 and colour:
        alpha = px[..., 3:]
        if alpha_mode == "PREMUL":  # premultiplied in the file: the colour apart from alpha first
            px[..., :3] = np.divide(px[..., :3], alpha, out=np.zeros_like(px[..., :3]), where=alpha > 0)
        if space in SRGB:
            px[..., :3] = srgb_to_linear(px[..., :3])
        if alpha_mode in ("STRAIGHT", "PREMUL"):
            px[..., :3] *= alpha
        elif alpha_mode == "NONE":
            px[..., 3] = 1.0
    elif is_float and space in SRGB:
        px[..., :3] = srgb_to_linear(px[..., :3])
    elif not is_float and px.shape[2] == 4 and colour:
        if alpha_mode == "NONE":
            px[..., 3] = 1.0
        elif alpha_mode == "PREMUL":
            alpha = px[..., 3:]
            # Blender un-premultiplies the bytes into bytes: held to 1, rounded to 1/255.
            rgb = np.minimum(np.divide(px[..., :3], alpha, out=np.zeros_like(px[..., :3]), where=alpha > 0), 1.0)
            px[..., :3] = np.round(rgb * 255.0) / 255.0
    return _by_rule(px, is_float, space, name, say)


_OIIO: list = []  # [module or None], once imported


def _oiio():
    """Blender's OpenImageIO module, or None. Blender's Python has it on its path; Blender as
    a Python module (bpy from PyPI) keeps it in the same place, off the path: imported from
    there by file, so that nothing else there is put on the path."""
    if _OIIO:
        return _OIIO[0]
    module = None
    try:
        import OpenImageIO as module  # noqa: N813
    except ImportError:
        import importlib.util
        import os
        import sys

        import bpy

        version = f"python{sys.version_info.major}.{sys.version_info.minor}"
        base = os.path.join(bpy.utils.resource_path("LOCAL"), "python")
        for lib in (os.path.join(base, "lib", version), os.path.join(base, "lib")):
            init = os.path.join(lib, "site-packages", "OpenImageIO", "__init__.py")
            if not os.path.isfile(init):
                continue
            spec = importlib.util.spec_from_file_location("OpenImageIO", init,
                                                      submodule_search_locations=[os.path.dirname(init)])
            try:
                module = importlib.util.module_from_spec(spec)
                sys.modules["OpenImageIO"] = module
                spec.loader.exec_module(module)
            except Exception:  # noqa: BLE001 - any failure: no half-loaded module left for others
                sys.modules.pop("OpenImageIO", None)
                module = None
            break
    _OIIO.append(module)
    return module


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
    if image.source in ("FILE", "TILED") and not image.has_data:  # (a tiled one: its first tile)
        try:
            image.pixels[0]  # reading a pixel loads the buffer
        except (IndexError, RuntimeError):
            return False
        if not image.has_data:
            return False
    w, h = image.size
    return len(image.pixels) == w * h * image.channels > 0
