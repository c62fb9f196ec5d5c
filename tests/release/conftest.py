"""The release checks' fixtures."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from geometry import fibonacci_sphere
from splat_tracer.pointcloud.readers import ply

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def dist_zip(tmp_path_factory):
    """The Linux zip only (the platform this machine can install and render); `make dist`
    builds the other three the same way, their binaries are checked by test_portable.py."""
    out = tmp_path_factory.mktemp("dist")
    subprocess.run([sys.executable, "-m", "tools.build_dist", "--platform", "linux-x64", "--output-dir", str(out)],
                   check=True, cwd=ROOT)
    (zip_path,) = out.glob("splat_tracer-*.zip")
    assert zip_path.name.endswith("-linux_x64.zip")  # blender_ext.py --split-platforms naming
    return zip_path


@pytest.fixture(scope="module")
def clouds(tmp_path_factory) -> list[Path]:
    """One sphere as PLY (normals, no radii: the core's k-NN gives them), LAZ (no normals:
    estimated by the core too; laspy + lazrs), E57 (pye57) and binary_compressed PCD (pypcd4,
    pydantic, python-neo-lzf): what the zip is shown to import in every Blender release and
    under Wine."""
    import laspy
    import pye57
    from pypcd4 import Encoding, PointCloud as Pcd

    out = tmp_path_factory.mktemp("clouds")
    p, n = fibonacci_sphere(5000)
    ply.write_ply(str(out / "sphere.ply"), p, n)
    header = laspy.LasHeader(point_format=3, version="1.2")
    header.offsets, header.scales = np.zeros(3), np.full(3, 1e-4)  # 0.1 mm steps
    las = laspy.LasData(header)
    las.x, las.y, las.z = p.T
    las.write(str(out / "sphere.laz"), laz_backend=laspy.LazBackend.Lazrs)
    with pye57.E57(str(out / "sphere.e57"), mode="w") as e57:
        e57.write_scan_raw({"cartesianX": p[:, 0], "cartesianY": p[:, 1], "cartesianZ": p[:, 2]})
    Pcd.from_xyz_points(p.astype(np.float32)).save(str(out / "sphere.pcd"), encoding=Encoding.BINARY_COMPRESSED)
    return [out / "sphere.ply", out / "sphere.laz", out / "sphere.e57", out / "sphere.pcd"]
