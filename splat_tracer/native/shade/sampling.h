// Random numbers, sample patterns and the pixel filter. Every random number is a function
// of (pixel, sample, dimension, seed), so an image never depends on the thread count or the
// tile order.
#pragma once

#include <cmath>
#include <cstdint>
#include <vector>

#include "base/vec3.h"

namespace splat {

constexpr float kPi = 3.14159265358979f;

// PCG-style integer hash (Jarzynski & Olano, "Hash Functions for GPU Rendering", 2020).
inline uint32_t pcg_hash(uint32_t v) {
    const uint32_t state = v * 747796405u + 2891336453u;
    const uint32_t word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

// Owen-scrambled Sobol points (Burley, "Practical Hash-based Owen Scrambling", JCGT 2020):
// the first four dimensions of the Sobol sequence, each point's coordinates and its index
// scrambled by hashes. A pixel's first 2^m samples are then stratified in every dimension
// and every pair of one 4D group, the way independent random numbers are not -- less noise
// at equal samples -- while each point stays uniformly distributed, so every estimate is as
// unbiased as with independent numbers. Groups (the pixel and lens; one bounce's BSDF
// sample; one lamp's shadow sample ...) are decorrelated from each other and from other
// pixels by seeds hashed from their keys ("padding"), which needs no tables.
namespace sobol {

constexpr int kDims = 4;

// Direction numbers of the first four Sobol dimensions, as 32-bit binary fractions: the
// van der Corput sequence, then the primitive polynomials x + 1, x^2 + x + 1 and
// x^3 + x + 1 with initial numbers (1), (1, 3), (1, 3, 1) (Joe & Kuo's first dimensions).
struct Directions {
    uint32_t v[kDims][32];
};

constexpr Directions make_directions() {
    Directions d{};
    for (int k = 0; k < 32; ++k) d.v[0][k] = 1u << (31 - k);
    const int degree[kDims] = {0, 1, 2, 3};
    const uint32_t coeffs[kDims] = {0, 0, 1, 1};  // the polynomials' inner coefficients a
    const uint32_t initial[kDims][3] = {{0, 0, 0}, {1, 0, 0}, {1, 3, 0}, {1, 3, 1}};
    for (int dim = 1; dim < kDims; ++dim) {
        const int s = degree[dim];
        for (int k = 0; k < 32; ++k) {
            if (k < s) {
                d.v[dim][k] = initial[dim][k] << (31 - k);
                continue;
            }
            uint32_t x = d.v[dim][k - s] ^ (d.v[dim][k - s] >> s);
            for (int j = 1; j < s; ++j)
                if ((coeffs[dim] >> (s - 1 - j)) & 1u) x ^= d.v[dim][k - j];
            d.v[dim][k] = x;
        }
    }
    return d;
}

inline constexpr Directions kDirections = make_directions();

constexpr uint32_t reverse_bits_constexpr(uint32_t x) {
    uint32_t r = 0;
    for (int k = 0; k < 32; ++k) r |= ((x >> k) & 1u) << (31 - k);
    return r;
}

// Sobol points computed with every bit order reversed (Burley's layout): a table takes the
// index's bits reversed -- the index's Owen scrambling leaves them so -- and gives the
// coordinate's bits reversed -- the coordinate's scrambling wants them so. Per dimension
// and byte of the reversed index, the XOR of the reversed direction numbers of its set
// bits: four lookups a coordinate (a 32-step loop over the bits took 60 ns a 3D point,
// slowing a simple scene's rendering by 20 %). 16 KB.
struct ByteTables {
    uint32_t t[kDims][4][256];
};

constexpr ByteTables make_byte_tables() {
    ByteTables b{};
    const Directions d = make_directions();
    for (int dim = 0; dim < kDims; ++dim)
        for (int byte = 0; byte < 4; ++byte)
            for (int value = 0; value < 256; ++value) {
                uint32_t x = 0;
                for (int bit = 0; bit < 8; ++bit)  // bit 8 byte + bit of the reversed index: index bit 31 - that
                    if ((value >> bit) & 1) x ^= reverse_bits_constexpr(d.v[dim][31 - (8 * byte + bit)]);
                b.t[dim][byte][value] = x;
            }
    return b;
}

inline constexpr ByteTables kByteTables = make_byte_tables();

inline uint32_t reverse_bits(uint32_t x) {
    x = ((x >> 1) & 0x55555555u) | ((x & 0x55555555u) << 1);
    x = ((x >> 2) & 0x33333333u) | ((x & 0x33333333u) << 2);
    x = ((x >> 4) & 0x0f0f0f0fu) | ((x & 0x0f0f0f0fu) << 4);
    x = ((x >> 8) & 0x00ff00ffu) | ((x & 0x00ff00ffu) << 8);
    return (x >> 16) | (x << 16);
}

// Nested uniform (Owen) scrambling of x read as a binary fraction, on its bits reversed:
// each bit is flipped by a hash of the seed and the bits above it. Burley's Laine-Karras-
// style hash, where on the reversed bits multiplying by an even constant lets each bit
// depend on lower ones only. Applied to a sample index it shuffles the samples so that every
// aligned block of 2^m indices stays a block: a pixel's first 2^m samples are still a
// stratified set.
inline uint32_t owen_scramble_reversed(uint32_t x, uint32_t seed) {
    x += seed;
    x ^= x * 0x6c50b47cu;
    x ^= x * 0xb82f1e52u;
    x ^= x * 0xc7afe638u;
    x ^= x * 0x8d22f6e6u;
    return x;
}

// Coordinate `dim` of the Sobol point of the index whose reversed bits are `rindex`, reversed.
inline uint32_t point_reversed(uint32_t rindex, int dim) {
    const auto &t = kByteTables.t[dim];
    return t[0][rindex & 0xffu] ^ t[1][(rindex >> 8) & 0xffu] ^ t[2][(rindex >> 16) & 0xffu] ^ t[3][rindex >> 24];
}

}  // namespace sobol

// The random numbers of one camera sample of one pixel. They depend only on (pixel, sample,
// seed) and on what they are for -- never on the thread, the tile or the round that renders
// the sample -- so a copy replays the same numbers (the shadow catcher's second path).
//
// A path asks for numbers by purpose (a Dim below) at its current vertex; each vertex has
// its own key, chained from its parent's (bounce()). Samples of a pixel with the same key
// and purpose are successive points of one Owen-scrambled Sobol set: the pixel's samples
// stratify each bounce's BSDF sample, each lamp's shadow sample, and so on. A purpose
// drawn `subs` times per sample (shadow_samples, ao_samples) takes sample * subs + sub as
// its index, so the draws of all samples together are stratified as well.
class Sampler {
  public:
    enum Dim : uint32_t {
        kCamera = 1,       // pixel filter x, y; lens u, v
        kBsdf = 2,         // direction u1, u2; lobe pick
        kRoulette = 3,     // Russian roulette of the ray that reached this vertex
        kLamp = 4,         // + kDimStride x lamp: a lamp's point u1, u2
        kMeshLight = 5,    // point u1, u2; emitter pick
        kOcclusion = 6,    // sky AO direction u1, u2
        kTransparent = 7,  // + kDimStride x layer: passing a partly transparent surface
        kTime = 8,         // the camera ray's time in the shutter (motion blur)
        kAoPass = 9,       // the AO pass's direction u1, u2 (camera vertex only)
        kShaderAo = 10,    // + kDimStride x row: an Ambient Occlusion node's directions u1, u2
        kEnvironment = 13,  // the environment light's direction u1, u2 (a value no other Dim takes)
    };
    // Added per lamp or layer to a Dim: any constant above the Dims keeps the keys apart.
    static constexpr uint32_t kDimStride = 16;

    Sampler(uint32_t pixel, uint32_t sample, uint32_t seed)
        : key_(pcg_hash(pixel ^ pcg_hash(seed))), sample_(sample) {}

    // `count` (up to 4) numbers in [0, 1) for `dim`; draw `sub` of `subs` per sample.
    void get(uint32_t dim, float *u, int count, uint32_t sub = 0, uint32_t subs = 1) const {
        uint32_t x[sobol::kDims];
        get_bits(dim, x, count, sub, subs);
        for (int d = 0; d < count; ++d) u[d] = to_unit(x[d]);
    }
    float get1(uint32_t dim, uint32_t sub = 0, uint32_t subs = 1) const {
        float u;
        get(dim, &u, 1, sub, subs);
        return u;
    }
    // The same numbers as 32-bit binary fractions.
    void get_bits(uint32_t dim, uint32_t *x, int count, uint32_t sub = 0, uint32_t subs = 1) const {
        const uint32_t group = pcg_hash(key_ ^ (dim * 0x9e3779b9u));  // golden ratio: dims spread over the bits
        const uint32_t rindex = sobol::owen_scramble_reversed(sobol::reverse_bits(sample_ * subs + sub), group);
        for (int d = 0; d < count; ++d)
            x[d] = sobol::reverse_bits(
                sobol::owen_scramble_reversed(sobol::point_reversed(rindex, d), pcg_hash(group + uint32_t(d) + 1u)));
    }
    // The sampler of the path's next vertex, reached by `branch` (a mirror and a glass ray
    // from one point are two branches, whose numbers must differ).
    Sampler bounce(uint32_t branch) const {
        Sampler next = *this;
        next.key_ = pcg_hash(key_ ^ pcg_hash(branch + 0x9e3779b9u));  // golden-ratio salt: branch 0 changes the key too
        return next;
    }
    static float to_unit(uint32_t x) { return float(x >> 8) * (1.f / 16777216.f); }  // 24 bits: exact, < 1

  private:
    uint32_t key_;  // the pixel's and the vertex's: a hash of the pixel, the seed and the branches taken
    uint32_t sample_;
};

// Pixel filter importance sampling, as Cycles does it: a separable filter's 1D inverse CDF
// in a table, so that each sample lands where the filter weighs it and all weights are 1.
class PixelFilter {
  public:
    enum Type { Box = 0, Gaussian = 1, BlackmanHarris = 2 };
    PixelFilter(int type, float width);
    // Offset from the pixel centre for a uniform u in [0, 1); 0 for u = 0.5.
    float offset(float u) const;

  private:
    std::vector<float> table_;  // inverse CDF over [0, 1]
};

inline Vec3 orthogonal(Vec3 n) {  // any unit vector perpendicular to unit n
    return std::fabs(n.x) > 0.9f ? normalize(cross(n, Vec3(0, 1, 0))) : normalize(cross(n, Vec3(1, 0, 0)));
}

// Cosine-weighted direction about unit n (pdf cos / pi).
inline Vec3 sample_cosine(Vec3 n, float u1, float u2) {
    const float r = std::sqrt(u1), phi = 2.f * kPi * u2;
    const Vec3 t = orthogonal(n), b = cross(n, t);
    return normalize(t * (r * std::cos(phi)) + b * (r * std::sin(phi)) + n * std::sqrt(std::fmax(0.f, 1.f - u1)));
}

// Uniform point on the unit disk (concentric map: strata stay strata).
inline void sample_disk(float u1, float u2, float *x, float *y) {
    const float a = 2.f * u1 - 1.f, b = 2.f * u2 - 1.f;
    if (a == 0.f && b == 0.f) {
        *x = *y = 0.f;
        return;
    }
    float r, phi;
    if (a * a > b * b) r = a, phi = (kPi / 4.f) * (b / a);
    else r = b, phi = (kPi / 2.f) - (kPi / 4.f) * (a / b);
    *x = r * std::cos(phi), *y = r * std::sin(phi);
}

// Uniform point of the regular polygon with `corners` corners on the unit circle, at angles
// rotation + (2k + 1) pi / corners: Cycles' regular_polygon_sample (a corner's triangle
// picked by u1, a uniform point of it), so that a polygonal aperture's bokeh has Cycles'
// shape and orientation.
inline void sample_polygon(int corners, float rotation, float u1, float u2, float *x, float *y) {
    const float n = float(corners);
    const float corner = std::floor(u1 * n);
    float u = u1 * n - corner, v = u2;
    u = std::sqrt(u);  // uniform barycentric weights of the triangle
    v = v * u;
    u = 1.f - u;
    const float angle = kPi / n;
    const float px = (u + v) * std::cos(angle), py = (u - v) * std::sin(angle);
    const float r = rotation + corner * 2.f * angle, cr = std::cos(r), sr = std::sin(r);
    *x = cr * px - sr * py, *y = sr * px + cr * py;
}

// The power heuristic (Veach, beta = 2), as Cycles weighs light and BSDF samples: the weight
// of a sample drawn with density a from a technique that could also be drawn with density b.
inline float power_heuristic(float a, float b) {
    const float a2 = a * a, b2 = b * b;
    return a2 + b2 > 0.f ? a2 / (a2 + b2) : 0.f;
}

// Uniform direction in the cone of half-angle acos(cos_max) about unit axis.
inline Vec3 sample_cone(Vec3 axis, float cos_max, float u1, float u2) {
    const float c = 1.f - u1 * (1.f - cos_max), s = std::sqrt(std::fmax(0.f, 1.f - c * c)), phi = 2.f * kPi * u2;
    const Vec3 t = orthogonal(axis), b = cross(axis, t);
    return normalize(t * (s * std::cos(phi)) + b * (s * std::sin(phi)) + axis * c);
}

}  // namespace splat
