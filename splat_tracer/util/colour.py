"""The sRGB transfer function (IEC 61966-2-1), one definition for the whole project: file
colours of scans, 8-bit and sRGB-tagged images, the comparison views' display values."""
from __future__ import annotations

import numpy as np


def srgb_to_linear(c, dtype=np.float32) -> np.ndarray:
    """sRGB-encoded values -> linear, computed in `dtype`. Not clipped: the curve's power
    segment continues above 1 (a float image's highlights), the linear one below 0."""
    c = np.asarray(c, dtype=dtype)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4).astype(dtype, copy=False)


def linear_to_srgb(c, dtype=np.float32) -> np.ndarray:
    """Linear -> sRGB-encoded, the inverse of srgb_to_linear over the same range (the power
    segment above 1, the linear one below 0)."""
    c = np.asarray(c, dtype=dtype)
    power = 1.055 * np.power(np.maximum(c, 0.0031308), 1 / 2.4) - 0.055
    return np.where(c <= 0.0031308, c * 12.92, power).astype(dtype, copy=False)
