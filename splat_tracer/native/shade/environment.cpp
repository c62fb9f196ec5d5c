#include "shade/environment.h"

#include <algorithm>
#include <cmath>

#include "shade/sampling.h"
#include "shade/shading.h"

namespace splat {

namespace {

// The first index i in [0, n) with cdf[i + 1] > u (cdf has n + 1 entries from 0 to 1).
int find_interval(const float *cdf, int n, float u) {
    const float *it = std::upper_bound(cdf + 1, cdf + n + 1, u);
    return std::clamp(int(it - (cdf + 1)), 0, n - 1);
}

}  // namespace

void EnvironmentMap::to_uv(Vec3 d, float *u, float *v) {
    *u = 0.5f - std::atan2(d.y, d.x) * (0.5f / kPi);
    *v = 0.5f + std::atan2(d.z, std::hypot(d.x, d.y)) * (1.f / kPi);
}

Vec3 EnvironmentMap::from_uv(float u, float v) {
    const float phi = (0.5f - u) * 2.f * kPi, elevation = (v - 0.5f) * kPi;
    const float c = std::cos(elevation);
    return Vec3(c * std::cos(phi), c * std::sin(phi), std::sin(elevation));
}

EnvironmentMap::EnvironmentMap(const float *rgb, int width, int height)
    : width_(width), height_(height), rgb_(rgb, rgb + size_t(width) * size_t(height) * 3) {
    const int w = width_, h = height_;
    // Per pixel the largest luminance of its row neighbours (wrapping in u), then of its
    // column neighbours of that: the 3x3 maximum in two passes.
    std::vector<float> across(size_t(w) * size_t(h));
    double mean[3] = {0, 0, 0}, solid = 0;
    std::vector<float> lum(static_cast<size_t>(w));
    for (int y = 0; y < h; ++y) {
        // The row's share of the sphere is proportional to sin(theta) at its centre.
        const double sin_theta = std::sin(kPi * (y + 0.5) / h);
        double row[3] = {0, 0, 0};
        for (int x = 0; x < w; ++x) {
            const Vec3 c = texel(x, y);
            lum[x] = std::fmax(luminance(c), 0.f);
            row[0] += c.x, row[1] += c.y, row[2] += c.z;
        }
        for (int k = 0; k < 3; ++k) mean[k] += row[k] * sin_theta;
        solid += sin_theta * w;
        float *a = &across[size_t(y) * w];
        for (int x = 0; x < w; ++x)
            a[x] = std::fmax(lum[x], std::fmax(lum[x > 0 ? x - 1 : w - 1], lum[x + 1 < w ? x + 1 : 0]));
    }
    mean_ = Vec3(float(mean[0] / solid), float(mean[1] / solid), float(mean[2] / solid));
    weight_.assign(size_t(w) * size_t(h), 0.f);
    std::vector<double> row_total(size_t(h), 0.0);
    for (int y = 0; y < h; ++y) {
        const float sin_theta = float(std::sin(kPi * (y + 0.5) / h));
        const float *up = &across[size_t(std::min(y + 1, h - 1)) * w], *mid = &across[size_t(y) * w],
                    *down = &across[size_t(std::max(y - 1, 0)) * w];
        float *out = &weight_[size_t(y) * w];
        double sum = 0;
        for (int x = 0; x < w; ++x) {
            out[x] = std::fmax(mid[x], std::fmax(up[x], down[x])) * sin_theta;
            sum += out[x];
        }
        row_total[y] = sum;
        total_ += sum;
    }
    if (!(total_ > 0.0) || !std::isfinite(total_)) {
        total_ = 0.0;
        return;
    }
    conditional_.assign(size_t(h) * size_t(w + 1), 0.f);
    marginal_.assign(size_t(h) + 1, 0.f);
    double rows = 0;
    for (int y = 0; y < h; ++y) {
        float *cdf = &conditional_[size_t(y) * (w + 1)];
        double acc = 0;
        for (int x = 0; x < w; ++x) {
            acc += weight_[size_t(y) * w + x];
            cdf[x + 1] = row_total[y] > 0 ? float(acc / row_total[y]) : float(x + 1) / float(w);
        }
        cdf[w] = 1.f;
        rows += row_total[y];
        marginal_[y + 1] = float(rows / total_);
    }
    marginal_[h] = 1.f;
    for (float &f : weight_) f = float(f / total_);
}

Vec3 EnvironmentMap::texel(int x, int y) const {
    const float *p = &rgb_[(size_t(y) * size_t(width_) + size_t(x)) * 3];
    return Vec3(p[0], p[1], p[2]);
}

Vec3 EnvironmentMap::lookup(Vec3 d) const {
    float u, v;
    to_uv(d, &u, &v);
    const float fx = u * width_ - 0.5f, fy = v * height_ - 0.5f;
    const float x0f = std::floor(fx), y0f = std::floor(fy);
    const float tx = fx - x0f, ty = fy - y0f;
    int x0 = int(x0f) % width_;
    if (x0 < 0) x0 += width_;
    const int x1 = (x0 + 1) % width_;
    const int y0 = std::clamp(int(y0f), 0, height_ - 1), y1 = std::clamp(int(y0f) + 1, 0, height_ - 1);
    return (texel(x0, y0) * (1.f - tx) + texel(x1, y0) * tx) * (1.f - ty) +
           (texel(x0, y1) * (1.f - tx) + texel(x1, y1) * tx) * ty;
}

EnvironmentSample EnvironmentMap::sample(float u1, float u2) const {
    EnvironmentSample s;
    if (!sampled()) return s;
    const int y = find_interval(marginal_.data(), height_, u2);
    const float *cdf = &conditional_[size_t(y) * (width_ + 1)];
    const int x = find_interval(cdf, width_, u1);
    // Uniform within the pixel: the numbers' position within the chosen intervals.
    const float dv = marginal_[y + 1] - marginal_[y], du = cdf[x + 1] - cdf[x];
    const float fv = dv > 0.f ? std::clamp((u2 - marginal_[y]) / dv, 0.f, 1.f) : 0.5f;
    const float fu = du > 0.f ? std::clamp((u1 - cdf[x]) / du, 0.f, 1.f) : 0.5f;
    const float u = (x + fu) / width_, v = (y + fv) / height_;
    const float sin_theta = std::cos((v - 0.5f) * kPi);
    if (!(sin_theta > 0.f)) return s;
    s.wi = from_uv(u, v);
    // Pixel probability / pixel solid angle (2 pi^2 sin(theta) / (w h) per unit of u x v).
    s.pdf = weight_[size_t(y) * width_ + x] * float(width_) * float(height_) / (2.f * kPi * kPi * sin_theta);
    if (!(s.pdf > 0.f)) return s;
    s.radiance = lookup(s.wi);
    s.valid = true;
    return s;
}

float EnvironmentMap::pdf(Vec3 d) const {
    if (!sampled()) return 0.f;
    float u, v;
    to_uv(d, &u, &v);
    const float sin_theta = std::sqrt(std::fmax(0.f, 1.f - d.z * d.z));
    if (!(sin_theta > 0.f)) return 0.f;
    const int x = std::clamp(int(u * width_), 0, width_ - 1), y = std::clamp(int(v * height_), 0, height_ - 1);
    return weight_[size_t(y) * width_ + x] * float(width_) * float(height_) / (2.f * kPi * kPi * sin_theta);
}

}  // namespace splat
