// Blender's noise, as Cycles defines it (intern/cycles/kernel/svm/noise.h, fractal_noise.h,
// noisetex.h; read to learn them, this is a separate implementation): Bob Jenkins' lookup3
// hash, improved Perlin noise in 1-4 dimensions, its five fractal sums and the Noise Texture
// node around them. Shared by the node interpreter (program.cpp: Noise, White Noise, Wave's
// distortion) and its tests.
#pragma once

#include <cstdint>
#include <cstring>

#include "base/vec3.h"

namespace splat {

// lookup3 hashes of 1-3 words, as Blender seeds them (0xdeadbeef + words * 4 + 13).
uint32_t hash_words(int n, uint32_t x, uint32_t y, uint32_t z);
uint32_t hash_uint(uint32_t kx);
uint32_t hash_uint2(uint32_t kx, uint32_t ky);
uint32_t hash_uint3(uint32_t kx, uint32_t ky, uint32_t kz);
// Four words: lookup3's mix() over the first three, then the fourth (Blender's hash_uint4).
uint32_t hash_uint4(uint32_t kx, uint32_t ky, uint32_t kz, uint32_t kw);
inline uint32_t float_bits(float f) {
    uint32_t u;
    std::memcpy(&u, &f, 4);
    return u;
}
inline float to_unit(uint32_t h) { return float(h) * (1.f / float(0xFFFFFFFFu)); }
// Cycles' mix(a, b, t) = a + t (b - a) (not (1 - t) a + t b: the rounding differs).
inline float mix(float a, float b, float t) { return a + t * (b - a); }
inline Vec3 mix(Vec3 a, Vec3 b, float t) { return a + (b - a) * t; }

// Blender's Perlin noise in 3-D, signed (about -1..1) and its fractal sum; Cycles' definitions.
float perlin_signed(Vec3 p);
float noise_fbm(Vec3 p, float detail, float roughness, float lacunarity, bool normalize);

// The Noise Texture node's fractal types (render/nodes.py NOISE_TYPES, same order).
enum class NoiseType : int32_t { FBM = 0, Multifractal, RidgedMultifractal, HybridMultifractal, HeteroTerrain, Count };

// Inputs of the Noise Texture node after its Vector, in this order (a register block).
struct NoiseParams {
    float scale, detail, roughness, lacunarity, distortion, w, offset, gain;
};
static_assert(sizeof(NoiseParams) == 8 * sizeof(float), "NoiseParams is read from eight registers");

// Blender's Noise Texture node in `dimensions` (1: W; 2: the vector's x, y; 3: the vector;
// 4: the vector and W): its Fac; its Color into *colour when colour is not null (two more
// fractal sums at offset points: not computed when nothing reads them). `normalize` is
// read by fBm only, as in Blender.
float noise_texture(int dimensions, NoiseType type, Vec3 vector, const NoiseParams &q, bool normalize, Vec3 *colour);

}  // namespace splat
