// A ray and the record of its nearest splat hit.
#pragma once

#include <cmath>
#include <cstdint>
#include <limits>

#include "vec3.h"

namespace splat {

constexpr float kInfinity = std::numeric_limits<float>::infinity();

// Largest coordinate or radius magnitude the core accepts. The traversal squares
// differences of coordinates in float: |a - b|^2 <= 3 (2 x 1e18)^2 = 1.2e37, well below
// float's 3.4e38, so no product overflows to inf and no box centre or SAH area becomes
// inf or NaN (which crashed the BVH build for centres near 2e38). Georeferenced data is
// recentred by the caller long before this (core.local_frame).
constexpr float kMaxCoordinate = 1e18f;

inline bool within_range(float v) { return std::fabs(v) <= kMaxCoordinate; }  // false for NaN

// o + t d for t in the open interval (tmin, tmax); d is unit length.
struct Ray {
    Vec3 o, d;
    float tmin = 0.f, tmax = kInfinity;
};

struct Hit {
    float t = kInfinity;
    int32_t id = -1;     // splat index in the caller's (input) order, -1 when nothing was hit
    bool front = false;  // d . n < 0: the ray meets the side the normal points to

    bool valid() const { return id >= 0; }
};

// Strict ordering of hits along a ray. Equal distances are broken by the smaller splat
// id, so that every traversal order (BVH or brute force) picks the same "nearest" hit.
inline bool closer(float t, int32_t id, const Hit &best) {
    return (t < best.t) | ((t == best.t) & (id < best.id));  // & and |: no branches
}

}  // namespace splat
