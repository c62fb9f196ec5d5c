// Ray / splat (oriented disc) intersection, as written in docs/ALGORITHM.md:
//   t = ((c - o) . n) / (d . n),  hit when |o + t d - c|^2 <= r^2.
#pragma once

#include <cmath>

#include "base/config.h"
#include "base/ray.h"
#include "base/simd.h"

#ifdef SPLAT_AVX2_KERNELS
#include <immintrin.h>
#endif

namespace splat {

// A ray closer than this to parallel with the disc plane (|d . n| = cos of the angle
// between the ray and the normal, d and n unit) is not tested: t's relative error grows
// like float epsilon / |d . n|, and at 1e-6 (0.00006 degrees off the plane) it would
// reach ~10 %, while such a ray sees the disc as a segment of zero area anyway.
constexpr float kParallelCosine = 1e-6f;

struct DiscHit {
    float t;      // distance along the (unit) ray direction
    float dist2;  // squared distance from the hit point to the disc centre
    bool front;   // d . n < 0
};

// Pure function of its inputs, used both by the BVH and by the brute-force reference, so
// that both agree bit for bit on which discs a ray meets.
inline bool intersect_disc(const Ray &ray, Vec3 c, Vec3 n, float r, DiscHit *out) {
    const float dn = dot(ray.d, n);
    if (std::fabs(dn) < kParallelCosine) return false;
    const Vec3 oc = c - ray.o;
    const float t = dot(oc, n) / dn;
    if (!(t > ray.tmin && t < ray.tmax)) return false;  // also rejects NaN
    const Vec3 p = ray.d * t - oc;                        // hit point relative to c
    const float dist2 = dot(p, p);
    if (dist2 > r * r) return false;
    out->t = t;
    out->dist2 = dist2;
    out->front = dn < 0.f;
    return true;
}

#ifdef SPLAT_SSE2
// intersect_disc() on four discs at once, lane by lane the same operations in the same
// order (SSE2 has no fused multiply-add: every product is rounded as in the scalar code),
// so the same hits with the same t and dist2. `disc[k]` points at {c.x, c.y, c.z, r,
// n.x, n.y, n.z, *} (a PackedSplat). Returns the mask of hits; out_* per lane.
struct DiscRay {
    __m128 o[3], d[3], tmin, tmax;
    explicit DiscRay(const Ray &ray) {
        for (int k = 0; k < 3; ++k) o[k] = _mm_set1_ps(ray.o[k]), d[k] = _mm_set1_ps(ray.d[k]);
        tmin = _mm_set1_ps(ray.tmin), tmax = _mm_set1_ps(ray.tmax);
    }
};

inline int intersect_discs4(const DiscRay &r, const float *const disc[4], float out_t[4], float out_dist2[4]) {
    __m128 c0 = _mm_loadu_ps(disc[0]), c1 = _mm_loadu_ps(disc[1]), c2 = _mm_loadu_ps(disc[2]),
           c3 = _mm_loadu_ps(disc[3]);
    __m128 n0 = _mm_loadu_ps(disc[0] + 4), n1 = _mm_loadu_ps(disc[1] + 4), n2 = _mm_loadu_ps(disc[2] + 4),
           n3 = _mm_loadu_ps(disc[3] + 4);
    _MM_TRANSPOSE4_PS(c0, c1, c2, c3);  // c.x, c.y, c.z, r
    _MM_TRANSPOSE4_PS(n0, n1, n2, n3);  // n.x, n.y, n.z, (id)
    const __m128 dn = _mm_add_ps(_mm_add_ps(_mm_mul_ps(r.d[0], n0), _mm_mul_ps(r.d[1], n1)), _mm_mul_ps(r.d[2], n2));
    const __m128 abs_dn = _mm_andnot_ps(_mm_set1_ps(-0.f), dn);
    // |dn| < kParallelCosine rejects; NaN passes this test, as in the scalar code.
    __m128 ok = _mm_cmpnlt_ps(abs_dn, _mm_set1_ps(kParallelCosine));
    const __m128 ocx = _mm_sub_ps(c0, r.o[0]), ocy = _mm_sub_ps(c1, r.o[1]), ocz = _mm_sub_ps(c2, r.o[2]);
    const __m128 t = _mm_div_ps(
        _mm_add_ps(_mm_add_ps(_mm_mul_ps(ocx, n0), _mm_mul_ps(ocy, n1)), _mm_mul_ps(ocz, n2)), dn);
    ok = _mm_and_ps(ok, _mm_and_ps(_mm_cmpgt_ps(t, r.tmin), _mm_cmplt_ps(t, r.tmax)));  // false for NaN
    const __m128 px = _mm_sub_ps(_mm_mul_ps(r.d[0], t), ocx), py = _mm_sub_ps(_mm_mul_ps(r.d[1], t), ocy),
                 pz = _mm_sub_ps(_mm_mul_ps(r.d[2], t), ocz);
    const __m128 dist2 = _mm_add_ps(_mm_add_ps(_mm_mul_ps(px, px), _mm_mul_ps(py, py)), _mm_mul_ps(pz, pz));
    ok = _mm_and_ps(ok, _mm_cmpngt_ps(dist2, _mm_mul_ps(c3, c3)));  // dist2 > r^2 rejects (NaN does not)
    const int mask = _mm_movemask_ps(ok);
    if (mask) _mm_storeu_ps(out_t, t), _mm_storeu_ps(out_dist2, dist2);
    return mask;
}

// intersect_disc() of each disc s[0..count) against the rays of `mask` (bits of lanes of
// `r`), four rays at a time with the same operations in the same order as the scalar test:
// the same hits with the same t and dist2. hit(i, k, DiscHit) for ray i and disc k, disc
// by disc, rays in ascending order.
template <class OnHit>
inline void intersect_disc_rays(const PacketRays &r, uint32_t mask, const float *s0, uint32_t count,
                                OnHit &&hit) {
    const __m128 parallel = _mm_set1_ps(kParallelCosine), sign = _mm_set1_ps(-0.f);
    for (uint32_t k = 0; k < count; ++k) {
        const float *s = s0 + 8 * k;  // a PackedSplat: c.x, c.y, c.z, r, n.x, n.y, n.z, id
        const __m128 cx = _mm_set1_ps(s[0]), cy = _mm_set1_ps(s[1]), cz = _mm_set1_ps(s[2]);
        const __m128 nx = _mm_set1_ps(s[4]), ny = _mm_set1_ps(s[5]), nz = _mm_set1_ps(s[6]);
        const __m128 r2 = _mm_set1_ps(s[3] * s[3]);
        for (uint32_t g = 0; g < 16; g += 4) {
            const int lanes = int(mask >> g & 15);
            if (!lanes) continue;
            const __m128 dx = _mm_load_ps(r.d[0] + g), dy = _mm_load_ps(r.d[1] + g), dz = _mm_load_ps(r.d[2] + g);
            const __m128 dn = _mm_add_ps(_mm_add_ps(_mm_mul_ps(dx, nx), _mm_mul_ps(dy, ny)), _mm_mul_ps(dz, nz));
            __m128 ok = _mm_cmpnlt_ps(_mm_andnot_ps(sign, dn), parallel);
            const __m128 ocx = _mm_sub_ps(cx, _mm_load_ps(r.o[0] + g)), ocy = _mm_sub_ps(cy, _mm_load_ps(r.o[1] + g)),
                         ocz = _mm_sub_ps(cz, _mm_load_ps(r.o[2] + g));
            const __m128 t = _mm_div_ps(
                _mm_add_ps(_mm_add_ps(_mm_mul_ps(ocx, nx), _mm_mul_ps(ocy, ny)), _mm_mul_ps(ocz, nz)), dn);
            ok = _mm_and_ps(ok, _mm_and_ps(_mm_cmpgt_ps(t, _mm_load_ps(r.tmin + g)),
                                           _mm_cmplt_ps(t, _mm_load_ps(r.tmax + g))));
            const __m128 px = _mm_sub_ps(_mm_mul_ps(dx, t), ocx), py = _mm_sub_ps(_mm_mul_ps(dy, t), ocy),
                         pz = _mm_sub_ps(_mm_mul_ps(dz, t), ocz);
            const __m128 dist2 = _mm_add_ps(_mm_add_ps(_mm_mul_ps(px, px), _mm_mul_ps(py, py)), _mm_mul_ps(pz, pz));
            ok = _mm_and_ps(ok, _mm_cmpngt_ps(dist2, r2));
            int m = _mm_movemask_ps(ok) & lanes;
            if (!m) continue;
            alignas(16) float tt[4], dd[4], nn[4];
            _mm_store_ps(tt, t), _mm_store_ps(dd, dist2), _mm_store_ps(nn, dn);
            for (; m; m &= m - 1) {
                const int j = __builtin_ctz(unsigned(m));
                hit(int(g) + j, k, DiscHit{tt[j], dd[j], nn[j] < 0.f});
            }
        }
    }
}

#ifdef SPLAT_AVX2_KERNELS
// intersect_disc_rays() eight rays at a time, for CPUs with AVX2 (simd.cpp decides at run
// time; the shipped binaries' baseline stays SSE2). The same operations in the same order
// (no fused multiply-add: the function enables AVX2 only, not FMA), so the same hits. A
// second copy rather than one template over the lane width: AVX2 intrinsics only inline
// into functions that carry the target attribute themselves.
template <class OnHit>
__attribute__((target("avx2"))) void intersect_disc_rays_avx2(const PacketRays &r, uint32_t mask, const float *s0,
                                                                uint32_t count, OnHit &&hit) {
    const __m256 parallel = _mm256_set1_ps(kParallelCosine), sign = _mm256_set1_ps(-0.f);
    for (uint32_t k = 0; k < count; ++k) {
        const float *s = s0 + 8 * k;  // a PackedSplat: c.x, c.y, c.z, r, n.x, n.y, n.z, id
        const __m256 cx = _mm256_set1_ps(s[0]), cy = _mm256_set1_ps(s[1]), cz = _mm256_set1_ps(s[2]);
        const __m256 nx = _mm256_set1_ps(s[4]), ny = _mm256_set1_ps(s[5]), nz = _mm256_set1_ps(s[6]);
        const __m256 r2 = _mm256_set1_ps(s[3] * s[3]);
        for (uint32_t g = 0; g < 16; g += 8) {
            const int lanes = int(mask >> g & 255);
            if (!lanes) continue;
            const __m256 dx = _mm256_load_ps(r.d[0] + g), dy = _mm256_load_ps(r.d[1] + g),
                         dz = _mm256_load_ps(r.d[2] + g);
            const __m256 dn =
                _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(dx, nx), _mm256_mul_ps(dy, ny)), _mm256_mul_ps(dz, nz));
            __m256 ok = _mm256_cmp_ps(_mm256_andnot_ps(sign, dn), parallel, _CMP_NLT_UQ);
            const __m256 ocx = _mm256_sub_ps(cx, _mm256_load_ps(r.o[0] + g)),
                         ocy = _mm256_sub_ps(cy, _mm256_load_ps(r.o[1] + g)),
                         ocz = _mm256_sub_ps(cz, _mm256_load_ps(r.o[2] + g));
            const __m256 t = _mm256_div_ps(
                _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(ocx, nx), _mm256_mul_ps(ocy, ny)), _mm256_mul_ps(ocz, nz)),
                dn);
            ok = _mm256_and_ps(ok, _mm256_and_ps(_mm256_cmp_ps(t, _mm256_load_ps(r.tmin + g), _CMP_GT_OQ),
                                                 _mm256_cmp_ps(t, _mm256_load_ps(r.tmax + g), _CMP_LT_OQ)));
            const __m256 px = _mm256_sub_ps(_mm256_mul_ps(dx, t), ocx), py = _mm256_sub_ps(_mm256_mul_ps(dy, t), ocy),
                         pz = _mm256_sub_ps(_mm256_mul_ps(dz, t), ocz);
            const __m256 dist2 =
                _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(px, px), _mm256_mul_ps(py, py)), _mm256_mul_ps(pz, pz));
            ok = _mm256_and_ps(ok, _mm256_cmp_ps(dist2, r2, _CMP_NGT_UQ));
            int m = _mm256_movemask_ps(ok) & lanes;
            if (!m) continue;
            alignas(32) float tt[8], dd[8], nn[8];
            _mm256_store_ps(tt, t), _mm256_store_ps(dd, dist2), _mm256_store_ps(nn, dn);
            for (; m; m &= m - 1) {
                const int j = __builtin_ctz(unsigned(m));
                hit(int(g) + j, k, DiscHit{tt[j], dd[j], nn[j] < 0.f});
            }
        }
    }
}
#endif
#else
struct DiscRay {  // nothing to precompute for the plain path
    explicit DiscRay(const Ray &) {}
};
#endif

}  // namespace splat
