"""Noise control read from where Cycles keeps it (issue #25 item 4), through real Blender: the
samples' one source of truth (scene.cycles) and the migration of an old file's own samples;
clamping, adaptive sampling and the time limit changing the render when changed in
scene.cycles, and the render report saying what adaptive sampling saved and where a time
limit cut. Small images and few samples.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from blender_helpers import add_camera, extension_module

pytestmark = pytest.mark.blender


def lit_plane(bpy, scene, strength=10.0):
    """A Lambert plane under a sun straight above, seen from above: every pixel is
    0.8 / pi x strength (2.546 for 10)."""
    bpy.ops.mesh.primitive_plane_add(size=100.0)
    plane = bpy.context.object
    mat = bpy.data.materials.new("Matte")
    mat.use_nodes = True
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (0.8, 0.8, 0.8, 1.0)
    bsdf.inputs["Roughness"].default_value = 1.0
    bsdf.inputs["Specular IOR Level"].default_value = 0.0
    plane.data.materials.append(mat)
    sun = bpy.data.lights.new("Sun", "SUN")
    sun.energy, sun.angle = strength, 0.0
    scene.collection.objects.link(bpy.data.objects.new("Sun", sun))
    add_camera(bpy, scene, (0, 0, 5), (0, 0, 0))
    scene.world = None
    scene.render.resolution_x, scene.render.resolution_y = 16, 12
    scene.view_settings.view_transform = "Standard"


def render(bpy, scene):
    session = extension_module("blender.session")
    bpy.context.view_layer.update()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    frame = session.render_frame(depsgraph, scene.splat_tracer.core_method())
    return frame.passes["Combined"][..., :3].astype(np.float64), frame.stats


def test_samples_are_read_from_cycles(blender, empty_scene):
    es = extension_module("blender.export.shading")
    scene = empty_scene
    scene.cycles.samples, scene.cycles.preview_samples = 24, 6
    scene.splat_tracer.samples = 99  # the old setting: no longer read while Cycles is on
    assert es.render_settings_of(scene).samples == 24
    assert es.render_settings_of(scene, viewport=True).samples == 6
    scene.cycles.preview_samples = 0  # Cycles' "no limit" in the viewport
    assert es.render_settings_of(scene, viewport=True).samples == 1 << 16


def test_every_noise_setting_is_read_from_scene_cycles(blender, empty_scene):
    es = extension_module("blender.export.shading")
    scene, c = empty_scene, empty_scene.cycles
    c.sample_clamp_direct, c.sample_clamp_indirect, c.blur_glossy = 2.0, 3.0, 0.5
    c.use_adaptive_sampling, c.adaptive_threshold, c.adaptive_min_samples, c.time_limit = True, 0.02, 12, 1.5
    c.use_preview_adaptive_sampling, c.preview_adaptive_threshold, c.preview_adaptive_min_samples = False, 0.2, 3
    s = es.render_settings_of(scene)
    assert (s.clamp_direct, s.clamp_indirect, s.filter_glossy) == (2.0, 3.0, 0.5)
    assert (s.adaptive, s.adaptive_min_samples, s.time_limit) == (True, 12, 1.5)
    assert s.adaptive_threshold == pytest.approx(0.02)
    v = es.render_settings_of(scene, viewport=True)
    assert (v.adaptive, v.adaptive_min_samples, v.time_limit) == (False, 3, 0.0)  # no time limit in the viewport
    assert v.adaptive_threshold == pytest.approx(0.2)


def _save_as_old_file(bpy, path):
    """Saves without the save handler that marks scenes as keeping their samples in Cycles:
    the file is what an older version of the add-on wrote."""
    handlers = [h for h in bpy.app.handlers.save_pre if h.__name__ == "_on_save_pre"]
    for h in handlers:
        bpy.app.handlers.save_pre.remove(h)
    try:
        bpy.ops.wm.save_as_mainfile(filepath=str(path))
    finally:
        bpy.app.handlers.save_pre.extend(handlers)


def test_an_old_file_keeps_its_sample_count(blender, empty_scene, tmp_path):
    bpy, scene = blender, empty_scene
    lit_plane(bpy, scene)
    scene.cycles.samples = scene.cycles.preview_samples = 4096
    scene.splat_tracer.samples = 7
    scene.splat_tracer.samples_in_cycles = False
    _save_as_old_file(bpy, tmp_path / "old.blend")
    bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "old.blend"))
    scene = bpy.context.scene
    assert (scene.cycles.samples, scene.cycles.preview_samples) == (7, 7)
    scene.cycles.use_adaptive_sampling = False
    _, stats = render(bpy, scene)
    assert stats["samples"] == 7 and stats["samples_taken"] == 7 * 16 * 12
    # Once moved, the samples are Cycles': a change survives saving and loading again.
    scene.cycles.samples = 9
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "new.blend"))
    bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "new.blend"))
    assert bpy.context.scene.cycles.samples == 9


def test_an_old_cycles_file_is_left_alone(blender, empty_scene, tmp_path):
    bpy, scene = blender, empty_scene
    scene.render.engine = "CYCLES"
    scene.cycles.samples = 128
    scene.splat_tracer.samples_in_cycles = False
    _save_as_old_file(bpy, tmp_path / "cycles.blend")
    bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "cycles.blend"))
    assert bpy.context.scene.cycles.samples == 128  # never used the engine: its default 16 is not moved


def test_clamp_direct_from_cycles_changes_the_render(blender, empty_scene):
    bpy, scene = blender, empty_scene
    lit_plane(bpy, scene)
    c = scene.cycles
    c.samples, c.use_adaptive_sampling, c.sample_clamp_direct, c.sample_clamp_indirect = 1, False, 0.0, 0.0
    free, _ = render(bpy, scene)
    assert np.allclose(free, 0.8 / math.pi * 10.0, rtol=1e-4)
    c.sample_clamp_direct = 0.5  # R + G + B at most 1.5
    clamped, _ = render(bpy, scene)
    assert np.allclose(clamped, 0.5, rtol=1e-4)
    c.sample_clamp_direct, c.sample_clamp_indirect = 0.0, 0.5  # the plane's light is direct: unchanged
    assert np.allclose(render(bpy, scene)[0], free, rtol=1e-5)


def test_adaptive_sampling_and_time_limit_from_cycles_and_the_report(blender, empty_scene):
    bpy, scene = blender, empty_scene
    lit_plane(bpy, scene)
    session = extension_module("blender.session")
    c = scene.cycles
    c.samples, c.use_adaptive_sampling, c.adaptive_threshold, c.adaptive_min_samples = 256, True, 0.01, 4
    img, stats = render(bpy, scene)
    # A noise-free plane stops at Cycles' first check after the minimum: 16 samples.
    assert stats["samples_taken"] == 16 * 16 * 12
    assert stats["sampling"] == "adaptive sampling: 16.0 samples per pixel on average, of 256 (94 % saved)"
    c.use_adaptive_sampling = False
    c.samples, c.time_limit = 1 << 16, 0.2
    _, stats = render(bpy, scene)
    assert stats["time_limited"] and stats["samples_reached"] < 1 << 16
    assert stats["sampling"].startswith(f"time limit 0.2 s reached after {stats['samples_reached']} of 65536")
    assert stats["render_seconds"] < 0.2 + 0.25  # the limit honoured (see tests/render/test_noise_control.py)
    assert session.HISTORY[-1] is not None
