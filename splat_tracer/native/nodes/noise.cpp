// Blender's noise (see noise.h). Every dimension follows the same definitions; the 3-D ones
// are written out as they were first (the Noise node's 3-D fBm renders bit for bit as before).
#include "nodes/noise.h"

#include <cmath>
#include <cstddef>

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

inline float fade(float t) { return t * t * t * (t * (t * 6.f - 15.f) + 10.f); }
inline float flip(float v, uint32_t bit) { return bit ? -v : v; }
// The fBm blend as the 3-D node has always computed it (kept: its renders stay bit for bit).
inline float lerp(float a, float b, float t) { return (1.f - t) * a + t * b; }

// Perlin's gradients: 1-D a slope of 1..8 either way; 2-D eight directions (one axis
// doubled); 3-D the twelve cube edges (four repeated); 4-D 32 edges of the hypercube.
inline float grad1(uint32_t hash, float x) {
    const uint32_t h = hash & 15u;
    return flip(1.f + float(h & 7u), h & 8u) * x;
}
inline float grad2(uint32_t hash, float x, float y) {
    const uint32_t h = hash & 7u;
    const float u = h < 4u ? x : y, v = 2.f * (h < 4u ? y : x);
    return flip(u, h & 1u) + flip(v, h & 2u);
}
inline float grad3(uint32_t hash, float x, float y, float z) {
    const uint32_t h = hash & 15u;
    const float u = h < 8u ? x : y;
    const float vt = (h == 12u || h == 14u) ? x : z;
    const float v = h < 4u ? y : vt;
    return ((h & 1u) ? -u : u) + ((h & 2u) ? -v : v);
}
inline float grad4(uint32_t hash, float x, float y, float z, float w) {
    const uint32_t h = hash & 31u;
    const float u = h < 24u ? x : y, v = h < 16u ? y : z, s = h < 8u ? z : w;
    return flip(u, h & 1u) + flip(v, h & 2u) + flip(s, h & 4u);
}

// Points of 2 and 4 dimensions, with what the fractal sums need of them.
struct Vec2 {
    float v[2];
};
struct Vec4 {
    float v[4];
};
template <typename V> V add(V a, V b) {
    for (size_t i = 0; i < sizeof(a.v) / sizeof(float); ++i) a.v[i] += b.v[i];
    return a;
}
template <typename V> V mul(V a, float s) {
    for (size_t i = 0; i < sizeof(a.v) / sizeof(float); ++i) a.v[i] *= s;
    return a;
}
inline Vec2 operator+(Vec2 a, Vec2 b) { return add(a, b); }
inline Vec4 operator+(Vec4 a, Vec4 b) { return add(a, b); }
inline Vec2 operator*(Vec2 a, float s) { return mul(a, s); }
inline Vec4 operator*(Vec4 a, float s) { return mul(a, s); }

// Blender repeats the noise every 100000 units (float precision), nudging beyond 1e6.
inline float wrap_coordinate(float x) {
    const float correction = std::fabs(x) >= 1000000.f ? 0.5f : 0.f;
    return std::fmod(x, 100000.f) + correction;
}
// The cell of a wrapped coordinate (|x| < 1e5 + 1: always an int) and the offset in it.
inline int cell(float x, float *f) {
    const int i = int(std::floor(x));
    *f = x - float(i);
    return i;
}

// Signed Perlin noise, about -1..1 (Blender's scale per dimension), 0 for a non-finite input.
float snoise(float p) {
    if (!std::isfinite(p)) return 0.f;
    float fx;
    const int X = cell(wrap_coordinate(p), &fx);
    const float r = mix(grad1(hash_words(1, uint32_t(X), 0, 0), fx),
                        grad1(hash_words(1, uint32_t(X + 1), 0, 0), fx - 1.f), fade(fx));
    return std::isfinite(r) ? 0.2500f * r : 0.f;
}

float snoise(Vec2 p) {
    if (!std::isfinite(p.v[0]) || !std::isfinite(p.v[1])) return 0.f;
    float fx, fy;
    const int X = cell(wrap_coordinate(p.v[0]), &fx), Y = cell(wrap_coordinate(p.v[1]), &fy);
    auto g = [&](int dx, int dy) {
        return grad2(hash_words(2, uint32_t(X + dx), uint32_t(Y + dy), 0), fx - float(dx), fy - float(dy));
    };
    const float u = fade(fx), v = fade(fy);
    const float r = mix(mix(g(0, 0), g(1, 0), u), mix(g(0, 1), g(1, 1), u), v);
    return std::isfinite(r) ? 0.6616f * r : 0.f;
}

float snoise(Vec3 p) { return perlin_signed(p); }

float snoise(Vec4 p) {
    int c[4];
    float f[4], s[4];
    for (int i = 0; i < 4; ++i) {
        if (!std::isfinite(p.v[i])) return 0.f;
        c[i] = cell(wrap_coordinate(p.v[i]), &f[i]);
        s[i] = fade(f[i]);
    }
    // The 16 corners' gradients, interpolated along x, then y, z and w.
    float layer[2];
    for (int dw = 0; dw < 2; ++dw) {
        float plane[2];
        for (int dz = 0; dz < 2; ++dz) {
            float line[2];
            for (int dy = 0; dy < 2; ++dy) {
                float g[2];
                for (int dx = 0; dx < 2; ++dx)
                    g[dx] = grad4(hash_uint4(uint32_t(c[0] + dx), uint32_t(c[1] + dy), uint32_t(c[2] + dz),
                                             uint32_t(c[3] + dw)),
                                  f[0] - float(dx), f[1] - float(dy), f[2] - float(dz), f[3] - float(dw));
                line[dy] = mix(g[0], g[1], s[0]);
            }
            plane[dz] = mix(line[0], line[1], s[1]);
        }
        layer[dw] = mix(plane[0], plane[1], s[2]);
    }
    const float r = mix(layer[0], layer[1], s[3]);
    return std::isfinite(r) ? 0.8344f * r : 0.f;
}

// The fractal sums of Blender's Noise Texture node, over octaves of `lacunarity` times the
// frequency and `roughness` times the amplitude; a fractional detail blends in a last octave.
template <typename P> float fbm(P p, float detail, float roughness, float lacunarity, bool normalize) {
    float scale = 1.f, amp = 1.f, max_amp = 0.f, sum = 0.f;
    for (int i = 0; i <= int(detail); ++i) {
        sum += snoise(p * scale) * amp;
        max_amp += amp;
        amp *= roughness;
        scale *= lacunarity;
    }
    const float rest = detail - std::floor(detail);
    if (rest != 0.f) {
        const float sum2 = sum + snoise(p * scale) * amp;
        return normalize ? lerp(0.5f * sum / max_amp + 0.5f, 0.5f * sum2 / (max_amp + amp) + 0.5f, rest)
                         : lerp(sum, sum2, rest);
    }
    return normalize ? 0.5f * sum / max_amp + 0.5f : sum;
}

// Multifractal: the octaves multiply (1 + amplitude x noise).
template <typename P> float multifractal(P p, float detail, float roughness, float lacunarity) {
    float value = 1.f, amp = 1.f;
    for (int i = 0; i <= int(detail); ++i) {
        value *= amp * snoise(p) + 1.f;
        amp *= roughness;
        p = p * lacunarity;
    }
    const float rest = detail - std::floor(detail);
    if (rest != 0.f) value *= rest * amp * snoise(p) + 1.f;
    return value;
}

// Heterogeneous terrain: each octave scaled by the value so far (smooth valleys, rough peaks).
template <typename P> float hetero_terrain(P p, float detail, float roughness, float lacunarity, float offset) {
    float amp = roughness;
    float value = offset + snoise(p);
    p = p * lacunarity;
    for (int i = 1; i <= int(detail); ++i) {
        value += (snoise(p) + offset) * amp * value;
        amp *= roughness;
        p = p * lacunarity;
    }
    const float rest = detail - std::floor(detail);
    if (rest != 0.f) value += rest * ((snoise(p) + offset) * amp * value);
    return value;
}

// Hybrid additive/multiplicative multifractal: octaves weighted by gain x the previous
// signal (at most 1), stopping once the weight is negligible (Blender's 0.001).
template <typename P>
float hybrid_multifractal(P p, float detail, float roughness, float lacunarity, float offset, float gain) {
    float amp = 1.f, value = 0.f, weight = 1.f;
    for (int i = 0; weight > 0.001f && i <= int(detail); ++i) {
        if (weight > 1.f) weight = 1.f;
        const float signal = (snoise(p) + offset) * amp;
        amp *= roughness;
        value += weight * signal;
        weight *= gain * signal;
        p = p * lacunarity;
    }
    const float rest = detail - std::floor(detail);
    if (rest != 0.f && weight > 0.001f) {
        if (weight > 1.f) weight = 1.f;
        value += rest * weight * ((snoise(p) + offset) * amp);
    }
    return value;
}

// Ridged multifractal: (offset - |noise|)^2 per octave, weighted by gain x the previous one
// (within 0..1). Blender reads no fractional detail here: only whole octaves.
template <typename P>
float ridged_multifractal(P p, float detail, float roughness, float lacunarity, float offset, float gain) {
    float amp = roughness;
    float signal = offset - std::fabs(snoise(p));
    signal *= signal;
    float value = signal;
    for (int i = 1; i <= int(detail); ++i) {
        p = p * lacunarity;
        const float weight = std::fmin(std::fmax(signal * gain, 0.f), 1.f);
        signal = offset - std::fabs(snoise(p));
        signal *= signal;
        signal *= weight;
        value += signal * amp;
        amp *= roughness;
    }
    return value;
}

template <typename P> float fractal(P p, NoiseType type, const NoiseParams &q, bool normalize) {
    switch (type) {
        case NoiseType::Multifractal: return multifractal(p, q.detail, q.roughness, q.lacunarity);
        case NoiseType::RidgedMultifractal:
            return ridged_multifractal(p, q.detail, q.roughness, q.lacunarity, q.offset, q.gain);
        case NoiseType::HybridMultifractal:
            return hybrid_multifractal(p, q.detail, q.roughness, q.lacunarity, q.offset, q.gain);
        case NoiseType::HeteroTerrain: return hetero_terrain(p, q.detail, q.roughness, q.lacunarity, q.offset);
        default: return fbm(p, q.detail, q.roughness, q.lacunarity, normalize);
    }
}

// A point offset by a fixed pseudo-random amount (100..200 per axis) per seed: the seeds of
// the distortion and of the colour's other two channels. 1-D hashes the seed alone; more
// dimensions hash (seed, axis).
inline float offset_axis(float seed, int axis) {
    return 100.f + to_unit(hash_words(2, float_bits(seed), float_bits(float(axis)), 0)) * 100.f;
}
inline void random_offset(float seed, float *out) { *out = 100.f + to_unit(hash_words(1, float_bits(seed), 0, 0)) * 100.f; }
inline void random_offset(float seed, Vec2 *out) {
    for (int i = 0; i < 2; ++i) out->v[i] = offset_axis(seed, i);
}
inline void random_offset(float seed, Vec3 *out) { *out = {offset_axis(seed, 0), offset_axis(seed, 1), offset_axis(seed, 2)}; }
inline void random_offset(float seed, Vec4 *out) {
    for (int i = 0; i < 4; ++i) out->v[i] = offset_axis(seed, i);
}
template <typename P> P offset_by(P p, float seed) {
    P o;
    random_offset(seed, &o);
    return p + o;
}
inline float &axis(float &p, int) { return p; }
inline float &axis(Vec2 &p, int i) { return p.v[i]; }
inline float &axis(Vec3 &p, int i) { return p[i]; }
inline float &axis(Vec4 &p, int i) { return p.v[i]; }

// The node in DIMS dimensions: distortion (each axis moved by noise at an offset point, seeds
// 0..DIMS-1), the fractal, and the colour's two more channels (seeds DIMS and DIMS + 1).
template <int DIMS, typename P>
float texture(P p, NoiseType type, const NoiseParams &q, bool normalize, Vec3 *colour) {
    if (q.distortion != 0.f) {
        P moved = p;
        for (int i = 0; i < DIMS; ++i) axis(moved, i) += snoise(offset_by(p, float(i))) * q.distortion;
        p = moved;
    }
    const float value = fractal(p, type, q, normalize);
    if (colour)
        *colour = {value, fractal(offset_by(p, float(DIMS)), type, q, normalize),
                   fractal(offset_by(p, float(DIMS + 1)), type, q, normalize)};
    return value;
}

}  // namespace

uint32_t hash_words(int n, uint32_t x, uint32_t y, uint32_t z) {
    uint32_t a, b, c;
    a = b = c = 0xdeadbeefu + (uint32_t(n) << 2) + 13u;
    if (n >= 3) c += z;
    if (n >= 2) b += y;
    a += x;
    final_mix(a, b, c);
    return c;
}

uint32_t hash_uint(uint32_t kx) { return hash_words(1, kx, 0, 0); }
uint32_t hash_uint2(uint32_t kx, uint32_t ky) { return hash_words(2, kx, ky, 0); }
uint32_t hash_uint3(uint32_t kx, uint32_t ky, uint32_t kz) { return hash_words(3, kx, ky, kz); }

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

float perlin_signed(Vec3 p) {
    // A non-finite input gives 0 (as the check of the result below always made it), before
    // its cell is converted to an int (undefined for inf and NaN).
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) return 0.f;
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
    return fbm(p, detail, roughness, lacunarity, normalize);
}

float noise_texture(int dimensions, NoiseType type, Vec3 vector, const NoiseParams &q, bool normalize, Vec3 *colour) {
    // Blender's bounds: at most 15 octaves after the first, no negative roughness.
    NoiseParams c = q;
    c.detail = std::fmin(std::fmax(q.detail, 0.f), 15.f);
    c.roughness = std::fmax(q.roughness, 0.f);
    const Vec3 v = vector * q.scale;
    const float w = q.w * q.scale;
    switch (dimensions) {
        case 1: return texture<1>(w, type, c, normalize, colour);
        case 2: return texture<2>(Vec2{{v.x, v.y}}, type, c, normalize, colour);
        case 4: return texture<4>(Vec4{{v.x, v.y, v.z, w}}, type, c, normalize, colour);
        default: return texture<3>(v, type, c, normalize, colour);
    }
}

}  // namespace splat
