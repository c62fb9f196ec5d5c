"""Loading the extension from the source tree into bpy, without building a zip.

Used by the tests and the demo. Call `isolate_user_dirs()` before the first `import bpy`
so that nothing is read from or written to the user's real Blender configuration.
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parent.parent
EXTENSION_ID = "splat_tracer"
REPO_MODULE = "dev"
ADDON_MODULE = f"bl_ext.{REPO_MODULE}.{EXTENSION_ID}"


def isolate_user_dirs(base: str | None = None) -> Path:
    """Points Blender's user config/scripts/resources at throwaway directories."""
    base = Path(base or tempfile.mkdtemp(prefix="splat_tracer_blender_"))
    for var in ("BLENDER_USER_CONFIG", "BLENDER_USER_SCRIPTS", "BLENDER_USER_RESOURCES"):
        path = base / var.lower()
        path.mkdir(parents=True, exist_ok=True)
        os.environ[var] = str(path)
    return base


def enable_from_source(workdir: Path) -> str:
    """Registers a local extension repository whose only entry links to this source tree,
    and enables the add-on. Returns the add-on's module name."""
    import addon_utils
    import bpy

    repo_dir = Path(workdir) / "extension_repo"
    repo_dir.mkdir(parents=True, exist_ok=True)
    link = repo_dir / EXTENSION_ID
    if not link.exists():
        link.symlink_to(REPO_ROOT, target_is_directory=True)
    repos = bpy.context.preferences.extensions.repos
    if not any(r.module == REPO_MODULE for r in repos):
        repos.new(name="splat_tracer dev", module=REPO_MODULE, custom_directory=str(repo_dir), source="USER")
    errors = []
    addon_utils.enable(ADDON_MODULE, default_set=True, handle_error=errors.append)
    if errors:
        raise RuntimeError(f"enabling {ADDON_MODULE} failed: {errors[0]!r}")
    if not hasattr(bpy.types.Scene, "splat_tracer"):
        raise RuntimeError(f"{ADDON_MODULE} did not register")
    return ADDON_MODULE


def start_docs_tool(build: Path, description: str, default_output: Path, argv=None):
    """The start of a tool that renders the README's images: its --output-dir argument, bpy
    with throwaway user directories under `build`, and the extension enabled from source.
    Returns (args, bpy)."""
    import argparse

    ap = argparse.ArgumentParser(description=description, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--output-dir", default=str(default_output))
    args = ap.parse_args(argv)
    build.mkdir(parents=True, exist_ok=True)
    isolate_user_dirs(str(build / "blender_user"))
    import bpy

    enable_from_source(build)
    return args, bpy
