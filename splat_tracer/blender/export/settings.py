"""The one place that says which of Blender's and Cycles' render settings the engine does not
honour: each, when changed from what the engine does, named once in the render report with
what the engine does instead (the contract: never ignored in silence).

Settings of one object, material, lamp or world are said where they are read (scene.py,
shading.py); this module checks the scene, the view layer and the camera, once a frame. It
reads only flags (a few dozen attribute reads: nothing measurable beside an export). Cycles'
settings exist only while the Cycles add-on is enabled: every read of them is a getattr with
the engine's behaviour as the default, so without the add-on there is nothing to say.
"""
from __future__ import annotations

from ...render import shading

# View-layer passes an artist can enable that the engine does not write: (the switch's owner on
# the view layer -- "" for Blender's own, "cycles" for the Cycles add-on's -- its property, the
# pass as Blender's Passes panel names it). The passes the engine writes are engine.py's table;
# tests/blender/test_unhonoured_settings.py checks that the two tables cover every pass switch
# of Blender's RNA, so a pass a new Blender adds fails that test instead of going unsaid.
UNWRITTEN_PASSES = (
    ("", "use_pass_vector", "Vector"),
    ("", "use_pass_uv", "UV"),  # meshes' UV maps are not exported
    ("", "use_pass_ambient_occlusion", "Ambient Occlusion"),
    ("", "use_pass_diffuse_direct", "Diffuse Direct"),
    ("", "use_pass_diffuse_indirect", "Diffuse Indirect"),
    ("", "use_pass_glossy_direct", "Glossy Direct"),
    ("", "use_pass_glossy_indirect", "Glossy Indirect"),
    ("", "use_pass_glossy_color", "Glossy Color"),
    ("", "use_pass_transmission_direct", "Transmission Direct"),
    ("", "use_pass_transmission_indirect", "Transmission Indirect"),
    ("", "use_pass_transmission_color", "Transmission Color"),
    ("", "use_pass_subsurface_direct", "Subsurface Direct"),
    ("", "use_pass_subsurface_indirect", "Subsurface Indirect"),
    ("", "use_pass_subsurface_color", "Subsurface Color"),
    ("", "use_pass_cryptomatte_object", "Cryptomatte Object"),
    ("", "use_pass_cryptomatte_material", "Cryptomatte Material"),
    ("", "use_pass_cryptomatte_asset", "Cryptomatte Asset"),
    ("", "use_pass_grease_pencil", "Grease Pencil"),
    ("cycles", "denoising_store_passes", "Denoising Data"),
    ("cycles", "use_pass_volume_direct", "Volume Direct"),
    ("cycles", "use_pass_volume_indirect", "Volume Indirect"),
    ("cycles", "use_pass_volume_scatter", "Volume Scatter"),
    ("cycles", "use_pass_volume_transmit", "Volume Transmit"),
    ("cycles", "use_pass_volume_majorant", "Volume Majorant"),
    ("cycles", "pass_debug_sample_count", "Debug Sample Count"),
    ("cycles", "pass_render_time", "Render Time"),
)


def _on(owner, prop: str) -> bool:
    return bool(getattr(owner, prop, False)) if owner is not None else False


def stereo_views(render) -> list:
    """The views a multi-view render makes, as Blender picks them: Stereo 3D renders the
    'left' and 'right' views (those switched on), Multi-View every view switched on."""
    views = [v for v in render.views if v.use]
    if render.views_format == "STEREO_3D":
        views = [v for v in views if v.name in ("left", "right")]
    return [v.name for v in views]


def report_unhonoured(scene, view_layer, report: shading.Report) -> None:
    """Says, once each, the scene's and the view layer's render settings the engine does not
    honour and what it does instead. Called once a frame by the session."""
    render = scene.render
    if render.use_motion_blur:
        report.once(f"Motion Blur is not rendered: the frame is rendered sharp at frame {scene.frame_current}'s "
                    f"time (the shutter of {render.motion_blur_shutter:g} frames is ignored)")
    if render.use_multiview:
        views = ", ".join(f"'{v}'" for v in stereo_views(render))
        report.once(f"Stereoscopy is not rendered: every view ({views}) gets the same image, from the scene "
                    "camera itself (no eye separation, no per-view camera)")
    cycles = getattr(scene, "cycles", None)
    if _on(cycles, "use_denoising") and getattr(getattr(view_layer, "cycles", None), "use_denoising", True):
        # The denoiser is not named: reading Cycles' `denoiser` enum (its items are computed)
        # initialises Cycles' GPU libraries, which logs a CUDA warning in every render.
        report.once("Cycles' Denoise is not applied: the image keeps its noise. The compositor's "
                    "Denoise node, "
                    "fed the Normal and Diffuse Color passes the engine writes, denoises it (turn Denoise off "
                    "in Splat Tracer > Sampling to silence this line)")
    owners = {"": view_layer, "cycles": getattr(view_layer, "cycles", None)}
    layer = f"view layer '{view_layer.name}'"
    for owner, prop, label in UNWRITTEN_PASSES:
        if _on(owners[owner], prop):
            report.once(f"{layer}: the {label} pass is not written")
    for group in view_layer.lightgroups:
        # One place for light groups: the lamps, objects and world a group holds light the
        # image as any other, so only the missing pass is worth saying.
        report.once(f"{layer}: the light group '{group.name}' pass is not written (what the group holds "
                    "lights Combined as usual)")
