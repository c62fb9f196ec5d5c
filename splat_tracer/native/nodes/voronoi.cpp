// The Voronoi Texture node (see voronoi.h).
#include "nodes/voronoi.h"

#include <cmath>

namespace splat {

namespace {

float voronoi_distance(Vec3 a, Vec3 b, int metric, float exponent) {
    const Vec3 d = vabs(a - b);
    switch (metric) {
        case 0: return length(a - b);                                   // EUCLIDEAN
        case 1: return d.x + d.y + d.z;                                 // MANHATTAN
        case 2: return std::fmax(d.x, std::fmax(d.y, d.z));             // CHEBYSHEV
        default:                                                        // MINKOWSKI
            return std::pow(std::pow(d.x, exponent) + std::pow(d.y, exponent) + std::pow(d.z, exponent),
                            1.f / exponent);
    }
}

// Blender's hash of an integer cell to three numbers in 0..1 (the PCG 3-D hash of Jarzynski
// and Olano, "Hash Functions for GPU Rendering", 2020, on signed integers as Blender runs it:
// wrapping products, an arithmetic shift).
Vec3 hash_cell(int32_t x, int32_t y, int32_t z) {
    uint32_t v[3] = {uint32_t(x), uint32_t(y), uint32_t(z)};
    for (uint32_t &c : v) c = c * 1664525u + 1013904223u;
    auto mix = [&] { v[0] += v[1] * v[2], v[1] += v[2] * v[0], v[2] += v[0] * v[1]; };
    mix();
    for (uint32_t &c : v) c ^= uint32_t(int32_t(c) >> 16);
    mix();
    constexpr float k = 1.f / float(0x7FFFFFFF);
    return {float(v[0] & 0x7FFFFFFFu) * k, float(v[1] & 0x7FFFFFFFu) * k, float(v[2] & 0x7FFFFFFFu) * k};
}

}  // namespace

void voronoi_f1(Vec3 p, float exponent, float randomness, int metric, float *distance, Vec3 *colour, Vec3 *position) {
    // Cells beyond int range would overflow: far coordinates are held where they still resolve.
    for (int a = 0; a < 3; ++a) p[a] = std::fmin(std::fmax(p[a], -1e9f), 1e9f);
    const int32_t cx = int32_t(std::floor(p.x)), cy = int32_t(std::floor(p.y)), cz = int32_t(std::floor(p.z));
    const Vec3 local = p - Vec3(float(cx), float(cy), float(cz));
    float best = 3.4e38f;
    int32_t bi = 0, bj = 0, bk = 0;
    Vec3 best_point;
    for (int32_t k = -1; k <= 1; ++k)
        for (int32_t j = -1; j <= 1; ++j)
            for (int32_t i = -1; i <= 1; ++i) {
                const Vec3 point = Vec3(float(i), float(j), float(k)) + hash_cell(cx + i, cy + j, cz + k) * randomness;
                const float d = voronoi_distance(point, local, metric, exponent);
                if (d < best) best = d, bi = i, bj = j, bk = k, best_point = point;
            }
    *distance = best;
    *colour = hash_cell(cx + bi, cy + bj, cz + bk);
    *position = best_point + Vec3(float(cx), float(cy), float(cz));
}

}  // namespace splat
