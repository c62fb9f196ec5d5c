// Binned SAH BVH construction (Wald 2007, "On fast construction of SAH-based bounding
// volume hierarchies"), written in the spirit of tinybvh: one flat node array, 16 bins
// per axis, leaves when splitting no longer pays.
//
// Two passes per node: one bins the centroids (SSE where there is SSE2), the bins then give
// both children's boxes; one partitions the records (without a branch) and gathers both
// children's centroid bounds on the way. Parallel in two phases: the top levels are
// split one node at a time with the binning spread over every thread, until no subtree
// holds more than a share of the primitives; those subtrees are then built each on one
// thread, largest first, pulled from a shared counter (parallel_for).
#include "bvh.h"

#include <algorithm>
#include <atomic>
#include <system_error>
#include <thread>
#include <utility>

#include "buffer.h"
#include "parallel.h"
#include "simd.h"

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
// Subtrees at most this large are built on one thread; larger nodes in the top phase.
constexpr uint32_t kParallelThreshold = 1u << 15;
// Nodes above this many primitives are binned by every thread at once (top phase).
constexpr uint32_t kParallelBinning = 1u << 17;
// Nodes above this many primitives are binned along their widest axis only (see
// Builder::split; on the 2M torus: 15 % off the build, 1-3 % more nodes entered).
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
    uint32_t node, begin, end;
    F4 clo, chi;  // centroid bounds
    int depth;
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
        const F4 half = F4::broadcast(0.5f);
        for (uint32_t i = 0; i < n; ++i) {
            const F4 l = lo_of(p[i]), h = hi_of(p[i]);
            int32_t b[4];
            bn.of(l * half + h * half, b);
            if (axis >= 0) {
                cnt[axis][b[axis]]++;
                lo[axis][b[axis]] = min4(lo[axis][b[axis]], l);
                hi[axis][b[axis]] = max4(hi[axis][b[axis]], h);
                continue;
            }
            for (int a = 0; a < 3; ++a) {
                cnt[a][b[a]]++;
                lo[a][b[a]] = min4(lo[a][b[a]], l);
                hi[a][b[a]] = max4(hi[a][b[a]], h);
            }
        }
    }
};

struct Builder {
    BuildPrim *prims;
    BVHNode *nodes;  // room for 2n - 1, written as they are made (see BVH::build)
    std::atomic<uint32_t> used{1};

    Builder(BuildPrim *p, BVHNode *n) : prims(p), nodes(n) {}

    void make_leaf(const Range &r) {
        nodes[r.node].first = r.begin;
        nodes[r.node].count = r.count();
    }

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

    // Splits r into two children (allocated here), or makes it a leaf: returns false then.
    bool split(const Range &r, Range &left, Range &right, int threads) {
        const uint32_t count = r.count();
        BVHNode &node = nodes[r.node];
        if (count <= 1) return make_leaf(r), false;
        AABB lbox, rbox;
        uint32_t mid = r.begin;
        bool have = false;
        F4 llo = F4::broadcast(kInfinity), lhi = F4::broadcast(-kInfinity), rlo = llo, rhi = lhi;
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
                const float parent_area = node.box.half_area();
                const float split_cost = kCostTraversal + kCostIntersect * best_cost / parent_area;
                const float leaf_cost = kCostIntersect * count;
                if (split_cost >= leaf_cost && count <= kMaxLeaf) return make_leaf(r), false;
                F4 alo = F4::broadcast(kInfinity), ahi = F4::broadcast(-kInfinity);
                F4 blo = alo, bhi = ahi;
                for (int b = 0; b < bins; ++b) {
                    if (b <= best_bin) alo = min4(alo, bs.lo[best_axis][b]), ahi = max4(ahi, bs.hi[best_axis][b]);
                    else blo = min4(blo, bs.lo[best_axis][b]), bhi = max4(bhi, bs.hi[best_axis][b]);
                }
                lbox = to_aabb(alo, ahi), rbox = to_aabb(blo, bhi);
                mid = partition(r, bn, best_axis, best_bin, llo, lhi, rlo, rhi, threads);
                have = true;
            }
        }
        if (!have) {  // all centroids coincide, or too deep for SAH
            if (count <= kMaxLeaf) return make_leaf(r), false;
            const AABB cb = to_aabb(r.clo, r.chi);
            const Vec3 e = cb.extent();
            const int axis = (e.x >= e.y && e.x >= e.z) ? 0 : (e.y >= e.z ? 1 : 2);
            mid = r.begin + count / 2;
            std::nth_element(prims + r.begin, prims + mid, prims + r.end,
                             [axis](const BuildPrim &a, const BuildPrim &b) {
                                 return a.lo[axis] * 0.5f + a.hi[axis] * 0.5f < b.lo[axis] * 0.5f + b.hi[axis] * 0.5f;
                             });
            F4 blo = F4::broadcast(kInfinity), bhi = F4::broadcast(-kInfinity), alo = blo, ahi = bhi;
            for (uint32_t i = r.begin; i < r.end; ++i) {
                const BuildPrim &p = prims[i];
                const F4 c = centroid_of(p);
                if (i < mid) alo = min4(alo, lo_of(p)), ahi = max4(ahi, hi_of(p)), llo = min4(llo, c), lhi = max4(lhi, c);
                else blo = min4(blo, lo_of(p)), bhi = max4(bhi, hi_of(p)), rlo = min4(rlo, c), rhi = max4(rhi, c);
            }
            lbox = to_aabb(alo, ahi), rbox = to_aabb(blo, bhi);
        }
        const uint32_t l = used.fetch_add(2);
        node.first = l;
        node.count = 0;
        nodes[l].box = lbox;
        nodes[l + 1].box = rbox;
        left = Range{l, r.begin, mid, llo, lhi, r.depth + 1};
        right = Range{l + 1, mid, r.end, rlo, rhi, r.depth + 1};
        return true;
    }

    // Records whose bin along `axis` is at most `best` first; both sides' centroid bounds
    // gathered on the way. Returns the partition point.
    uint32_t partition(uint32_t begin, uint32_t end, const Binner &bn, int axis, int best, F4 &llo, F4 &lhi, F4 &rlo,
                       F4 &rhi) {
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
        // their left parts there: as many of each.
        size_t a = 0, b = 0;
        uint32_t i = slice[0].mid, j = 0;
        auto next_wrong_right = [&]() -> bool {  // i: next right-goer before mid
            for (;;) {
                if (a == slice.size() || slice[a].mid >= mid) return false;
                if (i < std::min(slice[a].end, mid)) return true;
                if (++a < slice.size()) i = slice[a].mid;
            }
        };
        auto next_wrong_left = [&]() -> bool {  // j: next left-goer from mid on
            for (;;) {
                if (b == slice.size()) return false;
                const uint32_t lo = std::max(slice[b].begin, mid);
                if (j < lo) j = lo;
                if (j < slice[b].mid) return true;
                ++b;
            }
        };
        while (next_wrong_right() && next_wrong_left()) std::swap(prims[i++], prims[j++]);
        return mid;
    }

    void build_subtree(const Range &r) {
        Range left, right;
        if (!split(r, left, right, 1)) return;
        build_subtree(left);
        build_subtree(right);
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

// The binary tree as 4-wide nodes: each takes the children of a binary node and opens
// the largest (by surface area) of them that is not a leaf until it holds four. What a wide
// node holds depends only on its binary node's subtree, so subtrees can be collapsed apart.
struct Collapse {
    const BVHNode *bin;
    struct Todo {
        uint32_t b, w;  // binary node, index of the wide node made from it
    };

    // The (up to four) binary nodes that become binary node b's wide node's children.
    int kids_of(uint32_t b, uint32_t kids[4]) const {
        kids[0] = bin[b].first, kids[1] = bin[b].first + 1;
        // Area of each kid that can be opened (-1: a leaf), computed once.
        auto area_of = [&](uint32_t i) { return bin[i].leaf() ? -1.f : bin[i].box.half_area(); };
        float area[4] = {area_of(kids[0]), area_of(kids[1])};
        int n = 2;
        while (n < 4) {
            int open = -1;
            float largest = -1.f;
            for (int k = 0; k < n; ++k)
                if (area[k] > largest) open = k, largest = area[k];
            if (open < 0) break;
            const uint32_t first = bin[kids[open]].first;
            kids[open] = first, area[open] = area_of(first);
            kids[n] = first + 1, area[n] = area_of(first + 1), ++n;
        }
        return n;
    }

    // The wide node over `kids`; alloc() gives the index of each child wide node, which is
    // queued in `todo`.
    template <class Alloc>
    WideNode make(const uint32_t *kids, int n, Alloc &&alloc, std::vector<Todo> &todo) const {
        WideNode nd;
        for (int k = 0; k < 4; ++k) {
            if (k >= n) {
                for (int a = 0; a < 3; ++a) nd.box[2 * a][k] = kInfinity, nd.box[2 * a + 1][k] = -kInfinity;
                nd.child[k] = kNoChild, nd.count[k] = 0;
                continue;
            }
            const BVHNode &c = bin[kids[k]];
            for (int a = 0; a < 3; ++a) nd.box[2 * a][k] = c.box.lo[a], nd.box[2 * a + 1][k] = c.box.hi[a];
            if (c.leaf()) {
                nd.child[k] = c.first, nd.count[k] = c.count;
            } else {
                nd.child[k] = alloc(), nd.count[k] = 0;
                todo.push_back({kids[k], nd.child[k]});
            }
        }
        return nd;
    }

    // Everything below the entries of `todo`, depth first: store(index, node) for each.
    template <class Store, class Alloc>
    void drain(std::vector<Todo> &todo, Store &&store, Alloc &&alloc) const {
        uint32_t kids[4];
        while (!todo.empty()) {
            const Todo t = todo.back();
            todo.pop_back();
            store(t.w, make(kids, kids_of(t.b, kids), alloc, todo));
        }
    }

    // How many wide nodes lie below binary node b's own.
    size_t count_below(uint32_t b) const {
        std::vector<uint32_t> stack{b};
        size_t total = 0;
        uint32_t kids[4];
        while (!stack.empty()) {
            const uint32_t i = stack.back();
            stack.pop_back();
            for (int k = 0, n = kids_of(i, kids); k < n; ++k)
                if (!bin[kids[k]].leaf()) ++total, stack.push_back(kids[k]);
        }
        return total;
    }
};

// On one thread, depth first. On more: the top breadth first until there are subtrees
// enough for every thread; their sizes counted on the threads; then each written on a
// thread straight into its place in the final array. The same nodes either way.
void collapse(const BVHNode *bin, uint32_t used, Buffer<WideNode> &out, int threads) {
    const Collapse c{bin};
    std::vector<WideNode> top;
    std::vector<Collapse::Todo> todo;
    auto store_top = [&](uint32_t w, const WideNode &nd) { top[w] = nd; };
    auto alloc_top = [&] { return top.emplace_back(), uint32_t(top.size() - 1); };
    top.emplace_back();
    if (bin[0].leaf()) {
        const uint32_t root = 0;
        top[0] = c.make(&root, 1, alloc_top, todo);
    } else if (threads <= 1 || used < (1u << 16)) {
        top.reserve(used / 2 + 1);  // at most one per interior binary node: only the pages used are touched
        todo.push_back({0u, 0u});
        c.drain(todo, store_top, alloc_top);
    } else {
        todo.push_back({0u, 0u});
        size_t head = 0;
        uint32_t kids[4];
        while (head < todo.size() && todo.size() - head < size_t(16 * threads)) {
            const Collapse::Todo t = todo[head++];
            top[t.w] = c.make(kids, c.kids_of(t.b, kids), alloc_top, todo);
        }
        const std::vector<Collapse::Todo> roots(todo.begin() + head, todo.end());
        std::vector<size_t> offset(roots.size() + 1);
        parallel_for(roots.size(), threads, [&](size_t i) { offset[i + 1] = c.count_below(roots[i].b); },
                     [](size_t) { return true; });
        offset[0] = top.size();
        for (size_t i = 0; i < roots.size(); ++i) offset[i + 1] += offset[i];
        out.allocate(offset.back());
        std::copy(top.begin(), top.end(), out.begin());
        parallel_for(
            roots.size(), threads,
            [&](size_t i) {
                uint32_t next = uint32_t(offset[i]);
                std::vector<Collapse::Todo> st{roots[i]};
                c.drain(st, [&](uint32_t w, const WideNode &nd) { out[w] = nd; }, [&] { return next++; });
            },
            [](size_t) { return true; });
        return;
    }
    out.allocate(top.size());
    std::copy(top.begin(), top.end(), out.begin());
}

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
    // Room for the most nodes a tree of n leaves can have, left uninitialised: the pages
    // of the part never used (about half) are then never touched. The nodes used are
    // copied out at the end.
    Buffer<BVHNode> room(2 * size_t(n) - 1);
    F4 lo = F4::broadcast(kInfinity), hi = F4::broadcast(-kInfinity), clo = lo, chi = hi;
    for (uint32_t i = 0; i < n; ++i) {
        const BuildPrim &p = prims[i];
        const F4 c = centroid_of(p);
        lo = min4(lo, lo_of(p)), hi = max4(hi, hi_of(p)), clo = min4(clo, c), chi = max4(chi, c);
    }
    room.data()[0].box = to_aabb(lo, hi);
    Builder b(prims, room.data());
    const Range root{0, 0, n, clo, chi, 0};
    if (threads <= 1 || n <= kParallelThreshold) {
        b.build_subtree(root);
    } else {
        // Top phase: split the largest open range until none holds more than a share of
        // the primitives that keeps every thread busy to the end.
        const uint32_t share = std::max(kParallelThreshold, n / uint32_t(4 * threads));
        std::vector<Range> open{root}, ready;
        while (!open.empty()) {
            auto big = std::max_element(open.begin(), open.end(),
                                        [](const Range &x, const Range &y) { return x.count() < y.count(); });
            if (big->count() <= share) break;
            const Range r = *big;
            open.erase(big);
            Range left, right;
            if (b.split(r, left, right, threads)) open.push_back(left), open.push_back(right);
        }
        std::sort(open.begin(), open.end(), [](const Range &x, const Range &y) { return x.count() > y.count(); });
        parallel_for(open.size(), threads, [&](size_t i) { b.build_subtree(open[i]); }, [](size_t) { return true; });
    }
    collapse(room.data(), b.used.load(), nodes, threads);
}

int BVH::depth() const { return nodes.empty() ? 0 : depth_of(nodes); }

}  // namespace splat
