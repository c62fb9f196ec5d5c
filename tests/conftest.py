"""Shared fixtures. Blender tests run against the real `bpy` module (never a mock): the
extension is enabled from this source tree, in throwaway Blender user directories."""
from __future__ import annotations

from pathlib import Path

import pytest

from tools import dev_extension

BLENDER_TESTS = Path(__file__).resolve().parent / "blender"
BLENDER_FIXTURES = {"blender", "empty_scene"}

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
    # Samples are Cycles' settings (4096 and 1024 by default); the tests' scenes keep the 16
    # the engine's own setting gave them before, unless a test sets its own.
    scene.cycles.samples = scene.cycles.preview_samples = 16
    # Cycles' Denoise (on by default) is applied by the engine; the tests measure the engine's
    # own image unless they test denoising (test_denoise.py, a default scene's report).
    scene.cycles.use_denoising = False
    return scene


def pytest_collection_modifyitems(config, items):
    """The `blender` marker (pytest.ini), so that `pytest -m "not blender"` needs no bpy: every
    test under blender/, and elsewhere every test using a fixture that imports bpy (directly
    or through another fixture: fixturenames is the closure)."""
    for item in items:
        if BLENDER_TESTS in item.path.parents or BLENDER_FIXTURES & set(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.blender)


def pytest_addoption(parser):
    parser.addoption("--bpy", action="append", default=[], metavar="SERIES",
                     help="release/test_blender_versions.py: a Blender series to install the zip into (4.2, 4.5, "
                          "5.0; repeatable); without it those tests are skipped (make test-matrix passes them)")

