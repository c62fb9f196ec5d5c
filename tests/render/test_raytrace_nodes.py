"""The nodes that ask the scene for more than the shading point (native/nodes/raytrace.h):
Ambient Occlusion, Wireframe, Bevel. Run by `nodes.run` there is no scene to trace and no
triangle: they give what Cycles gives where it cannot trace (AO 1, the unchanged normal) and
off triangles (Wireframe 0). Their rays are checked beside Cycles in
tests/blender/test_node_raytrace.py."""
import numpy as np
import pytest

from splat_tracer.render import nodes


def test_ambient_occlusion_without_a_scene_is_unoccluded():
    b = nodes.Builder()
    colour, ao = b.register(width=3), b.register()
    tint, distance, normal = b.register((0.2, 0.5, 0.9), 3), b.register(1.0), b.global_("NORMAL")
    b.emit("AMBIENT_OCCLUSION", colour, ao, tint, distance, normal, 16, 3)
    r = nodes.run(b.program(), 2, N=(0, 0, 1))
    np.testing.assert_array_equal(r[:, ao], 1.0)
    np.testing.assert_allclose(r[:, colour:colour + 3], [[0.2, 0.5, 0.9]] * 2, rtol=1e-6)


def test_wireframe_off_a_triangle_is_zero():
    b = nodes.Builder()
    out = b.register(7.0)
    b.emit("WIREFRAME", out, b.register(100.0), 0)
    assert nodes.run(b.program())[0, out] == 0.0


@pytest.mark.parametrize("linked", [0, 1])
def test_bevel_without_a_scene_keeps_the_normal(linked):
    b = nodes.Builder()
    out = b.register(width=3)
    reference = b.register((0.0, 0.6, 0.8), 3) if linked else b.global_("NORMAL")
    b.emit("BEVEL", out, b.register(0.1), reference, 8, linked)
    r = nodes.run(b.program(), N=(1, 0, 0))
    # Cycles: the bevel's change of the normal (none here) added to the linked Normal.
    np.testing.assert_allclose(r[0, out:out + 3], (0.0, 0.6, 0.8) if linked else (1, 0, 0), atol=1e-6)


@pytest.mark.parametrize("op,operands,what", [
    ("AMBIENT_OCCLUSION", (0, 3, 0, 4, 0, nodes.MAX_AO_SAMPLES + 1, 0), "value out of range"),
    ("AMBIENT_OCCLUSION", (0, 3, 0, 4, 0, 1, 8), "value out of range"),
    ("WIREFRAME", (0, 3, 2), "value out of range"),
    ("BEVEL", (0, 4, 3, 8, 0), "register out of range"),  # the normal, registers 3-5 of 0-4
])
def test_bad_operands_are_refused(op, operands, what):
    b = nodes.Builder()
    for _ in range(5):
        b.register()
    b.emit(op, *operands)
    with pytest.raises(ValueError, match=what):
        nodes.run(b.program())
