// Bounding volume hierarchy over primitive boxes: binned SAH build, 32-byte nodes.
//
// The tree only knows boxes; what a leaf holds is the caller's business (see
// splat_scene.h, which stores its splats in the order of `prim_order`).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <utility>
#include <vector>

#include "aabb.h"

namespace splat {

struct BVHNode {
    AABB box;
    uint32_t first;  // interior: index of the left child (right = first + 1); leaf: first primitive
    uint32_t count;  // 0 for an interior node, else the number of primitives in the leaf

    bool leaf() const { return count != 0; }
};
static_assert(sizeof(BVHNode) == 32, "nodes are meant to be two per cache line");

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
    std::vector<BVHNode> nodes;       // nodes[0] is the root
    std::vector<uint32_t> prim_order; // leaf ranges index this; it maps to the input order

    // Builds over `bounds` (one box per primitive, all non-empty) on `threads` threads (0:
    // all cores): the top levels split one at a time with the binning shared by every
    // thread, then the subtrees, largest first, each on one thread.
    void build(const std::vector<AABB> &bounds, int threads);
    // The same from build records (consumed: freed before returning).
    void build(std::vector<BuildPrim> &&prims, int threads);

    // Bytes the tree keeps (nodes and leaf order).
    size_t memory_bytes() const { return nodes.capacity() * sizeof(BVHNode) + prim_order.capacity() * 4; }

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

// Front-to-back traversal shared by every query of every tree: `leaf(first, count)` is called
// for each leaf the ray enters within (tmin, min(tmax, limit)), nearer child first; it returns
// true to stop at once (occlusion queries). The leaf may lower `limit` as it learns (nearest
// hit so far, the layer query's cut); boxes entered beyond it are skipped. The comparison is
// inclusive so that equal-t hits with a smaller id are still found.
template <class Leaf>
void traverse_bvh(const BVH &bvh, const Ray &ray, const float &limit, Leaf &&leaf, uint64_t *node_count) {
    if (bvh.nodes.empty()) return;
    const Vec3 inv_d(1.f / ray.d.x, 1.f / ray.d.y, 1.f / ray.d.z);
    const BVHNode *nodes = bvh.nodes.data();
    struct Pending {
        uint32_t node;
        float entry;
    } stack[kStackSize];
    int sp = 0;
    uint32_t node = 0;
    uint64_t visited = 0;
    struct Flush {  // adds the count on every way out
        uint64_t *out;
        const uint64_t &n;
        ~Flush() {
            if (out) *out += n;
        }
    } flush{node_count, visited};
    if (intersect_box(nodes[0].box, ray.o, inv_d, ray.tmin, std::fmin(ray.tmax, limit)) == kInfinity) return;
    for (;;) {
        const BVHNode &nd = nodes[node];
        ++visited;
        if (nd.leaf()) {
            if (leaf(nd.first, nd.count)) return;
        } else {
            // The nearer child is visited first, the other one pushed with its entry.
            const float tmax = std::fmin(ray.tmax, limit);
            uint32_t a = nd.first, b = nd.first + 1;
            float ta = intersect_box(nodes[a].box, ray.o, inv_d, ray.tmin, tmax);
            float tb = intersect_box(nodes[b].box, ray.o, inv_d, ray.tmin, tmax);
            if (ta > tb) std::swap(ta, tb), std::swap(a, b);
            if (ta != kInfinity) {
                if (tb != kInfinity) stack[sp++] = {b, tb};
                node = a;
                continue;
            }
        }
        // Pop, skipping nodes that the limit has since moved in front of.
        for (;;) {
            if (sp == 0) return;
            --sp;
            if (stack[sp].entry <= limit) {
                node = stack[sp].node;
                break;
            }
        }
    }
}

}  // namespace splat
