// A ray and the record of its nearest splat hit.
#pragma once

#include <cmath>
#include <cstdint>
#include <limits>

#include "base/vec3.h"

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

// Rays traced together as a packet (packet.h: a 4x4 pixel tile), at most.
constexpr int kPacketRays = 16;
static_assert(kPacketRays <= 32, "a packet's rays are the bits of a uint32_t");

// A packet's rays by component (lane i: ray i), for the tests that take a box or a disc
// against several rays at once. inv_d is 1 / d, as the single-ray box test computes it.
struct PacketRays {
    alignas(32) float o[3][kPacketRays], d[3][kPacketRays], inv_d[3][kPacketRays];
    alignas(32) float tmin[kPacketRays], tmax[kPacketRays];
    PacketRays(const Ray *rays, int n) {
        for (int i = 0; i < kPacketRays; ++i) {
            const bool used = i < n;
            for (int k = 0; k < 3; ++k) {
                o[k][i] = used ? rays[i].o[k] : 0.f, d[k][i] = used ? rays[i].d[k] : 1.f;
                inv_d[k][i] = 1.f / d[k][i];
            }
            // Unused lanes: an empty interval (no t is > +inf), never a hit.
            tmin[i] = used ? rays[i].tmin : kInfinity, tmax[i] = used ? rays[i].tmax : -kInfinity;
        }
    }
};

// Strict ordering of hits along a ray. Equal distances are broken by the smaller splat
// id, so that every traversal order (BVH or brute force) picks the same "nearest" hit.
inline bool closer(float t, int32_t id, const Hit &best) {
    return (t < best.t) | ((t == best.t) & (id < best.id));  // & and |: no branches
}

}  // namespace splat
