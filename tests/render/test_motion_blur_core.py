"""Motion blur in the core, without Blender: instances and the camera over the shutter
(motion steps interpolated as Cycles does: translation and stretch linearly, rotation by
slerp), each camera ray at its own time, the shutter curve's inverse CDF."""
from __future__ import annotations

import math

import numpy as np
import pytest

from splat_tracer.render.camera import Camera
from splat_tracer.render.method import Method
from splat_tracer.render.scene import Instance, Mesh, RenderScene, shutter_table
from splat_tracer.render.shading import Material, RenderSettings, World

W, H = 96, 8
HALF_WIDTH = 3.0  # the view spans x in [-3, 3]
# Many samples of a box filter shrunk to the pixel's centre: each pixel's value is the share
# of the shutter its centre sees the square, to the noise of 512 stratified times (a 1D
# Sobol set: well under 0.01).
SETTINGS = RenderSettings(samples=512, pixel_filter="BOX", filter_width=0.01, max_bounces=0)
TOLERANCE = 0.02  # absolute, on a 0..1 coverage


def _square() -> Mesh:
    """A unit square in the z = 0 plane, centred on the origin."""
    v = np.array([[-0.5, -0.5, 0], [0.5, -0.5, 0], [0.5, 0.5, 0], [-0.5, 0.5, 0]], np.float32)
    return Mesh(v, np.array([[0, 1, 2], [0, 2, 3]], np.int32))


def _moved(x=0.0, angle=0.0) -> np.ndarray:
    m = np.eye(4)
    c, s = math.cos(angle), math.sin(angle)
    m[:2, :2] = [[c, -s], [s, c]]
    m[0, 3] = x
    return m


def _camera(motion=None) -> Camera:
    cam = Camera.look_at((0, 0, 5), (0, 0, 0), up=(0, 1, 0), aspect=W / H, ortho_height=2 * HALF_WIDTH * H / W)
    return Camera(cam.local_from_camera, cam.frustum, cam.clip, True, motion=motion)


def _render(instances, camera=None, shutter_curve=None) -> np.ndarray:
    scene = RenderScene(instances, [], World(colour=(0, 0, 0)))
    out = scene.render(camera or _camera(), W, H, SETTINGS, Method(), shutter_curve=shutter_curve)
    return out.passes["Combined"][:, :, 0]


def _emitter(motion=None, matrix=None) -> Instance:
    return Instance(_square(), matrix if matrix is not None else np.eye(4),
                    (Material(base_colour=(0, 0, 0), emission=(1, 1, 1)),), motion=motion)


def _columns() -> np.ndarray:
    return (np.arange(W) + 0.5) / W * 2 * HALF_WIDTH - HALF_WIDTH


def _translation_profile(x0: float, x1: float) -> np.ndarray:
    """The share of a box shutter during which each column's centre sees the unit square
    moving from x0 to x1 at constant speed: the times t where |x - (x0 + (x1 - x0) t)| <= 0.5."""
    x = _columns()
    p, q = (x - 0.5 - x0) / (x1 - x0), (x + 0.5 - x0) / (x1 - x0)
    a, b = np.minimum(p, q), np.maximum(p, q)
    return np.clip(np.minimum(b, 1) - np.maximum(a, 0), 0, 1)


def test_translation_smear_is_the_box_shutter_profile():
    image = _render([_emitter(motion=(_moved(-1.0), _moved(1.0)))])
    expected = _translation_profile(-1.0, 1.0)
    row = image[H // 2]
    assert np.abs(row - expected).max() < TOLERANCE
    # The tolerance tells a wrong render: the square still at the frame's time, or a smear of
    # half the length.
    assert np.abs(_render([_emitter()])[H // 2] - expected).max() > 5 * TOLERANCE
    assert np.abs(_translation_profile(-0.5, 0.5) - expected).max() > 5 * TOLERANCE


def test_steps_between_are_followed():
    """Three steps, the middle one off the straight line: the square goes out and back, so
    that the far end of the path is seen, not the line between the first and last steps."""
    image = _render([_emitter(motion=(_moved(0.0), _moved(2.0), _moved(0.0)))])
    x = _columns()
    # Centre's path: 0 -> 2 -> 0, each half of the shutter: coverage twice the one-way's.
    one_way = _translation_profile(0.0, 2.0)
    assert np.abs(image[H // 2] - one_way).max() < TOLERANCE
    assert image[H // 2][x > 2.0].max() > 0.1  # the far end is reached


def test_rotation_is_slerp_not_a_blend_of_matrices():
    """A square turning a quarter turn, seen through a shutter open only about its middle:
    a 45 degree diamond of its full size (x extent sqrt 2). A blend of the two matrices
    would shrink it by cos 45 (x extent 1)."""
    curve = np.zeros(101)
    curve[50] = 1.0
    row = _render([_emitter(motion=(_moved(angle=0.0), _moved(angle=math.pi / 2)))], shutter_curve=curve)[H // 2]
    x = _columns()
    seen = x[row > 0.5]
    extent = seen.max() - seen.min()
    pixel = 2 * HALF_WIDTH / W
    assert abs(extent - math.sqrt(2)) < 2 * pixel
    assert abs(extent - 1.0) > 4 * pixel


def test_camera_motion_is_the_mirror_of_the_object_s():
    """The camera moving right by 2 over the shutter sees what a still camera sees of the
    square moving left by 2."""
    cam = _camera()
    steps = []
    for dx in (-1.0, 1.0):
        m = cam.local_from_camera.copy()
        m[0, 3] += dx
        steps.append(m)
    panned = _render([_emitter()], camera=_camera(motion=steps))[H // 2]
    assert np.abs(panned - _translation_profile(1.0, -1.0)).max() < TOLERANCE


def test_shutter_curve_weights_times():
    """A shutter opening linearly (openness t): times follow the density 2t, so the square's
    trail is dim where it started and bright where it ended."""
    table = shutter_table([0.0, 1.0])
    u = np.linspace(0, 1, len(table))
    np.testing.assert_allclose(table, np.sqrt(u), atol=2e-3)
    np.testing.assert_allclose(shutter_table([1.0, 1.0]), u, atol=1e-6)  # a box shutter: the identity
    row = _render([_emitter(motion=(_moved(-1.0), _moved(1.0)))], shutter_curve=[0.0, 1.0])[H // 2]
    x = _columns()
    # Column x sees the square for t in [a, b] (clipped to [0, 1]): the weight is b^2 - a^2.
    a, b = np.clip((x - 0.5 + 1.0) / 2.0, 0, 1), np.clip((x + 0.5 + 1.0) / 2.0, 0, 1)
    assert np.abs(row - (b * b - a * a)).max() < TOLERANCE
    assert np.abs((b * b - a * a) - _translation_profile(-1.0, 1.0)).max() > 5 * TOLERANCE
    with pytest.raises(ValueError):
        shutter_table([0.0, 0.0])


def test_still_steps_and_no_motion_render_the_same():
    """Steps that do not move give the still image (to rounding); the still scene draws no
    time at all (the core has no time dimension when nothing moves)."""
    still = _render([_emitter(matrix=_moved(0.3))])
    held = _render([_emitter(motion=(_moved(0.3), _moved(0.3)), matrix=_moved(0.3))])
    assert np.abs(still - held).max() < 1e-6


def test_motion_is_validated():
    with pytest.raises(ValueError):
        RenderScene([_emitter(motion=(_moved(0.0),))])  # one step
    singular = np.eye(4)
    singular[2, 2] = 0
    with pytest.raises(ValueError):
        RenderScene([_emitter(motion=(_moved(0.0), singular))])
    with pytest.raises(ValueError):
        _camera(motion=[np.eye(4)])


def _splat_square():
    """The unit square as a grid of overlapping splats facing the camera (+Z)."""
    from splat_tracer.render.splats import SplatCloud

    g = (np.arange(20) + 0.5) / 20 - 0.5
    x, y = np.meshgrid(g, g)
    centres = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    normals = np.tile([0.0, 0.0, 1.0], (len(centres), 1))
    return SplatCloud(centres, normals, np.full(len(centres), 0.05))


def test_a_moving_cloud_smears_as_a_moving_mesh_and_packets_agree():
    """Splat clouds move through the same instance level as meshes; a packet of camera rays
    at different times finds what each ray alone finds."""
    emitter = Material(base_colour=(0, 0, 0), emission=(1, 1, 1))
    inst = Instance(_splat_square(), np.eye(4), (emitter,), motion=(_moved(-1.0), _moved(1.0)))
    scene = RenderScene([inst], [], World(colour=(0, 0, 0)))
    packed = scene.render(_camera(), W, H, SETTINGS, Method()).passes["Combined"]
    alone = scene.render(_camera(), W, H, SETTINGS, Method(), packets=False).passes["Combined"]
    assert np.array_equal(packed, alone)
    # The splats' disc edges overhang the square by up to a radius: compared away from them.
    row, expected = packed[H // 2, :, 0], _translation_profile(-1.0, 1.0)
    assert np.abs(row - expected).max() < TOLERANCE + 0.05


def test_rolling_shutter_gives_each_row_its_instant():
    """Duration 0: row r (from the top) sees the square at time (r + 1) / height only, so a
    column's coverage over the rows is the square's position at each row's instant."""
    row_times = (np.arange(H) + 1) / H
    scene = RenderScene([_emitter(motion=(_moved(-1.0), _moved(1.0)))], [], World(colour=(0, 0, 0)))
    image = scene.render(_camera(), W, H, SETTINGS, Method(), rolling_shutter=0.0).passes["Combined"][:, :, 0]
    x = _columns()
    for r in (1, H // 2, H - 2):
        centre = -1.0 + 2.0 * row_times[r]
        expected = (np.abs(x - centre) <= 0.5).astype(np.float32)
        assert np.abs(image[r] - expected).mean() < 0.02, r
    with pytest.raises(ValueError):
        scene.render(_camera(), W, H, SETTINGS, Method(), rolling_shutter=1.5)
