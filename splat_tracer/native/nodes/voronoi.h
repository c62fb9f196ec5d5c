// The Voronoi Texture node, as Blender's Cycles defines it (read to learn it; a separate
// implementation). On its own: the node has many features and dimensions.
#pragma once

#include <cstdint>

#include "base/vec3.h"

namespace splat {

// Voronoi F1 in 3-D: the nearest of the points scattered one per unit cell (offset by the
// cell's hash x randomness): its distance, its cell's colour and its position.
void voronoi_f1(Vec3 p, float exponent, float randomness, int metric, float *distance, Vec3 *colour, Vec3 *position);

}  // namespace splat
