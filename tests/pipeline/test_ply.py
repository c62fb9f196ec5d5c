"""PLY reading (no Blender): formats, optional properties, malformed files."""
from __future__ import annotations

import numpy as np
import pytest

from geometry import cube_cloud, fibonacci_sphere, random_sphere
from splat_tracer.pointcloud import readers, spacing
from splat_tracer.pointcloud.cloud import CloudFileError, srgb_to_linear
from splat_tracer.pointcloud.neighbours import first_of_duplicates
from splat_tracer.pointcloud.readers import ply


@pytest.mark.parametrize("binary, order", [(False, "="), (True, "<"), (True, ">")])
def test_formats_round_trip(tmp_path, binary, order):
    p, n = fibonacci_sphere(300, radius=2.0, centre=(1e6, -3e5, 12.0))
    colours = np.random.default_rng(0).uniform(size=(300, 3))
    radii = np.linspace(0.01, 0.02, 300)
    path = tmp_path / "cloud.ply"
    ply.write_ply(str(path), p, n, colours=colours, radii=radii, binary=binary, byte_order=order)
    cloud = ply.read_ply(str(path))
    np.testing.assert_array_equal(cloud.positions, p)  # x y z written as double: exact
    np.testing.assert_allclose(cloud.normals, n, atol=1e-6)
    np.testing.assert_allclose(cloud.radii, radii, rtol=1e-6)
    np.testing.assert_allclose(cloud.colours[:, :3], colours, atol=0.01)  # 8-bit sRGB steps
    np.testing.assert_array_equal(cloud.colours[:, 3], 1.0)


def test_float_normals_of_any_length_and_bad_normals_dropped(tmp_path):
    path = tmp_path / "n.ply"
    path.write_text("ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
                    "property float z\nproperty float nx\nproperty float ny\nproperty float nz\n"
                    "property uchar red\nproperty uchar green\nproperty uchar blue\nproperty uchar alpha\n"
                    "end_header\n0 0 0 0 0 3 255 0 0 128\n1 0 0 0 0 0 0 255 0 255\n"
                    "2 0 0 nan 0 1 0 0 255 255\n3 0 0 1 0 0 255 255 255 0\n")
    cloud = ply.read_ply(str(path))
    assert cloud.dropped_normals == 2 and len(cloud) == 2
    np.testing.assert_array_equal(cloud.positions[:, 0], [0, 3])
    np.testing.assert_allclose(cloud.normals, [[0, 0, 1], [1, 0, 0]])
    np.testing.assert_allclose(cloud.colours[0], [1, 0, 0, 128 / 255], atol=1e-6)
    np.testing.assert_allclose(cloud.colours[1], [1, 1, 1, 0], atol=1e-6)


def test_float32_normals_near_the_ends_of_float32s_range_become_unit(tmp_path):
    """Found by fuzz_ply: a denormal float32 normal (1e-40) has a reciprocal length of 1e40,
    beyond float32, and came out as inf/NaN instead of unit length."""
    n = np.array([[1e-40, 0, 0], [0, 3e-45, 0], [2e-39, 2e-39, 0], [3e38, 3e38, 3e38],
                  [0, 0, -1e-20], [0, 0.6, 0.8]], np.float32)
    p = np.arange(len(n) * 3, dtype=np.float64).reshape(-1, 3)
    path = str(tmp_path / "tiny.ply")
    ply.write_ply(path, p, n)
    cloud = ply.read_ply(path)
    assert len(cloud) == len(n) and cloud.dropped_normals == 0
    expected = n.astype(np.float64) / np.linalg.norm(n.astype(np.float64), axis=1)[:, None]
    np.testing.assert_allclose(cloud.normals, expected, atol=1e-6)


def test_srgb_to_linear_reference_values():
    np.testing.assert_allclose(srgb_to_linear(np.array([0.0, 0.04045, 0.5, 1.0])),
                               [0.0, 0.04045 / 12.92, 0.21404, 1.0], rtol=1e-4)


@pytest.mark.parametrize("body, message", [
    ("element face 0\nproperty list uchar int vertex_indices\nend_header\n", "no 'vertex' element"),
    ("element vertex 0\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\n"
     "property float ny\nproperty float nz\nend_header\n", "contains no vertices"),
    ("element vertex 1\nproperty float x\nproperty float y\nproperty float nx\nproperty float ny\n"
     "property float nz\nend_header\n0 0 0 0 1\n", "lack the coordinate(s) z"),
    ("element vertex 1\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\n"
     "property float ny\nproperty float nz\nproperty float radius\nend_header\n0 0 0 0 0 1 -2\n", "radius"),
    ("element vertex 1\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\n"
     "property float ny\nproperty float nz\nend_header\n0 0 0 0 0 0\n", "no vertex has a usable normal"),
])
def test_meaningless_files_are_refused_with_the_file_named(tmp_path, body, message):
    path = tmp_path / "bad.ply"
    path.write_text("ply\nformat ascii 1.0\n" + body)
    with pytest.raises(CloudFileError) as err:
        ply.read_ply(str(path))
    assert str(path) in str(err.value) and message in str(err.value)


@pytest.mark.parametrize("binary", [False, True])
@pytest.mark.parametrize("listed, items", [("x", 2), ("z", 1), ("nx", 3), ("red", 1), ("radius", 0), ("opacity", 1)])
def test_list_typed_vertex_properties_are_refused_naming_the_property(tmp_path, binary, listed, items):
    """`property list uchar float x` (numpy's 'setting an array element with a sequence'
    escaped as a bare ValueError, or a one-item list was read as if a number): a property a
    splat is read from is refused when it is a list, of any length."""
    from plyfile import PlyData, PlyElement

    names = ["x", "y", "z", "nx", "ny", "nz"] + (["red", "green", "blue"] if listed == "red" else [])
    names += ["radius"] if listed == "radius" else []
    names += ["f_dc_0", "f_dc_1", "f_dc_2", "opacity", "rot_0", "rot_1", "rot_2", "rot_3", "scale_0", "scale_1",
              "scale_2"] if listed == "opacity" else []
    fields = [(c, "O" if c == listed else ("u1" if c in ("red", "green", "blue") else "f4")) for c in names]
    rows = np.zeros(4, dtype=fields)
    for c in names:
        if c != listed:
            rows[c] = 1
    for i in range(4):
        rows[listed][i] = np.full(items, 1.0 + i, "f4")
    element = PlyElement.describe(rows, "vertex", val_types={listed: "f4"} if listed != "red" else {listed: "u1"})
    path = tmp_path / "listed.ply"
    PlyData([element], text=not binary).write(str(path))
    with pytest.raises(CloudFileError, match=f"the vertex property '{listed}' is a list") as err:
        readers.read_cloud(str(path))
    assert str(path) in str(err.value) and "property list uchar" in str(err.value)


def test_missing_file(tmp_path):
    with pytest.raises(CloudFileError, match="no such file"):
        ply.read_ply(str(tmp_path / "nope.ply"))


def test_knn_spacing_on_a_grid_and_with_duplicates():
    grid = np.stack(np.meshgrid(np.arange(20), np.arange(20)), -1).reshape(-1, 2).astype(float)
    pts = np.column_stack([grid, np.zeros(len(grid))])
    s, degenerate = spacing.knn_spacing(pts, k=4)
    inner = (grid > 0).all(1) & (grid < 19).all(1)
    np.testing.assert_allclose(s[inner], 1.0)  # 4 neighbours at distance 1
    dup = np.concatenate([pts, np.repeat(pts[:1], 10, axis=0)])
    s, degenerate = spacing.knn_spacing(dup, k=4)
    assert degenerate == 11 and (s > 0).all()
    with pytest.raises(spacing.SpacingError):
        spacing.knn_spacing(pts[:1])
    with pytest.raises(spacing.SpacingError, match="coincide"):
        spacing.knn_spacing(np.zeros((10, 3)))


@pytest.mark.parametrize("name, make, closed", [
    ("randomly sampled sphere", lambda: random_sphere(30000), True),
    ("even sphere", lambda: fibonacci_sphere(20000), True),
    ("cube with duplicated edge points", lambda: cube_cloud(20, on_edges=True), True),
    ("dome (open hemisphere)", lambda: tuple(a[fibonacci_sphere(20000)[0][:, 2] > 0] for a in fibonacci_sphere(20000)),
     False),
    ("sphere with a hole", lambda: tuple(a[fibonacci_sphere(20000)[0][:, 2] < 0.9] for a in fibonacci_sphere(20000)),
     False),
    ("flat patch", lambda: (np.column_stack([np.random.default_rng(1).uniform(-1, 1, (20000, 2)), np.zeros(20000)]),
                            np.tile([0.0, 0.0, 1.0], (20000, 1))), False),
])
def test_closed_guess(name, make, closed):
    points, normals = make()
    hood = spacing.analyse(points, normals)
    assert hood.closed_guess is closed, (name, hood.describe())


def _insert_header_lines(path, lines: list[str]) -> None:
    """Inserts lines (e.g. comments) after the 'format' line of a PLY file's header."""
    data = path.read_bytes()
    at = data.index(b"\n", data.index(b"format")) + 1
    path.write_bytes(data[:at] + "".join(line + "\n" for line in lines).encode() + data[at:])


@pytest.mark.parametrize("binary", [False, True])
@pytest.mark.parametrize("extra", [
    ["comment end_header is the last line of a header"],
    [f"comment scanner metadata line {i:05d} " + "x" * 60 for i in range(2000)],  # 150 KB
], ids=["comment_says_end_header", "header_over_64k"])
def test_header_ends_at_the_first_line_that_is_exactly_end_header(tmp_path, binary, extra):
    """A long header (scanner metadata) and a comment that mentions end_header are fine."""
    p, n = fibonacci_sphere(100)
    path = tmp_path / "header.ply"
    ply.write_ply(str(path), p, n, binary=binary)
    _insert_header_lines(path, extra)
    cloud = ply.read_ply(str(path))
    np.testing.assert_array_equal(cloud.positions, p)


def test_header_beyond_the_limit_is_refused_with_a_clear_message(tmp_path):
    p, n = fibonacci_sphere(100)
    path = tmp_path / "huge_header.ply"
    ply.write_ply(str(path), p, n)
    line = "comment " + "x" * 120
    _insert_header_lines(path, [line] * (ply.MAX_HEADER_BYTES // len(line) + 10))
    with pytest.raises(CloudFileError, match=r"header.*longer than") as err:
        ply.read_ply(str(path))
    assert str(path) in str(err.value)


@pytest.mark.parametrize("binary", [False, True])
@pytest.mark.parametrize("element", ["face", "vertex"])
def test_a_count_the_file_cannot_hold_is_refused_before_reading(tmp_path, binary, element):
    """A tiny file declaring 1e9 rows took 72 s and 8 GB before plyfile gave up: the
    declared counts are compared with the file's size first."""
    import time

    p, n = fibonacci_sphere(100)
    path = tmp_path / "lying.ply"
    ply.write_ply(str(path), p, n, binary=binary)
    data = path.read_bytes()
    if element == "vertex":
        data = data.replace(b"element vertex 100\n", b"element vertex 1000000000\n")
    else:
        data = data.replace(b"end_header\n", b"element face 1000000000\n"
                            b"property list uchar int vertex_indices\nend_header\n")
    path.write_bytes(data)
    start = time.perf_counter()
    with pytest.raises(CloudFileError) as err:
        ply.read_ply(str(path))
    # Before the fix: 54-72 s and 8 GB. A generous bound (the machine may be busy): only
    # the pathology is tested, not the speed, which the benchmarks measure.
    assert time.perf_counter() - start < 10.0
    message = str(err.value)
    assert str(path) in message and f"1,000,000,000 '{element}'" in message, message


def _cloud_with_faces(path, binary: bool, vertices: int = 50, faces: int = 4, vertex_list: bool = False):
    """A PLY with a vertex element and a face element (a list property), as meshes have;
    vertex_list: the vertices have a list property too (e.g. a scanner's per-point echoes)."""
    from plyfile import PlyData, PlyElement

    p, n = fibonacci_sphere(vertices)
    fields = [(c, "f4") for c in ("x", "y", "z", "nx", "ny", "nz")] + ([("echoes", "O")] if vertex_list else [])
    rows = np.empty(vertices, dtype=fields)
    for k, c in enumerate("xyz"):
        rows[c], rows["n" + c] = p[:, k], n[:, k]
    if vertex_list:
        rows["echoes"] = [np.arange(i % 3 + 1, dtype=np.float32) for i in range(vertices)]
    elements = [PlyElement.describe(rows, "vertex")]
    if faces:
        face = np.empty(faces, dtype=[("vertex_indices", "O")])
        face["vertex_indices"] = [np.array([i, i + 1, i + 2], np.int32) for i in range(faces)]
        elements.append(PlyElement.describe(face, "face"))
    PlyData(elements, text=not binary).write(str(path))
    return p


@pytest.mark.parametrize("binary", [False, True])
@pytest.mark.parametrize("layout", [dict(faces=4), dict(faces=0, vertex_list=True), dict(faces=4, vertex_list=True)],
                         ids=["faces", "vertex_list", "vertex_list_and_faces"])
@pytest.mark.parametrize("change", ["vertex 50->40", "face 4->2", "vertex 50->49", "none"])
def test_data_must_match_every_declared_count_with_list_properties(tmp_path, binary, layout, change):
    """With faces (a list property) after the vertices, a vertex count smaller than the
    data imported the first vertices silently; now every element's data must end where
    the next begins and the last one at the end of the file."""
    path = tmp_path / "mesh.ply"
    p = _cloud_with_faces(path, binary, **layout)
    if change == "none" or (change.startswith("face") and not layout["faces"]):
        np.testing.assert_allclose(ply.read_ply(str(path)).positions, p, atol=1e-6)
        return
    element, counts = change.split()
    old, new = counts.split("->")
    data = path.read_bytes()
    path.write_bytes(data.replace(f"element {element} {old}\n".encode(), f"element {element} {new}\n".encode(), 1))
    with pytest.raises(CloudFileError) as err:
        ply.read_ply(str(path))
    assert str(path) in str(err.value)


def test_trailing_blank_lines_after_ascii_data_are_fine(tmp_path):
    path = tmp_path / "blank.ply"
    p = _cloud_with_faces(path, binary=False)
    path.write_bytes(path.read_bytes() + b"\n  \n\n")
    np.testing.assert_allclose(ply.read_ply(str(path)).positions, p, atol=1e-6)


def _coloured_cloud(path, dtype, rgb, alpha=None, binary=True):
    """Three points with colour properties of the given type (and alpha, if given)."""
    from plyfile import PlyData, PlyElement

    fields = [(c, "f4") for c in ("x", "y", "z", "nx", "ny", "nz")] + [(c, dtype) for c in ("red", "green", "blue")]
    if alpha is not None:
        fields.append(("alpha", dtype))
    rows = np.zeros(len(rgb), dtype=fields)
    rows["x"], rows["nz"] = np.arange(len(rgb)), 1.0
    for k, c in enumerate(("red", "green", "blue")):
        rows[c] = np.asarray(rgb)[:, k]
    if alpha is not None:
        rows["alpha"] = alpha
    PlyData([PlyElement.describe(rows, "vertex")], text=not binary).write(str(path))


BYTE_RGB = [[255, 0, 0], [0, 128, 0], [10, 20, 255]]   # 0..255 values
BYTE_ALPHA = [255, 128, 0]


@pytest.mark.parametrize("dtype, scale", [
    ("u1", "0..255"), ("i1", "0..127"), ("i2", "0..255"), ("i4", "0..255"), ("u4", "0..255"),
    ("f4", "0..255"), ("f8", "0..255"), ("f4", "0..1"), ("f8", "0..1"),
    ("u2", "0..65535"), ("i4", "0..65535"), ("u4", "0..65535"), ("f4", "0..65535"),
], ids=lambda v: str(v))
def test_colour_types_are_read_by_type_and_range(tmp_path, dtype, scale):
    """uchar is /255 and ushort /65535 by type; every other type by its values: floats in
    0..1 as they are, anything within 0..255 /255, within 0..65535 /65535. Alpha alike."""
    rgb, alpha = np.array(BYTE_RGB, float) / 255, np.array(BYTE_ALPHA, float) / 255  # what is meant
    if scale == "0..127":  # int8 holds 0..127 only: values that are read /255
        rgb, alpha = np.floor(rgb * 127.5) / 255, np.floor(alpha * 127.5) / 255
    factor = {"0..1": 1, "0..127": 255, "0..255": 255, "0..65535": 65535}[scale]
    path = tmp_path / "colours.ply"
    stored = (lambda v: np.round(v * factor)) if factor > 1 else (lambda v: v)
    _coloured_cloud(path, dtype, stored(rgb), stored(alpha))
    cloud = ply.read_ply(str(path))
    np.testing.assert_allclose(cloud.colours[:, :3], srgb_to_linear(rgb), atol=1e-6)
    np.testing.assert_allclose(cloud.colours[:, 3], alpha, atol=1e-6)


@pytest.mark.parametrize("dtype, rgb, alpha, bad", [
    ("i4", [[0, 0, 0], [70000, 1, 2], [3, 4, 5]], None, "'red'"),
    ("i2", [[0, 0, 0], [1, -3, 2], [3, 4, 5]], None, "'green'"),
    ("f4", [[0, 0, 0], [0.5, 0.2, 1e6], [0.1, 0.1, 0.1]], None, "'blue'"),
    ("i4", BYTE_RGB, [255, 128, 100000], "'alpha'"),
])
def test_colours_outside_every_known_range_are_refused(tmp_path, dtype, rgb, alpha, bad):
    path = tmp_path / "colours.ply"
    _coloured_cloud(path, dtype, rgb, alpha)
    with pytest.raises(CloudFileError) as err:
        ply.read_ply(str(path))
    assert str(path) in str(err.value) and bad in str(err.value), str(err.value)


def test_exact_duplicates_are_merged_keeping_the_first(tmp_path):
    p, n = fibonacci_sphere(300)
    colours = np.random.default_rng(2).uniform(size=(300, 3))
    dup = np.array([5, 17, 17, 250])  # row 17 three times in all
    p2 = np.concatenate([p, p[dup]])
    n2 = np.concatenate([n, -n[dup]])  # the copies differ in all but their position
    path = tmp_path / "dups.ply"
    ply.write_ply(str(path), p2, n2, colours=np.concatenate([colours, 1 - colours[dup]]))
    cloud = ply.read_ply(str(path))
    assert len(cloud) == 300 and cloud.merged_duplicates == 4 and cloud.first_duplicate_row == 300
    np.testing.assert_array_equal(cloud.positions, p)
    np.testing.assert_allclose(cloud.normals, n, atol=1e-6)  # the first row's attributes
    np.testing.assert_allclose(cloud.colours[:, :3], colours, atol=0.01)
    np.testing.assert_array_equal(cloud.rows, np.arange(300))


def test_negative_zero_is_the_same_position():
    keep = first_of_duplicates(np.array([[0.0, 1.0, 2.0], [-0.0, 1.0, 2.0], [0.0, 1.0, 2.5]]))
    np.testing.assert_array_equal(keep, [True, False, True])


def test_rows_with_nan_equal_no_row():
    # The readers drop non-finite rows first; the duplicate search still takes them (the
    # fuzz harness passes them), a NaN row kept as its own, an infinite one like any value.
    keep = first_of_duplicates(np.array([[np.nan, 1.0, 2.0], [np.nan, 1.0, 2.0], [np.inf, 0.0, 0.0],
                                                    [np.inf, 0.0, -0.0]]))
    np.testing.assert_array_equal(keep, [True, True, True, False])


def test_first_of_duplicates_on_many_points_is_fast():
    import time

    rng = np.random.default_rng(3)
    p = rng.normal(size=(1_000_006, 3)) * 1000 + 4e6  # a multiple of 7 rows
    p[::7] = p[1::7]  # every 7th row repeats the next one
    start = time.perf_counter()
    keep = first_of_duplicates(p)
    # About 0.015 s (0.3 s with the numpy version before the native one); a quadratic pass
    # over a million rows would take hours. The bound only catches that, with room for a
    # busy machine.
    assert time.perf_counter() - start < 15.0
    assert (~keep).sum() == len(p[::7]) and keep[::7].all() and not keep[1::7].any()  # the later copy goes


def _utm_sphere(tmp_path, stray: bool, n_points: int = 3000):
    """A sphere of radius 1 m at UTM-like coordinates; stray: a scanner's invalid return at
    (0, 0, 0) written after the 1000th point."""
    p, n = fibonacci_sphere(n_points, radius=1.0, centre=(5e5, 4e6, 100.0))
    if stray:
        p = np.concatenate([p[:1000], [[0.0, 0.0, 0.0]], p[1000:]])
        n = np.concatenate([n[:1000], [[0.0, 0.0, 1.0]], n[1000:]])
    path = tmp_path / f"utm_{'stray' if stray else 'clean'}.ply"
    ply.write_ply(str(path), p, n)
    return path


@pytest.mark.parametrize("drop", [False, True])
def test_one_stray_point_changes_nothing_but_the_warning(tmp_path, drop):
    """Georeferenced scan with one stray (0,0,0): same origin, same radii for the sphere's
    points, same closed guess as without it; the stray point is found, reported (count and
    row), kept with a bounded radius or dropped."""
    from splat_tracer.pointcloud import prepare

    clean_path, stray_path = _utm_sphere(tmp_path, False), _utm_sphere(tmp_path, True)
    clean = prepare.prepare(ply.read_ply(str(clean_path)), str(clean_path))
    dirty = prepare.prepare(ply.read_ply(str(stray_path)), str(stray_path), drop_outliers=drop)
    assert clean.outliers == 0 and dirty.outliers == 1 and dirty.first_outlier_row == 1000
    np.testing.assert_allclose(dirty.origin, clean.origin, rtol=0, atol=np.spacing(np.float32(4e6)))
    sphere = np.arange(len(dirty.local)) != 1000 if not drop else slice(None)
    np.testing.assert_allclose(dirty.local[sphere] + dirty.origin, clean.local + clean.origin, atol=1e-6)
    np.testing.assert_allclose(dirty.radii[sphere], clean.radii, rtol=1e-5)
    assert dirty.hood.closed_guess is clean.hood.closed_guess is True
    assert dirty.hood.boundary == clean.hood.boundary
    notes = "\n".join(dirty.notes(6))
    assert "1 point lies far from the rest" in notes and "row 1000" in notes, notes
    if drop:
        assert len(dirty.local) == 3000 and "dropped" in notes
    else:
        assert len(dirty.local) == 3001
        assert dirty.radii[1000] <= 3 * np.percentile(clean.radii, 95) * (1 + 1e-6)  # not a 4e6 m disc
        assert dirty.clamped_radii >= 1 and "radii were reduced" in notes


def test_genuine_sparse_parts_are_not_outliers():
    """A scan's thinning tail (points farther out, fewer of them) stays in the bulk."""
    from splat_tracer.pointcloud import prepare

    rng = np.random.default_rng(4)
    r = np.exp(rng.uniform(0, np.log(100), 50000))  # ranges 1..100 m, log-uniform as a scanner sees them
    d = rng.normal(size=(50000, 3))
    d[:, 2] = np.abs(d[:, 2]) * 0.1
    p = d / np.linalg.norm(d, axis=1, keepdims=True) * r[:, None]
    assert prepare.bulk_mask(p).all()
    p[7] = [1e4, 0, 0]
    assert np.flatnonzero(~prepare.bulk_mask(p)).tolist() == [7]


@pytest.mark.parametrize("case", ["two clusters at +-2.5e38", "all near 1e300", "one point at 1e20"])
def test_clouds_beyond_safe_float32_offsets_are_refused(tmp_path, case):
    """Double coordinates near the top of float32's range imported and later crashed the
    renderer, which squares distances in float32."""
    from splat_tracer.pointcloud import prepare

    p, n = fibonacci_sphere(400)
    if case == "two clusters at +-2.5e38":
        p = np.concatenate([p[:200] + 2.5e38, p[200:] - 2.5e38])
    elif case == "all near 1e300":
        p = p * 1e290 + 1e300
    else:
        p = np.concatenate([p + [5e5, 4e6, 100.0], [[1e20, 0.0, 0.0]]])
        n = np.concatenate([n, [[0.0, 0.0, 1.0]]])
    path = tmp_path / "huge.ply"
    ply.write_ply(str(path), p, n)
    with pytest.raises(CloudFileError) as err:
        prepare.prepare(ply.read_ply(str(path)), str(path))
    message = str(err.value)
    assert str(path) in message and "spans" in message and "float32" in message, message
    if case == "one point at 1e20":  # the bulk alone is fine: dropping the stray point imports it
        assert "Outliers: Drop" in message
        dropped = prepare.prepare(ply.read_ply(str(path)), str(path), drop_outliers=True)
        assert len(dropped.local) == 400 and dropped.outliers == 1


@pytest.mark.parametrize("rows", [
    [[-1.7558342626051445e308, -1.7539056980694914e308, 3.6241848276995449e293], [-1.7976931348623157e308] * 3],
    [[1.7976931348623157e308, 0.0, 0.0], [-1.7976931348623157e308, 0.0, 0.0], [0.0, 1.0, 0.0]],
])
def test_coordinates_near_the_float64_limit_are_refused_not_a_numpy_error(tmp_path, rows):
    """Found by fuzz/fuzz_prepare.py: the bulk's percentiles overflowed on one axis, every
    point counted as an outlier and prepare() raised numpy's 'zero-size array' ValueError
    instead of refusing the file."""
    from splat_tracer.pointcloud import prepare

    p = np.array(rows)
    assert prepare.bulk_mask(p).all()
    path = tmp_path / "extreme.ply"
    ply.write_ply(str(path), p, np.tile([0.0, 0.0, 1.0], (len(p), 1)))
    with pytest.raises(CloudFileError, match="float32"):
        prepare.prepare(ply.read_ply(str(path)), str(path))


def test_non_ascii_bytes_after_ascii_data_are_refused_with_a_message(tmp_path):
    path = tmp_path / "junk.ply"
    _cloud_with_faces(path, binary=False, vertices=5000)  # the junk lies beyond plyfile's read-ahead
    path.write_bytes(path.read_bytes() + b"\n" * 100_000 + b"\xff\xfe junk\n")
    with pytest.raises(CloudFileError, match="follow") as err:
        ply.read_ply(str(path))
    assert str(path) in str(err.value)


def _range_scan(path, n=400, grid_first=False, ending="\n", spaces=" "):
    """An ascii PLY as Stanford's raw range scans are: vertices, then (or first) a
    'range_grid' element of lists with 0 or 1 vertex index per grid cell."""
    rng = np.random.default_rng(5)
    p = np.round(rng.uniform(-0.1, 0.1, (n, 3)), 6).astype(np.float32)
    rgb = rng.integers(0, 256, (n, 3))
    cells = 3 * n
    hit = np.zeros(cells, bool)
    hit[rng.choice(cells, n, replace=False)] = True
    grid = [f"1 {i}" if h else "0" for i, h in zip(np.cumsum(hit) - 1, hit)]
    vertices = [spaces.join(f"{v:g}" for v in row) + spaces + spaces.join(str(c) for c in colour)
                for row, colour in zip(p, rgb)]
    head = ["ply", "format ascii 1.0", "obj_info num_cols 60", "element range_grid %d" % cells,
            "property list uchar int vertex_indices", "element vertex %d" % n, "property float x", "property float y",
            "property float z", "property uchar red", "property uchar green", "property uchar blue", "end_header"]
    if not grid_first:  # vertex first, as bun000.ply
        head = head[:3] + head[5:12] + head[3:5] + head[12:]
    body = grid + vertices if grid_first else vertices + grid
    path.write_bytes(ending.join(head + body).encode() + ending.encode())
    return p, rgb


@pytest.mark.parametrize("grid_first", [False, True], ids=["grid_after", "grid_before"])
@pytest.mark.parametrize("ending, spaces", [("\n", " "), ("\r\n", "\t"), ("\r", "  ")], ids=["lf", "crlf_tab", "cr"])
def test_ascii_extra_elements_are_skipped_by_numpy_and_named(tmp_path, monkeypatch, grid_first, ending, spaces):
    """An ascii PLY's vertices are parsed by numpy, not plyfile's value-at-a-time loop, and
    the element of lists the importer does not use is only checked (a range scan: 1.46 s
    before, 0.08 s now, for 40,256 vertices and 204,800 grid rows); the notes name it."""
    from plyfile import PlyData

    path = tmp_path / "scan.ply"
    p, rgb = _range_scan(path, grid_first=grid_first, ending=ending, spaces=spaces)
    reference = ply.read_ply(str(path))
    monkeypatch.setattr(PlyData, "read", lambda *a: pytest.fail("plyfile parsed the data"))
    cloud = ply.read_ply(str(path))
    np.testing.assert_array_equal(cloud.positions, p)
    np.testing.assert_array_equal(cloud.colours, reference.colours)
    np.testing.assert_allclose(cloud.colours[:, :3], srgb_to_linear(rgb / 255.0), atol=1e-6)
    assert "elements ignored (only the vertices are points): 'range_grid' (1,200 rows)" in cloud.notes


@pytest.mark.parametrize("edit, message", [
    (lambda rows: rows.replace(" 0.", " 1.5e-1 0.", 1), "row 0: property 'red': malformed input"),  # a value more
    (lambda rows: rows.split("\n", 1)[0].rsplit(" ", 1)[0] + "\n" + rows.split("\n", 1)[1],
     "row 0: property 'blue': early end-of-line"),                                         # a value less
    (lambda rows: rows.replace("\n1 ", "\n1 2 ", 1), "'range_grid': row "),                 # a grid row too long
    (lambda rows: rows.replace("\n0\n", "\n\n", 1), "'range_grid': row "),                # a blank row
    (lambda rows: rows.replace(" 1", " one", 1), "malformed input"),                      # not a number
    (lambda rows: rows + "0\n", "1 more rows follow"),                                   # a row more
])
def test_ascii_rows_that_do_not_fit_are_refused_as_plyfile_says(tmp_path, edit, message):
    """Where numpy's parse finds a row it cannot take, plyfile reads the file and names the
    row and the problem, as it did before."""
    path = tmp_path / "scan.ply"
    _range_scan(path)
    head, _, rows = path.read_text().partition("end_header\n")
    changed = edit(rows)
    assert changed != rows
    path.write_text(head + "end_header\n" + changed)
    with pytest.raises(CloudFileError, match=message) as err:
        ply.read_ply(str(path))
    assert str(path) in str(err.value)
