"""PCD files (PCL's Point Cloud Data: depth cameras, robotics), read with pypcd4.

The header is read and checked here, within MAX_HEADER_BYTES, and then parsed by pypcd4's
own MetaData.parse_header (its pydantic model). Every count and size the header declares
is checked against the file before any data is read: pypcd4 allocates the declared points
and the declared decompressed size before it reads them, so a corrupt header in a small
file would otherwise ask for gigabytes. binary and binary_compressed data are decoded by
pypcd4; ascii data here, by the core's number parser (readers/numbers.py), whitespace-separated
as PCL splits a line (pypcd4's reader takes exactly one space between values and refuses
the tabs, runs of spaces and trailing spaces other writers leave), in float64, so that a
packed colour PCL writes as its integer, 4285098345, keeps every bit.

Fields: x y z; normal_x normal_y normal_z (PCL orients them towards the viewpoint when it
estimates them: taken as oriented, like a PLY's); a packed colour `rgb` or `rgba`, four bytes
of any type (PCL's float `rgb` and uint `rgba`): 0x00RRGGBB, or 0xAARRGGBB for `rgba`;
every other field of one value per point (intensity, label, curvature...) is kept as a point
attribute; fields of several values (a descriptor, COUNT > 1) and padding (`_`) are left
out, named in the notes. Rows whose coordinates are NaN (the holes of an organised depth
frame) are dropped and counted, and the points keep the file's row numbers (v * WIDTH + u).

VIEWPOINT (tx ty tz qw qx qy qz) is the sensor's pose in the cloud's frame: its position
(tx ty tz) is every point's scanner position, and estimated normals are oriented towards it
(the SCANNER orientation, as for an E57 scan). It is one row broadcast to every point, not
an (N,3) copy. PCL's default VIEWPOINT on an unorganised cloud (HEIGHT 1) is not taken as a
position: writers leave it when they do not know the sensor (a cloud merged from several
views), and the import's orientation decides from the geometry instead.
"""
from __future__ import annotations

import os
import re
import struct
from dataclasses import dataclass

import numpy as np

from ...util.columns import in_blocks
from ..cloud import CloudFileError, PointCloud, check_file, linear_colours, make_cloud
from .numbers import first_bad_row, lf_line_ends, parse_numbers

MAGIC = b"# .PCD"  # the comment PCL writes first; a header may also start with VERSION or FIELDS
# Without the comment, the header's lines that say what the data are: a text file may start
# with a line "Version 2.1 ..." or "fields x y z", never with all three of these.
SNIFF_KEYS = {"FIELDS", "SIZE", "TYPE"}
# PCL's header has ten lines (VERSION FIELDS SIZE TYPE COUNT WIDTH HEIGHT VIEWPOINT POINTS
# DATA) and comments: a few hundred bytes. Beyond this many without a DATA line it is not a header.
MAX_HEADER_BYTES = 1 << 20
_HEADER_LINES = 10  # pypcd4 reads at most this many lines that are not comments before DATA
_KEYS = ("VERSION", "FIELDS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT", "VIEWPOINT", "POINTS", "DATA")
_REQUIRED = ("FIELDS", "SIZE", "TYPE", "WIDTH", "POINTS", "DATA")
# Versions whose layout is 0.7's (0.6 has no VIEWPOINT, 0.5 no COUNT either: both default);
# pypcd4's model knows 0.7 only, so the others are handed to it as 0.7.
# What pypcd4's header pattern reads of a line (words, numbers, whitespace); anything else
# would silently end the line's values.
_UNREAD = re.compile(r"[^\w\s.+\-]")
_VERSIONS = (".5", "0.5", ".6", "0.6", ".7", "0.7")
_ENCODINGS = ("ascii", "binary", "binary_compressed")
# The least an ascii value can take: one character and a separator (a space or the newline).
_ASCII_MIN_BYTES_PER_VALUE = 2
# LZF's densest encoding is a back reference of 264 bytes in 3: no valid compressed block
# decompresses to more than 88 times its size, so a larger declared size is a corrupt header
# (refused before pypcd4 allocates it).
_LZF_MAX_RATIO = 88
_COMPRESSED_SIZES = struct.Struct("<II")  # compressed and decompressed size, before the LZF block
_COORDINATES = ("x", "y", "z")
NORMAL_FIELDS = ("normal_x", "normal_y", "normal_z")
_PACKED_COLOURS = ("rgb", "rgba")
_PADDING = "_"
# Point attributes the import object has of its own (cloud_object.py, the import
# operator): a field of the same name cannot be kept beside them.
_RESERVED_ATTRIBUTES = ("position", "splat_normal", "splat_radius", "splat_color", "scanner_position")
_MAX_ATTRIBUTE_NAME = 63  # Blender's longest attribute name (MAX_CUSTOMDATA_LAYER_NAME less its NUL)
_DEFAULT_VIEWPOINT = (0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)
# A VIEWPOINT coordinate beyond this is no position: its offset from the cloud, squared (a
# distance), overflows float64 to inf.
_MAX_VIEWPOINT = 1e300


@dataclass
class Header:
    metadata: object   # pypcd4.pypcd4.MetaData
    offset: int        # where the data start, in bytes
    values: int        # numbers per point (the sum of COUNT)


def is_pcd(head: bytes) -> bool:
    """Whether the file's first bytes are a PCD header: PCL's '# .PCD' comment, or (after
    comments and blank lines) header lines, up to DATA, among which FIELDS, SIZE and TYPE."""
    if head.startswith(MAGIC):
        return True
    keys = set()
    for line in head.split(b"\n")[:-1]:  # whole lines only
        line = line.strip()
        if not line or line.startswith(b"#"):
            continue
        words = line.split()
        key = words[0].decode("ascii", "replace").upper()
        if key not in _KEYS or len(words) < 2:
            break
        keys.add(key)
        if key == "DATA":
            break
    return SNIFF_KEYS <= keys


def _import_pypcd4(path: str):
    try:
        from pypcd4 import pypcd4
    except ImportError as e:  # pypcd4, or its compiled dependencies (pydantic_core, python-neo-lzf)
        raise CloudFileError(f"{path}: is a PCD file, and reading it needs the pypcd4 package and its dependencies, "
                             f"which are not installed for this platform ({e})") from None
    return pypcd4


def _header_lines(path: str) -> tuple[list[str], int]:
    """(the header's lines that are not comments, up to and including DATA; where the data start)."""
    with open(path, "rb") as f:
        head = f.read(MAX_HEADER_BYTES)
    lines, at = [], 0
    while True:
        end = head.find(b"\n", at)
        if end < 0:
            if len(head) >= MAX_HEADER_BYTES:
                raise CloudFileError(f"{path}: no DATA line within the first {MAX_HEADER_BYTES:,} bytes; this is not a "
                                     "PCD header")
            raise CloudFileError(f"{path}: not a valid PCD file (its header has no DATA line"
                                 + (f"; it ends after {', '.join(ln.split()[0] for ln in lines)})" if lines else ")"))
        raw, at = head[at:end], end + 1
        try:
            line = raw.decode("ascii").strip()
        except UnicodeDecodeError as e:
            number = head[:at].count(b"\n")
            raise CloudFileError(f"{path}: the PCD header is not ASCII text (line {number}, byte "
                                 f"0x{raw[e.start]:02x}); PCD headers are ASCII") from None
        if not line or line.startswith("#"):
            continue
        lines.append(line)
        if line.split()[0].upper() == "DATA":
            return lines, at
        if len(lines) >= _HEADER_LINES:
            raise CloudFileError(f"{path}: not a valid PCD file (no DATA line among its first {_HEADER_LINES} header "
                                 f"lines: {', '.join(ln.split()[0] for ln in lines)})")


def read_header(path: str) -> Header:
    """The header, checked (see the module's text); raises CloudFileError naming the problem."""
    pypcd4 = _import_pypcd4(path)
    lines, offset = _header_lines(path)
    tokens = {}
    for line in lines:
        bad = _UNREAD.search(line)
        if bad:  # pypcd4's header pattern would end the line's values there: say so instead
            raise CloudFileError(f"{path}: not a valid PCD file (the header line '{line[:60]}' has the character "
                                 f"{bad.group()!r}, which is not part of a name or a number)")
        key, *values = line.split()
        key = key.upper()
        if key not in _KEYS:
            raise CloudFileError(f"{path}: not a valid PCD file (unknown header line '{line[:60]}')")
        if key in tokens:
            raise CloudFileError(f"{path}: not a valid PCD file (its header has two {key} lines)")
        if not values:
            raise CloudFileError(f"{path}: not a valid PCD file (its {key} line has no value)")
        tokens[key] = values
    missing = [k for k in _REQUIRED if k not in tokens]
    if missing:
        raise CloudFileError(f"{path}: not a valid PCD file (its header lacks {', '.join(missing)})")
    version = tokens.get("VERSION", ["0.7"])[0]
    if version not in _VERSIONS:
        raise CloudFileError(f"{path}: PCD version {version} is not one this importer reads (0.5 to 0.7)")
    fields = tokens["FIELDS"]
    for key in ("SIZE", "TYPE", "COUNT"):
        got = len(tokens.get(key, fields))
        if got != len(fields):
            raise CloudFileError(f"{path}: not a valid PCD file (FIELDS names {len(fields)} fields but {key} gives "
                                 f"{got} values)")
    named = [f for f in fields if f != _PADDING]
    twice = sorted({f for f in named if named.count(f) > 1})
    if twice:
        raise CloudFileError(f"{path}: not a valid PCD file (the field(s) {', '.join(twice)} appear twice in FIELDS)")
    encoding = tokens["DATA"][0].lower()
    if encoding not in _ENCODINGS:
        raise CloudFileError(f"{path}: not a valid PCD file (DATA '{tokens['DATA'][0]}' is none of "
                             f"{', '.join(_ENCODINGS)})")
    # What pypcd4's model requires and old versions leave out: their defaults (PCL's).
    given = [line for line in lines if line.split()[0].upper() not in ("VERSION", "DATA")]
    given += ["VERSION 0.7", f"DATA {encoding}"]
    if "COUNT" not in tokens:
        given.append("COUNT " + " ".join("1" for _ in fields))
    try:
        metadata = pypcd4.MetaData.parse_header(given)
    except Exception as e:  # noqa: BLE001 -- pydantic's ValidationError, int() and float()'s ValueError
        errors = getattr(e, "errors", None)
        if callable(errors):
            first = errors()[0]
            where = ".".join(str(x) for x in first.get("loc", ())).upper()
            what = f"{where}: {first.get('msg', '')} (got {first.get('input')!r})"
        else:
            what = str(e)
        raise CloudFileError(f"{path}: not a valid PCD file (header {what})") from None
    if not len(metadata.fields) == len(metadata.size) == len(metadata.type) == len(metadata.count):
        raise CloudFileError(f"{path}: not a valid PCD file (FIELDS, SIZE, TYPE and COUNT give different numbers of "
                             "values)")
    for name, kind, size in zip(metadata.fields, metadata.type, metadata.size):
        if (kind, size) not in pypcd4.PCD_TYPE_TO_NUMPY_TYPE:
            raise CloudFileError(f"{path}: the field '{_name(name)}' has TYPE {kind} and SIZE {size}, which is no PCD "
                                 "number type (F 4/8, U and I 1/2/4/8)")
    if metadata.width * metadata.height != metadata.points:
        raise CloudFileError(f"{path}: not a valid PCD file (WIDTH {metadata.width:,} x HEIGHT {metadata.height:,} is "
                             f"not its POINTS {metadata.points:,})")
    return Header(metadata, offset, int(sum(metadata.count)))


def _name(field: str) -> str:
    """A field's name as the file writes it (pypcd4 renames padding fields '_')."""
    return _PADDING if field.startswith("#$%&~~") else field


def _check_sizes(path: str, header: Header) -> int:
    """Refuses counts and sizes the file cannot hold (see the module's text), before pypcd4
    allocates them. Returns how many bytes (fewer than a point's) follow binary points."""
    meta = header.metadata
    remaining = os.path.getsize(path) - header.offset
    n = meta.points
    row = meta.build_dtype().itemsize
    encoding = meta.data.value
    if encoding == "ascii":
        least = n * header.values * _ASCII_MIN_BYTES_PER_VALUE
        if least > remaining + 1:  # the last newline may be missing
            raise CloudFileError(f"{path}: early end-of-file: the header declares {n:,} points of {header.values} "
                                 f"values, at least {least:,} bytes as text, but only {remaining:,} bytes follow it")
        return 0
    if encoding == "binary":
        if n * row > remaining:
            raise CloudFileError(f"{path}: early end-of-file: the header declares {n:,} points of {row} bytes "
                                 f"({n * row:,} bytes) but only {remaining:,} bytes follow it")
        extra = remaining - n * row
        if extra >= row:
            raise CloudFileError(f"{path}: the header declares {n:,} points but {extra:,} more bytes follow them "
                                 "(POINTS is wrong)")
        return extra
    if n == 0:
        return 0
    if remaining < _COMPRESSED_SIZES.size:
        raise CloudFileError(f"{path}: early end-of-file: binary_compressed data need {_COMPRESSED_SIZES.size} bytes "
                             f"of sizes, and {remaining} follow the header")
    with open(path, "rb") as f:
        f.seek(header.offset)
        packed, unpacked = _COMPRESSED_SIZES.unpack(f.read(_COMPRESSED_SIZES.size))
    if unpacked != n * row:
        raise CloudFileError(f"{path}: not a valid PCD file (its compressed data decompress to {unpacked:,} bytes, "
                             f"but {n:,} points of {row} bytes are {n * row:,})")
    if packed > remaining - _COMPRESSED_SIZES.size:
        raise CloudFileError(f"{path}: early end-of-file: {packed:,} bytes of compressed data are declared but only "
                             f"{remaining - _COMPRESSED_SIZES.size:,} follow")
    if unpacked > _LZF_MAX_RATIO * packed:
        raise CloudFileError(f"{path}: not a valid PCD file ({packed:,} bytes of LZF data cannot decompress to the "
                             f"{unpacked:,} its header declares)")
    # What follows the compressed block is not data (PCL's own test frames carry 3.9 kB of
    # it: its writer sizes the file before it compresses), and is not said.
    return 0


def _read_ascii(path: str, header: Header) -> dict:
    """field -> (N,) float64 values of an ascii PCD (fields of COUNT > 1: (N, COUNT))."""
    meta = header.metadata
    with open(path, "rb") as f:
        f.seek(header.offset)
        data = f.read()
    if not data.isascii():
        e = data.decode("ascii", errors="replace").index("\ufffd")  # the first byte that is not ASCII
        raise CloudFileError(f"{path}: the ascii data are not ASCII text (byte 0x{data[e]:02x} at offset "
                             f"{header.offset + e:,})")
    data = lf_line_ends(data)
    parsed = parse_numbers(data)
    n, count = meta.points, header.values
    per_line = parsed.per_line[parsed.per_line > 0]  # the rows: lines that are not blank
    if not parsed.ok or len(per_line) != n or (per_line != count).any():
        # The error path only: name the first row that is wrong, as a person reads the text.
        found = first_bad_row(data.decode("ascii").splitlines(), count)
        if found:
            k, t, bad = found
            what = (f"has {len(t)} values where the header declares {count}" if bad is None
                    else f"has '{bad[:20]}', which is not a number")
            raise CloudFileError(f"{path}: data line {k + 1} {what}")
        raise CloudFileError(f"{path}: the header declares {n:,} points but {len(per_line):,} rows of data follow")
    values = parsed.values
    table = values.reshape(n, count)
    out, at = {}, 0
    for name, c in zip(meta.fields, meta.count):
        out[name] = table[:, at] if c == 1 else table[:, at:at + c]
        at += c
    return out


def _read_binary(path: str, header: Header, pypcd4) -> dict:
    """field -> (N,) values of a binary or binary_compressed PCD, decoded by pypcd4."""
    meta = header.metadata
    with open(path, "rb") as f:
        f.seek(header.offset)
        try:
            # What pypcd4's PointCloud.from_fileobj calls after its header (pypcd4 is pinned,
            # 1.5.1, and bundled as such): the header was read and checked above.
            data = pypcd4._parse_pc_data(f, meta)
        except Exception as e:  # noqa: BLE001 -- lzf, struct and numpy errors all mean corrupt data
            # lzf returns None for a block that does not decompress to the size given, which
            # pypcd4 then takes the length of (a TypeError): say what that means.
            why = "its LZF block does not decompress" if isinstance(e, TypeError) else str(e)
            raise CloudFileError(f"{path}: the PCD's {meta.data.value} data cannot be read (corrupt: {why})") from None
    if len(data) != meta.points:
        raise CloudFileError(f"{path}: the header declares {meta.points:,} points but the data hold {len(data):,}")
    out = {}
    for name, c in zip(meta.fields, meta.count):
        out[name] = data[name] if c == 1 else np.column_stack([data[f"{name}__{i:04d}"] for i in range(c)])
    return out


def _packed_colours(path: str, name: str, column: np.ndarray, kind: str, notes: list) -> np.ndarray:
    """(N,4) scene-linear RGBA from a packed colour field: 0x00RRGGBB, or 0xAARRGGBB for rgba."""
    column = np.asarray(column)
    if column.dtype.itemsize == 4 and column.dtype.kind in "fui":
        bits = column.view(np.uint32)  # the field's bytes (PCL stores a float rgb's bits)
    else:  # ascii, read as float64: PCL writes a float rgb as its bits' integer; others as the float
        whole = np.isfinite(column) & (column == np.floor(column)) & (column >= 0) & (column < 2.0 ** 32)
        if kind == "F" and not (whole.all() and column.max(initial=0) >= 1):
            bits = column.astype(np.float32).view(np.uint32)
        else:
            bits = np.where(whole, column, 0).astype(np.uint32)
    if not bits.any():
        notes.append(f"every packed colour ('{name}') is 0: imported without colours (a writer that prints a packed "
                     "float colour as a decimal number loses it)")
        return None
    out = np.empty((len(bits), 4), np.float32)

    def block(b: int, e: int) -> None:
        v = bits[b:e]
        linear_colours([(v >> 16) & 255, (v >> 8) & 255, v & 255], 255, out=out[b:e])
        out[b:e, 3] = ((v >> 24) & 255) / np.float32(255) if name == "rgba" else 1.0

    in_blocks(block, len(bits))
    if name == "rgba" and not (bits >> 24).any():
        out[:, 3] = 1.0
        notes.append("every alpha of 'rgba' is 0: taken as opaque (the writer left it unset)")
    return out


def _attribute(values: np.ndarray) -> np.ndarray:
    """A point attribute of a field: int32 when its values are integers that fit, else float32."""
    v = np.asarray(values)
    if v.dtype.kind in "ui" and v.size and int(v.min()) >= -2 ** 31 and int(v.max()) < 2 ** 31:
        return v.astype(np.int32)
    if v.dtype.kind == "f" and v.size and np.isfinite(v).all() and (v == np.round(v)).all() \
            and np.abs(v).max() < 2 ** 24 and v.dtype == np.float64:  # an ascii integer field
        return v.astype(np.int32)
    return v.astype(np.float32)


def viewpoint_note(viewpoint) -> str:
    """What the notes say of the sensor's position taken from VIEWPOINT."""
    t = ", ".join(f"{x:g}" for x in viewpoint[:3])
    default = " (PCL's default: the sensor at the cloud's origin)" if tuple(viewpoint) == _DEFAULT_VIEWPOINT else ""
    return f"the sensor's position from the file's VIEWPOINT: ({t}){default}"


def read_pcd(path: str) -> PointCloud:
    path = os.fspath(path)
    check_file(path)
    pypcd4 = _import_pypcd4(path)
    header = read_header(path)
    meta = header.metadata
    fields = dict(zip(meta.fields, zip(meta.type, meta.size, meta.count)))
    missing = [c for c in _COORDINATES if c not in fields]
    if missing:
        raise CloudFileError(f"{path}: has no {' '.join(missing)} field(s) (its fields: "
                             f"{' '.join(_name(f) for f in meta.fields)}); not points in space")
    for name in (*_COORDINATES, *NORMAL_FIELDS, *_PACKED_COLOURS):
        if name in fields and fields[name][2] != 1:
            raise CloudFileError(f"{path}: the field '{name}' has COUNT {fields[name][2]}; it is one value a point")
    if meta.points == 0:
        raise CloudFileError(f"{path}: contains no points")
    extra, notes = _check_sizes(path, header), []
    columns = _read_ascii(path, header) if meta.data.value == "ascii" else _read_binary(path, header, pypcd4)
    if extra:
        notes.append(f"{extra:,} bytes after the last point were ignored")
    n = meta.points
    single = all(fields[c][:2] == ("F", 4) for c in _COORDINATES)
    pos = np.empty((n, 3), np.float32 if single else np.float64)
    normals = np.empty((n, 3), np.float32) if all(c in fields for c in NORMAL_FIELDS) else None

    def convert(b: int, e: int) -> None:
        for i, c in enumerate(_COORDINATES):
            pos[b:e, i] = columns[c][b:e]
        if normals is not None:
            for i, c in enumerate(NORMAL_FIELDS):
                normals[b:e, i] = columns[c][b:e]

    in_blocks(convert, n)
    colours = None
    packed = [c for c in _PACKED_COLOURS if c in fields]
    if len(packed) > 1:
        notes.append("the field 'rgb' was ignored: 'rgba' gives the colours")
        packed = ["rgba"]
    if packed:
        name = packed[0]
        kind, size, _ = fields[name]
        if size != 4:
            raise CloudFileError(f"{path}: the packed colour field '{name}' has SIZE {size}; a packed colour is "
                                 "4 bytes (0xAARRGGBB)")
        colours = _packed_colours(path, name, columns[name], kind, notes)
    used = {*_COORDINATES, *_PACKED_COLOURS, *(NORMAL_FIELDS if normals is not None else ())}
    attributes, ignored = {}, []
    for name, (_, _, count) in fields.items():
        if name in used:
            continue
        label = _name(name)
        if label == _PADDING:
            continue  # padding: no data
        if count != 1:
            ignored.append(f"{label} ({count} values a point)")
        elif label in _RESERVED_ATTRIBUTES or label.startswith(".") or len(label.encode()) > _MAX_ATTRIBUTE_NAME:
            ignored.append(f"{label} (a name the object's own attributes use, or not a valid attribute name)")
        else:
            attributes[label] = _attribute(columns[name])
    if ignored:
        notes.append(f"fields ignored: {', '.join(ignored)}")
    if normals is None and any(c in fields for c in NORMAL_FIELDS):
        notes.append("fields ignored: " + ", ".join(c for c in NORMAL_FIELDS if c in fields)
                     + " (a normal needs all three)")
    viewpoint = tuple(float(x) for x in meta.viewpoint)
    scanner = np.asarray(viewpoint[:3], np.float64)
    if not (np.isfinite(scanner).all() and np.abs(scanner).max() < _MAX_VIEWPOINT):
        scanner = None
        notes.append(f"the file's VIEWPOINT {viewpoint} is not a position: not used")
    elif viewpoint == _DEFAULT_VIEWPOINT and meta.height <= 1:
        # PCL writes its default when nobody set the sensor: an unorganised cloud merged from
        # several views carries it too, and orienting those towards the origin would turn
        # them inside out. The orientation decides from the geometry instead (a single view
        # seen from the file's origin still faces it: normals.range_image).
        scanner = None
        notes.append("the file's VIEWPOINT is PCL's default (0, 0, 0, no rotation) and the cloud is not organised: "
                     "not taken as the sensor's position")
    else:
        notes.append(viewpoint_note(viewpoint))
    if meta.height > 1:
        notes.append(f"an organised cloud of {meta.width:,} x {meta.height:,} points (rows: v x {meta.width:,} + u)")
    cloud = make_cloud(path, pos, normals, colours, None, attributes, drop_non_finite=True, format="PCD",
                       notes=notes)
    if scanner is not None:  # one row for every point, set after make_cloud's in-place subset
        cloud.scanners = np.broadcast_to(scanner, (len(cloud), 3))
    return cloud
