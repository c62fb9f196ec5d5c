"""The layer rule (docs/architecture.md): blender (+ operators/, ui/) -> {pointcloud, render}
-> {util, the native core}. Only the Blender layer imports Blender's modules; the pipeline and
the render API never import each other. Checked twice: statically, every import statement of
every module (so a violation inside a function body is found too), and by importing every
Blender-free module in a fresh Python where `bpy` cannot be imported."""
from __future__ import annotations

import ast
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "splat_tracer"

# Blender's own Python modules: importable only inside Blender (or the bpy wheel).
BLENDER_MODULES = {"bpy", "bpy_extras", "bpy_types", "bmesh", "mathutils", "gpu", "gpu_extras", "bl_ui",
                   "bl_operators", "addon_utils", "idprop", "aud", "blf", "imbuf"}
# What each layer of splat_tracer/ may import from the package ("_core" is the native module).
ALLOWED = {
    "util": {"util"},
    "pointcloud": {"pointcloud", "util", "_core"},
    "render": {"render", "util", "_core"},
    "blender": {"blender", "pointcloud", "render", "util", "_core"},
}
LAYERS = tuple(ALLOWED)


def _imports(source: str, module: str, is_package: bool) -> list[tuple[int, str]]:
    """(line, absolute module name) of every import in `source`, the module `module`
    (dotted, e.g. 'splat_tracer.render.ab'; an __init__.py is its package itself);
    relative imports are resolved."""
    found = []
    package = module if is_package else module.rsplit(".", 1)[0]
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[:len(base) - (node.level - 1)]
                name = ".".join(base + ([node.module] if node.module else []))
            else:
                name = node.module
            # `from . import x` imports the submodule x: record each name as a module too.
            found.append((node.lineno, name))
            if not node.module or node.level:
                found += [(node.lineno, f"{name}.{alias.name}") for alias in node.names]
    return found


def violations(source: str, module: str, is_package: bool = False) -> list[str]:
    """The layer rule's violations in one module's source (empty when it holds)."""
    parts = module.split(".")
    layer = parts[1] if len(parts) > 2 and parts[0] == "splat_tracer" else None
    out = []
    for line, name in _imports(source, module, is_package):
        top = name.split(".")[0]
        if top in BLENDER_MODULES and layer != "blender":
            out.append(f"{module}:{line} imports {name}: only the Blender layer may import Blender's modules")
        if layer and top == "splat_tracer":
            target = name.split(".")[1] if name.count(".") else None
            if target is not None and target in (*LAYERS, "_core") and target not in ALLOWED[layer]:
                out.append(f"{module}:{line} imports {name}: {layer}/ may import only "
                           f"{', '.join(sorted(ALLOWED[layer]))}")
    return out


def _modules():
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(ROOT).with_suffix("")
        parts = list(rel.parts)
        is_package = parts[-1] == "__init__"
        if is_package:
            parts.pop()
        yield ".".join(parts), path, is_package


def test_every_module_belongs_to_a_layer():
    stray = [m for m, _, _ in _modules() if m != "splat_tracer" and m.split(".")[1] not in LAYERS]
    assert not stray, f"modules outside util/, pointcloud/, render/, blender/: {stray}"


def test_no_module_breaks_the_layer_rule():
    found = [v for module, path, is_package in _modules()
             for v in violations(path.read_text(encoding="utf-8"), module, is_package)]
    assert not found, "\n".join(found)


def test_the_package_root_imports_blender_only_inside_register():
    # splat_tracer/__init__.py is imported by every user of the Blender-free layers: Blender
    # may be imported there only lazily, by register().
    tree = ast.parse((PACKAGE / "__init__.py").read_text(encoding="utf-8"))
    top_level = [n for n in tree.body if isinstance(n, (ast.Import, ast.ImportFrom))]
    assert not top_level, "splat_tracer/__init__.py imports at module level"


@pytest.mark.parametrize("module, source, expected", [
    ("splat_tracer.pointcloud.spacing", "from ..render import splats\n", "pointcloud/ may import only"),
    ("splat_tracer.pointcloud.readers.las", "from ...render.method import Method\n", "pointcloud/ may import only"),
    ("splat_tracer.render.ab", "def f():\n    import bpy\n", "only the Blender layer"),
    ("splat_tracer.render.scene", "from splat_tracer.blender import session\n", "render/ may import only"),
    ("splat_tracer.util.columns", "from .. import _core\n", "util/ may import only"),
    ("splat_tracer.render.splats", "from mathutils import Vector\n", "only the Blender layer"),
])
def test_the_check_finds_a_broken_rule(module, source, expected):
    found = violations(source, module)
    assert found and expected in found[0], found


@pytest.mark.parametrize("module, source", [
    ("splat_tracer.pointcloud.spacing", "from ..util.progress import chunks\nfrom .. import _core\n"),
    ("splat_tracer.blender.session", "import bpy\nfrom ..render import scene\nfrom ..pointcloud import cloud\n"),
    ("splat_tracer.render.ab", "from . import difference\nimport numpy as np\n"),
])
def test_the_check_passes_what_the_rule_allows(module, source):
    assert violations(source, module) == []


def test_the_blender_free_layers_import_without_blender():
    # A fresh interpreter (run from the repository root, so splat_tracer is importable) where
    # importing any of Blender's modules fails, as in plain Python.
    script = textwrap.dedent(f"""
        import importlib, pkgutil, sys
        for name in {sorted(BLENDER_MODULES)!r}:
            sys.modules[name] = None
        import splat_tracer
        names = []
        for layer in ("util", "pointcloud", "render"):
            package = importlib.import_module("splat_tracer." + layer)
            names.append(package.__name__)
            for info in pkgutil.walk_packages(package.__path__, package.__name__ + "."):
                importlib.import_module(info.name)
                names.append(info.name)
        loaded = sorted(m for m in sys.modules if m.startswith("splat_tracer.blender"))
        assert not loaded, loaded
        print(len(names))
    """)
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120,
                         cwd=ROOT)
    assert run.returncode == 0, run.stderr
    assert int(run.stdout.split()[-1]) >= 25  # util 5, pointcloud 14, render 8 today


def test_a_package_init_resolves_its_relative_imports_from_itself():
    # In readers/__init__.py, `...render` is splat_tracer.render (a violation) and `.ply`
    # is its own reader.
    assert violations("from ...render import method\n", "splat_tracer.pointcloud.readers", is_package=True)
    assert not violations("from .ply import read_ply\n", "splat_tracer.pointcloud.readers", is_package=True)
