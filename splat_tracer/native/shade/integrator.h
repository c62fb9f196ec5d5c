// Rendering a frame of a RenderScene: camera samples spread by the pixel filter, a path per
// sample (lamps with shadow rays, recursive mirror and glass rays, sampled rough and diffuse
// bounces, the world as background and sky light), passes and counters.
#pragma once

#include <atomic>
#include <cmath>
#include <cstdint>
#include <vector>

#include "scene/camera.h"
#include "scene/render_scene.h"
#include "shade/environment.h"
#include "shade/film.h"
#include "shade/light_passes.h"
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
    // Ray kinds that see the world (World > Settings > Ray Visibility; kVis* bits). A kind
    // left out meets black where it leaves the scene -- camera rays keep alpha 1 on an opaque
    // film, as in Cycles.
    uint32_t world_visibility = kVisCamera | kVisDiffuse | kVisGlossy | kVisTransmission;
    bool film_transparent = false;
    // The world as an environment image (null: the uniform `world` above, as before). With it,
    // `world` is its mean radiance. `camera_environment`: what camera rays see instead (the
    // world's Light Path > Is Camera Ray trick), null: the same. Owned by the caller.
    const EnvironmentMap *environment = nullptr;
    const EnvironmentMap *camera_environment = nullptr;
    // Preview shading: base colour x |cos| between the view ray and the normal (a light at the
    // eye), no lamps, no secondary rays. What a scene without any light source renders with.
    bool headlight = false;
    // World light by ambient occlusion: at each diffuse point `ao_samples` cosine-distributed
    // occlusion rays bring the world's radiance where they escape; no diffuse bounce rays.
    bool sky_ao = false;
    int ao_samples = 1;
    // Noise control, Cycles' settings with Cycles' meaning (render/shading.py RenderSettings).
    // Clamp Direct / Indirect: the largest R + G + B a contribution may bring (0: no clamp).
    float clamp_direct = 0.f, clamp_indirect = 0.f;
    float filter_glossy = 0.f;  // Filter Glossy (0: off)
    // Adaptive sampling, the effective values (Cycles' automatic ones already resolved).
    bool adaptive = false;
    float adaptive_threshold = 0.f;
    int adaptive_min_samples = 0;
    double time_limit = 0.0;  // seconds of sampling; 0: none
    // Sampling in rounds over the whole image (adaptive sampling or a time limit).
    bool progressive() const { return adaptive || time_limit > 0.0; }
    // How emissive triangles light other surfaces: both shadow rays aimed at them and the
    // rays that meet them, weighed by multiple importance sampling (the default, as Cycles);
    // shadow rays only; or the rays that meet them only (as before mesh lights, and as a
    // material whose Emission Sampling is None). The last two exist to verify the first.
    // The environment image as a light follows the same strategy.
    enum MeshLightStrategy { kMis = 0, kLightOnly = 1, kBsdfOnly = 2 };
    int mesh_light_strategy = kMis;
    // Cycles' Film mist settings (the World's Mist Pass panel): start, 1 / depth (0: a depth
    // of 0) and the falloff's exponent (Quadratic 2, Linear 1, Inverse Quadratic 0.5).
    float mist_start = 0.f, mist_inv_depth = 0.01f, mist_falloff = 1.f;
    // The AO pass's reach (World > Light Settings > Distance, Cycles' ao_distance).
    float ao_distance = 10.f;
    // Film::light_groups: which group each lamp, emissive instance and the world lights.
    LightGroupMap light_groups;
    // Motion blur's shutter curve (Cycles' shutter table): the time in the shutter (0..1) of
    // evenly spaced values of a uniform number, its inverse CDF, held by the caller for the
    // render; null: a box shutter (the time is the number). Used only when something moves.
    const float *shutter_table = nullptr;
    int shutter_table_size = 0;
    // Cycles' rolling shutter (Top: the image's rows are exposed from top to bottom): the
    // duration of a row's exposure as a share of the shutter (0: each row at one instant);
    // negative: off, every row sees the whole shutter.
    float rolling_shutter_duration = -1.f;
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

    // Progressive rendering (settings.progressive()): rounds of samples over every tile, the
    // film's buffers holding sums until finish(). Samples [s0, s1) of the tile's pixels
    // still sampling.
    void render_tile_samples(size_t tile, int s0, int s1, const std::atomic<bool> *stop = nullptr);
    // Cycles' AdaptiveSampling::align_samples: how many of `wanted` samples from `start` to
    // render so that a round ends where a convergence check is due.
    int align_samples(int start, int wanted) const;
    // Cycles' need_filter: a convergence check is due after 0-based sample `sample`.
    bool need_check(int sample) const;
    // Cycles' convergence check and its 3x3 spread of unconverged pixels, after every pixel
    // still sampling has its samples; returns the pixels that go on.
    size_t check_convergence();
    // Each pixel's sums divided by its own sample count. Returns the samples taken.
    uint64_t finish();
    // Cycles' adaptive step: a convergence check every this many samples.
    static constexpr int kAdaptiveStep = 16;

  private:
    struct Tally;       // per-tile ray counts
    struct PathState;   // bounce counters, where the ray starts, its throughput
    struct Primary;     // what the passes want from the camera ray's first hit
    struct Lobes;       // a material's lobes at one point
    struct LobePicks;   // how the path goes on from a point: the sampled lobes' weights
    struct Pixel;       // one pixel's sums over its samples
    class NodeQueries;  // what node programs ask of the scene at a path's surface (ShadingQueries)
    // With shadow catchers (Cycles' film passes of the same names): the samples whose first
    // surface is not a catcher (the matte: colour, alpha); the catcher's samples shaded with
    // everything and as if only catchers were there; their count; the world seen by the
    // camera behind the catcher or past everything. Sums over samples, like every pass.
    // (Complete here: the progressive film keeps one per pixel.)
    struct CatcherSums {
        Vec3 matte, full, alone, background;
        float matte_alpha = 0, samples = 0;
        void add(const CatcherSums &o) {
            matte = matte + o.matte, full = full + o.full, alone = alone + o.alone;
            background = background + o.background;
            matte_alpha += o.matte_alpha, samples += o.samples;
        }
    };

    // `first`: the ray's first hit, already found (the camera packet's), else null.
    Vec3 radiance(Ray ray, PathState st, const Sampler &rng, Primary *primary, Tally &tally,
                  const SurfacePoint *first = nullptr) const;
    // Light from lamps and sampled emissive triangles at a surface point, shadow rays
    // included; `n` and `ng` face `wo`. `picks`: how the path goes on from here (all 0 when it
    // ends), which the mesh lights' MIS weights need. `weight` and `indirect`: the path's, for
    // the clamp.
    Vec3 direct_light(const SurfacePoint &sp, const Origin &from, Vec3 n, Vec3 ng, Vec3 wo, float cos_o,
                      const Lobes &lobes, const LobePicks &picks, const Sampler &rng, Primary *primary, Tally &tally,
                      Vec3 weight, bool indirect, const PathState &st) const;
    // The density with which the path's sampled reflection at a point goes in direction wi
    // (solid angle): the lobe picks times their densities; 0 when the path ends there.
    static float reflection_pdf(const Lobes &lobes, Vec3 n, Vec3 wo, float cos_o, Vec3 wi, const LobePicks &picks);
    // A shadow ray from the surface point towards wi, ending just short of `distance`.
    static Ray shadow_ray(const SurfacePoint &sp, Vec3 ng, Vec3 wi, float distance);
    // `st`: the path the shadow ray leaves from (Light Path nodes on the way read it); null: none.
    Vec3 shadow_transmittance(Ray ray, Origin from, Tally &tally, const PathState *st = nullptr) const;
    Vec3 sky_occlusion(const SurfacePoint &sp, const Origin &from, Vec3 n, Vec3 ng, const Sampler &rng, Tally &tally,
                       const PathState &st) const;
    void write_catcher(const CatcherSums &sums, float inv, float alpha, size_t p) const;
    // A pixel's passes finished from their sums (shade_block's and finish()'s one way).
    void finish_pixel(size_t p, float inv, float alpha_sum, const CatcherSums *catcher,
                      const LightSums *light) const;
    // 1 - Cycles' mist at local point p (what Cycles accumulates: the pass is 1 - the mean).
    float mist_term(Vec3 p) const;
    void write_centre(const Primary &centre, size_t p) const;
    // Light passes and groups (light_passes.h). tap: light `c` met at a vertex of path `st`
    // (`found`: by the ray that reached it -- emission, a lamp, the world -- rather than
    // sampled there), of light group `group` (-1: none); `lobe`: at the camera's own vertex,
    // the lobe that light sampled there lit.
    void tap(const PathState &st, Vec3 c, int group, bool found, int lobe = kLobeNone) const;
    // tap() of light sampled at a surface, split between its diffuse and glossy lobes.
    void tap_sampled(const PathState &st, Vec3 all, Vec3 diffuse_part, Vec3 added, int group) const;
    // Cycles' AO pass at the camera ray's first hit: 1 if a cosine-distributed ray from it
    // meets nothing within ao_distance, else 0.
    float ao_term(const SurfacePoint &sp, const Origin &from, Vec3 n, Vec3 ng, const Sampler &rng,
                  Tally &tally) const;
    // A pixel's light-pass sums written to the film; `inv` one over the samples.
    void write_light(const LightSums &sums, float inv, size_t p) const;
    // The film's light passes or groups are asked for: paths tap their light.
    bool light_split() const { return film_.light || film_.ao || film_.light_groups; }
    void shade_block(const int *cols, const int *rows, int n, Tally &tally, const std::atomic<bool> *stop) const;
    // Samples [s0, s1) of n pixels added to acc; false when stopped.
    bool shade_samples(const int *cols, const int *rows, int n, int s0, int s1, Pixel *acc, Tally &tally,
                       const std::atomic<bool> *stop) const;
    void add_tally(const Tally &tally) const;
    // Cycles' film_clamp_light: light `c` reaching the pixel with path weight `weight` is
    // scaled so that the contribution's |R| + |G| + |B| stays within the limit.
    Vec3 clamped(Vec3 c, Vec3 weight, bool indirect) const {
        const float limit = indirect ? clamp_indirect_ : clamp_direct_;
        if (!(limit < kInfinity)) return c;
        const float sum = std::fabs(weight.x * c.x) + std::fabs(weight.y * c.y) + std::fabs(weight.z * c.z);
        return sum > limit ? c * (limit / sum) : c;
    }
    // The id of the pixel in window column `col`, row `row`: its random numbers' key.
    uint32_t pixel_id_of(int col, int row) const {
        return uint32_t(film_.y0 + row) * uint32_t(film_.width) + uint32_t(film_.x0 + col);
    }
    // The rays leaving a point, as Sampler::bounce's branch: the one sampled continuation,
    // and a mirror-smooth surface's reflection and refraction.
    static constexpr uint32_t kSampled = 0, kMirror = 1, kGlass = 2;
    int inside_after_crossing(const SurfacePoint &sp, int inside_before) const;
    // Where rays leave surface point `sp` of a path that arrived from `path`: its Origin, and
    // in *offset how far off the surface they start.
    Origin leaving(const SurfacePoint &sp, const Origin &path, float *offset) const;
    // The width of a camera pixel's footprint at scene point p, across the ray (Wireframe's
    // Pixel Size).
    float pixel_width(Vec3 p) const;
    // The world's radiance for a ray of `kind` that leaves the scene (0 if hidden from it).
    Vec3 world_seen(uint32_t kind) const {
        return (settings_.world_visibility & kind) ? settings_.world : Vec3();
    }
    // The same towards direction d: the environment image's radiance there (the camera's own
    // image for camera rays), else the uniform world.
    Vec3 world_seen(uint32_t kind, Vec3 d) const {
        if (!settings_.environment) return world_seen(kind);
        if (!(settings_.world_visibility & kind)) return Vec3();
        const EnvironmentMap *map =
            kind == kVisCamera && settings_.camera_environment ? settings_.camera_environment : settings_.environment;
        return map->lookup(d);
    }
    // The world met by a ray of state `st` leaving the scene along d, weighed against the
    // chance that environment_light() drew that direction (multiple importance sampling).
    Vec3 world_missed(const PathState &st, Vec3 d) const;
    // The environment image as a light at a surface point: shadow rays towards directions
    // drawn from its distribution, weighed against the path's sampled reflection.
    Vec3 environment_light(const SurfacePoint &sp, const Origin &from, Vec3 n, Vec3 ng, Vec3 wo, float cos_o,
                           const Lobes &lobes, const LobePicks &picks, const Sampler &rng, Tally &tally, Vec3 weight,
                           bool indirect,
                           const PathState &st) const;

    const RenderScene &scene_;
    const Camera &camera_;
    const Film &film_;
    const IntegratorSettings &settings_;
    RenderCounters &counters_;
    PixelFilter filter_;
    const std::vector<uint8_t> camera_inside_;  // this render's RenderScene::locate_camera
    bool lit_scene_;  // something emits light: secondary rays can matter
    const MeshLights *mesh_lights_;  // sampled emissive triangles, or null (none, or not sampled)
    // The environment sampled as a light, or null (a uniform world, a black image, or sky AO
    // -- which lights diffuse surfaces by occlusion rays instead).
    const EnvironmentMap *environment_light_;
    // Cycles' kernel values: the clamps times 3 (they bound a sum of three channels) or
    // infinity; filter glossy as 1 / Filter Glossy, or 0 when off.
    float clamp_direct_, clamp_indirect_, filter_glossy_;
    // Motion blur: camera rays get a time in the shutter (an instance or the camera moves);
    // false leaves the time dimension out entirely, so a still scene renders as before.
    const bool timed_;
    float shutter_time(float u) const;
    // Progressive rendering only: per pixel of the window, the class-A half of the combined
    // sum (times 2, Cycles' adaptive aux buffer), the samples taken, and whether it converged.
    std::vector<Vec3> half_;
    std::vector<uint32_t> taken_;
    std::vector<uint8_t> converged_;
    // Progressive rendering of a scene with shadow catchers: each pixel's catcher sums.
    std::vector<CatcherSums> catcher_;
    // Progressive rendering with light passes or groups: each pixel's light sums.
    std::vector<LightSums> light_;
};

}  // namespace splat
