"""The Windows build loaded and run, under Wine (`make test-windows`): the Windows core and
the windows_x64 zip in Windows CPython and the Windows `bpy` 5.0.1, against the Linux build
on the same inputs. tools/wine.py sets up Wine (from Debian's packages when missing), its
prefix and the Windows Pythons and wheels (PyPI), under build/windows/.

1. The Windows core (`_core.pyd`, Zig's cross build) in Windows Python 3.11 with numpy
   1.26.4, and the Linux one (`_core.abi3.so`, the one the Linux zip ships) in this Python,
   run core_check.py on one .npz of inputs: the core's entry points (trace, the headlight
   render, k-nearest neighbours) and the Python API over it (trace_surface, a RenderScene
   with a mesh floor and a sun, the normals' estimation and orientation, splat radii).
   Every answer must be bit-identical, except where a value is an average over samples:
   the RenderScene's Combined and Diffuse Color. Their sample positions and directions go
   through sin, cos and exp of the C library, and Wine's UCRT rounds some of them
   differently from glibc; a sample then lands a hair elsewhere. Measured: 258 of 307,200
   Combined values differ, by at most 8.9e-7, and 6 of 230,400 Diffuse Color values, by
   6e-8. Allowed: at most 1 % of the values, each within 1e-5.
2. The same core in Windows Python 3.13 without numpy (numpy 2's Windows wheels need
   ucrtbase's crealf, which Wine 8.0 lacks): the numpy-free half of core_check.py, through
   memoryviews; bit-identical to Linux.
3. The windows_x64 zip installed into the Windows bpy 5.0.1 by Install from Disk (Blender's
   extension operator; the zip's Windows wheels go into the extensions' site-packages), a
   PLY, a LAZ (laspy + lazrs) and an E57 (pye57) imported through them, and the sphere
   rendered headlit and lit (install_and_render.py). The Linux zip does the same in this
   venv's bpy 5.0.1; the two EXRs must match pass by pass: bit for bit, but the lit
   Combined pass (sampled: measured 8 of 19,200 values per channel within 1.5e-8).
   Both in one process: the farm's way (install, then the next Blender reads the saved
   preferences: test_blender_versions.py) cannot run under Wine 8.0, whose Blender fails to
   read an uncompressed .blend ("not a blend file"), the saved preferences included.

What this proves: the Windows binaries (the core, lazrs, pye57 and Blender's own) load and
compute the same images as on Linux, against Windows' DLL names, calling conventions and
import tables, in the Python and Blender builds users run. What it does not: Wine is not
Windows. Its system DLLs, its C runtime's maths, its file system and its thread scheduling
are reimplementations, and it lacks pieces (see tools/wine.py: bcryptprimitives.dll); a
fault that only Windows' own DLLs, a real GPU driver, Windows paths with drive letters other
than Z:, or an antivirus would show is not caught here.
"""
from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from blender_helpers import blender_user_env, check_lit_sphere_render, check_sphere_render, read_exr
from geometry import sphere_cloud
from splat_tracer.render.camera import Camera
from tools import wine

ROOT = Path(__file__).resolve().parents[2]
CORE_CHECK = ROOT / "tests" / "release" / "core_check.py"
INSTALLER = ROOT / "tests" / "release" / "install_and_render.py"
# Answers that average samples (see the docstring), and how far Windows may be from Linux.
# Noisy Image is the lit render's Combined before the denoiser (Cycles' Denoise is on by
# default): the same average.
SAMPLED = {"scene_Combined", "scene_DiffCol", "render_lit.exr:ViewLayer.Combined",
           "render_lit.exr:ViewLayer.Noisy Image"}
SAMPLED_SHARE, SAMPLED_TOLERANCE = 0.01, 1e-5
# What core_check.py answers without numpy (its first half).
CORE_ANSWERS = {"trace_t", "trace_id", "trace_front", "trace_normal", "headlight_rgba", "headlight_depth",
                "headlight_normal", "knn_at_dist", "knn_at_ids", "knn_dist", "knn_ids"}


@pytest.fixture(scope="module")
def pythons() -> dict[str, Path]:
    try:
        return wine.setup()
    except wine.WineUnavailable as e:
        # CI (CI=true) installs Wine from Debian's packages as root: there a missing Wine is a
        # broken check, never a reason to pass.
        if os.environ.get("CI"):
            pytest.fail(f"Wine cannot be installed in CI: {e}")
        pytest.skip(f"Wine cannot be installed here: {e}")


@pytest.fixture(scope="module")
def zips(tmp_path_factory) -> dict[str, Path]:
    """The windows_x64 and linux_x64 zips; their cores are left in build/native/<platform>/."""
    out = tmp_path_factory.mktemp("dist")
    subprocess.run([sys.executable, "-m", "tools.build_dist", "--platform", "windows-x64", "--platform", "linux-x64",
                    "--output-dir", str(out)], check=True, cwd=ROOT, timeout=3600)
    return {platform: next(out.glob(f"splat_tracer-*-{platform.replace('-', '_')}.zip"))
            for platform in ("windows-x64", "linux-x64")}


def package_with(core: Path, tree: Path) -> Path:
    """A copy of the splat_tracer package holding `core` and no other build of it."""
    shutil.copytree(ROOT / "splat_tracer", tree / "splat_tracer",
                    ignore=shutil.ignore_patterns("native", "_core*", "__pycache__"))
    shutil.copy2(core, tree / "splat_tracer" / core.name)
    return tree


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> Path:
    """core_check.py's inputs, made here once: a closed 20,000-splat sphere, 4,096 rays at it
    from every side, a camera, k-NN queries and a floor under the sphere."""
    path = tmp_path_factory.mktemp("core_check") / "inputs.npz"
    centres, normals, radii = sphere_cloud(20000)
    rng = np.random.default_rng(1)
    origins = rng.normal(size=(4096, 3))
    origins *= 3.0 / np.linalg.norm(origins, axis=1, keepdims=True)
    directions = rng.normal(size=(4096, 3)) * 0.3 - origins  # towards the sphere, some missing it
    camera = Camera.look_at((0.3, -4.0, 1.2), (0.0, 0.0, -0.3), fov_y=40.0, aspect=4 / 3)
    f32 = np.float32
    np.savez(path, centres=centres.astype(f32), normals=normals.astype(f32), radii=radii.astype(f32),
             origins=origins.astype(f32), directions=directions.astype(f32),
             # the camera as the core takes it: local_from_camera 4x4, frustum, clip range and projection (12)
             local_from_camera=np.ascontiguousarray(camera.native()[0], np.float64),
             frustum=np.ascontiguousarray(camera.native()[1], np.float64),
             orthographic=np.array([camera.orthographic], np.int32),
             size=np.array([320, 240], np.int32), queries=rng.uniform(-1.2, 1.2, (2000, 3)).astype(f32),
             rows=np.arange(0, 20000, 7, dtype=np.int32),
             floor_vertices=np.array([[-4, -4, -1], [4, -4, -1], [4, 4, -1], [-4, 4, -1]], f32),
             floor_triangles=np.array([[0, 1, 2], [0, 2, 3]], np.int32), sun_direction=np.array([0.5, 0.6, -1.0]))
    return path


@pytest.fixture(scope="module")
def linux_answers(zips, inputs, tmp_path_factory) -> tuple[dict, Path]:
    work = tmp_path_factory.mktemp("linux")
    tree = package_with(ROOT / "build" / "native" / "linux-x64" / "_core.abi3.so", work / "tree")
    proc = subprocess.run([sys.executable, str(CORE_CHECK), str(tree), str(inputs), str(work / "answers.npz")],
                          capture_output=True, text=True, timeout=600, cwd=work)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    facts = json.loads(proc.stdout.splitlines()[-1])
    assert Path(facts["module"]) == tree / "splat_tracer" / "_core.abi3.so"
    return facts, work / "answers.npz"


def windows_core_check(python: Path, inputs: Path, work: Path) -> tuple[dict, Path]:
    tree = package_with(ROOT / "build" / "native" / "windows-x64" / "_core.pyd", work / "tree")
    proc = wine.run_python(python, [CORE_CHECK, tree, inputs, work / "answers.npz"], cwd=work)
    assert proc.returncode == 0, proc.stdout
    facts = json.loads(proc.stdout.splitlines()[-1])
    assert facts["platform"] == "win32"
    assert facts["module"] == wine.windows_path(tree / "splat_tracer" / "_core.pyd"), facts  # no other build
    return facts, work / "answers.npz"


def differing(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Where the bits differ (NaN == NaN, 0.0 != -0.0)."""
    return a.view(f"u{a.itemsize}") != b.view(f"u{b.itemsize}")


def assert_same(name: str, linux: np.ndarray, windows: np.ndarray) -> None:
    assert (windows.dtype, windows.shape) == (linux.dtype, linux.shape), name
    off = differing(np.ascontiguousarray(linux), np.ascontiguousarray(windows))
    if name in SAMPLED:
        worst = float(np.abs(linux[off].astype(np.float64) - windows[off]).max()) if off.any() else 0.0
        assert off.mean() <= SAMPLED_SHARE and worst <= SAMPLED_TOLERANCE, (
            f"{name}: {off.sum()} of {off.size} values differ from Linux's, by up to {worst:.3g}")
    else:
        assert not off.any(), f"{name}: {off.sum()} of {off.size} values differ from Linux's (must be bit-identical)"


def assert_same_answers(linux: Path, windows: Path, names: set) -> None:
    with np.load(linux) as a, np.load(windows) as b:
        assert set(b.files) == names, sorted(set(b.files) ^ names)
        for name in sorted(names):
            assert_same(name, a[name], b[name])


def test_windows_core_in_python_3_11_answers_like_the_linux_core(pythons, linux_answers, inputs, tmp_path):
    linux_facts, linux = linux_answers
    facts, windows = windows_core_check(pythons["3.11"], inputs, tmp_path)
    assert facts["python"].startswith("3.11.") and facts["numpy"] == "1.26.4", facts
    assert facts["simd"] == linux_facts["simd"], (facts["simd"], linux_facts["simd"])  # the same kernels chosen
    assert set(facts["answers"]) == set(linux_facts["answers"]) > CORE_ANSWERS
    assert_same_answers(linux, windows, set(linux_facts["answers"]))


def test_windows_core_in_python_3_13_without_numpy_answers_like_the_linux_core(pythons, linux_answers, inputs,
                                                                               tmp_path):
    facts, windows = windows_core_check(pythons["3.13"], inputs, tmp_path)
    assert facts["python"].startswith("3.13.") and facts["numpy"] is None, facts  # the abi3 module, no numpy
    assert_same_answers(linux_answers[1], windows, CORE_ANSWERS)


def windows_user_dirs(home: Path) -> dict[str, str]:
    """blender_user_env's directories, as the Windows Blender sees them."""
    return {var: wine.windows_path(home / var.lower())
            for var in ("BLENDER_USER_CONFIG", "BLENDER_USER_SCRIPTS", "BLENDER_USER_RESOURCES")}


def test_windows_zip_installs_into_windows_blender_and_renders_like_linux(pythons, zips, clouds, tmp_path):
    linux_home, windows_home = tmp_path / "linux", tmp_path / "windows"
    linux_home.mkdir(), windows_home.mkdir()
    linux = subprocess.run([sys.executable, str(INSTALLER), "--install", str(zips["linux-x64"]), "--output",
                            str(linux_home / "render.exr"), *map(str, clouds)], cwd=linux_home,
                           env=blender_user_env(linux_home),
                           capture_output=True, text=True, timeout=900)
    assert linux.returncode == 0, linux.stdout + linux.stderr

    proc = wine.run_python(pythons["3.11"], [INSTALLER, "--install", zips["windows-x64"], "--output",
                                             windows_home / "render.exr", *clouds], cwd=windows_home,
                           env=wine.environment(**windows_user_dirs(windows_home)))
    log = proc.stdout
    print(log)
    assert proc.returncode == 0, log
    assert not [line for line in log.splitlines() if re.search(r"\b(Error|ERROR)\b|Traceback", line)], log
    assert "installed with the operator into Blender 5.0.1 (online access: False)" in log, log
    assert "farm_check: scene 'Scene' renders with Splat Tracer" in log
    for suffix in (".ply", ".laz", ".e57", ".pcd"):
        assert f"imported {suffix}: 5000 points" in log, log
    # from the extensions' site-packages (the script checks)
    for module in ("plyfile", "laspy", "lazrs", "pye57", "pypcd4", "lzf", "pydantic_core"):
        assert f"bundled: {module} " in log, f"{module} was not imported from the zip's wheels"
    assert "numpy: 1.26.4" in log and "scipy: not imported" in log, log
    # Blender installed the zip's Windows wheels for its Python.
    site = windows_home / "blender_user_resources" / "extensions" / ".local" / "lib" / "python3.11" / "site-packages"
    assert list(site.glob("lazrs/*.cp311-win_amd64.pyd")) and list(site.glob("pye57/*.cp311-win_amd64.pyd")), site

    check_sphere_render(windows_home / "render.exr", new_pass_names=True)
    check_lit_sphere_render(windows_home / "render_lit.exr")
    for name in ("render.exr", "render_lit.exr"):
        a, b = read_exr(linux_home / name), read_exr(windows_home / name)
        assert sorted(a) == sorted(b), name
        for channel in sorted(a):
            answer = f"{name}:{channel.rsplit('.', 1)[0]}"  # the pass: render_lit.exr:ViewLayer.Combined
            assert_same(answer if answer in SAMPLED else f"{name}:{channel}", a[channel].pixels, b[channel].pixels)
