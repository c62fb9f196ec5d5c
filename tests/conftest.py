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
