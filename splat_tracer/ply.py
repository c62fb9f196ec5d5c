"""Reading point clouds with normals from PLY files (ascii, binary little/big endian).

Parsing is plyfile's (a maintained PLY library); this module checks what the file means
for a splat renderer and turns every problem into a `CloudFileError` that names the file
and the problem, so that the importer can refuse it before creating anything.
"""
from __future__ import annotations

import functools

import io
import os
import re
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from . import spacing
from .columns import compress, finite_rows, in_blocks, kept_rows


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


class CloudFileError(ValueError):
    """A point-cloud file that cannot be imported; the message names file and problem."""


@dataclass
class PointCloud:
    # (N,3) file coordinates: float64, or float32 as a file's float32 coordinates are (float64
    # holds them exactly, so every use gives the same answer; 120 MB less at 10M points);
    # None in a prepared cloud (prepare.PreparedCloud: its origin and float32 offsets hold them)
    positions: Optional[np.ndarray]
    normals: Optional[np.ndarray]    # (N,3) float32, unit length; None: the file has none (estimated on import)
    colours: Optional[np.ndarray]    # (N,4) float32 scene-linear RGBA, or None
    radii: Optional[np.ndarray]      # (N,) float32 from the file, or None
    dropped_normals: int = 0         # rows dropped for a zero or non-finite normal
    merged_duplicates: int = 0       # rows dropped for repeating an earlier row's position
    first_duplicate_row: int = -1    # the first of those, as a row of the file
    # (N,) integers (int32 from a mask below 2^31 rows): each point's row in the file; None: point i is row i
    rows: Optional[np.ndarray] = None
    # Per-point attributes kept on the object besides the splat's own (LAS intensity,
    # classification, return number; text intensity): name -> (N,) int32 or float32.
    attributes: dict = field(default_factory=dict)
    scanners: Optional[np.ndarray] = None  # (N,3) float64: the scanner's position per point (E57 poses)
    orientation: str = "PROPAGATE"   # how to orient estimated normals: PROPAGATE, UP (aerial), SCANNER
    oriented: bool = True            # False: the normals' axes are right but their signs arbitrary
    dropped_rows: int = 0            # rows dropped for non-finite coordinates (text, LAS, E57)
    format: str = "PLY"              # what the file was read as (for the notes)
    budget_dropped: int = 0          # points left out to keep within the import's point budget
    notes: list = field(default_factory=list)  # what the reader changed or ignored, one sentence each

    def __len__(self) -> int:
        # a prepared cloud has normals (estimated when the file had none) but no positions
        return len(self.positions if self.positions is not None else self.normals)

    def subset(self, keep: np.ndarray, in_place: bool = False) -> "PointCloud":
        """The same cloud with only the rows `keep` (a mask or indices) of every per-point array.
        in_place (a mask): the kept rows are moved to the front of this cloud's own arrays,
        which the result views (a reader's new cloud: no fresh memory; this one is then garbage)."""
        from dataclasses import replace

        keep = np.asarray(keep)
        if keep.dtype == bool:  # a mask: every array copied a block at a time on all cores
            names = list(self.attributes)
            pos, nrm, col, rad, rows, scn, *attrs = compress(
                [self.positions, self.normals, self.colours, self.radii, self.rows, self.scanners,
                 *(self.attributes[k] for k in names)], keep, in_place=in_place)
            rows = kept_rows(keep) if self.rows is None else rows
            return replace(self, positions=pos, normals=nrm, colours=col, radii=rad, rows=rows, scanners=scn,
                           attributes=dict(zip(names, attrs)))
        take = (lambda a: None if a is None else a[keep])
        return replace(self, positions=self.positions[keep], normals=take(self.normals),
                       colours=take(self.colours), radii=take(self.radii),
                       rows=keep if self.rows is None else self.rows[keep], scanners=take(self.scanners),
                       attributes={k: v[keep] for k, v in self.attributes.items()})


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 transfer function: file colours are display (sRGB) values."""
    c = np.asarray(c, dtype=np.float32)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4).astype(np.float32)


@functools.lru_cache(maxsize=2)
def _srgb_table(scale: int) -> np.ndarray:
    """srgb_to_linear of every integer colour 0..scale divided by scale, as the general path
    computes it (the value divided in float64, then float32)."""
    return srgb_to_linear((np.arange(scale + 1, dtype=np.float64) / scale).astype(np.float32))


def linear_colours(columns, scale: int, out: Optional[np.ndarray] = None) -> np.ndarray:
    """(N, len(columns)) float32 scene-linear colours from integer sRGB columns in
    0..scale (255 or 65535), by table: the same values as srgb_to_linear of column / scale,
    without the power function per point (10M points' colours: 0.75 s). out: an (N, >=
    len(columns)) float32 array to fill (its first columns), instead of a new one."""
    lut = _srgb_table(int(scale))
    if out is None:
        out = np.empty((len(columns[0]), len(columns)), np.float32)
    for i, c in enumerate(columns):
        out[:, i] = lut[np.asarray(c)]
    return out


# Colour conventions for types that do not imply one: a float channel within 0..1 is
# taken as it is; otherwise (and for integers other than uchar/ushort) values that fit
# 0..255 are 8-bit and values that fit 0..65535 are 16-bit colours. Anything else has no
# known meaning as a colour and is refused rather than guessed.
_COLOUR_RANGES = (255.0, 65535.0)
_BY_TYPE = {np.dtype(np.uint8): 255.0, np.dtype(np.uint16): 65535.0}  # the PLY convention


def _unit_colours(path: str, v, names: tuple[str, ...]) -> np.ndarray:
    """(N, len(names)) float32 in 0..1 from colour properties read together (one
    convention for red, green and blue, decided by their types and then their values)."""
    columns = [v[c] for c in names]
    scale = _BY_TYPE.get(columns[0].dtype)
    if scale is None or any(c.dtype != columns[0].dtype for c in columns):
        lo = [float(np.min(c)) for c in columns]
        hi = [float(np.max(c)) for c in columns]
        if not all(np.isfinite(lo + hi)):
            raise CloudFileError(f"{path}: some colours are not finite")
        worst = int(np.argmin(lo)) if min(lo) < 0 else int(np.argmax(hi))
        floats = any(np.issubdtype(c.dtype, np.floating) for c in columns)
        if min(lo) < 0 or max(hi) > _COLOUR_RANGES[-1]:
            raise CloudFileError(
                f"{path}: the colour property '{names[worst]}' ({columns[worst].dtype}) ranges from "
                f"{lo[worst]:g} to {hi[worst]:g}, which is none of the colour ranges 0..1 (floats), "
                "0..255 and 0..65535")
        scale = 1.0 if floats and max(hi) <= 1.0 else next(r for r in _COLOUR_RANGES if max(hi) <= r)
    return np.column_stack([c.astype(np.float64) / scale for c in columns]).astype(np.float32)


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


def _read_header(path: str):
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


def read_ply(path: str) -> PointCloud:
    """Reads vertices with x y z, nx ny nz, optional red green blue [alpha], optional radius."""
    from plyfile import PlyData  # imported here: only reading needs it

    path = os.fspath(path)
    if not os.path.isfile(path):
        raise CloudFileError(f"{path}: no such file")
    header_len, header = _read_header(path)
    _check_declared_sizes(path, header, header_len)
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
    from . import gaussians  # a 3D or 2D Gaussian-splatting capture is a PLY of its own kind

    if gaussians.is_gaussian(names):
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
        scale = _BY_TYPE.get(kind.pop()) if len(kind) == 1 else None

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
            colours[:, :3] = srgb_to_linear(_unit_colours(path, v, rgb))
        colours[:, 3] = _unit_colours(path, v, ("alpha",))[:, 0] if "alpha" in names else 1.0
    ignored = [p.name for p in ply["vertex"].properties if p.name not in _KNOWN_PROPERTIES]
    notes = [f"vertex properties ignored (not a splat's): {', '.join(ignored)}"] if ignored else []
    return make_cloud(path, pos, normals, colours, radii, drop_non_finite=True, notes=notes)


# The vertex properties a (non-Gaussian) PLY is read for; others are ignored and said.
_KNOWN_PROPERTIES = {"x", "y", "z", "nx", "ny", "nz", "red", "green", "blue", "alpha", "radius"}


def unit_rows(vectors, in_place: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(unit, ok): the rows of `vectors` (N, 3) scaled to unit length, in float32 when they
    are float32 (files' normals: no float64 copy of 10M of them), else float64; ok: the rows
    that have a direction (every value finite, not all zero; the others are left as garbage).
    in_place: float32 vectors are overwritten with the result (no second array of 10M normals)."""
    v = np.asarray(vectors)
    if v.dtype != np.float32:
        v = v.astype(np.float64)
    in_place = in_place and v.dtype == np.float32 and v.flags.c_contiguous and v.flags.writeable
    unit, ok = v if in_place else np.empty(v.shape, v.dtype), np.empty(len(v), bool)

    def block(b: int, e: int) -> None:
        unit[b:e], ok[b:e] = _unit_block(v[b:e])  # computed whole before it is stored: in place is safe

    in_blocks(block, len(v))
    return unit, ok


def _unit_block(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """unit_rows of rows in float32 or float64."""
    l2 = np.einsum("ij,ij->i", v, v)  # in v's precision (np.linalg.norm: 5x slower at 10M)
    # Squares within 1e-30..1e30 are safe in float32 (normal numbers, a reciprocal in range);
    # the rest (zero, NaN, inf, or a component beyond ~1e15 or below ~1e-15) is redone below.
    safe = (l2 > 1e-30) & (l2 < 1e30)
    unit = v * (1.0 / np.sqrt(np.where(safe, l2, 1.0)))[:, None].astype(v.dtype)
    ok = safe
    rest = np.flatnonzero(~safe)
    if len(rest):
        # In float64, divided by the largest component first: a normal of 1e-40 or of 1e300
        # still has a direction, and its square neither underflows nor overflows.
        w = v[rest].astype(np.float64)
        with np.errstate(invalid="ignore", over="ignore"):  # rows without a direction: garbage, not ok
            big = np.abs(w).max(axis=1)
            has = np.isfinite(big) & (big > 0)
            w /= np.where(has, big, 1.0)[:, None]
            w /= (np.sqrt(np.einsum("ij,ij->i", w, w)) + ~has)[:, None]  # + 1 where it has none: no 0 / 0
        unit[rest] = w
        ok[rest] = has
    return unit, ok


def make_cloud(path: str, positions: np.ndarray, normals=None, colours=None, radii=None, attributes=None,
               scanners=None, *, drop_non_finite: bool = False, **fields) -> PointCloud:
    """The checks and clean-up every reader shares: rows with non-finite coordinates dropped
    and counted (drop_non_finite; else the caller has refused them), normals made unit and
    rows with a zero or non-finite normal dropped and counted, exact duplicate positions
    merged into their first row. `fields` are PointCloud's other fields (format, orientation,
    oriented, notes). Raises CloudFileError naming `path` when nothing usable is left.
    The readers hand over arrays of their own, which are changed in place: float32 normals
    made unit, and the rows dropped compacted away in every per-point array (positions,
    normals, colours, radii, attributes, scanners), the result viewing their fronts."""
    pos = np.asarray(positions)
    if pos.dtype != np.float32:  # float32 coordinates stay so (see PointCloud.positions)
        pos = pos.astype(np.float64, copy=False)
    n = len(pos)
    keep = np.ones(n, bool)
    dropped_rows = 0
    if drop_non_finite:
        keep = finite_rows(pos)
        dropped_rows = int(n - keep.sum())
        if not keep.any():
            raise CloudFileError(f"{path}: no point has finite coordinates (all {n:,} rows are NaN or infinite)")
    nrm, dropped = None, 0
    if normals is not None:
        # A zero or non-finite normal is an error of that point alone (docs/ALGORITHM.md): the
        # point is dropped and counted, never rendered with a garbage orientation.
        nrm, ok = unit_rows(normals, in_place=True)
        dropped = int((keep & ~ok).sum())
        if not (ok & keep).any():
            raise CloudFileError(f"{path}: no vertex has a usable normal (all are zero or not finite)")
        keep &= ok
    # Points at exactly the same position as an earlier one are merged into it (the
    # first row's normal, colour and radius are kept): a splat repeated adds nothing, and
    # piles of them make the neighbour search pathological.
    every = bool(keep.all())  # then no copy of the positions and no 10M-entry index array
    usable = None if every else np.flatnonzero(keep)
    first = spacing.first_of_duplicates(pos if every else pos[usable])
    repeats = np.flatnonzero(~first) if every else usable[~first]
    merged = len(repeats)
    first_merged = int(repeats[0]) if merged else -1
    keep[repeats] = False
    cloud = PointCloud(pos, None if nrm is None else nrm.astype(np.float32, copy=False), colours, radii, dropped, merged,
                       first_merged, None, dict(attributes or {}), scanners, dropped_rows=dropped_rows,
                       **fields)
    # a mask: faster than indices; in place: the arrays are the reader's own and this
    # function's (normals made unit above), and the cloud before the subset is not returned
    return cloud if every and not merged else cloud.subset(keep, in_place=True)


def write_ply(path: str, positions, normals, colours=None, radii=None, binary: bool = True,
              byte_order: str = "<") -> None:
    """Writes a point cloud as PLY (tests, the demo and benchmarks use it). Colours are
    written as 8-bit sRGB from scene-linear floats."""
    from plyfile import PlyData, PlyElement

    pos = np.asarray(positions, dtype=np.float64)
    fields = [("x", "f8"), ("y", "f8"), ("z", "f8"), ("nx", "f4"), ("ny", "f4"), ("nz", "f4")]
    if colours is not None:
        fields += [("red", "u1"), ("green", "u1"), ("blue", "u1")]
    if radii is not None:
        fields += [("radius", "f4")]
    rows = np.empty(len(pos), dtype=fields)
    for k, c in enumerate("xyz"):
        rows[c] = pos[:, k]
        rows["n" + c] = np.asarray(normals)[:, k]
    if colours is not None:
        lin = np.clip(np.asarray(colours, dtype=np.float64)[:, :3], 0, 1)
        srgb = np.where(lin <= 0.0031308, lin * 12.92, 1.055 * lin ** (1 / 2.4) - 0.055)
        for k, c in enumerate(("red", "green", "blue")):
            rows[c] = np.round(srgb[:, k] * 255)
    if radii is not None:
        rows["radius"] = radii
    PlyData([PlyElement.describe(rows, "vertex")], text=not binary, byte_order=byte_order).write(path)
