"""The importer's readers (text, LAS/LAZ, E57, Gaussian-splatting PLY), normal estimation,
and the bad inputs of each; a 3DGS and a 2DGS capture rendered in real Blender."""
from __future__ import annotations

import re
import struct

import numpy as np
import pytest

from geometry import angle_deg, cube_cloud, fibonacci_sphere, random_sphere
from splat_tracer.pointcloud import importer, normals, prepare, readers
from splat_tracer.pointcloud.cloud import CloudFileError, srgb_to_linear
from splat_tracer.pointcloud.readers import gaussians, ply

RNG = np.random.default_rng(7)


# --- text --------------------------------------------------------------------------------

def _sphere(n=500):
    p, nrm = fibonacci_sphere(n, radius=2.0, centre=(1000.0, -20.0, 5.0))
    rgb = RNG.integers(0, 256, size=(n, 3))
    return p, nrm, rgb


def _fmt(table):
    return "\n".join(" ".join(repr(float(v)) if not float(v).is_integer() else str(int(v)) for v in row)
                     for row in table) + "\n"


@pytest.mark.parametrize("layout", ["xyz", "xyzrgb", "xyz_rgb_n", "xyz_n_rgb", "pts", "csv_header", "unit_rgb"])
def test_text_round_trips(tmp_path, layout):
    p, nrm, rgb = _sphere()
    inten = RNG.integers(-2048, 2048, size=(len(p), 1))
    path = tmp_path / "cloud.txt"
    if layout == "xyz":
        path.write_text(_fmt(p))
    elif layout == "xyzrgb":
        path.write_text("// written by a scanner\n" + _fmt(np.column_stack([p, rgb])))
    elif layout == "xyz_rgb_n":
        path.write_text(_fmt(np.column_stack([p, rgb, nrm])))
    elif layout == "xyz_n_rgb":
        path.write_text(_fmt(np.column_stack([p, nrm, rgb])).replace(" ", "\t"))
    elif layout == "pts":
        path = tmp_path / "cloud.pts"
        path.write_text(f"{len(p)}\n" + _fmt(np.column_stack([p, inten, rgb])))
    elif layout == "csv_header":
        path = tmp_path / "cloud.csv"
        path.write_text("X,Y,Z,Intensity,Nx,Ny,Nz,Red,Green,Blue\n"
                        + _fmt(np.column_stack([p, inten, nrm, rgb])).replace(" ", ","))
    else:
        path.write_text(_fmt(np.column_stack([p, rgb / 255.0])))
    assert readers.sniff(str(path)) == "TEXT"
    cloud = readers.read_cloud(str(path))
    np.testing.assert_allclose(cloud.positions, p, rtol=1e-15)  # repr() round-trips doubles exactly
    if "n" in layout.split("_") or layout == "csv_header":
        np.testing.assert_allclose(cloud.normals, nrm, atol=1e-6)
    else:
        assert cloud.normals is None
    if layout != "xyz":
        np.testing.assert_allclose(cloud.colours[:, :3], srgb_to_linear(rgb / 255.0), atol=1e-6)
    if layout in ("pts", "csv_header"):
        np.testing.assert_array_equal(cloud.attributes["intensity"], inten[:, 0])


def test_text_column_mapping_when_guessing_fails(tmp_path):
    p, _, rgb = _sphere()
    extra = RNG.uniform(-5, 5, size=(len(p), 2))  # two unknown columns: no guess explains them
    path = tmp_path / "odd.xyz"
    path.write_text(_fmt(np.column_stack([extra[:, :1], p, rgb, extra[:, 1:]])))
    with pytest.raises(CloudFileError, match="Columns option") as err:
        readers.read_cloud(str(path))
    assert str(path) in str(err.value)
    cloud = readers.read_cloud(str(path), columns="_ x y z r g b i")
    np.testing.assert_allclose(cloud.positions, p)
    np.testing.assert_allclose(cloud.attributes["intensity"], extra[:, 1], rtol=1e-6)
    with pytest.raises(CloudFileError, match="names 3 columns"):
        readers.read_cloud(str(path), columns="x y z")


def _grid_900():
    """A 30 x 30 grid with two decimals, as European exports write it."""
    x, y = np.meshgrid(10.0 + 0.5 * np.arange(30), 20.25 + 0.25 * np.arange(30))
    return np.column_stack([x.ravel(), y.ravel(), np.full(900, 1.25)])


@pytest.mark.parametrize("name, separator, header, colours", [
    ("grid.csv", ";", "", False),            # the example: 10,50;20,25;1,25
    ("grid.txt", "\t", "", False),
    ("grid.csv", ";", "X;Y;Z;R;G;B\n", True),
    ("grid.xyz", " ", "// exported\n", True),
    ("grid.csv", "; ", "x; y; z\n", False),
])
def test_decimal_comma_text_is_read_with_decimal_commas(tmp_path, name, separator, header, colours):
    p = _grid_900()
    rgb = RNG.integers(0, 256, size=(900, 3))
    rows = [[f"{v:.2f}".replace(".", ",") for v in row] + ([str(c) for c in rgb[i]] if colours else [])
            for i, row in enumerate(p)]
    path = tmp_path / name
    path.write_text(header + "".join(separator.join(r) + "\n" for r in rows))
    cloud = readers.read_cloud(str(path))
    assert len(cloud) == 900
    np.testing.assert_array_equal(cloud.positions, p)  # every digit after the comma kept
    if colours:
        np.testing.assert_allclose(cloud.colours[:, :3], srgb_to_linear(rgb / 255.0), atol=1e-6)
    else:
        assert cloud.colours is None
    assert "numbers read with decimal commas" in cloud.notes


@pytest.mark.parametrize("content, message", [
    ("1,5;2,5;3,5\n1,2,3\n", "line 1 ('1,5;2,5;3,5') and line 2 ('1,2,3') use ',' differently"),
    ("x y z\n1.5,2.5,3.5\n1,5 2,5 3,5\n", "line 2 ('1.5,2.5,3.5') and line 3 ('1,5 2,5 3,5')"),
    ("1,5;2.5;3\n", "line 1 ('1,5;2.5;3') has both '.' and ','"),
    ("1.234,5\t2.345,5\t7\n", "has both '.' and ','"),  # thousands separators
])
def test_undecidable_decimal_marks_are_refused_naming_the_lines(tmp_path, content, message):
    path = tmp_path / "mixed.csv"
    path.write_text(content)
    with pytest.raises(CloudFileError, match=re.escape(message)) as err:
        readers.read_cloud(str(path))
    assert str(path) in str(err.value)


@pytest.mark.parametrize("rows", ["1.5, 2.5, 3.5\n4,5,6\n7.25,8,9\n", "1.5 ,2.5 ,3.5\n4 ,5 ,6\n7.25 ,8 ,9\n"])
def test_commas_between_values_are_still_separators(tmp_path, rows):
    path = tmp_path / "plain.csv"
    path.write_text("x, y, z\n" + rows)
    cloud = readers.read_cloud(str(path))
    np.testing.assert_array_equal(cloud.positions, [[1.5, 2.5, 3.5], [4, 5, 6], [7.25, 8, 9]])
    assert "numbers read with decimal commas" not in cloud.notes


@pytest.mark.parametrize("ending", ["\r", "\r\n", "mixed"])
@pytest.mark.parametrize("layout", ["xyz", "pts", "csv_header"])
def test_text_with_any_line_ending(tmp_path, ending, layout):
    """CR-only line endings (classic Mac OS) made the whole file one row (refused as 'cannot
    tell what its 1500 columns are', or worse, read as one point); CR LF and a mix read alike."""
    p, _, rgb = _sphere(200)
    if layout == "xyz":
        lines = _fmt(p).splitlines()
    elif layout == "pts":
        lines = [str(len(p))] + _fmt(np.column_stack([p, np.zeros(len(p)), rgb])).splitlines()
    else:
        lines = ["X;Y;Z;Red;Green;Blue"] + _fmt(np.column_stack([p, rgb])).replace(" ", ";").splitlines()
    endings = ["\r", "\r\n", "\n"] if ending == "mixed" else [ending]
    path = tmp_path / "cloud.txt"
    path.write_bytes("".join(line + endings[k % len(endings)] for k, line in enumerate(lines)).encode())
    assert readers.sniff(str(path)) == "TEXT"
    cloud = readers.read_cloud(str(path))
    np.testing.assert_array_equal(cloud.positions, p)
    if layout != "xyz":
        np.testing.assert_allclose(cloud.colours[:, :3], srgb_to_linear(rgb / 255.0), atol=1e-6)


@pytest.mark.parametrize("content", [
    "nan 0 0 10 20 30\n1 inf 0 10 20 30\n",            # colours: their range was taken over no row
    "x y z r g b a\n-inf 1 2 0.5 0.5 0.5 1\n",          # and alpha
    "2\nnan nan nan 1 2 3 4\nNaN 5 6 7 8 9 10\n",      # PTS: x y z intensity r g b
])
def test_text_without_a_finite_row_is_refused_with_a_cloud_file_error(tmp_path, content):
    """Every row with a NaN or infinite coordinate and colour columns (a fuzzed file): the
    colours' range was taken over the finite rows, none, and numpy's ValueError escaped. It is
    refused as a file of no finite point (make_cloud's message)."""
    path = tmp_path / "cloud.txt"
    path.write_text(content)
    with pytest.raises(CloudFileError, match="no point has finite coordinates") as err:
        readers.read_cloud(str(path))
    assert str(path) in str(err.value)


@pytest.mark.parametrize("layout", ["xyz", "pts", "csv_header"])
def test_text_with_a_byte_order_mark_keeps_every_row(tmp_path, layout):
    """A UTF-8 byte order mark (found by the text fuzz harness's seed): the first row read as
    '\ufeff1.0 ...', not numbers, so a header, and that point was silently lost (a PTS file's
    count line was not checked). The mark is not part of the text."""
    p, _, rgb = _sphere(50)
    if layout == "xyz":
        text = _fmt(p)
    elif layout == "pts":
        text = f"{len(p) + 1}\n" + _fmt(np.column_stack([p, np.zeros(len(p)), rgb]))  # a count that lies
    else:
        text = "X;Y;Z;Red;Green;Blue\n" + _fmt(np.column_stack([p, rgb])).replace(" ", ";")
    path = tmp_path / "cloud.txt"
    path.write_bytes(b"\xef\xbb\xbf" + text.encode())
    assert readers.sniff(str(path)) == "TEXT"
    if layout == "pts":
        with pytest.raises(CloudFileError, match=f"its first line declares {len(p) + 1:,} points but {len(p):,} rows"):
            readers.read_cloud(str(path))
        return
    cloud = readers.read_cloud(str(path))
    np.testing.assert_array_equal(cloud.positions, p)
    if layout == "csv_header":
        np.testing.assert_allclose(cloud.colours[:, :3], srgb_to_linear(rgb / 255.0), atol=1e-6)


@pytest.mark.parametrize("content, message", [
    (b"0 0 0\r1 1 1\r2 2\r3 3 3\r", "data line 3 (after 0 header lines) has 2 values"),
    (b"0 0 0\r1 1 1\r2 2 \xe9\r", "byte 16, 0xe9, on line 3"),
    (b"0 0 0\r\n1 1 1\r\n2 2 \xe9\r\n", "byte 18, 0xe9, on line 3"),
])
def test_cr_only_text_errors_name_the_right_line(tmp_path, content, message):
    path = tmp_path / "ragged.xyz"
    path.write_bytes(content)
    with pytest.raises(CloudFileError, match=re.escape(message)):
        readers.read_cloud(str(path))


# --- LAS / LAZ ---------------------------------------------------------------------------

def _write_las(path, p, rgb=None, compress=False, point_format=3):
    import laspy

    header = laspy.LasHeader(point_format=point_format, version="1.2")
    header.offsets = np.floor(p.min(axis=0))
    header.scales = [0.001, 0.001, 0.001]
    las = laspy.LasData(header)
    las.x, las.y, las.z = p[:, 0], p[:, 1], p[:, 2]
    las.intensity = np.arange(len(p)) % 60000
    las.classification = np.arange(len(p)) % 7
    las.return_number = 1 + np.arange(len(p)) % 3
    if rgb is not None:
        las.red, las.green, las.blue = rgb.T
    las.write(str(path), laz_backend=laspy.LazBackend.Lazrs if compress else None)


@pytest.mark.parametrize("bits, compress", [(8, False), (16, False), (16, True), (8, True)])
def test_las_and_laz_round_trip(tmp_path, bits, compress):
    p = np.column_stack([RNG.uniform(0, 100, 2000) + 5e5, RNG.uniform(0, 100, 2000) + 4e6, RNG.uniform(0, 2, 2000)])
    p = np.round(p, 3)
    rgb8 = RNG.integers(0, 256, size=(2000, 3))
    rgb = rgb8 * 257 if bits == 16 else rgb8
    path = tmp_path / ("scan.laz" if compress else "scan.las")
    _write_las(path, p, rgb, compress)
    assert readers.sniff(str(path)) == "LAS"
    cloud = readers.read_cloud(str(path))
    assert cloud.format == ("LAZ" if compress else "LAS")
    np.testing.assert_allclose(cloud.positions, p, atol=1e-6)  # scale 0.001 and offset applied in float64
    np.testing.assert_allclose(cloud.colours[:, :3], srgb_to_linear(rgb8 / 255.0), atol=1e-6)
    np.testing.assert_array_equal(cloud.attributes["classification"], np.arange(2000) % 7)
    np.testing.assert_array_equal(cloud.attributes["intensity"], np.arange(2000) % 60000)
    np.testing.assert_array_equal(cloud.attributes["return_number"], 1 + np.arange(2000) % 3)
    prepared = prepare.prepare(cloud, str(path))  # no normals: estimated, oriented up
    assert prepared.normals_estimated and (prepared.cloud.normals[:, 2] > 0.9).all()


def test_las_lying_count_truncation_and_laz_without_backend(tmp_path, monkeypatch):
    import laspy

    p = np.column_stack([RNG.uniform(0, 10, (300, 2)), np.zeros(300)])
    path = tmp_path / "scan.las"
    _write_las(path, p)
    data = path.read_bytes()
    (tmp_path / "short.las").write_bytes(data[:-50])
    (tmp_path / "long.las").write_bytes(data + b"\0" * 34)  # one more record than the header says
    for name, message in (("short.las", "early end-of-file"), ("long.las", "more bytes follow")):
        with pytest.raises(CloudFileError, match=message) as err:
            readers.read_cloud(str(tmp_path / name))
        assert name in str(err.value)
    laz = tmp_path / "scan.laz"
    _write_las(laz, p, compress=True)
    monkeypatch.setattr(laspy.LazBackend, "detect_available", staticmethod(lambda: ()))
    with pytest.raises(CloudFileError, match="no LAZ backend") as err:
        readers.read_cloud(str(laz))
    assert str(laz) in str(err.value)


def _write_las14_with_evlrs(path, compress=False):
    import laspy
    from laspy.vlrs.vlrlist import VLRList

    header = laspy.LasHeader(point_format=6, version="1.4")
    header.scales = [0.001, 0.001, 0.001]
    las = laspy.LasData(header)
    las.x, las.y, las.z = RNG.uniform(0, 10, (200, 3)).T
    las.evlrs = VLRList([laspy.VLR("test", 1, "one", b"x" * 100), laspy.VLR("test", 2, "two", b"y" * 10)])
    las.write(str(path), laz_backend=laspy.LazBackend.Lazrs if compress else None)


def _patched(path, out, fmt, at, *values):
    data = bytearray(path.read_bytes())
    struct.pack_into(fmt, data, at, *values)
    out.write_bytes(bytes(data))
    return out


# (file, struct format, header offset, value, what the message names): the LAS public
# header's fields (header size 94, offset to point data 96, number of VLRs 100, scales
# 131.., offsets 155.., LAS 1.4's start of the first EVLR 235 and number of EVLRs 243)
_CORRUPT_HEADERS = [
    ("las12", "<I", 100, 0xFFFFFFF0, "number of VLRs (4,294,967,280) cannot fit"),
    ("las12", "<I", 100, 1, "number of VLRs (1) cannot fit"),  # one more than fit: none
    ("laz14", "<I", 100, 3, "number of VLRs (3) cannot fit"),
    ("las14", "<I", 243, 0xFFFFFFF0, "number of EVLRs (4,294,967,280) cannot fit"),
    ("laz14", "<I", 243, 1 << 20, "number of EVLRs (1,048,576) cannot fit"),
    ("las14", "<I", 243, 3, "EVLR 3 of 3 would start"),  # fits by count, not after the real two's data
    ("las14", "<Q", 235, 1 << 40, "start of the first EVLR"),
    ("las14", "<Q", 235, 0, "start of the first EVLR"),
    ("las12", "<I", 96, 1 << 31, "offset to point data"),
    ("las12", "<H", 94, 100, "size (100) is smaller than a LAS 1.2 header's 227 bytes"),
    ("laz14", "<H", 94, 235, "size (235) is smaller than a LAS 1.4 header's 375 bytes"),
    ("las12", "<d", 131, 0.0, "x scale is 0.0"),
    ("las14", "<d", 147, float("nan"), "z scale is nan"),
    ("laz14", "<d", 139, 0.0, "y scale is 0.0"),
    ("las12", "<d", 163, float("inf"), "y offset is inf"),
]


@pytest.mark.parametrize("kind, fmt, at, value, message", _CORRUPT_HEADERS)
def test_las_header_counts_and_scales_are_checked_before_laspy_reads(tmp_path, monkeypatch, kind, fmt, at, value,
                                                                      message):
    """laspy loops over the header's VLR and EVLR counts past the end of the file (a count of
    4 billion: hours, memory growing, no progress call): the counts are checked against the
    file first, and laspy never sees such a file. A zero or NaN scale is refused too (it
    would flatten or erase an axis)."""
    import laspy

    good = tmp_path / f"good_{kind}.las"
    if kind == "las12":
        _write_las(good, np.column_stack([RNG.uniform(0, 10, (300, 2)), np.zeros(300)]))
    else:
        _write_las14_with_evlrs(good, compress=kind == "laz14")
    assert len(readers.read_cloud(str(good))) > 0  # unpatched, each imports
    path = _patched(good, tmp_path / f"bad_{kind}.las", fmt, at, value)

    def untouched(*args, **kwargs):
        raise AssertionError("laspy was handed a file whose header cannot be right")

    monkeypatch.setattr(laspy, "open", untouched)
    for read in (readers.read_cloud, importer.load):  # the importer's memory check reads the header too
        with pytest.raises(CloudFileError, match=re.escape(message)) as err:
            read(str(path))
        assert str(path) in str(err.value)


def test_las_evlr_lengths_are_checked_against_the_file(tmp_path):
    good = tmp_path / "good.las"
    _write_las14_with_evlrs(good)
    start = struct.unpack_from("<Q", good.read_bytes(), 235)[0]
    for at, value, message in ((start + 20, 1 << 62, "EVLR 1 of 2 declares 4,611,686,018,427,387,904 bytes"),
                               (start + 20, 160, "EVLR 2 of 2 would start")):  # the second moved to the end
        path = _patched(good, tmp_path / "bad.las", "<Q", at, value)
        with pytest.raises(CloudFileError, match=re.escape(message)):
            readers.read_cloud(str(path))


@pytest.mark.parametrize("kind", ["laz12", "laz14"])
@pytest.mark.parametrize("chunks, at_end", [(0xF3896B63, False), (0xFFFFFFFF, True), ("one too many", False)])
def test_laz_chunk_table_count_is_checked_before_lazrs_allocates(tmp_path, monkeypatch, kind, chunks, at_end):
    """lazrs allocates the number of chunks a LAZ chunk table declares before decoding any
    entry, and a failed allocation in Rust aborts the process (a fuzzed file: 65 GB asked,
    Blender gone). The count is checked against the compressed bytes before the table (each
    chunk takes at least one), wherever lazrs finds the table: at the offset the point data
    starts with, or at the one in the file's last 8 bytes when that is not written."""
    import laspy

    good = tmp_path / "good.laz"
    if kind == "laz12":
        _write_las(good, RNG.uniform(0, 10, (300, 3)), compress=True)
    else:
        _write_las14_with_evlrs(good, compress=True)
    data = bytearray(good.read_bytes())
    offset = struct.unpack_from("<I", data, 96)[0]
    table = struct.unpack_from("<q", data, offset)[0]
    assert struct.unpack_from("<I", data, table + 4)[0] >= 1  # the real table: one chunk or more
    if chunks == "one too many":
        chunks = table - offset - 8 + 1
    struct.pack_into("<I", data, table + 4, chunks)
    if at_end:  # the table found through the file's last 8 bytes (the point data's own are -1)
        struct.pack_into("<q", data, offset, -1)
        data += struct.pack("<q", table)  # after the EVLRs of LAS 1.4: they stay where the header says
    path = tmp_path / "bad.laz"
    path.write_bytes(bytes(data))

    def untouched(*args, **kwargs):
        raise AssertionError("laspy was handed a LAZ file whose chunk table cannot be right")

    monkeypatch.setattr(laspy, "open", untouched)
    for read in (readers.read_cloud, importer.load):
        with pytest.raises(CloudFileError, match=f"its chunk table declares {chunks:,} chunks of points") as err:
            read(str(path))
        assert str(path) in str(err.value)


@pytest.mark.parametrize("chunk_size, available", [(3_607_101_776, None), (1_000_000, 8 << 20)])
def test_laz_chunk_larger_than_memory_is_refused_before_lazrs_decompresses(tmp_path, monkeypatch, chunk_size,
                                                                           available):
    """lazrs's parallel decompressor allocates a whole chunk (its declared points times the
    record length) at once, and a failed allocation in Rust aborts the process: a LAZ VLR
    whose fixed chunk size was corrupted to 3.6 billion asked for 94 GB (a fuzzed file). A
    chunk that cannot fit in the memory available is refused, naming it; laspy never reads."""
    import laspy

    from splat_tracer.util import resources

    good = tmp_path / "good.laz"
    _write_las(good, RNG.uniform(0, 10, (300, 3)), compress=True)
    data = bytearray(good.read_bytes())
    vlr = data.find(b"laszip encoded") - 2  # the VLR header starts with 2 reserved bytes
    struct.pack_into("<I", data, vlr + 54 + 12, chunk_size)  # the LAZ VLR's chunk size (fixed-size chunks)
    path = tmp_path / "bad.laz"
    path.write_bytes(bytes(data))
    monkeypatch.setattr(resources, "_override", available)

    def untouched(*args, **kwargs):
        raise AssertionError("laspy was handed a LAZ file with a chunk larger than memory")

    monkeypatch.setattr(laspy, "open", untouched)
    with pytest.raises(CloudFileError, match=f"chunk 1 of its 1 declares {chunk_size:,} points") as err:
        readers.read_cloud(str(path))
    assert str(path) in str(err.value) and "memory" in str(err.value)


@pytest.mark.parametrize("layer, size", [(6, 0xFFFFFFFF), (0, "one too many")])
def test_laz_layer_sizes_are_checked_against_their_chunk(tmp_path, monkeypatch, layer, size):
    """A layered LAZ chunk (LAS 1.4 point formats 6-10) starts with its first point, its
    point count and each layer's byte size; lazrs zero-fills a buffer of each size before
    reading it: a fuzzed size of 3.4 GB made a 1 KB file take 10 s and 4 GB of memory to be
    refused (or abort the process with less memory). Sizes beyond the chunk are refused."""
    import laspy

    good = tmp_path / "good.laz"
    _write_las14_with_evlrs(good, compress=True)  # point format 6: one Point14 item, 9 layers
    data = bytearray(good.read_bytes())
    offset, record_length = struct.unpack_from("<I", data, 96)[0], struct.unpack_from("<H", data, 105)[0]
    sizes_at = offset + 8 + record_length + 4
    sizes = struct.unpack_from("<9I", data, sizes_at)
    chunk = record_length + 4 + 36 + sum(sizes)
    if size == "one too many":
        size = sizes[layer] + 1
    struct.pack_into("<I", data, sizes_at + 4 * layer, size)
    path = tmp_path / "bad.laz"
    path.write_bytes(bytes(data))

    def untouched(*args, **kwargs):
        raise AssertionError("laspy was handed a LAZ file whose layers cannot fit in their chunk")

    monkeypatch.setattr(laspy, "open", untouched)
    declared = sum(sizes) - sizes[layer] + size
    with pytest.raises(CloudFileError, match=f"the layers of chunk 1 of 1 declare {declared:,} bytes but the chunk "
                                             f"holds {chunk - record_length - 40:,}") as err:
        readers.read_cloud(str(path))
    assert str(path) in str(err.value)


@pytest.mark.parametrize("panic", ["file", "any panic while reading"])
def test_laz_decompressor_panic_is_a_cloud_file_error(tmp_path, monkeypatch, panic):
    """A LAZ VLR whose chunk size is 0 in a small LAS 1.4 file with an EVLR: lazrs's Rust
    code panics ('capacity overflow'; a fuzzed file: a remainder by zero), which pyo3
    raises as PanicException, a BaseException that escaped the reader's `except Exception`.
    It is a CloudFileError naming the file; so is a panic anywhere in the reading loop."""
    import laspy
    from laspy.vlrs.vlrlist import VLRList

    header = laspy.LasHeader(point_format=6, version="1.4")
    header.scales = [0.001, 0.001, 0.001]
    las = laspy.LasData(header)
    las.x, las.y, las.z = RNG.uniform(0, 10, (40, 3)).T
    las.evlrs = VLRList([laspy.VLR("test", 1, "one", b"x" * 100)])
    path = tmp_path / "bad.laz"
    las.write(str(path), laz_backend=laspy.LazBackend.Lazrs)
    message = "capacity overflow"
    if panic == "file":
        data = bytearray(path.read_bytes())
        vlr = data.find(b"laszip encoded") - 2
        struct.pack_into("<I", data, vlr + 54 + 12, 0)  # the LAZ VLR's chunk size
        path.write_bytes(bytes(data))
    else:
        PanicException = type("PanicException", (BaseException,), {})  # as pyo3 makes it
        message = "index out of bounds"

        def panics(self, *args, **kwargs):
            raise PanicException(message)

        monkeypatch.setattr(laspy.LasReader, "chunk_iterator", panics)
    for read in (readers.read_cloud, importer.load):
        with pytest.raises(CloudFileError, match=f"the decompressor failed on its data: {message}") as err:
            read(str(path))
        assert str(path) in str(err.value)


def _within(seconds, read, path):
    """read(path) on a thread: its result, its exception, or 'hang' after `seconds`."""
    import threading

    outcome = []

    def run():
        try:
            outcome.append(read(path))
        except Exception as e:  # noqa: BLE001 -- the caller judges it
            outcome.append(e)

    worker = threading.Thread(target=run, daemon=True)
    worker.start()
    worker.join(seconds)
    return outcome[0] if outcome else "hang"


@pytest.mark.parametrize("kind", ["las12", "las14", "laz14"])
def test_mutated_las_headers_import_or_are_refused_never_hang(tmp_path, kind):
    """Random bytes and 32-bit words written over a LAS/LAZ file's header fields, its VLRs
    and EVLRs (a count of 2^32 - 1 among them): each file imports or is refused with a
    CloudFileError, within seconds; none hangs in laspy or escapes as another exception."""
    good = tmp_path / "good.las"
    if kind == "las12":
        _write_las(good, np.column_stack([RNG.uniform(0, 10, (300, 2)), np.zeros(300)]))
    else:
        _write_las14_with_evlrs(good, compress=kind == "laz14")
    base = good.read_bytes()
    fields = [94, 96, 100, 104, 105, 107, 131, 155] + ([235, 239, 243, 247] if kind != "las12" else [])
    rng = np.random.default_rng(11)
    outcomes = {"imported": 0, "refused": 0}
    for k in range(150):
        data = bytearray(base)
        for _ in range(int(rng.integers(1, 4))):
            if rng.uniform() < 0.5:
                at = int(rng.choice(fields))
                word = int(rng.choice([0, 1, 3, 1 << 16, 1 << 31, 0xFFFFFFFF, int(rng.integers(0, 1 << 32))]))
                data[at:at + 4] = struct.pack("<I", word)
            else:
                data[int(rng.integers(0, len(base)))] = int(rng.integers(0, 256))
        path = tmp_path / f"mutated_{k}.las"
        path.write_bytes(bytes(data))
        got = _within(20, readers.read_cloud, str(path))
        assert got != "hang", f"{path.name} hung"
        assert not isinstance(got, Exception) or isinstance(got, CloudFileError), f"{path.name}: {got!r}"
        outcomes["refused" if isinstance(got, CloudFileError) else "imported"] += 1
        path.unlink()
    assert outcomes["imported"] and outcomes["refused"]  # the mutations reach both


# --- E57 ---------------------------------------------------------------------------------

def test_e57_round_trip_with_scanner_positions(tmp_path):
    import pye57

    path = tmp_path / "scans.e57"
    stations = [np.array([0.0, 0.0, 1.5]), np.array([10.0, 0.0, 1.5])]
    p, nrm = fibonacci_sphere(4000, radius=1.0, centre=(5.0, 3.0, 1.0))  # an object both stations see
    faces = [np.einsum("ij,ij->i", nrm, s - p) > 0 for s in stations]  # what each station sees
    halves = [p[faces[0]], p[faces[1] & ~faces[0]]]
    with pye57.E57(str(path), mode="w") as e57:
        for station, pts in zip(stations, halves):
            local = pts - station
            rgb = np.tile([200, 100, 50], (len(pts), 1)).astype(np.uint8)
            e57.write_scan_raw({"cartesianX": local[:, 0], "cartesianY": local[:, 1], "cartesianZ": local[:, 2],
                                "colorRed": rgb[:, 0], "colorGreen": rgb[:, 1], "colorBlue": rgb[:, 2],
                                "intensity": np.full(len(pts), 0.5)},
                               rotation=np.array([1.0, 0, 0, 0]), translation=station)
    assert readers.sniff(str(path)) == "E57"
    cloud = readers.read_cloud(str(path))
    got = np.concatenate(halves)
    np.testing.assert_allclose(cloud.positions, got, atol=1e-6)  # pye57 writes single-precision coordinates
    np.testing.assert_allclose(cloud.scanners, np.repeat(stations, [len(h) for h in halves], axis=0))
    np.testing.assert_allclose(cloud.colours[0, :3], srgb_to_linear(np.array([200, 100, 50]) / 255), atol=1e-6)
    prepared = prepare.prepare(cloud, str(path))
    assert prepared.normals_oriented == "SCANNER"
    towards = np.einsum("ij,ij->i", prepared.cloud.normals, cloud.scanners - got)
    seen = np.concatenate([nrm[faces[0]], nrm[faces[1] & ~faces[0]]])
    grazing = np.abs(np.einsum("ij,ij->i", seen, cloud.scanners - got)) < 0.2 * np.linalg.norm(cloud.scanners - got,
                                                                                                 axis=1)
    assert (towards[~grazing] > 0).all()  # each point faces the station that saw it...
    assert (np.einsum("ij,ij->i", prepared.cloud.normals, seen) > 0).all()  # ...grazing ones via their neighbours


def _crc32c(data: bytes) -> int:
    crc = 0xFFFFFFFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ (0x82F63B78 if crc & 1 else 0)
    return crc ^ 0xFFFFFFFF


def _patch_e57(path, old: bytes, new: bytes):
    """The E57 file with `old` (in its XML) replaced by `new` of the same length, each page's
    checksum made right again (E57 pages: 1020 bytes and their big-endian CRC-32C), so that
    libE57 reads the change as the file's own."""
    data = bytearray(path.read_bytes())
    at = data.find(old)
    assert at >= 0 and len(old) == len(new)
    data[at:at + len(old)] = new
    for page in {at // 1024, (at + len(old) - 1) // 1024}:
        start = page * 1024
        data[start + 1020:start + 1024] = struct.pack(">I", _crc32c(bytes(data[start:start + 1020])))
    path.write_bytes(bytes(data))
    return path


def _write_scans(path, scans):
    """scans: (name, points, rotation, translation); each scan's points in its own frame."""
    import pye57

    with pye57.E57(str(path), mode="w") as e57:
        for name, p, rotation, translation in scans:
            e57.write_scan_raw({"cartesianX": p[:, 0], "cartesianY": p[:, 1], "cartesianZ": p[:, 2],
                                "intensity": np.full(len(p), 0.5)},
                               rotation=np.asarray(rotation, float), translation=np.asarray(translation, float),
                               name=name)
    return path


@pytest.mark.parametrize("declared, chunk", [(9000, None), (4001, None), (9000, 1000)])
def test_e57_records_beyond_the_file_are_not_imported(tmp_path, monkeypatch, declared, chunk):
    """A scan whose XML declares more records than its binary section holds: what libE57
    reads is what is imported (pye57's read_scan kept the unread entries of its buffer:
    garbage points), and the note names the scan."""
    from splat_tracer.pointcloud.readers import e57

    if chunk:  # the short scan ends in the middle of the reading loop
        monkeypatch.setattr(e57, "_E57_CHUNK", chunk)
    north = RNG.uniform(-5, 5, (3000, 3))
    south = RNG.uniform(-5, 5, (4000, 3))
    path = _write_scans(tmp_path / "scans.e57", [("north", north, [1, 0, 0, 0], [0, 0, 0]),
                                                ("south", south, [1, 0, 0, 0], [10, 0, 0])])
    _patch_e57(path, b'recordCount="4000"', f'recordCount="{declared}"'.encode())
    first = readers.read_cloud(str(path))
    assert len(first) == 7000
    np.testing.assert_allclose(first.positions, np.concatenate([north, south + [10, 0, 0]]), atol=1e-6)
    assert f"scan 1 ('south') declares {declared:,} points but holds 4,000: the 4,000 were read" in first.notes
    np.testing.assert_array_equal(readers.read_cloud(str(path)).positions, first.positions)  # nothing left to chance


def test_e57_read_in_chunks_gives_the_same_points(tmp_path, monkeypatch):
    from splat_tracer.pointcloud.readers import e57

    scans = [(f"s{k}", RNG.normal(size=(2500 + k, 3)), RNG.normal(size=4), RNG.normal(size=3)) for k in range(2)]
    path = _write_scans(tmp_path / "scans.e57", scans)
    whole = readers.read_cloud(str(path))
    monkeypatch.setattr(e57, "_E57_CHUNK", 999)
    chunked = readers.read_cloud(str(path))
    np.testing.assert_array_equal(chunked.positions, whole.positions)
    np.testing.assert_array_equal(chunked.scanners, whole.scanners)
    np.testing.assert_array_equal(chunked.attributes["intensity"], whole.attributes["intensity"])


@pytest.mark.parametrize("rotation, translation, reason", [
    ([0, 0, 0, 0], [5, 0, 0], "its rotation quaternion [0.0, 0.0, 0.0, 0.0] has zero length"),
    ([1e200, 0, 0, 1e200], [5, 0, 0], "has no finite length"),
    ([1e-200, 0, 0, 0], [5, 0, 0], "has zero length"),  # its square underflows: no rotation to normalise
])
def test_e57_scan_with_an_unusable_pose_is_left_out_by_name(tmp_path, rotation, translation, reason):
    """One scan whose pose cannot place its points (they collapsed to one point, reported as
    'duplicates merged'): left out and named, the other scans import; alone, the file is
    refused naming it."""
    north = RNG.uniform(-5, 5, (2000, 3))
    path = _write_scans(tmp_path / "scans.e57", [("north", north, [1, 0, 0, 0], [0, 0, 0]),
                                                ("south", RNG.uniform(-5, 5, (1500, 3)), rotation, translation)])
    cloud = readers.read_cloud(str(path))
    np.testing.assert_allclose(cloud.positions, north, atol=1e-6)
    assert cloud.merged_duplicates == 0
    assert any("1 of 2 scans left out" in n and "scan 1 ('south'): its rotation quaternion" in n and reason in n
               for n in cloud.notes), cloud.notes
    alone = _write_scans(tmp_path / "alone.e57", [("south", RNG.uniform(-5, 5, (1500, 3)), rotation, translation)])
    with pytest.raises(CloudFileError, match=re.escape(reason)) as err:
        readers.read_cloud(str(alone))
    assert str(alone) in str(err.value) and "scan 0 ('south')" in str(err.value)


@pytest.mark.parametrize("rotation, translation, reason", [
    ([np.nan, 0, 0, 1], [0, 0, 0], "rotation quaternion [nan, 0.0, 0.0, 1.0] is not finite"),
    ([1, 0, 0, 0], [0, np.inf, 0], "translation [0.0, inf, 0.0] is not finite"),
    ([1, 0, 0, 0], [np.nan, 0, 0], "translation [nan, 0.0, 0.0] is not finite"),
    ([0, 0, 0, 0], [0, 0, 0], "has zero length"),
    ([2, 0, 0, 0], [1e300, 0, 0], ""),  # not unit: normalised, as pye57 does; a far but finite translation
])
def test_e57_pose_check(rotation, translation, reason):
    """libE57 reads a NaN or infinite number in the XML as 0 or the largest double, so that
    these reach the check only from other readers of the format: tested on the header alone."""
    from types import SimpleNamespace

    from splat_tracer.pointcloud.readers import e57

    header = SimpleNamespace(has_pose=lambda: True, rotation=np.array(rotation, float),
                             translation=np.array(translation, float))
    assert e57._bad_pose(header).endswith(reason) and bool(e57._bad_pose(header)) == bool(reason)


# --- Gaussian splatting ------------------------------------------------------------------

def _blanked_e57(path, out, start: bytes, end: bytes, after: bytes, nul_after_xml: bool = False):
    """The E57 file with the first XML span from `start` to `end` (included) that follows
    `after` blanked out with spaces (the XML's length kept), on its logical bytes (the pages
    without their checksums), each page's checksum written again. nul_after_xml: the XML's
    length in the file header counts a NUL after it (libE57 ignores it)."""
    data = path.read_bytes()
    logical = bytearray(b"".join(data[k:k + 1020] for k in range(0, len(data), 1024)))
    a = logical.find(start, logical.find(after))
    b = logical.find(end, a) + len(end)
    assert 0 <= a < b
    logical[a:b] = b" " * (b - a)
    if nul_after_xml:
        end_of_xml = logical.rfind(b"</e57Root>") + len(b"</e57Root>")
        assert end_of_xml + 2 <= len(logical)
        logical[end_of_xml:end_of_xml + 2] = b"\n\0"
        struct.pack_into("<Q", logical, 32, struct.unpack_from("<Q", logical, 32)[0] + 1)  # xmlLogicalLength
    pages = [bytes(logical[k:k + 1020]) for k in range(0, len(logical), 1020)]
    out.write_bytes(b"".join(p + struct.pack(">I", _crc32c(p)) for p in pages))
    return out


@pytest.mark.parametrize("scan, nul, message", [
    ("south", False, "the points of scan 1 ('south') have no prototype"),
    ("north", False, "the points of scan 0 ('north') have no prototype"),
    ("south", True, "the points of scan 1 ('south') have no prototype"),  # a NUL after the XML (a fuzzed file)
])
def test_e57_scan_libe57_would_crash_on_is_refused_by_name(tmp_path, scan, nul, message):
    """A scan whose points lost their prototype (a fuzzed file): pye57's scan header made
    libE57 dereference a null node, a segmentation fault that takes Blender down. The XML is
    checked first (by the reader and the importer's memory check), naming the scan."""
    import subprocess
    import sys

    good = _write_scans(tmp_path / "good.e57", [("north", RNG.normal(size=(30, 3)), [1, 0, 0, 0], [0, 0, 0]),
                                                ("south", RNG.normal(size=(40, 3)), [1, 0, 0, 0], [5, 0, 0])])
    path = _blanked_e57(good, tmp_path / "bad.e57", b"<prototype", b"</prototype>", after=f"[{scan}]".encode(),
                        nul_after_xml=nul)
    index = 0 if scan == "north" else 1
    crash = subprocess.run([sys.executable, "-c", f"import pye57, sys; pye57.E57(sys.argv[1]).get_header({index})",
                            str(path)], capture_output=True)
    assert crash.returncode < 0  # what libE57 does with it, unguarded: a signal, the process gone
    for read in (readers.read_cloud, importer.load):
        with pytest.raises(CloudFileError, match=re.escape(message)) as err:
            read(str(path))
        assert str(path) in str(err.value)


def _quaternions(matrices):
    from scipy.spatial.transform import Rotation

    xyzw = Rotation.from_matrix(matrices).as_quat()
    return np.column_stack([xyzw[:, 3], xyzw[:, :3]])  # (w, x, y, z) as 3DGS stores them


def _plane_frames(n, normal, rng):
    """n rotations (N,3,3) whose third column is `normal` (sign random), first two a random tangent frame."""
    normal = np.asarray(normal, float) / np.linalg.norm(normal)
    helper = np.array([1.0, 0, 0]) if abs(normal[0]) < 0.9 else np.array([0, 1.0, 0])
    t1 = np.cross(normal, helper)
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(normal, t1)
    a = rng.uniform(0, 2 * np.pi, n)
    u = np.cos(a)[:, None] * t1 + np.sin(a)[:, None] * t2
    sign = rng.choice([-1.0, 1.0], n)
    m = sign[:, None] * normal
    v = np.cross(m, u)
    return np.stack([u, v, m], axis=2)


def write_gaussians(path, positions, frames, scales, dc_colour, opacity, three_d=True, f_rest=0):
    """A Gaussian-splatting PLY: frames (N,3,3) rotations, scales (N,3 or 2) standard deviations."""
    from plyfile import PlyData, PlyElement

    names = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"] + [f"f_rest_{i}" for i in range(f_rest)]
    names += ["opacity"] + [f"scale_{i}" for i in range(3 if three_d else 2)] + [f"rot_{i}" for i in range(4)]
    rows = np.zeros(len(positions), dtype=[(n, "f4") for n in names])
    for k, c in enumerate("xyz"):
        rows[c] = positions[:, k]
    dc = (np.asarray(dc_colour, float) - 0.5) / gaussians.C0
    for k in range(3):
        rows[f"f_dc_{k}"] = dc[:, k]
    rows["opacity"] = np.log(opacity / (1 - opacity))
    for k in range(scales.shape[1]):
        rows[f"scale_{k}"] = np.log(scales[:, k])
    q = _quaternions(frames) * RNG.uniform(0.5, 2.0, (len(positions), 1))  # stored unnormalised
    for k in range(4):
        rows[f"rot_{k}"] = q[:, k]
    PlyData([PlyElement.describe(rows, "vertex")]).write(str(path))


def gaussian_plane(path, normal, three_d, n_side=60, half=1.0, seed=3):
    """Gaussians on the plane through the origin with `normal`: left half (x < 0) one colour,
    right half another. 3DGS: the smallest scale along the normal, in a random column."""
    rng = np.random.default_rng(seed)
    g = (np.arange(n_side) + 0.5) / n_side * 2 * half - half
    u, v = (a.ravel() for a in np.meshgrid(g, g))
    frames = _plane_frames(len(u), normal, rng)
    positions = u[:, None] * np.array([1.0, 0, 0]) + v[:, None] * np.cross(normal, [1.0, 0, 0]) / np.linalg.norm(
        np.cross(normal, [1.0, 0, 0]))
    step = 2 * half / n_side
    scales = np.column_stack([np.full(len(u), 0.7 * step), np.full(len(u), 0.5 * step)])
    if three_d:  # the thin axis goes to a random slot: the reader must find it by its scale
        scales = np.column_stack([scales, np.full(len(u), 0.01 * step)])
        slot = rng.integers(0, 3, len(u))
        for k in range(len(u)):
            perm = [(j - slot[k] + 2) % 3 for j in range(3)]  # a cyclic shift: still a rotation
            frames[k] = frames[k][:, perm]
            scales[k] = scales[k][perm]
    colour = np.where((u < 0)[:, None], [0.8, 0.3, 0.2], [0.2, 0.4, 0.9])
    opacity = np.full(len(u), 0.98)
    write_gaussians(path, positions, frames, scales, colour, opacity, three_d, f_rest=9 if three_d else 0)
    return positions, colour, step


@pytest.mark.parametrize("three_d", [True, False], ids=["3DGS", "2DGS"])
def test_gaussian_splat_ply_round_trip(tmp_path, three_d):
    normal = np.array([0.0, np.sin(np.radians(30)), np.cos(np.radians(30))])
    path = tmp_path / "capture.ply"
    positions, colour, step = gaussian_plane(path, normal, three_d)
    cloud = readers.read_cloud(str(path))
    assert cloud.format == ("3DGS" if three_d else "2DGS") and not cloud.oriented
    np.testing.assert_allclose(cloud.positions, positions, atol=1e-6)
    np.testing.assert_allclose(np.abs(cloud.normals @ normal), 1.0, atol=1e-5)  # the thin axis, either sign
    np.testing.assert_allclose(cloud.radii, 2 * np.sqrt(0.7 * 0.5) * step, rtol=1e-5)
    np.testing.assert_allclose(cloud.colours[:, :3], srgb_to_linear(colour), atol=1e-5)
    np.testing.assert_allclose(cloud.colours[:, 3], 0.98, atol=1e-5)  # sigmoid(opacity)
    prepared = prepare.prepare(cloud, str(path))
    signs = prepared.cloud.normals @ normal
    assert (signs > 0.999).all() or (signs < -0.999).all()  # one side for all
    assert (signs > 0).all()  # a flat capture faces up
    assert any("f_rest" in note for note in prepared.notes(6)) is three_d


def test_gaussian_ply_missing_fields(tmp_path):
    path = tmp_path / "g.ply"
    path.write_text("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
                    "property float f_dc_0\nproperty float f_dc_1\nproperty float f_dc_2\nproperty float opacity\n"
                    "property float scale_0\nproperty float scale_1\nproperty float scale_2\nend_header\n"
                    "0 0 0 0 0 0 1 0 0 0\n")
    with pytest.raises(CloudFileError, match="Gaussian.*rot_0, rot_1, rot_2, rot_3") as err:
        readers.read_cloud(str(path))
    assert str(path) in str(err.value)


# --- normal estimation -------------------------------------------------------------------

def _thin_plate(n=30000, half=1.0, thickness=0.05, seed=5):
    """A closed box 2 x 2 x 0.05 sampled uniformly by area (spacing ~0.017, the plate ~3 spacings thick)."""
    rng = np.random.default_rng(seed)
    areas = np.array([4 * half ** 2] * 2 + [2 * half * thickness] * 4)
    counts = np.round(n * areas / areas.sum()).astype(int)
    pts, nrm = [], []
    for face, c in enumerate(counts):
        u = rng.uniform(-1, 1, (c, 2))
        s = 1.0 if face % 2 == 0 else -1.0
        if face < 2:
            p, m = np.column_stack([u * half, np.full(c, s * thickness / 2)]), [0, 0, s]
        elif face < 4:
            p, m = np.column_stack([np.full(c, s * half), u[:, 0] * half, u[:, 1] * thickness / 2]), [s, 0, 0]
        else:
            p, m = np.column_stack([u[:, 0] * half, np.full(c, s * half), u[:, 1] * thickness / 2]), [0, s, 0]
        pts.append(p)
        nrm.append(np.tile(m, (c, 1)))
    return np.concatenate(pts), np.concatenate(nrm).astype(float)


# Measured (k = 16): sphere (20k random points) median 0.3 deg, 95th pct 0.8 deg, worst 1.8; plane 0 deg;
# cube (40 per edge) 0 deg on the faces, about 32 deg at the points within ~2 spacings of an
# edge (a plane fitted across a crease); thin plate 0 deg on its faces, up to 81 deg on its
# rims (the 0.05 side faces are only 3 spacings wide). Tolerances: `away` points (farther
# than 3 spacings from any crease) within `tol` degrees; every point on the right side.
@pytest.mark.parametrize("name", ["sphere", "plane", "cube", "thin plate"])
def test_estimated_normals_agree_with_the_truth_and_are_consistently_oriented(name):
    if name == "sphere":
        p, truth = random_sphere(20000, radius=3.0, seed=6)
        away, tol = np.ones(len(p), bool), 2.0
    elif name == "plane":
        p = np.column_stack([RNG.uniform(-1, 1, (20000, 2)), np.zeros(20000)]) @ _plane_frames(1, [1, 2, 3], RNG)[0].T
        truth = np.tile(_plane_frames(1, [1, 2, 3], RNG)[0][:, 2], (20000, 1))
        away, tol = np.ones(len(p), bool), 0.1
    elif name == "cube":
        p, truth = cube_cloud(40)
        away, tol = (np.sort(1 - np.abs(p), axis=1)[:, 1] > 3 * 2 / 40), 0.1
    else:
        p, truth = _thin_plate()
        on_top = np.abs(truth[:, 2]) == 1
        away, tol = on_top & (np.abs(p[:, :2]) < 1 - 3 * 0.017).all(axis=1), 0.1
    axes = normals.estimate(p)
    unsigned = np.minimum(angle_deg(axes, truth), 180 - angle_deg(axes, truth))
    assert np.percentile(unsigned[away], 99) < tol, np.percentile(unsigned[away], [50, 99, 100])
    result = normals.orient(p, axes)
    cos = np.einsum("ij,ij->i", result.normals, truth)
    if name == "plane":  # no inside: one side for all
        assert (cos > 0).all() or (cos < 0).all()
    else:  # outward everywhere: no flipped patch, not even at creases
        assert (cos > 0).all(), f"{(cos <= 0).sum()} points flipped"
    assert result.ambiguous.sum() < 0.01 * len(p)


def test_propagated_normals_of_an_open_hilly_terrain_face_up():
    """An open sheet has no outward side: its farthest corner's slope decided the sign of all
    its normals (a 10M-point terrain came out facing down); its normals, which mostly agree,
    now face up whatever the corner's slope."""
    for seed in range(3):
        rng = np.random.default_rng(seed)
        xy = rng.uniform(0, 100, (20000, 2))
        a, b = 2 * np.pi / 17, 2 * np.pi / 23
        z = 1.2 * np.sin(a * xy[:, 0] + seed) * np.cos(b * xy[:, 1])
        up = np.column_stack([-1.2 * a * np.cos(a * xy[:, 0] + seed) * np.cos(b * xy[:, 1]),
                              1.2 * b * np.sin(a * xy[:, 0] + seed) * np.sin(b * xy[:, 1]), np.ones(len(xy))])
        p = np.column_stack([xy, z])
        result = normals.orient(p, normals.estimate(p))
        cos = np.einsum("ij,ij->i", result.normals, up / np.linalg.norm(up, axis=1, keepdims=True))
        assert (cos > 0).all(), f"seed {seed}: {(cos <= 0).sum()} of {len(p)} face down"


def test_up_and_scanner_orientation_fall_back_to_neighbours_where_the_rule_is_unclear():
    p, truth = cube_cloud(30)
    building = truth[:, 2] > -0.5  # what an aerial scan sees of a box: its roof and walls
    p, truth = p[building], truth[building]
    result = normals.orient(p, normals.estimate(p) * RNG.choice([-1, 1], (len(p), 1)), "UP")
    cos = np.einsum("ij,ij->i", result.normals, truth)
    top = truth[:, 2] > 0.5
    assert (cos[top] > 0).all()
    walls = np.abs(truth[:, 2]) < 0.5  # perpendicular to up: their sign comes from the top face
    assert (cos[walls & (np.sort(1 - np.abs(p), axis=1)[:, 1] > 0.2)] > 0).mean() > 0.99


# --- bad input ---------------------------------------------------------------------------

@pytest.mark.parametrize("name, content, message", [
    ("empty.xyz", b"", "empty"),
    ("nan.xyz", b"nan nan nan\nnan 1 2\n", "no point has finite coordinates"),
    ("ragged.xyz", b"0 0 0\n1 1 1\n2 2\n3 3 3\n", "data line 3 (after 0 header lines) has 2 values"),
    ("words.csv", b"x,y,z\n0,0,0\n1,oops,1\n", "not all numbers"),
    ("lying.pts", b"5\n0 0 0\n1 1 1\n2 2 2\n", "declares 5 points but 3 rows"),
    ("binary.xyz", b"\x00\x01\x02garbage\xff", "not a point-cloud format"),
    ("notext.xyz", b"header only\nno numbers here\n", "no row of at least three numbers"),
    ("e57.e57", b"ASTM-E57" + b"\0" * 100, "not a valid E57"),
    ("las.las", b"LASF" + b"\0" * 100, "not a valid LAS/LAZ"),
])
def test_bad_inputs_are_refused_naming_the_file(tmp_path, name, content, message):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(CloudFileError) as err:
        prepare.prepare(readers.read_cloud(str(path)), str(path))
    assert str(path) in str(err.value) and message in str(err.value), str(err.value)


def _not_a_file(tmp_path, kind):
    import os

    path = tmp_path / f"scan_{kind}.ply"
    if kind == "folder":
        path.mkdir()
    elif kind == "fifo":
        os.mkfifo(path)
    elif kind == "loop":
        os.symlink(tmp_path / "other.ply", path)
        os.symlink(path, tmp_path / "other.ply")
    elif kind == "self_loop":
        os.symlink(path, path)
    elif kind == "dangling":
        os.symlink(tmp_path / "gone.ply", path)
    elif kind == "in_a_file":  # a path through a file, as if it were a folder
        (tmp_path / "plain.ply").write_text("ply\n")
        path = tmp_path / "plain.ply" / "scan.ply"
    return path


@pytest.mark.parametrize("kind, message", [
    ("folder", "is a folder, not a file"),
    ("fifo", "is a named pipe (FIFO), not a file"),
    ("loop", "a symbolic link that loops"),
    ("self_loop", "a symbolic link that loops"),
    ("dangling", "a symbolic link to '"),
    ("missing", "no such file"),
    ("in_a_file", "no such file (a part of the path before its name is not a folder)"),
])
def test_paths_that_are_not_files_are_refused_saying_what_they_are(tmp_path, kind, message):
    """Each was 'no such file' (a folder, a FIFO, a loop of links all exist); a FIFO must
    never be opened (that waits for a writer forever): each read runs on a thread here, so
    that a regression fails rather than hangs."""
    import threading

    path = _not_a_file(tmp_path, kind)
    for read in (readers.read_cloud, importer.load, ply.read_ply):
        outcome = []

        def run():
            try:
                read(str(path))
                outcome.append(None)
            except Exception as e:  # noqa: BLE001 -- checked below
                outcome.append(e)

        worker = threading.Thread(target=run, daemon=True)
        worker.start()
        worker.join(10)
        assert outcome, f"{read.__name__} did not return for a {kind}"
        assert isinstance(outcome[0], CloudFileError), outcome[0]
        assert str(path) in str(outcome[0]) and message in str(outcome[0]), str(outcome[0])


def test_ply_without_normals_is_imported_with_estimated_normals(tmp_path):
    from plyfile import PlyData, PlyElement

    p, truth = fibonacci_sphere(5000, centre=(4e5, 5e6, 30.0))
    rows = np.zeros(len(p), dtype=[("x", "f8"), ("y", "f8"), ("z", "f8")])
    rows["x"], rows["y"], rows["z"] = p.T
    path = tmp_path / "bare.ply"
    PlyData([PlyElement.describe(rows, "vertex")]).write(str(path))
    prepared = prepare.prepare(readers.read_cloud(str(path)), str(path))
    assert prepared.normals_estimated and prepared.hood.closed_guess
    assert angle_deg(prepared.cloud.normals.astype(float), truth).max() < 2.0  # outward, within 2 degrees
    assert any("no normals: estimated" in note for note in prepared.notes(6))


# --- Blender -----------------------------------------------------------------------------

def test_import_operator_reads_las_by_content_and_keeps_attributes(blender, empty_scene, tmp_path):
    bpy = blender
    p = np.column_stack([RNG.uniform(0, 10, (500, 2)), RNG.uniform(0, 0.01, 500)])
    path = tmp_path / "scan.dat.ply"  # a misleading name: the content decides
    _write_las(path, p, RNG.integers(0, 65536, (500, 3)))
    bpy.ops.splat_tracer.import_cloud(filepath=str(path))
    obj = bpy.context.active_object
    attrs = obj.data.attributes
    assert {"splat_normal", "splat_radius", "splat_color", "intensity", "classification", "return_number"} <= set(
        attrs.keys())
    cls = np.empty(len(obj.data.vertices), np.int32)
    attrs["classification"].data.foreach_get("value", cls)
    assert set(cls) <= set(range(7)) and obj["splat_tracer_format"] == "LAS"
    nrm = np.empty(len(obj.data.vertices) * 3, np.float32)
    attrs["splat_normal"].data.foreach_get("vector", nrm)
    assert (nrm.reshape(-1, 3)[:, 2] > 0.9).all()  # estimated, upward
    # re-estimation on the object, another orientation
    for o in bpy.context.view_layer.objects:
        o.select_set(o == obj)
    assert bpy.ops.splat_tracer.estimate_normals(orientation="PROPAGATE", normal_neighbours=12) == {"FINISHED"}


@pytest.mark.parametrize("three_d", [True, False], ids=["3DGS", "2DGS"])
def test_gaussian_capture_renders_with_its_colours_and_orientation(blender, empty_scene, tmp_path, three_d):
    from blender_helpers import add_camera, render_to_exr

    bpy, scene = blender, empty_scene
    tilt = np.radians(30)
    normal = np.array([0.0, -np.sin(tilt), np.cos(tilt)])
    path = tmp_path / "capture.ply"
    gaussian_plane(path, normal, three_d)
    bpy.ops.splat_tracer.import_cloud(filepath=str(path))
    scene.splat_tracer.lighting = "HEADLIGHT"
    add_camera(bpy, scene, (0.0, 0.0, 4.0), (0.0, 0.0, 0.0))  # looking down -Z
    out = render_to_exr(bpy, scene, tmp_path / "gs.exr", 160, 120)
    half_width = 4.0 * 18 / 50  # world units across half the image at the plane's centre
    for x, colour in ((-0.4, [0.8, 0.3, 0.2]), (0.4, [0.2, 0.4, 0.9])):
        col, row = int(round((x / half_width + 1) / 2 * 160)), 60
        view = np.array([x, 0.0, 4.0]) / np.linalg.norm([x, 0.0, 4.0])  # towards the camera
        expected = srgb_to_linear(np.array(colour)) * abs(view @ normal)  # headlight: colour x |cos|
        np.testing.assert_allclose(out["rgba"][row, col, :3], expected, rtol=0.05)
        n = out["normal"][row, col]
        assert abs(n @ normal) > 0.99, n  # the Gaussians' thin axis


@pytest.mark.parametrize("radius", [1e30, 2e18, np.float32(3e38)])
def test_a_radius_beyond_the_renderers_limit_is_dropped_and_counted(tmp_path, radius):
    """What imports renders: a file radius the renderer would refuse (its limit, the core's
    MAX_COORDINATE) drops that point at import, counted in the notes."""
    p, n = fibonacci_sphere(500)
    radii = np.full(500, 0.05, np.float32)
    radii[4] = radius
    path = tmp_path / "huge.ply"
    ply.write_ply(str(path), p, n, radii=radii)
    cloud = readers.read_cloud(str(path))
    assert len(cloud) == 499 and cloud.dropped_radii == 1 and cloud.radii.max() == np.float32(0.05)
    notes = prepare.prepare(cloud, str(path)).notes(6)
    assert "1 points with a radius beyond the renderer's limit (1e+18) were dropped" in notes, notes


def test_a_gaussian_whose_scale_overflows_the_renderers_limit_is_dropped(tmp_path):
    """A 3DGS log-scale of 88 (exp(88) is about 1.7e38, finite) gave a radius the reader
    accepted and the renderer refused."""
    normal = np.array([0.0, 0.0, 1.0])
    path = tmp_path / "capture.ply"
    gaussian_plane(path, normal, True)
    from plyfile import PlyData

    data = PlyData.read(str(path), mmap=False)
    data["vertex"].data["scale_0"][7] = data["vertex"].data["scale_1"][7] = 88.0
    data.write(str(path))
    cloud = readers.read_cloud(str(path))
    assert len(cloud) == 60 * 60 - 1 and cloud.dropped_radii == 1
    assert cloud.radii.max() < 1.0
