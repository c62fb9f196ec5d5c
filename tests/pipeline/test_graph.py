"""The native neighbour-graph routines (spatial_order, permute_table, take_rows,
graph_weights, spanning_forest, forest_traversal, chain_flips) against scipy and numpy,
normals.orient, which runs on them, against the scipy-based propagation it replaced, and
the importer's duplicate search (first_of_duplicates) against numpy's np.unique."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.sparse import coo_matrix, csr_matrix
from scipy.sparse.csgraph import breadth_first_order, connected_components, minimum_spanning_tree
from scipy.spatial import cKDTree

from splat_tracer import _core
from splat_tracer.pointcloud import normals
from splat_tracer.pointcloud.graph import chain_flips, forest_traversal, graph_weights, spanning_forest
from splat_tracer.pointcloud.neighbours import first_of_duplicates, permute_table, spatial_order, take_rows
from splat_tracer.util.progress import Cancelled


def random_table(rng, n, k, ties=False):
    """A neighbour table with self entries, repeats and (for small n) isolated parts, and
    weights (rounded to a few values when `ties`)."""
    nbr = rng.integers(0, n, (n, k)).astype(np.int32)
    w = rng.random((n, k)).astype(np.float32)
    if ties:
        w = np.round(w * 4).astype(np.float32)
    return nbr, w


def scipy_forest(nbr, w):
    """(total weight, component count, labels) of scipy's minimum spanning forest of the
    table's graph: each vertex pair once, at its lightest entry; self entries left out."""
    n, k = nbr.shape
    rows = np.repeat(np.arange(n), k)
    cols = nbr.ravel()
    weights = w.ravel().astype(np.float64)
    keep = rows != cols
    a, b, weights = np.minimum(rows, cols)[keep], np.maximum(rows, cols)[keep], weights[keep]
    by = np.lexsort((weights, a * n + b))
    first = np.r_[True, (a * n + b)[by][1:] != (a * n + b)[by][:-1]][:len(by)]
    a, b, weights = a[by][first], b[by][first], weights[by][first]
    # csgraph reads a zero weight as no edge: every weight shifted by 1, taken back after.
    graph = csr_matrix((weights + 1.0, (a, b)), shape=(n, n))
    tree = minimum_spanning_tree(graph)
    count, labels = connected_components(graph, directed=False)
    return tree.sum() - tree.nnz, count, labels


def forest_weight(nbr, w, edges):
    """Total weight of `edges`, each at the lightest entry joining its two vertices."""
    lightest = {}
    for i, row in enumerate(nbr):
        for s, j in enumerate(row):
            key = (min(i, j), max(i, j))
            lightest[key] = min(lightest.get(key, np.inf), float(w[i, s]))
    return sum(lightest[(min(a, b), max(a, b))] for a, b in edges)


@pytest.mark.parametrize("seed", range(12))
def test_spanning_forest_has_scipys_weight_and_components(seed):
    rng = np.random.default_rng(seed)
    n, k = int(rng.integers(1, 400)), int(rng.integers(0, 7))
    nbr, w = random_table(rng, n, k, ties=seed % 3 == 0)
    forest = spanning_forest(nbr, w, threads=seed % 3)
    total, count, labels = scipy_forest(nbr, w)
    assert forest.components == count
    assert forest.edges.shape == (n - count, 2)
    assert (forest.edges[:, 0] != forest.edges[:, 1]).all()
    assert forest_weight(nbr, w, forest.edges) == pytest.approx(total, abs=1e-6)
    # the same partition, numbered by each component's smallest vertex
    assert len(set(zip(labels, forest.labels))) == count
    first = np.unique(forest.labels, return_index=True)[1]
    assert (np.diff(first) > 0).all() and forest.labels.max(initial=-1) == count - 1
    # every edge joins two vertices of one component, and the edges connect each component
    assert (forest.labels[forest.edges[:, 0]] == forest.labels[forest.edges[:, 1]]).all()
    joined = connected_components(coo_matrix((np.ones(len(forest.edges)), forest.edges.T), shape=(n, n)),
                                  directed=False)[0]
    assert joined == count


def test_spanning_forest_on_a_knn_graph_matches_scipy_edge_for_edge():
    # a k-NN graph over random points: distinct weights, so the forest is unique
    rng = np.random.default_rng(3)
    p = rng.random((3000, 3))
    nbr = cKDTree(p).query(p, k=9)[1][:, 1:].astype(np.int32)
    w = np.linalg.norm(p[nbr] - p[:, None], axis=2).astype(np.float32)
    forest = spanning_forest(nbr, w)
    total, count, _ = scipy_forest(nbr, w)
    assert forest.components == count
    assert forest_weight(nbr, w, forest.edges) == pytest.approx(total, rel=1e-9)
    mine = {(min(a, b), max(a, b)) for a, b in forest.edges}
    rows = np.repeat(np.arange(len(p)), 8)
    g = csr_matrix((w.ravel().astype(np.float64), (rows, nbr.ravel())), shape=(len(p), len(p)))
    g = g.maximum(g.T)  # both directions present with the same weight: one undirected edge
    t = minimum_spanning_tree(g).tocoo()
    assert mine == {(min(a, b), max(a, b)) for a, b in zip(t.row, t.col)}


def test_spanning_forest_is_the_same_for_any_number_of_threads():
    rng = np.random.default_rng(4)
    nbr, w = random_table(rng, 200_000, 8, ties=True)
    ref = spanning_forest(nbr, w, threads=1)
    for threads in (2, 3, 0):
        f = spanning_forest(nbr, w, threads=threads)
        np.testing.assert_array_equal(f.edges, ref.edges)
        np.testing.assert_array_equal(f.labels, ref.labels)


def test_spanning_forest_of_degenerate_tables():
    empty = spanning_forest(np.zeros((0, 3), np.int32), np.zeros((0, 3), np.float32))
    assert empty.components == 0 and empty.edges.shape == (0, 2) and empty.labels.shape == (0,)
    alone = spanning_forest(np.zeros((1, 0), np.int32), np.zeros((1, 0), np.float32))
    assert alone.components == 1 and len(alone.edges) == 0
    # every row only itself: no edges at all
    selfish = spanning_forest(np.arange(5, dtype=np.int32)[:, None].repeat(3, 1), np.zeros((5, 3), np.float32))
    assert selfish.components == 5 and list(selfish.labels) == [0, 1, 2, 3, 4]
    # duplicate points: rows full of one neighbour, weights all equal
    dup = spanning_forest(np.array([[1, 1], [0, 0], [0, 1]], np.int32), np.zeros((3, 2), np.float32))
    assert dup.components == 1 and len(dup.edges) == 2


def test_graph_weights_match_the_numpy_formula():
    rng = np.random.default_rng(5)
    p = rng.normal(size=(500, 3))
    nrm = rng.normal(size=(500, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    nbr = cKDTree(p).query(p, k=7)[1][:, 1:].astype(np.int32)
    nbr[0, 0] = 0  # a self entry: no direction, weight 1 - |n . n|
    d = p[nbr] - p[:, None]
    d /= np.maximum(np.linalg.norm(d, axis=2, keepdims=True), 1e-300)
    ni, nj = nrm[:, None], nrm[nbr]
    want = (1 - np.abs((ni * nj).sum(2)) + 0.7 * 0.5 * (np.abs((ni * d).sum(2)) + np.abs((nj * d).sum(2))))
    got = graph_weights(p, nrm, nbr, across=0.7)
    assert got.dtype == np.float32
    np.testing.assert_allclose(got, want, atol=1e-6)
    # both directions of an edge: bitwise the same weight
    for a in range(500):
        for c, b in enumerate(nbr[a]):
            back = np.flatnonzero(nbr[b] == a)
            if len(back):
                assert got[a, c] == got[b, back[0]]


def test_traversal_is_breadth_first_from_every_anchor():
    rng = np.random.default_rng(6)
    p = rng.random((4000, 3))
    nbr = cKDTree(p).query(p, k=9)[1][:, 1:].astype(np.int32)
    forest = spanning_forest(nbr, graph_weights(p, np.tile([0.0, 0, 1], (4000, 1)), nbr))
    anchors = rng.random(4000) < 0.01
    parent, order = forest_traversal(forest.edges, anchors)
    n = len(p)
    # scipy from a virtual root joined to every anchor: the same hop count for every vertex
    rows = np.r_[forest.edges[:, 0], np.full(anchors.sum(), n)]
    cols = np.r_[forest.edges[:, 1], np.flatnonzero(anchors)]
    g = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n + 1, n + 1)).tocsr()
    ref_order, pred = breadth_first_order(g, n, directed=False, return_predecessors=True)
    depth_ref = np.zeros(n + 1, int)
    for v in ref_order[1:]:
        depth_ref[v] = depth_ref[pred[v]] + 1
    reached = parent >= 0
    assert (reached == (pred[:n] >= 0)).all() and len(order) == reached.sum()
    assert (parent[anchors] == np.flatnonzero(anchors)).all()
    depth = np.zeros(n, int)
    for v in order:
        assert parent[v] == v or depth[parent[v]] > 0 or anchors[parent[v]]
        depth[v] = 1 if parent[v] == v else depth[parent[v]] + 1
    np.testing.assert_array_equal(depth[reached], depth_ref[:n][reached])
    assert (np.diff(depth[order]) >= 0).all()  # visited level by level
    # each parent is a forest neighbour
    pairs = {(min(a, b), max(a, b)) for a, b in forest.edges}
    assert all((min(v, parent[v]), max(v, parent[v])) in pairs for v in order if parent[v] != v)


def test_traversal_leaves_unreached_vertices_out():
    parent, order = forest_traversal(np.array([[0, 1], [2, 3]], np.int32), np.array([1, 0, 0, 0, 0], bool))
    assert list(parent) == [0, 0, -1, -1, -1] and list(order) == [0, 1]


def test_chain_flips_match_a_loop():
    rng = np.random.default_rng(8)
    n = 3000
    p = rng.random((n, 3))
    nbr = cKDTree(p).query(p, k=5)[1][:, 1:].astype(np.int32)
    forest = spanning_forest(nbr, rng.random((n, 4)).astype(np.float32))
    anchors = rng.random(n) < 0.02
    parent, order = forest_traversal(forest.edges, anchors)
    parent = np.where(parent < 0, np.arange(n), parent)
    flip = rng.random(n) < 0.3
    want = flip.copy()
    for v in order:
        if parent[v] != v:
            want[v] = want[parent[v]] ^ flip[v]
    np.testing.assert_array_equal(chain_flips(order, parent, flip), want)


def test_spatial_order_permute_table_and_take_rows():
    rng = np.random.default_rng(9)
    p = rng.random((5000, 3)) * [100, 1, 0]  # a flat box: one axis without extent
    order = spatial_order(p)
    assert sorted(order) == list(range(5000))
    # Morton order is local: consecutive points are close (random order: ~37 apart on average)
    assert np.median(np.linalg.norm(np.diff(p[order], axis=0), axis=1)) < 1.0
    table = rng.integers(0, 5000, (5000, 6)).astype(np.int32)
    rank = np.argsort(order)
    np.testing.assert_array_equal(permute_table(table, order, slice(1, 5)), rank[table[order, 1:5]])
    np.testing.assert_array_equal(permute_table(table, order), rank[table[order]])
    np.testing.assert_array_equal(take_rows(p, order), p[order])
    np.testing.assert_array_equal(take_rows(p, order[:7]), p[order[:7]])
    same = np.zeros((10, 3))
    assert list(spatial_order(same)) == list(range(10))  # all equal: index order


# --- first_of_duplicates against np.unique ---------------------------------------------

def unique_first(points) -> np.ndarray:
    """first_of_duplicates restated with numpy: the first row of each set of equal rows
    (np.unique's return_index is the first occurrence), -0.0 made 0.0 beforehand; a row with
    a NaN equals no row."""
    p = np.asarray(points, np.float64).reshape(-1, 3) + 0.0
    keep = np.isnan(p).any(axis=1)
    rows = np.flatnonzero(~keep)
    if len(rows):
        _, first = np.unique(p[rows], axis=0, return_index=True)
        keep[rows[first]] = True
    return keep


def check_first_of_duplicates(points):
    """The native mask on one and on two threads: both np.unique's."""
    want = unique_first(points)
    for threads in (1, 2):
        got = first_of_duplicates(points, threads=threads)
        assert got.dtype == bool and got.shape == want.shape
        np.testing.assert_array_equal(got, want)
    return want


def sprinkle_copies(rng, p, copies):
    """p with `copies` rows replaced by copies of other rows (before or after them)."""
    p = p.copy()
    to, frm = rng.integers(0, len(p), copies), rng.integers(0, len(p), copies)
    p[to] = p[frm]
    return p


@pytest.mark.parametrize("n", [2, 3, 100, 5000, 300_000])
def test_first_of_duplicates_matches_numpy_on_random_points_with_copies(n):
    rng = np.random.default_rng(n)
    p = sprinkle_copies(rng, rng.normal(size=(n, 3)) * 1000, max(n // 5, 1))
    want = check_first_of_duplicates(p)
    assert n < 100 or 0 < (~want).sum() < n // 5


def test_first_of_duplicates_of_float32_sourced_coordinates():
    """Coordinates read from float32 have their 29 low mantissa bits zero (the hash folds the
    high half into the low one for them)."""
    rng = np.random.default_rng(1)
    p = (rng.normal(size=(200_000, 3)) * [1e3, 1e3, 10] + [5e5, 4e6, 100]).astype(np.float32).astype(np.float64)
    p = sprinkle_copies(rng, p, 30_000)
    want = check_first_of_duplicates(p)
    # the float32 values themselves (a float32 file's coordinates, not widened): the same answer
    np.testing.assert_array_equal(check_first_of_duplicates(p.astype(np.float32)), want)
    grid = np.stack(np.meshgrid(*[np.arange(40, dtype=np.float32)] * 3), axis=-1).reshape(-1, 3).astype(np.float64)
    check_first_of_duplicates(np.concatenate([grid, grid[::7], grid[::-3]]))  # a grid and copies
    odd = np.array([[0.0, -0.0, 1], [-0.0, 0.0, 1], [np.nan, 0, 1], [np.nan, 0, 1], [np.inf, 2, 3], [np.inf, 2, 3]])
    np.testing.assert_array_equal(check_first_of_duplicates(odd.astype(np.float32)), [1, 0, 1, 1, 1, 0])


def test_rows_equal_only_through_negative_zero_are_duplicates():
    signs = np.array([[sx, sy, sz] for sx in (1, -1) for sy in (1, -1) for sz in (1, -1)], np.float64)
    p = np.concatenate([signs * 0.0, signs * [0.0, 1.0, 0.0], signs * [2.5, 0.0, 0.0]])
    keep = check_first_of_duplicates(p)
    np.testing.assert_array_equal(np.flatnonzero(keep), [0, 8, 10, 16, 20])  # y = +-1, x = +-2.5: distinct
    rng = np.random.default_rng(2)
    q = rng.normal(size=(50_000, 3))
    q[rng.random(q.shape) < 0.3] = 0.0
    q = sprinkle_copies(rng, q, 20_000)
    q[rng.random(q.shape) < 0.5] *= -1.0  # the zeros' signs at random
    check_first_of_duplicates(q)


def test_many_copies_of_one_row_among_others():
    rng = np.random.default_rng(3)
    p = rng.normal(size=(300_000, 3))
    p[rng.choice(len(p), 100_000, replace=False)] = p[12345]
    keep = check_first_of_duplicates(p)
    assert (~keep).sum() == (p == p[12345]).all(axis=1).sum() - 1
    check_first_of_duplicates(np.full((100_000, 3), 7.0))  # nothing else
    signs = np.where(rng.random((100_000, 3)) < 0.5, 1.0, -1.0)
    assert first_of_duplicates(np.zeros((100_000, 3)) * signs).sum() == 1  # 0.0 and -0.0 mixed


def test_rows_one_bit_apart_are_distinct():
    """Rows that differ in the last bit of one coordinate: hashes far apart but values close."""
    base = np.array([1.0, -2.5, 1e6])
    rows = [base]
    for axis in range(3):
        up, down = base.copy(), base.copy()
        for _ in range(3000):
            up[axis], down[axis] = np.nextafter(up[axis], np.inf), np.nextafter(down[axis], -np.inf)
            rows += [up.copy(), down.copy()]
    p = np.array(rows)
    keep = check_first_of_duplicates(np.concatenate([p, p[::-1], p[::11]]))
    assert keep[:len(p)].all() and not keep[len(p):].any()


# The core's row hash (native/pointcloud/duplicates.cpp), restated to build rows that all have one hash.
_MULTIPLIERS = [0x9E3779B97F4A7C15, 0xBF58476D1CE4E5B9, 0x94D049BB133111EB]


def colliding_rows(rng, count: int, target: int = 0x0123456789ABCDEF) -> np.ndarray:
    """`count` distinct finite rows whose hashes are all `target`: x and y at random, z's bits
    solved for (the hash is invertible in each coordinate: an odd multiplier and a fold)."""
    mask = (1 << 64) - 1
    inverse = pow(_MULTIPLIERS[2], -1, 1 << 64)
    out = []
    while len(out) < count:
        x, y = rng.normal(size=2) * 100
        h = target
        for v, m in ((x, _MULTIPLIERS[0]), (y, _MULTIPLIERS[1])):
            b = int(np.float64(v + 0.0).view(np.uint64))
            h ^= ((b ^ (b >> 32)) * m) & mask
        folded = (h * inverse) & mask
        z = float(np.uint64(folded ^ (folded >> 32)).view(np.float64))
        if np.isfinite(z) and z != 0.0:
            out.append((x, y, z))
    return np.array(out)


def test_rows_sharing_a_hash_are_compared_by_value():
    rng = np.random.default_rng(5)
    p = colliding_rows(rng, 3000)
    assert len(np.unique(p, axis=0)) == 3000
    q = np.concatenate([p, p[rng.integers(0, 3000, 3000)], rng.normal(size=(20_000, 3))])
    q = q[rng.permutation(len(q))]
    q[rng.random(len(q)) < 0.1, 0] *= -1.0  # some distinct rows more, and x = 0 never happens
    check_first_of_duplicates(q)
    zeros = p.copy()
    zeros[:, 0] = 0.0  # their hashes differ now; equal only through -0.0
    check_first_of_duplicates(np.concatenate([zeros, zeros * [-1.0, 1.0, 1.0]]))


def test_a_pile_of_distinct_rows_with_one_hash_is_not_quadratic():
    import time

    rng = np.random.default_rng(6)
    p = colliding_rows(rng, 20_000)
    p = np.concatenate([p] * 10)  # 200k rows, 20k distinct, one hash
    start = time.perf_counter()
    keep = first_of_duplicates(p)
    # Sorted by value: milliseconds; comparing each row with every earlier one of its hash
    # would take about 2e10 comparisons. The bound only catches that.
    assert time.perf_counter() - start < 5.0
    assert keep[:20_000].all() and not keep[20_000:].any()


def test_first_of_duplicates_of_non_finite_rows():
    nan, inf = np.nan, np.inf
    p = [[nan, 0, 0], [nan, 0, 0], [inf, 0, 0], [inf, 0, 0], [-inf, 1, 2], [0, 0, nan], [-inf, 1, 2], [0, 0, 0]]
    np.testing.assert_array_equal(first_of_duplicates(p), [1, 1, 1, 0, 1, 1, 0, 1])
    check_first_of_duplicates(p)
    rng = np.random.default_rng(7)
    q = sprinkle_copies(rng, rng.normal(size=(20_000, 3)), 5000)
    q[rng.random(q.shape) < 0.05] = rng.choice([nan, inf, -inf], size=1)[0]
    check_first_of_duplicates(q)


def test_first_of_duplicates_of_no_and_one_row():
    assert first_of_duplicates(np.empty((0, 3))).shape == (0,)
    np.testing.assert_array_equal(first_of_duplicates([[1.0, 2.0, 3.0]]), [True])
    np.testing.assert_array_equal(first_of_duplicates([[1.0, 2.0, 3.0]] * 2), [True, False])
    np.testing.assert_array_equal(first_of_duplicates(np.arange(6.0).reshape(2, 3)), [True, True])
    # any float dtype and layout: converted to C-contiguous float64 first
    p = np.asfortranarray(np.array([[1, 2, 3], [1, 2, 3], [3, 2, 1]], np.float32))
    np.testing.assert_array_equal(first_of_duplicates(p), [True, False, True])


# --- normals.orient against the scipy propagation it replaced ----------------------------

def scipy_orient(pts, nrm, mode="PROPAGATE"):
    """The orientation as normals.orient did it with scipy's csgraph (minimum_spanning_tree,
    connected_components, breadth_first_order from a virtual root, pointer jumping), given
    the same float32 weights: (normals, ambiguous, components)."""
    n, k = len(pts), normals.GRAPH_K
    anchor_sign = np.zeros(n, np.int8)
    if mode == "UP":
        anchor_sign[nrm[:, 2] >= normals.AMBIGUOUS_RULE] = 1
        anchor_sign[nrm[:, 2] <= -normals.AMBIGUOUS_RULE] = -1
    j = cKDTree(pts).query(pts, k=k + 1)[1][:, 1:].astype(np.int32)
    w = graph_weights(pts, nrm, j, normals.ACROSS_WEIGHT).astype(np.float64) + 1e-9
    mst = minimum_spanning_tree(csr_matrix((w.ravel(), j.ravel(), np.arange(0, n * k + 1, k)), shape=(n, n)))
    n_comp, labels = connected_components(mst, directed=False)
    has_anchor = np.zeros(n_comp, bool)
    has_anchor[labels[anchor_sign != 0]] = True
    counts = np.bincount(labels, minlength=n_comp)
    centroid = np.stack([np.bincount(labels, pts[:, a], n_comp) for a in range(3)], 1) / counts[:, None]
    outward = pts - centroid[labels]
    dist = np.einsum("ij,ij->i", outward, outward)
    by = np.lexsort((dist, labels))
    seeds = by[np.r_[labels[by][1:] != labels[by][:-1], True]]
    seeds = seeds[~has_anchor[labels[seeds]]]
    cos_out = np.einsum("ij,ij->i", nrm[seeds], outward[seeds]) / np.maximum(np.sqrt(dist[seeds]), 1e-300)
    anchor_sign[seeds] = np.where(cos_out >= 0, 1, -1)
    flat = seeds[np.abs(cos_out) < normals.AMBIGUOUS_RULE]
    anchors = np.flatnonzero(anchor_sign != 0)
    t = mst.tocoo()
    rows, cols = np.r_[t.row, np.full(len(anchors), n)], np.r_[t.col, anchors]
    g = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n + 1, n + 1)).tocsr()
    pred = breadth_first_order(g, n, directed=False, return_predecessors=True)[1][:n]
    is_anchor = anchor_sign != 0
    parent = np.where(is_anchor | (pred < 0), np.arange(n), pred)
    cos_parent = np.einsum("ij,ij->i", nrm, nrm[parent])
    acc = np.where(is_anchor, anchor_sign, np.where(cos_parent >= 0, 1, -1)).astype(np.int8)
    jump, done = parent.copy(), is_anchor | (pred < 0)
    while not done.all():
        todo = np.flatnonzero(~done)
        nxt = jump[todo]
        acc[todo] *= acc[nxt]
        done[todo], jump[todo] = done[nxt], jump[nxt]
    out = nrm * acc[:, None]
    # open sheets (normals.OPEN_SHEET, added with the native propagation) are flat too
    sums = np.stack([np.bincount(labels, out[:, a], n_comp) for a in range(3)], 1)
    open_sheet = np.linalg.norm(sums[labels[seeds]], axis=1) >= normals.OPEN_SHEET * counts[labels[seeds]]
    flat = np.union1d(flat, seeds[open_sheet])
    if len(flat):
        sums = sums[labels[flat]]
        tol = 1e-9 * counts[labels[flat]]
        key = np.where(np.abs(sums[:, 2]) > tol, sums[:, 2], np.where(np.abs(sums[:, 1]) > tol, sums[:, 1], sums[:, 0]))
        turn = np.zeros(n_comp, bool)
        turn[labels[flat]] = key < 0
        out[turn[labels]] *= -1
    return out.astype(np.float32), ~is_anchor & (np.abs(cos_parent) < normals.AMBIGUOUS_EDGE), n_comp


def _noisy_clouds():
    rng = np.random.default_rng(10)
    p = rng.normal(size=(6000, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    yield "sphere", p * 2.0
    # two separate bumpy sheets (two components, each flat: turned up) and a small blob
    xy = rng.random((4000, 2)) * 4
    sheet = np.column_stack([xy, 0.2 * np.sin(3 * xy[:, 0]) * np.cos(2 * xy[:, 1])])
    blob = rng.normal(size=(500, 3)) * 0.3 + [10, 10, 10]
    yield "sheets", np.concatenate([sheet, sheet[:2000] + [0, 0, 30], blob])


@pytest.mark.parametrize("mode", ["PROPAGATE", "UP"])
@pytest.mark.parametrize("name, pts", list(_noisy_clouds()))
def test_orient_signs_are_those_of_the_scipy_propagation(name, pts, mode):
    rng = np.random.default_rng(11)
    axes = normals.estimate(pts, 12) * rng.choice([-1.0, 1.0], (len(pts), 1))
    want, want_ambiguous, want_components = scipy_orient(pts, axes, mode)
    got = normals.orient(pts, axes, mode)
    assert got.components == want_components
    if mode == "PROPAGATE":  # one seed per tree: every point's path to it is unique
        np.testing.assert_array_equal(got.normals, want)
        np.testing.assert_array_equal(got.ambiguous, want_ambiguous)
    else:  # several anchors: a point as many hops from two may take either (scipy's queue order)
        assert (got.normals == want).all(axis=1).mean() > 0.995


def test_orient_is_cancelled_from_its_progress():
    rng = np.random.default_rng(12)
    p = rng.normal(size=(20000, 3))
    axes = normals.estimate(p, 8)
    calls = []

    def progress(fraction, message):
        calls.append(message)
        if "spanning tree" in message:
            raise Cancelled("cancelled")
    with pytest.raises(Cancelled):
        normals.orient(p, axes, progress=progress)
    assert any("neighbour graph" in m for m in calls)


# --- bad input ---------------------------------------------------------------------------

def test_native_steps_stop_when_progress_raises():
    rng = np.random.default_rng(13)
    nbr, w = random_table(rng, 1000, 4)

    def stop(fraction):
        raise Cancelled("stop")
    with pytest.raises(Cancelled):
        spanning_forest(nbr, w, progress=stop)
    with pytest.raises(Cancelled):
        graph_weights(rng.random((1000, 3)), rng.random((1000, 3)), nbr, progress=stop)
    forest = spanning_forest(nbr, w)
    with pytest.raises(Cancelled):
        forest_traversal(forest.edges, np.ones(1000, bool), progress=stop)
    seen = []
    spanning_forest(nbr, w, progress=seen.append)
    assert seen[0] == 0.0 and seen[-1] == 1.0 and all(0.0 <= f <= 1.0 for f in seen)


@pytest.mark.parametrize("call, error, message", [
    (lambda: spanning_forest([[1], [5]], np.zeros((2, 1))), ValueError, "row 1, column 0: 5 is not a point"),
    (lambda: spanning_forest([[1], [-1]], np.zeros((2, 1))), ValueError, "-1"),
    (lambda: spanning_forest([[1], [2 ** 40]], np.zeros((2, 1))), ValueError, "beyond int32"),
    (lambda: spanning_forest([[1.0], [0.0]], np.zeros((2, 1))), TypeError, "integers"),
    (lambda: spanning_forest([1, 0], np.zeros(2)), ValueError, "shape"),
    (lambda: spanning_forest([[1], [0]], np.zeros((2, 2))), ValueError, "shape"),
    (lambda: spanning_forest([[1], [0]], [[0.0], [np.nan]]), ValueError, "row 1, column 0 is not finite"),
    (lambda: spanning_forest([[1], [0]], [[0.0], [np.inf]]), ValueError, "not finite"),
    (lambda: spanning_forest([[1], [0]], [[0.0], [0.0]], threads=-1), ValueError, "threads"),
    (lambda: spanning_forest([[1], [0]], [[0.0], [0.0]], progress=3), TypeError, "callable"),
    (lambda: graph_weights([[0, 0, 0], [np.nan, 0, 0]], np.ones((2, 3)), [[1], [0]]), ValueError,
     "point 1: its position is not finite"),
    (lambda: graph_weights(np.zeros((2, 3)), [[0, 0, 1], [0, np.inf, 1]], [[1], [0]]), ValueError,
     "point 1: its normal is not finite"),
    (lambda: graph_weights(np.zeros((2, 3)), np.ones((3, 3)), [[1], [0]]), ValueError, "normals has size 3"),
    (lambda: graph_weights(np.zeros((2, 3)), np.ones((2, 3)), [[1], [2]]), ValueError, "2 is not a point"),
    (lambda: graph_weights(np.zeros((2, 3)), np.ones((2, 3)), [[1], [0]], across=np.nan), ValueError,
     "across"),
    (lambda: forest_traversal([[0, 3]], np.ones(3, bool)), ValueError, "edge 0: 3 is not a vertex"),
    (lambda: forest_traversal([[0, 1, 2]], np.ones(3, bool)), ValueError, "shape"),
    (lambda: forest_traversal([[0, 1]], np.ones((3, 1), bool)), ValueError, "anchors"),
    (lambda: chain_flips([1, 0], [0, 0], [0, 0]), ValueError, "vertex 1 comes before its parent 0"),
    (lambda: chain_flips([0, 0], [0, 0], [0, 0]), ValueError, "twice"),
    (lambda: chain_flips([0, 2], [0, 0], [0, 0]), ValueError, "2 is not a vertex"),
    (lambda: chain_flips([0, 1], [0, 7], [0, 0]), ValueError, "parent 7"),
    (lambda: chain_flips([0, 1], [0, 0], [0, 0, 0]), ValueError, "flip"),
    (lambda: chain_flips([0, 1, 1], [0, 0], [0, 0]), ValueError, "more entries"),
    (lambda: permute_table([[1], [0]], [0, 0]), ValueError, "not a permutation"),
    (lambda: permute_table([[1], [0]], [0, 2]), ValueError, "not a permutation"),
    (lambda: permute_table([[1], [3]], [1, 0]), ValueError, "row 1, column 0: 3 is not a point"),
    (lambda: permute_table([[1], [0]], [1, 0], slice(0, 2, 2)), ValueError, "step 1"),
    (lambda: take_rows(np.zeros((2, 3)), [0, 2]), ValueError, "order entry 1: 2 is not a row"),
    (lambda: spatial_order([[0, 0, 0], [0, np.inf, 0]]), ValueError, "point 1"),
    (lambda: first_of_duplicates(np.zeros((2, 2))), ValueError, "size 2 along axis 1"),
    (lambda: first_of_duplicates(np.zeros(3)), ValueError, "2 dimension"),
    (lambda: first_of_duplicates(np.zeros((2, 3)), threads=-1), ValueError, "threads"),
])
def test_bad_input_is_refused(call, error, message):
    with pytest.raises(error, match=message):
        call()


def test_native_entry_points_refuse_bad_buffers():
    nbr = np.array([[1], [0]], np.int32)
    w = np.zeros((2, 1), np.float32)
    edges, labels = np.empty((1, 2), np.int32), np.empty(2, np.int32)
    with pytest.raises(TypeError, match="int32"):
        _core.spanning_forest(nbr.astype(np.int64), w, edges, labels)
    with pytest.raises(TypeError):
        _core.spanning_forest(None, w, edges, labels)
    with pytest.raises(TypeError, match="contiguous"):
        _core.spanning_forest(np.zeros((2, 2), np.int32)[:, :1], w, edges, labels)
    with pytest.raises(ValueError, match="size"):
        _core.spanning_forest(nbr, w, np.empty((2, 2), np.int32), labels)
    with pytest.raises(TypeError, match="writable"):
        ro = np.empty((1, 2), np.int32)
        ro.flags.writeable = False
        _core.spanning_forest(nbr, w, ro, labels)
    # an output over an input would be read after being overwritten: refused
    table = np.array([[1, 0], [0, 1]], np.int32)
    with pytest.raises(ValueError, match="share memory"):
        _core.graph_weights(np.zeros((2, 3)), np.ones((2, 3)), table, 1.0, table.view(np.float32))
    with pytest.raises(ValueError, match="share memory"):
        both = np.empty(4, np.int32)
        _core.forest_traversal(np.array([[0, 1]], np.int32), np.ones(4, np.uint8), both, both)
    with pytest.raises(ValueError, match="columns"):
        _core.permute_table(table, np.array([1, 0], np.int32), 1, np.empty((2, 2), np.int32))
    with pytest.raises(ValueError, match="share memory"):
        points = np.zeros((4, 3))
        _core.first_of_duplicates(points, points.reshape(-1).view(np.uint8)[:4])
    with pytest.raises(TypeError, match="uint8 or bool"):
        _core.first_of_duplicates(np.zeros((4, 3)), np.empty(4, np.int32))
    with pytest.raises(ValueError, match="size"):
        _core.first_of_duplicates(np.zeros((4, 3)), np.empty(5, bool))


def test_spatial_order_of_points_spanning_the_float64_range():
    """Found by fuzz_core under UBSan: points at +-1e308 overflow the box's extent to inf and
    the cell's coordinate to NaN, whose conversion to an integer was undefined behaviour."""
    pts = np.array([[-1.7e308, 0.0, 1.0], [1.7e308, 1.0, 0.0], [0.0, -1e308, 1e308], [5.0, 5.0, 5.0]])
    order = spatial_order(pts)
    assert sorted(order) == [0, 1, 2, 3]
