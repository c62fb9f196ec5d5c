"""Reading point clouds with normals from PLY files (ascii, binary little/big endian).

Parsing is plyfile's (a maintained PLY library), but for the rows of an ascii file, which
the core's number parser reads (readers/numbers.py, _text_vertices); this module checks
what the file means for a splat renderer and turns every problem into a `CloudFileError`
that names the file and the problem, so that the importer can refuse it before creating
anything.
"""
from __future__ import annotations

import io
import os
import re
from typing import Optional

import numpy as np

from ...util.columns import finite_rows, in_blocks
from ..cloud import (INTEGER_COLOUR_SCALES, CloudFileError, PointCloud, check_file, linear_colours, make_cloud,
                     srgb_to_linear, unit_colours)
from . import gaussians
from .numbers import lf_line_ends, parse_numbers


# A header is a few lines per element and property, plus comments: scanners write a few
# kilobytes of metadata there. 4 MiB is a thousand times that and still parses in about a
# second (plyfile reads a header one character at a time, ~0.3 s per MiB); anything longer
# is not a header, and is refused before plyfile spends minutes on it.
MAX_HEADER_BYTES = 4 << 20
_SCAN_CHUNK = 1 << 16  # the header is searched for its end this many bytes at a time
# The least an ascii row can take per property: one character and one separator (a space,
# or the newline after the last one); a list property's count is such a property. A row
# of an element without properties is at least its newline.
_ASCII_MIN_BYTES_PER_PROPERTY = 2
_ROW_START = re.compile(r"^[ \t]*\S", re.MULTILINE)  # an ascii line that is not blank


def _header_length(path: str) -> tuple[int, bytes]:
    """(length, bytes) of the header: up to and including the header's last line, the first line that is exactly
    `end_header` (as plyfile reads it: lines end with the newline that follows `ply`, so
    a comment that mentions end_header does not end the header)."""
    with open(path, "rb") as f:
        buf = bytearray(f.read(5))
        for start, nl in ((b"ply\r\n", b"\r\n"), (b"ply\n", b"\n"), (b"ply\r", b"\r")):
            if buf.startswith(start):
                break
        else:
            raise CloudFileError(f"{path}: not a valid PLY file (it does not start with a 'ply' line)")
        marker = nl + b"end_header" + nl
        too_long = CloudFileError(f"{path}: the header is longer than {MAX_HEADER_BYTES >> 20} MiB (no "
                                  f"'end_header' line within its first {MAX_HEADER_BYTES:,} bytes); "
                                  "this is not a PLY header")
        searched = 0
        while (at := buf.find(marker, searched)) < 0:
            if len(buf) > MAX_HEADER_BYTES:
                raise too_long
            searched = max(0, len(buf) - len(marker) + 1)
            chunk = f.read(_SCAN_CHUNK)
            if not chunk:
                raise CloudFileError(f"{path}: not a valid PLY file (no 'end_header' line ends its header)")
            buf += chunk
    end = at + len(marker)
    if end > MAX_HEADER_BYTES:
        raise too_long
    return end, bytes(buf[:end])


def read_header(path: str):
    """(header length in bytes, the header as plyfile's PlyData with no data read)."""
    from plyfile import PlyData

    length, head = _header_length(path)
    try:
        head.decode("ascii")
    except UnicodeDecodeError as e:
        line = head[:e.start].count(b"\n") + 1
        raise CloudFileError(f"{path}: the PLY header is not ASCII text (byte {e.start}, 0x{head[e.start]:02x}, on "
                             f"line {line}); PLY headers are ASCII (re-export the file, or remove the comment "
                             "that has the character)") from None
    try:
        # plyfile has no public header-only reader; _parse_header is what PlyData.read
        # itself calls first (plyfile is pinned, 1.0.3, and bundled as such).
        header = PlyData._parse_header(io.BytesIO(head))  # refuses duplicate property names, unknown types
    except Exception as e:  # plyfile raises several types; all mean "malformed"
        raise CloudFileError(f"{path}: not a valid PLY file ({e})") from None
    return length, header


def _min_row_bytes(element, text: bool, byte_order: str) -> int:
    """The fewest bytes a row of this element can take in the file."""
    if text:
        return _ASCII_MIN_BYTES_PER_PROPERTY * len(element.properties) or 1
    size = 0
    for prop in element.properties:
        if hasattr(prop, "list_dtype"):  # a list may be empty: only its count is certain
            size += np.dtype(prop.list_dtype(byte_order)[0]).itemsize
        else:
            size += np.dtype(prop.dtype(byte_order)).itemsize
    return size


def _check_declared_sizes(path: str, header, header_len: int) -> None:
    """Refuses, before anything is allocated, counts that the file is too small to hold
    (plyfile allocates every element's declared rows before reading them: a tiny file
    declaring a billion rows cost a minute and gigabytes before it failed)."""
    available = os.path.getsize(path) - header_len
    needed = 0
    for element in header.elements:
        if element.count < 0:
            raise CloudFileError(f"{path}: the header declares a negative count for '{element.name}'")
        row = _min_row_bytes(element, header.text, header.byte_order)
        left = available - needed  # after the elements before this one
        needed += element.count * row
        if needed > available:
            raise CloudFileError(
                f"{path}: early end-of-file: the header declares {element.count:,} '{element.name}' rows, "
                f"at least {element.count * row:,} bytes ({row} a row), but only {max(left, 0):,} bytes "
                "of the file are left for them")


def _check_no_lists(path: str, header) -> None:
    """Refuses a list-typed vertex property among those a splat is read from (`property list
    uchar float x`): each is one number per vertex, and a list (of any length, per row) has
    no meaning as one."""
    for element in header.elements:
        if element.name != "vertex":
            continue
        for prop in element.properties:
            if hasattr(prop, "list_dtype") and prop.name in _USED_PROPERTIES:
                raise CloudFileError(f"{path}: the vertex property '{prop.name}' is a list ('{prop}'); a splat's "
                                     f"'{prop.name}' is one number per vertex")


def _declared(ply) -> str:
    return " and ".join(f"{e.count:,} '{e.name}'" for e in ply.elements) + " rows"


def _check_nothing_follows(path: str, ply, f) -> None:
    """plyfile stops reading after the declared counts; data left after the last element
    means a count in the header lies (e.g. a vertex count smaller than the data, whose
    first rows alone would otherwise be imported), which we refuse. `f` is the stream
    plyfile read from, positioned where it stopped."""
    if ply.text:  # whitespace may follow the last row; any other text is more rows
        rows = 0
        try:
            while chunk := f.read(_SCAN_CHUNK):
                chunk += f.readline()  # whole lines, so that no row is counted twice
                rows += len(_ROW_START.findall(chunk))
        except UnicodeDecodeError:
            raise CloudFileError(f"{path}: the header declares {_declared(ply)} but non-ascii data follow "
                                 "them") from None
        if rows:
            raise CloudFileError(f"{path}: the header declares {_declared(ply)} but {rows:,} more rows follow "
                                 "them (a count in the header is wrong)")
        return
    extra = os.fstat(f.fileno()).st_size - f.tell()
    if extra:
        raise CloudFileError(f"{path}: the header declares {_declared(ply)} but {extra:,} more bytes follow "
                             "them (a count in the header is wrong)")


def _text_vertices(path: str, header, header_len: int) -> Optional[np.ndarray]:
    """The vertex rows of an ascii PLY, as plyfile reads them, parsed by the core's number
    table (readers/numbers.py) on all cores: plyfile parses an ascii file a value at a time
    in Python, and an element the importer does not use costs the same (a Stanford range
    scan's 204,800 'range_grid' rows of lists: 1.5-4 s for its 40,256 vertices). The other
    elements are only checked to hold their rows (each row's count of values: a property
    each, or a list's length and its items), so that a count in the header that lies is
    still refused. None where plyfile is left to read the file and say what is wrong with
    it: a row that does not parse or does not fit, a blank line among the rows, a list
    property among the vertex's, an element of another shape, an integer property with a
    value its type cannot hold."""
    elements = list(header.elements)
    if [e.name for e in elements].count("vertex") != 1 or any(not e.properties for e in elements):
        return None
    vertex = header["vertex"]
    if any(hasattr(p, "list_dtype") for p in vertex.properties):
        return None
    # Read, not mapped: a mapped file cut short by another program while it is parsed would
    # kill Blender with SIGBUS; reading costs 0.08 s of a 138 MB, 1M-point file's 0.45 s.
    with open(path, "rb") as f:
        f.seek(header_len)
        data = f.read()
    table = parse_numbers(lf_line_ends(data))  # plyfile reads lines ended by CR LF, LF or CR too
    del data  # the values are what is needed from here on
    per_line, offsets = table.per_line, table.offsets()
    total = sum(e.count for e in elements)
    if len(per_line) < total or per_line[total:].any():  # rows missing, or more rows follow
        return None
    # Lines holding a token that is not a number, as a mask over lines (few: usually none).
    bad = np.zeros(len(per_line), bool)
    bad[table.bad_lines] = True
    row, out = 0, None
    for element in elements:
        first, row = row, row + element.count
        counts = per_line[first:row]
        width = len(element.properties)
        if element is vertex:
            if element.count == 0:  # refused by read_ply, naming it
                out = np.empty(0, element.dtype())
                continue
            # A value that is not a number, a row of another length, a blank line among the rows.
            if bad[first:row].any() or (counts != width).any():
                return None
            values = table.values[offsets[first]:offsets[row]].reshape(element.count, width)
            out = np.empty(element.count, element.dtype())
            for i, prop in enumerate(element.properties):
                column = values[:, i]
                kind = np.dtype(prop.dtype())
                with np.errstate(invalid="ignore"):  # NaN into an integer: refused just below
                    out[prop.name] = column
                # plyfile refuses '1.5' or 300 for an integer type: let it say so. A value kept
                # by the cast is an integer within the type's range (PLY's integers have at most
                # 32 bits: every one is exact in float64).
                if np.dtype(prop.dtype()).kind in "ui" and not (out[prop.name] == column).all():
                    return None
            continue
        if (counts == 0).any():
            return None
        if not any(hasattr(p, "list_dtype") for p in element.properties):
            if (counts != width).any():
                return None
        elif width == 1:  # one list (faces, a range grid): its length, then its items
            if bad[first:row].any():
                return None
            values = table.values[offsets[first]:offsets[row]]
            if (values[offsets[first:row] - offsets[first]] != counts - 1).any():
                return None
        else:
            return None
    return out


def read_ply(path: str) -> PointCloud:
    """Reads vertices with x y z, nx ny nz, optional red green blue [alpha], optional radius."""
    from plyfile import PlyData  # imported here: only reading needs it

    path = os.fspath(path)
    check_file(path)
    header_len, header = read_header(path)
    _check_declared_sizes(path, header, header_len)
    _check_no_lists(path, header)
    v = _text_vertices(path, header, header_len) if header.text else None
    if v is None:
        # Read from our own stream (ascii: text, as plyfile wants it) to see where it stops.
        with (open(path, "r", encoding="ascii", newline="") if header.text else open(path, "rb")) as f:
            try:
                ply = PlyData.read(f)
            except Exception as e:  # plyfile raises several types; all mean "malformed"
                raise CloudFileError(f"{path}: not a valid PLY file ({e})") from None
            _check_nothing_follows(path, ply, f)
        if "vertex" not in ply:
            raise CloudFileError(f"{path}: has no 'vertex' element")
        v = ply["vertex"].data
    names = set(v.dtype.names or ())
    missing = [c for c in "xyz" if c not in names]
    if missing:
        raise CloudFileError(f"{path}: vertices lack the coordinate(s) {', '.join(missing)}")
    n = len(v)
    if n == 0:
        raise CloudFileError(f"{path}: contains no vertices")
    if gaussians.is_gaussian(names):  # a 3D or 2D Gaussian-splatting capture is a PLY of its own kind
        return gaussians.read_gaussians(path, v, names)

    # Coordinates (float32 when the file's are, else float64), normals (float32 is enough for
    # a direction; make_cloud makes them unit) and 8/16-bit colours (by table) in one pass
    # over the records, a block of rows at a time on all cores (10M points: 1.2 s field by
    # field, 0.2 s this way).
    rgb = ("red", "green", "blue")
    single = all(v[c].dtype == np.float32 for c in "xyz")
    pos = np.empty((n, 3), np.float32 if single else np.float64)
    normals = np.empty((n, 3), np.float32) if {"nx", "ny", "nz"} <= names else None
    colours, scale = None, None
    if set(rgb) <= names:
        colours = np.empty((n, 4), np.float32)  # filled in place: no (N,4) temporaries
        kind = {v[c].dtype for c in rgb}
        scale = INTEGER_COLOUR_SCALES.get(kind.pop()) if len(kind) == 1 else None

    def convert(b: int, e: int) -> None:
        block = v[b:e]
        for i, c in enumerate("xyz"):
            pos[b:e, i] = block[c]
        if normals is not None:
            for i, c in enumerate(("nx", "ny", "nz")):
                normals[b:e, i] = block[c]
        if scale is not None:
            linear_colours([block[c] for c in rgb], int(scale), out=colours[b:e])

    in_blocks(convert, n)

    radii = None
    if "radius" in names:
        radii = v["radius"].astype(np.float32)
        # rows without finite coordinates are dropped and counted (make_cloud): their radius does not matter
        bad = ~(np.isfinite(radii) & (radii > 0)) & finite_rows(pos)
        if bad.any():
            raise CloudFileError(f"{path}: {int(bad.sum())} vertices have a radius that is not a positive "
                                 f"number (first: row {np.flatnonzero(bad)[0]})")

    if colours is not None:
        if scale is None:  # other types: their range decides (see _COLOUR_RANGES)
            colours[:, :3] = srgb_to_linear(unit_colours(path, v, rgb))
        colours[:, 3] = unit_colours(path, v, ("alpha",))[:, 0] if "alpha" in names else 1.0
    ignored = [p.name for p in header["vertex"].properties if p.name not in _KNOWN_PROPERTIES]
    notes = [f"vertex properties ignored (not a splat's): {', '.join(ignored)}"] if ignored else []
    others = [f"'{e.name}' ({e.count:,} rows)" for e in header.elements if e.name != "vertex"]
    if others:
        notes.append(f"elements ignored (only the vertices are points): {', '.join(others)}")
    return make_cloud(path, pos, normals, colours, radii, drop_non_finite=True, notes=notes)


# The vertex properties a (non-Gaussian) PLY is read for; others are ignored and said.
_KNOWN_PROPERTIES = {"x", "y", "z", "nx", "ny", "nz", "red", "green", "blue", "alpha", "radius"}
# Every vertex property either reader (this one, gaussians.py) takes a number from.
_USED_PROPERTIES = _KNOWN_PROPERTIES | set(gaussians.GAUSSIAN_FIELDS) | {"scale_2"}


def write_ply(path: str, positions, normals, colours=None, radii=None, binary: bool = True,
              byte_order: str = "<") -> None:
    """Writes a point cloud as PLY (tests, the demo and benchmarks use it). Colours are
    written as 8-bit sRGB from scene-linear floats. normals None: positions without normals
    (the importer estimates them)."""
    from plyfile import PlyData, PlyElement

    pos = np.asarray(positions, dtype=np.float64)
    fields = [("x", "f8"), ("y", "f8"), ("z", "f8")]
    if normals is not None:
        fields += [("nx", "f4"), ("ny", "f4"), ("nz", "f4")]
    if colours is not None:
        fields += [("red", "u1"), ("green", "u1"), ("blue", "u1")]
    if radii is not None:
        fields += [("radius", "f4")]
    rows = np.empty(len(pos), dtype=fields)
    for k, c in enumerate("xyz"):
        rows[c] = pos[:, k]
        if normals is not None:
            rows["n" + c] = np.asarray(normals)[:, k]
    if colours is not None:
        lin = np.clip(np.asarray(colours, dtype=np.float64)[:, :3], 0, 1)
        srgb = np.where(lin <= 0.0031308, lin * 12.92, 1.055 * lin ** (1 / 2.4) - 0.055)
        for k, c in enumerate(("red", "green", "blue")):
            rows[c] = np.round(srgb[:, k] * 255)
    if radii is not None:
        rows["radius"] = radii
    PlyData([PlyElement.describe(rows, "vertex")], text=not binary, byte_order=byte_order).write(path)
