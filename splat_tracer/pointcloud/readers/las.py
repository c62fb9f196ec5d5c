"""LAS/LAZ files (`LASF`), read with laspy (LAZ decompressed by lazrs).

Coordinates are the integer records times the header's scale plus its offset, in float64.
Colour is 16-bit by the specification, but many writers store 8-bit values: a file whose
colour values are all within 0..255 is read as 8-bit, otherwise as 16-bit (decided per
file; cloud.colour_channels). Intensity, classification and return number are kept as
point attributes. No normals: estimated and oriented upward (aerial data).

The header's counts and offsets are checked against the file's size (read_header) before
laspy sees the file: laspy loops over the declared number of VLRs and EVLRs, reading past
the end of the file, so a corrupt count of 4 billion runs for hours, allocating as it goes,
with no point at which a progress call could cancel it.
"""
from __future__ import annotations

import math
import os
import struct
from dataclasses import dataclass

import numpy as np

from ...util.columns import in_blocks
from ...util.progress import Cancelled
from ..cloud import CloudFileError, PointCloud, colour_channels, make_cloud

# LAS/LAZ points read at a time (about 0.05-0.25 s each). laspy reads a chunk's records into
# a new buffer (36 MB per 2^20 points of format 7): beyond glibc's largest mmap threshold
# (32 MB) each one is fresh pages from the system, faulted in again (10M points: 0.3-0.6 s);
# smaller ones are reused from the heap.
_LAS_CHUNK = 1 << 19

# The LAS 1.0-1.4 public header's fixed fields (ASPRS LAS specification, little-endian):
# size of the header, offset to the point data, number of VLRs, point data format, record
# length, legacy point count (offset 94); x/y/z scale and offset (131); LAS 1.4's start of
# the first EVLR, number of EVLRs and 64-bit point count (235).
_HEADER_FIELDS = struct.Struct("<HIIBHI")
_SCALES_AND_OFFSETS = struct.Struct("<6d")
_EVLR_FIELDS = struct.Struct("<QIQ")
_HEADER_SIZE_14 = 375   # a LAS 1.4 header: its fields end at 375 bytes
_HEADER_SIZE_MIN = 227  # a LAS 1.0-1.2 header
_HEADER_SIZE_13 = 235   # LAS 1.3 adds the start of the waveform records
_VLR_HEADER = 54        # bytes before each VLR's data
_EVLR_HEADER = 60       # bytes before each EVLR's data
_EVLR_LENGTH_AT = 20    # an EVLR's data length (uint64) follows its reserved, user ID and record ID fields


@dataclass(frozen=True)
class HeaderFields:
    """The few header fields that bound what reading the file can do (see read_header)."""
    version: tuple
    offset_to_points: int
    vlrs: int
    point_format: int
    record_length: int
    point_count: int       # LAS 1.4: the 64-bit count, as laspy takes it; else the legacy count
    scales: tuple
    offsets: tuple
    evlr_start: int
    evlrs: int


def read_header(path: str) -> HeaderFields:
    """The header's fixed fields, each count and offset checked against the file's size (and
    against the others: the VLRs lie between the header and the point records, the EVLRs
    after the records, each EVLR's data within the file), and the scales and offsets
    checked finite (a zero scale would put every point on one plane). Raises
    CloudFileError naming the file and the field that cannot be right."""
    size = os.path.getsize(path)
    with open(path, "rb") as f:
        head = f.read(_HEADER_SIZE_14)
        if len(head) < _HEADER_SIZE_MIN:
            raise CloudFileError(f"{path}: not a valid LAS/LAZ file (the file is {len(head)} bytes, shorter than "
                                 f"a LAS header's {_HEADER_SIZE_MIN})")
        version = (head[24], head[25])
        header_size, offset, vlrs, point_format, record_length, legacy_count = _HEADER_FIELDS.unpack_from(head, 94)
        numbers = _SCALES_AND_OFFSETS.unpack_from(head, 131)
        evlr_start = evlrs = 0
        count = legacy_count
        if version[1] >= 4:
            if len(head) < _HEADER_SIZE_14:
                raise CloudFileError(f"{path}: not a valid LAS/LAZ file (a LAS 1.{version[1]} header is "
                                     f"{_HEADER_SIZE_14} bytes but the file has {len(head)})")
            evlr_start, evlrs, count = _EVLR_FIELDS.unpack_from(head, 235)
        bad = f"{path}: not a valid LAS/LAZ file: its header's"
        least = _HEADER_SIZE_14 if version[1] >= 4 else _HEADER_SIZE_13 if version[1] == 3 else _HEADER_SIZE_MIN
        if header_size < least:
            raise CloudFileError(f"{bad} size ({header_size:,}) is smaller than a LAS 1.{version[1]} header's "
                                 f"{least} bytes")
        if not header_size <= offset <= size:
            raise CloudFileError(f"{bad} offset to point data ({offset:,}) is not between the header's size "
                                 f"({header_size:,}) and the file's ({size:,} bytes)")
        if vlrs * _VLR_HEADER > offset - header_size:
            raise CloudFileError(f"{bad} number of VLRs ({vlrs:,}) cannot fit: {vlrs:,} VLRs need at least "
                                 f"{vlrs * _VLR_HEADER:,} bytes but {offset - header_size:,} lie between the header "
                                 "and the point data")
        if evlrs:
            if not offset <= evlr_start <= size:
                raise CloudFileError(f"{bad} start of the first EVLR ({evlr_start:,}) is not between the start of "
                                     f"the point data ({offset:,}) and the end of the file ({size:,} bytes)")
            if evlrs * _EVLR_HEADER > size - evlr_start:
                raise CloudFileError(f"{bad} number of EVLRs ({evlrs:,}) cannot fit: {evlrs:,} EVLRs need at "
                                     f"least {evlrs * _EVLR_HEADER:,} bytes but the file has "
                                     f"{size - evlr_start:,} after the first one's start")
            at = evlr_start  # each EVLR's own length too: laspy reads what it declares
            for i in range(evlrs):
                if at + _EVLR_HEADER > size:
                    raise CloudFileError(f"{bad} number of EVLRs ({evlrs:,}) cannot be right: EVLR {i + 1} of "
                                         f"{evlrs:,} would start {at - evlr_start:,} bytes after the first and "
                                         "run beyond the end of the file")
                f.seek(at + _EVLR_LENGTH_AT)
                (length,) = struct.unpack("<Q", f.read(8))
                at += _EVLR_HEADER + length
                if at > size:
                    raise CloudFileError(f"{path}: not a valid LAS/LAZ file: its EVLR {i + 1} of {evlrs:,} declares "
                                         f"{length:,} bytes of data, which end {at - size:,} bytes beyond the end "
                                         "of the file")
    for axis, value in zip("xyz", numbers[:3]):
        if not (math.isfinite(value) and value != 0):
            raise CloudFileError(f"{bad} {axis} scale is {value!r}: every {axis} coordinate would be "
                                 f"{'the same' if value == 0 else 'undefined'} (the header is corrupt)")
    for axis, value in zip("xyz", numbers[3:]):
        if not math.isfinite(value):
            raise CloudFileError(f"{bad} {axis} offset is {value!r}: no {axis} coordinate would be a number "
                                 "(the header is corrupt)")
    return HeaderFields(version, offset, vlrs, point_format, record_length, count, numbers[:3], numbers[3:],
                     evlr_start, evlrs)


def read_las(path: str, progress=None) -> PointCloud:
    """progress: progress.ProgressFn, called between chunks of _LAS_CHUNK points."""
    try:
        import laspy
    except ImportError:
        raise CloudFileError(f"{path}: is a LAS/LAZ file, and reading it needs the laspy package, which is not "
                             "installed") from None
    read_header(path)
    try:
        with laspy.open(path) as reader:
            header = reader.header
            compressed = header.are_points_compressed
            if not compressed:  # the records must end where the header says (EVLRs may follow)
                end = header.offset_to_point_data + header.point_count * header.point_format.size
                size = os.path.getsize(path)
                evlr_start = getattr(header, "start_of_first_evlr", 0) or 0
                limit = evlr_start if evlr_start else size
                if end > size:
                    raise CloudFileError(
                        f"{path}: early end-of-file: the header declares {header.point_count:,} points "
                        f"({header.point_format.size} bytes each) but the file ends "
                        f"{end - size:,} bytes before them")
                if end != limit:
                    raise CloudFileError(
                        f"{path}: the header declares {header.point_count:,} points but "
                        f"{limit - end:,} more bytes follow them (a count in the header is wrong)")
            if compressed and not laspy.LazBackend.detect_available():
                raise CloudFileError(f"{path}: is compressed (LAZ) and no LAZ backend is installed (the lazrs "
                                     "package decompresses it)")
            dims = set(header.point_format.dimension_names)
            rgb = ("red", "green", "blue")
            fields = [c for c in rgb if set(rgb) <= dims]
            fields += [a for a in ("intensity", "classification", "return_number") if a in dims]
            # In chunks, so that a long read (LAZ decompresses at a few million points a
            # second) reports progress and can be cancelled between them; each chunk goes
            # straight into arrays of the declared size (no lists of chunks joined after).
            count = int(header.point_count)
            pos = np.empty((count, 3))
            column = {name: None for name in fields}
            read = 0
            for chunk in reader.chunk_iterator(_LAS_CHUNK):
                if progress is not None:
                    progress(read / max(count, 1), "reading")
                m = len(chunk)
                if read + m > count:
                    raise CloudFileError(f"{path}: holds more points than the {count:,} its header declares")
                raw = {name: np.asarray(chunk[name]) for name in ("X", "Y", "Z", *fields)}
                for name in fields:
                    if column[name] is None:  # attributes are kept as int32 (Blender's INT): converted here
                        column[name] = np.empty(count, raw[name].dtype if name in rgb else np.int32)

                def convert(b: int, e: int, at: int = read) -> None:
                    for i, name in enumerate(("X", "Y", "Z")):  # scaled and offset in float64
                        np.multiply(raw[name][b:e], header.scales[i], out=pos[at + b:at + e, i])
                        pos[at + b:at + e, i] += header.offsets[i]
                    for name in fields:
                        column[name][at + b:at + e] = raw[name][b:e]

                in_blocks(convert, m)
                read += m
    except (CloudFileError, Cancelled):
        raise
    except Exception as e:  # laspy raises LaspyException, ValueError, struct errors...
        raise CloudFileError(f"{path}: not a valid LAS/LAZ file ({e})") from None
    if read == 0:
        raise CloudFileError(f"{path}: contains no points")
    if read != header.point_count:
        raise CloudFileError(f"{path}: early end-of-file: the header declares {header.point_count:,} points but "
                             f"only {read:,} could be read")
    colours, notes = None, []
    if "red" in column:
        channels = {c: column[c] for c in ("red", "green", "blue")}
        if any(c.any() for c in channels.values()):
            colours = colour_channels(path, channels)
        else:
            notes.append("its colour fields are all zero: imported without colours")
    attributes = {name: column[name] for name in ("intensity", "classification", "return_number") if name in column}
    return make_cloud(path, pos, None, colours, None, attributes, drop_non_finite=True,
                      format="LAZ" if compressed else "LAS", orientation="UP", notes=notes)
