"""The version matrix (`make test-matrix`): the linux-x64 zip installed into every Blender
the manifest claims (4.2.13 to 5.2), each as the `bpy` module in its own venv
(build/matrix/bpy-<series>/) with the Python and numpy that Blender release ships, the way a
farm node installs it; then clouds of every format whose reader needs a bundled wheel are
imported, the sphere is rendered twice (headlight; sun and world), and the renders are read
back and checked; and the settings audit's RNA walk (tests/blender/settings_walk.py) is run in
each, so that a setting one of them has and the audit did not classify fails here.

    cd tests && python -m pytest release/test_blender_versions.py --bpy 4.2 --bpy 5.2

Skipped without --bpy (a plain `make test` does not download eight Blenders); the check
that the manifest's range is the matrix's always runs.
"""
from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from blender_helpers import blender_user_env, check_lit_sphere_render, check_sphere_render

ROOT = Path(__file__).resolve().parents[2]
MATRIX_DIR = ROOT / "build" / "matrix"
# Blender series -> (its Python, the packages of its venv, pinned): the newest bpy of the
# series on PyPI, and the numpy that Blender release bundles (nothing else of Blender's own
# Python matters to the add-on). 4.2.13 is the oldest claimed (blender_manifest.toml says
# why). bpy 4.2's wheel does not constrain numpy; Blender 4.2 ships numpy 1.24.3
# (NUMPY_VERSION in its build_files/build_environment/cmake/versions.cmake), the oldest
# that the add-on and the bundled readers (plyfile, laspy, pye57) must work with. bpy
# 4.3.0 and 4.4.0 (the only ones of those series on PyPI) do not constrain numpy either,
# and which one those releases ship was not found: they get 1.24.3, the demanding case
# (1.26.4 is tested with 4.5 and 5.0). bpy 4.5 and 5.0 require numpy>=1.26,<2.0, and
# 1.26.4 is the NUMPY_VERSION of those releases. bpy 5.1 and 5.2 are for Python 3.13 and
# require numpy>=2.2,<3; a 5.x versions.cmake has 2.3.4.
MATRIX = {
    "4.2.13": ("3.11", "bpy==4.2.13", "numpy==1.24.3"),
    "4.2": ("3.11", "bpy==4.2.23", "numpy==1.24.3"),
    "4.3": ("3.11", "bpy==4.3.0", "numpy==1.24.3"),
    "4.4": ("3.11", "bpy==4.4.0", "numpy==1.24.3"),
    "4.5": ("3.11", "bpy==4.5.15", "numpy==1.26.4"),
    "5.0": ("3.11", "bpy==5.0.1", "numpy==1.26.4"),
    "5.1": ("3.13", "bpy==5.1.2", "numpy==2.3.4"),
    "5.2": ("3.13", "bpy==5.2.3", "numpy==2.3.4"),
}
INSTALLER = ROOT / "tests" / "release" / "install_and_render.py"
SETTINGS_WALK = ROOT / "tests" / "blender" / "settings_walk.py"
TIMEOUT = 900  # seconds for one bpy process: the first import of a bpy is slow on a busy machine


def pytest_generate_tests(metafunc):
    if "series" in metafunc.fixturenames:
        wanted = metafunc.config.getoption("--bpy")
        unknown = set(wanted) - set(MATRIX)
        if unknown:
            raise pytest.UsageError(f"--bpy {sorted(unknown)}: the matrix has {sorted(MATRIX)}")
        metafunc.parametrize("series", wanted or [pytest.param("-", marks=pytest.mark.skip(
            reason="the version matrix runs with --bpy SERIES (make test-matrix)"))], scope="module")


def interpreter(version: str) -> str:
    """A Python `version` ("3.13") to make a venv from: this one, python3.13 on PATH, or one
    of pyenv's (whose shim on PATH fails while pyenv's selected version is another)."""
    if sys.version_info[:2] == tuple(map(int, version.split("."))):
        return sys.executable
    pyenv = Path(os.environ.get("PYENV_ROOT", Path.home() / ".pyenv")) / "versions"
    for candidate in [shutil.which(f"python{version}"), *sorted(pyenv.glob(f"{version}.*/bin/python{version}"))]:
        if candidate and subprocess.run([candidate, "-c", ""], capture_output=True).returncode == 0:
            return str(candidate)
    pytest.fail(f"the matrix needs Python {version} for this Blender series: no python{version} found on PATH "
                f"or in {pyenv}")


@pytest.fixture(scope="module")
def bpy_python(series) -> Path:
    """The Python of build/matrix/bpy-<series>/, (re)created when its pins changed."""
    python, *packages = MATRIX[series]
    venv = MATRIX_DIR / f"bpy-{series}"
    pins = "\n".join(MATRIX[series]) + "\n"
    stamp = venv / "pins.txt"
    if not (stamp.is_file() and stamp.read_text() == pins):
        base = interpreter(python)
        shutil.rmtree(venv, ignore_errors=True)
        started = time.perf_counter()
        subprocess.run([base, "-m", "venv", str(venv)], check=True)
        subprocess.run([str(venv / "bin" / "python"), "-m", "pip", "install", "--quiet", "--only-binary=:all:",
                        *packages], check=True)
        stamp.write_text(pins)
        print(f"\nmatrix: created {venv} in {time.perf_counter() - started:.0f} s")
    return venv / "bin" / "python"


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
    version = MATRIX[series][1].split("==")[1]
    assert f"into Blender {version}" in install.stdout, install.stdout  # this bpy, not another
    assert "(online access: False)" in install.stdout  # the wheels come from the zip, not the network
    assert (tmp_path / "blender_user_config" / "userpref.blend").is_file()  # enabled for the next start
    output = tmp_path / "render.exr"
    job = run(bpy_python, tmp_path, "--output", str(output), *map(str, clouds))
    log = job.stdout + job.stderr
    print(log)
    assert job.returncode == 0, log
    # Reported errors (the engine's self.report ERROR, a failed import) and tracebacks fail
    # the run even when Blender carried on.
    # (Blender 5.1+ prefix each line of its log with the time and a category.)
    assert not [line for line in log.splitlines() if re.search(r"\b(Error|ERROR)\b|Traceback", line)], log
    assert "farm_check: scene 'Scene' renders with Splat Tracer" in job.stdout
    for suffix in (".ply", ".laz", ".e57", ".pcd"):
        assert f"imported {suffix}: 5000 points" in job.stdout, job.stdout
    numpy_pin = next(p for p in MATRIX[series] if p.startswith("numpy=="))
    assert f"numpy: {numpy_pin.split('==')[1]}" in job.stdout  # Blender's numpy, not another
    for module in ("plyfile", "laspy", "lazrs", "pye57", "pypcd4", "lzf", "pydantic_core"):
        assert f"bundled: {module} " in job.stdout, f"{module} was not imported from the zip's wheels"
    assert "scipy: not imported" in job.stdout, job.stdout  # not bundled, not needed
    check_sphere_render(output, new_pass_names=tuple(map(int, series.split("."))) >= (5, 0))
    check_lit_sphere_render(tmp_path / "render_lit.exr")
    print(f"matrix: bpy {series}: installed, imported {len(clouds)} formats and rendered in "
          f"{time.perf_counter() - started:.1f} s")


def settings_walk(python: Path, home: Path, *args: str) -> dict:
    """settings_walk.py's JSON, run by `python` (a bpy; no extension, no pytest)."""
    proc = subprocess.run([str(python), str(SETTINGS_WALK), *args], cwd=home, env=blender_user_env(home),
                          capture_output=True, text=True, timeout=TIMEOUT)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    (line,) = [line for line in proc.stdout.splitlines() if line.startswith("SETTINGS_WALK ")]
    return json.loads(line.partition(" ")[2])


@pytest.fixture(scope="module")
def audited_settings(tmp_path_factory) -> Path:
    """The settings the settings audit walks in the bpy it runs on (this Python's): each
    classified there (tests/blender/test_settings_audit.py)."""
    home = tmp_path_factory.mktemp("audited")
    path = home / "keys.json"
    path.write_text(json.dumps(settings_walk(Path(sys.executable), home)))
    return path


def test_every_setting_of_this_blender_is_audited(series, bpy_python, audited_settings, tmp_path):
    """The settings audit's RNA walk in this series' bpy: every render setting it has was
    walked by the audit in the bpy the audit runs on (honoured, said or listed there), or is
    listed for this version (settings_not_rendered.py) -- a setting a Blender adds or keeps
    from before fails here instead of going unsaid. Entries for settings this series lacks
    are printed, not failed (an entry may be for other versions only)."""
    started = time.perf_counter()
    found = settings_walk(bpy_python, tmp_path, "--against", str(audited_settings))
    print(f"matrix: bpy {series}: {found['keys']} settings walked in {time.perf_counter() - started:.1f} s; "
          f"entries for settings this version lacks: {found['stale']}")
    assert found["version"][:2] == [int(v) for v in series.split(".")[:2]]
    assert not found["unaudited"], (f"Blender {series} has settings the audit (bpy {found['audited_version']}) did "
                                    f"not walk and tests/blender/settings_not_rendered.py does not list for it: "
                                    f"{found['unaudited']}")


def test_the_manifest_claims_exactly_the_tested_range():
    """blender_version_min is the oldest bpy of the matrix; blender_version_max (the first
    version not supported) is the minor release after the newest."""
    manifest = (ROOT / "blender_manifest.toml").read_text()
    claimed = [re.search(rf'(?m)^blender_version_{end} = "([0-9.]+)"$', manifest).group(1) for end in ("min", "max")]
    tested = sorted(tuple(map(int, bpy.split("==")[1].split("."))) for _, bpy, _ in MATRIX.values())
    major, minor, _ = tested[-1]
    assert claimed == [".".join(map(str, tested[0])), f"{major}.{minor + 1}.0"], (claimed, tested)
