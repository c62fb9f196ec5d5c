// A ray and the record of its nearest splat hit.
#pragma once

#include <cstdint>
#include <limits>

#include "vec3.h"

namespace splat {

constexpr float kInfinity = std::numeric_limits<float>::infinity();

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
    return t < best.t || (t == best.t && id < best.id);
}

}  // namespace splat
