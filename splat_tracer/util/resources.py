"""Memory a render will need, estimated before anything big is allocated, so that a scene
that cannot fit is refused with a message naming the object instead of driving the machine
into swap or having the operating system kill Blender (and the artist's unsaved work).
"""
from __future__ import annotations

import os
from typing import Optional

# Bytes per splat while its BVH is built, counted from the native structures at the build's
# peak (issue #12): what is kept, 66 at most (the packed splat 32 in leaf order; its slot 4;
# closed flag 1; colour 12 and alpha 4 when given; 4-wide BVH nodes about 13), plus the
# build's temporaries 77 (a build record 32; the splats packed in input order 32; the
# binary nodes about 13), plus the Python arrays being passed in (position, normal,
# radius, colour as float32: 40). benchmarks/scale.py measures the peak (RSS) next to it.
BYTES_PER_SPLAT = 66 + 77 + 40
# Per triangle: kept 208 (packed triangle 40; three corners 36; three corner normals 36;
# material 4; corner UVs 24; BVH 64; leaf order 4) + build temporaries 64 + Python arrays
# (indices 12, corner normals 36, material 4, corner UVs 24; vertices are shared and fewer).
BYTES_PER_TRIANGLE = 208 + 64 + 76
# A fraction of the available memory left for Blender itself, the render result and the
# film buffers: a build may use the rest.
HEADROOM = 0.25

_override: Optional[int] = None  # tests set a small "available memory" through override()


def available_memory() -> Optional[int]:
    """Bytes the system can give without swapping (Linux: MemAvailable), or None where
    unknown (then nothing is refused)."""
    if _override is not None:
        return _override
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def override(available: Optional[int]) -> None:
    """Pretend `available` bytes are free (None: ask the system again). For tests."""
    global _override
    _override = available


def check(what: str, needed: int) -> None:
    """Raises MemoryError naming `what` when `needed` bytes will not fit."""
    free = available_memory()
    if free is None:
        return
    budget = free * (1.0 - HEADROOM)
    if needed > budget:
        raise MemoryError(f"{what} needs about {needed / 2**30:.2f} GB to build, but only {free / 2**30:.2f} GB of "
                          f"memory are available; render fewer points (a lower import budget) or free memory")
