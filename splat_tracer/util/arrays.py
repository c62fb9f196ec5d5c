"""Input checks the numpy-facing wrappers share: arrays made into the contiguous buffers the
compiled core wants, with a ValueError naming the argument and the shape expected."""
from __future__ import annotations

import numpy as np


def as_f32(a, name: str, shape: tuple) -> np.ndarray:
    """`a` as a C-contiguous float32 array of `shape` (-1: any size)."""
    arr = np.ascontiguousarray(a, dtype=np.float32)
    if arr.ndim != len(shape) or any(s not in (-1, d) for s, d in zip(shape, arr.shape)):
        want = "x".join("N" if s == -1 else str(s) for s in shape)
        raise ValueError(f"{name} must have shape {want}, got {arr.shape}")
    return arr


def as_indices(a, name: str, shape: tuple) -> np.ndarray:
    """`a` as a C-contiguous int32 array of `shape` (-1: any size); other integer types are
    range-checked before the conversion (an int64 index beyond int32 would otherwise wrap
    into a valid one)."""
    arr = np.asarray(a)
    if arr.ndim != len(shape) or any(s not in (-1, d) for s, d in zip(shape, arr.shape)):
        want = "x".join("N" if s == -1 else str(s) for s in shape)
        raise ValueError(f"{name} must have shape {want}, got {arr.shape}")
    if arr.dtype != np.int32:
        if arr.dtype.kind not in "iu":
            raise TypeError(f"{name} must hold integers, got {arr.dtype}")
        info = np.iinfo(np.int32)
        if arr.size and (arr.min() < info.min or arr.max() > info.max):
            raise ValueError(f"{name} holds values beyond int32 ({arr.min()} to {arr.max()}): not vertex indices")
    return np.ascontiguousarray(arr, dtype=np.int32)
