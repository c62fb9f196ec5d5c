"""The native core through its plain-Python API (no Blender involved)."""
from __future__ import annotations

import numpy as np
import pytest

from splat_tracer import _core
from splat_tracer.render.camera import Camera
from splat_tracer.render.method import Method
from splat_tracer.render.splats import SplatCloud, TraceResult


def random_discs(n, rng, spread=1.0, offset=0.0):
    centres = rng.uniform(-spread, spread, size=(n, 3)) + offset
    normals = rng.normal(size=(n, 3))
    radii = rng.uniform(0.02, 0.15, size=n) * spread
    return centres, normals, radii


def unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def in_plane_directions(normals, rng):
    """A random unit vector perpendicular to each normal."""
    u = np.cross(normals, rng.normal(size=normals.shape))
    return unit(u)


def assert_same_hits(a: TraceResult, b: TraceResult):
    np.testing.assert_array_equal(a.id, b.id)
    np.testing.assert_array_equal(a.t, b.t)
    np.testing.assert_array_equal(a.front, b.front)
    np.testing.assert_array_equal(a.normal, b.normal)


@pytest.mark.parametrize("offset", [0.0, 1000.0])
def test_bvh_matches_brute_force_on_random_rays(offset):
    rng = np.random.default_rng(7)
    c, n, r = random_discs(3000, rng, offset=offset)
    scene = SplatCloud(c, n, r)
    origins = rng.uniform(-2, 2, size=(20000, 3)) + offset
    dirs = rng.normal(size=(20000, 3))
    bvh, brute = scene.trace(origins, dirs), scene.trace(origins, dirs, brute_force=True)
    assert_same_hits(bvh, brute)
    assert 0.2 < (bvh.id >= 0).mean() < 0.95  # the comparison covers hits and misses alike


def test_bvh_matches_brute_force_on_rim_and_grazing_rays():
    """Rays aimed exactly at disc rims (just inside, on, and just outside) and rays within
    a hair of the disc plane: where a too-tight box or a lax traversal would lose hits."""
    rng = np.random.default_rng(11)
    c, n, r = random_discs(2000, rng)
    scene = SplatCloud(c, n, r)
    nu = unit(n)
    pick = rng.integers(0, len(c), size=6000)
    u = in_plane_directions(nu[pick], rng)
    scale = np.repeat([1 - 1e-6, 1.0, 1 + 1e-6], 2000)
    rim_points = c[pick] + u * (r[pick] * scale)[:, None]
    # Rim rays: from a random outside point through the rim point.
    dirs = unit(rng.normal(size=(6000, 3)))
    origins = rim_points - 3.0 * dirs
    # Grazing rays: nearly in the disc plane (angles from 1e-2 down to 1e-7 rad), through
    # points inside the disc.
    angles = 10.0 ** rng.uniform(-7, -2, size=6000)
    g_dirs = unit(u * np.cos(angles)[:, None] + nu[pick] * np.sin(angles)[:, None])
    inside = c[pick] + in_plane_directions(nu[pick], rng) * (0.5 * r[pick])[:, None]
    g_origins = inside - 2.0 * g_dirs
    all_o = np.concatenate([origins, g_origins])
    all_d = np.concatenate([dirs, g_dirs])
    bvh, brute = scene.trace(all_o, all_d), scene.trace(all_o, all_d, brute_force=True)
    assert_same_hits(bvh, brute)
    assert (bvh.id[:4000] >= 0).mean() > 0.9  # rim rays at and just inside the rim hit


def test_results_do_not_depend_on_thread_count():
    rng = np.random.default_rng(3)
    scene = SplatCloud(*random_discs(5000, rng))
    o, d = rng.uniform(-2, 2, size=(50000, 3)), rng.normal(size=(50000, 3))
    assert_same_hits(scene.trace(o, d, threads=1), scene.trace(o, d, threads=2))


def test_build_does_not_depend_on_thread_count():
    """Above 32k splats the top of the tree is split with the binning and (above 128k) the
    partitioning shared by the threads, then subtrees are built on threads, and (above 64k
    binary nodes) collapsed into wide nodes on threads: the same tree, the same leaf order
    and so the same results of every query as on one thread."""
    rng = np.random.default_rng(5)
    discs = random_discs(150000, rng)
    one, two = SplatCloud(*discs, threads=1), SplatCloud(*discs, threads=2)
    assert one.bvh_stats() == two.bvh_stats()
    o, d = rng.uniform(-2, 2, size=(20000, 3)), rng.normal(size=(20000, 3))
    assert_same_hits(one.trace(o, d), two.trace(o, d))
    full = Method.preset("FULL")
    a, b = one.trace_surface(o, d, full, members=True), two.trace_surface(o, d, full, members=True)
    for field in ("t", "id", "normal", "members"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
    assert_same_hits(two.trace(o[:1000], d[:1000]), two.trace(o[:1000], d[:1000], brute_force=True))


def test_scene_keeps_at_most_64_bytes_per_splat():
    """Issue #12: centres, normals and radii stored once (in leaf order), no colour array
    without colours, the 4-wide tree shrunk to the nodes used."""
    from geometry import sphere_cloud
    c, n, r = sphere_cloud(200000)
    plain = SplatCloud(c, n, r, closed=True).bvh_stats()["bytes"] / len(c)
    assert plain <= 64, plain
    coloured = SplatCloud(c, n, r, colours=np.ones_like(c)).bvh_stats()["bytes"] / len(c)
    assert coloured == pytest.approx(plain + 12, abs=0.01)


def single_disc(normal=(0, 0, 1), radius=1.0, centre=(0, 0, 0)):
    return SplatCloud([centre], [normal], [radius])


def trace_one(scene, origin, direction, **kw):
    res = scene.trace([origin], [direction], **kw)
    return float(res.t[0]), int(res.id[0]), bool(res.front[0]), res.normal[0]


def test_hand_made_front_and_back_hits():
    scene = single_disc()
    t, i, front, nrm = trace_one(scene, (0.5, 0, 2), (0, 0, -1))
    assert (t, i, front) == (2.0, 0, True)
    np.testing.assert_array_equal(nrm, [0, 0, 1])
    t, i, front, _ = trace_one(scene, (0.5, 0, -3), (0, 0, 1))
    assert (t, i, front) == (3.0, 0, False)


def test_hand_made_rim_parallel_and_interval():
    scene = single_disc()
    assert trace_one(scene, (0.9999, 0, 2), (0, 0, -1))[1] == 0
    assert trace_one(scene, (1.0001, 0, 2), (0, 0, -1))[1] == -1
    assert trace_one(scene, (-5, 0, 0), (1, 0, 0))[1] == -1  # in the plane: parallel
    assert trace_one(scene, (0, 0, 2), (0, 0, -1), tmax=1.9)[1] == -1
    assert trace_one(scene, (0, 0, 2), (0, 0, -1), tmin=2.1)[1] == -1
    assert trace_one(scene, (0, 0, 2), (0, 0, -1), tmin=1.9, tmax=2.1)[1] == 0


def test_hand_made_oblique_hit_and_unnormalised_inputs():
    scene = single_disc(normal=(0, 0, 5.0))  # normals are normalised by the core
    d = unit([1.0, 0.0, -1.0])
    t, i, front, nrm = trace_one(scene, (-1, 0, 1), d * 7.0)  # directions need not be unit
    assert i == 0 and front
    assert t == pytest.approx(np.sqrt(2), rel=1e-6)  # t is a distance
    np.testing.assert_allclose(nrm, [0, 0, 1])


def test_equal_distance_ties_go_to_the_smaller_id():
    scene = SplatCloud([[0, 0, 0], [0.1, 0, 0], [0.05, 0, 0]], [[0, 0, 1]] * 3, [1, 1, 1])
    assert trace_one(scene, (0.05, 0, 1), (0, 0, -1))[1] == 0


def test_empty_scene_misses_everything():
    scene = SplatCloud(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0))
    res = scene.trace([[0, 0, 0]], [[0, 0, 1]])
    assert res.id[0] == -1 and np.isinf(res.t[0])
    assert scene.bounds is None
    img = scene.render(Camera.look_at((0, -5, 0), (0, 0, 0)), 8, 6, background=(0.1, 0.2, 0.3, 1))
    np.testing.assert_allclose(img.rgba[..., :3], np.broadcast_to([0.1, 0.2, 0.3], (6, 8, 3)), rtol=1e-6)


@pytest.mark.parametrize("bad, message", [
    (lambda c, n, r: (c[:, :2], n, r), "centres must have shape"),
    (lambda c, n, r: (c, n[:-1], r), "normals must have shape"),
    (lambda c, n, r: (c, n, r[:-1]), "radii must have shape"),
    (lambda c, n, r: (np.where(np.arange(len(c))[:, None] == 3, np.nan, c), n, r), "splat 3: centre is not finite"),
    (lambda c, n, r: (c, np.where(np.arange(len(c))[:, None] == 4, 0.0, n), r), "splat 4: normal has zero length"),
    (lambda c, n, r: (c, n, np.where(np.arange(len(r)) == 5, -1.0, r)), "splat 5: radius must be > 0"),
    (lambda c, n, r: (c, n, np.where(np.arange(len(r)) == 6, np.inf, r)), "splat 6: radius"),
])
def test_invalid_scene_input_raises(bad, message):
    rng = np.random.default_rng(0)
    c, n, r = random_discs(10, rng)
    with pytest.raises(ValueError, match=message):
        SplatCloud(*bad(c, n, r))


def test_native_module_validates_buffers_itself():
    """The compiled module checks dtype, layout and sizes even when called directly."""
    c = np.zeros((4, 3), np.float32)
    n = np.tile(np.float32([0, 0, 1]), (4, 1))
    r = np.ones(4, np.float32)
    with pytest.raises(TypeError, match="float32"):
        _core.SplatCloud(c.astype(np.float64), n, r)
    with pytest.raises(TypeError, match="C-contiguous"):
        _core.SplatCloud(np.zeros((3, 4), np.float32).T, n[:4], r)
    with pytest.raises(TypeError):
        _core.SplatCloud("not an array", n, r)
    with pytest.raises(ValueError, match="axis 0"):
        _core.SplatCloud(c, n[:3], r)
    scene = _core.SplatCloud(c, n, r)
    o = np.zeros((5, 3), np.float32)
    d = np.tile(np.float32([0, 0, 1]), (5, 1))
    out = (np.empty(5, np.float32), np.empty(5, np.int32), np.empty(5, np.uint8))
    with pytest.raises(ValueError, match="out_t"):
        scene.trace(o, d, 0.0, 1.0, np.empty(4, np.float32), *out[1:])
    with pytest.raises(TypeError, match="int32"):
        scene.trace(o, d, 0.0, 1.0, out[0], np.empty(5, np.int64), out[2])
    with pytest.raises(TypeError, match="writable"):
        ro = np.empty(5, np.float32)
        ro.flags.writeable = False
        scene.trace(o, d, 0.0, 1.0, ro, *out[1:])
    with pytest.raises(ValueError, match="tmin < tmax"):
        scene.trace(o, d, 1.0, 1.0, *out)
    bad_d = d.copy()
    bad_d[2] = 0
    with pytest.raises(ValueError, match="ray 2: direction"):
        scene.trace(o, bad_d, 0.0, 1.0, *out)
    bad_o = o.copy()
    bad_o[1, 0] = np.inf
    with pytest.raises(ValueError, match="ray 1: origin"):
        scene.trace(bad_o, d, 0.0, 1.0, *out)


def test_render_window_and_callback_validation():
    scene = single_disc()
    cam = Camera.look_at((0, 0, 5), (0, 0, 0), up=(0, 1, 0))
    with pytest.raises(ValueError, match="window"):
        scene.render(cam, 16, 16, window=(8, 8, 9, 4))
    with pytest.raises(TypeError, match="callable"):
        scene.render(cam, 16, 16, progress=42)

    def failing(done, total):
        raise KeyError("from the callback")

    with pytest.raises(KeyError, match="from the callback"):
        scene.render(cam, 512, 512, progress=failing, tile_size=8)


def test_render_stops_when_progress_asks():
    rng = np.random.default_rng(1)
    scene = SplatCloud(*random_discs(20000, rng))
    cam = Camera.look_at((0, -4, 0), (0, 0, 0))
    calls = []

    def stop(done, total):
        calls.append((done, total))
        return True

    img = scene.render(cam, 2000, 1500, progress=stop, tile_size=8, threads=1)
    assert not img.completed
    assert len(calls) == 1 and calls[0][1] == 250 * 188  # ceil(2000/8) x ceil(1500/8) tiles
    assert calls[0][0] < calls[0][1]
    calls.clear()
    full = scene.render(cam, 64, 48, progress=lambda d, t: calls.append((d, t)))
    assert full.completed and calls[-1] == (4, 4)  # 2 x 2 tiles of 32


def test_render_agrees_with_trace_and_planar_depth():
    """render() shoots exactly Camera.rays(); its depth pass is the planar depth."""
    rng = np.random.default_rng(5)
    scene = SplatCloud(*random_discs(4000, rng))
    for cam in (Camera.look_at((0.3, -4, 0.5), (0, 0, 0), fov_y=50),
                Camera.look_at((0.3, -4, 0.5), (0, 0, 0), ortho_height=2.5)):
        w, h = 64, 48
        img = scene.render(cam, w, h, method=Method.preset("GENERAL"))
        o, d = cam.rays(w, h)
        hits = scene.trace(o, d)
        hit = hits.id.reshape(h, w) >= 0
        np.testing.assert_array_equal(img.rgba[..., 3] == 1.0, hit)
        planar = ((o + d * np.where(hits.id >= 0, hits.t, 0)[:, None]) - cam.position) @ cam.forward
        np.testing.assert_allclose(img.depth[hit], planar.reshape(h, w)[hit], rtol=1e-5)
        np.testing.assert_array_equal(img.depth[~hit], 1e10)
        # An open cloud's back hit is written turned towards the ray, as Cycles writes a back face's.
        turned = np.where(hits.front[:, None], hits.normal, -hits.normal)
        assert (~hits.front[hits.id >= 0]).any()
        np.testing.assert_array_equal(img.normal.reshape(-1, 3)[hits.id >= 0], turned[hits.id >= 0])
        # Headlight shading: colour = |cos| between ray and normal (white splats).
        cos = np.abs(np.einsum("ij,ij->i", hits.normal, d)).reshape(h, w)
        np.testing.assert_allclose(img.rgba[..., 0][hit], cos[hit], atol=1e-5)


def test_window_render_equals_crop_of_full_render():
    rng = np.random.default_rng(9)
    scene = SplatCloud(*random_discs(3000, rng))
    cam = Camera.look_at((0, -4, 1), (0, 0, 0))
    full = scene.render(cam, 80, 60)
    part = scene.render(cam, 80, 60, window=(10, 20, 33, 17))
    np.testing.assert_array_equal(part.rgba, full.rgba[20:37, 10:43])
    np.testing.assert_array_equal(part.depth, full.depth[20:37, 10:43])


def test_camera_look_at_centre_ray_is_the_view_axis():
    cam = Camera.look_at((1, 2, 3), (4, 6, 3), up=(0, 0, 1), fov_y=30, aspect=2.0)
    o, d = cam.rays(3, 3)
    np.testing.assert_allclose(d[4], unit([3, 4, 0]), atol=1e-6)
    np.testing.assert_allclose(cam.forward, unit([3, 4, 0]))
    # Vertical field of view: the top-centre pixel of a 1-pixel-wide, N-tall image.
    _, d = cam.rays(1, 1000)
    angle = np.degrees(np.arccos(np.dot(d[0], unit([3, 4, 0]))))
    assert angle == pytest.approx(15.0 * (999 / 1000), rel=1e-3)
