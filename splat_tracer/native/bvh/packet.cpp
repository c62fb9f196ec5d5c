#include "bvh/packet.h"

#include <cmath>

namespace splat {

bool packet_coherent(const PacketRays &r, int n, float scene_size) {
    if (n <= 1) return false;
    // Cone of directions: every direction within ~4 degrees of their mean. A 4x4 tile of a
    // 50-degree view spans 4 x 50 / 160 = 1.25 degrees even at 160 pixels across; beyond a
    // few degrees the packet's bounds grow faster than its rays can share nodes.
    constexpr float kMinCosine = 0.9975f;  // cos 4 degrees
    float mean[3], spread2 = 0.f;
    for (int k = 0; k < 3; ++k) {
        float sum = 0.f, lo = r.o[k][0], hi = r.o[k][0];
        for (int i = 0; i < n; ++i) sum += r.d[k][i], lo = fmin2(lo, r.o[k][i]), hi = fmax2(hi, r.o[k][i]);
        mean[k] = sum, spread2 += (hi - lo) * (hi - lo);
    }
    // d . mean >= cos x |mean| for every ray, without normalising the mean (no branch per ray).
    const float bound = kMinCosine * std::sqrt(mean[0] * mean[0] + mean[1] * mean[1] + mean[2] * mean[2]);
    bool inside = bound > 0.f;
    for (int i = 0; i < n; ++i) inside &= r.d[0][i] * mean[0] + r.d[1][i] * mean[1] + r.d[2][i] * mean[2] >= bound;
    if (!inside) return false;
    // Origins: a camera's rays share theirs (perspective) or spread over the tile's own
    // footprint (orthographic); a tenth of the scene is a 4x4 tile of a view 40 pixels
    // across, about as wide as the 4-degree cone is at the scene's distance. Rays from
    // points scattered over the scene would make the packet's box of origins the scene.
    constexpr float kOriginSpread = 0.1f;
    return std::sqrt(spread2) <= kOriginSpread * scene_size;
}

PacketBounds::PacketBounds(const PacketRays &r, int n) {
    tmin = kInfinity;
    for (int i = 0; i < n; ++i) tmin = fmin2(tmin, r.tmin[i]);
    for (int k = 0; k < 3; ++k) {
        // The same inverses the single-ray test uses (1.f / d).
        float olo = kInfinity, ohi = -kInfinity, ilo = kInfinity, ihi = -kInfinity;
        bool parallel = true;
        for (int i = 0; i < n; ++i) {
            olo = fmin2(olo, r.o[k][i]), ohi = fmax2(ohi, r.o[k][i]);
            ilo = fmin2(ilo, r.inv_d[k][i]), ihi = fmax2(ihi, r.inv_d[k][i]);
            parallel &= r.d[k][i] == 0.f;
        }
        const bool finite = std::isfinite(ilo) && std::isfinite(ihi);
        axis[k] = parallel ? kParallel : finite && (ilo > 0.f || ihi < 0.f) ? kSlabs : kUntested;
        near_side[k] = ilo > 0.f ? 0 : 1;
        o_lo[k] = F4::broadcast(olo), o_hi[k] = F4::broadcast(ohi);
        inv_lo[k] = F4::broadcast(ilo), inv_hi[k] = F4::broadcast(ihi);
    }
}

}  // namespace splat
