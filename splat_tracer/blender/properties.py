"""Settings stored in .blend files: scene.splat_tracer and object.splat_tracer."""
import math

import bpy

from ..render import shading
from ..render.method import PRESETS, SWITCH, SWITCHES, Method, switch_fields, switches_of

# Hard limits are the ones shading.RenderSettings accepts.
_MAX_SAMPLES = 1 << 16
_MAX_SHADOW_SAMPLES = 1024

_PRESET_ITEMS = (
    ("GENERAL", "General", "Plain splat ray tracing: nearest hit of any facing, flat splat normal"),
    ("NEAREST_CENTRE", "Nearest Centre",
     "Linsen et al.: wrong hits eliminated, interpolated normals, the layer hit nearest its splat centre"),
    ("FULL", "Full", "The paper's method: every visibility rule and normal interpolation"),
    ("CUSTOM", "Custom", "The switches below do not match a preset"),
)
# The switches' properties, one per entry of the switch table (their names, labels and
# descriptions come from it).
_SWITCHES = tuple(switch.prop for switch in SWITCHES)
_syncing = False  # set while one property's update writes the others


def method_from_switches(switches: dict, epsilon: float, kernel: str, crease_angle: float = math.pi) -> Method:
    """The core method for a set of switch values (keys: the switches' property names, as in
    _SWITCHES); crease_angle in radians, as Blender stores angles."""
    return Method(**switch_fields({s.name: switches[s.prop] for s in SWITCHES}), kernel=kernel, epsilon=epsilon,
                  crease_angle=min(180.0, max(0.0, math.degrees(crease_angle))))


def _switches_of(preset: str) -> dict:
    """The switch properties' values of a preset (Method.preset is the single source of truth)."""
    return {SWITCH[name].prop: on for name, on in switches_of(Method.preset(preset)).items()}


def _on_method(self, context):
    global _syncing
    if _syncing or self.method == "CUSTOM":
        return
    _syncing = True
    try:
        for key, value in _switches_of(self.method).items():
            setattr(self, key, value)
    finally:
        _syncing = False


def _on_switch(self, context):
    global _syncing
    if _syncing:
        return
    current = self.switches()
    match = next((p for p in PRESETS if _switches_of(p) == current), "CUSTOM")
    _syncing = True
    try:
        self.method = match
    finally:
        _syncing = False


class _VisibilitySettings:
    """The settings a visibility comparison varies: the method preset and its switches,
    epsilon, the kernel and the radius factor. Shared by the scene's settings and the
    viewport's A/B slots (a mixin: Blender registers the annotations of each class that
    inherits it)."""

    method: bpy.props.EnumProperty(
        name="Method", items=_PRESET_ITEMS, default="FULL", update=_on_method,
        description="Preset of the visibility switches below",
    )
    epsilon: bpy.props.FloatProperty(
        name="Epsilon",
        description="Depth of a surface layer, in radii of its first splat: hits this close count as one surface",
        default=Method().epsilon, min=0.0, soft_max=4.0, precision=3,
    )
    radius_factor: bpy.props.FloatProperty(
        name="Radius Factor",
        description="Scales every splat radius at render time (1: each disc reaches its neighbours' centres)",
        # A hard max: discs 100 times their spacing already cover everything behind them,
        # and a factor of 1e30 put every radius beyond the renderer's limit.
        default=1.0, min=0.01, max=100.0, soft_min=0.25, soft_max=4.0, precision=3,
    )
    kernel: bpy.props.EnumProperty(
        name="Kernel",
        items=(("LINEAR", "Linear", "The paper's weight (r - d) / r"),
               ("SMOOTH", "Smooth", "(1 - (d / r)^2)^2, smooth at the splat rim")),
        default="LINEAR",
        description="Weight of a splat in the interpolated normal, by the distance of the hit from its centre",
    )
    crease_angle: bpy.props.FloatProperty(
        name="Crease Angle", subtype="ANGLE", default=math.radians(Method().crease_angle),
        min=0.0, max=math.pi,
        description="Splats whose normals differ by more than this do not blend, so sharp edges stay sharp "
                    "(like Auto Smooth); 180 degrees blends every overlapping splat as the paper does, right for "
                    "scans with estimated normals, while CAD models sampled with exact face normals want less",
    )

    def switches(self) -> dict:
        return {key: getattr(self, key) for key in _SWITCHES}

    def core_method(self, **overrides) -> Method:
        """The method these settings describe; `overrides` force switches (by property name)
        without touching the stored settings."""
        return method_from_switches({**self.switches(), **overrides}, self.epsilon, self.kernel, self.crease_angle)

    def copy_visibility(self, other) -> None:
        """Sets these settings to `other`'s (the preset follows from the switches)."""
        global _syncing
        _syncing = True
        try:
            for key in _VISIBILITY_KEYS:
                setattr(self, key, getattr(other, key))
        finally:
            _syncing = False


# One property per switch, as the switch table describes it; the default is the switch's
# value in the default Method (the Full preset, the `method` default).
_VisibilitySettings.__annotations__.update({
    s.prop: bpy.props.BoolProperty(name=s.label, description=s.description, default=s.of(Method()),
                                   update=_on_switch)
    for s in SWITCHES})

_VISIBILITY_KEYS = ("method",) + _SWITCHES + ("epsilon", "kernel", "crease_angle", "radius_factor")

_AB_MODES = (
    ("OFF", "Off", "The scene's own settings"),
    ("A", "A", "Settings A (both A and B render, so flipping to B is instant)"),
    ("B", "B", "Settings B (both A and B render, so flipping to A is instant)"),
    ("SPLIT", "Split", "A on the left of the wipe, B on its right"),
)


class SplatTracerABSlot(_VisibilitySettings, bpy.types.PropertyGroup):
    __slots__ = ()


def _on_ab_mode(self, context):
    """The first time A/B is turned on, A becomes the General preset and B the scene's
    current settings (the compare operator's default pair when the scene is Full)."""
    if self.mode == "OFF" or self.initialised:
        return
    scene_settings = self.id_data.splat_tracer
    self.b.copy_visibility(scene_settings)
    self.a.copy_visibility(scene_settings)
    self.a.method = "GENERAL"
    self.initialised = True


class SplatTracerAB(bpy.types.PropertyGroup):
    """The viewport's live A/B comparison (Rendered mode)."""
    __slots__ = ()

    mode: bpy.props.EnumProperty(name="A/B", items=_AB_MODES, default="OFF", update=_on_ab_mode,
                                 description="What the Rendered viewport shows: the scene's settings, A, B or a "
                                             "split view of both")
    a: bpy.props.PointerProperty(type=SplatTracerABSlot, name="A", description="Settings A")
    b: bpy.props.PointerProperty(type=SplatTracerABSlot, name="B", description="Settings B")
    split: bpy.props.FloatProperty(name="Split", default=0.5, min=0.0, max=1.0, subtype="FACTOR",
                                   description="Where the wipe divides the view: A left of it, B right of it")
    show_difference: bpy.props.BoolProperty(
        name="Difference", default=False,
        description="Colour the pixels where A and B differ visibly by their perceptual difference (the compare "
                    "operator's scale)",
    )
    initialised: bpy.props.BoolProperty(name="Initialised", default=False, options={"HIDDEN"},
                                        description="Whether A and B were set up from the scene")


class SplatTracerSceneSettings(_VisibilitySettings, bpy.types.PropertyGroup):
    __slots__ = ()  # Blender 5 warns about registered classes that allow arbitrary attributes

    ab: bpy.props.PointerProperty(type=SplatTracerAB, name="A/B",
                                  description="The viewport's live A/B comparison")
    lighting: bpy.props.EnumProperty(
        name="Lighting",
        items=(("SCENE", "Scene", "The scene's lamps, materials and world, with shadows, reflections and "
                                  "refractions (a scene with no light at all falls back to the headlight)"),
               ("HEADLIGHT", "Headlight", "Preview: each surface's base colour lit from the eye, no lamps and no "
                                          "secondary rays; shows the geometry the visibility rules produce")),
        default="SCENE",
        description="What lights the render",
    )
    sky_light: bpy.props.EnumProperty(
        name="Sky Light",
        items=(("BOUNCE", "Diffuse Bounces", "The world and every lit surface light the scene through diffuse "
                                             "bounce rays (Light Paths > Diffuse), as in Cycles"),
               ("AO", "Ambient Occlusion", "The world lights each diffuse point through occlusion rays only: "
                                          "cheaper, but light bounced off other surfaces is left out")),
        default="BOUNCE",
        description="How the world's light reaches diffuse surfaces",
    )
    ao_samples: bpy.props.IntProperty(
        name="AO Samples", default=1, min=1, soft_max=16, max=1024,
        description="Occlusion rays per diffuse point and camera sample, with Ambient Occlusion sky light",
    )
    # Samples are Cycles' (scene.cycles.samples, preview_samples): one place for a setting both
    # engines have. This was the engine's own before; kept so that an old file's value can be
    # moved there when it loads (migrate_samples), and read only while the Cycles add-on is off.
    samples: bpy.props.IntProperty(
        name="Samples (without Cycles)",
        description="Camera rays per pixel when the Cycles add-on is off; otherwise Cycles' Samples are used "
                    "(Sampling panel)",
        default=shading.RenderSettings.samples, min=1, soft_max=1024, max=_MAX_SAMPLES,
    )
    samples_in_cycles: bpy.props.BoolProperty(
        name="Samples in Cycles", default=False, options={"HIDDEN"},
        description="The samples are Cycles' settings: an older file's own samples were moved there",
    )
    shadow_samples: bpy.props.IntProperty(
        name="Shadow Samples",
        description="Shadow rays per lamp for each camera sample: softens the penumbra of lamps with a size "
                    "without raising the samples",
        default=shading.RenderSettings.shadow_samples, min=1, soft_max=16, max=_MAX_SHADOW_SAMPLES,
    )



class SplatTracerViewLayerSettings(bpy.types.PropertyGroup):
    __slots__ = ()

    use_pass_splat_count: bpy.props.BoolProperty(
        name="Splat Count", default=False,
        description="Debug pass: how many splats formed the surface point seen at each pixel's centre "
                    "(0 on the background and on meshes)",
    )


class SplatTracerObjectSettings(bpy.types.PropertyGroup):
    __slots__ = ()

    closed: bpy.props.BoolProperty(
        name="Closed Surface", default=False,
        description="The cloud samples a closed, hole-free surface, so the far phase may use where rays leave it "
                    "(turn off for open scans: terrain, facades, one-sided scans)",
    )


def migrate_samples(scene) -> bool:
    """Moves a scene's samples from the engine's old setting into Cycles' (Samples and
    Viewport Samples: the engine used one value for both), once, for a scene that used the
    engine: it renders with it, or its samples were set. True when moved."""
    props = scene.splat_tracer
    if props.samples_in_cycles:
        return False
    cycles = getattr(scene, "cycles", None)
    if cycles is None:
        return False  # nowhere to move them to: the legacy value stays the one read
    props.samples_in_cycles = True
    if scene.render.engine != "SPLAT_TRACER" and not props.is_property_set("samples"):
        return False
    cycles.samples = cycles.preview_samples = int(props.samples)
    return True


@bpy.app.handlers.persistent
def _on_load_post(*_args):
    for scene in bpy.data.scenes:
        migrate_samples(scene)


@bpy.app.handlers.persistent
def _on_save_pre(*_args):
    # A scene made in this version keeps its samples in Cycles from the start: marked before
    # it is saved, so that loading it again never takes it for an old file.
    for scene in bpy.data.scenes:
        if getattr(scene, "cycles", None) is not None:
            scene.splat_tracer.samples_in_cycles = True


classes = (SplatTracerABSlot, SplatTracerAB, SplatTracerSceneSettings, SplatTracerViewLayerSettings,
           SplatTracerObjectSettings)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.Scene.splat_tracer = bpy.props.PointerProperty(type=SplatTracerSceneSettings)
    bpy.types.ViewLayer.splat_tracer = bpy.props.PointerProperty(type=SplatTracerViewLayerSettings)
    bpy.types.Object.splat_tracer = bpy.props.PointerProperty(type=SplatTracerObjectSettings)
    bpy.app.handlers.load_post.append(_on_load_post)
    bpy.app.handlers.save_pre.append(_on_save_pre)


def unregister():
    for handlers, handler in ((bpy.app.handlers.load_post, _on_load_post), (bpy.app.handlers.save_pre, _on_save_pre)):
        if handler in handlers:
            handlers.remove(handler)
    del bpy.types.Object.splat_tracer
    del bpy.types.ViewLayer.splat_tracer
    del bpy.types.Scene.splat_tracer
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
