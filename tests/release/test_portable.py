"""The shipped native modules (tools/build_native.py, Zig's clang with its own libc/libc++):
each platform's binary has the right format, exports PyInit__core, and needs nothing from
the system beyond the Python C API and the platform's own libraries. The Linux one needs no
glibc newer than 2.28 and is loaded here and renders.

The fixture runs the build script, so the binaries are always those of the current sources
(Zig caches: seconds when nothing changed; the first build of each target also compiles
Zig's libc++ for it, about 3 minutes each on 2 cores)."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tools import build_native, native_check

from geometry import fibonacci_sphere

ROOT = Path(__file__).resolve().parents[2]

# What a system provides itself and every Blender install can rely on.
LINUX_SYSTEM = {"libc.so.6", "libm.so.6", "libpthread.so.0", "libdl.so.2", "librt.so.1", "ld-linux-x86-64.so.2"}
WINDOWS_SYSTEM_PREFIXES = ("kernel32.dll", "api-ms-win-crt-", "ntdll.dll", "advapi32.dll")
MACOS_SYSTEM = {"/usr/lib/libSystem.B.dylib"}


@pytest.fixture(scope="session")
def native(tmp_path_factory) -> dict[str, Path]:
    subprocess.run([sys.executable, "-m", "tools.build_native"], check=True, timeout=3600, cwd=ROOT)
    out = ROOT / "build" / "native"
    return {p: out / p / name for p, (_, name, _) in build_native.TARGETS.items()}


def test_every_platform_is_built(native):
    assert set(native) == {"linux-x64", "windows-x64", "macos-arm64", "macos-x64"}
    assert all(path.is_file() for path in native.values()), native


@pytest.mark.skipif(not (shutil.which("readelf") and shutil.which("objdump")), reason="needs binutils")
def test_linux_module_needs_glibc_2_28_and_system_libraries_only(native):
    f = native_check.facts(native["linux-x64"])
    assert f.format == "ELF x86-64"
    assert f.glibc and f.glibc <= (2, 28), f.glibc
    assert set(f.libraries) <= LINUX_SYSTEM, f.libraries  # no libstdc++, libgcc_s or libc++
    assert f.exports == {"PyInit__core"}  # the static libc++ stays inside


def test_windows_module_imports_python3_dll_and_system_dlls_only(native):
    f = native_check.facts(native["windows-x64"])
    assert f.format == "PE32+ x86-64"
    assert f.exports == {"PyInit__core"}
    libs = {lib.lower() for lib in f.libraries}
    assert "python3.dll" in libs  # the limited API's DLL, never python311.dll
    assert all(lib == "python3.dll" or lib.startswith(WINDOWS_SYSTEM_PREFIXES) for lib in libs), libs
    python = f.imports[next(lib for lib in f.imports if lib.lower() == "python3.dll")]
    assert "PyModuleDef_Init" in python and all(n.startswith(("Py", "_Py")) for n in python), python


@pytest.mark.parametrize("platform, cpu", [("macos-arm64", "arm64"), ("macos-x64", "x86_64")])
def test_macos_module_loads_libsystem_only_and_finds_python_at_load_time(native, platform, cpu):
    f = native_check.facts(native[platform])
    assert f.format == f"Mach-O {cpu}"
    assert set(f.libraries) <= MACOS_SYSTEM, f.libraries  # libc++ linked in, not a dylib
    assert "PyInit__core" in f.exports
    # Besides the module and the standard mach-o symbols, only operator new/delete (weak
    # definitions of the static libc++) are visible.
    assert all(e in ("PyInit__core", "__dso_handle", "_mh_dylib_header") or e.startswith(("_Znw", "_Zna", "_Zdl", "_Zda"))
               for e in f.exports), f.exports
    flat = f.imports.pop("(flat lookup)")  # -undefined dynamic_lookup: the Python process provides them
    assert "_PyModuleDef_Init" in flat and all(n.startswith(("_Py", "__Py")) for n in flat), flat
    assert set(f.imports) <= MACOS_SYSTEM, f.imports


# Runs in a copy of the package holding the cross-built module, first on the path: what is
# tested is that build, never the repository's development build.
RENDER = r"""
import json, sys
import numpy as np
sys.path.insert(0, sys.argv[1])
from splat_tracer import _core
from splat_tracer.render.camera import Camera
from splat_tracer.render.splats import SplatCloud
p, n = np.load(sys.argv[2])["p"], np.load(sys.argv[2])["n"]
scene = SplatCloud(p, n, np.full(len(p), 0.05))
res = scene.render(Camera.look_at((0, -5, 0), (0, 0, 0)), 80, 60, threads=2)
np.savez(sys.argv[3], rgba=res.rgba, depth=res.depth)
print(json.dumps({"module": _core.__file__}))
"""


def test_linux_module_loads_and_renders_like_the_development_build(native, tmp_path):
    package = tmp_path / "tree" / "splat_tracer"
    shutil.copytree(ROOT / "splat_tracer", package, ignore=shutil.ignore_patterns("native", "_core*", "__pycache__"))
    shutil.copy2(native["linux-x64"], package / "_core.abi3.so")
    p, n = fibonacci_sphere(5000)
    np.savez(tmp_path / "cloud.npz", p=p, n=n)
    proc = subprocess.run([sys.executable, "-c", RENDER, str(tmp_path / "tree"), str(tmp_path / "cloud.npz"),
                           str(tmp_path / "out.npz")], capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert Path(json.loads(proc.stdout)["module"]) == package / "_core.abi3.so"
    portable = np.load(tmp_path / "out.npz")

    from splat_tracer.render.camera import Camera  # the development build (make build, gcc)
    from splat_tracer.render.splats import SplatCloud

    dev = SplatCloud(p, n, np.full(len(p), 0.05)).render(Camera.look_at((0, -5, 0), (0, 0, 0)), 80, 60)
    hit = dev.depth < 1e9
    assert 0.1 < hit.mean() < 0.8
    np.testing.assert_array_equal(portable["depth"] < 1e9, hit)
    np.testing.assert_allclose(portable["depth"][hit], dev.depth[hit], rtol=1e-5)
    np.testing.assert_allclose(portable["rgba"], dev.rgba, atol=1e-5)
