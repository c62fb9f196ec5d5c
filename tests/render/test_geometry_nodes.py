"""Geometry-derived node inputs (issue 24): the values Cycles derives from a mesh at export
(render/mesh_attributes.py) and the TANGENT instruction, against values computed here
independently (closed forms, numpy written from Cycles' definitions, the core's own hash)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from splat_tracer.render import mesh_attributes, nodes


def test_the_island_hash_is_the_cores_white_noise_hash():
    # 1-D White Noise is Blender's hash_uint of the float's bits over 0xFFFFFFFF: the same
    # lookup3 as Cycles' hash_uint_to_float, here from the native core.
    w = np.linspace(-3.0, 7.0, 101).astype(np.float32)
    b = nodes.Builder()
    vector, value, colour = b.register(width=3), b.register(), b.register(width=3)
    b.emit("GLOBAL", vector, nodes.GLOBALS.index("POSITION"))
    b.emit("WHITE_NOISE", value, colour, vector, 1)
    native = nodes.run(b.program(), len(w), P=np.stack([w, 0 * w, 0 * w], 1))[:, value]
    np.testing.assert_array_equal(mesh_attributes.hash_uint_to_float(w.view(np.uint32)), native)


def test_island_roots_follow_union_by_rank_in_edge_order():
    # join(0,1): 1 under 0; join(2,3): 3 under 2; join(1,3): equal ranks, 0's root kept.
    np.testing.assert_array_equal(mesh_attributes.island_roots(5, [(0, 1), (2, 3), (1, 3)]), [0, 0, 0, 0, 4])
    # On a tie the first vertex of the edge is the root; a higher rank wins over order.
    np.testing.assert_array_equal(mesh_attributes.island_roots(2, [(1, 0)]), [1, 1])
    np.testing.assert_array_equal(mesh_attributes.island_roots(3, [(0, 1), (2, 0)]), [0, 0, 0])
    np.testing.assert_array_equal(mesh_attributes.island_roots(4, [(2, 3), (0, 1), (1, 3)]), [0, 0, 0, 0])


def test_random_per_island_is_the_hash_of_the_first_corners_root():
    values = mesh_attributes.random_per_island(6, [(0, 1), (1, 2), (4, 3), (3, 5)], [2, 0, 5, 3])
    expected = mesh_attributes.hash_uint_to_float(np.array([0, 0, 4, 4]))
    np.testing.assert_array_equal(values, expected)
    assert values[0] != values[2]


def _cube(split: bool):
    corners = np.array([(x, y, z) for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    edges = [(i, j) for i in range(8) for j in range(i + 1, 8) if np.abs(corners[i] - corners[j]).sum() == 2]
    normals = corners / math.sqrt(3)
    if not split:
        return corners, normals, edges
    # Every corner three times (one per face, as a mesh with split normals leaves them),
    # the face normals on the copies, the edges spread over the copies.
    positions = np.repeat(corners, 3, axis=0)
    axes = np.tile(np.eye(3), (8, 1)) * np.sign(positions)
    edges = [(3 * i + k % 3, 3 * j + (k + 1) % 3) for k, (i, j) in enumerate(edges)]
    return positions, axes, edges


@pytest.mark.parametrize("split", [False, True])
def test_pointiness_of_a_cube_corner(split):
    # Normal along the diagonal, three unit edges along -x, -y, -z: acos(-1/sqrt(3)) / pi at
    # every corner, which the blur (all corners alike) keeps; split copies are welded.
    positions, normals, edges = _cube(split)
    p = mesh_attributes.pointiness(positions, normals, edges)
    np.testing.assert_allclose(p, math.acos(-1 / math.sqrt(3)) / math.pi, rtol=1e-6)


def test_pointiness_of_a_flat_grid_is_a_half_and_a_bump_blurs_over_its_ring():
    n = 5
    xs, ys = np.meshgrid(np.arange(n, dtype=float), np.arange(n, dtype=float))
    positions = np.stack([xs.ravel(), ys.ravel(), 0 * xs.ravel()], 1)
    index = lambda i, j: i * n + j  # noqa: E731
    edges = [(index(i, j), index(i, j + 1)) for i in range(n) for j in range(n - 1)] + \
            [(index(i, j), index(i + 1, j)) for i in range(n - 1) for j in range(n)]
    normals = np.tile([0.0, 0.0, 1.0], (n * n, 1))
    p = mesh_attributes.pointiness(positions, normals, edges)
    inner = [index(i, j) for i in range(1, n - 1) for j in range(1, n - 1)]
    np.testing.assert_allclose(p[inner], 0.5, atol=1e-7)
    # The centre raised by h: its four edges tilt down, raw acos(-h / sqrt(1 + h^2)) / pi;
    # each neighbour's one tilted edge lowers its raw value; the blur averages the ring.
    h = 0.5
    positions[index(2, 2), 2] = h
    p = mesh_attributes.pointiness(positions, normals, edges)
    raw_centre = math.acos(-h / math.sqrt(1 + h * h)) / math.pi
    raw_side = math.acos(0.25 * h / math.sqrt(1 + h * h)) / math.pi  # one of four edges rises by h
    np.testing.assert_allclose(p[index(2, 2)], (raw_centre + 4 * raw_side) / 5, rtol=1e-6)


def _tangent_program(kind):
    b = nodes.Builder()
    out = b.register(width=3)
    b.emit("TANGENT", out, nodes.TANGENT_KINDS.index(kind))
    return b.program(), out


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_radial_tangent_is_perpendicular_to_the_normal_around_the_axis(axis):
    rng = np.random.default_rng(axis)
    generated = rng.uniform(0, 1, (200, 3)).astype(np.float32)
    normal = rng.normal(size=(200, 3))
    normal = (normal / np.linalg.norm(normal, axis=1, keepdims=True)).astype(np.float32)
    program, out = _tangent_program("RADIAL_" + "XYZ"[axis])
    t = nodes.run(program, 200, generated=generated, N=normal)[:, out:out + 3]
    # Cycles' svm_node_tangent: X (0, -z, y), Y (-z, 0, x), Z (-y, x, 0) of g - 1/2 (Y is
    # not the cross product's sign), then N x normalize(t x N).
    gx, gy, gz = (generated.astype(float) - 0.5).T
    zero = 0 * gx
    raw = np.stack([(zero, -gz, gy), (-gz, zero, gx), (-gy, gx, zero)][axis], 1)

    def project(raw):
        side = np.cross(raw, normal)
        return np.cross(normal, side / np.linalg.norm(side, axis=1, keepdims=True))

    np.testing.assert_allclose(t, project(raw), atol=2e-6)
    assert np.abs(t - project(-raw)).max() > 1.0, "the opposite sense must fail"


def test_uv_map_tangent_is_the_shading_points_and_zero_without_one():
    program, out = _tangent_program("UV_MAP")
    t = nodes.run(program, 2, tangent=np.array([[0.6, 0.8, 0.0], [0.0, 0.0, 0.0]], np.float32))[:, out:out + 3]
    np.testing.assert_allclose(t, [[0.6, 0.8, 0.0], [0.0, 0.0, 0.0]])


def test_parametric_off_meshes_is_cycles_on_its_points():
    # The barycentrics come from a mesh hit (render_scene.cpp); a shading point without one
    # (a splat) reads (1, 0, 0), Cycles' on a point (u = v = 0): test_geometry_inputs.py.
    b = nodes.Builder()
    out = b.global_("PARAMETRIC")
    np.testing.assert_array_equal(nodes.run(b.program(), 1)[:, out:out + 3], [[1, 0, 0]])


def test_uv_tangents_point_along_increasing_u():
    corners = np.array([[[0, 0, 0], [2, 0, 0], [0, 3, 0]]] * 3, float)
    uvs = np.array([[[0, 0], [1, 0], [0, 1]],     # u along x
                    [[0, 0], [0, 1], [1, 0]],     # u along y (mirrored map)
                    [[0, 0], [0, 0], [0, 0]]], float)  # degenerate: 0
    np.testing.assert_allclose(mesh_attributes.uv_tangents(corners, uvs), [[1, 0, 0], [0, 1, 0], [0, 0, 0]])


def test_an_object_space_tangent_is_taken_as_a_normal_and_made_perpendicular():
    b = nodes.Builder()
    given = b.register((1.0, 0.0, 1.0), 3)
    out = b.register(width=3)
    b.emit("TANGENT", out, nodes.TANGENT_KINDS.index("OBJECT_VECTOR"), given)
    t = nodes.run(b.program(), 1, N=[0.0, 0.0, 1.0])[0, out:out + 3]
    np.testing.assert_allclose(t, [1, 0, 0], atol=1e-6)
