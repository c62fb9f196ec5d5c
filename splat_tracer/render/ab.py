"""A/B comparison without Blender: which settings A and B are, what the viewport shows of
their two renders (the split wipe and the difference overlay), and when a difference between
A and B cannot change the image at all.

The viewport's view_draw only uploads the buffer `display_buffer` returns; the compare
operator uses `ineffective_differences` for its notes.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from . import difference
from .method import SWITCH, SWITCHES, Method

MODES = ("OFF", "A", "B", "SPLIT")
DIVIDER = 2                       # the wipe's divider line, pixels wide
DIVIDER_RGBA = (1.0, 1.0, 1.0, 1.0)  # white (scene-linear 1: white in every view transform)
OVERLAY_OPACITY = 0.8             # the difference colour over the image where A and B differ visibly
OVERLAY_FROM = 1.0                # ΔE below this (invisible even on a patch) is not coloured


@dataclass(frozen=True)
class Variant:
    """One render of the viewport: its name ('SCENE', 'A' or 'B'), method and radius factor
    (baked into the clouds' splats: two radius factors need two sets of cloud geometry)."""

    name: str
    method: Method
    radius_factor: float


def split_at(mouse_x: float, region_x: float, region_width: int) -> float:
    """The split position (0..1) of the wipe under a mouse at window column `mouse_x`, over
    a region starting at window column `region_x`."""
    return float(np.clip((mouse_x - region_x) / max(region_width, 1), 0.0, 1.0))


def divider_column(split: float, width: int) -> int:
    """The first column of B in a `width`-pixel buffer split at `split`."""
    return int(round(float(np.clip(split, 0.0, 1.0)) * width))


def _fit(pixels: Optional[np.ndarray], shape) -> np.ndarray:
    """The buffer, or transparent black when missing or of another size (a pass of the
    previous view that has not been replaced yet)."""
    if pixels is None or pixels.shape != shape:
        return np.zeros(shape, np.float32)
    return pixels


def display_buffer(mode: str, shape, scene: Optional[np.ndarray] = None, a: Optional[np.ndarray] = None,
                   b: Optional[np.ndarray] = None, split: float = 0.5, overlay: bool = False,
                   exposure: float = 0.0, gamma: float = 1.0) -> np.ndarray:
    """The (h, w, 4) premultiplied scene-linear buffer the viewport draws (top row first).

    mode 'OFF': the scene's render. 'A' / 'B': that render. 'SPLIT': A left of the column
    `divider_column(split, w)`, B from it on, with a DIVIDER-pixel white line centred on the
    cut. overlay: where A and B differ by ΔE >= OVERLAY_FROM (measured through the Standard
    view transform with `exposure` and `gamma`), the pixel is mixed towards the difference
    scale's colour (OVERLAY_OPACITY), and the scale's legend is drawn along the bottom.
    Overlay colours are given in scene-linear so that the Standard view transform shows them
    exactly; another view transform (AgX, Filmic) tints them as it tints the image."""
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    if mode == "OFF":
        return _fit(scene, shape).copy()
    a, b = _fit(a, shape), _fit(b, shape)
    h, w = shape[:2]
    cut = {"A": w, "B": 0, "SPLIT": divider_column(split, w)}[mode]
    out = np.concatenate([a[:, :cut], b[:, cut:]], axis=1).astype(np.float32)
    if overlay:
        de = difference.delta_e(difference.standard_display(a, exposure, gamma),
                                difference.standard_display(b, exposure, gamma))
        colour = difference.srgb_decode(difference.ramp(de)).astype(np.float32)
        where = de >= OVERLAY_FROM
        mixed = (1 - OVERLAY_OPACITY) * out[..., :3] + OVERLAY_OPACITY * colour
        out[..., :3][where] = mixed[where]
        out[..., 3][where] = 1.0
    if mode == "SPLIT" and 0 < cut < w:
        lo, hi = max(cut - DIVIDER // 2, 0), min(cut - DIVIDER // 2 + DIVIDER, w)
        out[:, lo:hi] = DIVIDER_RGBA
    if overlay:  # the legend last, over the divider
        strip = difference.legend(w)
        rows = min(len(strip), h)
        out[h - rows:, :, :3] = difference.srgb_decode(strip[len(strip) - rows:])
        out[h - rows:, :, 3] = 1.0
    return out


# --------------------------------------------------------------------------------------
# When A and B cannot differ

def _switch_labels() -> dict:
    """{Method field: label} of the switch table's fields; a field two switches share is the
    rule they choose between."""
    labels = {}
    for switch in SWITCHES:
        labels.setdefault(switch.field, []).append(switch.label)
    return {field: names[0] if len(names) == 1 else f"the surface {field} rule ({' / '.join(names)})"
            for field, names in labels.items()}


# What the notes call each setting A and B may differ in (every Method field and the radius
# factor: the Blender properties' labels), in the order the notes list them.
_LABELS = {**_switch_labels(), "kernel": "Kernel", "crease_angle": "Crease Angle", "epsilon": "Epsilon",
           "radius_factor": "Radius Factor"}
_INTERPOLATION = SWITCH["normal_interpolation"].label


def ineffective_differences(a: Method, b: Method, *, clouds: int, closed_clouds: int, headlight: bool,
                            radius_a: float = 1.0, radius_b: float = 1.0) -> list[str]:
    """Notes, one per setting in which A and B differ but which cannot change the Combined
    image under the other settings (from the visibility code's logic, docs/ALGORITHM.md);
    with a last note when no difference between A and B can change it. Empty when every
    difference can show.

    clouds / closed_clouds: cloud instances in the view layer / those marked Closed Surface.
    headlight: the images are lit by the headlight (base colour x |cos|, no secondary rays)."""
    differing = [k for k in _LABELS if k != "radius_factor" and getattr(a, k) != getattr(b, k)]
    if radius_a != radius_b:
        differing.append("radius_factor")
    if not differing:
        return ["A and B are the same settings: the images cannot differ"]
    notes = {}
    both = lambda test: test(a) and test(b)  # noqa: E731
    for key in differing:
        label = _LABELS[key]
        if clouds == 0:
            notes[key] = f"{label} changes nothing here: the view layer renders no point cloud, and the visibility " \
                         "settings act on splats only"
        elif key == "far_phase" and closed_clouds == 0:
            notes[key] = (f"{label} changes nothing here: it acts only on clouds marked Closed Surface (Object "
                          "Properties > Splat Cloud), and none is")
        elif key in ("kernel", "crease_angle") and both(lambda m: not m.normal_interpolation):
            notes[key] = f"{label} changes nothing here: it weights interpolated normals, and {_INTERPOLATION} " \
                         "is off in A and B"
        elif key == "position" and both(lambda m: m.epsilon == 0):
            notes[key] = (f"{label} changes nothing here: with Epsilon 0 a layer holds only its first disc (and "
                          "discs hit at exactly the same depth), so there is nothing to choose between")
        elif key == "position" and headlight and both(lambda m: m.normal_interpolation and m.crease_angle >= 180):
            notes[key] = (f"{label} changes nothing here: it moves the surface point within its layer, but with "
                          f"{_INTERPOLATION} on the normal and colour blend every disc of the layer wherever the "
                          "point is, and the headlight shades only those (turn interpolation off, or use the "
                          "scene's lighting, to see it)")
        elif key == "normal_interpolation" and both(lambda m: m.epsilon == 0):
            notes[key] = (f"{label} changes nothing here: with Epsilon 0 a layer holds only its first disc (and "
                          "discs hit at exactly the same depth), so there is nothing to blend")
        elif key == "epsilon" and both(lambda m: not m.normal_interpolation and m.position == "FIRST"
                                       and (not m.far_phase or closed_clouds == 0)):
            notes[key] = (f"{label} changes nothing here: the layer's depth matters only to normal interpolation, "
                          "the near phase, nearest centre and the far phase on closed clouds, and A and B use none "
                          "of them")
    out = list(notes.values())
    if len(notes) == len(differing):
        out.append("so A and B cannot differ under these settings")
    return out
