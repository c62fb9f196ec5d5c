// Bounding volume hierarchy over primitive boxes: 4-wide nodes, built by binned SAH splits
// (each wide node opens binary splits until it has four children), whose four child boxes
// are tested at once (SSE where the target has SSE2, the same arithmetic in plain floats
// elsewhere).
//
// The tree only knows boxes; what a leaf holds is the caller's business (see
// splat_scene.h, which stores its splats in the order of `prim_order`).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <utility>
#include <vector>

#include "base/aabb.h"
#include "base/buffer.h"
#include "base/simd.h"

namespace splat {

// Four children: their boxes by axis (lo x of each, then hi x, ...), and per child either
// a node (count 0: `child` indexes the nodes) or a leaf (`count` primitives from `child`).
// Unused slots have count 0 and child kNoChild.
struct alignas(16) WideNode {
    float box[6][4];  // lo x, hi x, lo y, hi y, lo z, hi z; one lane per child
    uint32_t child[4];
    uint32_t count[4];
};
static_assert(sizeof(WideNode) == 128, "a wide node is two cache lines");
constexpr uint32_t kNoChild = 0xffffffffu;

// A primitive while the tree is built: its box, with the id in the spare lane (32 bytes,
// two SSE loads). The records themselves are partitioned (not an index array into the
// boxes), so that every pass over a node's range reads memory in order.
struct alignas(16) BuildPrim {
    float lo[4];  // lo.xyz, 0
    float hi[3];
    uint32_t id;

    BuildPrim() = default;
    BuildPrim(const AABB &b, uint32_t i) : lo{b.lo.x, b.lo.y, b.lo.z, 0.f}, hi{b.hi.x, b.hi.y, b.hi.z}, id(i) {}
};
static_assert(sizeof(BuildPrim) == 32, "two build records per cache line");

struct BVH {
    Buffer<WideNode> nodes;           // nodes[0] is the root (always entered: it has the
                                      // root's box as its only child, or the root's children)
    std::vector<uint32_t> prim_order; // leaf ranges index this; it maps to the input order

    // Builds over `bounds` (one box per primitive, all non-empty) on `threads` threads (0:
    // all cores): the top wide nodes made one at a time with the binning and partitioning
    // shared by every thread, then the subtrees, largest first, each on one thread.
    void build(const std::vector<AABB> &bounds, int threads);
    // The same from `count` build records, which it leaves in leaf order (their ids are
    // then what prim_order would be; prim_order is left empty).
    void build(BuildPrim *prims, size_t count, int threads);

    // Bytes the tree keeps (nodes and leaf order).
    size_t memory_bytes() const { return nodes.bytes() + prim_order.capacity() * 4; }

    // Deepest path from the root: bounds the traversal stack.
    int depth() const;
};

// Traversal stack size. The builder stops using SAH splits below depth kSahMaxDepth and
// falls back to median splits, which halve the count, so no tree is deeper than
// kSahMaxDepth + 32 for up to 2^32 primitives.
constexpr int kSahMaxDepth = 64;
constexpr int kStackSize = kSahMaxDepth + 40;

}  // namespace splat

namespace splat {

// Work done by queries, summed by the caller: what the tests and benchmarks compare instead
// of timings (every view direction must cost about the same; a scene without lamps traces
// no shadow rays; ...).
struct TraversalStats {
    uint64_t nodes = 0;           // BVH nodes entered (both levels)
    uint64_t discs = 0;           // ray/disc tests
    uint64_t triangles = 0;       // ray/triangle tests
    uint64_t layer_queries = 0;   // epsilon-window gathers (general-method rays need none)
    uint64_t far_rejections = 0;  // layers the far phase rejected (fringes, grazed edges)
    uint64_t interpolations = 0;  // surface points whose normal blended more than one splat

    void add(const TraversalStats &o) {
        nodes += o.nodes, discs += o.discs, triangles += o.triangles, layer_queries += o.layer_queries;
        far_rejections += o.far_rejections, interpolations += o.interpolations;
    }
};

// The slab test of intersect_box() (aabb.h) on a wide node's four boxes at once, with
// the same arithmetic lane by lane: the same entry distances, the same misses. Returns a
// mask of the children entered within (tmin, tmax) and their entry distances.
struct WideRay {
    F4 o[3], inv_d[3];
    explicit WideRay(const Ray &ray) {
        for (int k = 0; k < 3; ++k) o[k] = F4::broadcast(ray.o[k]), inv_d[k] = F4::broadcast(1.f / ray.d[k]);
    }
};

// One axis of intersect_box()'s slab test, four lanes at a time: the slab [lo, hi] against
// origin o and inverse direction inv narrows (t0, t1). Shared by the wide node's test (lanes
// are children) and a packet's (lanes are rays), so both are the same arithmetic.
inline void slab_axis(F4 lo, F4 hi, F4 o, F4 inv, F4 &t0, F4 &t1) {
    const F4 zero = F4::broadcast(0.f);
    const F4 shrink = F4::broadcast(1.f - kSlabWiden), grow = F4::broadcast(1.f + kSlabWiden);
    const F4 a = (lo - o) * inv, b = (hi - o) * inv;
    // tn = min(a, b), tf = max(a, b) as the scalar swap makes them (a NaN stays where it
    // was: in tn when a is NaN, ...), then widened by scaling.
    F4 tn = select_gt(a, b, b, a), tf = select_gt(a, b, a, b);
    tn = tn * select_gt(tn, zero, shrink, grow);
    tf = tf * select_gt(tf, zero, grow, shrink);
    // t0 = tn > t0 ? tn : t0: a NaN distance leaves t0 and t1 as they were.
    t0 = select_gt(tn, t0, tn, t0);
    t1 = select_lt(tf, t1, tf, t1);
}

inline int intersect_wide(const WideNode &nd, const WideRay &r, float tmin, float tmax, float entry[4]) {
    F4 t0 = F4::broadcast(tmin), t1 = F4::broadcast(tmax);
    for (int k = 0; k < 3; ++k) slab_axis(F4::load(nd.box[2 * k]), F4::load(nd.box[2 * k + 1]), r.o[k], r.inv_d[k], t0, t1);
    t0.store(entry);
    return mask_le(t0, t1);
}

// The entered children of a wide node (`mask`; make(k) gives child k's stack entry, with
// its `entry` distance) sorted by entry, at most four by insertion: the nearest becomes
// `cur`, the others are pushed farthest first. Shared by the single-ray and packet traversals.
template <class Pending, class Make>
inline void descend(int mask, Make &&make, Pending &cur, Pending *stack, int &sp) {
    Pending hit[4];
    int n = 0;
    for (int k = 0; k < 4; ++k) {
        if (!(mask >> k & 1)) continue;
        const Pending p = make(k);
        int j = n++;
        while (j > 0 && hit[j - 1].entry > p.entry) hit[j] = hit[j - 1], --j;
        hit[j] = p;
    }
    for (int j = n - 1; j > 0; --j) stack[sp++] = hit[j];
    cur = hit[0];
}

// Front-to-back traversal shared by every query of every tree: `leaf(first, count)` is called
// for each leaf the ray enters within (tmin, min(tmax, limit)), nearer child first; it returns
// true to stop at once (occlusion queries). The leaf may lower `limit` as it learns (nearest
// hit so far, the layer query's cut); boxes entered beyond it are skipped. The comparison is
// inclusive so that equal-t hits with a smaller id are still found. `node_count` counts the
// wide nodes and the leaves entered.
template <class Leaf>
void traverse_bvh(const BVH &bvh, const Ray &ray, const float &limit, Leaf &&leaf, uint64_t *node_count) {
    if (bvh.nodes.empty()) return;
    const WideRay wr(ray);
    const WideNode *nodes = bvh.nodes.data();
    struct Pending {
        uint32_t child, count;  // as in WideNode
        float entry;
    } stack[3 * kStackSize];
    int sp = 0;
    uint64_t visited = 0;
    struct Flush {  // adds the count on every way out
        uint64_t *out;
        const uint64_t &n;
        ~Flush() {
            if (out) *out += n;
        }
    } flush{node_count, visited};
    Pending cur{0, 0, 0.f};
    for (;;) {
        ++visited;
        if (cur.count) {
            if (leaf(cur.child, cur.count)) return;
        } else {
            const WideNode &nd = nodes[cur.child];
            float t[4];
            int mask = intersect_wide(nd, wr, ray.tmin, std::fmin(ray.tmax, limit), t);
            for (int k = 0; k < 4; ++k)
                if (nd.child[k] == kNoChild) mask &= ~(1 << k);
            if (mask) {
                descend(mask, [&](int k) { return Pending{nd.child[k], nd.count[k], t[k]}; }, cur, stack, sp);
                continue;
            }
        }
        // Pop, skipping nodes that the limit has since moved in front of.
        for (;;) {
            if (sp == 0) return;
            --sp;
            if (stack[sp].entry <= limit) {
                cur = stack[sp];
                break;
            }
        }
    }
}

}  // namespace splat
