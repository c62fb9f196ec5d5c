"""The import pipeline's options (axes, scale, point budget, statistical outliers), its
progress and cancel, its memory check and the bad inputs of issue 10 -- without Blender,
then through the real operator (bpy) for what must hold in Blender: nothing created on
an error or a cancel."""
from __future__ import annotations

import re
import struct
import threading

import numpy as np
import pytest

from geometry import fibonacci_sphere
from splat_tracer.pointcloud import importer, prepare, readers, spacing
from splat_tracer.pointcloud.cloud import CloudFileError, make_cloud
from splat_tracer.pointcloud.readers import ply
from splat_tracer.pointcloud.readers import las as las_reader
from splat_tracer.util import resources
from splat_tracer.util.progress import Cancelled, Job, Steps, TerminalProgress

# bpy_extras.io_utils.axis_conversion(from_forward="-Z", from_up="Y"): a Y-up file into
# Blender's Z-up (x, y, z) -> (x, -z, y); written out so that these tests need no Blender.
Y_UP = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])
RNG = np.random.default_rng(10)


def _write(path, p, n=None, **kw):
    ply.write_ply(str(path), p, n if n is not None else np.tile([0.0, 0.0, 1.0], (len(p), 1)), **kw)
    return str(path)


def test_float32_coordinates_import_as_their_float64_values(tmp_path):
    """A file's float32 coordinates are kept as float32 until the origin is taken (no
    float64 copy of them): the import is the same as the same values written as float64,
    georeferenced, with duplicates, a NaN row and an outlier."""
    from plyfile import PlyData, PlyElement

    p, n = fibonacci_sphere(4000, centre=(0.0, 0.0, 0.0))
    p = (p * 20 + [431234.5, 5412345.25, 312.75]).astype(np.float32)
    p[100:120] = p[:20]  # exact duplicates
    p[7] = np.nan
    p[3999] = p[0] * 1e3  # far away: an outlier (kept)
    paths = []
    for dtype in ("f4", "f8"):
        rows = np.empty(len(p), [("x", dtype), ("y", dtype), ("z", dtype), ("nx", "f4"), ("ny", "f4"), ("nz", "f4")])
        for i, c in enumerate("xyz"):
            rows[c], rows["n" + c] = p[:, i], n[:, i]
        paths.append(str(tmp_path / f"{dtype}.ply"))
        PlyData([PlyElement.describe(rows, "vertex")]).write(paths[-1])
    assert readers.read_cloud(paths[0]).positions.dtype == np.float32
    assert readers.read_cloud(paths[1]).positions.dtype == np.float64
    a, b = (importer.load(path) for path in paths)
    assert a.outliers == b.outliers == 1 and a.cloud.merged_duplicates == b.cloud.merged_duplicates == 19  # row 107 copies row 7, now NaN
    np.testing.assert_array_equal(a.origin, b.origin)
    np.testing.assert_array_equal(a.local, b.local)
    np.testing.assert_array_equal(a.radii, b.radii)
    np.testing.assert_array_equal(a.cloud.rows, b.cloud.rows)
    assert a.hood.describe() == b.hood.describe()


# --- axes and scale ----------------------------------------------------------------------

def test_axes_and_scale_turn_normals_and_keep_the_georeference_exact(tmp_path):
    p, n = fibonacci_sphere(3000, centre=(0.0, 0.0, 0.0))
    utm = np.array([431234.5, 5412345.25, 312.75])  # metres; in the Y-up file: (x, z-up as y, -y as z)
    z_up = p + utm
    y_up = z_up @ Y_UP  # the inverse of Y_UP is its transpose: these are the file's coordinates
    a = importer.load(_write(tmp_path / "z.ply", z_up, n))
    b = importer.load(_write(tmp_path / "y.ply", y_up, n @ Y_UP), importer.ImportOptions(axes=Y_UP))
    np.testing.assert_array_equal(b.origin, a.origin)   # the converted origin, bit for bit
    np.testing.assert_array_equal(b.local, a.local)
    np.testing.assert_allclose(b.cloud.normals, a.cloud.normals, atol=1e-7)
    np.testing.assert_array_equal(b.radii, a.radii)
    scaled = importer.load(_write(tmp_path / "mm.ply", y_up * 1000.0, n @ Y_UP),
                           importer.ImportOptions(axes=Y_UP, scale=0.001))  # millimetres
    np.testing.assert_allclose(scaled.origin + scaled.local, z_up, atol=1e-6)
    np.testing.assert_allclose(scaled.radii, a.radii, rtol=1e-5)


def test_scale_multiplies_file_radii_and_scanner_positions():
    cloud = make_cloud("c", RNG.uniform(0, 1, (50, 3)), None, None, np.full(50, 0.1, np.float32),
                       scanners=np.tile([1.0, 2.0, 3.0], (50, 1)))
    out = importer.transform(cloud, Y_UP, 2.0)
    np.testing.assert_allclose(out.radii, 0.2, rtol=1e-6)
    np.testing.assert_allclose(out.scanners[0], np.array([1.0, -3.0, 2.0]) * 2)
    with pytest.raises(ValueError, match="orthonormal"):
        importer.transform(cloud, np.eye(3) * 2)


def test_a_radius_the_scale_carries_beyond_the_renderers_limit_is_dropped_and_counted():
    """What imports renders: 1e13 passes the reader; the largest import scale (1e6) makes it
    1e19, beyond the renderer's 1e18."""
    radii = np.full(50, 0.1, np.float32)
    radii[3] = 1e13
    cloud = make_cloud("c", RNG.uniform(0, 1, (50, 3)), None, None, radii)
    out = importer.transform(cloud, None, 1e6)
    assert len(out) == 49 and out.dropped_radii == 1 and out.radii.max() == np.float32(0.1 * 1e6)
    assert len(importer.transform(cloud, None, 1e4)) == 50  # 1e17: within the limit


# --- point budget ------------------------------------------------------------------------

def test_point_budget_is_exact_deterministic_and_spatially_even(tmp_path):
    # a plane whose left half is 9 times denser than its right half
    left = np.column_stack([RNG.uniform(0, 1, (45000, 2)), np.zeros(45000)])
    right = np.column_stack([RNG.uniform(1, 2, (5000, 1)), RNG.uniform(0, 1, (5000, 1)), np.zeros(5000)])
    path = _write(tmp_path / "dense.ply", np.concatenate([left, right]))
    options = importer.ImportOptions(max_points=8000)
    a, b = importer.load(path, options), importer.load(path, options)
    assert len(a.local) == 8000 and a.cloud.budget_dropped == 42000
    np.testing.assert_array_equal(a.cloud.rows, b.cloud.rows)  # the same points every time
    assert any("point budget 8,000: 42,000 of 50,000 points were left out" in note for note in a.notes(6))
    world = a.origin + a.local
    share_right = (world[:, 0] > 1).mean()
    # Even over space: a random choice keeps the density (10 % in the right half); the grid
    # gives each occupied cell one point, and the sparse half cannot fill all of its cells
    # (5,000 points in about 4,000 cells: 70 % occupied), so a bit under half.
    assert 0.35 < share_right < 0.5, share_right
    small = importer.load(path, importer.ImportOptions(max_points=10 ** 6))
    assert len(small.local) == 50000 and small.cloud.budget_dropped == 0


# --- statistical outliers ----------------------------------------------------------------

def test_statistical_outlier_removal_is_optional_and_counted(tmp_path):
    plane = np.column_stack([RNG.uniform(0, 1, (20000, 2)), np.zeros(20000)])
    noise = np.column_stack([RNG.uniform(0, 1, (40, 2)), RNG.uniform(0.05, 0.3, 40)])  # within the bulk's reach
    path = _write(tmp_path / "noisy.ply", np.concatenate([plane, noise]))
    kept = importer.load(path)
    assert len(kept.local) == 20040 and kept.statistical_outliers == 0
    cleaned = importer.load(path, importer.ImportOptions(statistical_ratio=2.0))
    assert 40 <= cleaned.statistical_outliers < 200, cleaned.statistical_outliers
    assert (cleaned.cloud.rows >= 20000).sum() == 0  # every stray point left out
    assert any("statistical outlier removal" in note for note in cleaned.notes(6))


# --- progress and cancel -----------------------------------------------------------------

def _bare_sphere(tmp_path, n=20000):
    from plyfile import PlyData, PlyElement

    p, _ = fibonacci_sphere(n)
    rows = np.zeros(n, dtype=[("x", "f8"), ("y", "f8"), ("z", "f8")])
    rows["x"], rows["y"], rows["z"] = p.T
    path = tmp_path / "bare.ply"
    PlyData([PlyElement.describe(rows, "vertex")]).write(str(path))
    return str(path)


def test_progress_rises_to_the_end_through_every_stage(tmp_path):
    seen = []
    importer.load(_bare_sphere(tmp_path), progress=lambda f, m: seen.append((f, m)))
    fractions = [f for f, _ in seen]
    assert fractions == sorted(fractions) and fractions[0] == 0.0 and fractions[-1] > 0.9
    messages = " ".join(m for _, m in seen)
    for stage in ("reading", "estimating normals", "orienting normals", "splat radii"):
        assert stage in messages


@pytest.mark.parametrize("at", ["reading", "estimating normals", "orienting normals: spanning tree", "splat radii"])
def test_a_cancel_at_any_stage_stops_the_import(tmp_path, at):
    def progress(fraction, message):
        if message.startswith(at):
            raise Cancelled("cancelled")
    with pytest.raises(Cancelled):
        importer.load(_bare_sphere(tmp_path), progress=progress)


@pytest.mark.parametrize("compress", [False, True], ids=["LAS", "LAZ"])
def test_las_reading_reports_progress_by_chunks_and_can_be_cancelled(tmp_path, monkeypatch, compress):
    import laspy

    las = laspy.LasData(laspy.LasHeader(point_format=3, version="1.2"))
    las.header.scales = np.full(3, 0.001)
    las.x, las.y, las.z = RNG.uniform(0, 10, (3, 1000))
    path = tmp_path / ("scan.laz" if compress else "scan.las")
    las.write(str(path), do_compress=compress)
    monkeypatch.setattr(las_reader, "_LAS_CHUNK", 300)
    seen = []
    cloud = readers.read_cloud(str(path), progress=lambda f, m: seen.append(f))
    assert len(cloud) == 1000 and seen == [0.0, 0.3, 0.6, 0.9]
    np.testing.assert_allclose(cloud.positions[:, 0], np.asarray(las.x), atol=1e-9)

    def cancel_at_the_third_chunk(fraction, message):  # reading is the import's first fifth
        if message == f"{path.name}: reading" and fraction >= 0.6 * 0.2:
            raise Cancelled("cancelled while reading")
    with pytest.raises(Cancelled, match="while reading"):
        importer.load(str(path), progress=cancel_at_the_third_chunk)


def test_a_job_runs_on_a_worker_thread_and_is_cancelled_at_its_next_progress_call():
    started, release = threading.Event(), threading.Event()

    def work(progress):
        for i in range(1000):
            progress(i / 1000, "working")
            started.set()
            release.wait(5)
        return "done"
    job = Job(work).start()
    assert started.wait(5) and not job.done
    job.cancel()
    release.set()
    assert job.wait(5)
    with pytest.raises(Cancelled):
        job.result()
    assert Job(lambda progress: 42).start().wait(5)
    ok = Job(lambda progress: 42).start()
    ok.wait(5)
    assert ok.result() == 42


def test_terminal_progress_prints_each_stage_once(capsys):
    out = TerminalProgress("import x.ply", every=3600)
    for i in range(10):
        out(i / 20, "estimating normals")
    out(0.6, "splat radii")
    lines = capsys.readouterr().out.splitlines()
    assert lines == ["import x.ply:   0 % estimating normals", "import x.ply:  60 % splat radii"]


def test_steps_share_one_bar():
    seen = []
    steps = Steps(lambda f, m: seen.append(f), {"a": 1.0, "skipped": 0.0, "b": 3.0})
    steps("a")(1.0, "")
    steps("b")(0.5, "")
    assert seen == [0.25, 0.625]


# --- memory and bad inputs ---------------------------------------------------------------

def test_a_count_too_large_for_memory_is_refused_before_reading(tmp_path, monkeypatch):
    p, n = fibonacci_sphere(2000)
    path = _write(tmp_path / "big.ply", p, n)
    monkeypatch.setattr(readers, "read_cloud", lambda *a: pytest.fail("read before the memory check"))
    resources.override(100 << 10)  # 100 KiB free
    try:
        with pytest.raises(CloudFileError, match=r"declares 2,000 points; importing them needs about .* GB "
                                                      r"of memory but only 0.0 GB are available") as err:
            importer.load(path)
    finally:
        resources.override(None)
    assert path in str(err.value)


def _crc32c(data: bytes) -> int:
    """CRC-32C (Castagnoli), the checksum at the end of every 1024-byte page of an E57 file."""
    crc = 0xFFFFFFFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0x82F63B78 if crc & 1 else crc >> 1
    return crc ^ 0xFFFFFFFF


def _e57_without_z(path):
    """An E57 file whose scan lacks cartesianZ: pye57 always writes x, y and z, so the field
    is renamed in the file's XML (cartesianZ -> cartesianQ) and the pages' checksums redone."""
    import pye57

    with pye57.E57(str(path), mode="w") as e57:
        pts = RNG.uniform(0, 1, (100, 3))
        e57.write_scan_raw({"cartesianX": pts[:, 0], "cartesianY": pts[:, 1], "cartesianZ": pts[:, 2]})
    data = bytearray(path.read_bytes())
    page, payload = 1024, 1020
    for hit in re.finditer(b"cartesianZ", bytes(data)):
        at = hit.start() + len("cartesian")
        data[at:at + 1] = b"Q"
        start = at // page * page
        data[start + payload:start + page] = struct.pack(">I", _crc32c(bytes(data[start:start + payload])))
    path.write_bytes(bytes(data))


def _las_count_beyond_memory(path):
    import laspy

    las = laspy.LasData(laspy.LasHeader(point_format=3, version="1.2"))
    las.x, las.y, las.z = RNG.uniform(0, 10, (3, 100))
    las.write(str(path), do_compress=True)
    with laspy.open(str(path)) as reader:
        assert reader.header.are_points_compressed
    data = bytearray(path.read_bytes())
    data[107:111] = struct.pack("<I", 4_000_000_000)  # legacy point count (LAS 1.2 header, offset 107)
    path.write_bytes(bytes(data))


PLY_HEAD = "ply\nformat ascii 1.0\nelement vertex 3\n"
XYZ = "property float x\nproperty float y\nproperty float z\n"
# (file name, content or a function writing it, what the message must say): every bad input of
# issue 10 not covered by test_readers.py / test_ply.py, plus a PLY version of the shared ones.
BAD = [
    ("empty.ply", b"", "the file is empty"),
    ("duplicate.ply", (PLY_HEAD + XYZ + "property float x\nend_header\n0 0 0 0\n1 1 1 1\n2 2 2 2\n").encode(),
     "not a valid PLY file (two properties with same name)"),
    ("unknown_type.ply", (PLY_HEAD + "property float x\nproperty float y\nproperty float128 z\nend_header\n"
                          "0 0 0\n1 1 1\n2 2 2\n").encode(), "not a valid PLY file"),
    ("latin1.ply", (PLY_HEAD + XYZ).encode() + "comment scanné à Genève\nend_header\n0 0 1\n1 0 0\n0 1 0\n".encode(
        "latin-1"), "the PLY header is not ASCII text (byte"),
    ("nan.ply", (PLY_HEAD + XYZ + "end_header\nnan 0 0\n0 nan 0\ninf 0 0\n").encode(),
     "no point has finite coordinates (all 3 rows"),
    ("truncated.ply", (PLY_HEAD.replace("ascii", "binary_little_endian") + XYZ + "end_header\n").encode()
     + np.zeros(8, "<f4").tobytes(), "early end-of-file"),
    ("latin1.xyz", "# scanné\n0 0 0\n1 1 1\n2 2 2\n".encode("latin-1"), "not UTF-8 text (byte 7, 0xe9, on line 1)"),
    ("no_z.e57", _e57_without_z, "scan 0 ('Scan 0') has neither cartesian nor spherical coordinates (its fields: "
                                 "cartesianQ, cartesianX, cartesianY)"),
    ("huge.laz", _las_count_beyond_memory, "declares 4,000,000,000 points; importing them needs about"),
]


def make_bad(tmp_path, name, content):
    path = tmp_path / name
    if callable(content):
        content(path)
    else:
        path.write_bytes(content)
    return path


@pytest.mark.parametrize("name, content, message", BAD, ids=[b[0] for b in BAD])
def test_bad_inputs_are_refused_naming_the_file_and_the_problem(tmp_path, name, content, message):
    path = make_bad(tmp_path, name, content)
    before = path.read_bytes()
    with pytest.raises(CloudFileError) as err:
        importer.load(str(path))
    assert str(path) in str(err.value) and message in str(err.value), str(err.value)
    assert path.read_bytes() == before  # the source is never touched


def test_non_finite_ply_rows_are_dropped_and_counted(tmp_path):
    p, n = fibonacci_sphere(500)
    p[[3, 70]] = np.nan
    prepared = importer.load(_write(tmp_path / "holes.ply", p, n))
    assert len(prepared.local) == 498 and prepared.cloud.dropped_rows == 2
    assert any("2 rows with non-finite coordinates were dropped" in note for note in prepared.notes(6))


def test_unknown_ply_properties_are_ignored_and_said(tmp_path):
    path = tmp_path / "extra.ply"
    path.write_text(PLY_HEAD.replace("3", "4") + XYZ + "property float quality\nproperty uchar flags\nend_header\n"
                    "0 0 0 1 0\n1 0 0 1 0\n0 1 0 1 0\n1 1 0 1 0\n")
    cloud = readers.read_cloud(str(path))
    assert any("ignored (not a splat's): quality, flags" in note for note in cloud.notes)


# --- in Blender ---------------------------------------------------------------------------

def _counts(bpy):
    return tuple(len(getattr(bpy.data, t)) for t in ("objects", "meshes", "node_groups", "materials"))


@pytest.mark.parametrize("name, content, message", BAD, ids=[b[0] for b in BAD])
def test_bad_inputs_create_nothing_in_blender(blender, empty_scene, tmp_path, name, content, message):
    bpy = blender
    path = make_bad(tmp_path, name, content)
    before = _counts(bpy)
    with pytest.raises(RuntimeError) as err:
        bpy.ops.splat_tracer.import_cloud(filepath=str(path))
    assert str(path) in str(err.value) and message in str(err.value)
    assert _counts(bpy) == before


def test_operator_axes_scale_and_budget(blender, empty_scene, tmp_path):
    bpy = blender
    p, n = fibonacci_sphere(4000, centre=(0.0, 0.0, 0.0))
    utm = np.array([431234.5, 5412345.25, 312.75])
    path = _write(tmp_path / "yup_mm.ply", ((p + utm) @ Y_UP) * 1000.0, n @ Y_UP)
    assert bpy.ops.splat_tracer.import_cloud(filepath=path, axis_forward="-Z", axis_up="Y", global_scale=0.001,
                                             max_points=1000) == {"FINISHED"}
    obj = bpy.context.active_object
    assert len(obj.data.vertices) == 1000
    assert np.abs(np.array(obj.location) - utm).max() < 1.0  # the converted georeference
    local = np.empty(3000, np.float32)
    obj.data.vertices.foreach_get("co", local)
    world = local.reshape(-1, 3).astype(np.float64) + np.array(obj.location, np.float64)
    assert np.abs(np.linalg.norm(world - utm, axis=1) - 1.0).max() < 1e-5  # on the unit sphere, in metres
    nrm = np.empty(3000, np.float32)
    obj.data.attributes["splat_normal"].data.foreach_get("vector", nrm)
    cos = np.einsum("ij,ij->i", nrm.reshape(-1, 3), world - utm)
    assert (cos > 0.99).all()  # normals turned with the points
    assert "point budget 1,000" in obj["splat_tracer_import_notes"]


def test_a_cancel_while_creating_objects_leaves_nothing(blender, empty_scene, tmp_path):
    from blender_helpers import extension_module

    bpy = blender
    ops = extension_module("operators.import_cloud")
    ext_importer = extension_module("splat_tracer.pointcloud.importer")
    for group in list(bpy.data.node_groups):  # so that this import creates the shared group and material
        bpy.data.node_groups.remove(group)
    for material in list(bpy.data.materials):
        bpy.data.materials.remove(material)
    paths = []
    for i in range(2):
        p, n = fibonacci_sphere(500, centre=(3.0 * i, 0.0, 0.0))
        paths.append(_write(tmp_path / f"part{i}.ply", p, n))
    loaded = ext_importer.load_many(paths)
    before = _counts(bpy)

    def cancel_after_the_first(fraction, message):
        if fraction >= 0.5:
            raise extension_module("splat_tracer.util.progress").Cancelled("cancelled")
    with pytest.raises(Exception, match="cancelled"):
        ops.create_objects(bpy.context, loaded, lambda prep: [], cancel_after_the_first)
    assert _counts(bpy) == before
    created = ops.create_objects(bpy.context, loaded, lambda prep: [])
    assert len(created) == 2 and _counts(bpy) == (before[0] + 2, before[1] + 2, before[2] + 1, before[3] + 1)


def test_objects_made_consuming_the_prepared_clouds_are_the_same(blender, empty_scene, tmp_path):
    """create_objects(consume=True), as the import operator calls it, lets go of each array
    as Blender takes its copy; the objects are the same as without."""
    from blender_helpers import extension_module

    bpy = blender
    ops = extension_module("operators.import_cloud")
    ext_importer = extension_module("splat_tracer.pointcloud.importer")
    p, n = fibonacci_sphere(2000, centre=(0.0, 0.0, 0.0))
    path = _write(tmp_path / "c.ply", p + [4e5, 5e6, 20.0], n, colours=RNG.random((2000, 3)))
    kept, consumed = ext_importer.load_many([path]), ext_importer.load_many([path])
    a, = ops.create_objects(bpy.context, kept, lambda prep: [])
    b, = ops.create_objects(bpy.context, consumed, lambda prep: [], consume=True)
    prep = consumed[0][1]
    assert prep.local is None and prep.radii is None and prep.cloud.normals is None and prep.cloud.colours is None
    assert kept[0][1].local is not None  # not consumed unless asked
    for name, field, width in (("position", "vector", 3), ("splat_normal", "vector", 3), ("splat_radius", "value", 1),
                               ("splat_color", "color", 4)):
        got = [np.empty(2000 * width, np.float32) for _ in range(2)]
        for obj, out in zip((a, b), got):
            obj.data.attributes[name].data.foreach_get(field, out)
        np.testing.assert_array_equal(got[0], got[1])
    assert tuple(a.location) == tuple(b.location)


def test_background_import_prints_progress_and_estimate_normals_still_works(blender, empty_scene, tmp_path, capfd):
    bpy = blender
    path = _bare_sphere(tmp_path, 3000)
    assert bpy.ops.splat_tracer.import_cloud(filepath=path) == {"FINISHED"}
    out = capfd.readouterr().out
    assert "Import Splat Point Cloud:" in out and "estimating normals" in out and "splat radii" in out
    obj = bpy.context.active_object
    for o in bpy.context.view_layer.objects:
        o.select_set(o == obj)
    assert bpy.ops.splat_tracer.estimate_normals(orientation="PROPAGATE") == {"FINISHED"}
    assert "Estimate Splat Normals:" in capfd.readouterr().out


def test_a_job_cancelled_midway_in_blender_leaves_nothing(blender, empty_scene, tmp_path):
    """What the modal operator does, less its window's events: the import's work on a worker
    thread (the extension's own Job and pipeline), cancelled while it runs; nothing exists."""
    from blender_helpers import extension_module

    bpy = blender
    progress = extension_module("splat_tracer.util.progress")
    ext_importer = extension_module("splat_tracer.pointcloud.importer")
    path = _bare_sphere(tmp_path, 20000)
    before = _counts(bpy)
    reached, cancelled = threading.Event(), threading.Event()

    def work(report):
        def watch(fraction, message):
            report(fraction, message)  # raises Cancelled once the job is cancelled
            if message.startswith("estimating normals") and not reached.is_set():
                reached.set()
                cancelled.wait(30)  # midway: the main thread cancels now
        return ext_importer.load_many([path], progress=watch)
    job = progress.Job(work).start()
    assert reached.wait(30)
    job.cancel()
    cancelled.set()
    assert job.wait(30)
    with pytest.raises(progress.Cancelled):
        job.result()
    assert _counts(bpy) == before


# --- float32 precision ----------------------------------------------------------------------

def _cluster(centre, axis, n=30, step=0.01):
    """An n x n grid of `step` spacing around `centre`, in the plane of `axis` and the next axis
    (so that rounding along `axis` shows)."""
    u, v = np.meshgrid(np.arange(n) * step, np.arange(n) * step, indexing="ij")
    p = np.zeros((n * n, 3))
    p[:, axis], p[:, (axis + 1) % 3] = u.ravel(), v.ravel()
    return p + centre


def _write_xyz(path, p):
    np.savetxt(path, p, fmt="%.4f")
    return str(path)


@pytest.mark.parametrize("apart, axis", [(1e7, 0), (1e6, 1), (1e7, 2), (1e6, 2)])
def test_two_clusters_too_far_apart_for_float32_are_named_as_such(tmp_path, apart, axis):
    """Two cm-spaced clusters `apart` metres apart share one float32 origin: the cloud's steps at
    that distance (0.03 m at 5e5, 0.5 m at 5e6) move or merge their points. The notes say so and
    count them, rather than blaming the file for duplicates."""
    far = np.zeros(3)
    far[axis] = apart
    path = _write_xyz(tmp_path / "two.xyz", np.concatenate([_cluster(0.0, axis), _cluster(far, axis)]))
    prep = importer.load(path)
    assert prep.lost_precision > 0 and prep.precision_error > 0.001
    note = next(n for n in prep.notes(8) if "lost precision" in n)
    assert f"{prep.lost_precision:,} points lost precision" in note
    assert f"span {apart:.2g}" in note and "0.01 apart" in note and "separate files" in note


def test_a_far_cluster_of_a_few_points_is_counted_as_outliers_and_as_lost_precision(tmp_path):
    """A small cluster 1e7 away is outside the bulk: kept (the origin stays at the bulk) but
    rounded to 1 m steps; both facts are in the notes."""
    p = np.concatenate([_cluster(0.0, 0), _cluster([1e7, 0, 0], 0, n=3)])
    prep = importer.load(_write_xyz(tmp_path / "stray.xyz", p))
    assert prep.outliers == 9 and prep.lost_precision == 9
    assert sum("lost precision" in n for n in prep.notes(8)) == 1


@pytest.mark.parametrize("centre", [(3e6, 5e6, 100.0), (1e7, -1e6, 0.0), (4e5, 1e7, 1e6)])
def test_a_georeferenced_cluster_far_from_the_world_origin_imports_silently(tmp_path, centre):
    """local_frame recentres a single cluster: its float32 offsets keep cm spacing exactly enough."""
    prep = importer.load(_write_xyz(tmp_path / "geo.xyz", _cluster(np.array(centre), 0, n=60)))
    assert prep.lost_precision == 0 and not any("precision" in n for n in prep.notes(8))
    assert len(prep.local) == 3600 and prep.cloud.merged_duplicates == 0


def test_clusters_far_apart_along_an_axis_they_are_flat_across_lose_nothing(tmp_path):
    """Offsets of exactly 0 and +-5e6 are float32 values: nothing moves, nothing is reported."""
    p = np.concatenate([_cluster(0.0, 0), _cluster([0, 0, 1e7], 0)])  # grids in the xy plane, 1e7 apart in z
    prep = importer.load(_write_xyz(tmp_path / "flat.xyz", p))
    assert prep.lost_precision == 0 and not any("precision" in n for n in prep.notes(8))
