"""The installable zip (`make dist`): validated by Blender's tool, installed the way a user
installs it, with its bundled wheels, and rendering with SPLAT_TRACER."""
from __future__ import annotations

import os
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from geometry import fibonacci_sphere
from splat_tracer import ply

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def dist_zip(tmp_path_factory):
    """The Linux zip only (the platform this machine can install and render); `make dist`
    builds the other three the same way, their binaries are checked by test_portable.py."""
    out = tmp_path_factory.mktemp("dist")
    subprocess.run([sys.executable, str(ROOT / "tools" / "build_dist.py"), "--platform", "linux-x64",
                    "--output-dir", str(out)], check=True)
    (zip_path,) = out.glob("splat_tracer-*.zip")
    assert zip_path.name.endswith("-linux_x64.zip")  # blender_ext.py --split-platforms naming
    return zip_path


def test_zip_holds_the_addon_the_portable_core_and_the_wheels_only(dist_zip):
    names = set(zipfile.ZipFile(dist_zip).namelist())
    assert {"blender_manifest.toml", "__init__.py", "LICENSE", "splat_tracer/_core.abi3.so",
            "splat_tracer/engine.py", "operators/import_cloud.py", "ui/__init__.py"} <= names
    assert not any(n.endswith(".pyd") for n in names)
    # The Zig build of tools/build_native.py (glibc 2.28), not the development build.
    shipped = zipfile.ZipFile(dist_zip).read("splat_tracer/_core.abi3.so")
    assert shipped == (ROOT / "build" / "native" / "linux-x64" / "_core.abi3.so").read_bytes()
    wheels = {n for n in names if n.startswith("wheels/")}
    assert any("scipy" in w and "cp311" in w for w in wheels) and any("scipy" in w and "cp313" in w for w in wheels)
    assert any("plyfile" in w for w in wheels) and not any("numpy" in w for w in wheels)
    for name in ("laspy", "pyquaternion"):
        assert any(name in w for w in wheels), name
    for name in ("lazrs", "pye57"):
        assert all(any(name in w and tag in w for w in wheels) for tag in ("cp311", "cp313")), name
    assert all("manylinux" in w or "none-any" in w for w in wheels), wheels
    assert not any(n.startswith(("tests/", "benchmarks/", "tools/", "splat_tracer/native/")) for n in names)
    manifest = zipfile.ZipFile(dist_zip).read("blender_manifest.toml").decode()
    assert all(f'"./{w}"' in manifest for w in wheels)
    assert 'platforms = ["linux-x64"]' in manifest


def test_zip_installs_into_blender_and_renders(dist_zip, tmp_path):
    p, n = fibonacci_sphere(5000)
    ply_path = tmp_path / "sphere.ply"
    ply.write_ply(str(ply_path), p, n)
    env = dict(os.environ)
    for var in ("BLENDER_USER_CONFIG", "BLENDER_USER_SCRIPTS", "BLENDER_USER_RESOURCES"):
        env[var] = str(tmp_path / var.lower())
    env["PYTHONPATH"] = ""  # nothing from this source tree: only what the zip installs
    output = tmp_path / "render.exr"
    proc = subprocess.run([sys.executable, str(ROOT / "tests" / "install_and_render.py"), str(dist_zip),
                           str(ply_path), str(output)], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    bundled = next(w for w in zipfile.ZipFile(dist_zip).namelist() if w.startswith("wheels/scipy-") and "cp311" in w)
    assert f"bundled: scipy {bundled.split('-')[1]} " in proc.stdout, proc.stdout  # not the venv's scipy
    # Blender installed the bundled wheels for this Python into the extensions' site-packages.
    site = list(tmp_path.glob("blender_user_*/**/.local/lib/python3.*/site-packages"))
    assert site and (site[0] / "plyfile.py").is_file() and (site[0] / "scipy").is_dir(), site
    import OpenEXR

    exr = OpenEXR.File(str(output), separate_channels=True)
    depth = next(part.channels["ViewLayer.Depth.Z"].pixels for part in exr.parts
                 if "ViewLayer.Depth.Z" in part.channels)
    hit = depth < 1e9
    assert 0.2 < hit.mean() < 0.6
    np.testing.assert_allclose(depth[hit].min(), 4.0, atol=0.02)  # the sphere's nearest point
