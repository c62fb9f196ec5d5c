"""E57 files (`ASTM-E57`), read with pye57: every scan, transformed by its pose; each point
keeps its scanner's position (the pose's translation) to orient estimated normals towards it.

Each scan's records are read here in chunks (_E57_CHUNK) rather than by pye57's read_scan,
which allocates the count the file's XML declares and ignores how many records libE57
actually read: a count beyond the records present imported the unread entries as whatever
the memory held. What was read is what is kept (a shorter scan is noted). A scan whose pose
cannot place its points (a rotation quaternion of zero length or not finite, a translation
not finite) is left out and named; the file is refused, naming them, when no scan is left.
"""
from __future__ import annotations

import os
import struct
import xml.etree.ElementTree as ElementTree

import numpy as np

from ...util.progress import Cancelled
from ..cloud import CloudFileError, PointCloud, colour_channels, make_cloud

_CARTESIAN = ("cartesianX", "cartesianY", "cartesianZ")
_SPHERICAL = ("sphericalRange", "sphericalAzimuth", "sphericalElevation")
_EXTRAS = ("intensity", "colorRed", "colorGreen", "colorBlue")
# E57 records read at a time: progress (and a cancel) between chunks; each chunk's buffers
# (about 32 MB at 2^20 records of every field) are reused for the next.
_E57_CHUNK = 1 << 20


# The file's pages: 1020 bytes of data and their CRC-32C (ASTM E57 9.3); the file header
# (the first 48 data bytes): signature, version, physical length, the XML's physical offset
# and logical length, page size.
_PAGE, _PAGE_DATA = 1024, 1020
_FILE_HEADER = struct.Struct("<8sIIQQQQ")


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]  # an element's name without the E57 namespace


def check_structure(path: str) -> None:
    """What libE57 dereferences without checking, checked in the file's XML first: each scan
    (data3D's children) must have `points`, a CompressedVector whose `prototype` is a
    Structure (a scan whose prototype was deleted made pye57's scan header crash the
    process with a segmentation fault: Blender gone). Raises CloudFileError naming the
    scan. What it cannot find or parse is left to libE57, which refuses it with an error."""
    with open(path, "rb") as f:
        head = f.read(_FILE_HEADER.size)
        if len(head) < _FILE_HEADER.size:
            return
        _, _, _, _, physical, length, _ = _FILE_HEADER.unpack(head)
        start = physical // _PAGE * _PAGE_DATA + physical % _PAGE  # the XML's logical offset
        size = os.path.getsize(path)
        if physical >= size or physical % _PAGE >= _PAGE_DATA or length > size:
            return  # no XML where the header says: libE57 refuses the file
        f.seek(start // _PAGE_DATA * _PAGE)  # the pages holding the XML
        pages = f.read((start % _PAGE_DATA + length) // _PAGE_DATA * _PAGE + _PAGE)
    data = b"".join(pages[k:k + _PAGE_DATA] for k in range(0, len(pages), _PAGE))
    xml = data[start % _PAGE_DATA:start % _PAGE_DATA + length]
    xml = xml[:xml.rfind(b">") + 1]  # what follows the root element (NULs of a padded length) libE57 ignores
    try:
        root = ElementTree.fromstring(xml)
    except Exception:  # noqa: BLE001 -- not well formed, an unknown encoding...: libE57 says so
        return
    scans = [child for child in root if _local(child.tag) == "data3D"]
    for index, scan in enumerate(c for d in scans for c in d):
        name = next((c.text for c in scan if _local(c.tag) == "name" and c.text), "")
        label = f"scan {index} ('{name.strip()}')" if name.strip() else f"scan {index}"
        points = [c for c in scan if _local(c.tag) == "points"]
        if not points or points[0].get("type") != "CompressedVector":
            raise CloudFileError(f"{path}: not a valid E57 file: {label} has no points (a CompressedVector) in its "
                                 "XML (the file is corrupt)")
        prototype = [c for c in points[0] if _local(c.tag) == "prototype"]
        if not prototype or prototype[0].get("type") != "Structure":
            raise CloudFileError(f"{path}: not a valid E57 file: the points of {label} have no prototype (a "
                                 "Structure naming their fields) in its XML (the file is corrupt)")


def _scan_label(header, index: int) -> str:
    """'scan 2' or "scan 2 ('north')": the scan's index and its name when it has one."""
    try:
        name = str(header["name"].value()).strip()
    except Exception:  # no name node (it is optional)
        name = ""
    return f"scan {index} ('{name}')" if name else f"scan {index}"


def _bad_pose(header) -> str:
    """Why the scan's pose cannot place its points, or '' when it can (or it has none)."""
    if not header.has_pose():
        return ""
    q = np.asarray(header.rotation, np.float64)
    t = np.asarray(header.translation, np.float64)
    if not np.isfinite(q).all():
        return f"its rotation quaternion {q.tolist()} is not finite"
    with np.errstate(over="ignore", under="ignore"):
        length2 = float(np.dot(q, q))  # as pyquaternion normalises it: 0 or inf leaves no rotation
    if not 0 < length2 < np.inf:
        return f"its rotation quaternion {q.tolist()} has {'zero' if length2 == 0 else 'no finite'} length"
    if not np.isfinite(t).all():
        return f"its translation {t.tolist()} is not finite"
    return ""


def _read_records(e57, header, fields: list, progress, done: int, total: int, label: str) -> dict:
    """field -> every record libE57 reads of the scan (as many as the file holds, which may
    be fewer than its declared count), a chunk at a time."""
    data, buffers = e57.make_buffers(fields, _E57_CHUNK)
    parts = {f: [] for f in fields}
    reader = header.points.reader(buffers)
    read = 0
    try:
        while True:
            if progress is not None:
                progress((done + read) / max(total, 1), f"reading {label}")
            got = reader.read()  # fills the buffers, or fewer at the end of the scan's data; 0 after it
            if got == 0:
                break
            for f in fields:
                parts[f].append(data[f][:got].copy())
            read += got
    finally:
        reader.close()
    return {f: (np.concatenate(p) if p else data[f][:0].copy()) for f, p in parts.items()}


def read_e57(path: str, progress=None) -> PointCloud:
    """progress: progress.ProgressFn, called between chunks of _E57_CHUNK records."""
    try:
        import pye57
        from pye57.utils import convert_spherical_to_cartesian
    except ImportError:
        raise CloudFileError(f"{path}: is an E57 file, and reading it needs the pye57 package, which is not "
                             "installed") from None
    check_structure(path)
    try:
        e57 = pye57.E57(path)
    except Exception as e:
        raise CloudFileError(f"{path}: not a valid E57 file ({e})") from None
    parts, scanners, colour_parts, intensity_parts = [], [], [], []
    notes, left_out = [], []
    try:
        if e57.scan_count == 0:
            raise CloudFileError(f"{path}: contains no scans")
        headers = [e57.get_header(i) for i in range(e57.scan_count)]
        total = sum(int(h.point_count) for h in headers)
        done = 0
        for i, header in enumerate(headers):
            label = _scan_label(header, i)
            fields = set(header.point_fields)
            cartesian = set(_CARTESIAN) <= fields
            if not (cartesian or set(_SPHERICAL) <= fields):
                raise CloudFileError(f"{path}: {label} has neither cartesian nor spherical coordinates "
                                     f"(its fields: {', '.join(sorted(fields))})")
            declared = int(header.point_count)
            why = _bad_pose(header)
            if why:
                left_out.append(f"{label}: {why}")
                done += declared
                continue
            coordinates = _CARTESIAN if cartesian else _SPHERICAL
            state = "cartesianInvalidState" if cartesian else "sphericalInvalidState"
            wanted = [*coordinates, *(f for f in _EXTRAS if f in fields), *([state] if state in fields else [])]
            data = _read_records(e57, header, wanted, progress, done, total, label)
            read = len(data[coordinates[0]])
            done += declared
            if read != declared:
                notes.append(f"{label} declares {declared:,} points but holds {read:,}: the {read:,} were read")
            if state in data:  # as pye57's read_scan: only records whose state is 0 (valid) are points
                valid = data.pop(state) == 0
                data = {f: v[valid] for f, v in data.items()}
            # Coordinates as pye57's read_scan computes them (its conversion and pose), so that
            # a file imports to the same numbers.
            xyz = np.array([data[f] for f in coordinates]).T
            if not cartesian:
                xyz = convert_spherical_to_cartesian(xyz)
            if header.has_pose():
                xyz = pye57.E57.to_global(xyz, header.rotation, header.translation)
            xyz = np.column_stack([np.asarray(xyz[:, k], np.float64) for k in range(3)])
            parts.append(xyz)
            scanners.append(np.broadcast_to(np.asarray(header.translation, np.float64), xyz.shape))
            rgb = [data.get(f"color{c}") for c in ("Red", "Green", "Blue")]
            colour_parts.append(None if any(c is None for c in rgb) else np.column_stack(rgb))
            intensity_parts.append(data.get("intensity"))
    except (CloudFileError, Cancelled):
        raise
    except Exception as e:
        raise CloudFileError(f"{path}: not a valid E57 file ({e})") from None
    finally:
        e57.close()
    if not parts:
        raise CloudFileError(f"{path}: no scan can be placed: " + "; ".join(left_out))
    if left_out:
        notes.append(f"{len(left_out)} of {len(headers)} scans left out, their poses unusable: " + "; ".join(left_out))
    pos = np.concatenate(parts)
    if len(pos) == 0:
        raise CloudFileError(f"{path}: its scans contain no valid points")
    colours = None
    if all(c is not None for c in colour_parts):
        rgb = np.concatenate(colour_parts)
        colours = colour_channels(path, {"colorRed": rgb[:, 0], "colorGreen": rgb[:, 1], "colorBlue": rgb[:, 2]})
    elif any(c is not None for c in colour_parts):
        notes.append("only some scans have colours: imported without colours")
    attributes = {}
    if all(c is not None for c in intensity_parts):
        attributes["intensity"] = np.concatenate(intensity_parts).astype(np.float32)
    return make_cloud(path, pos, None, colours, None, attributes, np.concatenate(scanners), drop_non_finite=True,
                      format="E57", notes=notes)
