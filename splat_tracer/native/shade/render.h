// The headlight preview of one splat cloud (render.splats.SplatCloud.render): one camera ray per pixel
// centre, the surface the method shows, shaded as base colour x |cos| between the ray and
// the normal. Its film, tiles and packets are the integrator's (film.h); what stays its own
// is the scene it reads (a SplatScene in its own frame, not a RenderScene's instances, whose
// object-space rays are renormalised) and its background (a fixed RGBA, not the world).
#pragma once

#include <cstddef>

#include "scene/camera.h"
#include "shade/film.h"
#include "splats/splat_scene.h"
#include "splats/visibility.h"

namespace splat {

struct RenderSettings : FrameSettings {
    float background[4] = {0.f, 0.f, 0.f, 0.f};  // RGBA written where no splat is hit
};

class Renderer {
  public:
    Renderer(const SplatScene &scene, const Camera &camera, const Film &film, const RenderSettings &settings)
        : scene_(scene), camera_(camera), film_(film), settings_(settings) {}

    size_t tile_count() const { return splat::tile_count(film_, settings_.tile_size); }
    void render_tile(size_t tile) const;

  private:
    void shade_pixel(int col, int row, const Ray &ray, const SurfaceHit &hit) const;

    const SplatScene &scene_;
    const Camera &camera_;
    const Film &film_;
    const RenderSettings &settings_;
};

}  // namespace splat
