"""Builds the installable extension zip (what `make dist` runs).

    python tools/build_dist.py --output-dir dist

1. Stages the add-on's files (no tests, benchmarks, native sources or build files) and
   the compiled core, splat_tracer/_core.abi3.so, which must have been built.
2. Adds the dependencies Blender does not ship, as unmodified PyPI wheels (scipy, lazrs
   and pye57 for each Python that Blender 4.2 to 5.1 use; plyfile, laspy and pyquaternion,
   pure Python), listed in the staged manifest.
   numpy is never bundled: Blender has its own.
3. Validates and zips with Blender's own extension tool (blender_ext.py, from the bpy wheel).
"""
from __future__ import annotations

import argparse
import importlib.util
import re
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
STAGE = ROOT / "build" / "dist_stage" / "splat_tracer"
WHEEL_CACHE = ROOT / "build" / "wheels"
# Wheel platform tags accepted, matching the manifest's linux-x64: Blender 4.2+ itself
# needs glibc 2.28, so manylinux_2_28 wheels load wherever Blender runs.
PLATFORMS = ("manylinux_2_28_x86_64", "manylinux_2_27_x86_64", "manylinux_2_17_x86_64", "manylinux2014_x86_64")
# (requirement, Python versions to fetch it for). Versions as pinned in requirements.txt.
WHEELS = [("scipy==1.17.1", ("3.11", "3.13")), ("plyfile==1.0.3", ("3.11",)), ("laspy==2.7.0", ("3.11",)),
          ("lazrs==0.8.2", ("3.11", "3.13")), ("pye57==0.4.19", ("3.11", "3.13")), ("pyquaternion==0.9.9", ("3.11",))]
PACKAGE_FILES = ["__init__.py", "blender_manifest.toml", "LICENSE", "README.md"]
PACKAGE_DIRS = ["splat_tracer", "operators", "ui"]
SKIP = shutil.ignore_patterns("__pycache__", "*.pyc", "native")


def blender_ext() -> Path:
    spec = importlib.util.find_spec("bpy")
    if spec is None or spec.origin is None:
        sys.exit("build_dist: the bpy module is needed for Blender's extension tool (run `make dist`)")
    tool = Path(spec.origin).parent / "5.0" / "scripts" / "addons_core" / "bl_pkg" / "cli" / "blender_ext.py"
    if not tool.is_file():
        sys.exit(f"build_dist: {tool} not found")
    return tool


def fetch_wheels() -> list[Path]:
    WHEEL_CACHE.mkdir(parents=True, exist_ok=True)
    found = []
    for requirement, pythons in WHEELS:
        name, version = requirement.split("==")
        for py in pythons:
            tag = "cp" + py.replace(".", "")
            pattern = re.compile(rf"{name}-{re.escape(version)}-(py3-none-any|{tag}-{tag}-.*x86_64.*)\.whl$")
            cached = [w for w in WHEEL_CACHE.glob("*.whl") if pattern.match(w.name)]
            if not cached:
                platforms = [arg for p in PLATFORMS for arg in ("--platform", p)]
                subprocess.run([sys.executable, "-m", "pip", "download", "--quiet", "--no-deps",
                                "--only-binary=:all:", "--python-version", py, *platforms,
                                "--dest", str(WHEEL_CACHE), requirement], check=True)
                cached = [w for w in WHEEL_CACHE.glob("*.whl") if pattern.match(w.name)]
            if not cached:
                sys.exit(f"build_dist: no wheel of {requirement} for Python {py}")
            found.extend(w for w in cached if w not in found)
    return found


def stage(wheels: list[Path]) -> None:
    core = list((ROOT / "splat_tracer").glob("_core*.so"))
    if not core:
        sys.exit("build_dist: splat_tracer/_core.abi3.so is not built (run `make build`)")
    shutil.rmtree(STAGE, ignore_errors=True)
    STAGE.mkdir(parents=True)
    for name in PACKAGE_FILES:
        shutil.copy2(ROOT / name, STAGE / name)
    for name in PACKAGE_DIRS:
        shutil.copytree(ROOT / name, STAGE / name, ignore=SKIP)
    (STAGE / "wheels").mkdir()
    for wheel in wheels:
        shutil.copy2(wheel, STAGE / "wheels" / wheel.name)
    manifest = (STAGE / "blender_manifest.toml").read_text()
    listing = "wheels = [\n" + "".join(f'  "./wheels/{w.name}",\n' for w in wheels) + "]\n"
    manifest = manifest.replace("\n[permissions]", "\n" + listing + "\n[permissions]", 1)
    (STAGE / "blender_manifest.toml").write_text(manifest)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--output-dir", default=str(ROOT / "dist"))
    args = ap.parse_args(argv)
    tool = blender_ext()
    stage(fetch_wheels())
    out = Path(args.output_dir).resolve()
    out.mkdir(parents=True, exist_ok=True)
    subprocess.run([sys.executable, str(tool), "validate", str(STAGE)], check=True)
    subprocess.run([sys.executable, str(tool), "build", "--source-dir", str(STAGE), "--output-dir", str(out)],
                   check=True)
    zips = sorted(out.glob("splat_tracer-*.zip"), key=lambda p: p.stat().st_mtime)
    print(f"build_dist: {zips[-1]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
