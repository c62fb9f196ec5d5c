"""The Attribute node (render/nodes.py Builder.attribute): the points' own attributes read by a
node program, as Cycles' Attribute node gives them (Color, Vector, Fac), and carried by a
splat cloud into a render, blended at a hit as the point colours are."""
import numpy as np
import pytest

from splat_tracer import _core
from splat_tracer.render import nodes, scene, shading
from splat_tracer.render.camera import Camera
from splat_tracer.render.splats import SplatCloud


def _program(*reads):
    b = nodes.Builder()
    regs = [b.attribute(name, width) for name, width in reads]
    return b.program(), regs


def test_float_and_colour_attributes_as_cycles_gives_them():
    prog, [(f_col, f_fac), (c_col, c_fac)] = _program(("intensity", 1), ("tint", 3))
    r = nodes.run(prog, 2, attributes={"intensity": [0.25, 0.75], "tint": [[0.9, 0.3, 0.0], [0.0, 0.6, 0.3]]})
    # A float fills Color/Vector and is its own Fac (Cycles' svm attribute node).
    np.testing.assert_allclose(r[:, f_col:f_col + 3], [[0.25] * 3, [0.75] * 3])
    np.testing.assert_allclose(r[:, f_fac], [0.25, 0.75])
    # A colour is its own Color; Fac is its components' average.
    np.testing.assert_allclose(r[:, c_col:c_col + 3], [[0.9, 0.3, 0.0], [0.0, 0.6, 0.3]], rtol=1e-6)
    np.testing.assert_allclose(r[:, c_fac], [0.4, 0.3], rtol=1e-6)


def test_missing_attribute_reads_zero_and_names_are_not_mixed_up():
    prog, [(col, fac), (col2, fac2)] = _program(("classification", 1), ("intensity", 1))
    r = nodes.run(prog, 1, attributes={"intensity": [0.5]})
    assert r[0, fac] == 0.0 and np.all(r[0, col:col + 3] == 0.0)  # missing: 0, as in Cycles
    assert r[0, fac2] == pytest.approx(0.5)
    r = nodes.run(prog, 1)  # no attributes at all
    assert r[0, fac] == 0.0 and r[0, fac2] == 0.0


def test_attribute_instruction_is_validated():
    b = nodes.Builder()
    out, fac = b.register(width=3), b.register()
    b.emit("ATTRIBUTE", out, fac, 0, 2)  # width 2 is neither a float nor a vector
    with pytest.raises(ValueError, match="attribute width"):
        nodes.run(b.program())
    b = nodes.Builder()
    out, fac = b.register(width=3), b.register()
    b.emit("ATTRIBUTE", out, fac, 0, 1)  # mapped below past the column bound
    b.attributes.append(("x", 1))
    prog = b.program()
    code, data, outputs, images = prog.native(attribute_columns={"x": nodes.MAX_POINT_ATTRIBUTES + 1})
    with pytest.raises(ValueError, match="out of range"):
        _core.run_nodes(code, data, outputs, images, np.zeros((1, 42), np.float32), np.zeros((1, len(data)), np.float32))


def test_layout_is_shared_and_bounded():
    p1, _ = _program(("intensity", 1), ("tint", 3))
    p2, _ = _program(("classification", 1), ("intensity", 1))
    layout = nodes.attribute_layout([p1, None, p2])
    assert layout == (("classification", 1), ("intensity", 1), ("tint", 3))
    assert nodes.columns_of(layout) == {"classification": 0, "intensity": 1, "tint": 2}
    # Past the limit the last names (by name) are left out: they read 0, never another's values.
    too_many, regs = _program(*[(f"c{i}", 3) for i in range(nodes.MAX_POINT_ATTRIBUTES // 3 + 1)])
    kept = nodes.attribute_layout([too_many])
    assert [n for n, _ in kept] == [f"c{i}" for i in range(nodes.MAX_POINT_ATTRIBUTES // 3)]
    values = {f"c{i}": np.full((1, 3), i + 1.0) for i in range(len(regs))}
    code, data, outputs, images = too_many.native(attribute_columns=nodes.columns_of(kept))
    out = np.zeros((1, len(data)), np.float32)
    _core.run_nodes(code, data, outputs, images, np.zeros((1, 42), np.float32), out,
                    nodes.attribute_columns(kept, values, 1))
    assert [out[0, fac] for _, fac in regs] == [1, 2, 3, 4, 0][:len(regs)]


def _grid_cloud(intensity, layout, n=48, name="intensity"):
    """A flat square of splats on z = 0, -1..1, whose attribute `name` is intensity(x)."""
    xs = (np.arange(n) + 0.5) / n * 2 - 1
    x, y = np.meshgrid(xs, xs)
    c = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], 1)
    values = {name: intensity(c[:, 0])}
    return SplatCloud(c, np.tile([0, 0, 1.0], (len(c), 1)), np.full(len(c), 1.5 * 2 / n),
                      attributes=nodes.attribute_columns(layout, values, len(c)), attribute_layout=layout)


def _render_emission(prog, cloud):
    material = shading.Material(base_colour=(0, 0, 0), program=prog)
    rs = scene.RenderScene([scene.Instance(cloud, materials=(material,))], world=shading.World(colour=(0, 0, 0)))
    cam = Camera.look_at((0, 0, 2), (0, 0, 0), up=(0, 1, 0), fov_y=40, aspect=1, ortho_height=2.0)
    return rs.render(cam, 32, 32, shading.RenderSettings(samples=1, max_bounces=0)).passes["Combined"][..., :3]


def test_cloud_attribute_drives_emission_in_a_render():
    b = nodes.Builder()
    col, _ = b.attribute("intensity", 1)
    b.output("emission", col)
    prog = b.program()
    layout = nodes.attribute_layout([prog])
    img = _render_emission(prog, _grid_cloud(lambda x: np.where(x < 0, 0.2, 0.8), layout))
    # Left half 0.2, right half 0.8 (the image's columns run along +x); blended across the seam.
    assert img[8:24, 2:12].mean() == pytest.approx(0.2, abs=1e-3)
    assert img[8:24, 20:30].mean() == pytest.approx(0.8, abs=1e-3)
    # A smooth ramp is blended, not stepped per splat: the middle reads about its own x.
    ramp = _render_emission(prog, _grid_cloud(lambda x: 0.5 + 0.4 * x, layout))
    row = ramp[16, :, 0]
    assert np.all(np.diff(row[4:28]) > 0)
    assert row[16] == pytest.approx(0.5, abs=0.05)


def test_cloud_without_the_attribute_reads_zero_and_wrong_layout_is_refused():
    b = nodes.Builder()
    col, _ = b.attribute("intensity", 1)
    b.output("emission", col)
    prog = b.program()
    layout = (("intensity", 1),)
    assert _render_emission(prog, _grid_cloud(lambda x: x * 0 + 0.7, layout)).mean() == pytest.approx(0.7, abs=1e-3)
    # The cloud has a `classification` but no `intensity`: 0, as Cycles reads a missing one.
    lacking = _grid_cloud(lambda x: x * 0 + 0.7, layout, name="classification")
    assert _render_emission(prog, lacking).max() == 0.0
    bare = SplatCloud(np.array([[0, 0, 0.0]]), np.array([[0, 0, 1.0]]), np.array([2.0]))
    assert _render_emission(prog, bare).max() == 0.0
    wrong = _grid_cloud(lambda x: x * 0 + 0.7, (("intensity", 1), ("tint", 3)))
    with pytest.raises(ValueError, match="carries the attributes"):
        _render_emission(prog, wrong)


def test_mesh_corner_attribute_is_interpolated_over_the_triangles():
    """A floor whose `intensity` is 0.2 at its x = -1 corners and 0.8 at x = 1: read across it
    as the linear blend Cycles interpolates (0.5 in the middle)."""
    b = nodes.Builder()
    col, _ = b.attribute("intensity", 1)
    b.output("emission", col)
    prog = b.program()
    layout = nodes.attribute_layout([prog])
    v = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float32)
    t = np.array([[0, 1, 2], [0, 2, 3]])
    per_vertex = np.where(v[:, 0] < 0, 0.2, 0.8)
    corners = nodes.attribute_columns(layout, {"intensity": per_vertex[t].ravel()}, t.size).reshape(len(t), 3, -1)
    floor = scene.Mesh(v, t, corner_attributes=corners, attribute_layout=layout)
    material = shading.Material(base_colour=(0, 0, 0), program=prog)
    rs = scene.RenderScene([scene.Instance(floor, materials=(material,))], world=shading.World(colour=(0, 0, 0)))
    cam = Camera.look_at((0, 0, 2), (0, 0, 0), up=(0, 1, 0), fov_y=40, aspect=1, ortho_height=2.0)
    img = rs.render(cam, 32, 32, shading.RenderSettings(samples=1, max_bounces=0)).passes["Combined"][..., 0]
    x = (np.arange(32) + 0.5) / 32 * 2 - 1  # pixel centres across the floor
    np.testing.assert_allclose(img[16], 0.5 + 0.3 * x, atol=0.02)
    bad = corners.copy()
    bad[0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="not finite"):
        scene.Mesh(v, t, corner_attributes=bad, attribute_layout=layout)
