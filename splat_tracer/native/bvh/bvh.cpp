// Binned SAH BVH construction (Wald 2007, "On fast construction of SAH-based bounding
// volume hierarchies"), written in the spirit of tinybvh: 16 bins per axis, leaves when
// splitting no longer pays; the 4-wide nodes made directly, without a binary tree.
//
// Each binary node is planned (its records binned, SSE where there is SSE2: the bins give
// the SAH plane and both children's boxes) and, when it is not a leaf, partitioned (without
// a branch, both children's centroid bounds gathered on the way). A wide node takes its
// node's two children and splits the largest (by surface area) that is not a leaf until
// it has four -- the rule the old collapse of a binary tree applied, so the tree is the
// same; made directly it spares writing the binary nodes and reading them back out of
// cache (0.15-0.3 s of a 10M build).
//
// Parallel in two phases: the top wide nodes (on two threads only the root's) are made
// one at a time with the binning and the partitioning of each split spread over every
// thread; their children are then built as subtrees, each on one thread, into its own
// array, a child of more than a grain of records handed off as a subtree of its own
// (largest first to an idle thread). The arrays are copied into one at the end, in an
// order that does not depend on which thread built what.
#include "bvh/bvh.h"

#include <algorithm>
#include <condition_variable>
#include <deque>
#include <mutex>
#include <queue>
#include <system_error>
#include <thread>
#include <type_traits>
#include <utility>

#include "base/buffer.h"
#include "base/config.h"
#include "base/parallel.h"
#include "base/simd.h"

namespace splat {
namespace {

constexpr int kBins = 16;  // at most; a node of n primitives uses min(kBins, n + 4) bins
// SAH cost model: the traversal step (stack, two box tests, the node's cache line) costs
// three disc tests. Measured on a 2M-splat torus against 1 and 2 (issue #12): leaves of
// ~5 discs instead of ~2, half the nodes (14 instead of 33 bytes a splat), 10 % fewer
// nodes entered per ray for twice the disc tests, nearest-hit traces as fast or faster,
// and a faster build.
constexpr float kCostTraversal = 3.0f;
constexpr float kCostIntersect = 1.0f;
constexpr uint32_t kMaxLeaf = 8;  // leaves never hold more, even when SAH would like it
// Nodes of at most this many records are first checked against a lower bound of the SAH
// cost of any split (Builder::plan): on the 2M torus it finds every leaf of 2-4 records, a
// third of those of 5 and almost none above, and costs a few box areas.
constexpr uint32_t kLeafBound = 5;
// Trees of at most this many records are built on one thread; the least a subtree handed
// to a thread holds (BVH::build).
constexpr uint32_t kParallelThreshold = 1u << 15;
// Nodes above this many primitives are binned by every thread at once (top phase).
constexpr uint32_t kParallelBinning = 1u << 17;
// Nodes above this many primitives are binned along their widest axis only (see
// Builder::plan; on the 2M torus: 15 % off the build, 1-3 % more nodes entered).
constexpr uint32_t kAllAxes = 256;

inline F4 lo_of(const BuildPrim &p) { return F4::load(p.lo); }
// The fourth lane holds the id's bits: replaced by 0 (a denormal there would make the
// arithmetic on it slow, and it is never read).
inline F4 hi_of(const BuildPrim &p) { return F4::load3(p.hi); }
// The box centre, as AABB::centre computes it (halves first).
inline F4 centroid_of(const BuildPrim &p) {
    const F4 half = F4::broadcast(0.5f);
    return lo_of(p) * half + hi_of(p) * half;
}

// AABB::half_area of the box (lo, hi), in registers (the sweeps call it per bin).
inline float half_area4(F4 lo, F4 hi) {
    float e[4];
    (hi - lo).store(e);
    if (!(e[0] >= 0.f)) return 0.f;  // empty
    return e[0] * e[1] + e[1] * e[2] + e[2] * e[0];
}

AABB to_aabb(F4 lo, F4 hi) {
    float l[4], h[4];
    lo.store(l), hi.store(h);
    return AABB{Vec3(l[0], l[1], l[2]), Vec3(h[0], h[1], h[2])};
}

// A node's range of records and what the builder knows of it.
struct Range {
    uint32_t begin, end;
    F4 clo, chi;  // centroid bounds
    AABB box;     // the node's box (its parent's bins give it exactly)
    int depth;    // in binary splits from the root
    uint32_t count() const { return end - begin; }
};

// Per-axis bin index of a centroid: (c - lo) * scale clamped to [0, bins - 1] before the
// conversion (a float outside int's range, or NaN, converted to int is undefined; NaN
// becomes 0 here), then truncated.
struct Binner {
    F4 lo, scale, top;
    void of(F4 c, int32_t out[4]) const {
        truncate4(min4(max4((c - lo) * scale, F4::broadcast(0.f)), top), out);
    }
};

struct Bins {
    F4 lo[3][kBins], hi[3][kBins];
    uint32_t cnt[3][kBins];

    int used = kBins;
    void clear() {
        for (int a = 0; a < 3; ++a)
            for (int b = 0; b < used; ++b)
                lo[a][b] = F4::broadcast(kInfinity), hi[a][b] = F4::broadcast(-kInfinity), cnt[a][b] = 0;
    }
    void add(const Bins &o) {
        for (int a = 0; a < 3; ++a)
            for (int b = 0; b < used; ++b)
                lo[a][b] = min4(lo[a][b], o.lo[a][b]), hi[a][b] = max4(hi[a][b], o.hi[a][b]), cnt[a][b] += o.cnt[a][b];
    }
    // Bins along `axis` only, or along all three when axis < 0.
    void fill(const BuildPrim *p, uint32_t n, const Binner &bn, int bins, int axis) {
        used = bins;
        clear();
        if (axis >= 0) return fill_axis(p, n, bn, axis);
        const F4 half = F4::broadcast(0.5f);
        for (uint32_t i = 0; i < n; ++i) {
            const F4 l = lo_of(p[i]), h = hi_of(p[i]);
            int32_t b[4];
            bn.of(l * half + h * half, b);
            for (int a = 0; a < 3; ++a) {
                cnt[a][b[a]]++;
                lo[a][b[a]] = min4(lo[a][b[a]], l);
                hi[a][b[a]] = max4(hi[a][b[a]], h);
            }
        }
    }

    // Along one axis, in two sets of bins (even and odd records) merged at the end:
    // neighbouring records mostly fall in the same bin, and with one set each record's
    // min/max waited for the previous record's through memory (one set: 10 % slower
    // builds of the 2M torus on one thread).
    void fill_axis(const BuildPrim *p, uint32_t n, const Binner &bn, int axis) {
        F4 l2[2][kBins], h2[2][kBins];
        uint32_t c2[2][kBins];
        for (int s = 0; s < 2; ++s)
            for (int b = 0; b < used; ++b)
                l2[s][b] = F4::broadcast(kInfinity), h2[s][b] = F4::broadcast(-kInfinity), c2[s][b] = 0;
        auto run = [&](auto bin_of) {
            auto add_one = [&](int s, const BuildPrim &q) {
                const F4 l = lo_of(q), h = hi_of(q);
                const int k = bin_of(l, h);
                c2[s][k]++, l2[s][k] = min4(l2[s][k], l), h2[s][k] = max4(h2[s][k], h);
            };
            uint32_t i = 0;
            for (; i + 1 < n; i += 2) add_one(0, p[i]), add_one(1, p[i + 1]);
            if (i < n) add_one(0, p[i]);
        };
        const F4 half = F4::broadcast(0.5f);
#ifdef SPLAT_SSE2
        // The bin taken from its lane in a register (a fixed lane per loop) instead of the
        // four stored and one loaded back.
        auto lane = [&](auto axis_c) {
            run([&](F4 l, F4 h) {
                const __m128 x = min4(max4((l * half + h * half - bn.lo) * bn.scale, F4::broadcast(0.f)), bn.top).v;
                constexpr int a = decltype(axis_c)::value;
                return _mm_cvtsi128_si32(_mm_shuffle_epi32(_mm_cvttps_epi32(x), _MM_SHUFFLE(a, a, a, a)));
            });
        };
        if (axis == 0) lane(std::integral_constant<int, 0>{});
        else if (axis == 1) lane(std::integral_constant<int, 1>{});
        else lane(std::integral_constant<int, 2>{});
#else
        run([&](F4 l, F4 h) {
            int32_t b[4];
            bn.of(l * half + h * half, b);
            return b[axis];
        });
#endif
        for (int b = 0; b < used; ++b) {
            lo[axis][b] = min4(l2[0][b], l2[1][b]), hi[axis][b] = max4(h2[0][b], h2[1][b]);
            cnt[axis][b] = c2[0][b] + c2[1][b];
        }
    }
};

// How a node is split, decided from its bins before its records are partitioned: the
// wide node above it needs to know whether it is a leaf (and its box) before opening it.
struct Plan {
    enum Kind { kLeaf, kSah, kMedian } kind = kLeaf;
    int axis = 0, bin = 0;  // SAH: records whose bin along axis is at most `bin` go left
    Binner bn{};
    AABB lbox, rbox;  // SAH: the children's boxes, from the bins
};

// A node of the binary tree the SAH splits describe (never stored): a range and its plan.
struct Node {
    Range r;
    Plan p;
    bool leaf() const { return p.kind == Plan::kLeaf; }
};

// A subtree's wide nodes while it is built: a Buffer of its own pages (they go back to the
// system when freed, whichever thread allocated them: see buffer.h) that doubles when
// full, its elements left uninitialised until written.
class NodeArray {
    Buffer<WideNode> buf_;
    size_t size_ = 0;

  public:
    NodeArray() = default;
    explicit NodeArray(size_t reserve) : buf_(reserve, true) {}
    size_t size() const { return size_; }
    WideNode &operator[](size_t i) { return buf_[i]; }
    const WideNode *begin() const { return buf_.data(); }
    const WideNode *end() const { return buf_.data() + size_; }
    uint32_t push() {  // the index of a new, unwritten node
        if (size_ == buf_.size()) {
            Buffer<WideNode> bigger(std::max<size_t>(16, 2 * size_), true);
            std::copy(begin(), end(), bigger.begin());
            buf_ = std::move(bigger);
        }
        return uint32_t(size_++);
    }
};

struct Builder {
    BuildPrim *prims;

    // job(t) for t in [0, threads): on threads of their own, this one doing job(0) and the
    // jobs of any thread the system refused.
    template <class Job>
    static void on_threads(int threads, Job &&job) {
        std::vector<std::thread> pool;
        int t = 1;
        for (; t < threads; ++t) {
            try {
                pool.push_back(start_thread([&job, t] { job(t); }));
            } catch (const std::system_error &) {
                break;  // refused: this thread does the rest
            }
        }
        job(0);
        for (int k = t; k < threads; ++k) job(k);
        for (auto &th : pool) th.join();
    }

    // Bins [begin, end) on up to `threads` threads.
    void bin(const Range &r, const Binner &bn, int bins, int axis, Bins &out, int threads) {
        const uint32_t n = r.count();
        if (threads <= 1 || n < kParallelBinning) return out.fill(&prims[r.begin], n, bn, bins, axis);
        std::vector<Bins> part(static_cast<size_t>(threads));
        const uint32_t step = (n + threads - 1) / threads;
        on_threads(threads, [&](int t) {
            const uint32_t b = std::min(n, t * step), e = std::min(n, b + step);
            part[t].fill(&prims[r.begin + b], e - b, bn, bins, axis);
        });
        out = part[0];
        for (int k = 1; k < threads; ++k) out.add(part[k]);
    }

    // Bins r and decides: a leaf, an SAH split (with both children's boxes), or a median
    // split when SAH finds no plane (all centroids coincide) or the tree is too deep.
    Node plan(const Range &r, int threads) {
        Node nd{r, Plan{}};
        Plan &p = nd.p;
        const uint32_t count = r.count();
        if (count <= 1) return nd;
        if (count <= kLeafBound) {
            // No split costs less than count records of the smallest record box: a node
            // whose smallest box is large enough next to its own is a leaf whatever the
            // bins say, and is not binned (the relative margin covers the float rounding
            // of the SAH's own sums, so that the bins could never have said otherwise).
            const float area = r.box.half_area();
            float smallest = kInfinity;
            for (uint32_t i = r.begin; i < r.end; ++i)
                smallest = std::min(smallest, half_area4(lo_of(prims[i]), hi_of(prims[i])));
            const double bound = kCostTraversal + kCostIntersect * double(count) * smallest / area * (1.0 - 1e-5);
            if (area > 0.f && bound >= kCostIntersect * double(count)) return nd;
        }
        if (r.depth < kSahMaxDepth) {
            // Small nodes get fewer bins: sweeping 16 mostly empty bins per axis cost more
            // than the binning itself in the lower levels of the tree (count / 2 + 3
            // instead of count + 4: 6 % off a 10M build, the same number of nodes).
            const int bins = int(std::min<uint32_t>(kBins, count / 2 + 3));
            float clo[4], chi[4], scale[4] = {0.f, 0.f, 0.f, 0.f};
            r.clo.store(clo), r.chi.store(chi);
            for (int a = 0; a < 3; ++a) {
                const float ext = chi[a] - clo[a];
                scale[a] = ext > 0.f ? bins / ext : 0.f;
            }
            // Nodes above kAllAxes primitives are binned along their widest centroid
            // extent only: a third of the work, for trees as good on scanned surfaces.
            int only = -1;
            if (count > kAllAxes) {
                only = scale[0] > 0.f ? 0 : (scale[1] > 0.f ? 1 : 2);
                for (int a = 0; a < 3; ++a)
                    if (scale[a] > 0.f && chi[a] - clo[a] > chi[only] - clo[only]) only = a;
                for (int a = 0; a < 3; ++a)
                    if (a != only) scale[a] = 0.f;
            }
            const Binner bn{r.clo, F4::load(scale), F4::broadcast(float(bins - 1))};
            Bins bs;
            bin(r, bn, bins, only, bs, threads);
            float best_cost = kInfinity;
            int best_axis = -1, best_bin = 0;
            for (int axis = 0; axis < 3; ++axis) {
                if (scale[axis] == 0.f) continue;
                // Sweep from the right, then from the left, evaluating the bins-1 planes.
                float right_area[kBins - 1];
                uint32_t right_count[kBins - 1];
                F4 alo = F4::broadcast(kInfinity), ahi = F4::broadcast(-kInfinity);
                uint32_t n = 0;
                for (int b = bins - 1; b > 0; --b) {
                    alo = min4(alo, bs.lo[axis][b]), ahi = max4(ahi, bs.hi[axis][b]);
                    n += bs.cnt[axis][b];
                    right_area[b - 1] = half_area4(alo, ahi);
                    right_count[b - 1] = n;
                }
                alo = F4::broadcast(kInfinity), ahi = F4::broadcast(-kInfinity);
                n = 0;
                for (int b = 0; b < bins - 1; ++b) {
                    alo = min4(alo, bs.lo[axis][b]), ahi = max4(ahi, bs.hi[axis][b]);
                    n += bs.cnt[axis][b];
                    if (n == 0 || right_count[b] == 0) continue;
                    const float cost = n * half_area4(alo, ahi) + right_count[b] * right_area[b];
                    if (cost < best_cost) best_cost = cost, best_axis = axis, best_bin = b;
                }
            }
            if (best_axis >= 0) {
                const float parent_area = r.box.half_area();
                const float split_cost = kCostTraversal + kCostIntersect * best_cost / parent_area;
                const float leaf_cost = kCostIntersect * count;
                if (split_cost >= leaf_cost && count <= kMaxLeaf) return nd;
                F4 alo = F4::broadcast(kInfinity), ahi = F4::broadcast(-kInfinity);
                F4 blo = alo, bhi = ahi;
                for (int b = 0; b < bins; ++b) {
                    if (b <= best_bin) alo = min4(alo, bs.lo[best_axis][b]), ahi = max4(ahi, bs.hi[best_axis][b]);
                    else blo = min4(blo, bs.lo[best_axis][b]), bhi = max4(bhi, bs.hi[best_axis][b]);
                }
                p.kind = Plan::kSah, p.axis = best_axis, p.bin = best_bin, p.bn = bn;
                p.lbox = to_aabb(alo, ahi), p.rbox = to_aabb(blo, bhi);
                return nd;
            }
        }
        if (count > kMaxLeaf) p.kind = Plan::kMedian;
        return nd;
    }

    // Partitions a node that is not a leaf as its plan says, into its two children.
    void split(const Node &nd, Range &left, Range &right, int threads) {
        const Range &r = nd.r;
        F4 llo = F4::broadcast(kInfinity), lhi = F4::broadcast(-kInfinity), rlo = llo, rhi = lhi;
        uint32_t mid;
        AABB lbox, rbox;
        if (nd.p.kind == Plan::kSah) {
            mid = partition(r, nd.p.bn, nd.p.axis, nd.p.bin, llo, lhi, rlo, rhi, threads);
            lbox = nd.p.lbox, rbox = nd.p.rbox;
        } else {  // median
            const AABB cb = to_aabb(r.clo, r.chi);
            const Vec3 e = cb.extent();
            const int axis = (e.x >= e.y && e.x >= e.z) ? 0 : (e.y >= e.z ? 1 : 2);
            mid = r.begin + r.count() / 2;
            std::nth_element(prims + r.begin, prims + mid, prims + r.end,
                             [axis](const BuildPrim &a, const BuildPrim &b) {
                                 return a.lo[axis] * 0.5f + a.hi[axis] * 0.5f < b.lo[axis] * 0.5f + b.hi[axis] * 0.5f;
                             });
            F4 blo = F4::broadcast(kInfinity), bhi = F4::broadcast(-kInfinity), alo = blo, ahi = bhi;
            for (uint32_t i = r.begin; i < r.end; ++i) {
                const BuildPrim &q = prims[i];
                const F4 c = centroid_of(q);
                if (i < mid) alo = min4(alo, lo_of(q)), ahi = max4(ahi, hi_of(q)), llo = min4(llo, c), lhi = max4(lhi, c);
                else blo = min4(blo, lo_of(q)), bhi = max4(bhi, hi_of(q)), rlo = min4(rlo, c), rhi = max4(rhi, c);
            }
            lbox = to_aabb(alo, ahi), rbox = to_aabb(blo, bhi);
        }
        left = Range{r.begin, mid, llo, lhi, lbox, r.depth + 1};
        right = Range{mid, r.end, rlo, rhi, rbox, r.depth + 1};
    }

    // The children of the wide node made from `nd` (not a leaf): its two children, then
    // the largest (by surface area) of them that is not a leaf opened into its own two,
    // until there are four. Each child is planned as it is made, so that whether it is a
    // leaf is known before the choice. What a wide node holds depends only on its own
    // records: the same tree whichever thread builds it.
    int open(const Node &nd, Node kids[4], int threads) {
        auto area_of = [](const Node &k) { return k.leaf() ? -1.f : k.r.box.half_area(); };
        Range a, b;
        split(nd, a, b, threads);
        kids[0] = plan(a, threads), kids[1] = plan(b, threads);
        float area[4] = {area_of(kids[0]), area_of(kids[1])};
        int n = 2;
        while (n < 4) {
            int o = -1;
            float largest = -1.f;
            for (int k = 0; k < n; ++k)
                if (area[k] > largest) o = k, largest = area[k];
            if (o < 0) break;
            split(kids[o], a, b, threads);
            kids[o] = plan(a, threads), area[o] = area_of(kids[o]);
            kids[n] = plan(b, threads), area[n] = area_of(kids[n]), ++n;
        }
        return n;
    }

    // The wide node over `kids`; inner(k) gives the index of the wide node kid k (not a
    // leaf) becomes.
    template <class Inner>
    static WideNode wide(const Node *kids, int n, Inner &&inner) {
        WideNode w;
        for (int k = 0; k < 4; ++k) {
            if (k >= n) {
                for (int a = 0; a < 3; ++a) w.box[2 * a][k] = kInfinity, w.box[2 * a + 1][k] = -kInfinity;
                w.child[k] = kNoChild, w.count[k] = 0;
                continue;
            }
            const Range &r = kids[k].r;
            for (int a = 0; a < 3; ++a) w.box[2 * a][k] = r.box.lo[a], w.box[2 * a + 1][k] = r.box.hi[a];
            if (kids[k].leaf()) w.child[k] = r.begin, w.count[k] = r.count();
            else w.child[k] = inner(k), w.count[k] = 0;
        }
        return w;
    }

    // The wide subtree of `root` (not a leaf) on this thread, depth first, into `out`
    // (root first; child indices relative to out[0]). Siblings are made next to each
    // other, and the last sibling's subtree is built first. A child for which
    // hand_off(child, node, lane) returns true is left to the caller (its lane is then
    // kNoChild until the caller links it).
    template <class HandOff>
    void build_subtree(const Node &root, NodeArray &out, HandOff &&hand_off) {
        struct Job {
            Node nd;
            uint32_t w;
        };
        std::vector<Job> todo{{root, out.push()}};
        Node kids[4];
        while (!todo.empty()) {
            const Job j = todo.back();
            todo.pop_back();
            const int n = open(j.nd, kids, 1);
            const WideNode w = wide(kids, n, [&](int k) {
                if (hand_off(kids[k], j.w, k)) return kNoChild;
                const uint32_t i = out.push();
                todo.push_back({kids[k], i});
                return i;
            });
            out[j.w] = w;
        }
    }

    // Records whose bin along `axis` is at most `best` first; both sides' centroid bounds
    // gathered on the way. Returns the partition point.
    uint32_t partition(uint32_t begin, uint32_t end, const Binner &bn, int axis, int best, F4 &llo, F4 &lhi, F4 &rlo,
                       F4 &rhi) {
#ifdef SPLAT_SSE2
        // The axis as a template argument: the bin compared in its lane, no store and
        // reload of the four bins (the loop below is the build's hottest).
        switch (axis) {
            case 0: return partition_sse<0>(begin, end, bn, best, llo, lhi, rlo, rhi);
            case 1: return partition_sse<1>(begin, end, bn, best, llo, lhi, rlo, rhi);
            default: return partition_sse<2>(begin, end, bn, best, llo, lhi, rlo, rhi);
        }
#endif
        // Branchless (Lomuto, swapping every record): [begin, k) goes left, [k, i) right.
        // A two-sided (Hoare) partition branched per record and mispredicted about every
        // other time: this one took a third off a 10M build.
        BuildPrim *p = prims;
        uint32_t k = begin;
        const F4 inf = F4::broadcast(kInfinity), ninf = F4::broadcast(-kInfinity);
        for (uint32_t i = begin; i < end; ++i) {
            const BuildPrim q = p[i];
            const F4 c = centroid_of(q);
            int32_t b[4];
            bn.of(c, b);
            const bool left = b[axis] <= best;
            llo = min4(llo, select4(left, c, inf)), lhi = max4(lhi, select4(left, c, ninf));
            rlo = min4(rlo, select4(left, inf, c)), rhi = max4(rhi, select4(left, ninf, c));
            p[i] = p[k];
            p[k] = q;
            k += left;
        }
        return k;
    }

#ifdef SPLAT_SSE2
    // partition() along Axis with SSE2 masks: the same bins as Binner::of (the same
    // operations in the same order), the same records moved, the same bounds.
    template <int Axis>
    uint32_t partition_sse(uint32_t begin, uint32_t end, const Binner &bn, int best, F4 &llo, F4 &lhi, F4 &rlo,
                           F4 &rhi) {
        BuildPrim *p = prims;
        uint32_t k = begin;
        const __m128 inf = _mm_set1_ps(kInfinity), ninf = _mm_set1_ps(-kInfinity), zero = _mm_setzero_ps();
        const __m128i last_left = _mm_set1_epi32(best);
        __m128 a = llo.v, b = lhi.v, c = rlo.v, d = rhi.v;
        for (uint32_t i = begin; i < end; ++i) {
            const BuildPrim q = p[i];
            const __m128 cen = centroid_of(q).v;
            const __m128i bins = _mm_cvttps_epi32(
                _mm_min_ps(_mm_max_ps(_mm_mul_ps(_mm_sub_ps(cen, bn.lo.v), bn.scale.v), zero), bn.top.v));
            // All ones where the record goes right.
            const __m128 right = _mm_castsi128_ps(
                _mm_shuffle_epi32(_mm_cmpgt_epi32(bins, last_left), _MM_SHUFFLE(Axis, Axis, Axis, Axis)));
            const __m128 on_left = _mm_andnot_ps(right, cen), on_right = _mm_and_ps(right, cen);
            a = _mm_min_ps(a, _mm_or_ps(on_left, _mm_and_ps(right, inf)));
            b = _mm_max_ps(b, _mm_or_ps(on_left, _mm_and_ps(right, ninf)));
            c = _mm_min_ps(c, _mm_or_ps(on_right, _mm_andnot_ps(right, inf)));
            d = _mm_max_ps(d, _mm_or_ps(on_right, _mm_andnot_ps(right, ninf)));
            p[i] = p[k];
            p[k] = q;
            k += uint32_t(1 + _mm_cvtsi128_si32(_mm_castps_si128(right)));  // -1 when right
        }
        llo = a, lhi = b, rlo = c, rhi = d;
        return k;
    }
#endif

    // Nodes above kParallelBinning records: kSlices slices partitioned apart (on up to
    // `threads` threads), then the records on the wrong side of the overall partition point
    // swapped pairwise, in order. The slices do not depend on the thread count, so neither
    // does the order the records end in (nor, then, the leaf order of the splats).
    static constexpr int kSlices = 8;
    uint32_t partition(const Range &r, const Binner &bn, int axis, int best, F4 &llo, F4 &lhi, F4 &rlo, F4 &rhi,
                       int threads) {
        const uint32_t n = r.count();
        if (n < kParallelBinning) return partition(r.begin, r.end, bn, axis, best, llo, lhi, rlo, rhi);
        struct Slice {
            uint32_t begin, end, mid;
            F4 llo, lhi, rlo, rhi;
        };
        std::vector<Slice> slice(kSlices);
        const uint32_t step = (n + kSlices - 1) / kSlices;
        const int workers = std::max(1, std::min(threads, kSlices));
        on_threads(workers, [&](int w) {
            for (int t = w; t < kSlices; t += workers) {
                Slice &sl = slice[t];
                sl.begin = r.begin + std::min(n, t * step), sl.end = r.begin + std::min(n, t * step + step);
                sl.llo = sl.rlo = F4::broadcast(kInfinity), sl.lhi = sl.rhi = F4::broadcast(-kInfinity);
                sl.mid = partition(sl.begin, sl.end, bn, axis, best, sl.llo, sl.lhi, sl.rlo, sl.rhi);
            }
        });
        uint32_t mid = r.begin;
        for (const Slice &sl : slice) {
            mid += sl.mid - sl.begin;
            llo = min4(llo, sl.llo), lhi = max4(lhi, sl.lhi), rlo = min4(rlo, sl.rlo), rhi = max4(rhi, sl.rhi);
        }
        // Right-goers before mid are the slices' right parts there, left-goers from mid on
        // their left parts there: as many of each. The k-th of the one swaps with the k-th
        // of the other, the k split among the threads (this pass alone took a seventh of
        // the top phase on one thread while the other waited).
        struct Span {
            uint32_t at, len;
        };
        std::vector<Span> wrong_right, wrong_left;
        uint64_t wrong = 0;
        for (const Slice &sl : slice) {
            const uint32_t e = std::min(sl.end, mid), lo = std::max(sl.begin, mid);
            if (sl.mid < e) wrong_right.push_back({sl.mid, e - sl.mid}), wrong += e - sl.mid;
            if (lo < sl.mid) wrong_left.push_back({lo, sl.mid - lo});
        }
        // The span and offset of the k-th misplaced record of a list.
        auto locate = [](const std::vector<Span> &spans, uint64_t k, size_t &span, uint32_t &off) {
            for (span = 0; span < spans.size() && k >= spans[span].len; ++span) k -= spans[span].len;
            off = uint32_t(k);
        };
        on_threads(wrong < kParallelBinning ? 1 : workers, [&](int w) {
            const int parts = wrong < kParallelBinning ? 1 : workers;
            const uint64_t k0 = wrong * w / parts, k1 = wrong * (w + 1) / parts;
            size_t x, y;
            uint32_t ox, oy;
            locate(wrong_right, k0, x, ox), locate(wrong_left, k0, y, oy);
            for (uint64_t k = k0; k < k1;) {
                const uint32_t run = uint32_t(std::min<uint64_t>(
                    {uint64_t(wrong_right[x].len - ox), uint64_t(wrong_left[y].len - oy), k1 - k}));
                BuildPrim *p = prims + wrong_right[x].at + ox;
                std::swap_ranges(p, p + run, prims + wrong_left[y].at + oy);
                k += run, ox += run, oy += run;
                if (ox == wrong_right[x].len) ++x, ox = 0;
                if (oy == wrong_left[y].len) ++y, oy = 0;
            }
        });
        return mid;
    }
};

// Iterative (an explicit stack): a recursion would follow whatever `child` says.
int depth_of(const Buffer<WideNode> &nodes) {
    int deepest = 0;
    std::vector<std::pair<uint32_t, int>> stack{{0u, 1}};
    while (!stack.empty()) {
        const auto [i, d] = stack.back();
        stack.pop_back();
        deepest = std::max(deepest, d);
        for (int k = 0; k < 4; ++k)
            if (nodes[i].child[k] != kNoChild && nodes[i].count[k] == 0) stack.push_back({nodes[i].child[k], d + 1});
    }
    return deepest;
}

// Wide nodes reserved for a subtree of `count` records, so that its vector is rarely
// copied as it grows: the SAH's leaves hold ~5 records and a wide node up to 4 children,
// ~0.105 nodes a record on the torus; an eighth leaves a little room. Reserved but unwritten
// pages are never touched on Linux and macOS, but Windows commits them: not more.
size_t nodes_expected(uint32_t count) { return count / 8 + 16; }

}  // namespace

void BVH::build(const std::vector<AABB> &bounds, int threads) {
    std::vector<BuildPrim> prims(bounds.size());
    for (size_t i = 0; i < bounds.size(); ++i) prims[i] = BuildPrim(bounds[i], uint32_t(i));
    build(prims.data(), prims.size(), threads);
    prim_order.resize(prims.size());
    for (size_t i = 0; i < prims.size(); ++i) prim_order[i] = prims[i].id;
}

void BVH::build(BuildPrim *prims, size_t count, int threads) {
    const uint32_t n = uint32_t(count);
    threads = resolve_threads(threads);
    nodes.release();
    prim_order.clear();
    if (n == 0) return;  // no nodes at all: traversals check for that
    F4 lo = F4::broadcast(kInfinity), hi = F4::broadcast(-kInfinity), clo = lo, chi = hi;
    for (uint32_t i = 0; i < n; ++i) {
        const BuildPrim &p = prims[i];
        const F4 c = centroid_of(p);
        lo = min4(lo, lo_of(p)), hi = max4(hi, hi_of(p)), clo = min4(clo, c), chi = max4(chi, c);
    }
    Builder b{prims};
    const Node root = b.plan(Range{0, n, clo, chi, to_aabb(lo, hi), 0}, threads);
    if (root.leaf()) {  // one leaf: node 0 holds it as its only child
        nodes.allocate(1);
        nodes[0] = Builder::wide(&root, 1, [](int) { return kNoChild; });
        return;
    }
    if (threads <= 1 || n <= kParallelThreshold) {
        NodeArray out(nodes_expected(n));
        b.build_subtree(root, out, [](const Node &, uint32_t, int) { return false; });
        nodes.allocate(out.size());
        std::copy(out.begin(), out.end(), nodes.begin());
        return;
    }
    // Top phase: wide nodes over more than a thread's share of the records are made here,
    // one at a time, the binning and partitioning of each split shared by the threads (on
    // two threads only the root's: its four children are the first subtrees).
    const uint32_t share = std::max(kParallelThreshold, n / uint32_t(threads));
    // Subtrees: each built on one thread into its own array; a child of more than `grain`
    // records met on the way is handed off as a subtree of its own, which an idle thread
    // takes (largest first). Threads stay busy to the end (at most a subtree of `grain`
    // records, ~1/32 of the work, left on one thread), and no level is split with the
    // threads sharing it when its nodes could go to different threads. (The old binary top
    // split until every subtree held at most n / 4t: up to four levels of shared splits,
    // 0.2-0.3 s of a 10M build on two threads, and subtrees of uneven sizes.)
    const uint32_t grain = std::max(kParallelThreshold, n / uint32_t(16 * threads));
    struct Subtree {
        Node root;
        size_t parent;  // the subtree whose array holds the wide node above (kTop: `top`)
        uint32_t w;     // that wide node, and its lane that points here
        int lane;
        NodeArray out;
        std::vector<size_t> handed;  // the subtrees this one handed off, in order
    };
    constexpr size_t kTop = ~size_t(0);
    std::vector<WideNode> top(1);
    std::deque<Subtree> subtrees;  // grows while the threads run: references stay valid
    std::vector<size_t> first;     // the subtrees under `top`, in order
    {
        struct Job {
            Node nd;
            uint32_t w;
        };
        std::vector<Job> queue{{root, 0}};
        Node kids[4];
        for (size_t head = 0; head < queue.size(); ++head) {
            const Job j = queue[head];
            const int m = b.open(j.nd, kids, threads);
            top[j.w] = Builder::wide(kids, m, [&](int k) {
                if (kids[k].r.count() <= share) {
                    first.push_back(subtrees.size());
                    subtrees.push_back({kids[k], kTop, j.w, k, {}, {}});
                    return kNoChild;  // linked below, once the arrays before it are sized
                }
                top.emplace_back();
                queue.push_back({kids[k], uint32_t(top.size() - 1)});
                return uint32_t(top.size() - 1);
            });
        }
    }
    std::mutex mutex;
    std::condition_variable wake;
    auto larger = [&](size_t x, size_t y) { return subtrees[x].root.r.count() < subtrees[y].root.r.count(); };
    std::priority_queue<size_t, std::vector<size_t>, decltype(larger)> ready(larger, first);
    int busy = 0;  // threads building a subtree (guarded by mutex, as are ready and subtrees)
    bool failed = false;
    // One per thread (parallel_for starts them; a thread the system refuses leaves its loop
    // to the others, which find nothing left).
    auto work = [&](size_t) {
        for (;;) {
            Subtree *t;
            size_t id;
            {
                std::unique_lock<std::mutex> lock(mutex);
                wake.wait(lock, [&] { return failed || !ready.empty() || busy == 0; });
                if (failed || ready.empty()) return;
                id = ready.top(), ready.pop(), ++busy;
                t = &subtrees[id];
            }
            try {
                t->out = NodeArray(nodes_expected(t->root.r.count()));
                b.build_subtree(t->root, t->out, [&](const Node &kid, uint32_t w, int lane) {
                    if (kid.r.count() <= grain) return false;
                    std::lock_guard<std::mutex> lock(mutex);
                    t->handed.push_back(subtrees.size());
                    subtrees.push_back({kid, id, w, lane, {}, {}});
                    ready.push(subtrees.size() - 1);
                    wake.notify_one();
                    return true;
                });
            } catch (...) {
                std::lock_guard<std::mutex> lock(mutex);
                failed = true, --busy;
                wake.notify_all();
                throw;  // parallel_for rethrows it once every thread has stopped
            }
            std::lock_guard<std::mutex> lock(mutex);
            if (--busy == 0 && ready.empty()) wake.notify_all();
        }
    };
    parallel_for(size_t(threads), threads, work, [](size_t) { return true; });
    // One array: the top nodes, then the subtrees depth first (each after the one that
    // handed it off, in the order handed): the same layout whichever thread built what.
    std::vector<size_t> order, offset(subtrees.size());
    std::vector<size_t> stack(first.rbegin(), first.rend());
    size_t total = top.size();
    while (!stack.empty()) {
        const size_t i = stack.back();
        stack.pop_back();
        order.push_back(i), offset[i] = total, total += subtrees[i].out.size();
        stack.insert(stack.end(), subtrees[i].handed.rbegin(), subtrees[i].handed.rend());
    }
    // Links: absolute in `top`; relative to the parent's first node in the subtrees' arrays
    // (the copy below adds the parent's offset to every child index there).
    for (size_t i = 0; i < subtrees.size(); ++i) {
        const Subtree &t = subtrees[i];
        if (t.parent == kTop) top[t.w].child[t.lane] = uint32_t(offset[i]);
        else subtrees[t.parent].out[t.w].child[t.lane] = uint32_t(offset[i] - offset[t.parent]);
    }
    nodes.allocate(total);
    std::copy(top.begin(), top.end(), nodes.begin());
    parallel_for(
        order.size(), threads,
        [&](size_t k) {
            const size_t i = order[k];
            const uint32_t shift = uint32_t(offset[i]);
            WideNode *dst = nodes.data() + offset[i];
            for (const WideNode &w : subtrees[i].out) {
                *dst = w;
                for (int l = 0; l < 4; ++l)
                    if (w.count[l] == 0 && w.child[l] != kNoChild) dst->child[l] += shift;
                ++dst;
            }
            subtrees[i].out = NodeArray();  // freed as soon as copied
        },
        [](size_t) { return true; });
}

int BVH::depth() const { return nodes.empty() ? 0 : depth_of(nodes); }

}  // namespace splat
