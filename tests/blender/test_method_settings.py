"""The visibility method inside Blender: settings, panels, the closed guess, A/B compare."""
from __future__ import annotations

import math
import sys
from dataclasses import astuple
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.ndimage import distance_transform_edt

from blender_helpers import add_camera
from geometry import blender_camera_rays, cube_cloud, fibonacci_sphere, ray_box
from splat_tracer.pointcloud.readers import ply
from splat_tracer.render.method import SWITCHES as SWITCH_TABLE
from splat_tracer.render.method import Method

SWITCHES = ("use_wrong_hit_elimination", "use_normal_interpolation", "use_far_phase", "use_near_phase",
            "use_nearest_centre")


def test_presets_set_the_switches_and_switches_set_the_preset(blender, empty_scene):
    s = empty_scene.splat_tracer
    # The add-on has its own copy of the method module (bl_ext.dev...): compare as tuples.
    method = lambda: astuple(s.core_method())  # noqa: E731
    assert s.method == "FULL" and method() == astuple(Method.preset("FULL"))
    s.method = "GENERAL"
    assert not any(getattr(s, k) for k in SWITCHES)
    assert method() == astuple(Method.preset("GENERAL"))
    s.method = "NEAREST_CENTRE"
    assert method() == astuple(Method.preset("NEAREST_CENTRE"))
    s.use_far_phase = True  # no preset has this combination
    assert s.method == "CUSTOM" and s.core_method().far_phase
    s.use_far_phase = False
    assert s.method == "NEAREST_CENTRE"
    s.epsilon, s.kernel = 2.5, "SMOOTH"
    assert method() == astuple(Method.preset("NEAREST_CENTRE", epsilon=2.5, kernel="SMOOTH"))
    s.crease_angle = math.radians(45)  # Blender stores angles in radians, the core takes degrees
    assert s.core_method().crease_angle == pytest.approx(45)


class _Layout:
    """Stands in for a UI layout: records the properties drawn into it and its sub-layouts."""

    def __init__(self, drawn: list):
        self.drawn = drawn

    def prop(self, data, key, **kwargs):
        self.drawn.append(key)

    def __getattr__(self, name):  # column(), row(), box(), label(), operator(), ...
        return lambda *args, **kwargs: _Layout(self.drawn)


def test_the_switch_table_makes_the_properties_the_compare_toggles_and_the_panels(blender, empty_scene):
    """Each switch of the table is a property of its name with its label and description, a
    toggle of the compare operator, and drawn once by the Visibility panel and an A/B slot."""
    bpy = blender
    assert SWITCHES == tuple(s.prop for s in SWITCH_TABLE)  # the names saved files and scripts use
    group = bpy.types.Scene.bl_rna.properties["splat_tracer"].fixed_type
    for switch in SWITCH_TABLE:
        prop = group.properties[switch.prop]
        assert (prop.name, prop.description) == (switch.label, switch.description)
    toggle = bpy.ops.splat_tracer.compare.get_rna_type().properties["toggle"]
    assert [(i.identifier, i.name) for i in toggle.enum_items] == [("NONE", "None")] + [
        (s.prop, s.label) for s in SWITCH_TABLE]
    panel = bpy.types.SPLAT_TRACER_PT_visibility
    drawn = []
    panel.draw(SimpleNamespace(layout=_Layout(drawn)), bpy.context)
    switches = set(SWITCHES)
    assert sorted(k for k in drawn if k in switches) == sorted(switches)
    drawn = []
    sys.modules[panel.__module__]._draw_slot(_Layout(drawn), empty_scene.splat_tracer.ab.a, "A")
    assert sorted(k for k in drawn if k in switches) == sorted(switches)


def test_panels_show_only_for_this_engine_and_every_setting_says_what_it_does(blender, empty_scene):
    bpy = blender
    panels = [bpy.types.SPLAT_TRACER_PT_render, bpy.types.SPLAT_TRACER_PT_visibility,
              bpy.types.SPLAT_TRACER_PT_passes]
    assert all(p.poll(bpy.context) for p in panels)
    empty_scene.render.engine = "CYCLES"
    assert not any(p.poll(bpy.context) for p in panels)
    for group in (bpy.types.Scene.bl_rna.properties["splat_tracer"].fixed_type,
                  bpy.types.Object.bl_rna.properties["splat_tracer"].fixed_type):
        for prop in group.properties:
            if prop.identifier == "rna_type":
                continue
            text = prop.description
            assert text and text[0].isupper() and text.count(". ") == 0, (prop.identifier, text)


def test_import_guesses_whether_the_surface_is_closed(blender, empty_scene, tmp_path):
    bpy = blender
    p, n = fibonacci_sphere(5000)
    ply.write_ply(str(tmp_path / "ball.ply"), p, n)
    g = np.stack(np.meshgrid(np.linspace(-1, 1, 70), np.linspace(-1, 1, 70)), -1).reshape(-1, 2)
    patch = np.column_stack([g, 0.1 * np.sin(2 * g[:, 0])])
    ply.write_ply(str(tmp_path / "terrain.ply"), patch, np.tile([0.0, 0.0, 1.0], (len(patch), 1)))
    bpy.ops.splat_tracer.import_cloud(directory=str(tmp_path), files=[{"name": "ball.ply"}, {"name": "terrain.ply"}])
    assert bpy.data.objects["ball"].splat_tracer.closed is True
    assert bpy.data.objects["terrain"].splat_tracer.closed is False
    assert "boundary" in bpy.data.objects["terrain"]["splat_tracer_closed_guess"]


def image_pixels(image) -> np.ndarray:
    w, h = image.size
    buf = np.empty(w * h * 4, np.float32)
    image.pixels.foreach_get(buf)
    return buf.reshape(h, w, 4)[::-1]  # top row first


def face_interiors(origins, dirs, t, radii):
    """(true coverage, pixels whose true surface point is more than 3 splat radii from any
    cube edge and 3 pixels inside the silhouette): where no rule can change anything."""
    truth = np.isfinite(t).reshape(240, 320)
    hit = origins + dirs * np.where(np.isfinite(t), t, 0)[:, None]
    sorted_abs = np.sort(np.abs(hit), axis=1)  # the largest coordinate is the face's
    to_edge = (1.0 - sorted_abs[:, 1]).reshape(240, 320)
    return truth, truth & (to_edge > 3 * radii.max()) & (distance_transform_edt(truth) > 3)


@pytest.fixture
def cube_in_blender(blender, empty_scene, tmp_path):
    """An imported cube cloud, a camera, and the analytic coverage of the cube."""
    bpy = blender
    scene = empty_scene
    p, n = cube_cloud(50)
    ply.write_ply(str(tmp_path / "cube.ply"), p, n)
    bpy.ops.splat_tracer.import_cloud(filepath=str(tmp_path / "cube.ply"))
    obj = bpy.context.active_object
    assert obj.splat_tracer.closed  # guessed: a cube has edges but no boundary
    radii = np.empty(len(p), np.float32)
    obj.data.attributes["splat_radius"].data.foreach_get("value", radii)
    cam = add_camera(bpy, scene, (3.2, -5.0, 3.6), (math.radians(55), 0.0, math.radians(33)))
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 320, 240, 100
    # One sample per pixel, at its centre: these tests compare coverage with the analytic
    # cube pixel by pixel (anti-aliasing spreads an edge over the filter's 1.5 px).
    scene.cycles.samples = 1
    origins, dirs, _ = blender_camera_rays(np.array(cam.matrix_world), 320, 240)
    t, _ = ray_box(origins, dirs)
    return scene, radii, origins, dirs, t


def test_compare_operator_headless_differs_exactly_at_edges_and_fringe(blender, cube_in_blender, tmp_path):
    """General (no correction) against the full method on a cube: the two differ at the
    silhouette fringe and along the edges, and nowhere on the faces' interiors."""
    bpy = blender
    scene, radii, origins, dirs, t = cube_in_blender
    out = tmp_path / "compare"
    assert bpy.ops.splat_tracer.compare(a="GENERAL", b="FULL", directory=str(out)) == {"FINISHED"}
    a, b, diff = (image_pixels(bpy.data.images[name]) for name in
                  ("Splat Compare A", "Splat Compare B", "Splat Compare Difference"))
    assert sorted(f.name for f in out.iterdir()) == ["compare_a.png", "compare_b.png", "compare_difference.png"]
    delta = np.abs(a - b).max(axis=2)
    differs = delta > 1e-3
    assert bpy.data.images["Splat Compare Difference"]["splat_tracer_differing_pixels"] == differs.sum()
    # The difference image is the fixed scale of ΔE between what A and B show (test_compare_operator.py
    # checks the colours); its legend strip lies below the 240 rows of the image.
    assert diff.shape[0] > 240 and diff.shape[1] == 320
    shown = diff[:240][..., :3].max(axis=2) > 0
    assert shown[~differs].mean() < 0.01 and shown[differs].mean() > 0.9

    truth, interior = face_interiors(origins, dirs, t, radii)
    assert interior.sum() > 5000 and not differs[interior].any()
    fringe = differs & ~truth
    assert fringe.sum() > 100  # the general method's fringe, gone in the full method
    assert differs[truth & ~interior].sum() > 100  # along the edges
    outside = ~truth & (distance_transform_edt(~truth) > 2)
    assert b[..., :3][outside].max() == 0.0  # B shows only the (black) background there: no fringe


def test_compare_toggle_shows_one_switch(blender, cube_in_blender):
    """Toggle mode: the scene's settings without and with one switch. The far phase on a
    closed cube removes the fringe outside the silhouette and the fringe discs seen in
    front of the cube's own faces along its edges; face interiors do not change."""
    bpy = blender
    scene, radii, origins, dirs, t = cube_in_blender
    scene.splat_tracer.method = "FULL"
    assert bpy.ops.splat_tracer.compare(toggle="use_far_phase") == {"FINISHED"}
    a, b = (image_pixels(bpy.data.images[name]) for name in ("Splat Compare A", "Splat Compare B"))
    differs = np.abs(a - b).max(axis=2) > 1e-3
    truth, interior = face_interiors(origins, dirs, t, radii)
    assert (differs & ~truth).sum() > 100 and (differs & truth).sum() > 50
    assert not differs[interior].any()
    assert scene.splat_tracer.use_far_phase and scene.splat_tracer.method == "FULL"  # settings untouched


def test_full_render_through_blender_has_the_true_cube_silhouette(blender, empty_scene, tmp_path):
    from blender_helpers import render_to_exr

    bpy = blender
    scene = empty_scene
    p, n = cube_cloud(50)
    ply.write_ply(str(tmp_path / "cube.ply"), p, n)
    bpy.ops.splat_tracer.import_cloud(filepath=str(tmp_path / "cube.ply"))
    cam = add_camera(bpy, scene, (3.2, -5.0, 3.6), (math.radians(55), 0.0, math.radians(33)))
    origins, dirs, _ = blender_camera_rays(np.array(cam.matrix_world), 320, 240)
    truth = np.isfinite(ray_box(origins, dirs)[0]).reshape(240, 320)
    edge = np.maximum(distance_transform_edt(truth), distance_transform_edt(~truth))
    wrong = {}
    for method in ("FULL", "GENERAL"):
        scene.splat_tracer.method = method
        out = render_to_exr(bpy, scene, tmp_path / f"{method}.exr", 320, 240)
        wrong[method] = (out["depth"] < 1e9) != truth
    # Full: a handful of pixels, each within about a pixel of the silhouette (2 at most).
    assert wrong["FULL"].sum() < 30 and edge[wrong["FULL"]].max() <= 2.0
    # General: the fringe runs along every silhouette edge.
    assert wrong["GENERAL"].sum() > 10 * max(wrong["FULL"].sum(), 20)
