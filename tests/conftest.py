"""Shared fixtures. Blender tests run against the real `bpy` module (never a mock): the
extension is enabled from this source tree, in throwaway Blender user directories."""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tools"))

import dev_extension  # noqa: E402

# Must happen before the first `import bpy` anywhere in the session.
BLENDER_HOME = dev_extension.isolate_user_dirs()


@pytest.fixture(scope="session")
def blender():
    """bpy with the extension enabled from source."""
    import bpy

    dev_extension.enable_from_source(BLENDER_HOME)
    return bpy


@pytest.fixture
def empty_scene(blender):
    """A fresh empty file (the extension stays enabled)."""
    blender.ops.wm.read_homefile(use_empty=True)
    scene = blender.context.scene
    scene.render.engine = "SPLAT_TRACER"
    return scene


def pytest_addoption(parser):
    parser.addoption("--bpy", action="append", default=[], metavar="SERIES",
                     help="test_matrix.py: a Blender series to install the zip into (4.2, 4.5, 5.0; repeatable); "
                          "without it those tests are skipped (make test-matrix passes them)")


@pytest.fixture(scope="session")
def dist_zip(tmp_path_factory):
    """The Linux zip only (the platform this machine can install and render); `make dist`
    builds the other three the same way, their binaries are checked by test_portable.py."""
    import subprocess

    out = tmp_path_factory.mktemp("dist")
    subprocess.run([sys.executable, str(ROOT / "tools" / "build_dist.py"), "--platform", "linux-x64",
                    "--output-dir", str(out)], check=True)
    (zip_path,) = out.glob("splat_tracer-*.zip")
    assert zip_path.name.endswith("-linux_x64.zip")  # blender_ext.py --split-platforms naming
    return zip_path

