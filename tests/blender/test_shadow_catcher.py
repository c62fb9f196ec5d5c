"""Shadow catcher, holdout and the world's ray visibility (issue 26, items 1 and 4) through
Blender, side by side with Cycles.

One scene for both engines: a scan (a splat-cloud sphere, which Cycles renders as its
points) over a floor, a slanted sun and a grey world, seen from above at 160x120 with 64
samples (Cycles: CPU, no denoising, no adaptive sampling). The regions are Cycles' own,
from its Object Index and alpha, so that a wrong render cannot move them: "on the scan"
(both engines see the cloud), "in the shadow" (Cycles' alpha > 0.45 on the floor, eroded),
"outside" (the floor 3 pixels and more away from any pixel where Cycles' alpha > 0.02).
The photograph is a colour gradient; compositing is Blender's Alpha Over of a
premultiplied image: rgb + photograph x (1 - alpha).

Tolerances (each measured with bpy 5.0.1, and shown below to reject a wrong render):
- ALPHA_TOL = 0.06 between the two engines' mean alpha (or Shadow Catcher pass) in the
  shadow: measured alpha 0.576 here, 0.601 in Cycles; pass 0.424 and 0.399; on an opaque
  film the world behind the shadow 0.212 and 0.199 (tolerance 0.06 x the world's 0.5). The
  floor without a catcher (what the engine did before: an opaque floor) is off by 0.40 in
  the shadow and by 1.0 outside.
- Outside the shadow, alpha: mean below OUTSIDE_TOL / 4 = 0.0025, 99th percentile below
  2 x OUTSIDE_TOL = 0.02 in both engines (measured: mean 0.0002 here, 0.0009 in Cycles; 99th
  percentile 0.004 and 0.013). It is exactly 0 on most pixels here -- both paths of a
  catcher sample take the same random numbers; what remains is the sky light the ball takes
  from the floor near it, in Cycles too. The Shadow Catcher pass there: mean 1 within
  OUTSIDE_TOL (1.006 here, 1.007 in Cycles).
- LIGHT_RTOL = 0.04 for lit floor brightness between engines (the diffuse floor under the
  sun and the world, the world hidden from the camera: 0.974 here, 0.967 in Cycles), and for
  the darkening that hiding the world from diffuse rays brings (floor 0.600 of its
  brightness here, 0.600 in Cycles; a renderer ignoring the setting keeps 1.0).
- The world hidden from the camera: its pixels black (below OUTSIDE_TOL) with alpha exactly
  0 on a transparent film and 1 on an opaque one, in both engines; the world seen (what the
  engine did before) leaves them at 0.5.
"""
from __future__ import annotations

import math
import sys
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.ndimage import binary_dilation

from blender_helpers import add_camera
from test_method_settings import _Layout
from test_scene_export import INDEX, cloud_sphere, erode, lamp, plane, principled, render

W, H = 160, 120
SAMPLES = 64
FLOOR, SCAN = 1, 2
WORLD = 0.5
ALPHA_TOL, OUTSIDE_TOL, LIGHT_RTOL = 0.06, 0.01, 0.04


def scan_on_floor(bpy):
    """A new empty scene with a grey cloud sphere, the "scan" (Object Index SCAN), over an 8 m
    grey floor (FLOOR): the scene here and in test_world_environment.py, before its camera and
    light. Returns (scene, floor, scan)."""
    bpy.ops.wm.read_homefile(use_empty=True)
    grey = principled(bpy, "Grey")
    floor = plane(bpy, "Floor", 8.0, (0, 0, 0), grey)
    scan = cloud_sphere(bpy, "Scan", 4000, 0.6, (0, 0, 1.0), grey)
    floor.pass_index, scan.pass_index = FLOOR, SCAN
    return bpy.context.scene, floor, scan


def _scene(bpy):
    scene, floor, scan = scan_on_floor(bpy)
    lamp(bpy, "SUN", rotation=(math.radians(-35), 0, 0), energy=3.0)
    add_camera(bpy, scene, (0, -5, 4), (math.radians(60), 0, 0))
    scene.world = bpy.data.worlds.new("Grey")
    scene.world.node_tree.nodes["Background"].inputs["Color"].default_value = (WORLD, WORLD, WORLD, 1)
    c = scene.cycles
    c.samples, c.device, c.use_denoising, c.use_adaptive_sampling = SAMPLES, "CPU", False, False
    scene.splat_tracer.samples = SAMPLES
    scene.view_layers[0].use_pass_object_index = True
    return scene, floor, scan


# Each case: what is set on the scene above.
CASES = {
    "plain": dict(),
    "catcher": dict(catcher=True, transparent=True),
    "catcher_pass": dict(catcher=True, transparent=True, catcher_pass=True),
    "catcher_opaque": dict(catcher=True),
    "holdout": dict(holdout=True, transparent=True),
    "world_camera_off": dict(camera=False),
    "world_camera_off_transparent": dict(camera=False, transparent=True),
    "world_diffuse_off": dict(diffuse=False),
}


@pytest.fixture(scope="module")
def renders(blender, tmp_path_factory):
    """renders(case, engine) -> the view layer's passes, each rendered once per module."""
    folder = tmp_path_factory.mktemp("catcher")
    scene, floor, scan = _scene(blender)
    cache = {}

    def get(case, engine="SPLAT_TRACER"):
        if (case, engine) not in cache:
            cfg = CASES[case]
            scene.render.engine = engine
            scene.render.film_transparent = cfg.get("transparent", False)
            scene.view_layers[0].cycles.use_pass_shadow_catcher = cfg.get("catcher_pass", False)
            floor.is_shadow_catcher = cfg.get("catcher", False)
            scan.is_holdout = cfg.get("holdout", False)
            vis = scene.world.cycles_visibility
            vis.camera, vis.diffuse = cfg.get("camera", True), cfg.get("diffuse", True)
            cache[case, engine] = render(blender, scene, folder / f"{case}_{engine}.exr", (W, H))["ViewLayer"]
        return cache[case, engine]
    return get


def regions(renders) -> dict:
    """Masks of Cycles' render with the catcher (see the module's docstring); the scan's
    pixels are those both engines see it on (Cycles' points are spheres a little larger
    than the splats' discs)."""
    cycles = renders("catcher", "CYCLES")
    alpha = cycles["Combined"][..., 3]
    floor = erode(cycles[INDEX] == FLOOR, 2)
    return {"scan": erode(cycles[INDEX] == SCAN, 2) & erode(renders("plain")[INDEX] == SCAN, 2),
            "shadow": floor & erode(alpha > 0.45, 1),
            "outside": floor & ~binary_dilation(alpha > 0.02, iterations=3)}


def photograph() -> np.ndarray:
    """The background plate: a colour gradient (any image would do)."""
    y, x = np.mgrid[:H, :W] / np.array([H, W])[:, None, None]
    return np.stack([0.2 + 0.6 * x, np.full_like(x, 0.4), 0.8 - 0.5 * y], axis=-1)


def alpha_over(rgba: np.ndarray, plate: np.ndarray) -> np.ndarray:
    """Blender's Alpha Over node (premultiplied foreground) of a render over a plate."""
    return rgba[..., :3] + plate * (1.0 - rgba[..., 3:4])


def composite_matches(ours: np.ndarray, cycles: np.ndarray, masks: dict) -> bool:
    """Whether our Combined, composited over the photograph, agrees with Cycles' region by
    region: the shadow darkens the plate as much (mean alpha within ALPHA_TOL), outside it
    the plate is untouched (on average within OUTSIDE_TOL / 4), the scan covers it."""
    plate = photograph()
    ours_c, cycles_c = alpha_over(ours, plate), alpha_over(cycles, plate)
    shadow, outside, scan = masks["shadow"], masks["outside"], masks["scan"]
    # The plate's darkening in the shadow: 1 - composite / plate = alpha where rgb is 0.
    dark = lambda c: 1.0 - (c[shadow] / plate[shadow]).mean()  # noqa: E731
    return bool(abs(dark(ours_c) - dark(cycles_c)) < ALPHA_TOL
                and np.abs(ours_c[outside] - plate[outside]).mean() < OUTSIDE_TOL / 4
                and ours[..., 3][scan].min() > 0.99)


def test_a_scan_on_a_catcher_floor_composites_over_a_photograph_as_in_cycles(renders):
    cycles, ours = renders("catcher", "CYCLES"), renders("catcher")
    masks = regions(renders)
    assert all(m.sum() > 150 for m in masks.values()), {k: int(m.sum()) for k, m in masks.items()}
    a_ours, a_cycles = ours["Combined"][..., 3], cycles["Combined"][..., 3]
    print("alpha in the shadow: ours", a_ours[masks["shadow"]].mean(), "Cycles", a_cycles[masks["shadow"]].mean())
    print("alpha outside: ours", a_ours[masks["outside"]].max(), "Cycles", a_cycles[masks["outside"]].mean())
    assert a_ours[masks["shadow"]].mean() == pytest.approx(a_cycles[masks["shadow"]].mean(), abs=ALPHA_TOL)
    for a in (a_ours, a_cycles):
        assert a[masks["outside"]].mean() < OUTSIDE_TOL / 4 and np.percentile(a[masks["outside"]], 99) < 2 * OUTSIDE_TOL
    # The same path twice: exactly unshadowed, except where a sample's bounce ray meets the scan
    # (measured: 89 % of the pixels exactly 0; a second path with numbers of its own: none).
    assert (a_ours[masks["outside"]] == 0.0).mean() > 0.85
    assert a_ours[masks["scan"]].min() > 0.99 and a_cycles[masks["scan"]].mean() > 0.99
    # The catcher is transparent in Combined: no colour of its own over the plate.
    assert np.abs(ours["Combined"][..., :3][masks["shadow"] | masks["outside"]]).max() < 1e-6
    assert composite_matches(ours["Combined"], cycles["Combined"], masks)
    # The floor as the engine rendered it before (no catcher: opaque grey) fails the check.
    assert not composite_matches(renders("plain")["Combined"], cycles["Combined"], masks)


def test_the_shadow_catcher_pass_matches_cycles(renders):
    """With the pass on, Cycles leaves the shadow out of Combined (the catcher is a hole,
    even on an opaque film) and puts it in the pass, under the same layer and channel
    names."""
    cycles, ours = renders("catcher_pass", "CYCLES"), renders("catcher_pass")
    masks = regions(renders)
    assert sorted(ours) == sorted(cycles) == ["Combined", "Object Index", "Shadow Catcher"]
    sc_ours, sc_cycles = ours["Shadow Catcher"], cycles["Shadow Catcher"]
    assert sc_ours.shape == sc_cycles.shape == (H, W, 3)
    print("Shadow Catcher in the shadow: ours", sc_ours[masks["shadow"]].mean(), "Cycles",
          sc_cycles[masks["shadow"]].mean())
    assert sc_ours[masks["shadow"]].mean() == pytest.approx(sc_cycles[masks["shadow"]].mean(), abs=ALPHA_TOL)
    for sc in (sc_ours, sc_cycles):  # a little above 1 where the scan lights the floor
        assert sc[masks["outside"]].mean() == pytest.approx(1.0, abs=OUTSIDE_TOL)
        assert np.percentile(sc[masks["outside"]], 1) > 1 - 2 * OUTSIDE_TOL
    assert (sc_ours[masks["scan"]] == 1.0).all()  # no catcher sample there
    for out in (ours, cycles):
        floor = masks["shadow"] | masks["outside"]
        assert out["Combined"][..., 3][floor].max() < OUTSIDE_TOL
    # The opaque floor of before has no Shadow Catcher pass at all, and a pass of 1s
    # (a catcher ignored) would be off by 0.6 in the shadow.
    assert abs(1.0 - sc_cycles[masks["shadow"]].mean()) > 5 * ALPHA_TOL


def test_an_opaque_film_shows_the_world_darkened_by_the_shadow_as_cycles(renders):
    cycles, ours = renders("catcher_opaque", "CYCLES"), renders("catcher_opaque")
    masks = regions(renders)
    for out in (ours, cycles):
        assert (out["Combined"][..., 3] == 1.0).all()
        assert out["Combined"][..., :3][masks["outside"]].mean() == pytest.approx(WORLD, rel=OUTSIDE_TOL)
    shade = lambda out: out["Combined"][..., 0][masks["shadow"]].mean()  # noqa: E731
    print("world behind the shadow: ours", shade(ours), "Cycles", shade(cycles))
    assert shade(ours) == pytest.approx(shade(cycles), abs=WORLD * ALPHA_TOL)
    assert shade(cycles) < WORLD * 0.6
    # The opaque floor of before shows itself (lit: 0.97), not the world, outside the shadow.
    assert abs(renders("plain")["Combined"][..., 0][masks["outside"]].mean() - WORLD) > 0.3


def test_holdout_on_the_scan_cuts_alpha_as_in_cycles(renders):
    cycles, ours = renders("holdout", "CYCLES"), renders("holdout")
    scan = regions(renders)["scan"]
    floor = erode(cycles[INDEX] == FLOOR, 2) & erode(ours[INDEX] == FLOOR, 2)
    assert (ours["Combined"][..., 3][scan] == 0.0).all() and cycles["Combined"][..., 3][scan].max() < OUTSIDE_TOL
    assert (ours["Combined"][..., 3][floor] == 1.0).all() and cycles["Combined"][..., 3][floor].min() == 1.0
    assert renders("catcher")["Combined"][..., 3][scan].min() > 0.99  # not held out: covered


def _floor(ours, cycles):
    return erode(cycles[INDEX] == FLOOR, 2) & erode(ours[INDEX] == FLOOR, 2)


def test_world_hidden_from_camera_rays_as_in_cycles(renders):
    """The background turns black (alpha 0 on a transparent film, 1 on an opaque one, as
    Cycles) and still lights the scene: the floor's pixels are the same numbers as with
    the world seen."""
    plain = renders("plain")
    for case in ("world_camera_off_transparent", "world_camera_off"):
        cycles, ours = renders(case, "CYCLES"), renders(case)
        sky = erode(cycles[INDEX] == 0, 2) & erode(ours[INDEX] == 0, 2)
        floor = _floor(ours, cycles)
        assert sky.sum() > 1000 and floor.sum() > 5000
        expected_alpha = 0.0 if case.endswith("transparent") else 1.0
        for out in (ours, cycles):
            assert np.abs(out["Combined"][..., :3][sky]).max() < OUTSIDE_TOL
            assert (out["Combined"][..., 3][sky] == expected_alpha).all()
        assert np.array_equal(ours["Combined"][..., :3][floor], plain["Combined"][..., :3][floor])
        lit = lambda out: out["Combined"][..., :3][floor].mean()  # noqa: E731
        print(case, "floor: ours", lit(ours), "Cycles", lit(cycles))
        assert lit(ours) == pytest.approx(lit(cycles), rel=LIGHT_RTOL)
    # The world seen (what the engine did before) fails: grey sky, alpha 1.
    assert plain["Combined"][..., :3][sky].min() > WORLD - OUTSIDE_TOL


def test_world_hidden_from_diffuse_rays_darkens_the_floor_as_in_cycles(renders):
    ratio = {}
    for engine in ("SPLAT_TRACER", "CYCLES"):
        on, off = renders("plain", engine), renders("world_diffuse_off", engine)
        floor = _floor(renders("plain"), renders("plain", "CYCLES"))
        ratio[engine] = off["Combined"][..., :3][floor].mean() / on["Combined"][..., :3][floor].mean()
        sky = erode(on[INDEX] == 0, 2)
        assert off["Combined"][..., :3][sky].mean() == pytest.approx(WORLD, rel=OUTSIDE_TOL)  # still seen
    print("floor brightness, world hidden from diffuse / seen:", ratio)
    assert ratio["SPLAT_TRACER"] == pytest.approx(ratio["CYCLES"], rel=LIGHT_RTOL)
    assert ratio["CYCLES"] < 1 - 5 * LIGHT_RTOL  # ignoring the setting (ratio 1) fails


# --------------------------------------------------------------------------------------
# Clouds as catchers and holdouts, the export's flags, the panels.

def flat_cloud(bpy, name, half, spacing, material):
    """A square splat cloud in the plane z = 0 (a scanned floor), normals up."""
    from splat_tracer.blender import cloud_object

    g = np.arange(-half, half + 1e-9, spacing)
    x, y = np.meshgrid(g, g)
    p = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    normals = np.tile([0.0, 0.0, 1.0], (len(p), 1))
    obj = cloud_object.create_cloud_object(name, p, normals, np.full(len(p), 0.75 * spacing), None)
    obj.data.materials.append(material)
    return obj


def test_a_scanned_floor_can_be_the_catcher_and_a_mesh_can_be_held_out(blender, empty_scene, tmp_path):
    """The per-instance flags reach the core for clouds as for meshes: a splat-cloud floor
    catches a mesh ball's shadow (alpha 0 outside it, the shadow's strength inside), and the
    ball, held out, cuts a hole."""
    from test_scene_export import uv_sphere

    bpy = blender
    scene = empty_scene
    grey = principled(bpy, "Grey")
    floor = flat_cloud(bpy, "ScanFloor", 2.0, 0.05, grey)
    ball = uv_sphere(bpy, "Ball", 0.5, (0, 0, 0.8), grey)
    floor.pass_index, ball.pass_index = FLOOR, SCAN
    lamp(bpy, "SUN", rotation=(math.radians(-35), 0, 0), energy=3.0)
    add_camera(bpy, scene, (0, 0, 8), (0, 0, 0), type="ORTHO", ortho_scale=4.0)
    scene.render.film_transparent = True
    scene.view_layers[0].use_pass_object_index = True
    floor.is_shadow_catcher = True
    out = render(bpy, scene, tmp_path / "cloud_catcher.exr")["ViewLayer"]
    alpha, index = out["Combined"][..., 3], out[INDEX]
    on_floor = erode(index == FLOOR, 2)
    shadow = on_floor & (alpha > 0.5)
    assert shadow.sum() > 200 and (on_floor & (alpha == 0.0)).sum() > 5000
    assert (alpha[erode(index == SCAN, 2)] == 1.0).all()
    ball.is_holdout = True
    held = render(bpy, scene, tmp_path / "mesh_holdout.exr")["ViewLayer"]
    assert (held["Combined"][..., 3][erode(index == SCAN, 2)] == 0.0).all()
    floor.is_shadow_catcher = ball.is_holdout = False
    plain = render(bpy, scene, tmp_path / "cloud_plain.exr")["ViewLayer"]
    assert (plain["Combined"][..., 3][on_floor] == 1.0).all()  # an ordinary floor again


def test_the_headlight_says_that_catchers_catch_nothing(blender, empty_scene, tmp_path):
    bpy = blender
    floor = plane(bpy, "Floor", 4.0, (0, 0, 0), principled(bpy, "Grey"))
    add_camera(bpy, empty_scene, (0, 0, 5), (0, 0, 0))
    empty_scene.render.resolution_x, empty_scene.render.resolution_y = 32, 24
    session = sys.modules[next(m for m in sys.modules if m.endswith("splat_tracer.blender.session"))]
    method = empty_scene.splat_tracer.core_method()
    floor.is_shadow_catcher = True
    lines = session.render_frame(bpy.context.evaluated_depsgraph_get(), method).report.lines
    assert any("shadow catchers are left out" in line for line in lines), lines  # no light: the headlight
    floor.is_shadow_catcher = False
    lines = session.render_frame(bpy.context.evaluated_depsgraph_get(), method).report.lines
    assert not any("shadow catcher" in line for line in lines), lines


def test_instances_take_catcher_and_holdout_from_their_instancer_and_indirect_only_hides_from_camera(
        blender, empty_scene):
    bpy = blender
    scene = empty_scene
    grey = principled(bpy, "Grey")
    shading = sys.modules[next(m for m in sys.modules if m.endswith("splat_tracer.blender.export.shading"))]
    floor = plane(bpy, "Floor", 2.0, (0, 0, 0), grey)
    layer = scene.view_layers[0]
    depsgraph = bpy.context.evaluated_depsgraph_get()
    flags = shading.object_visibility(floor.evaluated_get(depsgraph), layer)
    assert not flags["shadow_catcher"] and flags["camera"]
    floor.is_shadow_catcher = True
    helper = bpy.data.objects.new("Instancer", None)
    scene.collection.objects.link(helper)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    assert shading.object_visibility(floor.evaluated_get(depsgraph), layer)["shadow_catcher"]
    floor.is_shadow_catcher, helper.is_shadow_catcher = False, True
    assert shading.object_visibility(floor, layer, parent=helper)["shadow_catcher"]
    group = bpy.data.collections.new("Indirect")
    scene.collection.children.link(group)
    scene.collection.objects.unlink(floor)
    group.objects.link(floor)
    layer.layer_collection.children["Indirect"].indirect_only = True
    flags = shading.object_visibility(floor, layer)
    assert not flags["camera"] and flags["diffuse"] and flags["shadow"]
    floor.is_holdout = True  # Cycles: a held-out object stays seen by the camera, as a hole
    assert shading.object_visibility(floor, layer)["camera"]


def test_the_visibility_panels_show_the_catcher_holdout_and_world_ray_visibility(blender, empty_scene):
    bpy = blender
    panel = bpy.types.SPLAT_TRACER_PT_object_visibility
    assert panel.bl_parent_id == "OBJECT_PT_visibility"
    assert "SPLAT_TRACER" in bpy.types.OBJECT_PT_visibility.COMPAT_ENGINES
    floor = plane(bpy, "Floor", 2.0, (0, 0, 0), principled(bpy, "Grey"))
    context = SimpleNamespace(object=floor, engine="SPLAT_TRACER")
    assert bpy.types.OBJECT_PT_visibility.poll(context) and panel.poll(context)
    drawn = []
    panel.draw(SimpleNamespace(layout=_Layout(drawn)), context)
    assert {"is_shadow_catcher", "is_holdout", "visible_camera", "visible_shadow"} <= set(drawn)
    world = bpy.data.worlds.new("W")
    world_panel = bpy.types.SPLAT_TRACER_PT_world_ray_visibility
    context = SimpleNamespace(world=world, engine="SPLAT_TRACER")
    assert world_panel.poll(context)
    drawn = []
    world_panel.draw(SimpleNamespace(layout=_Layout(drawn)), context)
    assert drawn == ["camera", "diffuse", "glossy", "transmission"]
    drawn = []
    bpy.types.SPLAT_TRACER_PT_passes.draw(SimpleNamespace(layout=_Layout(drawn)),
                                          SimpleNamespace(view_layer=empty_scene.view_layers[0]))
    assert "use_pass_shadow_catcher" in drawn
