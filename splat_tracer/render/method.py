"""The rendering method: which surface a ray sees among the splats and how it is shaded
(docs/ALGORITHM.md), as the core takes it."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

POSITION_RULES = ("FIRST", "NEAR_PHASE", "NEAREST_CENTRE")
KERNELS = ("LINEAR", "SMOOTH")
PRESETS = ("GENERAL", "NEAREST_CENTRE", "FULL")


@dataclass(frozen=True)
class Method:
    """Which surface a ray sees and how it is shaded (docs/ALGORITHM.md); each rule a switch.
    The core reads these fields by name.

    wrong_hit_elimination: hits of the wrong facing before the first layer are ignored.
    normal_interpolation: normal and colour blended over the layer's splats, weighted by
        `kernel` ('LINEAR': the paper's (r - d)/r; 'SMOOTH': (1 - (d/r)^2)^2); off: flat.
    far_phase: on closed objects, a layer counts only if the next hit after it leaves the
        object (has the other facing); otherwise the search goes on along the ray.
    position: the surface point within the layer: 'FIRST' hit, 'NEAR_PHASE' (the paper's
        convex/concave rule) or 'NEAREST_CENTRE' (Linsen et al.).
    epsilon: depth of a layer, in radii of its first splat.
    crease_angle: degrees; with interpolation, only the layer's splats whose normal is within
        this angle of the surface splat's blend (sharp edges stay sharp, like Auto Smooth);
        180: every splat blends (the paper's).
    """

    wrong_hit_elimination: bool = True
    normal_interpolation: bool = True
    far_phase: bool = True
    position: str = "NEAR_PHASE"
    kernel: str = "LINEAR"
    epsilon: float = 1.0
    crease_angle: float = 180.0

    def __post_init__(self):
        if self.position not in POSITION_RULES:
            raise ValueError(f"position must be one of {POSITION_RULES}, got {self.position!r}")
        if self.kernel not in KERNELS:
            raise ValueError(f"kernel must be one of {KERNELS}, got {self.kernel!r}")
        if not (np.isfinite(self.epsilon) and self.epsilon >= 0):
            raise ValueError(f"epsilon must be a finite number >= 0, got {self.epsilon!r}")
        if not (0 <= self.crease_angle <= 180):
            raise ValueError(f"crease_angle must be between 0 and 180 degrees, got {self.crease_angle!r}")

    @classmethod
    def preset(cls, name: str, **overrides) -> "Method":
        """'GENERAL': nearest hit, any facing, flat normal. 'NEAREST_CENTRE' (Linsen et al.):
        wrong hits eliminated, interpolated normals, the layer hit nearest its disc centre.
        'FULL': every rule of the paper."""
        presets = {
            "GENERAL": dict(wrong_hit_elimination=False, normal_interpolation=False, far_phase=False,
                            position="FIRST"),
            "NEAREST_CENTRE": dict(wrong_hit_elimination=True, normal_interpolation=True, far_phase=False,
                                   position="NEAREST_CENTRE"),
            "FULL": dict(wrong_hit_elimination=True, normal_interpolation=True, far_phase=True,
                         position="NEAR_PHASE"),
        }
        if name not in presets:
            raise ValueError(f"preset must be one of {PRESETS}, got {name!r}")
        return cls(**{**presets[name], **overrides})
