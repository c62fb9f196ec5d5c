// Bounding volume hierarchy over primitive boxes: binned SAH build, 32-byte nodes.
//
// The tree only knows boxes; what a leaf holds is the caller's business (see
// splat_scene.h, which stores its splats in the order of `prim_order`).
#pragma once

#include <cstdint>
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

struct BVH {
    std::vector<BVHNode> nodes;       // nodes[0] is the root
    std::vector<uint32_t> prim_order; // leaf ranges index this; it maps to the input order

    // Builds over `bounds` (one box per primitive, all non-empty). Subtrees above a size
    // threshold are built on their own threads, up to `threads` at once.
    void build(const std::vector<AABB> &bounds, int threads);

    // Deepest path from the root: bounds the traversal stack.
    int depth() const;
};

// Traversal stack size. The builder stops using SAH splits below depth kSahMaxDepth and
// falls back to median splits, which halve the count, so no tree is deeper than
// kSahMaxDepth + 32 for up to 2^32 primitives.
constexpr int kSahMaxDepth = 64;
constexpr int kStackSize = kSahMaxDepth + 40;

}  // namespace splat
