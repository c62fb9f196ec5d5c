"""Builds the installable extension zips, one per platform (what `make dist` runs).

    python -m tools.build_dist [--platform linux-x64 ...] --output-dir dist

writes dist/splat_tracer-<version>-<platform>.zip for linux-x64, windows-x64, macos-arm64
and macos-x64 (default: all four). For each platform:

1. Builds that platform's native core with tools/build_native.py (Zig; Linux: glibc 2.28),
   never the development build of `make build`.
2. Stages the add-on's files (no tests, benchmarks, native sources or build files), the
   core, and the dependencies Blender does not ship as unmodified PyPI wheels for that
   platform (lazrs, pye57, pydantic_core and python-neo-lzf, compiled, for each Python that
   Blender 4.2 to 5.2 use; plyfile, laspy, pyquaternion, pypcd4, pydantic and its small
   dependencies, pure Python), listed in the staged manifest, whose `platforms` is that one
   platform. A reader's wheel that PyPI lacks for a platform (pye57 on macOS x64) is left out
   with a warning: that format is then refused there with a message. numpy is never
   bundled: Blender has its own. Nor is scipy: the add-on does not use it (the neighbour
   search and the normals' spanning tree are in the core).
3. Validates and zips with Blender's own extension tool (blender_ext.py, from the bpy
   wheel), `build --split-platforms`: the platform suffix in the name and the generated
   manifest block that extension repositories read.

One zip per platform rather than one for all: the Linux and macOS cores share the file name
_core.abi3.so, and each platform needs its own lazrs and pye57 wheels (pye57's Linux ones
are ~17 MB per Python version, a few MB elsewhere), which a single zip would carry for
everyone. blender_ext.py's --split-platforms only filters wheels, never other files, so the
split is made here.
"""
from __future__ import annotations

import argparse
import importlib.util
import re
import shutil
import subprocess
import sys
from pathlib import Path

from tools import build_native

ROOT = Path(__file__).resolve().parent.parent
STAGE_ROOT = ROOT / "build" / "dist_stage"
WHEEL_CACHE = ROOT / "build" / "wheels"
# Wheel platform tags pip may pick for each Blender platform, and the pattern of the wheel
# file names that fit it. Linux: Blender 4.2+ itself needs glibc 2.28, so manylinux_2_28
# wheels load wherever Blender runs. macOS: pip takes a macosx_X_Y tag as "X.Y or older";
# Blender 4.2 runs on macOS 11.2, so both ask for 11.0, the core's own target (the wheels
# bundled now: lazrs and pye57 11.0 on arm64, lazrs 10.12 on x64).
PLATFORMS = {
    "linux-x64": (("manylinux_2_28_x86_64", "manylinux_2_27_x86_64", "manylinux_2_17_x86_64",
                   "manylinux2014_x86_64"), r".*manylinux.*_x86_64"),
    "windows-x64": (("win_amd64",), r"win_amd64"),
    "macos-arm64": (("macosx_11_0_arm64",), r"macosx_\d+_\d+_(arm64|universal2)"),
    "macos-x64": (("macosx_11_0_x86_64",), r"macosx_\d+_\d+_(x86_64|universal2)"),
}
# (requirement, Python versions to fetch it for): one cp311 wheel serves Blender 4.2 to
# 5.0, a cp313 one 5.1 and 5.2.
# The third field: whether the add-on needs it everywhere (True) or only for one reader, which
# refuses its format with a message where the wheel is missing (False).
# PCD's pypcd4 brings pydantic (its header model) and python-neo-lzf (binary_compressed):
# pydantic_core and python-neo-lzf are compiled, the rest pure Python.
WHEELS = [("plyfile==1.0.3", ("3.11",), True), ("laspy==2.7.0", ("3.11",), False),
          ("lazrs==0.8.2", ("3.11", "3.13"), False), ("pye57==0.4.19", ("3.11", "3.13"), False),
          ("pyquaternion==0.9.9", ("3.11",), False),
          ("pypcd4==1.5.1", ("3.11",), False), ("pydantic==2.14.4", ("3.11",), False),
          ("pydantic_core==2.50.5", ("3.11", "3.13"), False), ("annotated-types==0.8.0", ("3.11",), False),
          ("typing-inspection==0.4.5", ("3.11",), False), ("typing_extensions==4.16.0", ("3.11",), False),
          ("python-neo-lzf==0.3.5", ("3.11", "3.13"), False)]
PACKAGE_FILES = ["__init__.py", "blender_manifest.toml", "LICENSE", "THIRD-PARTY-NOTICES.md", "README.md"]
PACKAGE_DIRS = ["splat_tracer", "operators", "ui"]
# The development core (make build) is never shipped: each stage gets its platform's.
SKIP = shutil.ignore_patterns("__pycache__", "*.pyc", "native", "_core*.so", "_core*.pyd")


def blender_ext() -> Path:
    spec = importlib.util.find_spec("bpy")
    if spec is None or spec.origin is None:
        sys.exit("build_dist: the bpy module is needed for Blender's extension tool (run `make dist`)")
    tool = Path(spec.origin).parent / "5.0" / "scripts" / "addons_core" / "bl_pkg" / "cli" / "blender_ext.py"
    if not tool.is_file():
        sys.exit(f"build_dist: {tool} not found")
    return tool


def fetch_wheels(platform: str) -> list[Path]:
    WHEEL_CACHE.mkdir(parents=True, exist_ok=True)
    tags, platform_pattern = PLATFORMS[platform]
    found = []
    for requirement, pythons, required in WHEELS:
        name, version = requirement.split("==")
        for py in pythons:
            tag = "cp" + py.replace(".", "")
            wheel_name = re.escape(re.sub(r"[-_.]+", "_", name))  # a wheel's file name spells it with '_'
            pattern = re.compile(rf"{wheel_name}-{re.escape(version)}-(py3-none-any|{tag}-{tag}-{platform_pattern})"
                                 r"\.whl$")
            cached = [w for w in WHEEL_CACHE.glob("*.whl") if pattern.match(w.name)]
            if not cached:
                platforms = [arg for p in tags for arg in ("--platform", p)]
                subprocess.run([sys.executable, "-m", "pip", "download", "--quiet", "--no-deps",
                                "--only-binary=:all:", "--python-version", py, *platforms,
                                "--dest", str(WHEEL_CACHE), requirement], check=required,
                               stderr=None if required else subprocess.DEVNULL)
                cached = [w for w in WHEEL_CACHE.glob("*.whl") if pattern.match(w.name)]
            if not cached:
                if required:
                    sys.exit(f"build_dist: no {platform} wheel of {requirement} for Python {py}")
                print(f"build_dist: warning: no {platform} wheel of {requirement} for Python {py}; its reader "
                      "refuses that format there", file=sys.stderr)
            found.extend(w for w in sorted(cached)[-1:] if w not in found)
    return found


def stage(platform: str, core: Path, wheels: list[Path]) -> Path:
    stage_dir = STAGE_ROOT / platform / "splat_tracer"
    shutil.rmtree(stage_dir, ignore_errors=True)
    stage_dir.mkdir(parents=True)
    for name in PACKAGE_FILES:
        shutil.copy2(ROOT / name, stage_dir / name)
    for name in PACKAGE_DIRS:
        shutil.copytree(ROOT / name, stage_dir / name, ignore=SKIP)
    shutil.copy2(core, stage_dir / "splat_tracer" / core.name)
    (stage_dir / "wheels").mkdir()
    for wheel in wheels:
        shutil.copy2(wheel, stage_dir / "wheels" / wheel.name)
    manifest = (stage_dir / "blender_manifest.toml").read_text()
    manifest, n = re.subn(r"(?m)^platforms = \[.*\]$", f'platforms = ["{platform}"]', manifest)
    if n != 1:
        sys.exit("build_dist: blender_manifest.toml has no one-line `platforms = [...]`")
    listing = "wheels = [\n" + "".join(f'  "./wheels/{w.name}",\n' for w in wheels) + "]\n"
    manifest = manifest.replace("\n[permissions]", "\n" + listing + "\n[permissions]", 1)
    (stage_dir / "blender_manifest.toml").write_text(manifest)
    return stage_dir


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--platform", action="append", choices=sorted(PLATFORMS),
                    help="a Blender platform to package (repeatable; default: all)")
    ap.add_argument("--output-dir", default=str(ROOT / "dist"))
    args = ap.parse_args(argv)
    tool = blender_ext()
    out = Path(args.output_dir).resolve()
    out.mkdir(parents=True, exist_ok=True)
    for platform in args.platform or list(PLATFORMS):
        core = build_native.build(platform, ROOT / "build" / "native")
        stage_dir = stage(platform, core, fetch_wheels(platform))
        subprocess.run([sys.executable, str(tool), "validate", str(stage_dir)], check=True)
        subprocess.run([sys.executable, str(tool), "build", "--split-platforms", "--source-dir", str(stage_dir),
                        "--output-dir", str(out)], check=True)
        suffix = platform.replace("-", "_")
        print(f"build_dist: {out / f'splat_tracer-{version()}-{suffix}.zip'}")
    return 0


def version() -> str:
    return re.search(r'(?m)^version = "([^"]+)"', (ROOT / "blender_manifest.toml").read_text()).group(1)


if __name__ == "__main__":
    sys.exit(main())
