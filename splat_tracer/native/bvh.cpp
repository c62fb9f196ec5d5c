// Binned SAH BVH construction (Wald 2007, "On fast construction of SAH-based bounding
// volume hierarchies"), written in the spirit of tinybvh: one flat node array, 16 bins
// per axis, leaves when splitting no longer pays.
#include "bvh.h"

#include <algorithm>
#include <atomic>
#include <thread>

namespace splat {
namespace {

constexpr int kBins = 16;
// SAH cost model: a disc test costs about as much as a box test; the traversal step
// (stack, two box tests) is charged once per interior node.
constexpr float kCostTraversal = 1.0f;
constexpr float kCostIntersect = 1.0f;
constexpr uint32_t kMaxLeaf = 8;  // leaves never hold more, even when SAH would like it
// A subtree with more primitives than this is worth a thread of its own.
constexpr uint32_t kParallelThreshold = 1u << 15;

struct Builder {
    const std::vector<AABB> &bounds;
    std::vector<Vec3> centroid;
    std::vector<uint32_t> &order;
    std::vector<BVHNode> &nodes;
    std::atomic<uint32_t> used{1};

    Builder(const std::vector<AABB> &b, std::vector<uint32_t> &o, std::vector<BVHNode> &n)
        : bounds(b), order(o), nodes(n) {
        centroid.resize(b.size());
        for (size_t i = 0; i < b.size(); ++i) centroid[i] = b[i].centre();
    }

    void make_leaf(BVHNode &node, uint32_t begin, uint32_t end) {
        node.first = begin;
        node.count = end - begin;
    }

    // Splits [begin, end) at the median along the widest centroid axis.
    uint32_t median_split(uint32_t begin, uint32_t end, int axis) {
        uint32_t mid = begin + (end - begin) / 2;
        std::nth_element(order.begin() + begin, order.begin() + mid, order.begin() + end,
                         [&](uint32_t a, uint32_t b) { return centroid[a][axis] < centroid[b][axis]; });
        return mid;
    }

    // Returns the partition point of the best SAH split, or `begin` when a leaf is cheaper.
    uint32_t sah_split(const BVHNode &node, uint32_t begin, uint32_t end, const AABB &cbox) {
        const uint32_t count = end - begin;
        float best_cost = kInfinity;
        int best_axis = -1, best_bin = 0;
        for (int axis = 0; axis < 3; ++axis) {
            const float lo = cbox.lo[axis], ext = cbox.hi[axis] - lo;
            if (!(ext > 0.f)) continue;
            const float scale = kBins / ext;
            AABB box[kBins];
            uint32_t cnt[kBins] = {};
            for (uint32_t i = begin; i < end; ++i) {
                const uint32_t p = order[i];
                int b = std::min(kBins - 1, int((centroid[p][axis] - lo) * scale));
                cnt[b]++;
                box[b].grow(bounds[p]);
            }
            // Sweep from the right, then from the left, evaluating the kBins-1 planes.
            float right_area[kBins - 1];
            uint32_t right_count[kBins - 1];
            AABB acc;
            uint32_t n = 0;
            for (int b = kBins - 1; b > 0; --b) {
                acc.grow(box[b]);
                n += cnt[b];
                right_area[b - 1] = acc.half_area();
                right_count[b - 1] = n;
            }
            acc = AABB();
            n = 0;
            for (int b = 0; b < kBins - 1; ++b) {
                acc.grow(box[b]);
                n += cnt[b];
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
        const float lo = cbox.lo[best_axis];
        const float scale = kBins / (cbox.hi[best_axis] - lo);
        auto mid = std::partition(order.begin() + begin, order.begin() + end, [&](uint32_t p) {
            return std::min(kBins - 1, int((centroid[p][best_axis] - lo) * scale)) <= best_bin;
        });
        return uint32_t(mid - order.begin());
    }

    void build(uint32_t node_index, uint32_t begin, uint32_t end, int depth, int spare_threads) {
        BVHNode &node = nodes[node_index];
        AABB cbox;
        node.box = AABB();
        for (uint32_t i = begin; i < end; ++i) {
            node.box.grow(bounds[order[i]]);
            cbox.grow(centroid[order[i]]);
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
            std::thread t([&, left, begin, mid, depth, give] { build(left, begin, mid, depth + 1, give); });
            build(left + 1, mid, end, depth + 1, spare_threads - 1 - give);
            t.join();
        } else {
            build(left, begin, mid, depth + 1, 0);
            build(left + 1, mid, end, depth + 1, 0);
        }
    }
};

int depth_of(const std::vector<BVHNode> &nodes, uint32_t i) {
    if (nodes[i].leaf()) return 1;
    return 1 + std::max(depth_of(nodes, nodes[i].first), depth_of(nodes, nodes[i].first + 1));
}

}  // namespace

void BVH::build(const std::vector<AABB> &bounds, int threads) {
    const uint32_t n = uint32_t(bounds.size());
    prim_order.resize(n);
    for (uint32_t i = 0; i < n; ++i) prim_order[i] = i;
    nodes.assign(n > 0 ? 2 * size_t(n) - 1 : 1, BVHNode{AABB(), 0, 0});
    if (n == 0) return;
    Builder b(bounds, prim_order, nodes);
    b.build(0, 0, n, 0, std::max(0, threads - 1));
    nodes.resize(b.used.load());
}

int BVH::depth() const { return nodes.empty() ? 0 : depth_of(nodes, 0); }

}  // namespace splat
