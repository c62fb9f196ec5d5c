"""The importer's readers, chosen by the file's content (its first bytes), not its name.

- PLY (`ply` + newline): ply.read_ply; 3D/2D Gaussian-splatting PLYs are recognised by
  their properties and read by gaussians.read_gaussians.
- LAS/LAZ (`LASF`): las.read_las (laspy; LAZ decompressed by lazrs).
- E57 (`ASTM-E57`): e57.read_e57 (pye57).
- PCD (`# .PCD`, or comments and then a VERSION or FIELDS line): pcd.read_pcd (pypcd4).
- Text (anything else that decodes as UTF-8 text): XYZ/PTS/TXT/CSV, text.read_text.
Each builds its cloud with cloud.make_cloud and raises cloud.CloudFileError naming the
file and the problem.
"""
from __future__ import annotations

import os

from ..cloud import CloudFileError, PointCloud, check_file
from .e57 import read_e57
from .las import read_las
from .pcd import is_pcd, read_pcd
from .ply import read_ply
from .text import read_text

FORMATS = ("PLY", "LAS", "E57", "PCD", "TEXT")
EXTENSIONS = (".ply", ".las", ".laz", ".e57", ".pcd", ".xyz", ".pts", ".txt", ".csv")
_SNIFF_BYTES = 4096
_TEXT_SHARE = 0.95  # the share of printable ASCII bytes that makes a non-UTF-8 file text in another encoding


def sniff(path: str) -> str:
    """The format of the file by its first bytes: one of FORMATS."""
    check_file(path)
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
    if is_pcd(head):  # before text: an ascii PCD is text too
        return "PCD"
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
                         "known: PLY, LAS/LAZ, E57, PCD, and XYZ/PTS/TXT/CSV text)")


def read_cloud(path: str, columns: str = "", progress=None) -> PointCloud:
    """Reads any supported file; `columns` maps a text file's columns (see read_text).
    progress: progress.ProgressFn, called while reading LAS/LAZ and E57 (others read in one call)."""
    path = os.fspath(path)
    kind = sniff(path)
    if kind == "PLY":
        return read_ply(path)
    if kind == "LAS":
        return read_las(path, progress)
    if kind == "E57":
        return read_e57(path, progress)
    if kind == "PCD":
        return read_pcd(path)
    try:
        return read_text(path, columns)
    except CloudFileError as e:
        if path.lower().endswith(".ply"):  # say what the name promised
            reason = str(e)[len(path) + 2:] if str(e).startswith(path + ": ") else str(e)
            raise CloudFileError(f"{path}: not a valid PLY file (it does not start with a 'ply' line), and as "
                                 f"text: {reason}") from None
        raise
