"""Depth of field (issue 25): the core's thin lens against values computed here another way.

An emitting half-plane (x > 0, or y > 0, in camera space) at depth z, seen by a camera
focused at f with a lens of radius R: pixel centre u (on the unit plane) sees the plane's
point u z + L (1 - z / f) through the lens point L, so the pixel is lit with the
probability that the aperture's coordinate L_x < (u - u_edge) / s, s = 1/f - 1/z (an
orthographic camera: L_x < (u - x_edge) / (z/f - 1)). Averaged over the rows, the edge's
profile is then the distribution function of the aperture's projection on the edge's
normal -- computed here from a fine grid of the points inside the disc or the polygon (an
inside test against its sides, not the sampling the core does) -- so the profile checks
that the lens points are uniform over the right shape, its size, orientation (blades,
rotation), anamorphic ratio and mean. The plane in focus maps each pixel to one point:
its edge is the pinhole's step, whatever the lens.

Tolerances: 64 rows x 64 samples = 4096 lens points per column, so the profile's noise is
about 0.5 / sqrt(4096) = 0.008 at most in a column; PROFILE_ATOL = 0.015 on the mean
absolute error over the blurred columns (measured 0.003 to 0.005). The wrong alternatives
(the radius 1.2x, the triangle mirrored, the ratio on the other axis) measured 0.031 to
0.20 from the render.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from splat_tracer.render.camera import Camera, Lens
from splat_tracer.render.method import Method
from splat_tracer.render.scene import Instance, Mesh, RenderScene
from splat_tracer.render.shading import Material, RenderSettings, World

W = 64
HALF = 0.1  # the image's half width on the unit plane (or the orthographic view plane)
PIXEL = 2 * HALF / W
SAMPLES = 64
PROFILE_ATOL = 0.015
# The pixel filter shrunk to (almost) nothing: every sample at the pixel's centre, so the
# profile is the lens's alone (0.01 px is the smallest width RenderSettings takes).
SETTINGS = RenderSettings(samples=SAMPLES, pixel_filter="BOX", filter_width=0.01, max_bounces=0)


def _half_plane(z: float, axis: int) -> RenderScene:
    """An emitter covering camera-space coordinate `axis` > 0 at depth z (far beyond the view)."""
    big = 100.0 * z
    lo = [-big, -big]
    lo[axis] = 0.0
    v = np.array([[lo[0], lo[1], -z], [big, lo[1], -z], [big, big, -z], [lo[0], big, -z]], np.float32)
    mesh = Mesh(v, np.array([[0, 1, 2], [0, 2, 3]], np.int32))
    return RenderScene([Instance(mesh, materials=(Material(base_colour=(0, 0, 0), emission=(1, 1, 1)),))], [],
                       World(colour=(0, 0, 0)))


def _profile(z: float, axis: int, lens, orthographic=False) -> np.ndarray:
    """The edge's profile across `axis` (towards +x: columns left to right; +y: rows bottom
    to top), averaged along it: the fraction of samples that saw the emitter."""
    cam = Camera(np.eye(4), (-HALF, HALF, -HALF, HALF), (0.01, 1000.0), orthographic, lens)
    img = _half_plane(z, axis).render(cam, W, W, SETTINGS, Method()).passes["Combined"][..., 0]
    return img.mean(axis=0) if axis == 0 else img.mean(axis=1)[::-1]


def _inside(points: np.ndarray, lens: Lens) -> np.ndarray:
    """Which (x, y) points lie in the aperture (radius 1, before the ratio): the disc, or
    the polygon whose corners are at angles rotation + (2k + 1) pi / blades."""
    if lens.blades == 0:
        return (points ** 2).sum(axis=1) <= 1.0
    n = lens.blades
    corners = lens.rotation + (2 * np.arange(n) + 1) * np.pi / n
    inside = np.ones(len(points), bool)
    for k in range(n):  # the side between corners k and k+1: its normal at the mid angle, distance cos(pi/n)
        mid = 0.5 * (corners[k] + corners[(k + 1) % n] + (2 * np.pi if k == n - 1 else 0))
        inside &= points @ np.array([math.cos(mid), math.sin(mid)]) <= math.cos(math.pi / n)
    return inside


def _aperture_points(lens: Lens, step=2e-3) -> np.ndarray:
    g = np.arange(-1 + step / 2, 1, step)
    xy = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    xy = xy[_inside(xy, lens)]
    return np.column_stack([xy[:, 0] / lens.ratio, xy[:, 1]]) * lens.radius


def _expected(lens: Lens, axis: int, scale: float, sign: float = 1.0) -> np.ndarray:
    """The profile at the pixel centres: P(L_axis < d PIXEL / scale), d = the centre's
    signed distance from the edge's pinhole image, in pixels."""
    coord = np.sort(sign * _aperture_points(lens)[:, axis])
    d = np.arange(W) - W / 2 + 0.5
    return np.searchsorted(coord, d * PIXEL / scale) / len(coord)


def _error(measured, expected) -> float:
    blurred = (expected > 0.001) & (expected < 0.999)
    return float(np.abs(measured - expected)[blurred].mean())


Z, F = 4.0, 2.0
S = 1 / F - 1 / Z  # the blur per unit of aperture, on the unit plane
# Apertures of radius 0.1 at s = 0.25: up to 0.025 on the unit plane, 8 pixels.
LENSES = [Lens(0.1, F), Lens(0.1, F, blades=3), Lens(0.1, F, blades=5, rotation=0.4),
          Lens(0.1, F, blades=6, rotation=-0.2, ratio=1.6), Lens(0.1, F, ratio=0.5)]


@pytest.mark.parametrize("lens", LENSES, ids=lambda l: f"blades{l.blades}_rot{l.rotation}_ratio{l.ratio}")
@pytest.mark.parametrize("axis", [0, 1], ids=["x", "y"])
def test_an_out_of_focus_edge_is_the_apertures_projection(lens, axis):
    measured = _profile(Z, axis, lens)
    expected = _expected(lens, axis, S)
    assert _error(measured, expected) < PROFILE_ATOL
    # The mean of the lens points is the aperture's centroid (0): the edge's 50 % point
    # stays where the pinhole sees it, for the symmetric shapes.
    if lens.blades % 2 == 0:
        d = np.arange(W) - W / 2 + 0.5
        assert abs(np.interp(0.5, measured, d)) < 0.25  # pixels
    # Wrong alternatives of the same aperture are caught.
    wrong = {"radius 1.2x": _expected(Lens(0.12, F, lens.blades, lens.rotation, lens.ratio), axis, S)}
    if lens.ratio != 1:
        wrong["ratio on the other axis"] = _expected(Lens(0.1, F, lens.blades, lens.rotation, 1 / lens.ratio), axis, S)
    if lens.blades % 2 == 1:
        wrong["mirrored"] = _expected(lens, axis, S, sign=-1.0)
    for name, alternative in wrong.items():
        if np.abs(alternative - expected).max() > 0.05:  # (a triangle's y profile is its mirror's)
            assert _error(measured, alternative) > 2 * PROFILE_ATOL, name


def test_the_triangles_corner_points_left_at_rotation_0():
    """Blades 3, rotation 0: corners at 60, 180 and 300 degrees (Cycles' polygon): the x
    profile spans -R s .. R s / 2, not the mirrored -R s / 2 .. R s."""
    measured = _profile(Z, 0, Lens(0.1, F, blades=3))
    d = np.arange(W) - W / 2 + 0.5
    reach = 0.1 * S / PIXEL  # 8 pixels
    first_lit, last_dark = d[np.argmax(measured > 0)], d[len(d) - 1 - np.argmax(measured[::-1] < 1)]
    assert first_lit == pytest.approx(-reach, abs=1.0) and last_dark == pytest.approx(reach / 2, abs=1.0)


@pytest.mark.parametrize("orthographic", [False, True])
def test_the_plane_in_focus_is_sharp_whatever_the_aperture(orthographic):
    for axis in (0, 1):
        pinhole = _profile(F, axis, None, orthographic)
        assert set(np.unique(pinhole)) == {0.0, 1.0}
        for lens in (Lens(0.3, F), Lens(0.3, F, blades=5, rotation=1.0, ratio=2.0)):
            np.testing.assert_array_equal(_profile(F, axis, lens, orthographic), pinhole)


def test_an_orthographic_cameras_blur_grows_from_its_focus_plane():
    """Cycles' orthographic lens: rays leave the lens around the pixel's point of the view
    plane and meet on the plane `focus_distance` in front of the camera, so the blur at
    depth z is the aperture times (z / f - 1), in view-plane units."""
    lens = Lens(0.02, 2.0)
    scale = 4.0 / 2.0 - 1.0
    measured = _profile(4.0, 0, lens, orthographic=True)
    assert _error(measured, _expected(lens, 0, scale)) < PROFILE_ATOL
    assert _error(measured, _expected(lens, 0, S)) > PROFILE_ATOL  # the perspective rule is another blur


def test_more_samples_converge_the_blur():
    """The lens point is drawn per pixel and per sample: the noise of one pixel row falls
    as 1 / sqrt(samples)."""
    lens = Lens(0.1, F)
    expected = _expected(lens, 0, S)
    cam = Camera(np.eye(4), (-HALF, HALF, -HALF, HALF), (0.01, 1000.0), False, lens)
    stage = _half_plane(Z, 0)
    errors = []
    for samples in (4, 64):
        settings = RenderSettings(samples=samples, pixel_filter="BOX", filter_width=0.01, max_bounces=0)
        img = stage.render(cam, W, W, settings, Method()).passes["Combined"][..., 0]
        blurred = (expected > 0.05) & (expected < 0.95)
        errors.append(float(np.sqrt(((img - expected) ** 2)[:, blurred].mean())))
    assert errors[1] < 0.4 * errors[0]  # sqrt(16) = 4x ideally; measured about 4x


def test_from_fstop_is_cycles_conversion():
    """blender/camera.cpp: aperture size = lens (mm) * 1e-3 / (2 f-stop); orthographic
    1 / (2 f-stop); both clamped (f-stop and focus distance >= 1e-5)."""
    assert Lens.from_fstop(2.8, 50.0, 3.0).radius == pytest.approx(0.05 / 5.6)
    assert Lens.from_fstop(1.4, 85.0, 3.0).radius == pytest.approx(0.085 / 2.8)
    assert Lens.from_fstop(2.0, 50.0, 3.0, orthographic=True).radius == pytest.approx(0.25)
    assert Lens.from_fstop(0.0, 50.0, 0.0).radius == pytest.approx(0.05 / 2e-5)
    assert Lens.from_fstop(0.0, 50.0, 0.0).focus_distance == 1e-5
    assert Lens(0.1, 1.0, blades=2).blades == 0  # fewer than 3 blades: a disc, as Cycles


@pytest.mark.parametrize("bad", [dict(radius=-1), dict(focus_distance=0), dict(ratio=0), dict(radius=math.nan),
                                 dict(blades=-3), dict(rotation=math.inf)])
def test_bad_lenses_are_refused(bad):
    args = dict(radius=0.1, focus_distance=1.0, blades=0, rotation=0.0, ratio=1.0)
    with pytest.raises(ValueError):
        Lens(**{**args, **bad})


def test_the_core_refuses_a_bad_lens_tuple_and_the_pinhole_preview_refuses_a_lens():
    stage = _half_plane(Z, 0)
    cam = Camera(np.eye(4), (-HALF, HALF, -HALF, HALF), (0.01, 1000.0))
    out = np.zeros((4, 4, 4), np.float32)
    for lens in ((0.1, 0.0, 0, 0.0, 1.0), (0.1, 1.0, 2, 0.0, 1.0), (0.1, 1.0, 0, 0.0), "lens"):
        with pytest.raises((ValueError, TypeError)):
            stage._scene.render(*cam.native(), 4, 4, (0, 0, 4, 4), SETTINGS.pack(), Method(), (0, 0, 0), False,
                                out, lens=lens)
    from splat_tracer.render.splats import SplatCloud
    cloud = SplatCloud(np.zeros((1, 3), np.float32), np.array([[0, 0, 1]], np.float32), np.ones(1, np.float32))
    with pytest.raises(ValueError, match="RenderScene.render"):
        cloud.render(cam.with_lens(Lens(0.1, 1.0)), 4, 4)
    assert cam.with_lens(Lens(0.0, 1.0)).lens is None  # a closed aperture is the pinhole


def test_the_lens_image_is_the_same_in_packets_ray_by_ray_and_on_any_thread_count():
    lens = Lens(0.1, F, blades=5, rotation=0.4)
    cam = Camera(np.eye(4), (-HALF, HALF, -HALF, HALF), (0.01, 1000.0), False, lens)
    stage = _half_plane(Z, 0)
    settings = RenderSettings(samples=8, max_bounces=0)
    ref = stage.render(cam, W, W, settings, Method(), threads=1).passes["Combined"]
    for kw in (dict(packets=False, threads=2), dict(threads=2, tile_size=8)):
        np.testing.assert_array_equal(stage.render(cam, W, W, settings, Method(), **kw).passes["Combined"], ref)
