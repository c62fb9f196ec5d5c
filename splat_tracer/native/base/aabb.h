// Axis-aligned box, the tight bounds of a disc, and the conservative ray/box slab test.
#pragma once

#include <algorithm>
#include <cmath>

#include "base/ray.h"

namespace splat {

struct AABB {
    Vec3 lo{kInfinity, kInfinity, kInfinity};
    Vec3 hi{-kInfinity, -kInfinity, -kInfinity};

    void grow(Vec3 p) { lo = vmin(lo, p), hi = vmax(hi, p); }
    void grow(const AABB &b) { lo = vmin(lo, b.lo), hi = vmax(hi, b.hi); }
    bool empty() const { return !(lo.x <= hi.x); }
    Vec3 extent() const { return hi - lo; }
    // Halves first: lo + hi would overflow for boxes near the float range's ends.
    Vec3 centre() const { return lo * 0.5f + hi * 0.5f; }
    float half_area() const {
        if (empty()) return 0.f;
        Vec3 e = extent();
        return e.x * e.y + e.y * e.z + e.z * e.x;
    }
};

// Tight bounds of the disc (c, n, r): along axis k the disc spans c_k +- r sqrt(1 - n_k^2).
// The bounds are widened by a few float ulps of the coordinates involved so that rounding
// in this formula can never cut off a rim point that intersect_disc() accepts.
inline AABB disc_bounds(Vec3 c, Vec3 n, float r) {
    AABB b;
    for (int k = 0; k < 3; ++k) {
        const float s = std::sqrt(std::max(0.f, 1.f - n[k] * n[k]));
        const float half = r * s;
        // 4 ulps of the largest magnitude that enters the sum, plus r's own rounding.
        const float pad = 4.f * 1.1920929e-7f * (std::fabs(c[k]) + r);
        b.lo[k] = c[k] - half - pad;
        b.hi[k] = c[k] + half + pad;
    }
    return b;
}

// Float's unit roundoff (half an ulp of 1), pbrt's u.
constexpr float kUnitRoundoff = 5.9604645e-8f;
// pbrt's gamma(n) = n u / (1 - n u): the relative error bound of n rounded float operations.
constexpr float rounding_gamma(int n) { return float(n) * kUnitRoundoff / (1.f - float(n) * kUnitRoundoff); }
// The slab tests' widening, 2 gamma(3) (below): every box test of the core (this one, the
// wide node's, a packet's) scales its entries and exits by 1 -+ this.
constexpr float kSlabWiden = 2.f * rounding_gamma(3);

// Slab test. `inv_d` is 1/d per axis (may be +-inf). Returns the entry distance, or
// +inf when the box is missed within (tmin, tmax). Entry and exit distances are widened
// by 2*gamma(3) of their magnitude (pbrt-v4, "Robust ray-bounds intersections") so that
// float rounding never rejects a box that the ray truly touches, nor reports an entry
// later than a hit inside it (the BVH prunes on that entry distance).
inline float intersect_box(const AABB &b, Vec3 o, Vec3 inv_d, float tmin, float tmax) {
    constexpr float kShrink = 1.f - kSlabWiden, kGrow = 1.f + kSlabWiden;
    float t0 = tmin, t1 = tmax;
    for (int k = 0; k < 3; ++k) {
        float tn = (b.lo[k] - o[k]) * inv_d[k];
        float tf = (b.hi[k] - o[k]) * inv_d[k];
        if (tn > tf) std::swap(tn, tf);
        // Widened by scaling, not by adding |t| * gamma: for a ray parallel to the slab the
        // distances are +-inf, and inf - inf * gamma would be NaN, which the comparisons
        // below skip -- the box was then never rejected and axis-aligned orthographic
        // views traced every box of the tree (500-1000x slower).
        tn *= tn > 0.f ? kShrink : kGrow;
        tf *= tf > 0.f ? kGrow : kShrink;
        // NaN (0 * inf when the origin lies on a slab plane of a parallel ray) is skipped:
        // the comparisons below are false for NaN, leaving t0/t1 unchanged.
        t0 = tn > t0 ? tn : t0;
        t1 = tf < t1 ? tf : t1;
        if (t0 > t1) return kInfinity;
    }
    return t0;
}

}  // namespace splat
