#include "nodes/image.h"

#include <cmath>
#include <cstdlib>
#include <string>

#include "base/errors.h"

namespace splat {

float srgb_to_linear(float c) {  // the sRGB standard's decoding (IEC 61966-2-1)
    if (c < 0.04045f) return c < 0.f ? 0.f : c * (1.f / 12.92f);
    return std::pow((c + 0.055f) * (1.f / 1.055f), 2.4f);
}

TextureImage::TextureImage(int width, int height, const uint8_t *bytes, bool srgb)
    : width_(width), height_(height), srgb_(srgb) {
    if (width < 1 || height < 1) throw InputError("an image has no pixels");
    bytes_.assign(bytes, bytes + size_t(width) * size_t(height) * 4);
}

TextureImage::TextureImage(int width, int height, const float *floats, bool srgb)
    : width_(width), height_(height), srgb_(srgb) {
    if (width < 1 || height < 1) throw InputError("an image has no pixels");
    floats_.assign(floats, floats + size_t(width) * size_t(height) * 4);
    for (float &f : floats_)
        if (!std::isfinite(f)) f = 0.f;  // a NaN or infinite pixel (an EXR's) reads as 0, as Cycles does
}

RGBA TextureImage::texel(int x, int y) const {
    const size_t i = (size_t(y) * size_t(width_) + size_t(x)) * 4;
    if (!bytes_.empty()) {
        constexpr float k = 1.f / 255.f;
        return {bytes_[i] * k, bytes_[i + 1] * k, bytes_[i + 2] * k, bytes_[i + 3] * k};
    }
    return {floats_[i], floats_[i + 1], floats_[i + 2], floats_[i + 3]};
}

namespace {
int mirror(int x, int size) {  // ... 2 1 0 | 0 1 2 ... size-1 | size-1 ...
    const int m = std::abs(x + (x < 0)) % (2 * size);
    return m >= size ? 2 * size - m - 1 : m;
}
int wrap(int x, int size) {
    const int m = x % size;
    return m < 0 ? m + size : m;
}
}  // namespace

RGBA TextureImage::fetch(int x, int y, ImageExtension extension) const {
    switch (extension) {
        case ImageExtension::Repeat: return texel(wrap(x, width_), wrap(y, height_));
        case ImageExtension::Extend:
            return texel(std::min(std::max(x, 0), width_ - 1), std::min(std::max(y, 0), height_ - 1));
        case ImageExtension::Clip:
            if (x < 0 || y < 0 || x >= width_ || y >= height_) return RGBA{};
            return texel(x, y);
        default: return texel(mirror(x, width_), mirror(y, height_));
    }
}

RGBA TextureImage::sample(float u, float v, ImageInterpolation interpolation, ImageExtension extension) const {
    if (!std::isfinite(u) || !std::isfinite(v)) return RGBA{};
    if (extension == ImageExtension::Clip && (u < 0.f || v < 0.f || u > 1.f || v > 1.f)) return RGBA{};
    // Keep the coordinates where float still resolves a pixel and int cannot overflow: the
    // repeat is periodic, and clamping far outside changes nothing for the other extensions.
    if (extension == ImageExtension::Repeat) u -= std::floor(u), v -= std::floor(v);
    u = std::fmin(std::fmax(u, -4.f), 5.f), v = std::fmin(std::fmax(v, -4.f), 5.f);
    RGBA out;
    auto add = [&](RGBA t, float w) { out.r += w * t.r, out.g += w * t.g, out.b += w * t.b, out.a += w * t.a; };
    const float x = u * float(width_), y = v * float(height_);
    if (interpolation == ImageInterpolation::Closest) {
        out = fetch(int(std::floor(x)), int(std::floor(y)), extension);
    } else if (interpolation == ImageInterpolation::Linear) {
        const float px = x - 0.5f, py = y - 0.5f;
        const int ix = int(std::floor(px)), iy = int(std::floor(py));
        const float tx = px - float(ix), ty = py - float(iy);
        add(fetch(ix, iy, extension), (1 - tx) * (1 - ty));
        add(fetch(ix + 1, iy, extension), tx * (1 - ty));
        add(fetch(ix, iy + 1, extension), (1 - tx) * ty);
        add(fetch(ix + 1, iy + 1, extension), tx * ty);
    } else {  // cubic: a uniform cubic B-spline over 4x4 texels (Cycles' bicubic)
        const float px = x - 0.5f, py = y - 0.5f;
        const int ix = int(std::floor(px)), iy = int(std::floor(py));
        auto weights = [](float t, float w[4]) {
            const float t2 = t * t, t3 = t2 * t;
            w[0] = (1.f - t) * (1.f - t) * (1.f - t) / 6.f;
            w[1] = (3.f * t3 - 6.f * t2 + 4.f) / 6.f;
            w[2] = (-3.f * t3 + 3.f * t2 + 3.f * t + 1.f) / 6.f;
            w[3] = t3 / 6.f;
        };
        float wx[4], wy[4];
        weights(px - float(ix), wx), weights(py - float(iy), wy);
        for (int j = 0; j < 4; ++j)
            for (int i = 0; i < 4; ++i) add(fetch(ix - 1 + i, iy - 1 + j, extension), wx[i] * wy[j]);
    }
    if (srgb_) out.r = srgb_to_linear(out.r), out.g = srgb_to_linear(out.g), out.b = srgb_to_linear(out.b);
    return out;
}

}  // namespace splat
