#include "pointcloud/neighbours.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>

#include "base/buffer.h"
#include "base/config.h"
#include "base/errors.h"
#include "base/parallel.h"
#include "base/ray.h"
#include "base/simd.h"

namespace splat {

namespace {

using BuildPoint = IndexedPoint;

// The axis along which the points spread widest, from at most kSpreadSample of them (evenly
// strided: an estimate is enough to choose an axis). Not the cell's widest side: a cell cut
// only from its parent keeps, say, a terrain's whole height range, and splitting that
// instead of the points' own extent left leaves long and thin, twice as many of them
// within a query's reach at 10M points.
constexpr size_t kSpreadSample = 256;
int widest_spread(const BuildPoint *p, size_t count) {
    const size_t stride = std::max<size_t>(1, count / kSpreadSample);
    float lo[3] = {p[0].c[0], p[0].c[1], p[0].c[2]}, hi[3] = {lo[0], lo[1], lo[2]};
    for (size_t i = stride; i < count; i += stride)
        for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], p[i].c[a]), hi[a] = std::max(hi[a], p[i].c[a]);
    const float e0 = hi[0] - lo[0], e1 = hi[1] - lo[1], e2 = hi[2] - lo[2];
    return e0 >= e1 ? (e0 >= e2 ? 0 : 2) : (e1 >= e2 ? 1 : 2);
}

// Moves the points so that p[nth] is the one a sort by coordinate `a` would put there, none
// before it larger and none after it smaller (std::nth_element's contract), by quickselect
// with branchless partitions: std::nth_element's comparisons branch unpredictably, which
// made it 3/4 of the k-d tree's build time. Each round splits at the median of nine
// evenly spaced points, moving every point below it to the front (each point is moved
// whether or not it goes: no branch).
void select_nth(BuildPoint *p, size_t n, size_t nth, int a) {
    constexpr size_t kSmall = 32;  // below this, std::nth_element's insertion sort is as fast
    // At most kRounds rounds (a range halves per round when the pivots are good; 64 allow
    // for bad luck), then std::nth_element, whose worst case is bounded: a pathological
    // input cannot make the build quadratic.
    constexpr int kRounds = 64;
    for (int round = 0; n > kSmall && round < kRounds; ++round) {
        float sample[9];
        for (int i = 0; i < 9; ++i) sample[i] = p[(2 * i + 1) * n / 18].c[a];
        std::nth_element(sample, sample + 4, sample + 9);
        const float pivot = sample[4];
        size_t lo = 0;
        for (size_t j = 0; j < n; ++j) {
            const BuildPoint t = p[j];
            const bool below = t.c[a] < pivot;
            p[j] = p[lo];
            p[lo] = t;
            lo += below;
        }
        if (lo == 0) {  // the pivot is the smallest value: the points equal to it to the front instead
            for (size_t j = 0; j < n; ++j) {
                const BuildPoint t = p[j];
                const bool equal = !(pivot < t.c[a]);
                p[j] = p[lo];
                p[lo] = t;
                lo += equal;
            }
            if (nth < lo) return;  // all of [0, lo) equal the pivot, everything after is larger
        }
        if (nth < lo) {
            n = lo;
        } else {
            p += lo, n -= lo, nth -= lo;
        }
    }
    std::nth_element(p, p + nth, p + n, [a](const BuildPoint &x, const BuildPoint &y) { return x.c[a] < y.c[a]; });
}

}  // namespace

// The k best candidates so far, nearest first (insertion into a sorted array: k is small).
struct PointIndex::Best {
    int k, count = 0;
    float *d2;
    uint32_t *slot;          // the candidates' slots (tree-order positions)
    uint32_t exclude;        // a tree-order position never to return (kNone: none)
    float worst = std::numeric_limits<float>::infinity();  // the k-th distance, once k are found
};

namespace {

// The index of the lowest set bit of v != 0.
inline int ctz32(uint32_t v) {
#if defined(__GNUC__) || defined(__clang__)
    return __builtin_ctz(v);
#else
    int i = 0;
    while (!(v & 1u)) v >>= 1, ++i;
    return i;
#endif
}

// Inserts (d, s) into the sorted candidates d2/slot (count of k; d < worst) and returns the
// new worst. On locals, not on a Best: stores through d2 could alias its members and force
// reloads in the hot loop.
inline float insert(float d, uint32_t s, int k, int &count, float *d2, uint32_t *slot, float worst) {
    int i = count < k ? count++ : k - 1;
    for (; i > 0 && d2[i - 1] > d; --i) d2[i] = d2[i - 1], slot[i] = slot[i - 1];
    d2[i] = d, slot[i] = s;
    return count == k ? d2[k - 1] : worst;
}

}  // namespace

PointIndex::PointIndex(const float *xyz, size_t n, int threads) : n_(n) {
    if (n == 0) throw InputError("a point index needs at least one point");
    if (n >= size_t(kNone)) throw InputError("too many points for a point index (at most 2^32 - 2)");
    const auto always = [](size_t) { return true; };
    // Checked and copied on the threads, in slices (each with its own bounds and first bad
    // point, so that the message names the first of all): one thread took a tenth of a
    // 10M-point build for this loop. The buffers are not zeroed first (a std::vector's
    // were, on one thread); their pages are first touched by the threads that fill them.
    constexpr size_t kSlice = size_t(1) << 16;
    const size_t slices = (n + kSlice - 1) / kSlice;
    pts_.allocate(n);
    pts_.prefer_huge_pages();
    Buffer<BuildPoint> &pts = pts_;  // built in place: the tree keeps its points so
    std::vector<Box> slice_box(slices);
    std::vector<size_t> slice_bad(slices, n);
    parallel_for(slices, threads, [&](size_t t) {
        const size_t b = t * kSlice, e = std::min(n, b + kSlice);
        Box box{{xyz[3 * b], xyz[3 * b + 1], xyz[3 * b + 2]}, {xyz[3 * b], xyz[3 * b + 1], xyz[3 * b + 2]}};
        bool ok = true;
        for (size_t i = b; i < e; ++i) {
            const float *p = xyz + 3 * i;
            for (int a = 0; a < 3; ++a) {
                ok &= within_range(p[a]);
                pts[i].c[a] = p[a];
                box.lo[a] = std::min(box.lo[a], p[a]), box.hi[a] = std::max(box.hi[a], p[a]);
            }
            pts[i].id = uint32_t(i);
        }
        if (!ok)  // rare: find the first bad point of the slice
            for (size_t i = b; i < e && slice_bad[t] == n; ++i)
                for (int a = 0; a < 3; ++a)
                    if (!within_range(xyz[3 * i + a])) slice_bad[t] = i;
        slice_box[t] = box;
    }, always);
    Box root = slice_box[0];
    for (size_t t = 0; t < slices; ++t) {
        if (slice_bad[t] < n)
            throw InputError("point " + std::to_string(slice_bad[t]) + " is not finite or beyond 1e18");
        for (int a = 0; a < 3; ++a)
            root.lo[a] = std::min(root.lo[a], slice_box[t].lo[a]), root.hi[a] = std::max(root.hi[a], slice_box[t].hi[a]);
    }
    bounds_ = root;
    while (double(n) > kLeafAverage * std::ldexp(1.0, depth_)) ++depth_;  // ceil(n / 2^depth) <= 23 <= kLeafSize
    const size_t inner = (size_t(1) << depth_) - 1;
    split_.resize(inner);
    axis_.resize(inner);

    // Splits node (depth d) at its middle; returns the children's cells (the node's cut at the split).
    auto split_node = [&](uint32_t node, int d, const Box &cell, Box &left, Box &right) {
        const size_t b = begin(node, d), e = begin(node + 1, d);  // node + 1: the next at this depth
        const size_t mid = begin(2 * node + 2, d + 1);
        const int a = widest_spread(pts.data() + b, e - b);
        select_nth(pts.data() + b, e - b, mid - b, a);
        const float s = pts[mid].c[a];
        split_[node] = s, axis_[node] = uint8_t(a);
        left = right = cell;
        left.hi[a] = s, right.lo[a] = s;
    };
    // The top levels one at a time (a level's nodes on the threads), then whole subtrees,
    // depth first, one per task: a subtree's points stay in the cache of the thread that
    // splits them. kSubtreeTasks per thread balance the subtrees' uneven work.
    constexpr int kSubtreeTasksPerThread = 8;
    const int workers = resolve_threads(threads);
    int top = 0;
    while (top < depth_ && (1 << top) < kSubtreeTasksPerThread * workers) ++top;
    std::vector<Box> cells{root}, next;
    for (int d = 0; d < top; ++d) {
        const uint32_t first = (1u << d) - 1u;
        next.assign(size_t(2) << d, Box{});
        parallel_for(size_t(1) << d, threads, [&](size_t j) {
            split_node(first + uint32_t(j), d, cells[j], next[2 * j], next[2 * j + 1]);
        }, always);
        cells.swap(next);
    }
    if (top < depth_) {
        const uint32_t first = (1u << top) - 1u;
        parallel_for(cells.size(), threads, [&](size_t j) {
            struct Item { uint32_t node; int d; Box cell; };
            std::vector<Item> stack{{first + uint32_t(j), top, cells[j]}};
            while (!stack.empty()) {
                const Item it = stack.back();
                stack.pop_back();
                Box l, r;
                split_node(it.node, it.d, it.cell, l, r);
                if (it.d + 1 < depth_) {
                    stack.push_back({2 * it.node + 2, it.d + 1, r});
                    stack.push_back({2 * it.node + 1, it.d + 1, l});
                }
            }
        }, always);
    }
    slot_.allocate(n);
    slot_.prefer_huge_pages();
    // The points stay where the build left them (the tree's order); only the inverse order
    // is written, on the threads, in slices (the ids are distinct: the scatter never races).
    // A copy of the points by axis took a fifth of a 10M-point build, and 160 MB more.
    parallel_for(slices, threads, [&](size_t t) {
        for (size_t i = t * kSlice; i < std::min(n, (t + 1) * kSlice); ++i) slot_[pts[i].id] = uint32_t(i);
    }, always);
}

void PointIndex::scan(size_t b, size_t e, const float q[3], Best &best) const {
    // Distances a leaf's worth at a time, then the few candidates nearer than the k-th.
    float d[kLeafSize];
    const int k = best.k;
    int count = best.count;
    float worst = best.worst, *d2 = best.d2;
    uint32_t *slot = best.slot;
    for (; b < e; b += kLeafSize) {
        const size_t m = std::min(kLeafSize, e - b);
        const IndexedPoint *p = &pts_[b];
        for (size_t i = 0; i < m; ++i) {
            const float dx = p[i].c[0] - q[0], dy = p[i].c[1] - q[1], dz = p[i].c[2] - q[2];
            d[i] = dx * dx + dy * dy + dz * dz;
        }
        if (best.exclude != kNone && best.exclude - b < m) d[best.exclude - b] = std::numeric_limits<float>::infinity();
        // Which are nearer than the k-th, as a bit mask built without branches: whether a
        // point is was most of the search's branch mispredictions. Each insertion lowers
        // `worst`, so the later candidates of the mask are compared again.
        uint32_t near = 0;
        for (size_t i = 0; i < m; ++i) near |= uint32_t(d[i] < worst) << i;
        for (; near; near &= near - 1) {
            const int i = ctz32(near);
            if (d[i] < worst) worst = insert(d[i], uint32_t(b + i), k, count, d2, slot, worst);
        }
    }
    best.count = count, best.worst = worst;
}

void PointIndex::search(const float q[3], Best &best, uint32_t node, int depth, float mindist, float off[3],
                        size_t skip_b, size_t skip_e) const {
    const size_t b = begin(node, depth), e = begin(node + 1, depth);  // node + 1: the next at this depth
    if (b >= skip_b && e <= skip_e) return;
    if (depth == depth_) {
        scan(b, e, q, best);
        return;
    }
    const int a = axis_[node];
    const float diff = q[a] - split_[node];
    const uint32_t near = 2 * node + (diff < 0.f ? 1 : 2), far = 4 * node + 3 - near;
    search(q, best, near, depth + 1, mindist, off, skip_b, skip_e);
    // The far cell lies at least |diff| away along `a`: replace the query's distance to the
    // cell along that axis (nanoflann's incremental bound).
    const float d = diff * diff, far_dist = mindist - off[a] + d;
    if (far_dist < best.worst) {
        const float saved = off[a];
        off[a] = d;
        search(q, best, far, depth + 1, far_dist, off, skip_b, skip_e);
        off[a] = saved;
    }
}

uint32_t PointIndex::leaf_of(size_t s) const {
    uint32_t node = 0;
    for (int d = 0; d < depth_; ++d) node = s < begin(2 * node + 2, d + 1) ? 2 * node + 1 : 2 * node + 2;
    return node;
}

int PointIndex::nearest(const float q[3], uint32_t exclude, int k, float *d2, uint32_t *slots) const {
    Best best{k, 0, d2, slots, exclude};
    size_t skip_b = 0, skip_e = 0;
    if (exclude != kNone) {  // a point of the index: its own leaf first, for a tight bound
        const uint32_t leaf = leaf_of(best.exclude);
        skip_b = begin(leaf, depth_), skip_e = begin(leaf + 1, depth_);
        scan(skip_b, skip_e, q, best);
    }
    float off[3] = {0.f, 0.f, 0.f};
    search(q, best, 0, 0, 0.f, off, skip_b, skip_e);
    return best.count;
}

int PointIndex::nearest_of(uint32_t s, int k, float *d2, uint32_t *slots) const {
    const float q[3] = {pts_[s].c[0], pts_[s].c[1], pts_[s].c[2]};
    return nearest(q, s, k, d2, slots);
}

namespace {

// Squared distance between two boxes (0 when they touch or overlap).
inline float box_gap2(const float alo[3], const float ahi[3], const float blo[3], const float bhi[3]) {
    float d = 0.f;
    for (int a = 0; a < 3; ++a) {
        const float g = std::max(0.f, std::max(alo[a] - bhi[a], blo[a] - ahi[a]));
        d += g * g;
    }
    return d;
}

// leaf_nearest gathers at most this many candidate points for one leaf, else its points
// search one by one: a cluster of coincident points makes every leaf of the cluster a
// candidate of every other (their cells all touch), which one search per point, whose
// bound is then 0, avoids. 64 leaves: far more than a surface's leaves need (10-20).
constexpr size_t kMaxGathered = 64 * PointIndex::kLeafSize;

}  // namespace

void PointIndex::gather(uint32_t node, int depth, const Box &cell, const Box &box, float r2, size_t skip_b,
                        size_t skip_e, std::vector<std::pair<uint32_t, Box>> &leaves, size_t &points) const {
    const size_t b = begin(node, depth), e = begin(node + 1, depth);
    if ((b >= skip_b && e <= skip_e) || points > kMaxGathered) return;
    if (box_gap2(cell.lo, cell.hi, box.lo, box.hi) > r2) return;
    if (depth == depth_) {
        leaves.push_back({node, cell});
        points += e - b;
        return;
    }
    const int a = axis_[node];
    Box left = cell, right = cell;
    left.hi[a] = right.lo[a] = split_[node];
    gather(2 * node + 1, depth + 1, left, box, r2, skip_b, skip_e, leaves, points);
    gather(2 * node + 2, depth + 1, right, box, r2, skip_b, skip_e, leaves, points);
}

namespace {

// leaf_nearest's candidates: the points every query of a leaf may have among its k nearest,
// copied once per leaf by axis, so that each query's distances to all of them go four to a
// vector register (the copies cost about as much as one query's distances). They are in
// the order the one-at-a-time search visited them, the subtree's then the gathered
// leaves' by slot: among equal distances the earlier one is the nearer (see select_nearest).
struct Candidates {
    std::vector<float> x, y, z;
    std::vector<uint32_t> slot;
    size_t count = 0;

    void clear() { count = 0; }
    void append(const IndexedPoint *p, size_t b, size_t e) {
        const size_t n = count + (e - b);
        if (x.size() < n + kLanes) {
            const size_t grown = std::max(2 * x.size(), n + kLanes);
            x.resize(grown), y.resize(grown), z.resize(grown), slot.resize(grown);
        }
        for (size_t s = b; s < e; ++s, ++count)
            x[count] = p[s].c[0], y[count] = p[s].c[1], z[count] = p[s].c[2], slot[count] = uint32_t(s);
    }
    // count rounded up to whole vectors, the padding points at infinity: no query's
    // distance to them (+inf) is below any bound.
    size_t padded() {
        const size_t n = (count + kLanes - 1) / kLanes * kLanes;
        for (size_t j = count; j < n; ++j) x[j] = y[j] = z[j] = std::numeric_limits<float>::infinity();
        return n;
    }
    static constexpr size_t kLanes = 4;  // floats in an SSE2 (or NEON) register
};

// d[j]: the squared distance from q to candidate j < n (n: a multiple of kLanes), computed
// as PointIndex::scan does it ((dx^2 + dy^2) + dz^2 in float): the same values, to the bit.
// A plain loop the compiler vectorises.
void distances(const Candidates &c, size_t n, const float q[3], float *d) {
    const float *x = c.x.data(), *y = c.y.data(), *z = c.z.data();
    for (size_t j = 0; j < n; ++j) {
        const float dx = x[j] - q[0], dy = y[j] - q[1], dz = z[j] - q[2];
        d[j] = dx * dx + dy * dy + dz * dz;
    }
}

// The k-th smallest of d[0..n) (n: a multiple of Candidates::kLanes; 1 <= k <= n): the
// smallest value that at least k of them are at most. Counted per value, n^2 comparisons
// without a branch (a sort's or a quickselect's branches mispredict), for the few values
// of a leaf's subtree (k + 1 to about 2k + 2 of them).
float kth_smallest(const float *d, size_t n, int k) {
    constexpr size_t L = Candidates::kLanes;
    float kth = std::numeric_limits<float>::infinity();
    for (size_t b = 0; b < n; b += L) {
        int32_t at_most[L] = {};
        for (size_t i = 0; i < n; ++i)
            for (size_t l = 0; l < L; ++l) at_most[l] += d[i] <= d[b + l];
        for (size_t l = 0; l < L; ++l) kth = at_most[l] >= k && d[b + l] < kth ? d[b + l] : kth;
    }
    return kth;
}

// The candidates j with d[j] <= bound, in order, into within[] (room for n + kLanes);
// returns how many. Without a branch per candidate: whether one is within is a coin toss.
size_t within_bound(const float *d, size_t n, float bound, uint32_t *within) {
    size_t count = 0;
#ifdef SPLAT_SSE2
    // A vector of four at a time: the lanes within (a 4-bit mask) are moved to the front
    // by a table of lane orders and all four stored; the count advances past the ones within.
    alignas(16) static const int32_t kFront[16][4] = {
        {0, 1, 2, 3}, {0, 1, 2, 3}, {1, 0, 2, 3}, {0, 1, 2, 3}, {2, 0, 1, 3}, {0, 2, 1, 3}, {1, 2, 0, 3},
        {0, 1, 2, 3}, {3, 0, 1, 2}, {0, 3, 1, 2}, {1, 3, 0, 2}, {0, 1, 3, 2}, {2, 3, 0, 1}, {0, 2, 3, 1},
        {1, 2, 3, 0}, {0, 1, 2, 3}};
    const __m128 limit = _mm_set1_ps(bound);
    for (size_t j = 0; j < n; j += 4) {
        const int mask = _mm_movemask_ps(_mm_cmple_ps(_mm_loadu_ps(d + j), limit));
        const __m128i lanes = _mm_load_si128(reinterpret_cast<const __m128i *>(kFront[mask]));
        _mm_storeu_si128(reinterpret_cast<__m128i *>(within + count), _mm_add_epi32(lanes, _mm_set1_epi32(int32_t(j))));
        count += (0x4332322132212110u >> (4 * mask)) & 0xf;  // the mask's set bits, 4 bits per mask
    }
#else
    for (size_t j = 0; j < n; ++j) within[count] = uint32_t(j), count += d[j] <= bound;
#endif
    return count;
}

// rank[l] for l < 4: how many of v[0..n) rank before v[b + l] (smaller, or equal and
// earlier), for a block of four (b: a multiple of 4, n too). Split by where i lies, so that
// each comparison is one: before the block an equal value ranks before (<=), after it not
// (<); within it, per lane. Fixed inner loops of four, which compile to one vector
// comparison each (SSE2, NEON).
inline void rank_block(const float *v, size_t n, size_t b, int32_t rank[4]) {
    int32_t r[4] = {};
    for (size_t i = 0; i < b; ++i)
        for (size_t l = 0; l < 4; ++l) r[l] += v[i] <= v[b + l];
    for (size_t t = 0; t < 4; ++t)
        for (size_t l = 0; l < 4; ++l) r[l] += l > t ? v[b + t] <= v[b + l] : v[b + t] < v[b + l];
    for (size_t i = b + 4; i < n; ++i)
        for (size_t l = 0; l < 4; ++l) r[l] += v[i] < v[b + l];
    for (size_t l = 0; l < 4; ++l) rank[l] = r[l];
}

// A query's k nearest among the candidates within its bound: the k smallest of d[within[j]]
// (j < count, count >= k, within[] rising), ties to the smaller j (the earlier candidate,
// as the one-at-a-time search's sorted insertion had it), nearest first, into out_d2 and
// out_slot. By counting each one's rank, count^2 comparisons without a branch, for up to
// kRankMax: sorted insertion's varying shifts mispredicted, a third of the search's time.
// Beyond it (k far above the import's 6 to 24) a sort.
constexpr size_t kRankMax = 64;
void select_nearest(const float *d, const uint32_t *within, size_t count, int k, const uint32_t *slot,
                    float *out_d2, uint32_t *out_slot) {
    constexpr size_t L = Candidates::kLanes;
    if (count > kRankMax) {
        // (distance, j) as one 64-bit key: squared distances are >= 0, whose bits order as the values do
        thread_local std::vector<uint64_t> key;
        key.resize(count);
        for (size_t j = 0; j < count; ++j) {
            uint32_t bits;
            std::memcpy(&bits, &d[within[j]], sizeof bits);
            key[j] = uint64_t(bits) << 32 | j;
        }
        std::partial_sort(key.begin(), key.begin() + k, key.end());
        for (int r = 0; r < k; ++r) {
            const uint32_t j = uint32_t(key[r]);
            out_d2[r] = d[within[j]], out_slot[r] = slot[within[j]];
        }
        return;
    }
    float v[kRankMax];
    const size_t n = (count + L - 1) / L * L;
    for (size_t j = 0; j < count; ++j) v[j] = d[within[j]];
    for (size_t j = count; j < n; ++j) v[j] = std::numeric_limits<float>::infinity();  // rank after every real one
    // Ranks below k land in their place; the others in a spare last place (no branch).
    float d2[PointIndex::kMaxK + 1];
    uint32_t s[PointIndex::kMaxK + 1];
    for (size_t b = 0; b < n; b += L) {
        int32_t rank[L];
        rank_block(v, n, b, rank);
        for (size_t l = 0; l < L && b + l < count; ++l) {
            const int r = std::min(rank[l], k);
            d2[r] = v[b + l], s[r] = slot[within[b + l]];
        }
    }
    std::copy(d2, d2 + k, out_d2), std::copy(s, s + k, out_slot);
}

// leaf_nearest's first bound on a point's k-th nearest, in squared distance: the previous
// point's (the one before it in the leaf) times this. On randomly sampled surfaces (a 1M
// terrain and a sphere, k = 12) the squared k-th distance of a point is within 1.5x its
// predecessor's 9 times in 10, and about 18 candidates lie within the bound; when fewer
// than k do, the exact bound serves. 1.3 and 1.8 measured no faster.
constexpr float kPreviousWiden = 1.5f;

}  // namespace

void PointIndex::leaf_nearest(size_t b, size_t e, int k, float *d2, uint32_t *slots, float &guess) const {
    const size_t m = e - b;  // <= kLeafSize: one leaf's points at most
    // The smallest subtree around the leaf with k + 1 points: every point's first candidates.
    uint32_t node = leaf_of(b);
    int depth = depth_;
    while (begin(node + 1, depth) - begin(node, depth) < size_t(k) + 1) node = (node - 1) / 2, --depth;
    const size_t sb = begin(node, depth), se = begin(node + 1, depth);
    // With a guess (the previous leaf's largest k-th distance, widened), nothing beyond it
    // counts and only the leaves within it are gathered: on an evenly sampled surface the
    // neighbours of adjacent leaves lie about as far, and the first candidates (the
    // subtree's) bounded the gathering far more loosely. A point left with fewer than k
    // searches again without the guess, so the answer is exact either way.
    const float inf = std::numeric_limits<float>::infinity();
    const float cap = guess > 0.f ? guess : inf;
    // "d < cap" as "d <= below_cap", so that every bound below is inclusive.
    const float below_cap = std::nextafter(cap, 0.f);
    thread_local Candidates cand;
    thread_local std::vector<float> dist;
    thread_local std::vector<uint32_t> within;
    cand.clear();
    cand.append(pts_.data(), sb, se);
    const size_t sub = cand.padded();
    if (dist.size() < sub) dist.resize(sub), within.resize(sub + Candidates::kLanes);
    // Without a guess, each point's k-th nearest within the subtree: a bound on its k-th
    // nearest, and with the box around the points, on where they all lie. With one, the
    // guess bounds the gathering: the subtree's k-th distances were below it for every
    // point of most leaves of 19 (10M points) and narrowed it a little, for a fifth of the
    // search's time; a point whose k nearest are not all within it searches on its own.
    thread_local std::vector<float> sub_dist;  // the points' distances to the subtree, a row each
    if (sub_dist.size() < m * sub) sub_dist.resize(m * sub);
    Box box{{pts_[b].c[0], pts_[b].c[1], pts_[b].c[2]}, {pts_[b].c[0], pts_[b].c[1], pts_[b].c[2]}};
    const bool all_within = !(guess > 0.f);  // no cap: the subtree has k points within it
    for (size_t i = 0; i < m; ++i) {
        const size_t s = b + i;
        const float q[3] = {pts_[s].c[0], pts_[s].c[1], pts_[s].c[2]};
        if (all_within) {
            float *row = &sub_dist[i * sub];
            distances(cand, sub, q, row);
            row[s - sb] = inf;  // not itself
        }
        for (int a = 0; a < 3; ++a) box.lo[a] = std::min(box.lo[a], q[a]), box.hi[a] = std::max(box.hi[a], q[a]);
    }
    float worst[kLeafSize];  // each point's bound: the subtree's k-th without a cap, else the cap
    float r2 = cap;
    if (all_within) {
        r2 = 0.f;
        for (size_t i = 0; i < m; ++i) r2 = std::max(r2, worst[i] = kth_smallest(&sub_dist[i * sub], sub, k));
    } else {
        std::fill(worst, worst + m, cap);
    }
    // Every point's k nearest lie within its k-th candidate's distance, at most sqrt(r2)
    // from the box: the leaves whose cells come that close, outside the subtree.
    thread_local std::vector<std::pair<uint32_t, Box>> leaves;
    leaves.clear();
    size_t points = 0;
    gather(0, 0, bounds_, box, r2, sb, se, leaves, points);
    const bool gathered = points <= kMaxGathered;
    size_t n = sub;
    if (gathered) {
        for (const auto &leaf : leaves) cand.append(pts_.data(), begin(leaf.first, depth_), begin(leaf.first + 1, depth_));
        n = cand.padded();
        if (dist.size() < n) dist.resize(n), within.resize(n + Candidates::kLanes);
    }
    float widest = 0.f, previous = 0.f;
    for (size_t i = 0; i < m; ++i) {
        const size_t s = b + i;
        float *di = d2 + i * k;
        uint32_t *si = slots + i * k;
        size_t found = 0;
        if (gathered) {
            const float q[3] = {pts_[s].c[0], pts_[s].c[1], pts_[s].c[2]};
            distances(cand, n, q, dist.data());
            dist[s - sb] = inf;
            // The k nearest are the k smallest (ties: the earlier candidate first) of those
            // within any bound that at least k are within: first a tight guess, the previous
            // point's k-th distance widened (neighbouring points' differ by less than
            // kPreviousWiden in squared distance 9 times in 10 on randomly sampled surfaces),
            // then the exact bound, its subtree's k-th or the cap.
            const float exact = worst[i] < cap ? worst[i] : below_cap;
            const float tight = std::min(exact, kPreviousWiden * previous);
            found = previous > 0.f ? within_bound(dist.data(), n, tight, within.data()) : 0;
            if (found < size_t(k)) found = within_bound(dist.data(), n, exact, within.data());
            if (found >= size_t(k)) select_nearest(dist.data(), within.data(), found, k, cand.slot.data(), di, si);
        }
        if (found < size_t(k)) {  // one search of its own, exact
            Best best{k, 0, di, si, uint32_t(s)};
            const float q[3] = {pts_[s].c[0], pts_[s].c[1], pts_[s].c[2]};
            scan(sb, se, q, best);
            float off[3] = {0.f, 0.f, 0.f};
            search(q, best, 0, 0, 0.f, off, sb, se);
        }
        previous = di[k - 1];
        widest = std::max(widest, previous);
    }
    // The next leaf's guess: 1.5 x this one's largest squared k-th distance (1.22 x the
    // distance): wide enough that few points of an evenly sampled surface search again,
    // narrow enough to gather about half the leaves the subtree's bound did.
    guess = widest > 0.f && std::isfinite(widest) ? 1.5f * widest : 0.f;
}

// ---------------------------------------------------------------------------------------
// Geometry from the neighbours

namespace {

// The unit normal n (of `normal`, any length but 0) and a tangent frame (u, v): u = n x
// helper, the helper an axis far from n; v = n x u (spacing.py's _tangent_frame).
inline void tangent_frame(const float normal[3], double n[3], double u[3], double v[3]) {
    const double nl = std::sqrt(double(normal[0]) * normal[0] + double(normal[1]) * normal[1] +
                                double(normal[2]) * normal[2]);
    for (int a = 0; a < 3; ++a) n[a] = normal[a] / nl;
    const double h[3] = {std::fabs(n[0]) < 0.9 ? 1.0 : 0.0, std::fabs(n[0]) < 0.9 ? 0.0 : 1.0, 0.0};
    u[0] = n[1] * h[2] - n[2] * h[1], u[1] = n[2] * h[0] - n[0] * h[2], u[2] = n[0] * h[1] - n[1] * h[0];
    const double ul = std::sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
    for (int a = 0; a < 3; ++a) u[a] /= ul;
    v[0] = n[1] * u[2] - n[2] * u[1], v[1] = n[2] * u[0] - n[0] * u[2], v[2] = n[0] * u[1] - n[1] * u[0];
}

// A monotonic stand-in for atan2(y, x) mapped to [0, 2 pi): in [0, 4] (4 only by rounding
// 3 + p up), no trigonometry (the "diamond angle"). Sorting by it orders vectors around the
// origin as the angle does. In arithmetic rather than branches, so that a loop over
// neighbours vectorises (and whether y < 0 is a coin toss): below = 1 gives 3 + p, below = 0
// gives 1 - p, the same roundings; a coincident neighbour gets 0 (atan2(0, 0) = 0 as well).
inline double pseudo_angle(double x, double y) {
    const double l1 = std::fabs(x) + std::fabs(y), some = l1 != 0.0, below = y < 0.0;
    const double p = x / (l1 + (1.0 - some));  // no 0 / 0 when coincident
    return some * ((1.0 + 2.0 * below) + (2.0 * below - 1.0) * p);
}

}  // namespace

namespace {
constexpr int kRankSortMax = 32;
// covering_radius's loops over neighbours go in blocks of this many (m rounded up), fixed
// inner loops that compile to vector code without remainders: two SSE2 registers of
// doubles, one of 32-bit integers.
constexpr int kBlock = 4;

// order[0..m): the neighbours j by their angles ang[j] (pseudo_angle's, in [0, 4]), ties by
// position in the list (a stable sort's order); order[m] = order[0] (the turn closes); and
// rank[j]: j's place in that order.
void angular_order(const double *ang, int m, int *order, int32_t *rank) {
    if (m <= kRankSortMax) {
        // For up to kRankSortMax neighbours, by counting each one's rank, m^2 comparisons
        // without a branch: a comparison sort's unpredictable branches cost more at the few
        // neighbours the import asks for (12, 24). They compare 32-bit keys, four to a register
        // (SSE2 compares two doubles, and no 64-bit integers): the angle x 2^28 truncated, in
        // [0, 2^30] (the padding's above), ordered as the angles are wherever keys differ.
        const int mb = (m + kBlock - 1) / kBlock * kBlock;
        int32_t key[kRankSortMax];
        for (int j = 0; j < m; ++j) key[j] = int32_t(ang[j] * 0x1p28);
        for (int j = m; j < mb; ++j) key[j] = INT32_MAX;
        for (int b = 0; b < mb; b += kBlock) {  // a block's ranks kept in a register
            int32_t r[kBlock] = {};
            for (int i = 0; i < m; ++i)
                for (int l = 0; l < kBlock; ++l) r[l] += key[i] < key[b + l];
            for (int l = 0; l < kBlock && b + l < m; ++l) rank[b + l] = r[l];
        }
        // Distinct keys rank 0 to m - 1, which sum to m (m - 1) / 2; equal keys (coincident
        // neighbours, a grid's collinear ones, angles within 2^-28) share the smaller rank and
        // sum to less. Only then are the angles themselves counted, ties broken by position.
        int32_t sum = 0;
        for (int j = 0; j < m; ++j) sum += rank[j];
        if (sum != m * (m - 1) / 2)
            for (int j = 0; j < m; ++j) {
                rank[j] = 0;
                for (int i = 0; i < m; ++i) rank[j] += (ang[i] < ang[j]) | ((ang[i] == ang[j]) & (i < j));
            }
        for (int j = 0; j < m; ++j) order[rank[j]] = j;
    } else {  // the same order
        for (int j = 0; j < m; ++j) order[j] = j;
        std::stable_sort(order, order + m, [&](int a, int b) { return ang[a] < ang[b]; });
        for (int i = 0; i < m; ++i) rank[order[i]] = i;
    }
    order[m] = order[0];
}
}  // namespace

float covering_radius(const PointIndex &index, uint32_t self, const uint32_t *slots, int m, const float normal[3],
                      float spacing, float hole, float max_gap) {
    if (m < 2) return spacing;
    double n[3], u[3], v[3];
    tangent_frame(normal, n, u, v);
    float p[3];
    index.at(self, p);
    // The padding up to mb is the point itself (offset 0), which changes nothing below: it
    // ranks after every neighbour (left out of the order) and lies on every circle, not inside.
    const int mb = (m + kBlock - 1) / kBlock * kBlock;
    float ox[PointIndex::kMaxK], oy[PointIndex::kMaxK], oz[PointIndex::kMaxK];
    for (int b = 0; b < mb; b += kBlock) {
        // Gathered into registers and stored a block at a time: the projection's vector loads
        // then take the data from the store queue, which they cannot from several smaller
        // stores (they wait for them to reach the cache instead).
        float qx[kBlock], qy[kBlock], qz[kBlock];
        for (int l = 0; l < kBlock; ++l) {
            float q[3];
            index.at(b + l < m ? slots[b + l] : self, q);
            qx[l] = q[0], qy[l] = q[1], qz[l] = q[2];
        }
        for (int l = 0; l < kBlock; ++l)  // in float, as ever
            ox[b + l] = qx[l] - p[0], oy[b + l] = qy[l] - p[1], oz[b + l] = qz[l] - p[2];
    }
    double x[PointIndex::kMaxK], y[PointIndex::kMaxK], ang[PointIndex::kMaxK];
    for (int b = 0; b < mb; b += kBlock)
        for (int j = b; j < b + kBlock; ++j) {
            const double o[3] = {ox[j], oy[j], oz[j]};
            x[j] = o[0] * u[0] + o[1] * u[1] + o[2] * u[2];
            y[j] = o[0] * v[0] + o[1] * v[1] + o[2] * v[2];
            ang[j] = pseudo_angle(x[j], y[j]);
        }
    // (xn[j], yn[j]): the neighbour after j counter-clockwise (the last one's is the first),
    // gathered by j's rank and stored in order, so that the test below is a loop of vector
    // arithmetic (scalar before: a fifth of this function's time). No sorted copies of x and
    // y: their scatter's scalar stores stalled the vector loads of the loops after it.
    int order[PointIndex::kMaxK + 1];
    int32_t rank[PointIndex::kMaxK];
    angular_order(ang, m, order, rank);
    double xn[PointIndex::kMaxK], yn[PointIndex::kMaxK];
    for (int j = 0; j < m; ++j) {
        const int after = order[rank[j] + 1];
        xn[j] = x[after], yn[j] = y[after];
    }
    // First which adjacent pairs have a circle within the spacing band, without branches
    // (whether one does is unpredictable: mispredictions were most of this function's time),
    // then only those few are solved and tested.
    const double lo2 = double(spacing) * spacing, hi2 = lo2 * double(hole) * hole;
    int32_t in_band[PointIndex::kMaxK];
    for (int j = m; j < mb; ++j) xn[j] = yn[j] = 0.0;  // the padding (the point itself): d = 0, no circle
    for (int b = 0; b < mb; b += kBlock)
        for (int j = b; j < b + kBlock; ++j) {
            const double xa = x[j], ya = y[j], xb = xn[j], yb = yn[j];
            // Circumcentre of (0, 0), (x_a, y_a), (x_b, y_b) is (nx, ny) / d; collinear
            // triples (d = 0) have none, and fail both comparisons. r^2 = (nx^2 + ny^2) / d^2,
            // compared without dividing.
            const double d = 2.0 * (xa * yb - ya * xb);
            const double sa = xa * xa + ya * ya, sb = xb * xb + yb * yb;
            const double nx = yb * sa - ya * sb, ny = xa * sb - xb * sa;
            const double r2d2 = nx * nx + ny * ny, d2 = d * d;
            in_band[j] = (r2d2 > lo2 * d2) & (r2d2 <= hi2 * d2);
        }
    int cand[PointIndex::kMaxK], nc = 0;
    for (int j = 0; j < m; ++j) cand[nc] = j, nc += in_band[j];
    // The largest squared radius so far (its root once, at the end: not on the path to the
    // emptiness test); (1 - 1e-4)^2, the empty circle's margin below, squared.
    double best2 = double(spacing) * spacing;
    constexpr double kInner2 = (1.0 - 1e-4) * (1.0 - 1e-4);
    for (int k = 0; k < nc; ++k) {
        const int j = cand[k];
        const double xa = x[j], ya = y[j], xb = xn[j], yb = yn[j];
        const double d = 2.0 * (xa * yb - ya * xb);
        const double sa = xa * xa + ya * ya, sb = xb * xb + yb * yb;
        const double cx = (yb * sa - ya * sb) / d, cy = (xa * sb - xb * sa) / d;
        const double r2 = cx * cx + cy * cy;
        // Empty: no neighbour strictly inside (1e-4 of the radius: the two on the circle, in
        // rounding). Every one tested, with no early exit (an unpredictable branch): the
        // nearest squared distance to the centre, per vector lane.
        const double inner2 = r2 * kInner2;
        double nearest[kBlock];
        for (int l = 0; l < kBlock; ++l) nearest[l] = inner2;
        for (int b = 0; b < mb; b += kBlock)
            for (int l = 0; l < kBlock; ++l) {
                const double dx = cx - x[b + l], dy = cy - y[b + l], dd = dx * dx + dy * dy;
                nearest[l] = dd < nearest[l] ? dd : nearest[l];
            }
        bool empty = true;
        for (int l = 0; l < kBlock; ++l) empty &= !(nearest[l] < inner2);
        if (!(r2 > best2) || !empty) continue;
        // The angular gap from a to b, counter-clockwise in [0, 2 pi): its atan2 only for the
        // few circles that got this far (most have a neighbour inside).
        double gap = std::atan2(d, 2.0 * (xa * xb + ya * yb));
        if (gap < 0.0) gap += 2.0 * M_PI;
        if (gap < max_gap) best2 = r2;
    }
    return float(std::sqrt(best2));
}

double widest_gap(const PointIndex &index, uint32_t self, const uint32_t *slots, int m, const float *normals) {
    if (m < 1) return 2.0 * M_PI;
    double n[3], u[3], v[3];
    tangent_frame(normals + 3 * size_t(index.id(self)), n, u, v);
    float p[3];
    index.at(self, p);
    double x[PointIndex::kMaxK], y[PointIndex::kMaxK], ang[PointIndex::kMaxK];
    for (int j = 0; j < m; ++j) {
        float q[3];
        index.at(slots[j], q);
        double o[3] = {double(q[0] - p[0]), double(q[1] - p[1]), double(q[2] - p[2])};
        const double depth = std::max(-(o[0] * n[0] + o[1] * n[1] + o[2] * n[2]), 0.0);  // below the plane
        if (depth > 0.0) {
            // Unfolded along the neighbour's normal's tilt from this one's: a neighbour round
            // a fold (a sharp edge) lies beside the point, not behind it.
            const float *nj = normals + 3 * size_t(index.id(slots[j]));
            const double along = nj[0] * n[0] + nj[1] * n[1] + nj[2] * n[2];
            const double t[3] = {nj[0] - along * n[0], nj[1] - along * n[1], nj[2] - along * n[2]};
            const double tl = std::sqrt(t[0] * t[0] + t[1] * t[1] + t[2] * t[2]);
            if (tl > 1e-6)  // spacing.py's threshold: no tilt, no unfolding
                for (int a = 0; a < 3; ++a) o[a] += depth * t[a] / tl;
        }
        x[j] = o[0] * u[0] + o[1] * u[1] + o[2] * u[2], y[j] = o[0] * v[0] + o[1] * v[1] + o[2] * v[2];
        if (x[j] == 0.0 && y[j] == 0.0) x[j] = 1.0;  // no direction: angle 0, as atan2(0, 0) gives
        ang[j] = pseudo_angle(x[j], y[j]);
    }
    // In angular order (the pseudo-angle orders as the angle does), the gap from each
    // neighbour to the next counter-clockwise, compared by the pseudo-angle of the vector
    // (a.b, a x b), which grows with the gap over [0, 2 pi); one atan2 for the widest alone
    // (an atan2 per neighbour and the sort of their angles were most of the test's time).
    // The pseudo-angles' difference (4 a turn, exactly 2 a half turn) says which side of the
    // wrap a gap near 0 or 2 pi is on, where the cross product's sign is a rounding's.
    int order[PointIndex::kMaxK + 1];
    int32_t rank[PointIndex::kMaxK];
    angular_order(ang, m, order, rank);
    double widest_key = -1.0, dot = 0.0, cross = 0.0;
    for (int i = 0; i < m; ++i) {
        const int a = order[i], b = order[i + 1];
        const double turn = i + 1 < m ? ang[b] - ang[a] : ang[b] + 4.0 - ang[a];
        const double d = x[a] * x[b] + y[a] * y[b];
        double c = x[a] * y[b] - y[a] * x[b];
        if (turn <= 1.0) c = std::max(c, 0.0);  // a gap below a right angle
        // nearly a whole turn (one neighbour, or all on one ray) when the cross product says none
        if (turn >= 3.0 && d > 0.0 && c >= 0.0) return 2.0 * M_PI;
        const double key = pseudo_angle(d, c);
        if (key > widest_key) widest_key = key, dot = d, cross = c;
    }
    double widest = std::atan2(cross, dot);
    if (widest < 0.0) widest += 2.0 * M_PI;
    return widest;
}

namespace {

double det3(const double m[3][3]) {
    return m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
           m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
}

// Cyclic Jacobi rotations: slow but exact for any symmetric matrix (repeated eigenvalues
// included), for the few the closed form cannot decide.
void jacobi_smallest(const double a6[6], double out[3]) {
    double a[3][3] = {{a6[0], a6[3], a6[4]}, {a6[3], a6[1], a6[5]}, {a6[4], a6[5], a6[2]}};
    double v[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    for (int sweep = 0; sweep < 50; ++sweep) {  // converges quadratically: a handful suffice
        const double off = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
        const double diag = a[0][0] * a[0][0] + a[1][1] * a[1][1] + a[2][2] * a[2][2];
        if (off <= 1e-30 * diag || off == 0.0) break;
        for (int p = 0; p < 2; ++p)
            for (int q = p + 1; q < 3; ++q) {
                if (a[p][q] == 0.0) continue;
                const double theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
                const double t = (theta >= 0 ? 1.0 : -1.0) / (std::fabs(theta) + std::sqrt(theta * theta + 1.0));
                const double c = 1.0 / std::sqrt(t * t + 1.0), s = t * c;
                for (int r = 0; r < 3; ++r) {  // a <- a J
                    const double arp = a[r][p], arq = a[r][q];
                    a[r][p] = c * arp - s * arq, a[r][q] = s * arp + c * arq;
                }
                for (int r = 0; r < 3; ++r) {  // a <- J^T a
                    const double apr = a[p][r], aqr = a[q][r];
                    a[p][r] = c * apr - s * aqr, a[q][r] = s * apr + c * aqr;
                }
                for (int r = 0; r < 3; ++r) {  // v <- v J
                    const double vrp = v[r][p], vrq = v[r][q];
                    v[r][p] = c * vrp - s * vrq, v[r][q] = s * vrp + c * vrq;
                }
            }
    }
    int best = 0;
    for (int i = 1; i < 3; ++i)
        if (a[i][i] < a[best][best]) best = i;
    for (int r = 0; r < 3; ++r) out[r] = v[r][best];
}

}  // namespace

void smallest_eigenvector(const double a6[6], double out[3]) {
    // Closed form (Smith 1961): the smallest eigenvalue by the trigonometric solution of the
    // characteristic cubic, its vector as the largest cross product of two rows of A - lambda I.
    const double q = (a6[0] + a6[1] + a6[2]) / 3.0;
    const double p1 = a6[3] * a6[3] + a6[4] * a6[4] + a6[5] * a6[5];
    const double p2 = (a6[0] - q) * (a6[0] - q) + (a6[1] - q) * (a6[1] - q) + (a6[2] - q) * (a6[2] - q) + 2.0 * p1;
    const double p = std::sqrt(p2 / 6.0);
    if (p > 0.0 && std::isfinite(p)) {
        const double b[3][3] = {{(a6[0] - q) / p, a6[3] / p, a6[4] / p},
                                {a6[3] / p, (a6[1] - q) / p, a6[5] / p},
                                {a6[4] / p, a6[5] / p, (a6[2] - q) / p}};
        const double r = std::clamp(det3(b) / 2.0, -1.0, 1.0);
        const double lambda = q + 2.0 * p * std::cos(std::acos(r) / 3.0 + 2.0 * M_PI / 3.0);
        const double m[3][3] = {{a6[0] - lambda, a6[3], a6[4]}, {a6[3], a6[1] - lambda, a6[5]},
                                {a6[4], a6[5], a6[2] - lambda}};
        double best[3] = {0, 0, 0}, best_len = -1.0;
        const int pairs[3][2] = {{0, 1}, {0, 2}, {1, 2}};
        for (const auto &pr : pairs) {
            const double *r0 = m[pr[0]], *r1 = m[pr[1]];
            const double c[3] = {r0[1] * r1[2] - r0[2] * r1[1], r0[2] * r1[0] - r0[0] * r1[2],
                                 r0[0] * r1[1] - r0[1] * r1[0]};
            const double len = std::sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
            if (len > best_len) best_len = len, best[0] = c[0], best[1] = c[1], best[2] = c[2];
        }
        // Well conditioned: the cross product is of the order of p^2 (the eigenvalue gap);
        // its direction's error grows as the inverse of the gap. 1e-3: normals.py's
        // _EIGEN_TOLERANCE, which measured this threshold.
        if (best_len > 1e-3 * p * p) {
            for (int i = 0; i < 3; ++i) out[i] = best[i] / best_len;
            return;
        }
    }
    jacobi_smallest(a6, out);
}

void pca_normal(const PointIndex &index, uint32_t self, const uint32_t *slots, int found, double normal[3]) {
    // About the point itself first (offsets are small: no cancellation), then the mean.
    float p[3];
    index.at(self, p);
    double s[3] = {0, 0, 0}, ss[6] = {0, 0, 0, 0, 0, 0};
    for (int j = 0; j < found; ++j) {
        float q[3];
        index.at(slots[j], q);
        const double o[3] = {double(q[0]) - p[0], double(q[1]) - p[1], double(q[2]) - p[2]};
        s[0] += o[0], s[1] += o[1], s[2] += o[2];
        ss[0] += o[0] * o[0], ss[1] += o[1] * o[1], ss[2] += o[2] * o[2];
        ss[3] += o[0] * o[1], ss[4] += o[0] * o[2], ss[5] += o[1] * o[2];
    }
    const double count = found + 1.0;  // the point itself, at offset 0
    const double m[3] = {s[0] / count, s[1] / count, s[2] / count};
    const double cov[6] = {ss[0] - count * m[0] * m[0], ss[1] - count * m[1] * m[1], ss[2] - count * m[2] * m[2],
                           ss[3] - count * m[0] * m[1], ss[4] - count * m[0] * m[2], ss[5] - count * m[1] * m[2]};
    smallest_eigenvector(cov, normal);
}

}  // namespace splat
