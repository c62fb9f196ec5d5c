// Binned SAH BVH construction (Wald 2007, "On fast construction of SAH-based bounding
// volume hierarchies"), written in the spirit of tinybvh: one flat node array, 16 bins
// per axis, leaves when splitting no longer pays.
#include "bvh.h"

#include <algorithm>
#include <atomic>
#include <system_error>
#include <thread>
#include <utility>

#include "parallel.h"

namespace splat {
namespace {

constexpr int kBins = 16;  // at most; a node of n primitives uses min(kBins, n + 4) bins
// SAH cost model: a disc test costs about as much as a box test; the traversal step
// (stack, two box tests) is charged once per interior node.
constexpr float kCostTraversal = 1.0f;
constexpr float kCostIntersect = 1.0f;
constexpr uint32_t kMaxLeaf = 8;  // leaves never hold more, even when SAH would like it
// A subtree with more primitives than this is worth a thread of its own.
constexpr uint32_t kParallelThreshold = 1u << 15;

// A primitive during the build. The records themselves are partitioned (not an index
// array into the boxes), so that every pass over a node's range reads memory in order:
// with an indirection, each level of a 1M-primitive build was a million cache misses.
struct BuildPrim {
    AABB box;
    Vec3 centroid;
    uint32_t id;
};

struct Builder {
    std::vector<BuildPrim> prims;
    std::vector<BVHNode> &nodes;
    std::atomic<uint32_t> used{1};

    Builder(const std::vector<AABB> &bounds, std::vector<BVHNode> &n) : nodes(n) {
        prims.resize(bounds.size());
        for (size_t i = 0; i < bounds.size(); ++i) prims[i] = {bounds[i], bounds[i].centre(), uint32_t(i)};
    }

    void make_leaf(BVHNode &node, uint32_t begin, uint32_t end) {
        node.first = begin;
        node.count = end - begin;
    }

    // Splits [begin, end) at the median along the widest centroid axis.
    uint32_t median_split(uint32_t begin, uint32_t end, int axis) {
        uint32_t mid = begin + (end - begin) / 2;
        std::nth_element(prims.begin() + begin, prims.begin() + mid, prims.begin() + end,
                         [axis](const BuildPrim &a, const BuildPrim &b) { return a.centroid[axis] < b.centroid[axis]; });
        return mid;
    }

    // Returns the partition point of the best SAH split, or `begin` when a leaf is cheaper.
    // One pass over the primitives fills the bins of all three axes.
    uint32_t sah_split(const BVHNode &node, uint32_t begin, uint32_t end, const AABB &cbox) {
        const uint32_t count = end - begin;
        // Small nodes get fewer bins: sweeping 16 mostly empty bins per axis cost more
        // than the binning itself in the lower levels of the tree.
        const int bins = int(std::min<uint32_t>(kBins, count + 4));
        AABB box[3][kBins];
        uint32_t cnt[3][kBins] = {};
        float scale[3];
        for (int a = 0; a < 3; ++a) {
            const float ext = cbox.hi[a] - cbox.lo[a];
            scale[a] = ext > 0.f ? bins / ext : 0.f;
        }
        for (uint32_t i = begin; i < end; ++i) {
            const BuildPrim &p = prims[i];
            for (int a = 0; a < 3; ++a) {
                const int b = bin_of(p.centroid[a], cbox.lo[a], scale[a], bins);
                cnt[a][b]++;
                box[a][b].grow(p.box);
            }
        }
        float best_cost = kInfinity;
        int best_axis = -1, best_bin = 0;
        for (int axis = 0; axis < 3; ++axis) {
            if (scale[axis] == 0.f) continue;
            // Sweep from the right, then from the left, evaluating the kBins-1 planes.
            float right_area[kBins - 1];
            uint32_t right_count[kBins - 1];
            AABB acc;
            uint32_t n = 0;
            for (int b = bins - 1; b > 0; --b) {
                acc.grow(box[axis][b]);
                n += cnt[axis][b];
                right_area[b - 1] = acc.half_area();
                right_count[b - 1] = n;
            }
            acc = AABB();
            n = 0;
            for (int b = 0; b < bins - 1; ++b) {
                acc.grow(box[axis][b]);
                n += cnt[axis][b];
                if (n == 0 || right_count[b] == 0) continue;
                const float cost = n * acc.half_area() + right_count[b] * right_area[b];
                if (cost < best_cost) best_cost = cost, best_axis = axis, best_bin = b;
            }
        }
        if (best_axis < 0) return begin;  // all centroids coincide
        const float parent_area = node.box.half_area();
        const float split_cost = kCostTraversal + kCostIntersect * best_cost / parent_area;
        const float leaf_cost = kCostIntersect * count;
        if (split_cost >= leaf_cost && count <= kMaxLeaf) return begin;
        const float lo = cbox.lo[best_axis], sc = scale[best_axis];
        auto mid = std::partition(prims.begin() + begin, prims.begin() + end, [&](const BuildPrim &p) {
            return bin_of(p.centroid[best_axis], lo, sc, bins) <= best_bin;
        });
        return uint32_t(mid - prims.begin());
    }

    // Clamped on both sides, and computed before the int conversion: a float outside
    // int's range (or NaN) converted to int is undefined behaviour.
    static int bin_of(float x, float lo, float scale, int bins) {
        const float b = (x - lo) * scale;
        return b > 0.f ? (b < float(bins - 1) ? int(b) : bins - 1) : 0;
    }

    void build(uint32_t node_index, uint32_t begin, uint32_t end, int depth, int spare_threads) {
        BVHNode &node = nodes[node_index];
        AABB cbox;
        node.box = AABB();
        for (uint32_t i = begin; i < end; ++i) {
            node.box.grow(prims[i].box);
            cbox.grow(prims[i].centroid);
        }
        const uint32_t count = end - begin;
        if (count <= 1) return make_leaf(node, begin, end);

        uint32_t mid = depth < kSahMaxDepth ? sah_split(node, begin, end, cbox) : begin;
        if (mid == begin || mid == end) {
            if (count <= kMaxLeaf) return make_leaf(node, begin, end);
            Vec3 e = cbox.extent();
            int axis = (e.x >= e.y && e.x >= e.z) ? 0 : (e.y >= e.z ? 1 : 2);
            mid = median_split(begin, end, axis);
        }

        const uint32_t left = used.fetch_add(2);
        node.first = left;
        node.count = 0;
        if (spare_threads > 0 && count > kParallelThreshold) {
            const int give = spare_threads / 2;
            std::thread t;
            try {
                t = start_thread([&, left, begin, mid, depth, give] { build(left, begin, mid, depth + 1, give); });
            } catch (const std::system_error &) {
                // The system refused a thread: build this subtree here, and the rest with
                // no more threads.
                build(left, begin, mid, depth + 1, 0);
                build(left + 1, mid, end, depth + 1, 0);
                return;
            }
            build(left + 1, mid, end, depth + 1, spare_threads - 1 - give);
            t.join();
        } else {
            build(left, begin, mid, depth + 1, 0);
            build(left + 1, mid, end, depth + 1, 0);
        }
    }
};

// Iterative (an explicit stack): a recursion would follow whatever `first` says.
int depth_of(const std::vector<BVHNode> &nodes) {
    int deepest = 0;
    std::vector<std::pair<uint32_t, int>> stack{{0u, 1}};
    while (!stack.empty()) {
        const auto [i, d] = stack.back();
        stack.pop_back();
        deepest = std::max(deepest, d);
        if (!nodes[i].leaf()) stack.push_back({nodes[i].first, d + 1}), stack.push_back({nodes[i].first + 1, d + 1});
    }
    return deepest;
}

}  // namespace

void BVH::build(const std::vector<AABB> &bounds, int threads) {
    const uint32_t n = uint32_t(bounds.size());
    nodes.clear();
    prim_order.resize(n);
    if (n == 0) return;  // no nodes at all: traversals check for that
    nodes.assign(2 * size_t(n) - 1, BVHNode{AABB(), 0, 0});
    Builder b(bounds, nodes);
    b.build(0, 0, n, 0, std::max(0, threads - 1));
    nodes.resize(b.used.load());
    for (uint32_t i = 0; i < n; ++i) prim_order[i] = b.prims[i].id;
}

int BVH::depth() const { return nodes.empty() ? 0 : depth_of(nodes); }

}  // namespace splat
