"""Object Info, object attributes and Light Path in the core (render/nodes.py OBJECT_VALUE,
LIGHT_PATH): per instance values reach the program, a camera sees Is Camera Ray, bounce rays
and shadow rays see theirs. Values set here, compared exactly (emission seen directly)."""
from __future__ import annotations

import numpy as np
import pytest

from splat_tracer.render import nodes, scene, shading
from splat_tracer.render.camera import Camera


def _square(half=0.5):
    v = np.array([[-half, -half, 0], [half, -half, 0], [half, half, 0], [-half, half, 0]], np.float32)
    return scene.Mesh(v, np.array([[0, 1, 2], [0, 2, 3]]))


def _render(instances, samples=1, bounces=0, height=2.0):
    rs = scene.RenderScene(instances, world=shading.World(colour=(0, 0, 0)))
    cam = Camera.look_at((0, 0, 2), (0, 0, 0), up=(0, 1, 0), fov_y=40, aspect=1, ortho_height=height)
    settings = shading.RenderSettings(samples=samples, max_bounces=bounces)
    return rs.render(cam, 32, 32, settings).passes["Combined"][..., :3]


def _placed(x, y):
    return ((1, 0, 0, x), (0, 1, 0, y), (0, 0, 1, 0), (0, 0, 0, 1))


def test_object_info_and_attributes_are_per_instance():
    b = nodes.Builder()
    random, index = b.object_info("Random"), b.object_info("Object Index")
    attr = b.object_attribute("OBJECT", "tint")
    colour = b.register(width=3)
    b.emit("COMBINE", colour, random, index, attr + 1)  # (random, index, the tint's green)
    b.output("emission", colour)
    material = shading.Material(base_colour=(0, 0, 0), program=b.program())
    square = _square()
    left = scene.Instance(square, _placed(-0.5, 0), (material,), name="L",
                          object_info=(-0.5, 0, 0, 1, 1, 1, 1, 3, 0.25),
                          object_attributes=((("OBJECT", "tint"), (0.1, 0.7, 0.2, 1.0)),))
    right = scene.Instance(square, _placed(0.5, 0), (material,), pass_index=2, name="R")  # defaults, no tint
    img = _render([left, right])
    np.testing.assert_allclose(img[16, 8], [0.25, 3, 0.7], atol=1e-6)
    np.testing.assert_allclose(img[16, 24], [0, 2, 0], atol=1e-6)  # random 0, its pass index, tint 0


def test_a_scene_without_object_nodes_carries_no_values():
    b = nodes.Builder()
    b.output("emission", b.global_("UV"))
    assert not b.program().reads_object()
    with pytest.raises(ValueError):
        scene.RenderScene([scene.Instance(_square(), object_info=(1, 2), materials=(shading.Material(program=_info()),))])


def _info():
    b = nodes.Builder()
    b.output("emission", b.object_info("Color"))
    return b.program()


def _light_path(output: str):
    b = nodes.Builder()
    first = b.light_path()
    value = first + nodes.LIGHT_PATH.index(output)
    colour = b.register(width=3)
    b.emit("COMBINE", colour, value, value, value)
    return b, colour


def test_a_camera_ray_is_a_camera_ray_and_depth_zero():
    for output, want in (("Is Camera Ray", 1.0), ("Is Diffuse Ray", 0.0), ("Ray Depth", 0.0),
                         ("Is Shadow Ray", 0.0)):
        b, colour = _light_path(output)
        b.output("emission", colour)
        img = _render([scene.Instance(_square(1.0), materials=(shading.Material(base_colour=(0, 0, 0),
                                                                                program=b.program()),))])
        assert img[16, 16] == pytest.approx([want] * 3, abs=1e-6), output


def test_the_core_refuses_bad_object_values():
    """Not finite, too many per instance, or not one row per instance: a ValueError, never a crash."""
    square = _square()
    row = scene.InstanceRow(0, np.eye(4)[:3].ravel(), np.eye(4)[:3].ravel(), (0, 1), 31, False, 0.0, False, None)
    material = shading.Material(program=_info())
    args = ([square._mesh], [row], [material.pack()], [], 1, [material.program.native()])
    scene.native_scene(*args, object_values=np.zeros((1, nodes.OBJECT_INFO_FLOATS)))
    for bad in (np.full((1, nodes.OBJECT_INFO_FLOATS), np.nan), np.zeros((1, 200)), np.zeros((2, 9))):
        with pytest.raises(ValueError):
            scene.native_scene(*args, object_values=bad)
