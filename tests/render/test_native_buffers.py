"""Every native entry point that writes into caller-given buffers refuses an output sharing
memory with an input or with another output (issue #22: PointIndex.covering given an `out`
overlapping `rows` segfaulted). For each binding and each (output, other buffer) pair: the
very same array (where dtype and shape allow), a reshaped view of the other's memory, and a
view sharing only the other's last bytes are each refused with a ValueError naming both;
the same call with separate buffers works."""
from __future__ import annotations

import re

import numpy as np
import pytest

from splat_tracer import _core
from splat_tracer.render.camera import Camera
from splat_tracer.render.method import Method
from splat_tracer.render.scene import Instance, RenderScene
from splat_tracer.render.shading import RenderSettings
from splat_tracer.render.splats import SplatCloud

from geometry import sphere_cloud

N = 64   # points, rays
K = 4    # neighbours


def _cloud():
    return SplatCloud(*sphere_cloud(200))


def _rays():
    rng = np.random.default_rng(1)
    o = np.tile(np.float32([0, 0, 3]), (N, 1))
    d = (rng.normal(size=(N, 3)) * 0.1 + [0, 0, -1]).astype(np.float32)
    return o, d


def _camera_args():
    cam = Camera.look_at((0, 0, 4), (0, 0, 0), (0, 1, 0), 40.0, 1.0)
    return list(cam.native())  # local_from_camera, frustum, orthographic


def _points():
    return np.random.default_rng(2).random((N, 3)).astype(np.float32)


def _normals32():
    n = np.random.default_rng(3).normal(size=(N, 3)).astype(np.float32)
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def _neighbours():
    rng = np.random.default_rng(4)
    return ((np.arange(N)[:, None] + rng.integers(1, N, (N, K))) % N).astype(np.int32)


# name -> (build() -> (function, positional args, keyword args), the output arguments'
# names; args are addressed by position (int) or keyword (str)).
def _trace():
    o, d = _rays()
    return (_cloud()._scene.trace, [o, d, 0.0, np.inf, np.empty(N, np.float32), np.empty(N, np.int32),
                                    np.empty(N, np.bool_)],
            {"out_normal": np.empty((N, 3), np.float32), "out_stats": np.zeros(2, np.int64)})


def _trace_surface():
    o, d = _rays()
    return (_cloud()._scene.trace_surface,
            [o, d, 0.0, np.inf, Method(), np.empty(N, np.float32), np.empty(N, np.int32),
             np.empty(N, np.bool_), np.empty((N, 3), np.float32), np.empty((N, 3), np.float32)],
            {"out_members": np.empty((N, _core.MAX_LAYER_HITS), np.int32), "inside": np.zeros(N, np.bool_),
             "exclude": np.full((N, 2), -1, np.int32)})


def _splat_render():
    return (_cloud()._scene.render, _camera_args() + [8, 8, (0, 0, 8, 8), (0.0, 0.0, 0.0, 0.0),
                                                     np.empty((8, 8, 4), np.float32)],
            {"out_depth": np.empty((8, 8), np.float32), "out_normal": np.empty((8, 8, 3), np.float32)})


def _scene_render():
    scene = RenderScene([Instance(_cloud())])
    passes = {"depth": 1, "normal": 3, "diffcol": 3, "emit": 3, "shadow": 3, "index": 1, "splat_count": 1}
    return (scene._scene.render, _camera_args() + [8, 8, (0, 0, 8, 8), RenderSettings(samples=1).pack(),
                                                  Method(), (0.0, 0.0, 0.0), False,
                                                  np.empty((8, 8, 4), np.float32)],
            {k: np.empty((8, 8) if c == 1 else (8, 8, c), np.float32) for k, c in passes.items()})


def _index():
    return _core.PointIndex(_points())


def _run_nodes():
    from splat_tracer.render import nodes

    b = nodes.Builder()
    r = b.register(width=3)
    b.emit("GLOBAL", r, nodes.GLOBALS.index("POSITION"))
    code, data, outputs, images = b.program().native()
    width = 3 * len(nodes.GLOBAL_FIELDS) + 3  # render/nodes.py run: the vec3 fields, then three floats
    return (_core.run_nodes, [code, data, outputs, images, np.zeros((N, width), np.float32),
                              np.empty((N, len(data)), np.float32)], {})


ROWS = np.arange(N, dtype=np.int32)
CASES = {
    "run_nodes": (_run_nodes, [5]),
    "SplatCloud.trace": (_trace, [4, 5, 6, "out_normal", "out_stats"]),
    "SplatCloud.trace_surface": (_trace_surface, [5, 6, 7, 8, 9, "out_members"]),
    "SplatCloud.render": (_splat_render, [7, "out_depth", "out_normal"]),
    "RenderScene.render": (_scene_render, [10, "depth", "normal", "diffcol", "emit", "shadow", "index",
                                           "splat_count"]),
    "PointIndex.knn": (lambda: (_index().knn, [ROWS.copy(), K, np.empty((N, K), np.float32),
                                               np.empty((N, K), np.int32)], {}), [2, 3]),
    "PointIndex.knn_at": (lambda: (_index().knn_at, [_points(), K, np.empty((N, K), np.float32),
                                                     np.empty((N, K), np.int32)], {}), [2, 3]),
    "PointIndex.covering": (lambda: (_index().covering, [ROWS.copy(), _normals32(), np.full(N, 0.1, np.float32), K,
                                                         1.0, 2.0, np.empty(N, np.float32)], {}), [6]),
    "PointIndex.radii": (lambda: (_index().radii, [ROWS.copy(), K, np.empty(N, np.float32), _normals32(), K, 1.0,
                                                   2.0, np.empty(N, np.float32)], {}), [2, 7]),
    "PointIndex.widest_gaps": (lambda: (_index().widest_gaps, [ROWS.copy(), K, _normals32(),
                                                               np.empty(N, np.float32)], {}), [3]),
    "PointIndex.pca": (lambda: (_index().pca, [ROWS.copy(), K, np.empty((N, 3), np.float64)],
                                {"graph": np.empty((N, K + 1), np.int32), "spacing_k": K,
                                 "spacing": np.empty(N, np.float32), "cover_k": K, "hole": 1.0, "max_gap": 2.0,
                                 "cover": np.empty(N, np.float32)}), [2, "graph", "spacing", "cover"]),
    "camera_rays": (lambda: (_core.camera_rays, [*_camera_args(), 8, 8, np.empty((64, 3), np.float32),
                                                np.empty((64, 3), np.float32)], {}), [5, 6]),
    "spatial_order": (lambda: (_core.spatial_order, [_points().astype(np.float64), np.empty(N, np.int32)], {}), [1]),
    "first_of_duplicates": (lambda: (_core.first_of_duplicates, [_points(), np.empty(N, np.bool_)], {}), [1]),
    "permute_table": (lambda: (_core.permute_table, [_neighbours(), ROWS[::-1].copy(), 0,
                                                     np.empty((N, K), np.int32)], {}), [3]),
    "take_rows": (lambda: (_core.take_rows, [_points().astype(np.float64), ROWS[::-1].copy(),
                                             np.empty((N, 3), np.float64)], {}), [2]),
    "graph_weights": (lambda: (_core.graph_weights, [_points().astype(np.float64), _normals32().astype(np.float64),
                                                     _neighbours(), 1.0, np.empty((N, K), np.float32)], {}), [4]),
    "spanning_forest": (lambda: (_core.spanning_forest, [_neighbours(), np.random.default_rng(5).random(
        (N, K)).astype(np.float32), np.empty((N - 1, 2), np.int32), np.empty(N, np.int32)], {}), [2, 3]),
    "forest_traversal": (lambda: (_core.forest_traversal, [np.stack([ROWS[:-1], ROWS[1:]], 1).copy(),
                                                           (ROWS == 0), np.empty(N, np.int32),
                                                           np.empty(N, np.int32)], {}), [2, 3]),
    "chain_flips": (lambda: (_core.chain_flips, [ROWS.copy(), np.maximum(ROWS - 1, 0).astype(np.int32),
                                                 np.zeros(N, np.bool_), np.empty(N, np.bool_)], {}), [3]),
}


def _get(args, kwargs, key):
    return args[key] if isinstance(key, int) else kwargs[key]


def _set(args, kwargs, key, value):
    if isinstance(key, int):
        args[key] = value
    else:
        kwargs[key] = value


def _buffers(args, kwargs):
    """Every array argument, by position or keyword."""
    keys = [i for i, a in enumerate(args) if isinstance(a, np.ndarray)]
    return keys + [k for k, a in kwargs.items() if isinstance(a, np.ndarray)]


def _share(other: np.ndarray, out: np.ndarray, how: str):
    """(other', out') with other's content and out's dtype and shape, sharing memory: `same`
    the one array, `reshaped` both from the start of one block, `tail` out starting over
    other's last bytes (rounded to 8 for alignment)."""
    if how == "same":
        return other, other
    offset = 0 if how == "reshaped" else max(0, (other.nbytes - 1) // 8 * 8)
    block = np.zeros(max(other.nbytes, offset + out.nbytes) + 8, np.uint8)
    o2 = block[:other.nbytes].view(other.dtype).reshape(other.shape)
    o2[...] = other
    return o2, block[offset:offset + out.nbytes].view(out.dtype).reshape(out.shape)


PAIRS = []
for _name, (_build, _outs) in CASES.items():
    _fn, _args, _kwargs = _build()
    for _out in _outs:
        for _other in _buffers(_args, _kwargs):
            if _other == _out:
                continue
            a, b = _get(_args, _kwargs, _other), _get(_args, _kwargs, _out)
            for _how in ("same", "reshaped", "tail"):
                if _how == "same" and (a.dtype != b.dtype or a.shape != b.shape):
                    continue
                if _how == "tail" and b.nbytes <= 8:
                    continue
                PAIRS.append(pytest.param(_name, _out, _other, _how, id=f"{_name}-{_out}-{_other}-{_how}"))


@pytest.mark.parametrize("name", sorted(CASES))
def test_separate_buffers_work(name):
    fn, args, kwargs = CASES[name][0]()
    fn(*args, **kwargs)


@pytest.mark.parametrize("name,out,other,how", PAIRS)
def test_an_output_sharing_memory_is_refused(name, out, other, how):
    fn, args, kwargs = CASES[name][0]()
    shared_other, shared_out = _share(_get(args, kwargs, other), _get(args, kwargs, out), how)
    _set(args, kwargs, other, shared_other)
    _set(args, kwargs, out, shared_out)
    with pytest.raises(ValueError, match="share memory") as e:
        fn(*args, **kwargs)
    names = [n if isinstance(n, str) else None for n in (out, other)]
    assert "output" in str(e.value) and all(n in str(e.value) for n in names if n), str(e.value)


def test_every_binding_with_an_output_is_covered():
    """Each callable of _core whose docstring names an out_/output argument is in CASES."""
    covered = {name.split(".")[-1] for name in CASES}
    found = set()
    for owner in (_core, _core.SplatCloud, _core.RenderScene, _core.PointIndex):
        for attr in dir(owner):
            doc = getattr(getattr(owner, attr), "__doc__", None) or ""
            head = doc.split("--")[0].split(":")[0]
            if attr.startswith("_") or "(" not in head:
                continue
            params = head[head.index("("):]
            if re.search(r"\b(out\w*|dist|combined|spacing)\b", params):
                found.add(attr)
    # order(out) writes the tree's order and reads no caller buffer: nothing can overlap.
    assert found - covered <= {"order"}, found - covered
