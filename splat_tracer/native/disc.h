// Ray / splat (oriented disc) intersection, as written in docs/ALGORITHM.md:
//   t = ((c - o) . n) / (d . n),  hit when |o + t d - c|^2 <= r^2.
#pragma once

#include <cmath>

#include "ray.h"

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

}  // namespace splat
