"""Fuzz harness: the native core's entry points, called directly (splat_tracer._core).

    python fuzz/fuzz_core.py [libFuzzer options] [corpus dirs]    (`make fuzz` runs it)

The input bytes are decoded (atheris.FuzzedDataProvider) into float32 splat arrays mixing
ordinary values with NaN, inf, -0.0, denormals, 1e18..1e19 and float32's extremes
(sometimes with a wrong dtype or shape), and then into calls of every native entry
point on them: _core.SplatCloud(...), trace, trace_surface (methods read by field name, exclude ids, inside
flags, tmin/tmax), render (camera matrices, windows, tile sizes), bvh_stats and bounds,
coherent rays (fans and parallel bundles) traced in packets and one by one, which must
agree exactly; then a _core.Mesh and a _core.RenderScene over both with fuzzed transforms, material
and lamp rows and settings, rendered; then the neighbour-graph functions (spatial_order,
permute_table, take_rows, graph_weights, spanning_forest, forest_traversal, chain_flips)
on fuzzed tables whose indices stray out of range, weights, anchors and orders, and
first_of_duplicates on the points (checked against a pairwise comparison); then a
_core.PointIndex and its queries (knn, knn_at, covering, radii, widest_gaps, pca) on fuzzed points,
rows, k, normals and spacings. The contract of a native entry point: it returns,
or raises ValueError, TypeError or MemoryError. Anything else (another exception, a
crash, and under the sanitizer build of `make fuzz` any AddressSanitizer or UBSan
report) is a finding.

`make fuzz` runs this harness against the ASan + UBSan build (build/sanitize/tree): the
native code is not coverage-instrumented (GCC cannot emit libFuzzer's coverage), so
atheris's guidance comes from the Python side and the decoding; the sanitizers turn
silent memory errors and undefined behaviour into findings.
Seed corpus: fuzz/corpus/core/.
"""
import sys
from pathlib import Path
from types import SimpleNamespace

import atheris
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from splat_tracer import _core  # noqa: E402

ALLOWED = (ValueError, TypeError, MemoryError)
SPECIAL = [np.nan, np.inf, -np.inf, 0.0, -0.0, 1e-45, 1.1754942e-38, 1e18, -1e18, 1.0000001e18, 1e19, -1e19,
           3.4028235e38, -3.4028235e38, 1.0, -1.0, 0.5, 2.0, 1e-7, 1e7]
MAX_LAYER_HITS = _core.MAX_LAYER_HITS


@atheris.instrument_func  # Python-side coverage: which branches and refusals an input reached
def value(fdp) -> float:
    k = fdp.ConsumeIntInRange(0, 3)
    if k == 0:
        return SPECIAL[fdp.ConsumeIntInRange(0, len(SPECIAL) - 1)]
    if k == 1:
        return fdp.ConsumeFloat()  # any double, NaN and inf included
    return fdp.ConsumeFloatInRange(-3.0, 3.0)  # mostly ordinary geometry


@atheris.instrument_func
def array(fdp, shape, dtype=np.float32):
    n = int(np.prod(shape))
    a = np.array([value(fdp) for _ in range(n)], np.float64)
    with np.errstate(over="ignore", invalid="ignore"):
        out = a.astype(dtype).reshape(shape)
    if fdp.ConsumeIntInRange(0, 30) == 0:  # now and then a wrong dtype or layout
        out = [out.astype(np.float64), out.T, out.ravel(), "not an array", None][fdp.ConsumeIntInRange(0, 4)]
    return out


@atheris.instrument_func
def method(fdp):
    """A method object as the core reads it (by field name), its fields fuzzed past what
    render.method.Method would accept; now and then not a method at all or one missing a field."""
    if fdp.ConsumeIntInRange(0, 20) == 0:
        return [None, "FULL", (True, True, True, 1, 0, 1.0), SimpleNamespace(far_phase=True),
                SimpleNamespace(**{**FULL, "epsilon": "1"})][fdp.ConsumeIntInRange(0, 4)]
    positions = ("FIRST", "NEAR_PHASE", "NEAREST_CENTRE", "MIDDLE", 1)
    kernels = ("LINEAR", "SMOOTH", "", None)
    return SimpleNamespace(wrong_hit_elimination=fdp.ConsumeBool(), normal_interpolation=fdp.ConsumeBool(),
                           far_phase=fdp.ConsumeBool(), position=positions[fdp.ConsumeIntInRange(0, 4)],
                           kernel=kernels[fdp.ConsumeIntInRange(0, 3)], epsilon=value(fdp),
                           crease_angle=[180.0, 45.0, value(fdp)][fdp.ConsumeIntInRange(0, 2)])


FULL = dict(wrong_hit_elimination=True, normal_interpolation=True, far_phase=True, position="NEAR_PHASE",
            kernel="LINEAR", epsilon=1.0, crease_angle=180.0)


def small_int(fdp):
    return [0, 1, 2, 3, 7, 8, 16, 33, -1, 2**31 - 1, -2**31][fdp.ConsumeIntInRange(0, 10)]


@atheris.instrument_func
def call(fn, *args, **kwargs):
    try:
        return fn(*args, **kwargs)
    except ALLOWED:
        return None


@atheris.instrument_func
def camera(fdp):
    if fdp.ConsumeBool():  # a plausible camera looking at the origin, from a fuzzed place
        m = np.eye(4)
        m[:3, :3] *= fdp.ConsumeFloatInRange(0.1, 3)
        m[:3, 3] = [value(fdp) for _ in range(3)]
        m[3, 2] = fdp.ConsumeFloatInRange(-1, 1)
        m[3, 3] = fdp.ConsumeFloatInRange(0, 2)
    else:
        m = np.array([value(fdp) for _ in range(16)], np.float64).reshape(4, 4)
    pos = np.array([value(fdp) for _ in range(3)], np.float64)
    fwd = np.array([value(fdp) for _ in range(3)], np.float64)
    return np.ascontiguousarray(m), pos, fwd


@atheris.instrument_func
def fuzz_scene(fdp):
    n = fdp.ConsumeIntInRange(0, 40)
    c, nrm = array(fdp, (n, 3)), array(fdp, (n, 3))
    r = array(fdp, (n,))
    col = array(fdp, (n, 3)) if fdp.ConsumeBool() else None
    closed = np.frombuffer(fdp.ConsumeBytes(n).ljust(n, b"\1"), np.uint8).copy() if fdp.ConsumeBool() else None
    scene = call(_core.SplatCloud, c, nrm, r, col, closed, fdp.ConsumeIntInRange(0, 3))
    if scene is None:
        return None
    assert scene.size == n
    scene.bvh_stats()
    b = scene.bounds
    assert (b is None) == (n == 0)

    k = fdp.ConsumeIntInRange(0, 24)
    o, d = array(fdp, (k, 3)), array(fdp, (k, 3))
    tmin, tmax = value(fdp), value(fdp)
    out = (np.empty(k, np.float32), np.empty(k, np.int32), np.empty(k, np.uint8))
    if call(scene.trace, o, d, tmin, tmax, *out, np.empty((k, 3), np.float32), fdp.ConsumeIntInRange(0, 3),
            fdp.ConsumeBool(), np.zeros(2, np.int64)) is not None:
        t, ids, _ = out
        assert ((ids >= -1) & (ids < n)).all()
        assert (np.isinf(t) == (ids < 0)).all()
    m_ex = fdp.ConsumeIntInRange(0, 4)
    ex = np.array([fdp.ConsumeIntInRange(-2, n) for _ in range(k * m_ex)], np.int32).reshape(k, m_ex)
    inside = np.frombuffer(fdp.ConsumeBytes(k).ljust(k, b"\0"), np.uint8).copy()
    sout = (np.empty(k, np.float32), np.empty(k, np.int32), np.empty(k, np.uint8), np.empty((k, 3), np.float32),
            np.empty((k, 3), np.float32), np.empty((k, MAX_LAYER_HITS), np.int32))
    if call(scene.trace_surface, o, d, tmin, tmax, method(fdp), *sout, inside if fdp.ConsumeBool() else None,
            ex if fdp.ConsumeBool() else None, fdp.ConsumeIntInRange(0, 3), fdp.ConsumeBool()) is not None:
        assert ((sout[1] >= -1) & (sout[1] < n)).all() and ((sout[5] >= -1) & (sout[5] < n)).all()

    width, height = fdp.ConsumeIntInRange(1, 24), fdp.ConsumeIntInRange(1, 24)
    win = (0, 0, width, height) if fdp.ConsumeBool() else tuple(small_int(fdp) for _ in range(4))
    h, w = max(win[3], 0), max(win[2], 0)
    if h * w <= 4096:
        m, pos, fwd = camera(fdp)
        call(scene.render, m, pos, fwd, width, height, win, (value(fdp), 0.0, 0.0, 1.0),
             np.empty((h, w, 4), np.float32), np.empty((h, w), np.float32), np.empty((h, w, 3), np.float32),
             fdp.ConsumeIntInRange(0, 3), None, small_int(fdp), method(fdp))
    fuzz_packets(fdp, scene, n)
    return scene


def fuzz_packets(fdp, scene, n):
    """Coherent rays (a fuzzed origin and direction, spread by a fuzzed angle or, parallel,
    over a fuzzed patch of origins): packets must give exactly the answers of single rays."""
    k = fdp.ConsumeIntInRange(1, 40)
    def vectors(count):  # well-formed arrays (array() may give wrong shapes or dtypes on purpose)
        return np.array([[value(fdp) for _ in range(3)] for _ in range(count)], np.float32).reshape(count, 3)
    o0, d0 = vectors(1), vectors(1)
    spread = (0.0, 1e-7, 1e-4, 0.01, 0.1)[fdp.ConsumeIntInRange(0, 4)]
    offsets = vectors(k) * np.float32(spread) if fdp.ConsumeBool() else np.zeros((k, 3), np.float32)
    with np.errstate(all="ignore"):
        i = np.arange(k)
        jitter = np.column_stack([i % 4, i // 4 % 4, np.zeros(k)]).astype(np.float32) * np.float32(spread)
        if fdp.ConsumeBool():
            o, d = np.repeat(o0, k, 0), (d0 + jitter + offsets).astype(np.float32)  # a fan from one point
        else:
            o, d = (o0 + jitter + offsets).astype(np.float32), np.repeat(d0, k, 0)  # parallel rays
    tmin, tmax = value(fdp), value(fdp)
    meth = method(fdp)
    outs = []
    for packets in (True, False):
        out = (np.empty(k, np.float32), np.empty(k, np.int32), np.empty(k, np.uint8))
        sout = (np.empty(k, np.float32), np.empty(k, np.int32), np.empty(k, np.uint8),
                np.empty((k, 3), np.float32), np.empty((k, 3), np.float32), np.empty((k, MAX_LAYER_HITS), np.int32))
        a = call(scene.trace, o, d, tmin, tmax, *out, None, 1, False, None, packets)
        b = call(scene.trace_surface, o, d, tmin, tmax, meth, *sout, None, None, 1, False, packets)
        outs.append((a is not None, out, b is not None, sout))
    (a1, out1, b1, s1), (a2, out2, b2, s2) = outs
    assert a1 == a2 and b1 == b2
    if a1:
        for x, y in zip(out1, out2):
            assert np.array_equal(x, y), "packets changed a nearest hit"
    if b1:
        for x, y in zip(s1, s2):
            assert np.array_equal(x, y, equal_nan=True), "packets changed a surface"


@atheris.instrument_func
def fuzz_render_scene(fdp, splats):
    v = fdp.ConsumeIntInRange(0, 12)
    verts = array(fdp, (v, 3))
    tris = np.array([fdp.ConsumeIntInRange(-1, v) for _ in range(3 * fdp.ConsumeIntInRange(0, 6))],
                    np.int32).reshape(-1, 3)
    t = len(tris)
    normals = array(fdp, (t, 3, 3)) if fdp.ConsumeBool() else None
    mat_index = np.array([fdp.ConsumeIntInRange(-1, 3) for _ in range(t)], np.int32) if fdp.ConsumeBool() else None
    mesh = call(_core.Mesh, verts, tris, normals, mat_index, 1)
    geos = [g for g in (splats, mesh) if g is not None]
    if not geos:
        return
    n = fdp.ConsumeIntInRange(0, 4)
    n_mat, n_light = fdp.ConsumeIntInRange(0, 3), fdp.ConsumeIntInRange(0, 3)
    rows = lambda count, fields: array(fdp, (count, fields))
    to_world = np.tile(np.eye(4)[:3].ravel(), (n, 1)).astype(np.float32)
    if fdp.ConsumeBool():
        to_world = rows(n, 12)
    scene = call(_core.RenderScene, geos, np.array([fdp.ConsumeIntInRange(-1, len(geos)) for _ in range(n)], np.int32),
                 to_world, rows(n, 12) if fdp.ConsumeBool() else to_world,
                 np.array([[fdp.ConsumeIntInRange(-1, n_mat), fdp.ConsumeIntInRange(0, 2)] for _ in range(n)],
                          np.int32).reshape(n, 2),
                 np.full(n, fdp.ConsumeIntInRange(-1, 64), np.int32), np.zeros(n, np.uint8), np.zeros(n, np.float32),
                 rows(n_mat, 15), rows(n_light, 21), fdp.ConsumeIntInRange(0, 2))
    if scene is None:
        return
    w, h = fdp.ConsumeIntInRange(1, 12), fdp.ConsumeIntInRange(1, 12)
    settings = (fdp.ConsumeIntInRange(0, 3), fdp.ConsumeIntInRange(-1, 3), value(fdp), fdp.ConsumeIntInRange(0, 2),
                *[fdp.ConsumeIntInRange(-1, 4) for _ in range(5)], fdp.ConsumeIntInRange(0, 2**31 - 1),
                fdp.ConsumeBool())
    m, pos, fwd = camera(fdp)
    buffers = {name: np.zeros((h, w, c) if c > 1 else (h, w), np.float32)
               for name, c in (("depth", 1), ("normal", 3), ("diffcol", 3), ("emit", 3), ("shadow", 3), ("index", 1),
                               ("splat_count", 1))}
    call(scene.render, m, pos, fwd, w, h, (0, 0, w, h), settings, method(fdp),
         tuple(abs(value(fdp)) for _ in range(3)), fdp.ConsumeBool(), np.zeros((h, w, 4), np.float32),
         threads=fdp.ConsumeIntInRange(0, 2), tile_size=fdp.ConsumeIntInRange(1, 8), **buffers)


@atheris.instrument_func
def indices(fdp, shape, n):
    """int32 indices, mostly in 0..n-1, now and then just outside or extreme."""
    count = int(np.prod(shape))
    out = np.array([fdp.ConsumeIntInRange(0, max(n - 1, 0)) if fdp.ConsumeIntInRange(0, 15) else small_int(fdp)
                    for _ in range(count)], np.int64)
    return out.astype(np.int32).reshape(shape)


@atheris.instrument_func
def fuzz_graph(fdp):
    n, k = fdp.ConsumeIntInRange(0, 30), fdp.ConsumeIntInRange(0, 5)
    pts, nrm = array(fdp, (n, 3), np.float64), array(fdp, (n, 3), np.float64)
    nbr = indices(fdp, (n, k), n)
    threads = fdp.ConsumeIntInRange(0, 3)
    order = np.empty(n, np.int32)
    if call(lambda: _core.spatial_order(pts, order, threads) or True):  # None: refused (it returns None on success)
        assert sorted(order) == list(range(n))
    else:
        order = indices(fdp, (n,), n)
    first = np.empty(n, bool)
    if call(lambda: _core.first_of_duplicates(pts, first, threads) or True):  # None: refused
        for i in range(n):  # equal as numbers: -0.0 is 0.0, a row with a NaN equals none
            assert first[i] == (not (pts[:i] == pts[i]).all(axis=1).any()), i
    call(_core.permute_table, nbr, order, fdp.ConsumeIntInRange(-1, k), np.empty((n, fdp.ConsumeIntInRange(0, k)),
                                                                                  np.int32), threads)
    rows = indices(fdp, (fdp.ConsumeIntInRange(0, 10),), n)
    call(_core.take_rows, pts, rows, np.empty((len(rows), 3)), threads)
    weights = np.empty((n, k), np.float32)
    if call(_core.graph_weights, pts, nrm, nbr, value(fdp), weights, threads) is None:
        weights = array(fdp, (n, k))
    edges, labels = np.empty((max(n - 1, 0), 2), np.int32), np.empty(n, np.int32)
    got = call(_core.spanning_forest, nbr, weights, edges, labels, threads)
    if got is not None:
        m, components = got
        assert m + components == n and ((labels >= 0) & (labels < max(components, 1))).all()
        edges = edges[:m]
    else:
        edges = indices(fdp, (fdp.ConsumeIntInRange(0, 8), 2), n)
    anchors = np.frombuffer(fdp.ConsumeBytes(n).ljust(n, b"\0"), np.uint8).copy()
    parent, visit = np.empty(n, np.int32), np.empty(n, np.int32)
    reached = call(_core.forest_traversal, edges, anchors, parent, visit)
    if reached is None:
        parent, visit, reached = indices(fdp, (n,), n), indices(fdp, (n,), n), n
    flip = np.frombuffer(fdp.ConsumeBytes(n).ljust(n, b"\0"), np.uint8).copy()
    call(_core.chain_flips, visit[:reached], parent, flip, np.empty(n, np.uint8))


@atheris.instrument_func
def fuzz_neighbours(fdp):
    """_core.PointIndex over fuzzed points (coincident ones often), and every query on fuzzed
    rows, k, normals, spacings and outputs."""
    n = fdp.ConsumeIntInRange(0, 40)
    pts = array(fdp, (n, 3))
    if fdp.ConsumeIntInRange(0, 3) == 0 and isinstance(pts, np.ndarray) and pts.ndim == 2 and len(pts) > 1:
        pts[fdp.ConsumeIntInRange(0, len(pts) - 1):] = pts[0]  # a pile of coincident points
    index = call(_core.PointIndex, pts, fdp.ConsumeIntInRange(0, 3))
    if index is None:
        return
    size = index.size
    order = np.empty(size, np.int32)
    index.order(order)
    assert sorted(order) == list(range(size))
    m = fdp.ConsumeIntInRange(0, 12)
    start = fdp.ConsumeIntInRange(0, size)
    pick = fdp.ConsumeIntInRange(0, 2)  # a run of the order, runs of it (a sampled boundary test), or anything
    if pick == 0:
        rows = order[start:start + m]
    elif pick == 1:
        other = fdp.ConsumeIntInRange(0, size)
        rows = np.concatenate([order[start:start + m], order[other:other + fdp.ConsumeIntInRange(0, 12)]])
    else:
        rows = indices(fdp, (m,), size)
    k, threads = small_int(fdp) if fdp.ConsumeIntInRange(0, 7) == 0 else fdp.ConsumeIntInRange(1, 13), \
        fdp.ConsumeIntInRange(0, 3)
    cols = min(max(k, 0), 300)  # outputs sized for k, but never gigabytes (the core refuses k > 256 anyway)
    shape = (len(rows), cols)
    call(index.knn, rows, k, np.empty(shape, np.float32), np.empty(shape, np.int32), threads)
    call(index.radii, rows, k, np.empty(len(rows), np.float32), threads=threads)
    q = array(fdp, (fdp.ConsumeIntInRange(0, 5), 3))
    rq = len(q) if isinstance(q, np.ndarray) and q.ndim == 2 else 0
    call(index.knn_at, q, k, np.empty((rq, cols), np.float32), np.empty((rq, cols), np.int32), threads)
    normals, spacing = array(fdp, (size, 3)), array(fdp, (size,))
    hole, gap = value(fdp), value(fdp)
    call(index.covering, rows, normals, spacing, k, hole, gap, np.empty(len(rows), np.float32), threads)
    call(index.widest_gaps, rows, k, normals, np.empty(len(rows), np.float32), threads)
    call(index.radii, rows, fdp.ConsumeIntInRange(0, 8), np.empty(len(rows), np.float32), normals, k, hole, gap,
         np.empty(len(rows), np.float32), threads)
    width = fdp.ConsumeIntInRange(0, 14)
    call(index.pca, rows, k, np.empty((len(rows), 3)), np.empty((len(rows), width), np.int32) if width else None,
         fdp.ConsumeIntInRange(0, 8), np.empty(len(rows), np.float32), fdp.ConsumeIntInRange(0, 14), hole, gap,
         np.empty(len(rows), np.float32), threads)


@atheris.instrument_func
def TestOneInput(data: bytes) -> None:
    fdp = atheris.FuzzedDataProvider(data)
    splats = fuzz_scene(fdp)
    fuzz_render_scene(fdp, splats)
    fuzz_graph(fdp)
    fuzz_neighbours(fdp)


if __name__ == "__main__":
    atheris.Setup(sys.argv, TestOneInput)
    atheris.Fuzz()
