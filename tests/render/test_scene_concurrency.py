"""Renders of one RenderScene at once (issue #22): from two threads, or from inside another's
progress callback. Which closed clouds enclose the camera was a flag of the shared scene,
rewritten by each render while another ran without the GIL (its depth pixels changed); it is
now each render's own. Every render must give exactly the image it gives alone."""
from __future__ import annotations

import threading

import numpy as np
import pytest

from splat_tracer.render.camera import Camera
from splat_tracer.render.method import Method
from splat_tracer.render.scene import Instance, RenderScene
from splat_tracer.render.shading import Light, RenderSettings, World
from splat_tracer.render.splats import SplatCloud

from geometry import sphere_cloud

W = H = 48
PASSES = ("Combined", "Depth", "Normal")
# Inside the closed sphere (its camera rays start inside it: they see its inner side) and
# outside it, and a second view from inside.
CAMERAS = {
    "inside": Camera.look_at((0.0, 0.0, 0.2), (0.0, 0.0, -1.0), (0, 1, 0), 60.0, 1.0),
    "outside": Camera.look_at((0.0, 0.0, 4.0), (0.0, 0.0, 0.0), (0, 1, 0), 40.0, 1.0),
    "inside_side": Camera.look_at((0.3, 0.0, 0.0), (1.0, 0.0, 0.0), (0, 0, 1), 60.0, 1.0),
}


@pytest.fixture(scope="module")
def scene():
    c, n, r = sphere_cloud(6000)
    cloud = SplatCloud(c, n, r, closed=True)
    return RenderScene([Instance(cloud)], [Light(type="POINT", power=50.0, position=(0.0, 0.0, 0.0))],
                       World(colour=(0.05, 0.05, 0.05)))


def frame(scene, name, progress=None, samples=2):
    result = scene.render(CAMERAS[name], W, H, RenderSettings(samples=samples), Method.preset("FULL"), PASSES,
                          progress=progress, tile_size=8, threads=2)
    return result


@pytest.fixture(scope="module")
def alone(scene):
    return {name: frame(scene, name).passes for name in CAMERAS}


def assert_same(passes, expected):
    for name in PASSES:
        assert np.array_equal(passes[name], expected[name]), name


def test_the_cameras_differ_where_the_flag_matters(alone):
    """The case is a real one: a camera inside sees the sphere's inside at every pixel."""
    assert (alone["inside"]["Depth"] < 2.0).all() and (alone["inside_side"]["Depth"] < 2.0).all()
    assert (alone["outside"]["Depth"] > 2.0).any()


@pytest.mark.parametrize("pair", [("inside", "outside"), ("outside", "inside"), ("inside", "inside_side")])
def test_two_threads_render_one_scene_as_each_alone(scene, alone, pair):
    results, errors = {}, []
    barrier = threading.Barrier(2)

    def run(name, repeat=4):
        try:
            barrier.wait()
            results[name] = [frame(scene, name).passes for _ in range(repeat)]
        except Exception as e:  # noqa: BLE001 - reported below
            errors.append(e)
    threads = [threading.Thread(target=run, args=(name,)) for name in pair]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors, errors
    for name in pair:
        for passes in results[name]:
            assert_same(passes, alone[name])


@pytest.mark.parametrize("outer,inner", [("inside", "outside"), ("outside", "inside")])
def test_a_render_from_inside_another_renders_progress_callback(scene, alone, outer, inner):
    inner_frames = []

    def progress(done, total):
        if len(inner_frames) < 3:  # a few times during the outer render
            inner_frames.append(frame(scene, inner).passes)
        return False
    outer_result = frame(scene, outer, progress=progress)
    assert outer_result.completed and inner_frames
    assert_same(outer_result.passes, alone[outer])
    for passes in inner_frames:
        assert_same(passes, alone[inner])
