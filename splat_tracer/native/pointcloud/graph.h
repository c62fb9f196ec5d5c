// The neighbour graph of a point cloud, as normals.orient() propagates signs over it: the
// weights of its edges, its minimum spanning forest, a breadth-first traversal of that
// forest from given anchors, and signs chained along that traversal.
//
// The graph comes as a k-nearest-neighbour table: row i holds k vertices joined to i (row-
// major, n x k, int32). An entry equal to i itself (duplicate points can push a point out of
// its own first column) is no edge; an entry repeated, or present in both directions, is a
// parallel edge, which a spanning forest never takes twice. Edge e = i * k + s is slot s of
// row i; that number breaks ties between equal weights, so every result is deterministic
// (the same for any number of threads).
//
// Long steps call `poll(fraction done)` between chunks of work, on the calling thread; when
// it returns false the call stops and returns `false` (its outputs are then undefined). Bad
// input throws InputError naming the first offending entry.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>

namespace splat {

using GraphPoll = std::function<bool(double fraction)>;

// The points' indices in Morton (Z-curve) order over their bounding box, 11 bits per axis,
// ties by index: neighbours in space become neighbours in memory, so that the graph steps
// below, given the cloud renumbered this way, mostly read memory that is already in cache.
// 10M terrain points in random order: weights, forest and traversal took 42.5 s, against
// 6.3 s renumbered, plus 4.9 s to renumber (spatial_order, permute_table, take_rows), in
// one run on the shared machine. `points` n x 3, finite.
void spatial_order(const double *points, size_t n, int32_t *order, int threads);

// The neighbour table renumbered by `order` (a permutation of 0 .. n-1): out row r (k
// entries) holds, for columns first .. first+k-1 of row order[r] of `table` (n x stride),
// the new numbers of those points. Throws InputError for an order that is not a
// permutation or a table entry that is not a point.
void permute_table(const int32_t *table, size_t n, size_t stride, size_t first, size_t k, const int32_t *order,
                   int32_t *out, int threads);

// out row r = src row order[r] (rows of `columns` doubles; order: `count` row numbers):
// numpy's fancy indexing, in parallel and with the next rows fetched ahead (a spatial order
// reads a file-ordered array at random). Throws InputError for an order entry out of range.
void take_rows(const double *src, size_t n, size_t columns, const int32_t *order, size_t count, double *out,
               int threads);

// Each table entry's weight, 1 - |n_i . n_j| + across * (|n_i . d| + |n_j . d|) / 2 with d
// the edge's unit direction (normals.py says why), computed in double, stored in float32:
// `out` is n x k. `points` and `normals` are n x 3. The weight of (i, j) is bitwise that of
// (j, i), so both directions of an edge tie and the edge number decides. A self-entry gets
// 1 - |n_i . n_i| (about 0); the forest ignores it anyway.
bool neighbour_edge_weights(const double *points, const double *normals, size_t n, const int32_t *nbr, size_t k,
                            double across, float *out, int threads, const GraphPoll &poll);

// The minimum spanning forest of the table's graph under `weights` (n x k, finite; ties
// broken by edge number), by Boruvka's algorithm: `edges` (room for n - 1 pairs) receives the
// forest's edges as vertex pairs (row vertex first), `labels` (n) each vertex's connected
// component, numbered 0, 1, ... in the order of each component's smallest vertex. Sets
// `edge_count` and `component_count` (their sum is n). n * k must be below 2^32.
bool minimum_spanning_forest(const int32_t *nbr, const float *weights, size_t n, size_t k, int32_t *edges,
                             int32_t *labels, size_t &edge_count, size_t &component_count, int threads,
                             const GraphPoll &poll);

// Breadth-first traversal of the undirected graph of `m` edges (pairs of vertices in
// [0, n)) from every vertex whose `anchors` entry is non-zero at once, the anchors queued in
// increasing order and each vertex's neighbours in the order of the edge list. `parent`
// (n): the vertex each one was reached from (an anchor: itself; not reached: -1); `order`
// (n): the reached vertices in the order visited (the rest -1). Sets `reached`.
bool forest_traversal(const int32_t *edges, size_t m, size_t n, const uint8_t *anchors, int32_t *parent,
                      int32_t *order, size_t &reached, const GraphPoll &poll);

// negative[v] = flip[v] where parent[v] == v, else negative[parent[v]] XOR flip[v], for v in
// `order` (count vertices, each after its parent: a traversal's order): the sign of each
// vertex when each one's sign is its parent's unless flipped (a root's: negative if
// flipped). Vertices not in `order` get their flip. Throws InputError for an order that is
// not one (an index out of range, a vertex twice, a vertex before its parent).
void chain_flips(const int32_t *order, size_t count, const int32_t *parent, const uint8_t *flip, size_t n,
                 uint8_t *negative);

}  // namespace splat
