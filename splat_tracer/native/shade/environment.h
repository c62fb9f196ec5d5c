// The world as an environment image: an equirectangular radiance map (Cycles' orientation)
// looked up bilinearly by direction, and sampled as a light by a 2-D piecewise-constant
// distribution over luminance x sin(theta), so that a small bright sun is found by shadow
// rays instead of by chance.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "base/vec3.h"

namespace splat {

// A direction towards the environment with its radiance and its solid-angle density.
struct EnvironmentSample {
    Vec3 wi, radiance;
    float pdf = 0.f;
    bool valid = false;
};

class EnvironmentMap {
  public:
    // `rgb`: height x width x 3 scene-linear radiance, row 0 at the nadir (v = 0) and row
    // height - 1 at the zenith, column 0 at u = 0 (Cycles' direction_to_equirectangular:
    // u = 0.5 - atan2(y, x) / 2 pi, v = 0.5 + asin(z) / pi). Values must be finite, >= 0.
    EnvironmentMap(const float *rgb, int width, int height);

    // Radiance towards unit direction d, bilinear between pixel centres (wrapping in u,
    // clamped at the poles): what Cycles' Linear interpolation of the image gives.
    Vec3 lookup(Vec3 d) const;
    // A direction drawn with density pdf(d) (solid angle) from two uniform numbers.
    EnvironmentSample sample(float u1, float u2) const;
    // The density with which sample() draws unit direction d (0 where it never does).
    float pdf(Vec3 d) const;
    // Whether there is anything to sample (some pixel of positive luminance).
    bool sampled() const { return total_ > 0.0; }
    // Mean radiance over the sphere (solid-angle weighted): what a constant world of the
    // same power would be.
    Vec3 mean() const { return mean_; }
    int width() const { return width_; }
    int height() const { return height_; }

    static void to_uv(Vec3 d, float *u, float *v);
    static Vec3 from_uv(float u, float v);

  private:
    Vec3 texel(int x, int y) const;
    int width_, height_;
    std::vector<float> rgb_;
    // Sampling: per row the CDF over its columns (width + 1 entries, normalised), and the
    // CDF over rows of the rows' totals (height + 1). The weights are the largest luminance of
    // each pixel's 3x3 neighbourhood -- the support of the bilinear lookup -- times sin(theta).
    std::vector<float> conditional_, marginal_;
    std::vector<float> weight_;  // per pixel, normalised so that their sum is 1
    double total_ = 0.0;
    Vec3 mean_;
};

}  // namespace splat
