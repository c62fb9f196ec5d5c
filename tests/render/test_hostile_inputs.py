"""Regression tests for what a hostile test of the core found (issue #9): inputs that used to
crash the process, silently wrong answers, and pathological slowness (checked by counting
the traversal's work, never by timing)."""
from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from splat_tracer import _core
from splat_tracer.render.camera import Camera
from splat_tracer.render.method import Method
from splat_tracer.render.scene import Instance, Mesh, RenderScene
from splat_tracer.render.splats import SplatCloud

from geometry import sphere_cloud

ROOT = Path(__file__).resolve().parents[2]


def run_isolated(code: str) -> subprocess.CompletedProcess:
    """Runs `code` in a fresh interpreter, so that a crash fails this test instead of killing
    the whole test session."""
    prelude = (f"import sys; sys.path.insert(0, {str(ROOT)!r})\nimport numpy as np\n"
               "from splat_tracer.render.camera import Camera\n"
               "from splat_tracer.render.method import Method\n"
               "from splat_tracer.render.scene import Instance, Mesh, RenderScene\n"
               "from splat_tracer.render.splats import SplatCloud\n")
    return subprocess.run([sys.executable, "-c", prelude + textwrap.dedent(code)], capture_output=True, text=True,
                          timeout=120)


def test_empty_scene_statistics_do_not_crash():
    result = run_isolated("""
        s = SplatCloud(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0))
        print(s.bvh_stats())
    """)
    assert result.returncode == 0, result.stderr
    assert "'nodes': 0" in result.stdout and "'depth': 0" in result.stdout


@pytest.mark.parametrize("coordinate", [2e38, 3.0e38, -2.5e38, 1.5e18])
def test_centres_beyond_the_safe_range_are_refused_not_crashed(coordinate):
    result = run_isolated(f"""
        c = np.array([[{coordinate}, 0, 0], [-{coordinate}, 0, 0], [{coordinate}, 1, 0]], np.float32)
        try:
            SplatCloud(c, np.tile([0, 0, 1.0], (3, 1)), np.ones(3))
        except ValueError as e:
            print("refused:", e)
    """)
    assert result.returncode == 0, result.stderr
    assert "refused: splat 0: centre is beyond 1e18" in result.stdout


def test_largest_accepted_coordinates_still_trace():
    """Right at the limit the BVH builds and the hits are the brute-force hits."""
    rng = np.random.default_rng(3)
    c = (rng.uniform(-1, 1, (200, 3)) * 1e18).astype(np.float32)
    n = rng.normal(size=(200, 3))
    scene = SplatCloud(c, n, np.full(200, 1e16))
    o = np.zeros((64, 3), np.float32)
    d = rng.normal(size=(64, 3)).astype(np.float32)
    a, b = scene.trace(o, d), scene.trace(o, d, brute_force=True)
    np.testing.assert_array_equal(a.id, b.id)
    assert scene.bvh_stats()["depth"] > 1


def test_huge_radius_is_refused():
    with pytest.raises(ValueError, match="splat 0: radius must be > 0 and at most 1e18"):
        SplatCloud([[0, 0, 0]], [[0, 0, 1]], [1e30])


@pytest.mark.parametrize("budget", [0, 1])
def test_refused_threads_degrade_to_fewer_threads(budget):
    """When the system refuses a worker thread (after `budget` were started), the build,
    trace and render finish with the threads they got, and give the same answer."""
    c, n, r = sphere_cloud(40_000, seed=2)  # big enough for a parallel BVH build
    reference_scene = SplatCloud(c, n, r, closed=True, threads=2)
    cam = Camera.look_at((0, -3, 0.5), (0, 0, 0))
    reference = reference_scene.render(cam, 64, 48, threads=2)
    o, d = cam.rays(64, 48)
    reference_hits = reference_scene.trace(o, d, threads=2)
    _core._set_thread_budget(budget)
    try:
        scene = SplatCloud(c, n, r, closed=True, threads=2)
        image = scene.render(cam, 64, 48, threads=2)
        hits = scene.trace(o, d, threads=2)
    finally:
        _core._set_thread_budget(-1)
    assert image.completed
    np.testing.assert_array_equal(image.rgba, reference.rgba)
    np.testing.assert_array_equal(hits.id, reference_hits.id)


def test_render_with_no_thread_at_all_still_reports_progress_and_stops():
    c, n, r = sphere_cloud(20_000, seed=4)
    scene = SplatCloud(c, n, r, threads=1)
    cam = Camera.look_at((0, -3, 0.5), (0, 0, 0))
    calls = []
    _core._set_thread_budget(0)
    try:
        image = scene.render(cam, 1024, 768, threads=2, tile_size=8,
                             progress=lambda done, total: calls.append(done) or True)
    finally:
        _core._set_thread_budget(-1)
    assert not image.completed and calls


@pytest.mark.parametrize("axis", range(3))
def test_axis_aligned_orthographic_views_cost_what_oblique_ones_cost(axis):
    """Rays parallel to a box's slab used to make the slab test NaN, so no box was ever
    rejected: axis-aligned orthographic views traced the whole tree (500-1000x slower)."""
    c, n, r = sphere_cloud(20_000, seed=1)
    scene = SplatCloud(c, n, r, closed=True)
    direction = np.eye(3)[axis]
    up = np.eye(3)[(axis + 1) % 3]
    aligned = Camera.look_at(5 * direction, (0, 0, 0), up=up, ortho_height=3.0)
    tilted = Camera.look_at(5 * direction + 0.2 * up + 0.1 * np.eye(3)[(axis + 2) % 3], (0, 0, 0), up=up,
                            ortho_height=3.0)
    cost_aligned = scene.traversal_cost(*aligned.rays(80, 60))
    cost_tilted = scene.traversal_cost(*tilted.rays(80, 60))
    assert cost_aligned["nodes"] < 2.0 * cost_tilted["nodes"], (cost_aligned, cost_tilted)
    assert cost_aligned["discs"] < 2.0 * cost_tilted["discs"], (cost_aligned, cost_tilted)
    # ... and the image is right: the sphere's disc shape, not empty.
    hits = scene.trace(*aligned.rays(80, 60))
    assert (hits.id >= 0).mean() == pytest.approx(np.pi / 12, abs=0.02)  # unit disc in a 4 x 3 view


def test_very_long_and_very_short_directions_are_normalised():
    scene = SplatCloud([[0, 0, 0]], [[0, 0, 1]], [1.0])
    for length in (1e-30, 1e20, 3e38):
        res = scene.trace([[0, 0, 5]], np.array([[0, 0, -length]], np.float32))
        assert res.id[0] == 0 and res.t[0] == pytest.approx(5.0), length


def test_render_window_near_int_range_is_refused_not_overflowed():
    scene = SplatCloud([[0, 0, 0]], [[0, 0, 1]], [1.0])
    cam = Camera.look_at((0, 0, 5), (0, 0, 0), up=(0, 1, 0))
    with pytest.raises(ValueError, match="window"):
        scene._scene.render(*cam.native(), 100, 100,
                            (2**31 - 10, 0, 20, 1), (0, 0, 0, 0), np.empty((1, 20, 4), np.float32))


@pytest.mark.parametrize("exclude, error", [
    (np.array([[2**32]], np.int64), ValueError),
    (np.array([[7]]), ValueError),
    (np.array([[-2]]), ValueError),
    (np.array([[0.5]]), TypeError),
])
def test_exclude_ids_are_checked_not_cast(exclude, error):
    scene = SplatCloud([[0, 0, 0], [0, 0, 1]], [[0, 0, 1]] * 2, [1.0, 1.0])
    with pytest.raises(error):
        scene.trace_surface([[0, 0, 5]], [[0, 0, -1]], exclude=exclude)


def test_native_exclude_check():
    scene = _core.SplatCloud(np.zeros((1, 3), np.float32), np.float32([[0, 0, 1]]), np.ones(1, np.float32))
    out = [np.empty(1, np.float32), np.empty(1, np.int32), np.empty(1, np.uint8), np.empty((1, 3), np.float32),
           np.empty((1, 3), np.float32)]
    with pytest.raises(ValueError, match="exclude"):
        scene.trace_surface(np.float32([[0, 0, 5]]), np.float32([[0, 0, -1]]), 0.0, 10.0, Method(),
                            *out, None, None, np.int32([[5]]))


@pytest.mark.parametrize("kwargs, message", [
    (dict(fov_y=0), "fov_y"), (dict(fov_y=-10), "fov_y"), (dict(fov_y=180), "fov_y"),
    (dict(near=1.0, far=1.0), "near < far"), (dict(near=0.0), "near < far"), (dict(far=np.inf), "near < far"),
    (dict(ortho_height=0.0), "ortho_height"), (dict(aspect=0.0), "aspect"),
])
def test_look_at_rejects_unusable_cameras(kwargs, message):
    with pytest.raises(ValueError, match=message):
        Camera.look_at((0, 0, 5), (0, 0, 0), up=(0, 1, 0), **kwargs)


def test_look_at_rejects_eye_on_target():
    with pytest.raises(ValueError, match="same point"):
        Camera.look_at((1, 2, 3), (1, 2, 3))


@pytest.mark.parametrize("window", [(-1, -1, 1, 2**31 - 1), (0, 0, 2**20, 2**20), (3, 0, 8, 6)])
def test_render_window_is_checked_before_its_buffers_are_allocated(window):
    """Found by the property tests' degenerate inputs: Scene.render and RenderScene.render
    allocated the window's buffers before the core checked the window, so a bad one asked
    numpy for up to 34 GB (MemoryError) instead of being refused."""
    scene = SplatCloud([[0, 0, 0]], [[0, 0, 1]], [1.0])
    cam = Camera.look_at((0, 0, 5), (0, 0, 0), up=(0, 1, 0))
    with pytest.raises(ValueError, match="window"):
        scene.render(cam, 8, 6, window=window)
    with pytest.raises(ValueError, match="window"):
        RenderScene([Instance(scene)]).render(cam, 8, 6, window=window)


def test_objects_of_an_earlier_module_initialisation_stay_usable():
    """Found by the property tests (a RenderScene test refused a Scene when it ran after
    the Blender tests): the native module is initialised again when the same file is
    imported under a second package name (Blender's bl_ext copy beside splat_tracer, or an
    add-on reload). The core remembered only the last Scene and Mesh types, so earlier
    Scenes were refused and len() of an earlier Mesh dereferenced null (segfault)."""
    result = run_isolated(f"""
        import importlib, os, sys, tempfile
        from splat_tracer import _core
        mesh = Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
        scene = SplatCloud([[0, 0, 0]], [[0, 0, 1]], [1.0])
        d = tempfile.mkdtemp()
        os.makedirs(os.path.join(d, "other"))
        open(os.path.join(d, "other", "__init__.py"), "w").close()
        os.symlink(os.path.abspath(_core.__file__), os.path.join(d, "other", "_core.abi3.so"))
        sys.path.insert(0, d)
        other = importlib.import_module("other._core")
        assert other is not _core
        print("mesh size", len(mesh))
        print("instances", RenderScene([Instance(scene), Instance(mesh)])._scene.instances)
        new_scene = other.SplatCloud(np.zeros((1, 3), np.float32), np.float32([[0, 0, 1]]), np.ones(1, np.float32))
        print("new scene", len(new_scene.bvh_stats()))
    """)
    assert result.returncode == 0, result.stderr
    assert "mesh size 1" in result.stdout and "instances 2" in result.stdout, result.stdout
