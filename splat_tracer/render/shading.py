"""What a scene looks like, as the native core consumes it: materials, lights, the world and
the render settings. Plain dataclasses (no Blender needed); `pack()` turns each into the flat
float32 row the core reads, whose layout is mirrored in `native/shade/shading.h` (keep both in step:
the `*_FIELDS` tuples below are the single list of columns).

Units are Blender's, so that a scene lit for Cycles renders at the same brightness:
- point and spot lamps: `power` in watts (radiant intensity P / (4 pi) W/sr, like Cycles);
- sun: `strength` in W/m^2 (irradiance on a surface facing it);
- area lamps: `power` in watts, emitted from one side;
- emission and the world background: radiance, colour x strength.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Optional, Sequence

import numpy as np

# --------------------------------------------------------------------------------------
# Materials: a simplified Principled BSDF.

MATERIAL_FIELDS = (
    "base_r", "base_g", "base_b", "metallic", "roughness", "ior", "transmission", "alpha",
    "emission_r", "emission_g", "emission_b", "specular_level", "use_point_colour", "use_point_alpha",
    "emission_sides", "pass_index", "metal_r", "metal_g", "metal_b", "bump_correction",
)

# Cycles' Emission Sampling (Material > Settings), with its identifiers: which sides of a
# mesh's emissive triangles are sampled as lights (the others are found by rays only).
EMISSION_SAMPLING = ("NONE", "AUTO", "FRONT", "BACK", "FRONT_BACK")
_EMISSION_SIDES = {"NONE": 0, "FRONT": 1, "BACK": 2, "FRONT_BACK": 3}
# Cycles' Auto samples a material when its emission estimate (colour x strength, at most
# this in any channel) exceeds 0.5, so that faint glows do not take samples from the lights
# that matter (Shader::estimate_emission in Cycles' scene/shader.cpp).
AUTO_EMISSION_THRESHOLD = 0.5


@dataclass(frozen=True)
class Material:
    """The subset of Blender's Principled BSDF the engine renders.

    base_colour: scene-linear RGB (replaced by the point colours when `use_point_colour`).
    metallic, roughness, transmission, alpha: 0..1, as the Principled BSDF's sockets.
    ior: index of refraction (glass and the dielectric Fresnel).
    specular_level: the Principled BSDF's 'Specular IOR Level' (0.5: the IOR's own Fresnel;
        0: no specular reflection on dielectrics; 1: twice it).
    emission: emitted radiance, colour x strength.
    emission_sampling: Cycles' Emission Sampling (EMISSION_SAMPLING): which sides of a mesh's
        emissive triangles are sampled as lights; AUTO as Cycles (both sides when the
        emission exceeds AUTO_EMISSION_THRESHOLD in a channel, else none). Clouds' emission
        is never sampled. Where `program` drives the emission the core picks triangles by
        an estimate of the program's power and runs it at the sampled point (Auto reads the
        constant `emission` here; the Blender export resolves it by Cycles' estimate).
    use_point_alpha: multiply alpha by the points' own alpha (4th colour channel).
    pass_index: Blender's material pass index, the Material Index pass's value.
    metal_colour: the metallic lobe's own colour, or None: the base colour's (every single
        shader). A Mix Shader of a diffuse and a glossy sets it (export/shading.py _combine):
        Cycles sums the two closures, the diffuse of its colour and the glossy of its own, so
        the diffuse share keeps `base_colour` and the metallic share this. Packed as -1s.
    bump_correction: Cycles' Bump Map Correction (Material > Settings): the bump shadowing
        term on the diffuse lobe where a node program tilts the normal; off: left out.
    program: the node program (render/nodes.py) that drives some of the inputs above at
        each shading point, or None (the constant values are the material). The inputs it
        does not drive keep their constant values.
    name: the material's name in the Cryptomatte Material pass (render/cryptomatte.py).
    """

    base_colour: Sequence[float] = (0.8, 0.8, 0.8)
    metallic: float = 0.0
    roughness: float = 0.5
    ior: float = 1.5
    transmission: float = 0.0
    alpha: float = 1.0
    emission: Sequence[float] = (0.0, 0.0, 0.0)
    specular_level: float = 0.5
    use_point_colour: bool = False
    use_point_alpha: bool = False
    emission_sampling: str = "AUTO"
    pass_index: int = 0
    program: Optional[object] = None
    metal_colour: Optional[Sequence[float]] = None
    bump_correction: bool = True
    name: str = "default_surface"  # cryptomatte.DEFAULT_MATERIAL: Cycles' name for no material

    def __post_init__(self):
        if self.emission_sampling not in EMISSION_SAMPLING:
            raise ValueError(f"material emission_sampling must be one of {EMISSION_SAMPLING}, "
                             f"got {self.emission_sampling!r}")
        for name in ("metallic", "roughness", "transmission", "alpha"):
            v = getattr(self, name)
            if not (math.isfinite(v) and 0.0 <= v <= 1.0):
                raise ValueError(f"material {name} must be in 0..1, got {v!r}")
        if not (math.isfinite(self.ior) and self.ior > 0):
            raise ValueError(f"material ior must be a positive number, got {self.ior!r}")
        if not (math.isfinite(self.specular_level) and self.specular_level >= 0):
            raise ValueError(f"material specular_level must be >= 0, got {self.specular_level!r}")
        for name in ("base_colour", "emission", "metal_colour"):
            v = getattr(self, name)
            if v is None and name == "metal_colour":
                continue
            if len(v) != 3 or not all(math.isfinite(c) and c >= 0 for c in v):
                raise ValueError(f"material {name} must be three non-negative numbers, got {v!r}")

    def pack(self) -> np.ndarray:
        return np.array([*self.base_colour, self.metallic, self.roughness, self.ior, self.transmission, self.alpha,
                         *self.emission, self.specular_level, float(self.use_point_colour),
                         float(self.use_point_alpha), float(self.emission_sides), float(self.pass_index),
                         *(self.metal_colour if self.metal_colour is not None else (-1.0, -1.0, -1.0)),
                         float(self.bump_correction)], np.float32)

    @property
    def emission_sides(self) -> int:
        """The sides sampled as a light: 1 front, 2 back, 3 both, 0 none (AUTO resolved)."""
        if self.emission_sampling == "AUTO":
            return 3 if max(self.emission) > AUTO_EMISSION_THRESHOLD else 0
        return _EMISSION_SIDES[self.emission_sampling]


# --------------------------------------------------------------------------------------
# Lights.

LIGHT_TYPES = ("POINT", "SPOT", "SUN", "AREA")
AREA_SHAPES = ("SQUARE", "RECTANGLE", "DISK", "ELLIPSE")
LIGHT_FIELDS = (
    "type", "r", "g", "b",           # type index; colour x power (W) or x strength (sun, W/m^2)
    "px", "py", "pz",                # position (local frame)
    "dx", "dy", "dz",                # emission axis: the lamp's local -Z, unit
    "ux", "uy", "uz",                # area: first edge axis (lamp's local X), unit
    "radius",                        # point/spot: sphere radius; sun: half the angular diameter (radians)
    "size_u", "size_v",              # area: full sizes along u and v (the lamp's X and Y)
    "shape",                         # area: AREA_SHAPES index
    "spot_half_angle", "spot_blend", # spot: half the cone angle (radians), blend 0..1
    "cast_shadow",                   # 0 or 1
    "soft_falloff",                  # point/spot with a radius: Blender 4's Soft Falloff
    "visibility",                    # bits: 1 seen by camera rays, 4 by mirror rays, 8 through glass
)


@dataclass(frozen=True)
class Light:
    """One lamp, in the scene's local frame (see RenderScene's origin).

    type: 'POINT', 'SPOT', 'SUN' or 'AREA'. colour: linear RGB multiplier. power: watts for
    point, spot and area lamps; for 'SUN' it is the strength in W/m^2.
    position: lamp centre; direction: the way it shines (the lamp's local -Z axis);
    u_axis: the area lamp's local X axis (its local Y is direction x u_axis... taken as
    cross(u_axis, direction) by the core, so any right-handed frame works).
    radius: point/spot soft-shadow radius; for the sun, `angle` (full angular diameter, rad).
    size, size_y: area lamp size along X and Y (SQUARE and DISK use `size` for both).
    spot_size: full cone angle (radians), spot_blend: 0..1.
    """

    type: str = "POINT"
    colour: Sequence[float] = (1.0, 1.0, 1.0)
    power: float = 1000.0
    position: Sequence[float] = (0.0, 0.0, 0.0)
    direction: Sequence[float] = (0.0, 0.0, -1.0)
    u_axis: Sequence[float] = (1.0, 0.0, 0.0)
    radius: float = 0.0
    angle: float = 0.0
    size: float = 1.0
    size_y: float = 1.0
    shape: str = "SQUARE"
    spot_size: float = math.radians(45.0)
    spot_blend: float = 0.15
    cast_shadow: bool = True
    soft_falloff: bool = True
    # Whether the lamp itself is seen (a sun disc, a sphere, an area's shape) by camera rays,
    # in mirrors and through clear glass (Object > Visibility > Ray Visibility).
    visible_camera: bool = True
    visible_glossy: bool = True
    visible_transmission: bool = True
    # The light group it belongs to (Object > Shading > Light Group; "": none), for the light
    # groups' passes (RenderScene.render's light_groups). Not packed: a render-time map.
    light_group: str = ""

    def __post_init__(self):
        if self.type not in LIGHT_TYPES:
            raise ValueError(f"light type must be one of {LIGHT_TYPES}, got {self.type!r}")
        if self.shape not in AREA_SHAPES:
            raise ValueError(f"area shape must be one of {AREA_SHAPES}, got {self.shape!r}")
        vectors = (self.colour, self.position, self.direction, self.u_axis)
        if not all(len(v) == 3 and all(math.isfinite(c) for c in v) for v in vectors):
            raise ValueError("light colour, position, direction and u_axis must be three finite numbers each")
        scalars = (self.power, self.radius, self.angle, self.size, self.size_y, self.spot_size, self.spot_blend)
        if not all(math.isfinite(v) and v >= 0 for v in scalars):
            raise ValueError("light power, radius, angle, sizes and spot settings must be finite and >= 0")
        if not math.hypot(*self.direction) > 0:
            raise ValueError("light direction must not be zero")

    def pack(self) -> np.ndarray:
        d = np.asarray(self.direction, np.float64)
        d = d / np.linalg.norm(d)
        u = np.asarray(self.u_axis, np.float64)
        u = u - d * np.dot(u, d)  # make u perpendicular to the emission axis
        if np.linalg.norm(u) < 1e-9:
            u = np.cross(d, [1.0, 0.0, 0.0] if abs(d[0]) < 0.9 else [0.0, 1.0, 0.0])
        u = u / np.linalg.norm(u)
        square = self.shape in ("SQUARE", "DISK")
        radius = self.angle / 2 if self.type == "SUN" else self.radius
        rgb = np.asarray(self.colour, np.float64) * self.power
        return np.array([LIGHT_TYPES.index(self.type), *rgb, *self.position, *d, *u, radius, self.size,
                         self.size if square else self.size_y, AREA_SHAPES.index(self.shape),
                         min(self.spot_size, math.pi) / 2, min(self.spot_blend, 1.0), float(self.cast_shadow),
                         float(self.soft_falloff),
                         float(1 * self.visible_camera + 4 * self.visible_glossy + 8 * self.visible_transmission)],
                        np.float32)


# --------------------------------------------------------------------------------------
# World and render settings.

WORLD_RAYS = ("camera", "diffuse", "glossy", "transmission")  # ray kinds the world may be hidden from
# The World's Mist Pass falloffs (Blender's identifiers) and the exponent Cycles raises the
# mist to for each (its Blender sync: Quadratic 2, Linear 1, Inverse Quadratic 0.5).
MIST_FALLOFFS = {"QUADRATIC": 2.0, "LINEAR": 1.0, "INVERSE_QUADRATIC": 0.5}


@dataclass(frozen=True)
class World:
    """The background: a uniform radiance (colour x strength) seen by rays that leave the
    scene, which also lights it (through diffuse bounces). `transparent`: camera rays that
    miss get alpha 0 (Film > Transparent). `visibility`: the ray kinds that see it (World >
    Ray Visibility: 'camera', 'diffuse', 'glossy', 'transmission'); a kind left out meets
    black instead -- camera rays on an opaque film keep alpha 1, as in Cycles.
    mist_start, mist_depth, mist_falloff: the World's Mist Pass settings (MIST_FALLOFFS), which
    only the Mist pass reads; the defaults are Cycles' for a scene without a world.
    environment: None (the uniform colour x strength), or the world as an equirectangular
    image (float32, height x width x 3, scene-linear radiance, strength included; row 0 at the
    nadir, column 0 at u = 0, Cycles' orientation: u = 0.5 - atan2(y, x) / 2 pi,
    v = 0.5 + asin(z) / pi): seen by rays that leave the scene and sampled as a light.
    camera_environment: with `environment`, what camera rays see instead (the world's Light
    Path > Is Camera Ray trick), or None: the same. Compared by identity, not by value."""

    colour: Sequence[float] = (0.05, 0.05, 0.05)
    strength: float = 1.0
    transparent: bool = False
    visibility: frozenset = frozenset(WORLD_RAYS)
    mist_start: float = 0.0
    mist_depth: float = 100.0
    mist_falloff: str = "LINEAR"
    # World > Light Settings > Distance: how far the AO pass's rays look (Cycles' ao_distance),
    # and an Ambient Occlusion node's whose Distance is 0.
    ao_distance: float = 10.0
    light_group: str = ""  # World > Settings > Light Group ("": none)
    environment: Optional[np.ndarray] = field(default=None, compare=False, repr=False)
    camera_environment: Optional[np.ndarray] = field(default=None, compare=False, repr=False)

    def __post_init__(self):
        if not (math.isfinite(self.ao_distance) and self.ao_distance >= 0):
            raise ValueError(f"ao_distance must be finite and >= 0, got {self.ao_distance!r}")
        for name in ("environment", "camera_environment"):
            image = getattr(self, name)
            if image is not None and not (isinstance(image, np.ndarray) and image.dtype == np.float32
                                          and image.ndim == 3 and image.shape[2] == 3):
                raise ValueError(f"{name} must be a float32 (height, width, 3) array")
        if self.camera_environment is not None and self.environment is None:
            raise ValueError("camera_environment needs an environment")
        if self.mist_falloff not in MIST_FALLOFFS:
            raise ValueError(f"mist_falloff must be one of {sorted(MIST_FALLOFFS)}, got {self.mist_falloff!r}")
        if not (math.isfinite(self.mist_start) and math.isfinite(self.mist_depth) and self.mist_depth >= 0):
            raise ValueError(f"mist start must be finite and depth >= 0, got {self.mist_start!r}, {self.mist_depth!r}")
        unknown = set(self.visibility) - set(WORLD_RAYS)
        if unknown:
            raise ValueError(f"unknown world ray visibility {sorted(unknown)}; use {list(WORLD_RAYS)}")

    def radiance(self) -> tuple:
        """The uniform radiance; with an environment image, its mean over the sphere."""
        if self.environment is not None:
            return self._environment_mean
        return tuple(float(c) * float(self.strength) for c in self.colour)

    @functools.cached_property
    def _environment_mean(self) -> tuple:
        """The environment's mean radiance over the sphere (rows weighed by sin(theta)): once
        per World, which a viewport renders many times."""
        h = self.environment.shape[0]
        weights = np.sin(np.pi * (np.arange(h) + 0.5) / h)
        rows = self.environment.mean(axis=1, dtype=np.float64)
        return tuple(float(c) for c in weights @ rows / weights.sum())

    def world_map(self):
        """The core's world_map argument: None, or (light image, camera image or None)."""
        if self.environment is None:
            return None
        return (np.ascontiguousarray(self.environment),
                None if self.camera_environment is None else np.ascontiguousarray(self.camera_environment))

    def mist(self) -> tuple:
        """(start, 1 / depth, falloff exponent), as the core takes them: Cycles' Film values
        (a depth of 0 gives 1 / depth 0, as Cycles' mist_inv_depth)."""
        inv_depth = 1.0 / self.mist_depth if self.mist_depth > 0 else 0.0
        return float(self.mist_start), inv_depth, MIST_FALLOFFS[self.mist_falloff]


PIXEL_FILTERS = ("BOX", "GAUSSIAN", "BLACKMAN_HARRIS")
MESH_LIGHT_STRATEGIES = ("MIS", "LIGHT", "BSDF")  # the core's IntegratorSettings::MeshLightStrategy order


@dataclass(frozen=True)
class RenderSettings:
    """How a frame is sampled (Blender's Sampling and Light Paths panels).

    samples: camera rays per pixel (anti-aliasing; every secondary effect shares them).
    pixel_filter / filter_width: Blender's pixel filter type and width (pixels).
    shadow_samples: shadow rays per lamp per camera sample (soft shadows).
    max_bounces, diffuse_bounces, glossy_bounces, transmission_bounces,
    transparent_bounces: path depth limits, as in Cycles' Light Paths.
    seed: varies the noise pattern (Blender's seed).
    headlight: preview shading instead of the scene's light: base colour x |cos| of the
        view ray and the normal, no lamps, no secondary rays.
    sky_ao: light from the world by ambient occlusion instead of diffuse bounces: at each
        diffuse point `ao_samples` occlusion rays, the world's radiance where they escape
        (cheaper; ignores light bounced off other surfaces).
    mesh_light_strategy: how emissive mesh triangles light other surfaces (MESH_LIGHT_STRATEGIES):
        "MIS" (shadow rays aimed at them and the rays that meet them, weighed by multiple
        importance sampling, as Cycles), "LIGHT" (shadow rays only) or "BSDF" (the rays that
        meet them only). The last two are for verifying the first; all three converge alike.
        The world's environment image (World.environment) is sampled by the same strategy.

    Noise control, Cycles' settings with Cycles' meaning (0 turns each off):
    clamp_direct / clamp_indirect: Cycles' Clamp Direct / Indirect. A sample's contribution
        (the light a path brings, times the path's weight) whose R + G + B exceeds 3x the
        clamp is scaled down to it. Direct: light reaching the first surface the camera
        sees (its lamps sampled there, or emission and world found by its bounce ray) and
        what the camera sees itself; indirect: everything deeper.
    filter_glossy: Cycles' Filter Glossy. After a bounce into a direction of pdf p (the
        smallest so far), glossy lobes get at least the roughness (alpha) sqrt(1 - p / filter_glossy) / 2.
    adaptive: Cycles' adaptive sampling. A pixel stops sampling once its noise estimate
        (the difference between the estimate of all its samples and of half of them) is
        below the noise threshold; `adaptive_parameters` gives the values used.
    adaptive_threshold: Cycles' Noise Threshold; 0: automatic (from the samples).
    adaptive_min_samples: Cycles' Min Samples; 0: automatic (from the threshold).
    time_limit: Cycles' Time Limit in seconds: sampling stops once it has taken that long
        (the samples reached are in FrameResult.counters).
    """

    samples: int = 16
    pixel_filter: str = "BLACKMAN_HARRIS"
    filter_width: float = 1.5
    shadow_samples: int = 1
    max_bounces: int = 12
    diffuse_bounces: int = 1
    glossy_bounces: int = 4
    transmission_bounces: int = 12
    transparent_bounces: int = 8
    seed: int = 0
    headlight: bool = False
    sky_ao: bool = False
    ao_samples: int = 1
    clamp_direct: float = 0.0
    clamp_indirect: float = 0.0
    filter_glossy: float = 0.0
    adaptive: bool = False
    adaptive_threshold: float = 0.0
    adaptive_min_samples: int = 0
    time_limit: float = 0.0
    mesh_light_strategy: str = "MIS"

    def __post_init__(self):
        if self.mesh_light_strategy not in MESH_LIGHT_STRATEGIES:
            raise ValueError(f"mesh_light_strategy must be one of {MESH_LIGHT_STRATEGIES}, "
                             f"got {self.mesh_light_strategy!r}")
        if self.pixel_filter not in PIXEL_FILTERS:
            raise ValueError(f"pixel_filter must be one of {PIXEL_FILTERS}, got {self.pixel_filter!r}")
        if not 1 <= self.samples <= 1 << 16:
            raise ValueError(f"samples must be in 1..65536, got {self.samples!r}")
        if not 1 <= self.ao_samples <= 1024:
            raise ValueError(f"ao_samples must be in 1..1024, got {self.ao_samples!r}")
        if not 1 <= self.shadow_samples <= 1024:
            raise ValueError(f"shadow_samples must be in 1..1024, got {self.shadow_samples!r}")
        if not (math.isfinite(self.filter_width) and 0.01 <= self.filter_width <= 10):
            raise ValueError(f"filter_width must be in 0.01..10 pixels, got {self.filter_width!r}")
        for name in ("max_bounces", "diffuse_bounces", "glossy_bounces", "transmission_bounces",
                     "transparent_bounces"):
            if not 0 <= getattr(self, name) <= 1024:
                raise ValueError(f"{name} must be in 0..1024")
        for name in ("clamp_direct", "clamp_indirect", "filter_glossy", "adaptive_threshold", "time_limit"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be finite and >= 0, got {value!r}")
        if not 0 <= self.adaptive_min_samples <= 1 << 16:
            raise ValueError(f"adaptive_min_samples must be in 0..65536, got {self.adaptive_min_samples!r}")

    def adaptive_parameters(self) -> tuple[float, int]:
        """(threshold, min_samples) that adaptive sampling uses, as Cycles'
        Integrator::get_adaptive_sampling derives them: a threshold of 0 is
        max(0.001, 1 / samples); min samples of 0 is max(4, ceil(16 / threshold^0.3)), else
        at least 4; then the threshold is multiplied by 5 (Cycles' "arbitrary factor" that
        keeps its values like those of its former error measure)."""
        threshold = self.adaptive_threshold if self.adaptive_threshold > 0 else max(0.001, 1.0 / self.samples)
        if self.adaptive_min_samples == 0:
            # Cycles computes this in float32: ceilf(16.0f / powf(threshold, 0.3f)).
            t = np.float32(threshold)
            min_samples = max(4, int(np.ceil(np.float32(16.0) / np.power(t, np.float32(0.3)))))
        else:
            min_samples = max(4, self.adaptive_min_samples)
        return float(np.float32(threshold) * np.float32(5.0)), min_samples

    def pack(self) -> tuple:
        """The settings tuple the core's render parses, in SETTINGS_FIELDS order."""
        threshold, min_samples = self.adaptive_parameters() if self.adaptive else (0.0, 0)
        packed = dict(samples=self.samples, pixel_filter=PIXEL_FILTERS.index(self.pixel_filter),
                      filter_width=float(self.filter_width), shadow_samples=self.shadow_samples,
                      max_bounces=self.max_bounces, diffuse_bounces=self.diffuse_bounces,
                      glossy_bounces=self.glossy_bounces, transmission_bounces=self.transmission_bounces,
                      transparent_bounces=self.transparent_bounces, seed=self.seed & 0x7FFFFFFF,
                      headlight=bool(self.headlight), sky_ao=bool(self.sky_ao), ao_samples=self.ao_samples,
                      clamp_direct=float(self.clamp_direct), clamp_indirect=float(self.clamp_indirect),
                      filter_glossy=float(self.filter_glossy), adaptive=bool(self.adaptive),
                      adaptive_threshold=threshold, adaptive_min_samples=min_samples,
                      time_limit=float(self.time_limit),
                      mesh_light_strategy=MESH_LIGHT_STRATEGIES.index(self.mesh_light_strategy))
        return tuple(packed[name] for name in SETTINGS_FIELDS)


# The entries of RenderSettings.pack(), in order: the tuple the core's render parses (its
# format string in native/python/py_render.cpp; keep both in step). Enumerations are packed
# as their index; adaptive_threshold and adaptive_min_samples are the values used
# (RenderSettings.adaptive_parameters, 0 without adaptive sampling).
SETTINGS_FIELDS = (
    "samples", "pixel_filter", "filter_width", "shadow_samples", "max_bounces", "diffuse_bounces", "glossy_bounces",
    "transmission_bounces", "transparent_bounces", "seed", "headlight", "sky_ao", "ao_samples", "clamp_direct",
    "clamp_indirect", "filter_glossy", "adaptive", "adaptive_threshold", "adaptive_min_samples", "time_limit",
    "mesh_light_strategy",
)


# Passes the core can write, by the name Blender shows, with their channel count.
PASSES = {
    "Combined": 4,
    "Depth": 1,        # planar depth along the view axis, of the pixel-centre sample
    "Normal": 3,       # world-space shading normal, pixel-centre sample
    "DiffCol": 3,      # albedo of the diffuse lobe, averaged over the samples
    "Emit": 3,         # emitted radiance seen by camera rays, averaged
    "Shadow": 3,       # lamps' direct light received / unshadowed (1: fully lit or no lamp; not mesh lights)
    "IndexOB": 1,      # the object's pass index, pixel-centre sample
    "Splat Count": 1,  # debug: splats that formed the surface point, pixel-centre sample
    "Shadow Catcher": 3,  # Cycles': what the background is multiplied by (1: no shadow); see RenderScene.render
    "Position": 3,     # position of the first hit (the scene's local frame), pixel-centre sample; 0 on a miss
    "IndexMA": 1,      # the material's pass index, pixel-centre sample
    "Mist": 1,         # Cycles' mist (World.mist_*): 0 at the start, 1 at start + depth and on a miss; averaged
    "Env": 3,          # the world seen by camera rays that leave the scene (black on surfaces), averaged
    # Cycles' light passes, averaged: by the lobe of the path's first bounce, the light that
    # reached the first surface straight from its source (Direct) or by more bounces (Indirect),
    # divided by the lobe's colour as Cycles' film does, so (Dir + Ind) x Col is its light.
    "DiffDir": 3, "DiffInd": 3, "GlossDir": 3, "GlossInd": 3, "GlossCol": 3,
    "TransDir": 3, "TransInd": 3, "TransCol": 3,
    "AO": 3,           # Cycles' AO pass: 1 where a cosine ray from the first hit meets nothing within World.ao_distance
    "Vector": 4,       # Cycles' screen-space motion: 0 here (blender/export/motion.py vector_pass fills it)
    "Instance": 1,     # the pixel-centre sample's first hit's instance + 1 (0 on a miss): for the Vector pass
    "UV": 3,           # the mesh's UV map (U, V, 1) at the pixel-centre sample's first hit; 0 on clouds and misses
}
# The light passes in the core's order (its `light` buffer's planes: PassLobe order, Direct,
# Indirect, Color).
LIGHT_PASSES = ("DiffDir", "GlossDir", "TransDir", "DiffInd", "GlossInd", "TransInd", "DiffCol", "GlossCol",
                "TransCol")
# Each light group's Combined, as Cycles names it (RenderScene.render's light_groups).
LIGHT_GROUP_PREFIX = "Combined_"
# The most light groups a render writes (native/shade/light_passes.h, kMaxLightGroups).
MAX_LIGHT_GROUPS = 16


@dataclass
class Report:
    """Approximations made while exporting a scene, each said once in the render report."""

    lines: list = field(default_factory=list)

    def once(self, line: str) -> None:
        if line not in self.lines:
            self.lines.append(line)
