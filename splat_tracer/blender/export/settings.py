"""The one place that says which of Blender's and Cycles' render settings the engine does not
honour: each, when changed from what the engine does, named once in the render report with
what the engine does instead (the contract: never ignored in silence). Motion blur's own
approximations (deformation, a moving emitter's light) are said where it is read,
export/motion.py and export/scene.py.

Settings of one object, material, lamp or world are said where they are read (scene.py,
shading.py); this module checks the scene, the view layer and the camera, once a frame. It
reads only flags (a few dozen attribute reads: nothing measurable beside an export). Cycles'
settings exist only while the Cycles add-on is enabled: every read of them is a getattr with
the engine's behaviour as the default, so without the add-on there is nothing to say.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

from ...render import shading

# View-layer passes an artist can enable that the engine does not write: (the switch's owner on
# the view layer -- "" for Blender's own, "cycles" for the Cycles add-on's -- its property, the
# pass as Blender's Passes panel names it). The passes the engine writes are engine.py's table;
# tests/blender/test_unhonoured_settings.py checks that the two tables cover every pass switch
# of Blender's RNA, so a pass a new Blender adds fails that test instead of going unsaid.
UNWRITTEN_PASSES = (
    ("", "use_pass_subsurface_direct", "Subsurface Direct"),
    ("", "use_pass_subsurface_indirect", "Subsurface Indirect"),
    ("", "use_pass_subsurface_color", "Subsurface Color"),
    ("", "use_pass_grease_pencil", "Grease Pencil"),
    ("cycles", "use_pass_volume_direct", "Volume Direct"),
    ("cycles", "use_pass_volume_indirect", "Volume Indirect"),
    ("cycles", "use_pass_volume_scatter", "Volume Scatter"),
    ("cycles", "use_pass_volume_transmit", "Volume Transmit"),
    ("cycles", "use_pass_volume_majorant", "Volume Majorant"),
    ("cycles", "pass_debug_sample_count", "Debug Sample Count"),
    ("cycles", "pass_render_time", "Render Time"),
)


# Blender's default Alpha Threshold of the data passes (ViewLayer.pass_alpha_threshold).
_ALPHA_THRESHOLD = 0.5


def _report_cycles_scene(scene, cycles, report: shading.Report) -> None:
    """Cycles' scene settings the engine does not read (the settings audit found them)."""
    if cycles.film_exposure != 1.0:  # Cycles' brightness scale, 1 by default
        report.once(f"Cycles' Film > Exposure ({cycles.film_exposure:g}) is not applied: the image is rendered "
                    "at 1 (Color Management > Exposure, which Blender applies, brightens both engines' images)")
    if not cycles.caustics_reflective or not cycles.caustics_refractive:
        report.once("Cycles' Caustics > Reflective/Refractive off is not honoured: caustic paths are not filtered")
    if cycles.film_transparent_glass and scene.render.film_transparent:
        report.once("Cycles' Film > Transparent Glass is not honoured: glass is not made transparent in the "
                    "film's alpha")
    if cycles.use_fast_gi:
        report.once("Cycles' Fast GI Approximation is not used: indirect light is traced to the bounce limits")
    # Sample Subset came in Blender 4.4: older releases have no such setting.
    if getattr(cycles, "use_sample_subset", False):
        report.once(f"Cycles' Sample Subset is not used: all {cycles.samples} samples are taken")
    # Blender 5.2's texture cache scales the images Cycles reads (1: full resolution).
    scale = getattr(cycles, "texture_resolution_render", 1.0)
    if scale != 1.0:
        report.once(f"Cycles' Render Texture Resolution ({scale:g}) is not applied: images are read at their full "
                    "resolution")


def _on(owner, prop: str) -> bool:
    return bool(getattr(owner, prop, False)) if owner is not None else False


def stereo_views(render) -> list:
    """The views a multi-view render makes, as Blender picks them: Stereo 3D renders the
    'left' and 'right' views (those switched on), Multi-View every view switched on."""
    views = [v for v in render.views if v.use]
    if render.views_format == "STEREO_3D":
        views = [v for v in views if v.name in ("left", "right")]
    return [v.name for v in views]


# Cycles' `denoiser` enum by its stored number (properties.py's items: OptiX 2,
# OpenImageDenoise 4, the default). Read raw, by number: the enum's items are computed, and
# computing them asks Cycles for its GPU devices, which logs a CUDA warning ("CUEW
# initialization failed") in every render.
_DENOISER_OPTIX, _DENOISER_DEFAULT = 2, 4


def _stored(owner, prop: str, default):
    """An add-on property's stored value, without RNA's conversion: the system properties
    (Blender 5.0+ keeps bpy.props values there) or, before 5.0, the group's own ID
    properties; `default` when never set."""
    system = getattr(owner, "bl_system_properties_get", None)
    store = system() if system is not None else owner
    return default if store is None else store.get(prop, default)


# Cycles' denoising passes, by the names Cycles gives them (the one place they are spelled:
# the engine registers them, the session writes them, the report names the guides).
NOISY_IMAGE = "Noisy Image"
DENOISING_NORMAL = "Denoising Normal"
DENOISING_ALBEDO = "Denoising Albedo"
DENOISING_DEPTH = "Denoising Depth"
DENOISING_DATA = (DENOISING_NORMAL, DENOISING_ALBEDO, DENOISING_DEPTH)


@dataclass(frozen=True)
class Denoising:
    """Cycles' Denoise settings (Render > Sampling > Render > Denoise) as the engine applies
    them with OpenImageDenoise (blender/denoise.py)."""
    input_passes: str  # RGB, RGB_ALBEDO or RGB_ALBEDO_NORMAL
    prefilter: str     # NONE, FAST or ACCURATE
    quality: str       # HIGH, BALANCED or FAST

    @property
    def albedo(self) -> bool:
        return self.input_passes in ("RGB_ALBEDO", "RGB_ALBEDO_NORMAL")

    @property
    def normal(self) -> bool:
        return self.input_passes == "RGB_ALBEDO_NORMAL"

    def describe(self) -> str:
        inputs = {"RGB": "the image alone", "RGB_ALBEDO": f"the image and {DENOISING_ALBEDO}",
                  "RGB_ALBEDO_NORMAL": f"the image, {DENOISING_ALBEDO} and {DENOISING_NORMAL}"}[self.input_passes]
        return (f"denoised by OpenImageDenoise (CPU) from {inputs}, prefilter {self.prefilter.title()}, "
                f"quality {self.quality.title()}")


def denoising_of(scene, view_layer, report: Optional[shading.Report] = None,
                 viewport: bool = False) -> Optional[Denoising]:
    """The final render's denoising (None: off), read where Cycles keeps it: the scene's
    Denoise switch and the view layer's own (View Layer > Denoising); viewport: the
    viewport's (Sampling > Viewport > Denoise, its own passes, prefilter and quality).
    Without the Cycles add-on there is no switch, and nothing is denoised."""
    cycles = getattr(scene, "cycles", None)
    prefix = "preview_" if viewport else ""
    if not _on(cycles, f"use_{prefix}denoising"):
        return None
    if not viewport and not getattr(getattr(view_layer, "cycles", None), "use_denoising", True):
        return None
    if report is not None and not viewport and _stored(cycles, "denoiser", _DENOISER_DEFAULT) == _DENOISER_OPTIX:
        report.once("Denoiser OptiX is Cycles' GPU denoiser: the image is denoised by OpenImageDenoise instead")
    names = ("input_passes", "prefilter", "quality")
    return Denoising(*(getattr(cycles, f"{prefix}denoising_{name}") for name in names))


def denoising_passes(scene, view_layer) -> tuple:
    """The denoising passes Cycles writes, by its names: Noisy Image whenever the render is
    denoised, Denoising Normal/Albedo/Depth with the view layer's Denoising Data switch."""
    names = ()
    if denoising_of(scene, view_layer) is not None:
        names += (NOISY_IMAGE,)
    if _on(getattr(view_layer, "cycles", None), "denoising_store_passes"):
        names += DENOISING_DATA
    return names


def report_unhonoured(scene, view_layer, report: shading.Report) -> None:
    """Says, once each, the scene's and the view layer's render settings the engine does not
    honour and what it does instead. Called once a frame by the session."""
    render = scene.render
    if render.use_multiview:
        camera = scene.camera
        if camera is not None and camera.type == "CAMERA" and camera.data.type == "PANO" \
                and render.views_format == "STEREO_3D":
            # Cycles' spherical stereo moves each ray's origin by the eye offset turned with
            # the ray's direction (omni-directional stereo); the engine renders each eye as
            # a whole camera moved sideways, which is right only near the view's centre.
            report.once(f"camera '{camera.name}': stereo panorama rendered with each eye's camera moved by half "
                        "the interocular distance, not Cycles' spherical stereo (each ray's own eye offset): "
                        "the disparity is right ahead of the camera only")
    cycles = getattr(scene, "cycles", None)
    if cycles is not None:
        _report_cycles_scene(scene, cycles, report)
    owners = {"": view_layer, "cycles": getattr(view_layer, "cycles", None)}
    layer = f"view layer '{view_layer.name}'"
    if cycles is not None and view_layer.samples > 0 and getattr(cycles, "use_layer_samples", "USE") != "IGNORE":
        report.once(f"{layer}: its Samples override ({view_layer.samples}) is not used: the scene's "
                    f"{cycles.samples} samples are taken")
    for prop, label in (("use_solid", "Surfaces"), ("use_sky", "Environment")):
        if not getattr(view_layer, prop, True):
            report.once(f"{layer}: Filter > {label} off is not honoured (rendered as on)")
    if view_layer.pass_alpha_threshold != _ALPHA_THRESHOLD:
        # Read by the shader AOVs (session.py); Cycles' data passes would stop at it too.
        report.once(f"{layer}: the passes' Alpha Threshold ({view_layer.pass_alpha_threshold:g}) is read by the "
                    "Shader AOVs only: Depth, Normal and the other data passes are of the surface the "
                    "pixel-centre sample stops at")
    for owner, prop, label in UNWRITTEN_PASSES:
        if _on(owners[owner], prop):
            report.once(f"{layer}: the {label} pass is not written")
    for group in list(view_layer.lightgroups)[shading.MAX_LIGHT_GROUPS:]:
        # Past the core's bound: what the group holds lights Combined as usual.
        report.once(f"{layer}: the light group '{group.name}' pass is not written (only the first "
                    f"{shading.MAX_LIGHT_GROUPS} light groups are; what the group holds lights Combined as usual)")


def light_groups(view_layer) -> tuple:
    """The names of the view layer's light groups the engine writes a Combined_<name> pass
    for (the first shading.MAX_LIGHT_GROUPS; report_unhonoured says the rest)."""
    return tuple(g.name for g in view_layer.lightgroups)[:shading.MAX_LIGHT_GROUPS]
