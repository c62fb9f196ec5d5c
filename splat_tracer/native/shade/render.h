// Image rendering: one camera ray per pixel centre, traced and shaded in square tiles.
#pragma once

#include <cstddef>

#include "scene/camera.h"
#include "splats/splat_scene.h"
#include "splats/visibility.h"

namespace splat {

// Where the pixels go. The image is width x height; the rendered window is the w x h
// rectangle whose top-left pixel is (x0, y0) (column, row from the top), so a border
// render fills only part of the frame. Buffers are w x h, row-major, top row first;
// `depth` and `normal` may be null when those passes are not wanted.
struct RenderTarget {
    int width = 0, height = 0;
    int x0 = 0, y0 = 0, w = 0, h = 0;
    float *rgba = nullptr;    // 4 floats a pixel: scene-linear colour and alpha
    float *depth = nullptr;   // 1 float: planar depth along the view axis (Cycles' Z)
    float *normal = nullptr;  // 3 floats: the surface normal, world orientation
};

struct RenderSettings {
    float background[4] = {0.f, 0.f, 0.f, 0.f};  // RGBA written where no splat is hit
    float background_depth = 1e10f;             // Cycles writes 1e10 in Z where nothing is hit
    int tile_size = 32;
    Method method;  // which surface each pixel shows (visibility.h)
    bool packets = true;  // 4x4 pixels traced as one ray packet (packet.h); the same image
};

class Renderer {
  public:
    Renderer(const SplatScene &scene, const Camera &camera, const RenderTarget &target,
             const RenderSettings &settings)
        : scene_(scene), camera_(camera), target_(target), settings_(settings) {}

    size_t tile_count() const;
    void render_tile(size_t tile) const;

  private:
    void shade_pixel(int col, int row, const Ray &ray, const SurfaceHit &hit) const;

    const SplatScene &scene_;
    const Camera &camera_;
    const RenderTarget &target_;
    const RenderSettings &settings_;
};

}  // namespace splat
