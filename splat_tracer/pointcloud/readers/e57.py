"""E57 files (`ASTM-E57`), read with pye57: every scan, transformed by its pose; each point
keeps its scanner's position (the pose's translation) to orient estimated normals towards it.
"""
from __future__ import annotations

import numpy as np

from ..cloud import CloudFileError, PointCloud, colour_channels, make_cloud


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
        colours = colour_channels(path, {"colorRed": rgb[:, 0], "colorGreen": rgb[:, 1], "colorBlue": rgb[:, 2]})
    elif any(c is not None for c in colour_parts):
        notes.append("only some scans have colours: imported without colours")
    attributes = {}
    if all(c is not None for c in intensity_parts):
        attributes["intensity"] = np.concatenate(intensity_parts).astype(np.float32)
    return make_cloud(path, pos, None, colours, None, attributes, np.concatenate(scanners), drop_non_finite=True,
                      format="E57", orientation="SCANNER", notes=notes)
