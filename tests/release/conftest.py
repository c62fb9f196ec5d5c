"""The release checks' fixtures."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

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
