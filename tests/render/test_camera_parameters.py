"""render.camera.Camera from its parameters in double (issue 22): the core builds each ray
from the frustum and the clip range, so any range Blender allows renders; a projection
matrix is read only for its image rectangle, and a float32 one that lost its range says
so instead of giving NaN rays."""
from __future__ import annotations

import numpy as np
import pytest

from splat_tracer.render.camera import Camera
from splat_tracer.render.splats import SplatCloud

from geometry import random_sphere

EYE, TARGET = (0.3, -4.0, 0.5), (0.0, 0.0, 0.0)


def _sphere(n=4000, radius=1.0):
    p, nrm = random_sphere(n, radius, seed=1)
    return SplatCloud(p.astype(np.float32), nrm.astype(np.float32), np.full(n, 0.06, np.float32))


def _perspective(near, far, fov_y=50.0, aspect=4 / 3):
    """An OpenGL perspective projection, as Blender builds it, in double."""
    f = 1.0 / np.tan(np.radians(fov_y) / 2)
    p = np.zeros((4, 4))
    p[0, 0], p[1, 1] = f / aspect, f
    p[2, 2], p[2, 3], p[3, 2] = (far + near) / (near - far), 2 * far * near / (near - far), -1.0
    return p


@pytest.mark.parametrize("ortho_height", [None, 2.5])
@pytest.mark.parametrize("clip", [(1e-3, 1e5), (1e-2, 1e6), (1e-6, 1e30)])
def test_huge_clip_ranges_render_what_an_ordinary_one_does(ortho_height, clip):
    cloud = _sphere()
    reference = cloud.render(Camera.look_at(EYE, TARGET, fov_y=50, near=0.1, far=100, ortho_height=ortho_height),
                             96, 72)
    huge = cloud.render(Camera.look_at(EYE, TARGET, fov_y=50, near=clip[0], far=clip[1], ortho_height=ortho_height),
                        96, 72)
    seen = reference.rgba[..., 3] > 0
    assert seen.mean() > 0.15 and np.array_equal(seen, huge.rgba[..., 3] > 0)
    np.testing.assert_allclose(huge.depth[seen], reference.depth[seen], rtol=1e-5)


def test_a_float32_matrix_that_lost_its_range_is_refused_or_given_its_range():
    """calc_matrix_camera's float32 at 0.001-1e5: the far plane unprojects to w = 0 (the
    issue's NaN rays). Read from the matrix alone, the range is refused by name; given the
    clip range, the camera is the double one."""
    world_from_camera = Camera.look_at(EYE, TARGET).local_from_camera
    lost = _perspective(1e-3, 1e5).astype(np.float32)
    assert lost[2, 2] == -1.0  # (far + near) / (near - far) rounds to -1: the far plane is at w = 0
    with pytest.raises(ValueError, match="lost its clipping range"):
        Camera.from_view_projection(lost, world_from_camera)
    camera = Camera.from_view_projection(lost, world_from_camera, clip=(1e-3, 1e5))
    assert camera.clip == (1e-3, 1e5) and np.array_equal(camera.local_from_camera, world_from_camera)
    o, d = camera.rays(32, 24)
    assert np.isfinite(o).all() and np.isfinite(d).all()
    # The image rectangle is the double matrix's to float32 precision.
    double = Camera.from_view_projection(_perspective(1e-3, 1e5), world_from_camera)
    np.testing.assert_allclose(camera.frustum, double.frustum, rtol=1e-7)
    np.testing.assert_allclose(double.clip, (1e-3, 1e5), rtol=1e-6)


@pytest.mark.parametrize("ortho_height", [None, 2.5])
def test_a_matrix_gives_the_rays_its_parameters_give(ortho_height):
    """from_view_projection reads back look_at's parameters (perspective and orthographic,
    with an off-centre image as a lens shift gives)."""
    cam = Camera.look_at(EYE, TARGET, fov_y=50, near=0.1, far=100, ortho_height=ortho_height)
    shifted = Camera.from_frustum(cam.local_from_camera, (-0.3, 0.9, -0.2, 0.6), cam.clip, cam.orthographic)
    for c in (cam, shifted):
        left, right, bottom, top = c.frustum
        near, far = c.clip
        p = np.zeros((4, 4))
        if c.orthographic:
            p[0, 0], p[0, 3] = 2 / (right - left), -(right + left) / (right - left)
            p[1, 1], p[1, 3] = 2 / (top - bottom), -(top + bottom) / (top - bottom)
            p[2, 2], p[2, 3], p[3, 3] = -2 / (far - near), -(far + near) / (far - near), 1.0
        else:
            p[0, 0], p[0, 2] = 2 / (right - left), (right + left) / (right - left)
            p[1, 1], p[1, 2] = 2 / (top - bottom), (top + bottom) / (top - bottom)
            p[2, 2], p[2, 3], p[3, 2] = (far + near) / (near - far), 2 * far * near / (near - far), -1.0
        back = Camera.from_view_projection(p, c.local_from_camera)
        assert back.orthographic == c.orthographic
        np.testing.assert_allclose(back.frustum, c.frustum, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(back.clip, c.clip, rtol=1e-9)
        for a, b in zip(back.rays(16, 12), c.rays(16, 12)):
            np.testing.assert_allclose(a, b, atol=1e-6)


@pytest.mark.parametrize("kwargs, error", [
    (dict(frustum=(1, -1, -1, 1)), "left < right"),
    (dict(frustum=(-1, 1, -1, float("nan"))), "finite"),
    (dict(clip=(5.0, 2.0)), "clip start < clip end"),
    (dict(clip=(-1.0, 2.0)), "clip start > 0"),
    (dict(clip=(0.1, float("inf"))), "finite"),
    (dict(local_from_camera=np.diag([1.0, 1.0, 0.0, 1.0])), "no view axis"),
])
def test_bad_parameters_are_refused_by_name(kwargs, error):
    args = dict(local_from_camera=np.eye(4), frustum=(-1, 1, -1, 1), clip=(0.1, 10.0))
    args.update(kwargs)
    with pytest.raises(ValueError, match=error):
        Camera(**args)


def test_the_core_checks_the_camera_it_is_given():
    """The bindings refuse what the Camera class refuses, for callers of _core directly."""
    cloud = _sphere(100)
    out = np.empty((4, 4, 4), np.float32)
    good = Camera.look_at(EYE, TARGET)
    m, frustum, ortho = good.native()
    plane = lambda *values: np.array([*values, 0, 0, 0, 0, 0, 0], np.float64)  # a planar camera's 12 numbers
    for bad_m, bad_f, bad_o, error in ((m, plane(1.0, -1, -1, 1, 0.1, 10), False, "left < right"),
                                      (m, plane(-1.0, 1, -1, 1, 0.0, 10), False, "clip start"),
                                      (m, plane(-1.0, 1, -1, 1, 10, 0.1), True, "clip start"),
                                      (m, frustum[:6].copy(), False, "expected 12"),
                                      (m, np.r_[frustum[:6], 9, 0, 0, 0, 0, 0], False, "projection"),
                                      (m, np.r_[frustum[:6], 1.5, 0, 0, 0, 0, 0], False, "projection"),
                                      (m, np.r_[frustum[:6], 2, 0, 0, 0, 0, 0], False, "projection"),
                                      (m, np.r_[frustum[:6], 1, 0, 0, 0, 0, 0], True, "projection"),
                                      (np.diag([1.0, 1, 0, 1]), frustum, False, "view axis"),
                                      (np.full((4, 4), np.nan), frustum, False, "finite")):
        with pytest.raises(ValueError, match=error):
            cloud._scene.render(bad_m, bad_f, bad_o, 4, 4, (0, 0, 4, 4), (0, 0, 0, 0), out)
    # An orthographic camera may start behind its position (Blender's orthographic views do).
    cloud._scene.render(m, plane(-1.0, 1, -1, 1, -5.0, 5.0), True, 4, 4, (0, 0, 4, 4), (0, 0, 0, 0), out)
