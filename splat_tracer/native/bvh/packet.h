// Ray packets: up to 16 coherent rays (the camera rays of a 4x4 pixel tile) traced through
// the BVH together. Inner nodes are tested once for the whole packet, against the bounds of
// its origins and inverse directions (interval arithmetic: Reshetov, Soupikov & Hurley 2005,
// "Multi-level ray tracing algorithm"; Wald et al. 2006's frustum tests for the same role);
// a node holding leaves is then tested ray by ray with the single-ray slab test, and each
// leaf is visited only by the rays that enter its box -- so every ray meets exactly the
// discs it would meet alone, and the queries built on this one give the single-ray answers.
//
// Why the packet test never drops a box a ray of the packet enters: along an axis whose
// inverse directions share a sign and are finite, each ray's entry distance fl(fl(near - o)
// x inv) is monotonic in o and in inv under round-to-nearest, so the smallest of its four
// values at the corners of [o_lo, o_hi] x [inv_lo, inv_hi] is a lower bound for every ray's
// computed entry (the largest one an upper bound for every exit), and the same widening
// keeps the order. An axis every ray runs parallel to (d = 0: inv = +-inf) bounds the
// boxes by the rays' range of origins on it (a ray there never leaves its coordinate); an
// axis where only some rays run parallel, or the signs differ, is not tested (only looser).
#pragma once

#include <cstdint>

#include "base/config.h"
#include "bvh/bvh.h"
#include "splats/disc.h"

namespace splat {

// Whether rays are coherent enough for a packet to pay: directions within a narrow cone
// and origins close together (relative to `scene_size`, the diagonal of the scene's
// bounds). A 4x4 tile of camera rays is well inside both, even at 160x120; scattered rays
// would make the packet's bounds cover much of the scene, and are traced one by one.
bool packet_coherent(const PacketRays &rays, int n, float scene_size);

// The bounds of a packet's rays, broadcast for the four lanes of a wide node.
struct PacketBounds {
    F4 o_lo[3], o_hi[3], inv_lo[3], inv_hi[3];
    int near_side[3];  // 0: the boxes' lo planes are entered first (inverse directions > 0)
    enum Axis { kUntested, kSlabs, kParallel };
    Axis axis[3];      // kSlabs: finite inverse directions of one sign; kParallel: all d = 0
    float tmin;        // the smallest of the rays' tmin
    PacketBounds(const PacketRays &rays, int n);  // of lanes 0..n-1
};

// The conservative slab test of the four children of `nd` against the packet (see the
// header comment): a mask of the children some ray may enter within (tmin, tmax), and a
// lower bound of every ray's entry distance into each.
inline int intersect_wide_packet(const WideNode &nd, const PacketBounds &p, float tmax, float entry[4]) {
    const F4 shrink = F4::broadcast(1.f - kSlabWiden), grow = F4::broadcast(1.f + kSlabWiden);
    const F4 zero = F4::broadcast(0.f);
    F4 t0 = F4::broadcast(p.tmin), t1 = F4::broadcast(tmax);
    for (int k = 0; k < 3; ++k) {
        if (p.axis[k] == PacketBounds::kParallel) {  // boxes beside every ray's coordinate
            const F4 lo = F4::load(nd.box[2 * k]), hi = F4::load(nd.box[2 * k + 1]), inf = F4::broadcast(kInfinity);
            t0 = select_gt(lo, p.o_hi[k], inf, select_lt(hi, p.o_lo[k], inf, t0));
            t1 = select_gt(lo, p.o_hi[k], zero - inf, select_lt(hi, p.o_lo[k], zero - inf, t1));
            continue;
        }
        if (p.axis[k] != PacketBounds::kSlabs) continue;
        const F4 near = F4::load(nd.box[2 * k + p.near_side[k]]), far = F4::load(nd.box[2 * k + 1 - p.near_side[k]]);
        const F4 a = near - p.o_lo[k], b = near - p.o_hi[k];
        F4 tn = min4(min4(a * p.inv_lo[k], a * p.inv_hi[k]), min4(b * p.inv_lo[k], b * p.inv_hi[k]));
        const F4 c = far - p.o_lo[k], e = far - p.o_hi[k];
        F4 tf = max4(max4(c * p.inv_lo[k], c * p.inv_hi[k]), max4(e * p.inv_lo[k], e * p.inv_hi[k]));
        tn = tn * select_gt(tn, zero, shrink, grow);
        tf = tf * select_gt(tf, zero, grow, shrink);
        t0 = max4(t0, tn);
        t1 = min4(t1, tf);
    }
    t0.store(entry);
    return mask_le(t0, t1);
}

// intersect_wide() of every ray of `rays` (a mask of soa's lanes) with the children of
// `children` (a mask of nd's): child_rays[k] = the rays entering child k within (tmin,
// limit). Child by child, four rays at a time, with the same arithmetic lane by lane as
// intersect_wide(): the same entries, the same misses.
inline void enter_children(const WideNode &nd, const PacketRays &soa, const float *limit, uint32_t rays,
                           int children, uint32_t child_rays[4]) {
    for (int k = 0; k < 4; ++k) {
        child_rays[k] = 0;
        if (!(children >> k & 1)) continue;
        for (int g = 0; g < kPacketRays; g += 4) {
            const int lanes = int(rays >> g & 15);
            if (!lanes) continue;
            F4 t0 = F4::load(soa.tmin + g), t1 = F4::load(limit + g);
            for (int a = 0; a < 3; ++a)
                slab_axis(F4::broadcast(nd.box[2 * a][k]), F4::broadcast(nd.box[2 * a + 1][k]), F4::load(soa.o[a] + g),
                          F4::load(soa.inv_d[a] + g), t0, t1);
            child_rays[k] |= uint32_t(mask_le(t0, t1) & lanes) << g;
        }
    }
}

#ifdef SPLAT_AVX2_KERNELS
// x > y ? a : b per lane (false for NaN: b), as select_gt.
__attribute__((target("avx2"))) inline __m256 sel_gt(__m256 x, __m256 y, __m256 a, __m256 b) {
    return _mm256_blendv_ps(b, a, _mm256_cmp_ps(x, y, _CMP_GT_OQ));
}

// enter_children() eight rays at a time (AVX2, chosen at run time): slab_axis() written out
// in AVX2 intrinsics (they only inline into functions carrying the target attribute).
__attribute__((target("avx2"))) inline void enter_children_avx2(const WideNode &nd, const PacketRays &soa,
                                                                 const float *limit, uint32_t rays, int children,
                                                                 uint32_t child_rays[4]) {
    const __m256 shrink = _mm256_set1_ps(1.f - kSlabWiden), grow = _mm256_set1_ps(1.f + kSlabWiden);
    const __m256 zero = _mm256_setzero_ps();
    for (int k = 0; k < 4; ++k) {
        child_rays[k] = 0;
        if (!(children >> k & 1)) continue;
        for (int g = 0; g < kPacketRays; g += 8) {
            const int lanes = int(rays >> g & 255);
            if (!lanes) continue;
            __m256 t0 = _mm256_load_ps(soa.tmin + g), t1 = _mm256_loadu_ps(limit + g);
            for (int a = 0; a < 3; ++a) {
                const __m256 o = _mm256_load_ps(soa.o[a] + g), inv = _mm256_load_ps(soa.inv_d[a] + g);
                const __m256 x = _mm256_mul_ps(_mm256_sub_ps(_mm256_set1_ps(nd.box[2 * a][k]), o), inv);
                const __m256 y = _mm256_mul_ps(_mm256_sub_ps(_mm256_set1_ps(nd.box[2 * a + 1][k]), o), inv);
                __m256 tn = sel_gt(x, y, y, x), tf = sel_gt(x, y, x, y);
                tn = _mm256_mul_ps(tn, sel_gt(tn, zero, shrink, grow));
                tf = _mm256_mul_ps(tf, sel_gt(tf, zero, grow, shrink));
                t0 = sel_gt(tn, t0, tn, t0);
                t1 = sel_gt(t1, tf, tf, t1);  // tf < t1 ? tf : t1
            }
            child_rays[k] |= uint32_t(_mm256_movemask_ps(_mm256_cmp_ps(t0, t1, _CMP_LE_OQ)) & lanes) << g;
        }
    }
}
#endif

// traverse_bvh() for a packet of n <= kPacketRays rays (`soa`, by component): `leaf(rays,
// first, count, limit)` is called for each leaf with the mask of the rays that enter it,
// ray i within (tmin, limit[i]), where limit[i] starts at the ray's tmax and the leaf may
// lower it as it learns (nearest hit so far, the layer query's cut).
// Leaves are met nearer first by the packet's bounds, not by each ray's own order, so the
// queries on top must not depend on the order of their hits (the nearest hit and the layer
// query do not). `node_count` counts the inner nodes the packet entered (once for all its
// rays) and the leaves each ray entered.
template <class Leaf>
void traverse_packet(const BVH &bvh, const PacketRays &soa, int n, Leaf &&leaf, uint64_t *node_count) {
    if (bvh.nodes.empty() || n <= 0) return;
    const PacketBounds bounds(soa, n);
#ifdef SPLAT_AVX2_KERNELS
    const bool avx2 = simd_avx2();
#endif
    alignas(16) float limit[kPacketRays];  // lanes past n: -inf, never entered
    for (int i = 0; i < kPacketRays; ++i) limit[i] = soa.tmax[i];  // -inf in unused lanes
    // The farthest any of `mask`'s rays may still need: the pruning bound of a node they share.
    auto reach = [&](uint32_t mask) {
        F4 r = F4::broadcast(-kInfinity);
        for (int j = 0; j < n; j += 4)
            r = max4(r, select_bits(int(mask >> j & 15), F4::load(limit + j), F4::broadcast(-kInfinity)));
        return hmax4(r);
    };
    const WideNode *nodes = bvh.nodes.data();
    struct Pending {
        uint32_t child, count;  // as in WideNode
        float entry;            // lower bound of the rays' entries
        uint32_t rays;          // the rays that may enter it
    } stack[3 * kStackSize];
    int sp = 0;
    uint64_t visited = 0;
    Pending cur{0, 0, 0.f, n >= 32 ? ~0u : (1u << n) - 1u};
    for (;;) {
        if (cur.count) {
            // The rays whose limit has not moved in front of the leaf since it was pushed.
            uint32_t live = 0;
            for (int j = 0; j < n; j += 4)
                live |= uint32_t(mask_le(F4::broadcast(cur.entry), F4::load(limit + j))) << j;
            live &= cur.rays;
            if (live) {
                visited += uint64_t(__builtin_popcount(live));
                leaf(live, cur.child, cur.count, limit);
            }
        } else {
            ++visited;
            const WideNode &nd = nodes[cur.child];
            float t[4];
            int mask = intersect_wide_packet(nd, bounds, reach(cur.rays), t);
            uint32_t child_rays[4] = {cur.rays, cur.rays, cur.rays, cur.rays};
            int leaves = 0;
            for (int k = 0; k < 4; ++k) {
                if (nd.child[k] == kNoChild) mask &= ~(1 << k);
                leaves |= (nd.count[k] != 0) << k;
            }
            if (mask & leaves) {
                // Leaves among the children: each ray's own slab test decides which it
                // enters (and narrows the inner children's rays on the way).
#ifdef SPLAT_AVX2_KERNELS
                if (avx2) enter_children_avx2(nd, soa, limit, cur.rays, mask, child_rays);
                else
#endif
                    enter_children(nd, soa, limit, cur.rays, mask, child_rays);
                for (int k = 0; k < 4; ++k)
                    if (!child_rays[k]) mask &= ~(1 << k);
            }
            if (mask) {
                descend(mask, [&](int k) { return Pending{nd.child[k], nd.count[k], t[k], child_rays[k]}; }, cur,
                        stack, sp);
                continue;
            }
        }
        for (;;) {
            if (sp == 0) {
                if (node_count) *node_count += visited;
                return;
            }
            --sp;
            if (stack[sp].entry <= reach(stack[sp].rays)) {
                cur = stack[sp];
                break;
            }
        }
    }
}

}  // namespace splat
