// The Gabor Texture node (Blender 4.3+), as Cycles 5 defines it (read to learn it; a separate
// implementation): sparse convolution noise -- in each unit cell of a 2-D or 3-D grid, eight
// Gabor kernels (a Gaussian envelope, Hann-windowed within unit distance, times a plane wave of
// the node's frequency) at hashed positions, with hashed +-1 weights and, with anisotropy below
// 1, hashed orientations; summed over the 3^n neighbouring cells as a complex phasor (Tricard et
// al. 2019), whose sine part is the value, its angle the phase and its modulus the intensity.
#pragma once

#include "base/vec3.h"

namespace splat {

struct GaborOutputs {
    float value, phase, intensity;
};

// `coordinates` already as the node reads them (the Vector); scale, frequency, anisotropy and
// the 2-D orientation (radians) as its sockets hold them; orientation_3d: the 3-D type's
// direction (normalised here). three_d: the 3-D type, else 2-D (x, y).
GaborOutputs gabor_texture(Vec3 coordinates, float scale, float frequency, float anisotropy, float orientation_2d,
                           Vec3 orientation_3d, bool three_d);

}  // namespace splat
