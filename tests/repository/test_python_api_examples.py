"""The examples of docs/python-api.md run against the code as it is.

The ```python blocks run in order, in one namespace (a later block uses what an earlier one
made: `cloud`, `cam`, `full`), from a scratch folder. The names the examples leave to the
reader are made here, small: a LAZ file `scan.laz`, a sphere's points and normals, rays
towards it, and a floor of two triangles. A failing example fails with its block's line.
Needs the native core (and laspy with lazrs for the LAZ file), not bpy: about 3 s.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from geometry import fibonacci_sphere

ROOT = Path(__file__).resolve().parents[2]
API = ROOT / "docs" / "python-api.md"
_PYTHON_BLOCK = re.compile(r"^```python\n(.*?)^```", re.MULTILINE | re.DOTALL)


def examples() -> list[tuple[int, str]]:
    """(first line number, code) of each python block."""
    text = API.read_text(encoding="utf-8")
    return [(text.count("\n", 0, m.start(1)) + 1, m.group(1)) for m in _PYTHON_BLOCK.finditer(text)]


def reader_inputs(folder: Path) -> dict:
    """What the examples take as given, as small as makes them meaningful."""
    laspy = pytest.importorskip("laspy")
    points, normals = fibonacci_sphere(2000)
    header = laspy.LasHeader(point_format=0, version="1.2")
    header.scales, header.offsets = (1e-4, 1e-4, 1e-4), (0.0, 0.0, 0.0)
    las = laspy.LasData(header)
    las.x, las.y, las.z = points.T
    las.write(str(folder / "scan.laz"), laz_backend=laspy.LazBackend.Lazrs)
    rng = np.random.default_rng(0)
    return dict(
        points64=points.astype(np.float64) + 1e5,  # georeferenced
        normals=normals, centres=points, radii=np.full(len(points), 0.08),
        origins=np.tile([0.0, 0.0, 5.0], (100, 1)), directions=rng.normal([0.0, 0.0, -1.0], 0.1, (100, 3)),
        eye=(0.0, -5.0, 0.0), target=(0.0, 0.0, 0.0),
        vertices=np.array([[-3, -3, -1.5], [3, -3, -1.5], [3, 3, -1.5], [-3, 3, -1.5]], float),
        triangles=[[0, 1, 2], [0, 2, 3]],
    )


def test_there_are_examples():
    assert len(examples()) >= 4


def test_the_examples_run(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    namespace = reader_inputs(tmp_path)
    for line, code in examples():
        exec(compile(code, f"{API.relative_to(ROOT)} (block at line {line})", "exec"), namespace)
    # and they did what their comments say
    assert namespace["sniff"]("scan.laz") == "LAS"
    assert len(namespace["prepared"].local) == 2000
    assert (namespace["surf"].id >= 0).any() and namespace["surf"].members is not None
    assert namespace["image"].rgba.shape == (480, 640, 4)
    assert {"Combined", "Depth", "Shadow"} <= set(namespace["frame"].passes)
    assert namespace["frame"].counters["shadow_rays"] > 0
    # Noise control: adaptive sampling stops some pixels before the 256 samples.
    assert 0 < namespace["taken"] < 256 * 320 * 240
