"""The installable zip (`make dist`): validated by Blender's tool, installed the way a user
installs it, with its bundled wheels, and rendering with SPLAT_TRACER."""
from __future__ import annotations

import subprocess
import sys
import zipfile
from pathlib import Path

from blender_helpers import blender_user_env, check_lit_sphere_render, check_sphere_render
from geometry import fibonacci_sphere
from splat_tracer.pointcloud.readers import ply

ROOT = Path(__file__).resolve().parents[2]


def test_zip_holds_the_addon_the_portable_core_and_the_wheels_only(dist_zip):
    names = set(zipfile.ZipFile(dist_zip).namelist())
    assert {"blender_manifest.toml", "__init__.py", "LICENSE", "splat_tracer/_core.abi3.so",
            "operators/import_cloud.py", "ui/__init__.py"} <= names
    modules = {p.relative_to(ROOT).as_posix() for p in (ROOT / "splat_tracer").rglob("*.py") if "native" not in p.parts}
    assert "splat_tracer/blender/engine.py" in modules and modules <= names, sorted(modules - names)
    assert not any(n.startswith("splat_tracer/native/") for n in names)  # the sources stay out
    assert not any(n.endswith(".pyd") for n in names)
    # The Zig build of tools/build_native.py (glibc 2.28), not the development build.
    shipped = zipfile.ZipFile(dist_zip).read("splat_tracer/_core.abi3.so")
    assert shipped == (ROOT / "build" / "native" / "linux-x64" / "_core.abi3.so").read_bytes()
    wheels = {n for n in names if n.startswith("wheels/")}
    assert any("plyfile" in w for w in wheels)
    assert not any(name in w for w in wheels for name in ("numpy", "scipy")), wheels  # Blender's; not used
    for name in ("laspy", "pyquaternion", "pypcd4", "pydantic-", "annotated_types", "typing_inspection",
                 "typing_extensions"):
        assert any(name in w for w in wheels), name
    for name in ("lazrs", "pye57", "pydantic_core", "python_neo_lzf"):
        assert all(any(name in w and tag in w for w in wheels) for tag in ("cp311", "cp313")), name
    assert all("manylinux" in w or "none-any" in w for w in wheels), wheels
    assert not any(n.startswith(("tests/", "benchmarks/", "tools/", "splat_tracer/native/")) for n in names)
    manifest = zipfile.ZipFile(dist_zip).read("blender_manifest.toml").decode()
    assert all(f'"./{w}"' in manifest for w in wheels)
    assert 'platforms = ["linux-x64"]' in manifest


def test_zip_installs_into_blender_and_renders(dist_zip, tmp_path):
    """Installed as a user does (Install from Disk), in the development venv's bpy 5.0.1;
    test_blender_versions.py installs it the farm's way into each Blender series."""
    p, n = fibonacci_sphere(5000)
    ply_path = tmp_path / "sphere.ply"
    ply.write_ply(str(ply_path), p, n)
    output = tmp_path / "render.exr"
    proc = subprocess.run([sys.executable, str(ROOT / "tests" / "release" / "install_and_render.py"), "--install",
                           str(dist_zip), "--output", str(output), str(ply_path)], cwd=tmp_path,
                          env=blender_user_env(tmp_path),
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    # The reader came from the extensions' site-packages, not the venv's (install_and_render.py
    # asserts where from); scipy, which the venv has but the zip does not, was never imported.
    assert "bundled: plyfile " in proc.stdout, proc.stdout
    assert "scipy: not imported" in proc.stdout, proc.stdout
    # Blender installed the bundled wheels for this Python into the extensions' site-packages.
    site = list(tmp_path.glob("blender_user_*/**/.local/lib/python3.*/site-packages"))
    assert site and (site[0] / "plyfile.py").is_file() and (site[0] / "lazrs").is_dir(), site
    assert not (site[0] / "scipy").exists(), site
    check_sphere_render(output, new_pass_names=True)
    check_lit_sphere_render(tmp_path / "render_lit.exr")
