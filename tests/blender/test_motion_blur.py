"""Motion blur (issue 25, item 2) through Blender, side by side with Cycles.

Both engines render the same scene: an emitting unit square (a mesh, so that Cycles sees
what we see) in a black world, seen square-on by an orthographic camera, the square (or the
camera) animated at constant speed along x with linear keys, rendered with Render > Motion
Blur set as an artist sets it for Cycles. The smear is measured the same way in both renders
along the rows' mean profile: its 10-90 % ramp width at the square's left edge (the blur
length: 0.8 x the travel over the shutter, plus the pixel filter), and the profile's centroid
(where the shutter position puts the square).

Tolerances: RAMP_RTOL = 15 % between the engines' ramp widths (a shutter twice as long
doubles the ramp, far outside); CENTROID_ATOL = 1 pixel between the engines' centroids
(Start and End move the centroid by 8 pixels here: a wrong shutter position is far outside).
Measured (bpy 5.0.1, 32 samples): ramps 6.37 px here / 6.54 Cycles at a 0.5-frame shutter,
12.85 / 12.65 at 1 frame, 1.59 / 1.59 with motion blur off; centroids Start 71.98 / 71.99,
Center 63.97 / 63.96, End 55.99 / 55.97; camera pan ramp 12.78 / 12.85, centroid 64.02 /
64.02. Rolling shutter: ROLL_ATOL = 0.08 px a row on the rows' centroid slope; measured 0.666 /
0.667 at Duration 0, 0.331 / 0.333 at 0.5.
"""
from __future__ import annotations

import numpy as np
import pytest

from blender_helpers import add_camera, extension_module
from test_scene_export import black_world, mesh_object, principled, render

W, H = 128, 24
SAMPLES = 32
RAMP_RTOL = 0.15
CENTROID_ATOL = 1.0
ROLL_ATOL = 0.08  # px a row, on slopes of 0.33 and 0.67: a wrong duration is outside
ORTHO = 6.0            # the view's width in scene units: W / ORTHO pixels a unit
SPEED = 0.75           # scene units a frame
FRAME = 5


def _square(bpy):
    def build(bm):
        vs = [bm.verts.new(v) for v in ((-0.5, -0.5, 0), (0.5, -0.5, 0), (0.5, 0.5, 0), (-0.5, 0.5, 0))]
        bm.faces.new(vs)
    glow = principled(bpy, "Glow", base=(0, 0, 0), specular=0.0, emission=(1, 1, 1, 1.0))
    return mesh_object(bpy, "Square", build, materials=[glow])


def _animate_x(obj, x_at_frame: float, speed: float):
    """Linear keys so that obj's x is x_at_frame at FRAME and moves `speed` a frame."""
    for frame in (FRAME - 2, FRAME + 2):
        obj.location.x = x_at_frame + speed * (frame - FRAME)
        obj.keyframe_insert("location", index=0, frame=frame)
    action = obj.animation_data.action
    for fcurve in _fcurves(action):
        for key in fcurve.keyframe_points:
            key.interpolation = "LINEAR"


def _fcurves(action):
    # Blender 5 keeps an action's curves in its layers' strips' channel bags.
    if hasattr(action, "fcurves"):
        return list(action.fcurves)
    return [fc for layer in action.layers for strip in layer.strips for bag in strip.channelbags
            for fc in bag.fcurves]


def _setup(bpy, scene, moving="square", shutter=0.5, position="CENTER"):
    square = _square(bpy)
    black_world(bpy, scene)
    cam = add_camera(bpy, scene, (0, 0, 5), (0, 0, 0), type="ORTHO", ortho_scale=ORTHO, clip_start=0.1,
                     clip_end=100.0)
    _animate_x(square if moving == "square" else cam, 0.0, SPEED)
    scene.frame_set(FRAME)
    r = scene.render
    r.use_motion_blur, r.motion_blur_shutter = True, shutter
    r.motion_blur_position = position
    scene.cycles.samples, scene.cycles.device = SAMPLES, "CPU"
    scene.cycles.use_denoising = False
    scene.cycles.use_adaptive_sampling = False
    scene.cycles.max_bounces = 0
    return square, cam


def _render(bpy, scene, tmp_path, engine: str, name: str) -> np.ndarray:
    scene.render.engine = engine
    return render(bpy, scene, tmp_path / f"{name}_{engine}.exr", (W, H))["ViewLayer"]["Combined"][..., 0]


def smear(image: np.ndarray) -> dict:
    """The mean row's left-edge 10-90 % ramp width and its centroid, in pixels."""
    p = image.mean(axis=0)
    p = p / p.max()
    x = np.arange(W) + 0.5

    def crossing(level):
        k = int(np.argmax(p >= level))  # the first column at or above the level
        return x[k - 1] + (level - p[k - 1]) / (p[k] - p[k - 1]) if k > 0 else x[0]
    return {"ramp": float(crossing(0.9) - crossing(0.1)), "centroid": float((p * x).sum() / p.sum())}


def _both(bpy, scene, tmp_path, name):
    return {e: smear(_render(bpy, scene, tmp_path, e, name)) for e in ("SPLAT_TRACER", "CYCLES")}


def _travel_px(shutter: float) -> float:
    return SPEED * shutter * W / ORTHO


def test_blur_length_of_a_moving_square_matches_cycles(blender, empty_scene, tmp_path):
    """Shutter 0.5 and 1.0 frame: the square travels 8 and 16 pixels; the ramp is 0.8 x
    the travel (plus the filter's) in both engines; off, the edge is sharp."""
    _setup(blender, empty_scene, shutter=0.5)
    found = {0.5: _both(blender, empty_scene, tmp_path, "half")}
    empty_scene.render.motion_blur_shutter = 1.0
    found[1.0] = _both(blender, empty_scene, tmp_path, "one")
    empty_scene.render.use_motion_blur = False
    found["off"] = _both(blender, empty_scene, tmp_path, "off")
    print("smear (px) by shutter:", found)
    for shutter in (0.5, 1.0):
        ours, cycles = found[shutter]["SPLAT_TRACER"], found[shutter]["CYCLES"]
        assert ours["ramp"] == pytest.approx(cycles["ramp"], rel=RAMP_RTOL), shutter
        assert ours["ramp"] == pytest.approx(0.8 * _travel_px(shutter), abs=2.0), shutter
    # The tolerance tells a wrong shutter length: half of it, or twice, is outside.
    assert abs(found[1.0]["CYCLES"]["ramp"] / found[0.5]["CYCLES"]["ramp"] - 1) > 2 * RAMP_RTOL
    # Motion blur off: sharp (the pixel filter's width alone) in both.
    assert found["off"]["SPLAT_TRACER"]["ramp"] < 2.0 and found["off"]["CYCLES"]["ramp"] < 2.0
    assert found[0.5]["SPLAT_TRACER"]["ramp"] > 2 * found["off"]["SPLAT_TRACER"]["ramp"]


def test_shutter_position_moves_the_smear_as_in_cycles(blender, empty_scene, tmp_path):
    """Start: the shutter opens on the frame (the smear lies ahead of the frame's position);
    End: it closes there (behind); Center: around it."""
    _setup(blender, empty_scene, shutter=1.0)
    centroids = {}
    for position in ("START", "CENTER", "END"):
        empty_scene.render.motion_blur_position = position
        found = _both(blender, empty_scene, tmp_path, position)
        centroids[position] = {e: v["centroid"] for e, v in found.items()}
    print("centroids (px) by shutter position:", centroids)
    half = _travel_px(1.0) / 2
    for position, shift in (("START", half), ("CENTER", 0.0), ("END", -half)):
        c = centroids[position]
        assert c["SPLAT_TRACER"] == pytest.approx(c["CYCLES"], abs=CENTROID_ATOL), position
        assert c["SPLAT_TRACER"] - W / 2 == pytest.approx(shift, abs=CENTROID_ATOL), position
    # A wrong position is outside the tolerance.
    assert abs(centroids["START"]["CYCLES"] - centroids["CENTER"]["CYCLES"]) > 4 * CENTROID_ATOL


def test_camera_pan_blurs_as_in_cycles(blender, empty_scene, tmp_path):
    """The camera moving (the square still): the same smear, mirrored, in both engines."""
    _setup(blender, empty_scene, moving="camera", shutter=1.0)
    found = _both(blender, empty_scene, tmp_path, "pan")
    print("camera pan smear (px):", found)
    ours, cycles = found["SPLAT_TRACER"], found["CYCLES"]
    assert ours["ramp"] == pytest.approx(cycles["ramp"], rel=RAMP_RTOL)
    assert ours["ramp"] == pytest.approx(0.8 * _travel_px(1.0), abs=2.0)
    assert ours["centroid"] == pytest.approx(cycles["centroid"], abs=CENTROID_ATOL)


def _row_slope(image: np.ndarray) -> float:
    """The slope (pixels a row, rows downwards) of the rows' centroids across the square's
    inner rows."""
    rows = np.arange(4, H - 4)
    x = np.arange(W) + 0.5
    centroids = [(image[r] * x).sum() / image[r].sum() for r in rows]
    return float(np.polyfit(rows, centroids, 1)[0])


def test_rolling_shutter_skews_as_in_cycles(blender, empty_scene, tmp_path):
    """Cycles' Rolling Shutter (Top): rows exposed from the top down, so the moving square
    leans; Duration 0 (each row an instant) and 0.5. Its centroids' slope per row matches
    Cycles' within ROLL_ATOL; a global shutter does not lean."""
    _setup(blender, empty_scene, shutter=1.0)
    empty_scene.cycles.rolling_shutter_type = "TOP"
    slopes = {}
    for duration in (0.0, 0.5):
        empty_scene.cycles.rolling_shutter_duration = duration
        slopes[duration] = {e: _row_slope(_render(blender, empty_scene, tmp_path, e, f"roll{duration}"))
                            for e in ("SPLAT_TRACER", "CYCLES")}
    print("rolling shutter slopes (px a row):", slopes, "expected at duration 0:", _travel_px(1.0) / H)
    for duration, slope in slopes.items():
        assert slope["SPLAT_TRACER"] == pytest.approx(slope["CYCLES"], abs=ROLL_ATOL), duration
    assert slopes[0.0]["CYCLES"] == pytest.approx(_travel_px(1.0) / H, abs=ROLL_ATOL)
    # Half the duration halves the lean: the wrong duration is outside the tolerance.
    assert abs(slopes[0.0]["CYCLES"] - slopes[0.5]["CYCLES"]) > 2 * ROLL_ATOL
    empty_scene.cycles.rolling_shutter_type = "NONE"
    assert abs(_row_slope(_render(blender, empty_scene, tmp_path, "SPLAT_TRACER", "global"))) < ROLL_ATOL


def test_object_switch_and_still_scenes(blender, empty_scene, tmp_path):
    """Object > Motion Blur off keeps that object sharp (as Cycles), so does the view layer's
    Motion Blur off; with motion blur on and nothing moving, the image is bit-identical to
    motion blur off (no time dimension)."""
    square, _ = _setup(blender, empty_scene, shutter=1.0)
    square.cycles.use_motion_blur = False
    found = _both(blender, empty_scene, tmp_path, "object_off")
    print("object's motion blur off:", found)
    assert found["SPLAT_TRACER"]["ramp"] < 2.0 and found["CYCLES"]["ramp"] < 2.0
    # The view layer's switch off (the scene's on) renders the layer sharp, as in Cycles.
    square.cycles.use_motion_blur = True
    empty_scene.view_layers[0].use_motion_blur = False
    found = _both(blender, empty_scene, tmp_path, "layer_off")
    print("view layer's motion blur off:", found)
    assert found["SPLAT_TRACER"]["ramp"] < 2.0 and found["CYCLES"]["ramp"] < 2.0
    empty_scene.view_layers[0].use_motion_blur = True
    square.animation_data_clear()
    square.location.x = 0.3
    square.cycles.use_motion_blur = True
    on = _render(blender, empty_scene, tmp_path, "SPLAT_TRACER", "still_on")
    empty_scene.render.use_motion_blur = False
    off = _render(blender, empty_scene, tmp_path, "SPLAT_TRACER", "still_off")
    assert np.array_equal(on, off)


def test_report_says_what_is_approximated(blender, empty_scene):
    """Deformation blur is said once; the moving square is blurred; the rolling shutter is
    rendered, so not said."""
    square, _ = _setup(blender, empty_scene, shutter=0.5)
    empty_scene.cycles.rolling_shutter_type = "TOP"
    square.modifiers.new("Wave", "WAVE")
    empty_scene.render.resolution_x, empty_scene.render.resolution_y = 32, 8
    session = extension_module("blender.session")
    blender.ops.render.render()
    stats = session.HISTORY[-1]
    lines = " | ".join(stats["report"])
    print(lines)
    assert stats["moving"] == 1
    assert "Rolling Shutter" not in lines
    assert "Deformation motion blur is not rendered ('Square')" in lines
    assert "Motion Blur is not rendered" not in lines


def test_the_motion_blur_panels_show_for_the_engine(blender, empty_scene):
    """Render > Motion Blur (with its Shutter Curve) and Object > Motion Blur show for the
    engine, as Cycles' do for Cycles (whose own hide for other engines)."""
    from types import SimpleNamespace

    square = _square(blender)
    for name in ("SPLAT_TRACER_PT_motion_blur", "SPLAT_TRACER_PT_motion_blur_curve"):
        panel = getattr(blender.types, name)
        assert panel.poll(SimpleNamespace(engine="SPLAT_TRACER")) and not panel.poll(SimpleNamespace(engine="CYCLES"))
    panel = blender.types.SPLAT_TRACER_PT_object_motion_blur
    assert panel.poll(SimpleNamespace(engine="SPLAT_TRACER", object=square))
    assert not panel.poll(SimpleNamespace(engine="CYCLES", object=square))


def test_the_shutter_curve_is_read(blender, empty_scene):
    """Blender's default Shutter Curve is flat (a box shutter: nothing passed to the core);
    a ramp is read as the shutter's openness over time."""
    motion = extension_module("blender.export.motion")
    assert motion.shutter_curve(empty_scene) is None
    curve = empty_scene.render.motion_blur_shutter_curve
    points = curve.curves[0].points
    for k, point in enumerate(points):  # y = x through the default curve's points
        x = k / (len(points) - 1)
        point.location = (x, x)
    curve.update()
    values = motion.shutter_curve(empty_scene)
    assert values is not None and values[0] == pytest.approx(0.0, abs=1e-3) and values[-1] == pytest.approx(1.0)
    assert values[len(values) // 2] == pytest.approx(0.5, abs=0.05)


@pytest.mark.parametrize("mode", ["PARALLEL", "TOE"])
def test_each_stereo_eye_blurs_with_its_own_camera_as_in_cycles(blender, empty_scene, tmp_path, mode):
    """A stereo render of a camera pan: each eye's camera moves over the shutter with the eye
    kept beside the camera (Blender's eye matrix at the frame's time, moved as the camera
    moves), as Cycles moves each eye. Per eye, the smear's ramp and centroid must be Cycles'
    (RAMP_RTOL, CENTROID_ATOL); the eyes' centroids differ by the disparity (10.7 px for
    Parallel eyes 0.3 apart, 5 units from the square). Both eyes blurred with the scene
    camera's own motion would put both smears at the camera's place, half the disparity
    (5.3 px for Parallel) from each eye's: outside CENTROID_ATOL."""
    from test_stereo import _render as render_views

    bpy, scene = blender, empty_scene
    _square(bpy)
    black_world(bpy, scene)
    cam = add_camera(bpy, scene, (0, 0, 5), (0, 0, 0), lens=50.0, sensor_width=36.0, sensor_fit="HORIZONTAL")
    _animate_x(cam, 0.0, SPEED)
    scene.frame_set(FRAME)
    stereo = cam.data.stereo
    # Both eyes beside the camera (pivot Center), converging beyond the square (Toe-in's
    # disparity then about half Parallel's, not 0).
    stereo.convergence_mode, stereo.interocular_distance, stereo.convergence_distance = mode, 0.3, 10.0
    stereo.pivot = "CENTER"
    r = scene.render
    r.use_multiview, r.views_format = True, "STEREO_3D"
    r.use_motion_blur, r.motion_blur_shutter = True, 0.5
    c = scene.cycles
    c.samples, c.device, c.use_denoising, c.use_adaptive_sampling, c.max_bounces = SAMPLES, "CPU", False, False, 0
    got = {}
    for engine in ("SPLAT_TRACER", "CYCLES"):
        r.engine = engine
        views = render_views(bpy, scene, tmp_path / f"stereo_{mode}_{engine}.exr")
        got[engine] = {view: smear(views[view]["Combined"][..., 0]) for view in ("left", "right")}
    print(mode, got)
    for view in ("left", "right"):
        ours, cycles = got["SPLAT_TRACER"][view], got["CYCLES"][view]
        assert ours["ramp"] == pytest.approx(cycles["ramp"], rel=RAMP_RTOL)
        assert abs(ours["centroid"] - cycles["centroid"]) < CENTROID_ATOL
    ours = got["SPLAT_TRACER"]
    # Blurred (a 0.375-unit pan, 13 px here; sharp: a 1.6 px ramp), and the eyes apart.
    assert ours["left"]["ramp"] > 5.0 and ours["right"]["ramp"] > 5.0
    assert abs(ours["right"]["centroid"] - ours["left"]["centroid"]) > 2 * CENTROID_ATOL
