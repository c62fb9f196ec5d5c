"""The rendering method: which surface a ray sees among the splats and how it is shaded
(docs/ALGORITHM.md), as the core takes it, and its visibility switches: SWITCHES is the one
table the Blender properties, the compare operator and the A/B notes derive from (the panels'
hand-made layouts are tested against it)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

POSITION_RULES = ("FIRST", "NEAR_PHASE", "NEAREST_CENTRE")
KERNELS = ("LINEAR", "SMOOTH")
PRESETS = ("GENERAL", "NEAREST_CENTRE", "FULL")


@dataclass(frozen=True)
class Switch:
    """One visibility switch: a rule of the method turned on or off.

    name: the switch's one name; the Blender property is `use_<name>` (`prop`).
    label, description: its Blender label and tooltip (also the compare operator's and the
        A/B notes' wording).
    field: the Method field it sets: `name` itself for a plain on/off rule; 'position' for
        the two switches that choose the surface position rule.
    on, off: the field's value with the switch on / off. Of two switches on one field, the
        earlier in SWITCHES decides when it is on (the near phase over the nearest centre:
        the nearest centre applies only without the near phase).
    """

    name: str
    label: str
    description: str
    field: str = ""
    on: object = True
    off: object = False

    def __post_init__(self):
        if not self.field:
            object.__setattr__(self, "field", self.name)

    @property
    def prop(self) -> str:
        """The Blender property (Blender's convention for booleans: a use_ prefix)."""
        return "use_" + self.name

    def of(self, method: "Method") -> bool:
        """Whether this switch is on in `method`."""
        return getattr(method, self.field) == self.on


# The order is the Blender properties' and the compare operator's.
SWITCHES = (
    Switch("wrong_hit_elimination", "Wrong Hit Elimination",
           "Ignore back-facing discs that poke out in front of the surface (and, for rays leaving a surface, the "
           "splats they start from)"),
    Switch("normal_interpolation", "Normal Interpolation",
           "Blend the normals and colours of the overlapping splats for smooth shading (off: flat splats)"),
    Switch("far_phase", "Far Phase",
           "On closed objects, accept a layer only if the ray leaves the object after it, which removes the fringe "
           "at silhouettes"),
    Switch("near_phase", "Near Phase",
           "Place the surface point in a layer by the convex/concave rule, which keeps sharp edges sharp",
           field="position", on="NEAR_PHASE", off="FIRST"),
    Switch("nearest_centre", "Nearest Centre",
           "Without the near phase, take the layer hit closest to its splat centre (Linsen et al.) instead of the "
           "first one", field="position", on="NEAREST_CENTRE", off="FIRST"),
)
SWITCH = {s.name: s for s in SWITCHES}


def switches_of(method: "Method") -> dict:
    """{switch name: on} for `method`."""
    return {s.name: s.of(method) for s in SWITCHES}


def switch_fields(switches: Mapping[str, bool]) -> dict:
    """The Method fields a set of switch values (a value for every switch name) sets."""
    missing = [s.name for s in SWITCHES if s.name not in switches]
    if missing:
        raise KeyError(f"switch values missing for {missing}")
    out = {}
    for s in SWITCHES:
        if out.get(s.field, s.off) == s.off:  # not decided yet by an earlier switch that is on
            out[s.field] = s.on if switches[s.name] else s.off
    return out


@dataclass(frozen=True)
class Method:
    """Which surface a ray sees and how it is shaded (docs/ALGORITHM.md); each rule a switch
    (SWITCHES). The core reads these fields by name.

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
