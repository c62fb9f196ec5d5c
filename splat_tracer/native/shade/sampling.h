// Random numbers, sample patterns and the pixel filter. Every random number is a hash of
// (pixel, sample, dimension, seed), so an image never depends on the thread count or the
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

// The random stream of one camera sample: next() gives independent numbers in [0, 1).
struct Sampler {
    uint32_t state;
    Sampler(uint32_t pixel, uint32_t sample, uint32_t seed)
        : state(pcg_hash(pixel ^ pcg_hash(sample ^ pcg_hash(seed)))) {}
    float next() {
        state = pcg_hash(state);
        return float(state >> 8) * (1.f / 16777216.f);  // 24 bits: exactly representable, < 1
    }
};

// The R2 sequence (Roberts 2018): the n-th point of a 2D low-discrepancy set, with point 0
// at (0.5, 0.5), so that one sample per pixel is the pixel centre.
inline void r2_point(uint32_t n, float *x, float *y) {
    constexpr double a1 = 0.7548776662466927, a2 = 0.5698402909980532;  // 1/g, 1/g^2 for the plastic number
    const double fx = 0.5 + a1 * n, fy = 0.5 + a2 * n;
    *x = float(fx - std::floor(fx)), *y = float(fy - std::floor(fy));
}

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
