"""The version matrix (`make test-matrix`): the linux-x64 zip installed into each Blender
series the manifest claims, each as the `bpy` module in its own venv (build/matrix/bpy-X.Y/)
with the numpy that Blender release ships, the way a farm node installs it; then clouds of
every format whose reader needs a bundled wheel are imported and one is rendered, and the
render is read back and checked.

    cd tests && python -m pytest test_matrix.py --bpy 4.2 --bpy 4.5 --bpy 5.0

Skipped without --bpy (a plain `make test` does not download three Blenders).
"""
from __future__ import annotations

import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from blender_helpers import blender_user_env, check_sphere_render
from geometry import fibonacci_sphere
from splat_tracer import ply

ROOT = Path(__file__).resolve().parent.parent
MATRIX_DIR = ROOT / "build" / "matrix"
# Blender series -> the packages of its venv, pinned: the newest bpy of the series on PyPI
# for Python 3.11, and the numpy that Blender release bundles (nothing else of Blender's own
# Python matters to the add-on). bpy 4.2's wheel does not constrain numpy at all; Blender
# 4.2 ships numpy 1.24.3 (NUMPY_VERSION in its build_files/build_environment/cmake/
# versions.cmake), whose API the bundled scipy 1.15.3 must load with. bpy 4.5 and 5.0
# require numpy>=1.26,<2.0 and Blender 4.4+ ships 1.26.4.
MATRIX = {
    "4.2": ("bpy==4.2.23", "numpy==1.24.3"),
    "4.5": ("bpy==4.5.15", "numpy==1.26.4"),
    "5.0": ("bpy==5.0.1", "numpy==1.26.4"),
}
INSTALLER = ROOT / "tests" / "install_and_render.py"
TIMEOUT = 900  # seconds for one bpy process: the first import of a bpy is slow on a busy machine


def pytest_generate_tests(metafunc):
    if "series" in metafunc.fixturenames:
        wanted = metafunc.config.getoption("--bpy")
        unknown = set(wanted) - set(MATRIX)
        if unknown:
            raise pytest.UsageError(f"--bpy {sorted(unknown)}: the matrix has {sorted(MATRIX)}")
        metafunc.parametrize("series", wanted or [pytest.param("-", marks=pytest.mark.skip(
            reason="the version matrix runs with --bpy SERIES (make test-matrix)"))], scope="module")


@pytest.fixture(scope="module")
def bpy_python(series) -> Path:
    """The Python of build/matrix/bpy-<series>/, (re)created when its pins changed."""
    venv = MATRIX_DIR / f"bpy-{series}"
    pins = "\n".join(MATRIX[series]) + "\n"
    stamp = venv / "pins.txt"
    if not (stamp.is_file() and stamp.read_text() == pins):
        shutil.rmtree(venv, ignore_errors=True)
        started = time.perf_counter()
        subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
        subprocess.run([str(venv / "bin" / "python"), "-m", "pip", "install", "--quiet", "--only-binary=:all:",
                        *MATRIX[series]], check=True)
        stamp.write_text(pins)
        print(f"\nmatrix: created {venv} in {time.perf_counter() - started:.0f} s")
    return venv / "bin" / "python"


@pytest.fixture(scope="module")
def clouds(tmp_path_factory) -> list[Path]:
    """One sphere as PLY (normals, no radii: scipy's k-NN gives them), LAZ (no normals:
    estimated with scipy too; laspy + lazrs) and E57 (pye57)."""
    import laspy
    import pye57

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
    return [out / "sphere.ply", out / "sphere.laz", out / "sphere.e57"]


def run(python: Path, home: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([str(python), str(INSTALLER), *args], cwd=home, env=blender_user_env(home),
                          capture_output=True, text=True, timeout=TIMEOUT)


def test_a_node_without_the_extension_fails_the_farm_check(bpy_python, clouds, tmp_path):
    proc = run(bpy_python, tmp_path, "--output", str(tmp_path / "render.exr"), str(clouds[0]))
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert "farm_check: Splat Tracer is not enabled" in proc.stderr, proc.stderr
    assert not (tmp_path / "render.exr").exists()


def test_installed_from_the_command_line_it_imports_every_format_and_renders(series, bpy_python, dist_zip, clouds,
                                                                             tmp_path):
    started = time.perf_counter()
    install = run(bpy_python, tmp_path, "--install", str(dist_zip), "--via", "cli")
    assert install.returncode == 0, install.stdout + install.stderr
    assert f"into Blender {series}." in install.stdout, install.stdout
    assert (tmp_path / "blender_user_config" / "userpref.blend").is_file()  # enabled for the next start
    output = tmp_path / "render.exr"
    job = run(bpy_python, tmp_path, "--output", str(output), *map(str, clouds))
    log = job.stdout + job.stderr
    print(log)
    assert job.returncode == 0, log
    # Reported errors (the engine's self.report ERROR, a failed import) and tracebacks fail
    # the run even when Blender carried on.
    assert not [line for line in log.splitlines() if line.startswith(("Error", "ERROR", "Traceback"))], log
    assert "farm_check: scene 'Scene' renders with Splat Tracer" in job.stdout
    for suffix in (".ply", ".laz", ".e57"):
        assert f"imported {suffix}: 5000 points" in job.stdout, job.stdout
    numpy_pin = next(p for p in MATRIX[series] if p.startswith("numpy=="))
    assert f"numpy: {numpy_pin.split('==')[1]}" in job.stdout  # Blender's numpy, not another
    for module in ("scipy", "plyfile", "laspy", "lazrs", "pye57"):
        assert f"bundled: {module} " in job.stdout, f"{module} was not imported from the zip's wheels"
    check_sphere_render(output, new_pass_names=tuple(map(int, series.split("."))) >= (5, 0))
    print(f"matrix: bpy {series}: installed, imported 3 formats and rendered in "
          f"{time.perf_counter() - started:.1f} s")
