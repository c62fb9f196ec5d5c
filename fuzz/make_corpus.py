"""Writes the seed corpora of the reader harnesses: fuzz/corpus/las/, e57/, text/ and pcd/.

    python -m fuzz.make_corpus    (from the root; overwrites the seeds it writes)

Small real files (a few KB each), written by the libraries the importer reads them with
(laspy + lazrs, pye57, pypcd4) or, for text, in the layouts the text reader meets: the fuzzer
mutates from these, so each is chosen to open a different path through its reader.
Point values come from a fixed seed; E57 files carry a fresh GUID each time they are
written, so remade E57 seeds differ in those bytes only.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

CORPUS = Path(__file__).resolve().parent / "corpus"
POINTS = 40  # enough for every path (colours, duplicates, k-NN radii), few enough for KB-sized files


def _points(seed: int, n: int = POINTS) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-5.0, 5.0, (n, 3))


def _las(path: Path, version: str, point_format: int, compress: bool = False, vlr: bool = False,
         evlrs: bool = False, sixteen_bit: bool = False) -> None:
    import laspy
    from laspy.vlrs.vlrlist import VLRList

    p = _points(len(path.name))
    header = laspy.LasHeader(point_format=point_format, version=version)
    header.scales = np.array([0.001, 0.001, 0.001])
    header.offsets = np.array([1000.0, 2000.0, 0.0])
    if vlr:
        header.vlrs.append(laspy.VLR("fuzz", 7, "a VLR", b"v" * 24))
    las = laspy.LasData(header)
    las.x, las.y, las.z = p[:, 0] + 1000, p[:, 1] + 2000, p[:, 2]
    if "red" in las.point_format.dimension_names:
        top = 65535 if sixteen_bit else 255
        rgb = np.random.default_rng(1).integers(0, top + 1, (len(p), 3))
        las.red, las.green, las.blue = rgb.T
    if "intensity" in las.point_format.dimension_names:
        las.intensity = np.arange(len(p))
        las.classification = np.full(len(p), 2)
    if evlrs:
        las.evlrs = VLRList([laspy.VLR("fuzz", 1, "one", b"x" * 40), laspy.VLR("fuzz", 2, "two", b"y" * 8)])
    las.write(str(path), laz_backend=laspy.LazBackend.Lazrs if compress else None)


def _e57(path: Path, scans: list) -> None:
    """scans: (name, fields, rotation, translation); fields maps E57 field names to arrays."""
    import pye57

    with pye57.E57(str(path), mode="w") as e57:
        for name, fields, rotation, translation in scans:
            e57.write_scan_raw(fields, rotation=np.asarray(rotation, float), translation=np.asarray(translation, float),
                               name=name)


def _cartesian(seed: int, colour: bool = True, intensity: bool = True) -> dict:
    p = _points(seed)
    fields = {"cartesianX": p[:, 0], "cartesianY": p[:, 1], "cartesianZ": p[:, 2]}
    if colour:
        rgb = np.random.default_rng(seed).integers(0, 256, (len(p), 3)).astype(np.uint8)
        fields.update(colorRed=rgb[:, 0], colorGreen=rgb[:, 1], colorBlue=rgb[:, 2])
    if intensity:
        fields["intensity"] = np.linspace(0.0, 1.0, len(p))
    return fields


def las_seeds(out: Path) -> None:
    _las(out / "las12_format3_rgb8.las", "1.2", 3)
    _las(out / "las12_format1_vlr.las", "1.2", 1, vlr=True)
    _las(out / "las12_format2_rgb16.laz", "1.2", 2, compress=True, sixteen_bit=True)
    _las(out / "las14_format6_evlrs.las", "1.4", 6, vlr=True, evlrs=True)
    _las(out / "las14_format7_evlrs.laz", "1.4", 7, compress=True, evlrs=True)
    _las(out / "las13_format0.las", "1.3", 0)


def e57_seeds(out: Path) -> None:
    _e57(out / "one_scan_colour.e57", [("station", _cartesian(1), [1, 0, 0, 0], [0, 0, 0])])
    _e57(out / "two_scans_posed.e57", [("north", _cartesian(2, colour=False), [0.92388, 0, 0, 0.38268], [1, 2, 3]),
                                        ("south", _cartesian(3, colour=False), [1, 0, 0, 0], [10, 0, 1.5])])
    _e57(out / "no_intensity.e57", [("plain", _cartesian(4, colour=False, intensity=False), [1, 0, 0, 0], [0, 0, 0])])
    states = _cartesian(5, colour=False)
    states["cartesianInvalidState"] = (np.arange(POINTS) % 5 == 0).astype(np.int8)
    _e57(out / "invalid_states.e57", [("states", states, [1, 0, 0, 0], [0, 0, 0])])


def text_seeds(out: Path) -> None:
    p = np.round(_points(6, 12), 3)
    rgb = np.random.default_rng(6).integers(0, 256, (len(p), 3))
    nrm = p / np.linalg.norm(p, axis=1, keepdims=True)
    rows = lambda fmt, values: [fmt.format(*v) for v in values]  # noqa: E731
    xyz = rows("{} {} {}", p)
    files = {
        "plain.xyz": "\n".join(xyz) + "\n",
        "header_csv.csv": "x,y,z,red,green,blue\n" + "\n".join(rows("{},{},{},{},{},{}", np.c_[p, rgb])) + "\n",
        "count_intensity_rgb.pts": f"{len(p)}\n" + "\n".join(
            rows("{} {} {} {} {:.0f} {:.0f} {:.0f}", np.c_[p, np.arange(len(p)) - 2048, rgb])) + "\n",
        "decimal_comma_semicolon.csv": "X;Y;Z\n" + "\n".join(rows("{};{};{}", p)).replace(".", ",") + "\n",
        "decimal_comma_tab.txt": "\n".join(rows("{}\t{}\t{}", p)).replace(".", ",") + "\n",
        "crlf_normals.txt": "x y z nx ny nz\r\n" + "\r\n".join(rows("{} {} {} {:.4f} {:.4f} {:.4f}", np.c_[p, nrm]))
                            + "\r\n",
        "cr_only.xyz": "\r".join(xyz) + "\r",
        "comma_space_unit_colours.txt": "\n".join(rows("{}, {}, {}, {:.3f}, {:.3f}, {:.3f}", np.c_[p, rgb / 255])),
        "nan_exponent_rows.xyz": "# comment line\n" + "\n".join(xyz[:8] + ["nan 1 2", "1e3 -2.5E-2 +.5", "inf 0 0"]),
    }
    for name, text in files.items():
        (out / name).write_bytes(text.encode("utf-8"))
    (out / "bom_utf8.xyz").write_bytes(b"\xef\xbb\xbf" + files["plain.xyz"].encode())
    (out / "latin1_header.txt").write_bytes("# relevé\n".encode("latin-1") + files["plain.xyz"].encode())


def pcd_seeds(out: Path) -> None:
    from pypcd4 import Encoding, MetaData, PointCloud as Pcd

    p = _points(7).astype(np.float32)
    n = len(p)
    rng = np.random.default_rng(7)
    rgb = rng.integers(0, 256, (n, 3)).astype(np.uint32)
    packed = (rgb[:, 0] << 16) | (rgb[:, 1] << 8) | rgb[:, 2]
    nrm = (p / np.linalg.norm(p, axis=1, keepdims=True)).astype(np.float32)
    xyz = [p[:, 0], p[:, 1], p[:, 2]]

    def write(name, columns, fields, types, encoding, height=1, viewpoint=None):
        cloud = Pcd.from_points(columns, fields, types)
        cloud.metadata = cloud.metadata.derive(width=n // height, height=height,
                                               viewpoint=viewpoint or (0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0))
        cloud.save(str(out / name), encoding=encoding)

    write("ascii_rgba.pcd", [*xyz, packed | np.uint32(0xFF000000)], ("x", "y", "z", "rgba"), [np.float32] * 3 +
          [np.uint32], Encoding.ASCII)
    write("binary_normals_intensity.pcd", [*xyz, *nrm.T, rng.random(n).astype(np.float32)],
          ("x", "y", "z", "normal_x", "normal_y", "normal_z", "intensity"), [np.float32] * 7, Encoding.BINARY)
    holes = p.copy()
    holes[::5] = np.nan
    write("compressed_organised_viewpoint.pcd", [holes[:, 0], holes[:, 1], holes[:, 2], packed.view(np.float32)],
          ("x", "y", "z", "rgb"), [np.float32] * 4, Encoding.BINARY_COMPRESSED, height=4,
          viewpoint=(1.0, -2.0, 3.0, 0.8, 0.2, 0.4, -0.4))
    meta = MetaData.model_validate(dict(fields=("x", "y", "z", "label", "fpfh", "_"), size=(8, 8, 8, 8, 4, 1),
                                        type=("F", "F", "F", "U", "F", "U"), count=(1, 1, 1, 1, 3, 4),
                                        points=n, width=n))
    cols = [*p.T.astype(np.float64), np.arange(n, dtype=np.uint64), *rng.random((3, n)).astype(np.float32),
            *np.zeros((4, n), np.uint8)]
    Pcd(meta, np.rec.fromarrays(cols, dtype=meta.build_dtype())).save(str(out / "wide_types_counts.pcd"),
                                                                        encoding=Encoding.BINARY_COMPRESSED)
    rows = "\n".join(f"{a:.4f}\t{b:.4f}  {c:.4f} {v} " for (a, b, c), v in zip(p, packed | np.uint32(0xFF000000)))
    (out / "pcl_ascii_float_rgb.pcd").write_text(
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z rgb\nSIZE 4 4 4 4\nTYPE F F F F\n"
        f"COUNT 1 1 1 1\nWIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA ascii\n{rows}\n")


def main() -> None:
    for name, write in (("las", las_seeds), ("e57", e57_seeds), ("text", text_seeds), ("pcd", pcd_seeds)):
        out = CORPUS / name
        out.mkdir(parents=True, exist_ok=True)
        write(out)
        print(f"{out}: {len(list(out.iterdir()))} files, {sum(f.stat().st_size for f in out.iterdir()):,} bytes")


if __name__ == "__main__":
    main()
