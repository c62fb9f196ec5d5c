// Rendering a frame of a RenderScene: camera samples spread by the pixel filter, a path per
// sample (lamps with shadow rays, recursive mirror and glass rays, sampled rough and diffuse
// bounces, the world as background and sky light), passes and counters.
#pragma once

#include <atomic>
#include <cstdint>
#include <vector>

#include "scene/camera.h"
#include "scene/render_scene.h"
#include "shade/film.h"
#include "shade/sampling.h"

namespace splat {

struct IntegratorSettings : FrameSettings {
    int samples = 1;
    int filter_type = PixelFilter::BlackmanHarris;
    float filter_width = 1.5f;
    int shadow_samples = 1;
    int max_bounces = 12, diffuse_bounces = 1, glossy_bounces = 4, transmission_bounces = 12,
        transparent_bounces = 8;
    uint32_t seed = 0;
    Vec3 world;  // background radiance
    bool film_transparent = false;
    // Preview shading: base colour x |cos| between the view ray and the normal (a light at the
    // eye), no lamps, no secondary rays. What a scene without any light source renders with.
    bool headlight = false;
    // World light by ambient occlusion: at each diffuse point `ao_samples` cosine-distributed
    // occlusion rays bring the world's radiance where they escape; no diffuse bounce rays.
    bool sky_ao = false;
    int ao_samples = 1;
    // How emissive triangles light other surfaces: both shadow rays aimed at them and the
    // rays that meet them, weighed by multiple importance sampling (the default, as Cycles);
    // shadow rays only; or the rays that meet them only (as before mesh lights, and as a
    // material whose Emission Sampling is None). The last two exist to verify the first.
    enum MeshLightStrategy { kMis = 0, kLightOnly = 1, kBsdfOnly = 2 };
    int mesh_light_strategy = kMis;
};

// Rays traced, by kind, and the queries' work: what proves a scene pays only for what it uses.
struct RenderCounters {
    std::atomic<uint64_t> camera{0}, shadow{0}, reflection{0}, refraction{0}, diffuse{0}, transparent{0};
    std::atomic<uint64_t> nodes{0}, discs{0}, triangles{0}, layer_queries{0}, far_rejections{0},
        interpolations{0};
};

class Integrator {
  public:
    Integrator(const RenderScene &scene, const Camera &camera, const Film &film, const IntegratorSettings &settings,
               RenderCounters &counters);

    size_t tile_count() const { return splat::tile_count(film_, settings_.tile_size); }
    // stop: set by another thread to end the render early; the tile's pixels are then
    // left unfinished (the caller discards a stopped render).
    void render_tile(size_t tile, const std::atomic<bool> *stop = nullptr) const;

  private:
    struct Tally;       // per-tile ray counts
    struct PathState;   // bounce counters, where the ray starts, its throughput
    struct Primary;     // what the passes want from the camera ray's first hit
    struct Lobes;       // a material's lobes at one point

    // `first`: the ray's first hit, already found (the camera packet's), else null.
    Vec3 radiance(Ray ray, PathState st, Sampler &rng, Primary *primary, Tally &tally,
                  const SurfacePoint *first = nullptr) const;
    // Lamps' light at a surface point, shadow rays included; `n` and `ng` face `wo`.
    // `pick`: the probabilities that the path goes on by a sampled diffuse and glossy
    // reflection (0 when it ends here), which the mesh lights' MIS weights need.
    Vec3 direct_light(const SurfacePoint &sp, const Origin &from, Vec3 n, Vec3 ng, Vec3 wo, float cos_o,
                      const Lobes &lobes, const float pick[2], Sampler &rng, Primary *primary, Tally &tally) const;
    // The density with which the path's sampled reflection at a point goes in direction wi
    // (solid angle): the lobe picks times their densities.
    static float reflection_pdf(const Lobes &lobes, Vec3 n, Vec3 wo, float cos_o, Vec3 wi, const float pick[2]);
    // A shadow ray from the surface point towards wi, ending just short of `distance`.
    static Ray shadow_ray(const SurfacePoint &sp, Vec3 ng, Vec3 wi, float distance);
    Vec3 shadow_transmittance(Ray ray, Origin from, Tally &tally) const;
    Vec3 sky_occlusion(const SurfacePoint &sp, const Origin &from, Vec3 n, Vec3 ng, Sampler &rng, Tally &tally) const;
    void shade_block(const int *cols, const int *rows, int n, Tally &tally, const std::atomic<bool> *stop) const;
    // The id of the pixel in window column `col`, row `row`: its random numbers' key.
    uint32_t pixel_id_of(int col, int row) const {
        return uint32_t(film_.y0 + row) * uint32_t(film_.width) + uint32_t(film_.x0 + col);
    }
    // Salt of the seed for the lens points' stream (any constant unlike the others: the
    // hash decorrelates it from the path's stream of the same pixel and sample).
    static constexpr uint32_t kLensStream = 0x6c656e73u;  // "lens"
    int inside_after_crossing(const SurfacePoint &sp, int inside_before) const;

    const RenderScene &scene_;
    const Camera &camera_;
    const Film &film_;
    const IntegratorSettings &settings_;
    RenderCounters &counters_;
    PixelFilter filter_;
    const std::vector<uint8_t> camera_inside_;  // this render's RenderScene::locate_camera
    bool lit_scene_;  // something emits light: secondary rays can matter
    const MeshLights *mesh_lights_;  // sampled emissive triangles, or null (none, or not sampled)
};

}  // namespace splat
