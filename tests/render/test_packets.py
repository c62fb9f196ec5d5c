"""Ray packets (native/bvh/packet.h): 16 coherent rays through the BVH together give exactly the
answers each ray gets alone -- for the nearest hit, for every visibility method, for rays
inside objects and with exclusions, for perspective and orthographic cameras and for views
along an axis -- and incoherent rays fall back to one ray at a time."""
from __future__ import annotations

import numpy as np
import pytest

from geometry import cube_cloud, fibonacci_sphere
from splat_tracer import _core
from splat_tracer.pointcloud import spacing
from splat_tracer.render.camera import Camera, packet_order
from splat_tracer.render.method import PRESETS, Method
from splat_tracer.render.splats import SplatCloud, SurfaceResult, TraceResult, simd_path

W, H = 96, 72  # not multiples of 16 rays per row: packets straddle rows and the last is short


@pytest.fixture(autouse=True, params=["AVX2", "SSE2"])
def simd(request):
    """Every test on both packet kernels: AVX2 (chosen at run time where the CPU has it)
    and the SSE2 baseline every x86-64 build runs elsewhere."""
    want = request.param == "AVX2"
    before = _core._use_avx2(want)
    try:
        if want and "AVX2" not in simd_path():
            pytest.skip("this CPU has no AVX2")
        yield request.param
    finally:
        _core._use_avx2(before)


@pytest.fixture(scope="module")
def scene():
    """A rough sphere with radii varying 6x (layers of several depths, a nearer first hit
    with a larger window met late) inside a cube shell: closed, nested, sharp edges."""
    rng = np.random.default_rng(5)
    p, n = fibonacci_sphere(5000, radius=0.6)
    p = p + rng.normal(scale=0.006, size=p.shape)
    radii = 0.025 * rng.uniform(0.5, 3.0, size=len(p))
    q, m = cube_cloud(40)
    rq, _ = spacing.knn_spacing(q)
    return SplatCloud(np.concatenate([p, q]), np.concatenate([n, m]), np.concatenate([radii, rq]), closed=True)


def tiles(cam):
    o, d = cam.rays(W, H)
    order = packet_order(W, H)
    return o[order], d[order]


CAMERAS = {
    "perspective, outside": lambda: Camera.look_at((2.6, -3.1, 1.9), (0, 0, 0), fov_y=40, aspect=W / H),
    "perspective, inside the cube": lambda: Camera.look_at((0.1, -0.85, 0.2), (0, 0, 0), fov_y=70,
                                                               aspect=W / H),
    "orthographic": lambda: Camera.look_at((3, 2, 1.5), (0, 0, 0), ortho_height=2.6, aspect=W / H),
    # Along -z exactly: every ray's x and y direction components are 0 (orthographic) or
    # change sign across the image (perspective): axes the packet test must leave untested.
    "orthographic along an axis": lambda: Camera.look_at((0, 0, 4), (0, 0, 0), up=(0, 1, 0),
                                                             ortho_height=2.6, aspect=W / H),
    "perspective along an axis": lambda: Camera.look_at((0, 0, 4), (0, 0, 0), up=(0, 1, 0), fov_y=40,
                                                            aspect=W / H),
}


def assert_same(a, b):
    for name, x, y in zip(a._fields, a, b):
        if x is not None or y is not None:
            np.testing.assert_array_equal(x, y, err_msg=name)


@pytest.mark.parametrize("camera", CAMERAS)
def test_nearest_hit_packets_equal_single_rays_and_brute_force(scene, camera):
    o, d = tiles(CAMERAS[camera]())
    packed = scene.trace(o, d, packets=True)
    assert_same(packed, scene.trace(o, d, packets=False))
    sub = slice(0, len(o), 7)  # brute force on every 7th ray (it tests every splat)
    assert_same(TraceResult(*(None if v is None else v[sub] for v in packed)),
                scene.trace(o[sub], d[sub], brute_force=True))
    assert 0.2 < (packed.id >= 0).mean() <= 1.0
    # The packets were really traced as packets: their inner nodes count once for 16 rays.
    assert scene.traversal_cost(o, d, packets=True)["nodes"] < 0.6 * scene.traversal_cost(o, d)["nodes"]


@pytest.mark.parametrize("camera", CAMERAS)
@pytest.mark.parametrize("preset", PRESETS)
def test_surface_packets_equal_single_rays(scene, camera, preset):
    o, d = tiles(CAMERAS[camera]())
    method = Method.preset(preset)
    a = scene.trace_surface(o, d, method, members=True, packets=True)
    assert_same(a, scene.trace_surface(o, d, method, members=True, packets=False))
    sub = slice(3, len(o), 11)
    assert_same(SurfaceResult(*(v[sub] for v in a)),
                scene.trace_surface(o[sub], d[sub], method, members=True, brute_force=True))


def test_surface_packets_with_inside_rays_and_exclusions(scene):
    """Refracted and shadow rays' inputs ride along per ray: mixed inside flags, and each
    ray excluding the splats its neighbour in the packet hit."""
    o, d = tiles(CAMERAS["perspective, outside"]())
    rng = np.random.default_rng(2)
    inside = rng.uniform(size=len(o)) < 0.4
    first = scene.trace_surface(o, d, Method.preset("FULL"), members=True)
    exclude = np.roll(first.members[:, :4], 1, axis=0)
    for preset in PRESETS:
        method = Method.preset(preset)
        for kwargs in ({"inside": inside}, {"exclude": exclude}, {"inside": inside, "exclude": exclude}):
            a = scene.trace_surface(o, d, method, members=True, packets=True, **kwargs)
            assert_same(a, scene.trace_surface(o, d, method, members=True, packets=False, **kwargs))


def test_render_packets_give_the_same_image(scene):
    cam = CAMERAS["perspective, outside"]()
    for preset in PRESETS:
        method = Method.preset(preset)
        for tile in (32, 7):  # 7: blocks cut short at every tile's edge
            a = scene.render(cam, W, H, method=method, tile_size=tile)
            b = scene.render(cam, W, H, method=method, tile_size=tile, packets=False)
            for x, y in zip(a[:3], b[:3]):
                np.testing.assert_array_equal(x, y)
            assert (a.depth < 1e10).mean() > 0.3


def test_incoherent_rays_are_traced_one_by_one_with_the_same_answers(scene):
    rng = np.random.default_rng(9)
    o = rng.uniform(-2, 2, size=(1000, 3))
    d = rng.normal(size=(1000, 3))
    assert_same(scene.trace(o, d, packets=True), scene.trace(o, d, packets=False))
    # Nothing was packed: the same work as one ray at a time.
    assert scene.traversal_cost(o, d, packets=True) == scene.traversal_cost(o, d)
    for preset in PRESETS:
        method = Method.preset(preset)
        assert_same(scene.trace_surface(o, d, method, members=True),
                    scene.trace_surface(o, d, method, members=True, packets=False))


def test_a_packet_wider_than_the_cone_is_not_packed(scene):
    """Rays from one point fanning out 10 degrees apart (a coarse 16-ray probe) fail the
    coherence test; rays 0.1 degree apart pass it."""
    def fan(step_deg):
        a = np.radians(step_deg) * (np.arange(16) - 7.5)
        d = np.column_stack([np.sin(a), np.full(16, 0.0), -np.cos(a)])
        return np.tile([0.0, 0.0, 3.0], (16, 1)), d
    for step, packed in ((10.0, False), (0.1, True)):
        o, d = fan(step)
        single = scene.traversal_cost(o, d)["nodes"]
        cost = scene.traversal_cost(o, d, packets=True)["nodes"]
        assert (cost < single) == packed, (step, cost, single)
        assert_same(scene.trace(o, d), scene.trace(o, d, packets=False))


def test_packet_order_puts_4x4_tiles_together():
    order = packet_order(10, 6)
    assert sorted(order) == list(range(60))
    rows, cols = np.divmod(order[:16], 10)
    assert set(rows) == {0, 1, 2, 3} and set(cols) == {0, 1, 2, 3}
    with pytest.raises(ValueError):
        packet_order(0, 4)
