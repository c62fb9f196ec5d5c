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

from ...util import resources
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
# A point data format ID with bit 7 set and bit 6 clear: compressed (LAZ), as laspy tells it.
_LAZ_BITS, _LAZ_COMPRESSED = 0xC0, 0x80
_CHUNK_TABLE_HEADER = 8  # a LAZ chunk table's version and number of chunks (uint32 each)
_LASZIP_RECORD_ID = 22204  # the LAZ VLR's record ID (user ID 'laszip encoded')
# The LAZ VLR (LASzip): compressor (uint16; 3 is the layered compressor of LAS 1.4's point
# formats 6-10), coder, version, options, chunk size, special EVLRs, then the number of items
# (uint16 at 32) and each item (type, size, version: uint16 each). Layers per item type in a
# layered chunk: Point14 9 (XY, Z, classification, flags, intensity, scan angle, user data,
# point source, GPS time), RGB14 1, RGBNIR14 2, Wavepacket14 1, Byte14 one per byte.
_LAZ_LAYERED = 3
_LAZ_VLR_ITEMS_AT = 34
_LAZ_BYTE14 = 14
_LAZ_LAYERS = {10: 9, 11: 1, 12: 2, 13: 1}


def _is_panic(e: BaseException) -> bool:
    """Whether `e` is a panic of lazrs's Rust code (a bounds or arithmetic check failing on a
    corrupt LAZ file: a divisor of zero in a chunk's point count), which pyo3 raises as its
    PanicException: a BaseException, so that `except Exception` does not catch it; it
    escaped the import as no CloudFileError. Matched by name: pyo3 makes the class in each
    extension and exports it from none."""
    return type(e).__name__ == "PanicException"


def _laszip_vlr(path: str, fields: "HeaderFields") -> bytes:
    """The LAZ VLR's body (user ID 'laszip encoded', record 22204), or b'' when the file has
    none (laspy then refuses it). The VLRs' count was checked by read_header."""
    with open(path, "rb") as f:
        f.seek(fields.header_size)
        for _ in range(fields.vlrs):
            head = f.read(_VLR_HEADER)
            if len(head) < _VLR_HEADER:
                break
            record_id, length = struct.unpack_from("<HH", head, 18)
            body = f.read(length)
            if head[2:18].rstrip(b"\0") == b"laszip encoded" and record_id == _LASZIP_RECORD_ID:
                return body
    return b""


def _check_chunks(path: str, fields: "HeaderFields") -> None:
    """Each chunk of a LAZ file's chunk table must fit in memory once decompressed: lazrs's
    parallel decompressor allocates a chunk's declared points times the record length at
    once (a fixed chunk size of 3.6 billion in the LAZ VLR: 94 GB asked, and a failed
    allocation in Rust aborts the process, Blender with it). A table lazrs cannot read is
    left for laspy to refuse, and so is a LAZ file without lazrs (another backend, or none)."""
    try:
        import lazrs  # laspy's first choice of backend when it is installed
    except ImportError:
        return
    vlr = _laszip_vlr(path, fields)
    try:
        with open(path, "rb") as f:
            f.seek(fields.offset_to_points)
            table = lazrs.read_chunk_table(f, lazrs.LazVlr(vlr))
    except BaseException as e:  # no LAZ VLR or no table: laspy's own error names it
        if isinstance(e, Exception) or _is_panic(e):
            return
        raise
    free = resources.available_memory()
    if free is None:
        return
    budget = free * (1.0 - resources.HEADROOM)
    for k, (points, _) in enumerate(table):
        if points * fields.record_length > budget:
            raise CloudFileError(
                f"{path}: not a valid LAZ file: chunk {k + 1} of its {len(table):,} declares {points:,} points "
                f"({points * fields.record_length / 2**30:,.1f} GB to decompress at once) but only "
                f"{free / 2**30:.1f} GB of memory are available (the file's chunk size or chunk table is corrupt)")
    _check_layers(path, fields, vlr, table)


def _layers(vlr: bytes) -> int:
    """The number of layers in each chunk of a layered LAZ file (LAS 1.4 point formats 6-10),
    from the LAZ VLR's items; 0 when the file is not layered or an item is unknown."""
    if len(vlr) < _LAZ_VLR_ITEMS_AT or struct.unpack_from("<H", vlr, 0)[0] != _LAZ_LAYERED:
        return 0
    (count,) = struct.unpack_from("<H", vlr, _LAZ_VLR_ITEMS_AT - 2)
    items = [struct.unpack_from("<HH", vlr, _LAZ_VLR_ITEMS_AT + 6 * i) for i in range(count)
             if _LAZ_VLR_ITEMS_AT + 6 * (i + 1) <= len(vlr)]
    layers = [size if kind == _LAZ_BYTE14 else _LAZ_LAYERS.get(kind) for kind, size in items]
    return 0 if not layers or None in layers else sum(layers)


def _check_layers(path: str, fields: "HeaderFields", vlr: bytes, table: list) -> None:
    """In a layered LAZ file, each chunk starts with its first point raw, its point count and
    the byte size of each layer: lazrs zero-fills a buffer of each declared size before
    reading it, so one size of 4 GB (a uint32) made a 1 KB file take 10 s and 4 GB to be
    refused, or abort the process where the memory was not there. The sizes must fit in
    the chunk (its byte count in the chunk table)."""
    layers = _layers(vlr)
    if not layers:
        return
    at = fields.offset_to_points + 8  # the chunks follow the chunk table's offset
    with open(path, "rb") as f:
        for k, (_, size) in enumerate(table):
            f.seek(at + fields.record_length + 4)
            raw = f.read(4 * layers)
            if len(raw) < 4 * layers:
                return  # beyond the end of the file: lazrs refuses it as it reads
            declared = sum(struct.unpack(f"<{layers}I", raw))
            room = size - fields.record_length - 4 - 4 * layers
            if declared > room:
                raise CloudFileError(f"{path}: not a valid LAZ file: the layers of chunk {k + 1} of {len(table):,} "
                                     f"declare {declared:,} bytes but the chunk holds {max(room, 0):,} (the file is "
                                     "corrupt)")
            at += size


def _check_chunk_table(f, path: str, offset: int, end: int, size: int) -> None:
    """A LAZ file's chunk table, where lazrs looks for it (its offset is the point data's
    first 8 bytes, or the file's last 8 when the writer could not go back to write it):
    its number of chunks must fit between the point data's start and the table, as every
    chunk takes at least one byte. lazrs allocates the count it reads before decoding a
    single entry, and a failed allocation in Rust aborts the process (Blender with it)."""
    f.seek(offset)
    first = f.read(8)
    f.seek(max(size - 8, 0))
    for raw in (first, f.read(8)):
        if len(raw) < 8:
            continue
        (at,) = struct.unpack("<q", raw)
        if offset + 8 <= at <= end - _CHUNK_TABLE_HEADER:
            f.seek(at + 4)
            (chunks,) = struct.unpack("<I", f.read(4))
            if chunks > at - offset - 8:
                raise CloudFileError(f"{path}: not a valid LAZ file: its chunk table declares {chunks:,} chunks of "
                                     f"points, but only {at - offset - 8:,} bytes of compressed points precede it")
            return


@dataclass(frozen=True)
class HeaderFields:
    """The few header fields that bound what reading the file can do (see read_header)."""
    version: tuple
    header_size: int
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
        if point_format & _LAZ_BITS == _LAZ_COMPRESSED:
            _check_chunk_table(f, path, offset, evlr_start if evlrs else size, size)
    for axis, value in zip("xyz", numbers[:3]):
        if not (math.isfinite(value) and value != 0):
            raise CloudFileError(f"{bad} {axis} scale is {value!r}: every {axis} coordinate would be "
                                 f"{'the same' if value == 0 else 'undefined'} (the header is corrupt)")
    for axis, value in zip("xyz", numbers[3:]):
        if not math.isfinite(value):
            raise CloudFileError(f"{bad} {axis} offset is {value!r}: no {axis} coordinate would be a number "
                                 "(the header is corrupt)")
    return HeaderFields(version, header_size, offset, vlrs, point_format, record_length, count, numbers[:3],
                        numbers[3:], evlr_start, evlrs)


def read_las(path: str, progress=None) -> PointCloud:
    """progress: progress.ProgressFn, called between chunks of _LAS_CHUNK points."""
    try:
        import laspy
    except ImportError:
        raise CloudFileError(f"{path}: is a LAS/LAZ file, and reading it needs the laspy package, which is not "
                             "installed") from None
    fields = read_header(path)
    if fields.point_format & _LAZ_BITS == _LAZ_COMPRESSED:
        _check_chunks(path, fields)
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
    except BaseException as e:
        if not _is_panic(e):
            raise
        raise CloudFileError(f"{path}: not a valid LAZ file (the decompressor failed on its data: {e})") from None
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
                      format="LAZ" if compressed else "LAS", notes=notes)
