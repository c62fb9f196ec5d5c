// Image textures: an image's pixels and their lookup (interpolation, extension), the way
// Cycles samples an Image Texture node. On its own so that every user of images (the
// material's Image Texture node; the world's environment) samples them alike.
#pragma once

#include <cstdint>
#include <vector>

namespace splat {

enum class ImageInterpolation : int32_t { Closest = 0, Linear, Cubic, Count };
enum class ImageExtension : int32_t { Repeat = 0, Extend, Clip, Mirror, Count };

struct RGBA {
    float r = 0, g = 0, b = 0, a = 0;
};

class TextureImage {
  public:
    // `width` x `height` RGBA pixels, bottom row first (Blender's order). With `srgb` the colour
    // is sRGB-encoded and turned into scene linear after interpolation, as Cycles does with
    // sRGB images (bytes, and floats tagged sRGB); else bytes are linear values / 255 and
    // floats are used as they are. Throws InputError on a size of 0.
    TextureImage(int width, int height, const uint8_t *bytes, bool srgb);
    TextureImage(int width, int height, const float *floats, bool srgb = false);

    int width() const { return width_; }
    int height() const { return height_; }
    // The image at texture coordinates (u, v): (0, 0) its bottom-left corner, (1, 1) its top-right.
    RGBA sample(float u, float v, ImageInterpolation interpolation, ImageExtension extension) const;

  private:
    RGBA texel(int x, int y) const;  // in range
    RGBA fetch(int x, int y, ImageExtension extension) const;  // any integer coordinates
    int width_ = 0, height_ = 0;
    bool srgb_ = false;
    std::vector<uint8_t> bytes_;
    std::vector<float> floats_;
};

float srgb_to_linear(float c);

}  // namespace splat
