#include "nodes/gabor.h"

#include <cmath>

#include "nodes/noise.h"

namespace splat {
namespace {

constexpr float kPi = 3.14159265358979323846f;
// Kernels per cell: a fixed count (stratified sampling, as Cycles after Tavernier et al. 2019).
constexpr int kImpulses = 8;

struct Phasor {
    float re = 0.f, im = 0.f;
};

// Blender's hashes of float words to 0..1 (lookup3 of their bits).
float hash3(float x, float y, float z) { return to_unit(hash_uint3(float_bits(x), float_bits(y), float_bits(z))); }
float hash4(float x, float y, float z, float w) {
    return to_unit(hash_uint4(float_bits(x), float_bits(y), float_bits(z), float_bits(w)));
}

// One kernel at `d` from its centre (|d|^2 < 1): envelope exp(-pi r^2) x Hann window
// (1 + cos(pi r^2)) / 2, as a phasor of angle 2 pi d . frequency vector.
Phasor kernel(float r2, float angle) {
    const float envelope = std::exp(-kPi * r2) * (0.5f + 0.5f * std::cos(kPi * r2));
    return {envelope * std::cos(angle), envelope * std::sin(angle)};
}

Phasor cell_2d(float cx, float cy, float px, float py, float frequency, float isotropy, float orientation) {
    Phasor sum;
    for (int i = 0; i < kImpulses; ++i) {
        const float k = float(i * 3);
        // Seeds: (cell, 3i) orientation, (cell, 3i + 1) centre, (cell, 3i + 2) weight. The
        // random orientation spans pi: the kernel is symmetric under a half turn.
        const float angle = orientation + (hash3(cx, cy, k) - 0.5f) * kPi * isotropy;
        const float centre_x = hash3(cx, cy, k + 1.f), centre_y = hash3(k + 1.f, cx, cy);
        const float dx = px - centre_x, dy = py - centre_y, r2 = dx * dx + dy * dy;
        if (r2 >= 1.f) continue;  // the window is zero beyond unit distance
        const float weight = hash3(cx, cy, k + 2.f) < 0.5f ? -1.f : 1.f;
        const Phasor p = kernel(r2, 2.f * kPi * (dx * frequency * std::cos(angle) + dy * frequency * std::sin(angle)));
        sum.re += weight * p.re, sum.im += weight * p.im;
    }
    return sum;
}

Vec3 orientation_3d_of(Vec3 o, float isotropy, float cx, float cy, float cz, float k) {
    if (isotropy == 0.f) return o;
    // Randomised in spherical coordinates, each angle by up to pi x isotropy.
    float inclination = std::acos(o.z);
    float azimuth = (o.y < 0.f ? -1.f : 1.f) * std::acos(o.x / std::sqrt(o.x * o.x + o.y * o.y));
    inclination += hash4(cx, cy, cz, k) * kPi * isotropy;
    azimuth += hash4(cz, cx, k, cy) * kPi * isotropy;
    return {std::sin(inclination) * std::cos(azimuth), std::sin(inclination) * std::sin(azimuth), std::cos(inclination)};
}

Phasor cell_3d(Vec3 cell, Vec3 p, float frequency, float isotropy, Vec3 orientation) {
    Phasor sum;
    for (int i = 0; i < kImpulses; ++i) {
        const float k = float(i * 3);
        const Vec3 o = orientation_3d_of(orientation, isotropy, cell.x, cell.y, cell.z, k);
        const float k1 = k + 1.f;
        const Vec3 centre(hash4(cell.x, cell.y, cell.z, k1), hash4(cell.z, cell.x, k1, cell.y),
                          hash4(k1, cell.z, cell.y, cell.x));
        const Vec3 d = p - centre;
        const float r2 = dot(d, d);
        if (r2 >= 1.f) continue;
        const float weight = hash4(cell.x, cell.y, cell.z, k + 2.f) < 0.5f ? -1.f : 1.f;
        const Phasor q = kernel(r2, 2.f * kPi * dot(d, o * frequency));
        sum.re += weight * q.re, sum.im += weight * q.im;
    }
    return sum;
}

}  // namespace

GaborOutputs gabor_texture(Vec3 coordinates, float scale, float frequency, float anisotropy, float orientation_2d,
                           Vec3 orientation_3d, bool three_d) {
    const Vec3 c = coordinates * scale;
    const float isotropy = 1.f - std::fmin(std::fmax(anisotropy, 0.f), 1.f);
    frequency = std::fmax(0.001f, frequency);
    Phasor sum;
    float deviation;
    if (!three_d) {
        const float fx = std::floor(c.x), fy = std::floor(c.y), lx = c.x - fx, ly = c.y - fy;
        for (int j = -1; j <= 1; ++j)
            for (int i = -1; i <= 1; ++i) {
                const Phasor p = cell_2d(fx + float(i), fy + float(j), lx - float(i), ly - float(j), frequency,
                                         isotropy, orientation_2d);
                sum.re += p.re, sum.im += p.im;
            }
        // sqrt(impulses x second moment of the +-1 weights (1/2) x the squared kernel's
        // integral (its limit for large frequencies, 1/4 in 2-D, 1/(4 sqrt 2) in 3-D)).
        deviation = std::sqrt(kImpulses * 0.5f * 0.25f);
    } else {
        const float len = length(orientation_3d);
        const Vec3 o = orientation_3d * (1.f / len);  // Cycles' normalize: a zero vector gives NaN there too
        const Vec3 cell(std::floor(c.x), std::floor(c.y), std::floor(c.z)), local = c - cell;
        for (int k = -1; k <= 1; ++k)
            for (int j = -1; j <= 1; ++j)
                for (int i = -1; i <= 1; ++i) {
                    const Vec3 offset{float(i), float(j), float(k)};
                    const Phasor p = cell_3d(cell + offset, local - offset, frequency, isotropy, o);
                    sum.re += p.re, sum.im += p.im;
                }
        deviation = std::sqrt(kImpulses * 0.5f * (1.f / (4.f * std::sqrt(2.f))));
    }
    const float norm = 6.f * deviation;  // Cycles' empirical normalisation: six deviations
    return {sum.im / norm * 0.5f + 0.5f, (std::atan2(sum.im, sum.re) + kPi) / (2.f * kPi),
            std::sqrt(sum.re * sum.re + sum.im * sum.im) / norm};
}

}  // namespace splat
