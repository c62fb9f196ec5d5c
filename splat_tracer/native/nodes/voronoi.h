// The Voronoi Texture node, as Blender 5's Cycles defines it (read to learn it; a separate
// implementation): points scattered one per unit cell of a 1-, 2-, 3- or 4-D grid (offset
// by the cell's hash x randomness), and what the node measures of them at a point -- the
// nearest (F1), the second nearest (F2), a smooth blend of the nearest (Smooth F1), the
// distance to the nearest cell's edge, the radius of the largest sphere about the nearest
// point that touches no other -- summed over octaves as fractal Voronoi (Detail > 0).
// On its own: the node has many features and dimensions.
#pragma once

#include <cstdint>

#include "base/vec3.h"

namespace splat {

// Blender's enumerations, in render/nodes.py VORONOI_METRICS and VORONOI_FEATURES order.
enum class VoronoiMetric : int32_t { Euclidean = 0, Manhattan, Chebyshev, Minkowski, Count };
enum class VoronoiFeature : int32_t { F1 = 0, F2, SmoothF1, DistanceToEdge, NSphereRadius, Count };

// The node's inputs as its sockets hold them (clamped here as Cycles clamps them).
struct VoronoiInputs {
    float scale, detail, roughness, lacunarity, smoothness, exponent, randomness;
    bool normalize;
};

// The node's outputs (those a feature does not give are 0, as Cycles leaves them).
struct VoronoiOutputs {
    float distance = 0.f;
    Vec3 colour, position;
    float w = 0.f, radius = 0.f;
};

// The node at `vector` and `w` (the 4th coordinate; 1-D reads only w, 2-D only x and y).
VoronoiOutputs voronoi_texture(Vec3 vector, float w, int dimensions, VoronoiFeature feature, VoronoiMetric metric,
                               const VoronoiInputs &in);

}  // namespace splat
