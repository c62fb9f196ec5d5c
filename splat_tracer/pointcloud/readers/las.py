"""LAS/LAZ files (`LASF`), read with laspy (LAZ decompressed by lazrs).

Coordinates are the integer records times the header's scale plus its offset, in float64.
Colour is 16-bit by the specification, but many writers store 8-bit values: a file whose
colour values are all within 0..255 is read as 8-bit, otherwise as 16-bit (decided per
file; cloud.colour_channels). Intensity, classification and return number are kept as
point attributes. No normals: estimated and oriented upward (aerial data).
"""
from __future__ import annotations

import os

import numpy as np

from ...util.columns import in_blocks
from ...util.progress import Cancelled
from ..cloud import CloudFileError, PointCloud, colour_channels, make_cloud

# LAS/LAZ points read at a time (about 0.05-0.25 s each). laspy reads a chunk's records into
# a new buffer (36 MB per 2^20 points of format 7): beyond glibc's largest mmap threshold
# (32 MB) each one is fresh pages from the system, faulted in again (10M points: 0.3-0.6 s);
# smaller ones are reused from the heap.
_LAS_CHUNK = 1 << 19


def read_las(path: str, progress=None) -> PointCloud:
    """progress: progress.ProgressFn, called between chunks of _LAS_CHUNK points."""
    try:
        import laspy
    except ImportError:
        raise CloudFileError(f"{path}: is a LAS/LAZ file, and reading it needs the laspy package, which is not "
                             "installed") from None
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
