"""readers/numbers.py (native/pointcloud/numbers.h): the number-table parser the ASCII readers share."""
import re
import sys

import numpy as np
import pytest

from splat_tracer import _core
from splat_tracer.pointcloud import readers
from splat_tracer.pointcloud.cloud import CloudFileError
from splat_tracer.pointcloud.readers.numbers import parse_numbers

RNG = np.random.default_rng(27)

# Spellings at the edges of the grammar and of float64, each one token.
EDGE = [
    "0", "-0", "+0", "0.0", "-0.0", "00012", "1.", "5.", ".5", "+.5", "-.5", "+5.", "1e5", "1E5", "1e+5", "1e-5",
    "1.5E-05", ".5e1", "5.e1", "-1.25e+002", "1e0", "1e-0", "1e000000000000000000000001",
    "inf", "-inf", "+inf", "Inf", "INF", "infinity", "-Infinity", "INFINITY", "iNfInItY",
    "1e308", "1.7976931348623157e308", "1.7976931348623158e308", "1.7976931348623159e308", "-1.8e308",
    "1e309", "1e400", "-1e400", "1e99999999999999999999999", "9" * 400,
    "2.2250738585072014e-308", "2.2250738585072011e-308", "4.9e-324", "5e-324", "-5e-324",
    "2.4703282292062327e-324", "2.4703282292062328e-324", "2.5e-324", "1e-320", "1e-400", "-1e-400",
    "1e-99999999999999999999", "0e99999999999999", "0.000000000000000000000000000001e30",
    "0." + "0" * 400 + "1e400", "1" * 800 + "e-800", "3." + "1415926535897932384626433832795028841971" * 20,
    "9007199254740993", "9007199254740992.5", "0.1", "0.30000000000000004", "123456789012345678901234567890",
    "4503599627370496.5", "4503599627370497.5", "2.0000000000000002",
    # halfway between 1 and the next float64, and a hair either side
    "1.00000000000000011102230246251565404236316680908203125",
    "1.00000000000000011102230246251565404236316680908203124",
    "1.00000000000000011102230246251565404236316680908203126",
]
# numpy reads these too, but its NaN has no sign: compared as NaN.
NANS = ["nan", "NaN", "NAN", "-nan", "+nan", "nAn"]
# float() refuses these, and so do numpy and the parser.
NOT_NUMBERS = ["+", "-", ".", "+.", "e5", ".e5", "1e", "1e+", "1e-", "1.5e3e4", "--1", "+-1", "-+1", "1-2", "1+",
               "0x10", "0X1p3", "1,5", "1d5", "in", "infinit", "infinityy", "nana", "inf1",
               "1\x002", "\x00", "1\xc3\xa9", "1.2.3", "..5", "5..", "1e5.5", "e", "--", "\x7f", "1/2"]
# float() reads these (underscores, digits of other scripts: UTF-8 bytes here); numpy and the parser do not.
FLOAT_ONLY = ["1_000", "\xd9\xa3", "\xef\xbc\x91"]
# np.fromstring reads C's 'nan(chars)'; float(), np.loadtxt (the PLY reader's parse before) and the parser do not.
NUMPY_ONLY = ["nan(1)"]


def _bits(a):
    return np.asarray(a, np.float64).view(np.int64)


def _random_tokens(n):
    """Random float64 values in many spellings: repr, %.17g, %.3e, short and very long
    mantissas, random digit strings with random exponents, subnormals."""
    out = []
    values = np.concatenate([RNG.normal(size=n) * 10.0 ** RNG.integers(-30, 30, n),
                             RNG.integers(-2**62, 2**62, n).view(np.float64)])  # every exponent, subnormals too
    for v in values:
        if not np.isfinite(v):
            continue
        out += [repr(float(v)), "%.17g" % v, "%.3e" % v, "%.25g" % v, "%.40e" % v]
    for _ in range(n):
        digits = "".join(RNG.choice(list("0123456789"), RNG.integers(1, 60)))
        point = RNG.integers(0, len(digits) + 1)
        out.append(f"{digits[:point]}.{digits[point:]}e{RNG.integers(-340, 320)}")
    return out


def test_values_equal_python_floats_on_tricky_and_random_numbers():
    tokens = EDGE + _random_tokens(3000)
    signs = ["", "-", "+"]
    tokens = [signs[k % 3] + t if t[0] not in "+-" else t for k, t in enumerate(tokens)]
    data = "\n".join(" ".join(tokens[k:k + 7]) for k in range(0, len(tokens), 7)).encode()
    table = parse_numbers(data)
    assert table.ok and len(table.values) == len(tokens)
    expected = np.array([float(t) for t in tokens])
    np.testing.assert_array_equal(_bits(table.values), _bits(expected))  # -0.0, subnormals, inf: bit for bit
    with np.testing.suppress_warnings():  # and numpy's own parse agrees
        np.testing.assert_array_equal(_bits(table.values), _bits(np.fromstring(data, sep=" ")))


def test_nan_spellings_and_what_is_not_a_number():
    table = parse_numbers(" ".join(NANS).encode())
    assert table.ok and np.isnan(table.values).all() and len(table.values) == len(NANS)
    for token in NOT_NUMBERS + FLOAT_ONLY + NUMPY_ONLY:
        if token not in FLOAT_ONLY:
            with pytest.raises(ValueError):
                float(token.encode("latin-1").decode("utf-8", "replace"))
        if token not in NUMPY_ONLY:
            with pytest.warns(DeprecationWarning):  # numpy: "could not be read to its end"
                np.fromstring(token.encode("latin-1"), sep=" ")
        data = b"1 2\n3 " + token.encode("latin-1") + b" 4\n5"
        table = parse_numbers(data)
        assert table.bad_lines.tolist() == [1], token
        assert table.per_line.tolist() == [2, 3, 1], token
        assert np.isnan(table.values[3]) and table.values[[0, 1, 2, 4, 5]].tolist() == [1, 2, 3, 4, 5], token


def test_lines_are_counted_blank_ones_and_the_last_one_without_its_newline():
    cases = {
        b"": [], b"\n": [0], b"   ": [0], b"1": [1], b"1\n": [1], b"1 2 3\n\n4 5\n6": [3, 0, 2, 1],
        b"\t1\v2\f3\r\n 4 \n\n": [3, 1, 0], b"1\r2\r3": [3], b"\n\n1\n": [0, 0, 1],
    }
    for data, counts in cases.items():
        table = parse_numbers(data)
        assert table.ok and table.per_line.tolist() == counts, data
        assert table.offsets().tolist() == np.concatenate([[0], np.cumsum(counts)]).tolist()


def test_pieces_and_threads_do_not_change_the_result():
    tokens = _random_tokens(500) + EDGE
    lines = []
    for k in range(3000):
        row = [tokens[(k * 5 + j) % len(tokens)] for j in range(k % 9)]  # rows of 0 to 8 values
        if k % 97 == 5:
            row.append("oops")  # a few bad lines, to be numbered across the pieces
        lines.append(" ".join(row))
    data = "\n".join(lines).encode()
    one = parse_numbers(data, threads=1, chunk_bytes=len(data) + 1)
    for threads, chunk in [(1, 1), (2, 1), (2, 7), (0, 4096), (3, 1 << 20)]:
        other = parse_numbers(data, threads=threads, chunk_bytes=chunk)
        np.testing.assert_array_equal(_bits(other.values), _bits(one.values))
        np.testing.assert_array_equal(other.per_line, one.per_line)
        np.testing.assert_array_equal(other.bad_lines, one.bad_lines)
    assert one.bad_lines.tolist() == [k for k in range(3000) if k % 97 == 5]
    assert one.per_line.tolist() == [k % 9 + (k % 97 == 5) for k in range(3000)]


def test_hostile_input_is_read_or_refused_never_crashes():
    huge = b"1" * (8 << 20)  # one 8 MiB token: its value, and its line is one line
    table = parse_numbers(huge + b"e-8388607 2", chunk_bytes=1024)
    assert table.ok and table.values.tolist() == [float("1" * 50 + "e-49"), 2.0] and table.per_line.tolist() == [2]
    table = parse_numbers(huge + b"x\n" + huge, chunk_bytes=1024)  # pieces cut only at line ends
    assert table.bad_lines.tolist() == [0] and table.values[1] == np.inf and table.per_line.tolist() == [1, 1]
    noise = RNG.integers(0, 256, 1 << 16, dtype=np.uint8).tobytes()  # NULs, non-ASCII bytes, anything
    table = parse_numbers(noise, chunk_bytes=100)
    assert len(table.per_line) == noise.count(b"\n") + (not noise.endswith(b"\n"))
    assert len(table.values) == sum(len(line.split()) for line in noise.split(b"\n"))
    assert parse_numbers(bytearray(b"1 2")).values.tolist() == [1, 2]  # any buffer
    assert parse_numbers(memoryview(b"9 1 2 3")[2:]).values.tolist() == [1, 2, 3]
    assert parse_numbers(np.frombuffer(b"4 5", np.uint8)).values.tolist() == [4, 5]


def test_bad_arguments_raise():
    with pytest.raises(TypeError, match="bytes"):
        _core.parse_numbers("1 2 3")
    with pytest.raises(TypeError, match="buffer"):
        _core.parse_numbers(memoryview(b"1 2 3 4")[::2])
    with pytest.raises(TypeError):
        _core.parse_numbers(12)
    with pytest.raises(ValueError, match="threads"):
        _core.parse_numbers(b"1", -1)
    with pytest.raises(ValueError, match="chunk_bytes"):
        _core.parse_numbers(b"1", 0, 0)


@pytest.mark.parametrize("name, content, message", [
    # A short row followed by a long one holds as many numbers as the rows should: the rows
    # are checked one by one, not by their total, and the short one is named.
    ("shifted.xyz", b"0 0 0\n1 1\n2 2 2 2\n3 3 3\n",
     "data line 2 (after 0 header lines) has 2 values where the first row has 3"),
    ("shifted.pcd", b"# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 3\n"
                    b"HEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 3\nDATA ascii\n0 0 0\n1 1 1 1\n2 2\n",
     "data line 2 has 4 values where the header declares 3"),
    ("word.xyz", b"x y z\n0 0 0\n1 nan(2) 1\n",
     "data line 2 (after 1 header lines) is not all numbers ('1 nan(2) 1')"),
])
def test_rows_of_the_wrong_length_are_named_by_their_line(tmp_path, name, content, message):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(CloudFileError, match=re.escape(message)):
        readers.read_cloud(str(path))


def test_ascii_ply_rows_of_the_wrong_length_fall_back_to_plyfile(tmp_path):
    """A vertex row one value short, then one long: plyfile reads the rows and says what is wrong."""
    head = (b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
            b"end_header\n")
    path = tmp_path / "shifted.ply"
    path.write_bytes(head + b"0 0 0\n1 1\n2 2 2 2\n")
    with pytest.raises(CloudFileError, match="not a valid PLY file"):
        readers.read_cloud(str(path))
    path.write_bytes(head + b"0 0 0\n1 1 1\n2 2 2.5e-1\n")
    np.testing.assert_array_equal(readers.read_cloud(str(path)).positions, [[0, 0, 0], [1, 1, 1], [2, 2, 0.25]])
