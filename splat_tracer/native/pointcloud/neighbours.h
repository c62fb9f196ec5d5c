// k nearest neighbours among a point cloud: the import's neighbourhood work (splat radii,
// gap-closing radii, PCA normals, outlier statistics) without leaving native code.
//
// A k-d tree laid out implicitly: the points are reordered so that every node is a range
// of the array, node (depth d, number j) holding [floor(j n / 2^d), floor((j+1) n / 2^d));
// each inner node splits its range at the middle by the median along the widest side of
// its cell, so the tree is balanced whatever the density (a terrestrial scan's near and far
// returns alike) and needs no child pointers: a node is 5 bytes (split value and axis).
// Leaves hold about 11 to 23 points (kLeafAverage).
//
// Queries are for the indexed points themselves (the import asks about every point) or for
// other positions. A point's query starts in its own leaf, which gives a tight bound before
// the descent from the root; the descent keeps the squared distance from the query to each
// cell incrementally (per axis), as nanoflann does, and skips cells no nearer than the k-th
// candidate. The caller walks the points in the tree's order (`id(0)`, `id(1)`, ...), so
// that consecutive queries touch the same nodes and leaves.
#pragma once

#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

#include "base/buffer.h"

namespace splat {

// A point of a PointIndex: its coordinates and input id, together (16 bytes): the tree is
// built by moving these, and kept in them (a point's coordinates are read together).
struct IndexedPoint {
    float c[3];
    uint32_t id;
};

class PointIndex {
public:
    // A query returns at most this many neighbours (the import asks for 6 to 24).
    static constexpr int kMaxK = 256;
    // Points per leaf: the tree has 2^depth leaves, the fewest with at most kLeafAverage
    // points each on average, so a leaf holds from about kLeafAverage / 2 to kLeafAverage
    // (at most kLeafSize) points, 16 in the middle (in log scale). 16 measured fastest for
    // k = 6..24 at 1M points (8: more nodes visited; 32: more distances computed than the
    // bound needs); at 10M points an upper bound of 16 left 9.5 a leaf, 7 % slower radii
    // than 19.
    static constexpr double kLeafAverage = 22.627416997969522;  // 16 sqrt(2)
    static constexpr size_t kLeafSize = 24;
    static constexpr uint32_t kNone = 0xffffffffu;

    // xyz: n points, 3 floats each, finite and within 1e18 (InputError otherwise); at most
    // 2^32 - 2 of them. threads: builder threads (0: all cores).
    PointIndex(const float *xyz, size_t n, int threads);

    size_t size() const { return n_; }
    // Queries answer with slots, positions in the tree's order (reading a neighbour's
    // position by input id would cost a cache miss per neighbour on a large cloud);
    // id(slot) for slots 0, 1, ... is the tree's order: neighbouring points are close in it.
    uint32_t slot(uint32_t id) const { return slot_[id]; }
    uint32_t id(uint32_t slot) const { return pts_[slot].id; }
    void at(uint32_t slot, float out[3]) const {
        out[0] = pts_[slot].c[0], out[1] = pts_[slot].c[1], out[2] = pts_[slot].c[2];
    }
    // The end of the leaf holding slot s (one past its last point).
    size_t leaf_end(size_t s) const { return begin(leaf_of(s) + 1, depth_); }

    // The k nearest points to q (k <= kMaxK), nearest first, excluding slot `exclude`
    // (kNone: none), as squared distances and slots. Returns how many were found:
    // min(k, points available).
    int nearest(const float q[3], uint32_t exclude, int k, float *d2, uint32_t *slots) const;
    // The k nearest other points of the point at slot s.
    int nearest_of(uint32_t s, int k, float *d2, uint32_t *slots) const;
    // The k nearest other points of each of the points at slots [b, e), all in one leaf
    // (k <= size() - 1): k squared distances and slots per point, nearest first. The same
    // answer as nearest_of, found for the leaf's points together: the guess (below) or,
    // without one, their candidates within a smallest surrounding subtree give a bound (a
    // point whose k nearest are not all within it searches on its own), the leaves within
    // that bound of the points' box are gathered and copied by axis once, and each point
    // computes its distances to all of them, four at a time, and ranks those within a bound
    // (the previous point's k-th distance, widened; else the exact one) without sorted
    // insertion. Among equal distances the candidate visited first by a one-point scan of
    // the subtree and then of the gathered leaves in tree order comes first (the answer the
    // sequential version gave, to the bit). guess: a squared distance the k-th neighbours probably lie
    // within (0: none), in; for the next leaf in the tree's order, out (the caller walking
    // the leaves in order passes it on).
    void leaf_nearest(size_t b, size_t e, int k, float *d2, uint32_t *slots, float &guess) const;

private:
    struct Best;
    struct Box {
        float lo[3], hi[3];
    };
    // Skips the subtrees within tree-order positions [skip_b, skip_e): already scanned.
    void search(const float q[3], Best &best, uint32_t node, int depth, float mindist, float off[3], size_t skip_b,
                size_t skip_e) const;
    void scan(size_t b, size_t e, const float q[3], Best &best) const;
    void gather(uint32_t node, int depth, const Box &cell, const Box &box, float r2, size_t skip_b, size_t skip_e,
                std::vector<std::pair<uint32_t, Box>> &leaves, size_t &points) const;
    uint32_t leaf_of(size_t s) const;
    size_t begin(uint32_t node, int depth) const { return size_t((uint64_t(node_rank(node, depth)) * n_) >> depth); }
    static uint32_t node_rank(uint32_t node, int depth) { return node - ((1u << depth) - 1u); }

    size_t n_ = 0;
    int depth_ = 0;                 // leaves are the nodes at this depth
    Box bounds_{};                  // the root's cell: the points' bounding box
    Buffer<IndexedPoint> pts_;  // points in tree order (their ids: tree order -> input id)
    Buffer<uint32_t> slot_;     // input id -> tree order
    std::vector<float> split_;      // inner nodes in heap order (children 2i+1, 2i+2)
    std::vector<uint8_t> axis_;
};

// The geometry the import computes from each point's neighbours (docs/ALGORITHM.md,
// "Radius" and "Normals"); spacing.py and normals.py describe the rules.

// The radius of the largest empty circle through point `id` and two angularly adjacent
// neighbours among its k nearest, seen in its tangent plane (normal: any length but 0), when it is
// wider than `spacing` but at most hole x spacing and the angular gap between the two is
// below max_gap (radians); else `spacing`. See spacing.py, "Gap-closing radii".
// self: the point's slot; slots: its m nearest others, nearest first.
float covering_radius(const PointIndex &index, uint32_t self, const uint32_t *slots, int m, const float normal[3],
                      float spacing, float hole, float max_gap);

// The widest angle (radians, in [0, 2 pi]) between angularly adjacent neighbours of the
// point at slot `self` among its m nearest others (slots), seen in its tangent plane after
// each neighbour below the plane is unfolded onto it along its own normal's tilt: the
// boundary test of spacing.py ("closed surface guess"). normals: by input id, any length
// but 0 (normal[self]'s direction is the plane's).
double widest_gap(const PointIndex &index, uint32_t self, const uint32_t *slots, int m, const float *normals);

// The unit eigenvector of the smallest eigenvalue of the scatter matrix of the point at
// slot `self` and its m nearest others (slots): the PCA normal, unoriented.
void pca_normal(const PointIndex &index, uint32_t self, const uint32_t *slots, int m, double normal[3]);

// The unit eigenvector of the smallest eigenvalue of a symmetric 3x3 matrix (a[0..5] =
// xx, yy, zz, xy, xz, yz): closed form where well conditioned, Jacobi rotations otherwise.
void smallest_eigenvector(const double a[6], double out[3]);

}  // namespace splat
