// Which surface a ray sees, and its normal and colour: the paper's visibility method
// (docs/ALGORITHM.md) on top of the ε-window query, with each rule a switch.
#pragma once

#include "splats/layer.h"
#include "splats/splat_scene.h"

namespace splat {

// Where on the layer the surface point is.
enum class PositionRule : int {
    First = 0,          // the layer's first hit (the general method's nearest hit)
    NearPhase = 1,      // the paper's pairwise convex/concave rule (omega)
    NearestCentre = 2,  // Linsen et al.: the member hit closest to its own disc centre
};

// Weight of a member splat in the interpolated normal and colour, d = distance of the hit
// from the disc centre, r = disc radius.
enum class Kernel : int {
    Linear = 0,  // (r - d) / r, the paper's
    Smooth = 1,  // (1 - (d / r)^2)^2, C1 at the rim
};

struct Method {
    bool wrong_hit_elimination = true;
    bool normal_interpolation = true;
    bool far_phase = true;  // applied to splats of closed objects only
    PositionRule position = PositionRule::NearPhase;
    Kernel kernel = Kernel::Linear;
    float epsilon = 1.f;  // layer depth in radii of the layer's first splat
    // Edge-aware interpolation: only members whose normal is within the crease angle of the
    // surface splat's blend into its normal and colour (cosine of the angle; below -1: all).
    float crease_cos = -2.f;
    // Far-phase rejections a ray may go through before it is declared a miss: each one is a
    // fringe or a grazed edge in front of the surface, a handful at most in practice.
    int max_layers = 8;

    // Nearest hit, any facing, flat normal: no layer needs to be gathered.
    bool is_general() const {
        return !wrong_hit_elimination && !normal_interpolation && !far_phase && position == PositionRule::First;
    }
};

struct SurfaceHit {
    float t = kInfinity;
    int32_t id = -1;  // the splat whose hit is the surface point
    bool front = false;
    Vec3 normal, colour;
    float alpha = 1.f;  // the points' own opacity, blended like the colour
    float attributes[kMaxPointAttributes];  // SplatScene::attributes blended like the colour (its count of them)
    int n_members = 0;  // the splats that contributed (secondary rays exclude them)
    int32_t members[kMaxLayerHits];
    bool overflow = false;

    bool valid() const { return id >= 0; }
};

// `inside`: the ray travels inside an object (a refracted ray), so a layer begins with a
// back-facing hit (the exit). `exclude`: splats the ray must not hit (the ones that made
// its origin point, for reflected, refracted and shadow rays).
// `stats` (may be null) counts the traversal's work, the layer queries, the far phase's
// rejections and the interpolated points.
SurfaceHit find_surface(const SplatScene &scene, Ray ray, const Method &method, bool inside = false,
                        const int32_t *exclude = nullptr, int n_exclude = 0, bool brute_force = false,
                        TraversalStats *stats = nullptr);

// find_surface() for n <= kPacketRays rays at once, ray i with inside[i] and exclude[i]
// (n_exclude ids each; exclude may be null): the first layer query of every ray in one
// packet traversal (packet.h; ray by ray when the rays are not coherent), the rest ray by
// ray. The same answers as find_surface(). out[i] is built in place (it may be storage
// without objects yet).
void find_surfaces(const SplatScene &scene, const Ray *rays, int n, const Method &method, const bool *inside,
                   const int32_t *const *exclude, int n_exclude, SurfaceHit *out, TraversalStats *stats = nullptr);

// The near phase's test for two member splats j (nearer) and k: whether omega, the sum of
// the angles (c_k - c_j, n_j) and (c_j - c_k, n_k), exceeds pi (convex); n_j and n_k unit.
// Coincident centres count as right angles (omega = pi: not convex).
bool near_phase_convex(Vec3 cj, Vec3 nj, Vec3 ck, Vec3 nk);

}  // namespace splat
