"""The point cloud every reader produces (PointCloud), the clean-up every reader shares
(make_cloud), colour conversion, and CloudFileError, the one error a file that cannot be
imported raises (naming the file and the problem)."""
from __future__ import annotations

import errno
import functools
import os
import stat
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from .. import _core
from ..util.columns import compress, finite_rows, in_blocks, kept_rows
from ..util.colour import srgb_to_linear  # noqa: F401 (file colours are sRGB; the readers take it from here)
from .neighbours import first_of_duplicates

# Largest radius the renderer accepts (native/base/ray.h): the import drops points beyond
# it, so that what imports renders -- the same constant the export checks against.
MAX_RADIUS = _core.MAX_COORDINATE


class CloudFileError(ValueError):
    """A point-cloud file that cannot be imported; the message names file and problem."""


def check_file(path: str) -> None:
    """Refuses a path that is not a readable regular file, saying what it is instead: a
    folder, a named pipe (opening one waits for a writer, forever), a device, a symbolic
    link that loops or leads nowhere, or a file that cannot be read."""
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        if os.path.islink(path):
            raise CloudFileError(f"{path}: a symbolic link to '{os.readlink(path)}', which does not exist") from None
        raise CloudFileError(f"{path}: no such file") from None
    except OSError as e:
        if e.errno == errno.ELOOP:
            raise CloudFileError(f"{path}: a symbolic link that loops (following it leads back to a link already "
                                 "followed), not a file") from None
        if e.errno == errno.ENOTDIR:
            raise CloudFileError(f"{path}: no such file (a part of the path before its name is not a folder)") from None
        raise CloudFileError(f"{path}: cannot be opened ({e.strerror})") from None
    if stat.S_ISDIR(mode):
        raise CloudFileError(f"{path}: is a folder, not a file (choose the point-cloud files in it)")
    if stat.S_ISFIFO(mode):
        raise CloudFileError(f"{path}: is a named pipe (FIFO), not a file; the importer reads files from disk "
                             "(save the data to a file first)")
    if not stat.S_ISREG(mode):
        what = "a device" if stat.S_ISCHR(mode) or stat.S_ISBLK(mode) else "a socket" if stat.S_ISSOCK(mode) else \
            "not a regular file"
        raise CloudFileError(f"{path}: is {what}, not a file of points")
    try:
        open(path, "rb").close()
    except OSError as e:
        raise CloudFileError(f"{path}: cannot be read ({e.strerror})") from None


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
    # (N,3) float64: the scanner's position per point (E57 poses); one row broadcast to every
    # point (shared_row) when one sensor saw them all (a PCD's VIEWPOINT)
    scanners: Optional[np.ndarray] = None
    oriented: bool = True            # False: the normals' axes are right but their signs arbitrary
    dropped_rows: int = 0            # rows dropped for non-finite coordinates (text, LAS, E57)
    dropped_radii: int = 0           # rows dropped for a radius beyond MAX_RADIUS (a 3DGS scale of 88)
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
        shared = shared_row(self.scanners)  # one sensor: broadcast again, neither copied nor moved
        scanners = None if shared is not None else self.scanners
        if keep.dtype == bool:  # a mask: every array copied a block at a time on all cores
            names = list(self.attributes)
            pos, nrm, col, rad, rows, scn, *attrs = compress(
                [self.positions, self.normals, self.colours, self.radii, self.rows, scanners,
                 *(self.attributes[k] for k in names)], keep, in_place=in_place)
            rows = kept_rows(keep) if self.rows is None else rows
            kept = int(keep.sum())
        else:
            take = (lambda a: None if a is None else a[keep])
            pos, nrm, col, rad, scn = (self.positions[keep], take(self.normals), take(self.colours), take(self.radii),
                                       take(scanners))
            rows = keep if self.rows is None else self.rows[keep]
            names, attrs, kept = list(self.attributes), [v[keep] for v in self.attributes.values()], len(keep)
        if shared is not None:
            scn = np.broadcast_to(shared, (kept, 3))
        return replace(self, positions=pos, normals=nrm, colours=col, radii=rad, rows=rows, scanners=scn,
                       attributes=dict(zip(names, attrs)))


def shared_row(a: Optional[np.ndarray]) -> Optional[np.ndarray]:
    """The (3,) row of a per-point (N,3) array that is one row broadcast to every point (a
    PCD's sensor position), else None: such an array is mapped by its row and broadcast again
    (PointCloud.subset, importer.transform, prepare), never copied to N rows (80 MB per
    million points that all say the same)."""
    if a is None or a.ndim != 2 or len(a) == 0 or a.strides[0] != 0:
        return None
    return a[0]


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
INTEGER_COLOUR_SCALES = {np.dtype(np.uint8): 255.0, np.dtype(np.uint16): 65535.0}  # the PLY convention


def unit_colours(path: str, v, names: tuple[str, ...]) -> np.ndarray:
    """(N, len(names)) float32 in 0..1 from colour properties read together (one
    convention for red, green and blue, decided by their types and then their values)."""
    columns = [v[c] for c in names]
    scale = INTEGER_COLOUR_SCALES.get(columns[0].dtype)
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


def colour_channels(path: str, channels: dict) -> np.ndarray:
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
        rgb = unit_colours(path, {k: np.asarray(v, np.float64) for k, v in channels.items()}, tuple(channels))
    return np.column_stack([srgb_to_linear(np.clip(rgb, 0, 1)), np.ones(len(rgb))]).astype(np.float32)


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
    merged into their first row. `fields` are PointCloud's other fields (format,
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
    dropped_radii = 0
    if radii is not None:
        # A file radius of 1e30 (or a Gaussian's exp(88) scale) would be refused by the
        # renderer: the point is dropped and counted here instead.
        huge = keep & ~(np.asarray(radii) <= MAX_RADIUS)
        dropped_radii = int(huge.sum())
        if dropped_radii:
            if dropped_radii == int(keep.sum()):
                raise CloudFileError(f"{path}: every radius is beyond the renderer's limit ({MAX_RADIUS:.0e})")
            keep &= ~huge
    # Points at exactly the same position as an earlier one are merged into it (the
    # first row's normal, colour and radius are kept): a splat repeated adds nothing, and
    # piles of them make the neighbour search pathological.
    every = bool(keep.all())  # then no copy of the positions and no 10M-entry index array
    usable = None if every else np.flatnonzero(keep)
    first = first_of_duplicates(pos if every else pos[usable])
    repeats = np.flatnonzero(~first) if every else usable[~first]
    merged = len(repeats)
    first_merged = int(repeats[0]) if merged else -1
    keep[repeats] = False
    cloud = PointCloud(pos, None if nrm is None else nrm.astype(np.float32, copy=False), colours, radii, dropped, merged,
                       first_merged, None, dict(attributes or {}), scanners, dropped_rows=dropped_rows,
                       dropped_radii=dropped_radii, **fields)
    # a mask: faster than indices; in place: the arrays are the reader's own and this
    # function's (normals made unit above), and the cloud before the subset is not returned
    return cloud if every and not merged else cloud.subset(keep, in_place=True)
