// Blender's noise (see noise.h).
#include "nodes/noise.h"

#include <cmath>

namespace splat {

namespace {

inline uint32_t rot(uint32_t x, int k) { return (x << k) | (x >> (32 - k)); }
inline void final_mix(uint32_t &a, uint32_t &b, uint32_t &c) {  // Bob Jenkins' lookup3 final()
    c ^= b, c -= rot(b, 14);
    a ^= c, a -= rot(c, 11);
    b ^= a, b -= rot(a, 25);
    c ^= b, c -= rot(b, 16);
    a ^= c, a -= rot(c, 4);
    b ^= a, b -= rot(a, 14);
    c ^= b, c -= rot(b, 24);
}
inline float lerp(float a, float b, float t) { return (1.f - t) * a + t * b; }
inline float fade(float t) { return t * t * t * (t * (t * 6.f - 15.f) + 10.f); }
inline float grad3(uint32_t hash, float x, float y, float z) {
    const uint32_t h = hash & 15u;
    const float u = h < 8u ? x : y;
    const float vt = (h == 12u || h == 14u) ? x : z;
    const float v = h < 4u ? y : vt;
    return ((h & 1u) ? -u : u) + ((h & 2u) ? -v : v);
}

}  // namespace

// lookup3 hashes of 1-3 words, as Blender seeds them (0xdeadbeef + words * 4 + 13).
uint32_t hash_words(int n, uint32_t x, uint32_t y, uint32_t z) {
    uint32_t a, b, c;
    a = b = c = 0xdeadbeefu + (uint32_t(n) << 2) + 13u;
    if (n >= 3) c += z;
    if (n >= 2) b += y;
    a += x;
    final_mix(a, b, c);
    return c;
}

uint32_t hash_uint4(uint32_t kx, uint32_t ky, uint32_t kz, uint32_t kw) {
    uint32_t a, b, c;
    a = b = c = 0xdeadbeefu + (4u << 2) + 13u;
    a += kx, b += ky, c += kz;
    a -= c, a ^= rot(c, 4), c += b;  // lookup3's mix()
    b -= a, b ^= rot(a, 6), a += c;
    c -= b, c ^= rot(b, 8), b += a;
    a -= c, a ^= rot(c, 16), c += b;
    b -= a, b ^= rot(a, 19), a += c;
    c -= b, c ^= rot(b, 4), b += a;
    a += kw;
    final_mix(a, b, c);
    return c;
}

// A point offset by a fixed pseudo-random amount per seed (for Noise's distortion and colour).
Vec3 random_offset(float seed) {
    auto h = [&](float k) { return 100.f + to_unit(hash_words(2, float_bits(seed), float_bits(k), 0)) * 100.f; };
    return {h(0.f), h(1.f), h(2.f)};
}

uint32_t hash_uint3(uint32_t kx, uint32_t ky, uint32_t kz) { return hash_words(3, kx, ky, kz); }

float perlin_signed(Vec3 p) {
    // Blender repeats the noise every 100000 units (float precision), nudging beyond 1e6.
    for (int i = 0; i < 3; ++i) {
        const float correction = std::fabs(p[i]) >= 1000000.f ? 0.5f : 0.f;
        p[i] = std::fmod(p[i], 100000.f) + correction;
    }
    const int X = int(std::floor(p.x)), Y = int(std::floor(p.y)), Z = int(std::floor(p.z));
    const float fx = p.x - float(X), fy = p.y - float(Y), fz = p.z - float(Z);
    const float u = fade(fx), v = fade(fy), w = fade(fz);
    auto g = [&](int dx, int dy, int dz) {
        return grad3(hash_words(3, uint32_t(X + dx), uint32_t(Y + dy), uint32_t(Z + dz)), fx - float(dx),
                     fy - float(dy), fz - float(dz));
    };
    auto bimix = [](float v0, float v1, float v2, float v3, float x, float y) {
        const float x1 = 1.f - x;
        return (1.f - y) * (v0 * x1 + v1 * x) + y * (v2 * x1 + v3 * x);
    };
    const float r = (1.f - w) * bimix(g(0, 0, 0), g(1, 0, 0), g(0, 1, 0), g(1, 1, 0), u, v) +
                    w * bimix(g(0, 0, 1), g(1, 0, 1), g(0, 1, 1), g(1, 1, 1), u, v);
    // Blender's scale for 3-D Perlin noise (about -1..1), and 0 for a non-finite input.
    return std::isfinite(r) ? 0.9820f * r : 0.f;
}

float noise_fbm(Vec3 p, float detail, float roughness, float lacunarity, bool normalize) {
    float scale = 1.f, amp = 1.f, max_amp = 0.f, sum = 0.f;
    for (int i = 0; i <= int(detail); ++i) {
        sum += perlin_signed(p * scale) * amp;
        max_amp += amp;
        amp *= roughness;
        scale *= lacunarity;
    }
    const float rest = detail - std::floor(detail);
    if (rest != 0.f) {
        const float sum2 = sum + perlin_signed(p * scale) * amp;
        return normalize ? lerp(0.5f * sum / max_amp + 0.5f, 0.5f * sum2 / (max_amp + amp) + 0.5f, rest)
                         : lerp(sum, sum2, rest);
    }
    return normalize ? 0.5f * sum / max_amp + 0.5f : sum;
}

}  // namespace splat
