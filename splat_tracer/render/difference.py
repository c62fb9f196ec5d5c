"""A fixed perceptual difference scale for A/B comparisons (no Blender needed).

The difference of two display-referred images (the values a screen shows, after the view
transform) is measured as CIE76 ΔE*ab: the Euclidean distance in CIELAB (sRGB primaries,
D65 white), where about 1 is the smallest difference anyone sees on a patch and 2.3 a
just-noticeable difference (Sharma, *Digital Color Imaging Handbook*, 2003). A fixed colour
ramp over fixed breakpoints (below) maps ΔE to a colour, so the same difference has the same
colour in every comparison: unlike a scale normalised to the image's largest difference,
which paints a one-level change as white as a missing object and makes every difference
image look binary. A legend strip (the ramp and its breakpoints) is drawn with a tiny
built-in bitmap font, so an image carries its own scale.

Used by the compare operator (images through the scene's view transform) and the viewport's
difference overlay (`ab.display_buffer`, through the Standard transform: the viewport's own view
transform is applied by the GPU when drawing, after the buffer is built).
"""
from __future__ import annotations

import numpy as np

from ..util import matrices
from ..util.colour import linear_to_srgb, srgb_to_linear

# ΔE breakpoints and the ramp's colour at each (display sRGB). Chosen to be read at a
# glance: black = identical; dark blue = below the ~1 of a just-visible patch difference;
# blue = a just-noticeable difference (2.3); cyan, green, yellow = clearly visible,
# obvious, large; red = a different surface (50); white = black against white (100).
BREAKPOINTS = (0.0, 1.0, 2.3, 5.0, 10.0, 20.0, 50.0, 100.0)
COLOURS = np.array([(0.0, 0.0, 0.0), (0.10, 0.10, 0.45), (0.15, 0.35, 1.0), (0.0, 0.8, 0.8),
                    (0.2, 0.85, 0.2), (1.0, 0.85, 0.0), (1.0, 0.15, 0.1), (1.0, 1.0, 1.0)], np.float32)
VISIBLE = 2.3  # ΔE of a just-noticeable difference: pixels at or above it "differ visibly"

# sRGB (IEC 61966-2-1) linear RGB -> CIE XYZ, and the D65 white point.
_XYZ_FROM_RGB = np.array([[0.4124564, 0.3575761, 0.1804375],
                          [0.2126729, 0.7151522, 0.0721750],
                          [0.0193339, 0.1191920, 0.9503041]])
_WHITE = np.array([0.95047, 1.0, 1.08883])


def srgb_encode(linear: np.ndarray) -> np.ndarray:
    """The sRGB transfer function (Blender's *Standard* view transform), clipped to 0..1."""
    return linear_to_srgb(np.clip(np.asarray(linear, np.float64), 0.0, 1.0), np.float64)


def srgb_decode(encoded: np.ndarray) -> np.ndarray:
    """Display sRGB values (clipped to 0..1) -> linear, in float64."""
    return srgb_to_linear(np.clip(np.asarray(encoded, np.float64), 0.0, 1.0), np.float64)


def standard_display(rgba_linear: np.ndarray, exposure: float = 0.0, gamma: float = 1.0) -> np.ndarray:
    """(h, w, 3) display sRGB of a premultiplied scene-linear RGBA buffer seen over black,
    through Blender's Standard view transform with the scene's exposure and gamma (as
    Blender applies them: a scale of 2^exposure before the transform, an exponent of
    1/gamma after it)."""
    rgb = np.asarray(rgba_linear, np.float64)[..., :3] * 2.0 ** exposure
    return np.power(srgb_encode(rgb), 1.0 / max(gamma, 1e-6))


def lab(display_rgb: np.ndarray) -> np.ndarray:
    """CIELAB (L*, a*, b*) of display sRGB values in 0..1."""
    rgb = srgb_decode(display_rgb)
    # A row transform without BLAS (matrices.py: a threaded product leaves OpenBLAS' threads
    # spinning while the viewport renders).
    xyz = matrices.transform_rows(rgb.reshape(-1, 3), _XYZ_FROM_RGB).reshape(rgb.shape) / _WHITE
    delta = 6 / 29
    f = np.where(xyz > delta ** 3, np.cbrt(xyz), xyz / (3 * delta ** 2) + 4 / 29)
    return np.stack([116 * f[..., 1] - 16, 500 * (f[..., 0] - f[..., 1]), 200 * (f[..., 1] - f[..., 2])], -1)


def delta_e(a_display: np.ndarray, b_display: np.ndarray) -> np.ndarray:
    """(h, w) CIE76 ΔE*ab between two display sRGB images (their first three channels)."""
    return np.linalg.norm(lab(np.asarray(a_display)[..., :3]) - lab(np.asarray(b_display)[..., :3]), axis=-1)


def ramp(de: np.ndarray) -> np.ndarray:
    """(..., 3) display sRGB colour of each ΔE on the fixed scale (linear between breakpoints,
    the last colour beyond the last one)."""
    de = np.asarray(de, np.float64)
    return np.stack([np.interp(de, BREAKPOINTS, COLOURS[:, c]) for c in range(3)], -1).astype(np.float32)


# --------------------------------------------------------------------------------------
# The legend

# A 3x5 bitmap font for the legend's labels: each glyph is five rows of three pixels.
_GLYPHS = {
    "0": ("111", "101", "101", "101", "111"), "1": ("010", "110", "010", "010", "111"),
    "2": ("111", "001", "111", "100", "111"), "3": ("111", "001", "111", "001", "111"),
    "4": ("101", "101", "111", "001", "001"), "5": ("111", "100", "111", "001", "111"),
    "6": ("111", "100", "111", "101", "111"), "7": ("111", "001", "010", "010", "010"),
    "8": ("111", "101", "111", "101", "111"), "9": ("111", "101", "111", "001", "111"),
    ".": ("000", "000", "000", "000", "010"), "d": ("001", "001", "111", "101", "111"),
    "E": ("111", "100", "110", "100", "111"), " ": ("000", "000", "000", "000", "000"),
}
_BAR = 8          # legend bar height, pixels
_GAP = 2          # between the bar and the labels, and around the strip


def _text_mask(text: str, scale: int) -> np.ndarray:
    """(5*scale, width) bool pixels of `text` in the bitmap font (one blank column between glyphs)."""
    cols = []
    for ch in text:
        glyph = np.array([[c == "1" for c in row] for row in _GLYPHS[ch]])
        cols += [glyph, np.zeros((5, 1), bool)]
    mask = np.hstack(cols[:-1]) if cols else np.zeros((5, 0), bool)
    return mask.repeat(scale, 0).repeat(scale, 1)


def legend_height(width: int) -> int:
    """Rows of the legend strip for an image `width` pixels wide."""
    return _GAP + _BAR + _GAP + 5 * _font_scale(width) + _GAP


def _font_scale(width: int) -> int:
    # Eight labels of up to three glyphs (4 px each at scale 1, plus a gap) need ~16 px each.
    return 2 if width >= 8 * 32 else 1


def legend(width: int) -> np.ndarray:
    """(legend_height(width), width, 3) display sRGB strip: the ramp with the breakpoints
    equally spaced along it, each labelled below its tick, and "dE" after the last label.
    Labels that would not fit (images narrower than 130 px) are left out."""
    scale = _font_scale(width)
    labelled = width >= 130
    out = np.zeros((legend_height(width), width, 3), np.float32)
    margin = 6 * scale  # half the widest label ("100"), so the first and last labels fit
    # On the right, also room for the unit: "dE" (7 columns) two columns after the last label.
    x0, x1 = margin, max(margin + 1, width - (16 * scale if labelled else margin))
    # Equal widths per interval: position u along the bar -> ΔE, piecewise linear.
    n = len(BREAKPOINTS) - 1
    u = (np.arange(x0, x1) - x0 + 0.5) / max(x1 - x0, 1)
    out[_GAP:_GAP + _BAR, x0:x1] = ramp(np.interp(u * n, np.arange(n + 1), BREAKPOINTS))[None]
    if labelled:
        top = _GAP + _BAR + _GAP
        for i, value in enumerate(BREAKPOINTS):
            x = int(round(x0 + i * (x1 - x0) / n))
            out[_GAP + _BAR:top - 1, min(x, width - 1)] = 1.0  # the tick
            _stamp(out, _text_mask(f"{value:g}", scale), top, x)
        _stamp(out, _text_mask("dE", scale), top, x1 + 8 * scale, centred=False)
    return out


def _stamp(out: np.ndarray, mask: np.ndarray, top: int, x: int, centred: bool = True) -> None:
    """Draws a text mask in white with its top at row `top`, centred on column x (clipped)."""
    h, w = mask.shape
    left = x - w // 2 if centred else x
    left = min(max(left, 0), out.shape[1] - w)
    if left < 0 or top + h > out.shape[0]:
        return
    region = out[top:top + h, left:left + w]
    region[mask] = 1.0


def difference_image(a_display: np.ndarray, b_display: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(RGBA display sRGB image, ΔE per pixel): the ramp colour of each pixel's ΔE between two
    display sRGB images of the same size, with the legend strip appended below (the image is
    legend_height(width) rows taller than A and B)."""
    de = delta_e(a_display, b_display)
    h, w = de.shape
    rgb = np.vstack([ramp(de), legend(w)])
    return np.dstack([rgb, np.ones(rgb.shape[:2], np.float32)]), de
