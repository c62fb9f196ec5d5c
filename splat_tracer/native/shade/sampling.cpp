#include "shade/sampling.h"

#include <algorithm>

namespace splat {

PixelFilter::PixelFilter(int type, float width) {
    // Tabulate the filter's 1D profile over [-width/2, width/2], integrate, invert.
    constexpr int kSteps = 1024;  // the inverse CDF is linear between steps: 1/1024 px error
    // Cycles spreads Blackman-Harris over twice the width setting (its window falls to
    // nearly 0 at the ends, so this keeps the same visual sharpness); so do we.
    if (type == BlackmanHarris) width *= 2.f;
    const float half = 0.5f * width;
    std::vector<double> cdf(kSteps + 1, 0.0);
    for (int i = 0; i < kSteps; ++i) {
        const double x = -half + (i + 0.5) * width / kSteps;  // the step's middle
        double w = 1.0;
        if (type == Gaussian) {
            // Cycles' Gaussian: exp(-2 (6 x / width)^2).
            const double v = 6.0 * x / width;
            w = std::exp(-2.0 * v * v);
        } else if (type == BlackmanHarris) {
            const double t = 2.0 * kPi * (x / width + 0.5);
            w = 0.35875 - 0.48829 * std::cos(t) + 0.14128 * std::cos(2 * t) - 0.01168 * std::cos(3 * t);
        }
        cdf[i + 1] = cdf[i] + std::max(w, 0.0);
    }
    for (double &c : cdf) c /= cdf[kSteps];
    table_.resize(kSteps + 1);
    int j = 0;
    for (int i = 0; i <= kSteps; ++i) {
        const double u = double(i) / kSteps;
        while (j < kSteps - 1 && cdf[j + 1] < u) ++j;
        const double span = cdf[j + 1] - cdf[j];
        const double f = span > 0 ? (u - cdf[j]) / span : 0.5;
        table_[i] = float(-half + (j + std::clamp(f, 0.0, 1.0)) * width / kSteps);
    }
}

float PixelFilter::offset(float u) const {
    const float x = u * float(table_.size() - 1);
    const int i = std::min(int(x), int(table_.size()) - 2);
    const float f = x - float(i);
    return table_[i] * (1.f - f) + table_[i + 1] * f;
}

}  // namespace splat
