"""PCD files (readers/pcd.py): each encoding as pypcd4 writes it, packed colours, organised
clouds with NaN rows, normals, intensity and other fields, the VIEWPOINT as the sensor
that orients estimated normals (a synthetic depth frame), and broken files."""
from __future__ import annotations

import numpy as np
import pytest
from pypcd4 import Encoding, MetaData, PointCloud as Pcd

from frames import slanted_wall_frame
from geometry import fibonacci_sphere
from splat_tracer.pointcloud import importer, prepare, readers
from splat_tracer.pointcloud.cloud import CloudFileError, linear_colours
from splat_tracer.pointcloud.readers import pcd
from splat_tracer.util import resources
from splat_tracer.util.matrices import quaternion_matrices

RNG = np.random.default_rng(27)
ENCODINGS = (Encoding.ASCII, Encoding.BINARY, Encoding.BINARY_COMPRESSED)


def _write(path, columns: dict, encoding=Encoding.BINARY, viewpoint=None, height=1):
    """A PCD written by pypcd4: name -> (N,) array (its dtype is the field's type)."""
    names = tuple(columns)
    cloud = Pcd.from_points([np.asarray(c) for c in columns.values()], names, [np.asarray(c).dtype for c in
                                                                                columns.values()])
    n = len(next(iter(columns.values())))
    cloud.metadata = cloud.metadata.derive(width=n // height, height=height,
                                           viewpoint=viewpoint or (0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0))
    cloud.save(str(path), encoding=encoding)
    return str(path)


def _srgb(n):
    return RNG.integers(0, 256, (n, 3)).astype(np.uint32)


def _expected_linear(rgb):
    return linear_colours([rgb[:, 0], rgb[:, 1], rgb[:, 2]], 255)


@pytest.mark.parametrize("encoding", ENCODINGS, ids=lambda e: e.value)
def test_each_encoding_reads_coordinates_normals_colours_and_intensity(tmp_path, encoding):
    p, nrm = fibonacci_sphere(400, radius=2.0, centre=(10.0, -3.0, 1.0))
    rgb = _srgb(len(p))
    packed = (rgb[:, 0] << 16) | (rgb[:, 1] << 8) | rgb[:, 2]
    # pypcd4's ascii prints a float field as '%.10f', which loses a packed float colour:
    # ascii carries PCL's uint 'rgba' (printed as an integer), the binary ones PCL's float 'rgb'.
    colour = {"rgba": packed | np.uint32(0xFF000000)} if encoding == Encoding.ASCII else \
        {"rgb": packed.astype(np.uint32).view(np.float32)}
    intensity = RNG.uniform(0, 100, len(p)).astype(np.float32)
    label = RNG.integers(0, 7, len(p)).astype(np.uint32)
    path = _write(tmp_path / "cloud.pcd", {
        "x": p[:, 0].astype(np.float32), "y": p[:, 1].astype(np.float32), "z": p[:, 2].astype(np.float32),
        "normal_x": nrm[:, 0].astype(np.float32), "normal_y": nrm[:, 1].astype(np.float32),
        "normal_z": nrm[:, 2].astype(np.float32), **colour, "intensity": intensity, "label": label}, encoding)
    assert readers.sniff(path) == "PCD"
    cloud = readers.read_cloud(path)
    assert cloud.format == "PCD" and len(cloud) == len(p)
    assert np.allclose(cloud.positions, p, atol=1e-5) and cloud.positions.dtype == np.float32
    assert cloud.oriented and np.allclose(cloud.normals, nrm, atol=1e-5)  # PCL's normals face the viewpoint
    assert np.array_equal(cloud.colours[:, :3], _expected_linear(rgb)) and (cloud.colours[:, 3] == 1).all()
    assert np.allclose(cloud.attributes["intensity"], intensity, atol=1e-4)
    assert cloud.attributes["label"].dtype == np.int32 and np.array_equal(cloud.attributes["label"], label)
    prepared = prepare.prepare(cloud, path)
    assert not prepared.normals_estimated  # the file's own normals, as they are


def test_packed_colours_both_ways_and_rgba_alpha(tmp_path):
    n = 300
    p = RNG.uniform(-1, 1, (n, 3)).astype(np.float32)
    rgb = _srgb(n)
    alpha = RNG.integers(0, 256, n).astype(np.uint32)
    packed = (alpha << 24) | (rgb[:, 0] << 16) | (rgb[:, 1] << 8) | rgb[:, 2]
    xyz = {"x": p[:, 0], "y": p[:, 1], "z": p[:, 2]}
    as_float = readers.read_cloud(_write(tmp_path / "float.pcd", {**xyz, "rgb": packed.view(np.float32)}))
    as_uint = readers.read_cloud(_write(tmp_path / "uint.pcd", {**xyz, "rgba": packed}))
    want = _expected_linear(rgb)
    assert np.array_equal(as_float.colours[:, :3], want) and (as_float.colours[:, 3] == 1).all()  # rgb: no alpha
    assert np.array_equal(as_uint.colours[:, :3], want)
    assert np.allclose(as_uint.colours[:, 3], alpha / 255.0, atol=1e-6)


def test_ascii_float_rgb_as_pcl_writes_it(tmp_path):
    """PCL prints a float 'rgb' field in ascii as the integer of its bits (4285098345);
    read in float64 every bit is kept (pypcd4's float32 would round it)."""
    rgb = np.array([[255, 128, 1], [3, 200, 77], [0, 0, 255], [17, 34, 51]], np.uint32)
    packed = (np.uint32(0xFF) << 24) | (rgb[:, 0] << 16) | (rgb[:, 1] << 8) | rgb[:, 2]
    rows = "\n".join(f"{i}\t{i * 2}  {i % 3} {v} " for i, v in enumerate(packed))  # tabs, runs of spaces, trailing
    path = tmp_path / "pcl.pcd"
    path.write_text("# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z rgb\nSIZE 4 4 4 4\n"
                    "TYPE F F F F\nCOUNT 1 1 1 1\nWIDTH 4\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 4\nDATA ascii\n"
                    + rows + "\n")
    cloud = readers.read_cloud(str(path))
    assert np.array_equal(cloud.colours[:, :3], _expected_linear(rgb))


@pytest.mark.parametrize("encoding", ENCODINGS, ids=lambda e: e.value)
def test_an_organised_cloud_drops_its_nan_rows_and_keeps_the_file_rows(tmp_path, encoding):
    width, height = 40, 30
    u, v = np.meshgrid(np.arange(width), np.arange(height))
    p = np.column_stack([u.ravel() * 0.01, v.ravel() * 0.01, 1.0 + 0.001 * u.ravel()]).astype(np.float32)
    holes = RNG.random(len(p)) < 0.3
    p[holes] = np.nan
    path = _write(tmp_path / "frame.pcd", {"x": p[:, 0], "y": p[:, 1], "z": p[:, 2]}, encoding, height=height)
    cloud = readers.read_cloud(path)
    assert cloud.dropped_rows == holes.sum() and len(cloud) == (~holes).sum()
    assert np.array_equal(cloud.rows, np.flatnonzero(~holes))  # v * WIDTH + u
    assert any(f"{width:,} x {height:,}" in note for note in cloud.notes)
    prepared = prepare.prepare(cloud, path)
    assert f"{holes.sum():,} rows with non-finite coordinates were dropped" in prepared.notes(8)


def test_eight_byte_types_and_fields_of_several_values(tmp_path):
    n = 50
    p = RNG.uniform(-1e6, 1e6, (n, 3))  # float64 coordinates stay float64
    descriptor = RNG.random((n, 3)).astype(np.float32)
    meta = MetaData.model_validate(dict(fields=("x", "y", "z", "id", "fpfh"), size=(8, 8, 8, 8, 4),
                                        type=("F", "F", "F", "U", "F"), count=(1, 1, 1, 1, 3), points=n, width=n))
    cloud = Pcd(meta, np.rec.fromarrays([p[:, 0], p[:, 1], p[:, 2], np.arange(n, dtype=np.uint64), *descriptor.T],
                                        dtype=meta.build_dtype()))
    cloud.save(str(tmp_path / "wide.pcd"), encoding=Encoding.BINARY_COMPRESSED)
    read = readers.read_cloud(str(tmp_path / "wide.pcd"))
    assert read.positions.dtype == np.float64 and np.array_equal(read.positions, p)
    assert np.array_equal(read.attributes["id"], np.arange(n))
    assert "fields ignored: fpfh (3 values a point)" in read.notes and "fpfh" not in read.attributes


def test_estimated_normals_face_the_sensor_at_the_viewpoint(tmp_path):
    q = (0.8, 0.3, -0.4, 0.33)  # qw qx qy qz: a rotation about a skew axis
    t = np.array([12.0, -4.0, 2.5])
    camera, _ = slanted_wall_frame()
    # the sensor's frame into the cloud's: its pose, VIEWPOINT
    world = camera @ quaternion_matrices(np.array([q]) / np.linalg.norm(q))[0].T + t
    f32 = world.astype(np.float32)
    viewpoint = (*t, *(np.asarray(q) / np.linalg.norm(q)))
    path = _write(tmp_path / "frame.pcd", {"x": f32[:, 0], "y": f32[:, 1], "z": f32[:, 2]},
                  Encoding.BINARY_COMPRESSED, viewpoint=viewpoint, height=120)
    cloud = readers.read_cloud(path)
    assert cloud.dropped_rows == np.isnan(camera[:, 0]).sum() > 0  # the holes beyond the sensor's range
    assert cloud.scanners.strides[0] == 0  # one row, not (N,3)
    assert np.array_equal(cloud.scanners[0], t)
    assert pcd.viewpoint_note(viewpoint) in cloud.notes and "12, -4, 2.5" in pcd.viewpoint_note(viewpoint)
    prepared = importer.load(path)
    assert prepared.normals_oriented == "SCANNER"
    points = prepared.local.astype(np.float64) + prepared.origin
    towards = np.einsum("ij,ij->i", prepared.cloud.normals, t - points)
    assert (towards > 0).mean() >= 0.99, (towards > 0).mean()
    assert any("towards the scanner positions (decided by the file's scanner positions)" in note
               for note in prepared.notes(8)), prepared.notes(8)


def test_the_default_viewpoint_of_an_unorganised_cloud_is_not_a_sensor(tmp_path):
    # A closed object merged from several views, written with PCL's default VIEWPOINT (the
    # origin, inside it): oriented towards that origin it would face inwards.
    p, nrm = fibonacci_sphere(3000, radius=1.0)
    f32 = p.astype(np.float32)
    path = _write(tmp_path / "merged.pcd", {"x": f32[:, 0], "y": f32[:, 1], "z": f32[:, 2]})
    cloud = readers.read_cloud(path)
    assert cloud.scanners is None and any("PCL's default" in note and "not organised" in note for note in cloud.notes)
    prepared = importer.load(path)
    assert prepared.normals_oriented != "SCANNER"
    outward = np.einsum("ij,ij->i", prepared.cloud.normals, prepared.local.astype(np.float64) + prepared.origin)
    assert (outward > 0).mean() >= 0.99, (outward > 0).mean()
    # The same default on an organised frame is its sensor (one view: a depth image).
    frame = slanted_wall_frame()[0].astype(np.float32)
    organised = readers.read_cloud(_write(tmp_path / "frame.pcd", {"x": frame[:, 0], "y": frame[:, 1],
                                                                   "z": frame[:, 2]}, height=120))
    assert organised.scanners is not None and np.array_equal(organised.scanners[0], [0.0, 0.0, 0.0])


def test_a_viewpoint_survives_axes_the_budget_and_subsets_as_one_row(tmp_path):
    p = RNG.uniform(-1, 1, (2000, 3)).astype(np.float32)
    path = _write(tmp_path / "cloud.pcd", {"x": p[:, 0], "y": p[:, 1], "z": p[:, 2]},
                  viewpoint=(1.0, 2.0, 3.0, 1.0, 0.0, 0.0, 0.0))
    cloud = readers.read_cloud(path)
    turned = importer.transform(cloud, np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]]), 2.0)
    assert turned.scanners.strides[0] == 0 and np.array_equal(turned.scanners[0], [2.0, -6.0, 4.0])
    thinned = importer.apply_budget(turned, 500)
    assert thinned.scanners.shape == (500, 3) and thinned.scanners.strides[0] == 0
    masked = cloud.subset(np.arange(len(cloud)) % 3 == 0)
    assert masked.scanners.shape == (len(masked), 3) and np.array_equal(masked.scanners[-1], [1.0, 2.0, 3.0])


def test_a_count_too_large_for_memory_is_refused_before_reading(tmp_path, monkeypatch):
    p = RNG.uniform(-1, 1, (1000, 3)).astype(np.float32)
    path = _write(tmp_path / "big.pcd", {"x": p[:, 0], "y": p[:, 1], "z": p[:, 2]})
    monkeypatch.setattr(readers, "read_cloud", lambda *a: pytest.fail("read before the memory check"))
    resources.override(100 << 10)  # 100 KiB free
    try:
        with pytest.raises(CloudFileError, match=r"declares 1,000 points; importing them needs about") as err:
            importer.load(path)
    finally:
        resources.override(None)
    assert path in str(err.value)


HEAD = ("VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {n}\nHEIGHT 1\n"
        "VIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {data}\n")


def _head(n=3, data="binary"):
    return HEAD.format(n=n, data=data).encode()


def _compressed(n_declared=3, unpacked=None, packed=None, body=b""):
    return (_head(n_declared, "binary_compressed")
            + np.array([packed if packed is not None else len(body), unpacked if unpacked is not None
                        else n_declared * 12], "<u4").tobytes() + body)


BAD = [
    ("truncated.pcd", _head(3) + np.zeros(8, "<f4").tobytes(), "early end-of-file: the header declares 3 points of "
                                                               "12 bytes (36 bytes) but only 32 bytes follow"),
    ("longer.pcd", _head(3) + np.zeros(12, "<f4").tobytes(), "the header declares 3 points but 12 more bytes follow"),
    ("no_data_line.pcd", _head(3).replace(b"DATA binary\n", b""), "its header has no DATA line"),
    ("no_fields.pcd", b"# .PCD v0.7\nVERSION 0.7\nWIDTH 1\nPOINTS 1\nDATA ascii\n0 0 0\n", "lacks FIELDS, SIZE, TYPE"),
    ("bad_size.pcd", _head(3).replace(b"SIZE 4 4 4", b"SIZE 4 4 0"), "header SIZE.2: Input should be greater than 0"),
    ("odd_type.pcd", _head(3).replace(b"SIZE 4 4 4", b"SIZE 4 4 2"), "the field 'z' has TYPE F and SIZE 2"),
    ("short_size.pcd", _head(3).replace(b"SIZE 4 4 4", b"SIZE 4 4"), "FIELDS names 3 fields but SIZE gives 2"),
    ("words.pcd", _head(3).replace(b"WIDTH 3", b"WIDTH three"), "not a valid PCD file (header"),
    ("width.pcd", _head(3).replace(b"WIDTH 3", b"WIDTH 2"), "WIDTH 2 x HEIGHT 1 is not its POINTS 3"),
    ("encoding.pcd", _head(3).replace(b"DATA binary", b"DATA zip"), "DATA 'zip' is none of"),
    ("version.pcd", b"VERSION 0.9\n" + _head(3)[12:], "PCD version 0.9 is not one"),
    ("twice.pcd", _head(3).replace(b"FIELDS x y z", b"FIELDS x y x"), "the field(s) x appear twice"),
    ("no_z.pcd", _head(3).replace(b"FIELDS x y z", b"FIELDS x y w"), "has no z field(s) (its fields: x y w)"),
    ("latin1.pcd", "# .PCD scanné\n".encode("latin-1") + _head(3), "the PCD header is not ASCII text (line 1"),
    ("ascii_short.pcd", _head(3, "ascii") + b"0 0 0\n1 1 1\n", "early end-of-file"),
    ("ascii_ragged.pcd", _head(3, "ascii") + b"0 0 0\n1 1\n2 2 2 2\n", "data line 2 has 2 values where the header "
                                                                         "declares 3"),
    ("ascii_words.pcd", _head(3, "ascii") + b"0 0 0\n1 one 1\n2 2 2\n", "data line 2 has 'one', which is not a number"),
    ("ascii_more.pcd", _head(2, "ascii") + b"0 0 0\n1 1 1\n2 2 2\n", "declares 2 points but 3 rows of data follow"),
    ("lzf_sizes.pcd", _compressed(3, unpacked=999, body=b"\0" * 20), "decompress to 999 bytes, but 3 points of 12"),
    ("lzf_short.pcd", _compressed(3, packed=400, body=b"\0" * 20), "400 bytes of compressed data are declared"),
    ("lzf_ratio.pcd", _compressed(100000, packed=4, body=b"\0" * 4), "bytes of LZF data cannot decompress to"),
    ("lzf_corrupt.pcd", _compressed(3, body=b"\xff" * 20), "binary_compressed data cannot be read (corrupt"),
    ("lzf_missing.pcd", _head(3, "binary_compressed") + b"\0\0", "binary_compressed data need 8 bytes of sizes"),
    ("huge.pcd", _head(4_000_000_000), "declares 4,000,000,000 points; importing them needs about"),
    ("count.pcd", _head(3).replace(b"COUNT 1 1 1", b"COUNT 1 1 2"), "the field 'z' has COUNT 2"),
    ("empty.pcd", _head(0), "contains no points"),
    ("image.pcd", b"# .PCD v0.7\nVERSION 0.7\nFIELDS rgba\nSIZE 4\nTYPE U\nCOUNT 1\nWIDTH 1\nHEIGHT 1\nPOINTS 1\n"
                  b"DATA binary\n\0\0\0\0", "has no x y z field(s) (its fields: rgba)"),
]


@pytest.mark.parametrize("name, content, message", BAD, ids=[b[0] for b in BAD])
def test_broken_files_are_refused_naming_the_file_and_the_problem(tmp_path, name, content, message):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(CloudFileError) as err:
        importer.load(str(path))
    assert str(path) in str(err.value) and message in str(err.value), str(err.value)


def test_an_ascii_pcd_without_the_comment_is_sniffed_as_pcd(tmp_path):
    path = tmp_path / "plain.txt"  # the name does not decide
    path.write_bytes(_head(3, "ascii") + b"0 0 0\n1 0 0\n0 1 0\n")
    assert readers.sniff(str(path)) == "PCD"
    assert len(readers.read_cloud(str(path))) == 3


@pytest.mark.parametrize("first", ["Version 2.1 exported by FooScan", "fields x y z", "VERSION 3\nFIELDS x y z"])
def test_a_text_file_starting_with_a_pcd_key_is_text(tmp_path, first):
    """A first line starting VERSION or FIELDS (any case) made the file a PCD, refused as
    one with no DATA line: without PCL's comment, FIELDS, SIZE and TYPE lines are needed."""
    path = tmp_path / "scan.xyz"
    path.write_text(first + "\n0 0 0\n1 0 0\n0 1 0\n")
    assert readers.sniff(str(path)) == "TEXT"
    assert len(readers.read_cloud(str(path))) == 3


@pytest.mark.parametrize("end", [b"\r", b"\r\n"])
def test_ascii_data_with_cr_line_ends(tmp_path, end):
    """Lone CRs ended no line for the parse: 'declares 3 points but 3 rows of data follow'."""
    path = tmp_path / "cr.pcd"
    path.write_bytes(_head(3, "ascii") + end.join([b"0 0 0", b"1 0 0", b"0 1 2"]) + end)
    cloud = readers.read_cloud(str(path))
    assert np.array_equal(cloud.positions, [[0, 0, 0], [1, 0, 0], [0, 1, 2]])


def test_pypcd4_missing_is_refused_naming_the_package(tmp_path, monkeypatch):
    import builtins

    path = tmp_path / "cloud.pcd"
    path.write_bytes(_head(3, "ascii") + b"0 0 0\n1 0 0\n0 1 0\n")
    real = builtins.__import__

    def no_pypcd4(name, *args, **kwargs):
        if name.startswith("pypcd4"):
            raise ImportError("No module named 'lzf'")
        return real(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_pypcd4)
    with pytest.raises(CloudFileError, match="reading it needs the pypcd4 package"):
        readers.read_cloud(str(path))
