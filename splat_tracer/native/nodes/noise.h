// Blender's noise, as Cycles defines it (intern/cycles/kernel/svm/noise.h, fractal_noise.h;
// read to learn them, this is a separate implementation): Bob Jenkins' lookup3 hash, improved
// Perlin noise and its fractal sum. Shared by the node interpreter (program.cpp: Noise, White Noise, Wave's
// distortion) and its tests.
#pragma once

#include <cstdint>
#include <cstring>

#include "base/vec3.h"

namespace splat {

// lookup3 hashes of 1-3 words, as Blender seeds them (0xdeadbeef + words * 4 + 13).
uint32_t hash_words(int n, uint32_t x, uint32_t y, uint32_t z);
uint32_t hash_uint3(uint32_t kx, uint32_t ky, uint32_t kz);
// Four words: lookup3's mix() over the first three, then the fourth (Blender's hash_uint4).
uint32_t hash_uint4(uint32_t kx, uint32_t ky, uint32_t kz, uint32_t kw);
inline uint32_t float_bits(float f) {
    uint32_t u;
    std::memcpy(&u, &f, 4);
    return u;
}
inline float to_unit(uint32_t h) { return float(h) * (1.f / float(0xFFFFFFFFu)); }

// Blender's Perlin noise in 3-D, signed (about -1..1) and its fractal sum; Cycles' definitions.
float perlin_signed(Vec3 p);
float noise_fbm(Vec3 p, float detail, float roughness, float lacunarity, bool normalize);

// A point offset by a fixed pseudo-random amount per seed (for Noise's distortion and colour).
Vec3 random_offset(float seed);

}  // namespace splat
