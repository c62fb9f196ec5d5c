"""The importer's readers, chosen by the file's content (its first bytes), not its name.

- PLY (`ply` + newline): ply.read_ply; 3D/2D Gaussian-splatting PLYs are recognised by
  their properties (gaussians.py).
- LAS/LAZ (`LASF`): laspy (LAZ decompressed by lazrs). Coordinates are the integer records
  times the header's scale plus its offset, in float64. Colour is 16-bit by the
  specification, but many writers store 8-bit values: a file whose colour values are all
  within 0..255 is read as 8-bit, otherwise as 16-bit (decided per file). Intensity,
  classification and return number are kept as point attributes. No normals: estimated and
  oriented upward (aerial data).
- E57 (`ASTM-E57`): pye57. Every scan, transformed by its pose; each point keeps its
  scanner's position (the pose's translation) to orient estimated normals towards it.
- Text (anything else that decodes as UTF-8 text): XYZ/PTS/TXT/CSV, see read_text.
Each raises ply.CloudFileError naming the file and the problem.
"""
from __future__ import annotations

import os
import re
import warnings

import numpy as np

from .columns import finite_rows, in_blocks
from .ply import CloudFileError, PointCloud, linear_colours, make_cloud, read_ply, srgb_to_linear, _unit_colours
from .progress import Cancelled

FORMATS = ("PLY", "LAS", "E57", "TEXT")
EXTENSIONS = (".ply", ".las", ".laz", ".e57", ".xyz", ".pts", ".txt", ".csv")
_SNIFF_BYTES = 4096
# LAS/LAZ points read at a time (about 0.05-0.25 s each). laspy reads a chunk's records into
# a new buffer (36 MB per 2^20 points of format 7): beyond glibc's largest mmap threshold
# (32 MB) each one is fresh pages from the system, faulted in again (10M points: 0.3-0.6 s);
# smaller ones are reused from the heap.
_LAS_CHUNK = 1 << 19
_TEXT_SHARE = 0.95  # the share of printable ASCII bytes that makes a non-UTF-8 file text in another encoding


def sniff(path: str) -> str:
    """The format of the file by its first bytes: one of FORMATS."""
    if not os.path.isfile(path):
        raise CloudFileError(f"{path}: no such file")
    with open(path, "rb") as f:
        head = f.read(_SNIFF_BYTES)
    if not head:
        raise CloudFileError(f"{path}: the file is empty")
    if head.startswith(b"ply") and head[3:4] in (b"\n", b"\r"):
        return "PLY"
    if head.startswith(b"LASF"):
        return "LAS"
    if head.startswith(b"ASTM-E57"):
        return "E57"
    if b"\0" not in head:
        try:
            head.decode("utf-8")
            return "TEXT"
        except UnicodeDecodeError as e:
            if e.start >= len(head) - 3:  # a character cut by the sniffing window
                return "TEXT"
            # Mostly printable ASCII with a few other bytes: text in another encoding (Latin-1,
            # Windows-1252), which read_text refuses naming the first such byte.
            printable = sum(1 for b in head if 32 <= b < 127 or b in (9, 10, 13))
            if printable >= _TEXT_SHARE * len(head):
                return "TEXT"
    what = "a PLY header" if head.lower().startswith(b"ply") else f"{head[:8]!r}"
    raise CloudFileError(f"{path}: not a point-cloud format this importer reads (it starts with {what}; "
                         "known: PLY, LAS/LAZ, E57, and XYZ/PTS/TXT/CSV text)")


def read_cloud(path: str, columns: str = "", progress=None) -> PointCloud:
    """Reads any supported file; `columns` maps a text file's columns (see read_text).
    progress: progress.ProgressFn, called while reading LAS/LAZ (others read in one call)."""
    path = os.fspath(path)
    kind = sniff(path)
    if kind == "PLY":
        return read_ply(path)
    if kind == "LAS":
        return read_las(path, progress)
    if kind == "E57":
        return read_e57(path)
    try:
        return read_text(path, columns)
    except CloudFileError as e:
        if path.lower().endswith(".ply"):  # say what the name promised
            reason = str(e)[len(path) + 2:] if str(e).startswith(path + ": ") else str(e)
            raise CloudFileError(f"{path}: not a valid PLY file (it does not start with a 'ply' line), and as "
                                 f"text: {reason}") from None
        raise


# --- LAS / LAZ --------------------------------------------------------------------------

def _colour_channels(path: str, channels: dict) -> np.ndarray:
    """(N,4) scene-linear RGBA from integer colour channels: 8-bit when every value fits 0..255."""
    hi = max(int(np.max(c)) if len(c) else 0 for c in channels.values())
    columns = [np.asarray(c) for c in channels.values()]
    if hi <= 65535 and all(np.issubdtype(c.dtype, np.integer) and (not len(c) or c.min() >= 0) for c in columns):
        out = np.empty((len(columns[0]), 4), np.float32)
        scale = 255 if hi <= 255 else 65535

        def block(b: int, e: int) -> None:  # LAS: uint16 channels, by table, on all cores
            linear_colours([c[b:e] for c in columns], scale, out=out[b:e])
            out[b:e, 3] = 1.0

        in_blocks(block, len(out))
        return out
    if hi <= 255:
        rgb = np.column_stack([np.asarray(c, np.float64) / 255.0 for c in channels.values()])
    else:
        rgb = _unit_colours(path, {k: np.asarray(v, np.float64) for k, v in channels.items()}, tuple(channels))
    return np.column_stack([srgb_to_linear(np.clip(rgb, 0, 1)), np.ones(len(rgb))]).astype(np.float32)


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
            colours = _colour_channels(path, channels)
        else:
            notes.append("its colour fields are all zero: imported without colours")
    attributes = {name: column[name] for name in ("intensity", "classification", "return_number") if name in column}
    return make_cloud(path, pos, None, colours, None, attributes, drop_non_finite=True,
                      format="LAZ" if compressed else "LAS", orientation="UP", notes=notes)


# --- E57 --------------------------------------------------------------------------------

def read_e57(path: str) -> PointCloud:
    try:
        import pye57
    except ImportError:
        raise CloudFileError(f"{path}: is an E57 file, and reading it needs the pye57 package, which is not "
                             "installed") from None
    try:
        e57 = pye57.E57(path)
    except Exception as e:
        raise CloudFileError(f"{path}: not a valid E57 file ({e})") from None
    parts, scanners, colour_parts, intensity_parts = [], [], [], []
    try:
        if e57.scan_count == 0:
            raise CloudFileError(f"{path}: contains no scans")
        for i in range(e57.scan_count):
            header = e57.get_header(i)
            fields = set(header.point_fields)
            if not ({"cartesianX", "cartesianY", "cartesianZ"} <= fields
                    or {"sphericalRange", "sphericalAzimuth", "sphericalElevation"} <= fields):
                raise CloudFileError(f"{path}: scan {i} has neither cartesian nor spherical coordinates "
                                     f"(its fields: {', '.join(sorted(fields))})")
            data = e57.read_scan(i, colors=True, intensity=True, ignore_missing_fields=True)
            xyz = np.column_stack([np.asarray(data[f"cartesian{c}"], np.float64) for c in "XYZ"])
            parts.append(xyz)
            scanners.append(np.broadcast_to(np.asarray(header.translation, np.float64), xyz.shape))
            rgb = [data.get(f"color{c}") for c in ("Red", "Green", "Blue")]
            colour_parts.append(None if any(c is None for c in rgb) else np.column_stack(rgb))
            intensity_parts.append(data.get("intensity"))
    except CloudFileError:
        raise
    except Exception as e:
        raise CloudFileError(f"{path}: not a valid E57 file ({e})") from None
    finally:
        e57.close()
    pos = np.concatenate(parts)
    if len(pos) == 0:
        raise CloudFileError(f"{path}: its scans contain no valid points")
    colours, notes = None, []
    if all(c is not None for c in colour_parts):
        rgb = np.concatenate(colour_parts)
        colours = _colour_channels(path, {"colorRed": rgb[:, 0], "colorGreen": rgb[:, 1], "colorBlue": rgb[:, 2]})
    elif any(c is not None for c in colour_parts):
        notes.append("only some scans have colours: imported without colours")
    attributes = {}
    if all(c is not None for c in intensity_parts):
        attributes["intensity"] = np.concatenate(intensity_parts).astype(np.float32)
    return make_cloud(path, pos, None, colours, None, attributes, np.concatenate(scanners), drop_non_finite=True,
                      format="E57", orientation="SCANNER", notes=notes)


# --- Text: XYZ / PTS / TXT / CSV --------------------------------------------------------

# Column names a header line may use (lower case), to the roles below.
_NAMES = {
    "x": "x", "y": "y", "z": "z", "//x": "x",
    "r": "r", "red": "r", "g": "g", "green": "g", "b": "b", "blue": "b",
    "nx": "nx", "ny": "ny", "nz": "nz", "normal_x": "nx", "normal_y": "ny", "normal_z": "nz",
    "normalx": "nx", "normaly": "ny", "normalz": "nz",
    "i": "i", "intensity": "i", "scalar_intensity": "i", "a": "a", "alpha": "a",
}
ROLES = ("x", "y", "z", "r", "g", "b", "a", "nx", "ny", "nz", "i", "_")
_SEPARATORS = str.maketrans({",": " ", ";": " ", "\t": " "})
_HEADER_LINES = 100  # at most this many lines before the data are taken as a header
_NUMBER = re.compile(r"^[+-]?(\d+\.?\d*([eE][+-]?\d+)?|\.\d+([eE][+-]?\d+)?|nan|inf|infinity)$", re.IGNORECASE)


def _is_numbers(tokens) -> bool:
    return bool(tokens) and all(_NUMBER.match(t) for t in tokens)


def _parse_columns(path: str, spec: str, count: int) -> list[str]:
    roles = spec.replace(",", " ").lower().split()
    unknown = [r for r in roles if r not in ROLES and r != "-"]
    if unknown:
        raise CloudFileError(f"{path}: the column mapping '{spec}' has unknown names {', '.join(unknown)} "
                             f"(known: {' '.join(ROLES)}; '_' or '-' skips a column)")
    roles = ["_" if r == "-" else r for r in roles]
    if len(roles) != count:
        raise CloudFileError(f"{path}: the column mapping '{spec}' names {len(roles)} columns but the file's rows "
                             f"have {count}")
    return roles


def _guess_columns(path: str, table: np.ndarray) -> list[str]:
    """Roles of the columns by their count and values: x y z first; then a triplet of
    unit-length rows is a normal, a triplet within a colour range (0..1, 0..255, 0..65535)
    a colour (the last such, as PTS writes x y z intensity r g b), one column left intensity."""
    count = table.shape[1]
    roles = ["x", "y", "z"] + ["?"] * (count - 3)
    free = lambda s: all(roles[c] == "?" for c in range(s, s + 3))  # noqa: E731
    for s in range(3, count - 2):
        t = table[:, s:s + 3]
        length = np.linalg.norm(t, axis=1)
        if free(s) and np.isfinite(t).all() and np.abs(t).max() <= 1 + 1e-3 and np.median(np.abs(length - 1)) < 1e-2:
            roles[s:s + 3] = ["nx", "ny", "nz"]
            break
    for s in reversed(range(3, count - 2)):
        t = table[:, s:s + 3]
        if free(s) and np.isfinite(t).all() and t.min() >= 0 and (t.max() <= 1 or (
                t.max() <= 65535 and np.all(t == np.round(t)))):
            roles[s:s + 3] = ["r", "g", "b"]
            break
    left = [c for c in range(count) if roles[c] == "?"]
    if len(left) == 1:
        roles[left[0]] = "i"
    elif left:
        raise CloudFileError(
            f"{path}: cannot tell what its {count} columns are (guessed: {' '.join(roles)}; '?' unknown); import "
            "with the Columns option naming each, e.g. 'x y z i r g b' (names: x y z r g b a nx ny nz i, '_' to skip)")
    return roles


def read_text(path: str, columns: str = "") -> PointCloud:
    """x y z rows separated by whitespace, commas or semicolons, with optional colour
    (0..255, 0..65535 or 0..1), alpha, intensity and normal columns. Lines before the first
    row of numbers are a header (its last line may name the columns; a PTS file's first
    line is its point count, which must match). Columns come from `columns` (e.g.
    'x y z i r g b', '_' skips one), else the header's names, else a guess."""
    with open(path, "rb") as f:
        data = f.read()
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        line = data[:e.start].count(b"\n") + 1
        raise CloudFileError(f"{path}: not UTF-8 text (byte {e.start}, 0x{data[e.start]:02x}, on line {line}) and no "
                             "other point-cloud format; save it as UTF-8 or ASCII") from None
    text = text.translate(_SEPARATORS)
    # The header: lines before the first one made of numbers only.
    offset, header, first = 0, [], None
    for _ in range(_HEADER_LINES + 1):
        end = text.find("\n", offset)
        line = text[offset:] if end < 0 else text[offset:end]
        tokens = line.split()
        if tokens and _is_numbers(tokens) and len(tokens) >= 3:
            first = tokens
            break
        if tokens:
            header.append(tokens)
        if end < 0:
            break
        offset = end + 1
    if first is None:
        if not text.strip():
            raise CloudFileError(f"{path}: the file is empty")
        raise CloudFileError(f"{path}: no row of at least three numbers (x y z) within its first "
                             f"{_HEADER_LINES} lines; not a point-cloud text file")
    count = len(first)
    body = text[offset:]
    rows = len(re.findall(r"^[ \r]*\S", body, re.MULTILINE))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        try:
            values = np.fromstring(body, sep=" ")
        except (DeprecationWarning, ValueError):
            values = None
    if values is None or values.size != rows * count:
        for k, line in enumerate(body.splitlines()):  # the error path only: find the row to name
            tokens = line.split()
            if tokens and (len(tokens) != count or not _is_numbers(tokens)):
                what = (f"has {len(tokens)} values where the first row has {count}" if _is_numbers(tokens)
                        else f"is not all numbers ('{line.strip()[:60]}')")
                raise CloudFileError(f"{path}: data line {k + 1} (after {len(header)} header lines) {what}")
        raise CloudFileError(f"{path}: the rows could not be read as {count} numbers each")
    table = values.reshape(rows, count)
    # A PTS file's first line is its point count: it must not lie.
    if len(header) == 1 and len(header[0]) == 1 and header[0][0].isdigit() and int(header[0][0]) != rows:
        raise CloudFileError(f"{path}: its first line declares {int(header[0][0]):,} points but {rows:,} rows "
                             "follow (the count is wrong or the file is truncated)")
    named = [_NAMES.get(t.lower()) for t in header[-1]] if header else []
    if columns.strip():
        roles = _parse_columns(path, columns, count)
    elif named and len(named) == count and all(named) and {"x", "y", "z"} <= set(named):
        roles = named
    else:
        roles = _guess_columns(path, table)
    for role in ROLES[:-1]:
        if roles.count(role) > 1:
            raise CloudFileError(f"{path}: the column '{role}' is given {roles.count(role)} times")
    for group in (("x", "y", "z"), ("r", "g", "b"), ("nx", "ny", "nz")):
        present = [r for r in group if r in roles]
        if present and len(present) != 3 or (group[0] == "x" and not present):
            raise CloudFileError(f"{path}: the columns need all of {' '.join(group)} (have: {' '.join(roles)})")
    col = {r: table[:, c] for c, r in enumerate(roles) if r != "_"}
    pos = np.column_stack([col["x"], col["y"], col["z"]])
    finite = finite_rows(pos)
    colours = None
    if "r" in col:
        rgb = _unit_colours(path, {"red": col["r"][finite], "green": col["g"][finite], "blue": col["b"][finite]},
                            ("red", "green", "blue"))
        alpha = (_unit_colours(path, {"alpha": col["a"][finite]}, ("alpha",))[:, 0] if "a" in col
                 else np.ones(len(rgb), np.float32))
        colours = np.zeros((rows, 4), np.float32)
        colours[finite] = np.column_stack([srgb_to_linear(rgb), alpha])
    normals = np.column_stack([col["nx"], col["ny"], col["nz"]]) if "nx" in col else None
    attributes = {"intensity": col["i"].astype(np.float32)} if "i" in col else {}
    return make_cloud(path, pos, normals, colours, None, attributes, drop_non_finite=True, format="TEXT",
                      notes=[f"columns read as: {' '.join(roles)}"])
