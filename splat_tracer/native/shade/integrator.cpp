#include "shade/integrator.h"

#include <algorithm>
#include <cmath>

namespace splat {

// Paths deeper than this are cut whatever the settings say: each level is a stack frame of
// the recursion (about 1 KB), and a worker thread's stack must hold them all.
constexpr int kMaxDepth = 64;
// Below this throughput (luminance) a path continues only by Russian roulette, with the
// survivors weighted up: unbiased, and branching mirror/glass paths stop multiplying.
constexpr float kRouletteThroughput = 0.02f;
// The origin offset of secondary rays from splats in plain splat ray tracing (no wrong-hit
// elimination), in radii of the splat: the usual epsilon of that method, small enough not to
// skip thin features and large enough to clear the disc it starts on.
constexpr float kPlainSplatOffset = 1e-3f;

struct Integrator::Tally {
    TraversalStats stats;
    uint64_t camera = 0, shadow = 0, reflection = 0, refraction = 0, diffuse = 0, transparent = 0;
};

// The node programs' questions at a surface a path meets (ShadingQueries): the Ambient
// Occlusion node's rays leave the point as the path's own shadow rays do (leaving(): the
// splats that formed it excluded, a triangle's point moved off the surface) and see what
// shadow rays see, and draw their directions from the path's sampler at this vertex, so that
// they converge over the pixel's samples and render the same every time. Made for each
// surface but only asked when a program has such a node.
class Integrator::NodeQueries final : public ShadingQueries {
  public:
    // `min_pdf`: the path's (PathState::min_pdf), for Bevel.
    NodeQueries(const Integrator &in, const SurfacePoint &sp, const Origin &path, const Sampler &rng, Tally &tally,
                float min_pdf)
        : in_(in), sp_(sp), path_(path), rng_(rng), tally_(tally), min_pdf_(min_pdf) {}
    void random(uint32_t key, float *u, int count, uint32_t sub, uint32_t subs) const override {
        rng_.get(Sampler::kShaderAo + Sampler::kDimStride * key, u, count, sub, subs);
    }
    bool occluded(Vec3 d, float distance, bool only_local) const override {
        float offset;
        Origin from = in_.leaving(sp_, path_, &offset);
        const bool behind = dot(d, sp_.ng) < 0.f;
        // Into a cloud (the node's Inside): the ray travels inside it, as a refracted one does.
        if (behind == sp_.front) from.inside = in_.inside_after_crossing(sp_, from.inside);
        Ray r;
        r.o = sp_.p + (behind ? sp_.ng * -1.f : sp_.ng) * offset;
        r.d = d;
        r.tmin = 0.f;
        r.tmax = distance;
        ++tally_.shadow;
        return in_.scene_.occluded(r, in_.settings_.method, from, &tally_.stats, only_local ? sp_.instance : -1);
    }
    float pixel_width(Vec3 p) const override { return in_.pixel_width(p); }
    int local_hits(Vec3 o, Vec3 d, float distance, LocalHit *out, int max) const override {
        Ray r;
        r.o = o, r.d = d, r.tmin = 0.f, r.tmax = distance;
        ++tally_.shadow;
        return in_.scene_.local_hits(sp_.instance, r, path_.time, out, max, &tally_.stats);
    }
    float ao_distance() const override { return in_.settings_.ao_distance; }
    float min_ray_pdf() const override { return min_pdf_; }

  private:
    const Integrator &in_;
    const SurfacePoint &sp_;
    const Origin &path_;
    const Sampler &rng_;
    Tally &tally_;
    float min_pdf_;
};

struct Integrator::PathState {
    int bounces = 0, diffuse = 0, glossy = 0, transmission = 0, transparent = 0;
    uint32_t kind = kVisCamera;  // which ray visibility applies
    bool camera = true;
    Origin from;
    float throughput = 1.f;
    bool specular = true;  // camera, mirror or clear-glass ray: it may see the lamps themselves
    bool singular = false;  // sampled from a mirror or clear glass (Light Path's Is Singular Ray)
    // A sampled reflection from `mis_from`, with density `mis_pdf`, where mesh lights were
    // sampled too: emission it meets on them is weighed by MIS. 0: emission counts in full.
    float mis_pdf = 0.f;
    Vec3 mis_from;
    Vec3 weight{1.f, 1.f, 1.f};  // the product of the bounces' weights: what the pixel gets of light found here
    // Cycles' min_ray_pdf: the smallest pdf of the directions sampled so far (Filter Glossy).
    float min_pdf = kInfinity;
    // Light passes and groups only (else null): the camera sample's sums, and the lobe of the
    // path's first bounce, which names the pass its light goes to.
    LightSums *split = nullptr;
    int lobe = kLobeNone;
};

namespace {

// Light Path's view of a ray (program.h kLightPathFloats), as Cycles' path flags and bounce
// counts give it: a camera ray stays one through transparent surfaces; a bounce is a
// reflection (diffuse or glossy) or a transmission (glossy), a mirror's or clear glass's also
// singular; a shadow ray is only that (Cycles evaluates shadows with PATH_RAY_SHADOW alone),
// with the path's depths and its own transparent crossings. `t`: the ray's length to the point.
template <class State>
void light_path_of(const State &st, float t, bool shadow, int transparent, float *out) {
    const bool camera = !shadow && st.camera, diffuse = !shadow && !st.camera && st.kind == kVisDiffuse;
    const bool glossy = !shadow && !st.camera && (st.kind == kVisGlossy || st.kind == kVisTransmission);
    const bool transmission = !shadow && !st.camera && st.kind == kVisTransmission;
    const float v[kLightPathFloats] = {float(camera), float(shadow), float(diffuse), float(glossy),
                                       float(glossy && st.singular), float(diffuse || (glossy && !transmission)),
                                       float(transmission), 0.f /* volume scatter: no volumes */, t,
                                       float(st.bounces), float(st.diffuse), float(st.glossy), float(transparent),
                                       float(st.transmission)};
    std::copy(v, v + kLightPathFloats, out);
}

}  // namespace

struct Integrator::Primary {
    bool hit = false;
    float t = 0;
    Vec3 normal, diffcol, emit;
    float index = 0;
    int splats = 0;
    float alpha = 1.f;
    float lit = 0, unshadowed = 0;  // direct light with and without shadows (luminance)
    bool catcher = false;  // the first opaque surface is a shadow catcher's
    Vec3 position;  // of the first opaque surface (local frame)
    float material_index = 0;
    float mist = 0;    // 1 - Cycles' mist there (0 where nothing is hit); only with the Mist pass
    Vec3 environment;  // the world seen where the ray leaves the scene (black where it meets a surface)
    float *aov = nullptr;  // the pixel's shader-AOV sums (Film::aov), null when none is written
    float ao = 0;      // the AO pass's term (only with that pass)
    Vec3 uv;           // the UV pass's (U, V, 1) on a mesh; 0 on a cloud
    int instance = -1, material = 0;  // of the first opaque surface (not a holdout): Cryptomatte's names
};

struct Integrator::Pixel {
    Vec3 sum, diffcol, emit, shadow, environment;
    float mist = 0;  // sum of Primary::mist
    Vec3 half;  // progressive rendering: the class-A samples' sum, times 2
    float alpha = 0;
    Primary centre;  // sample 0 is the pixel centre: depth, normal, index and splat count
    CatcherSums catcher;  // scenes with shadow catchers only
    LightSums light;      // light passes and groups only
};

namespace {

// Cycles' bump shadowing term (its bsdf.h, after Conty Estevez, Lecocq and Stein, "A
// Microfacet-Based Shadowing Function to Solve the Bump Terminator Problem", Ray Tracing Gems
// 2019): where a node program tilted the shading normal (Bump, Normal Map), the diffuse
// reflection towards wi is attenuated by the Smith G1 of a GGX whose alpha^2 is tan^2 of the
// tilt / 8, at the angle between wi and the surface's own normal -- the light grazing the
// surface fades as on a rough one instead of lighting the tilted facets in full. 1 where
// nothing was tilted (the multiplication by 1 leaves unbumped surfaces bit for bit).
float bump_shadowing(const SurfacePoint &sp, Vec3 wi) {
    if (!sp.bumped) return 1.f;
    const float cos_i = std::fabs(dot(sp.ns_surface, wi)), cos_d = std::fabs(dot(sp.ns_surface, sp.ns));
    if (cos_d >= 1.f || cos_i >= 1.f) return 1.f;
    if (cos_i < 1e-6f) return 0.f;  // grazing exactly: none (and no division by 0 below)
    const float alpha2 = std::fmin(std::fmax(0.125f * (1.f / (cos_d * cos_d) - 1.f), 0.f), 1.f);
    const float tan2_i = 1.f / (cos_i * cos_i) - 1.f;
    return 2.f / (1.f + std::sqrt(1.f + alpha2 * tan2_i));
}

Vec3 reflect(Vec3 wo, Vec3 n) { return n * (2.f * dot(wo, n)) - wo; }

// Refraction of wo (pointing away from the surface, on n's side) with eta = n_t / n_i.
bool refract(Vec3 wo, Vec3 n, float eta, Vec3 *wt) {
    const float c = dot(wo, n);
    const float s2 = (1.f - c * c) / (eta * eta);
    if (s2 >= 1.f) return false;
    *wt = normalize(wo * (-1.f / eta) + n * (c / eta - std::sqrt(1.f - s2)));
    return true;
}

Vec3 schlick(Vec3 f0, float c) { return f0 + (Vec3(1, 1, 1) - f0) * schlick_weight(c); }

// Cycles' sample_is_class_A: splits the samples into two halves whose estimates are
// compared for adaptive sampling (Christensen et al., progressive multi-jittered sequences).
bool sample_is_class_a(uint32_t s) {
    uint32_t bits = s & 0xaaaaaaaau, count = 0;
    for (; bits; bits &= bits - 1) ++count;
    return (count & 1u) != 0;
}

// The pdf of the GGX reflection lobe's VNDF sampling, for the direction wi (both about n).
float ggx_reflection_pdf(Vec3 n, Vec3 wo, Vec3 wi, float cos_o, float alpha) {
    const Vec3 h = normalize(wo + wi);
    return ggx_g1(cos_o, alpha) * ggx_d(std::fmax(dot(n, h), 0.f), alpha) / (4.f * cos_o);
}

}  // namespace

// The lobes of a material at one point, as energy weights.
struct Integrator::Lobes {
    float metal, glass, plastic;  // metallic, transmissive, opaque dielectric shares (sum 1)
    float f0;                     // opaque dielectric's normal-incidence reflectance
    float spec_eta;               // the IOR whose exact Fresnel has that f0 (1: none)
    float eta;                    // n_transmitted / n_incident for the glass lobe
    float alpha;                  // GGX roughness
    bool delta;                   // mirror-smooth: specular lobes are traced, not sampled
    Vec3 base;
    Vec3 metal_base;              // the metallic lobe's colour: the base colour, or its own

    Lobes(const Material &m, Vec3 base_colour, bool entering)
        : base(base_colour), metal_base(m.own_metal ? m.metal_colour : base_colour) {
        metal = m.metallic;
        glass = (1.f - m.metallic) * m.transmission;
        plastic = (1.f - m.metallic) * (1.f - m.transmission);
        const float r = (m.ior - 1.f) / (m.ior + 1.f);
        f0 = std::clamp(r * r * 2.f * m.specular_level, 0.f, 0.9999f);  // level 0.5: the IOR's own
        // As Cycles does, the specular level changes the layer's IOR, and its Fresnel is the
        // exact dielectric one: level 0 gives eta 1, no reflection at any angle, so the
        // diffuse lobe is pure Lambert. (Schlick's f0 + (1 - f0)(1 - c)^5 kept a grazing
        // reflection and dimmed the diffuse by it even at f0 = 0.)
        const float sf0 = std::sqrt(f0);
        spec_eta = (1.f + sf0) / (1.f - sf0);
        eta = entering ? m.ior : 1.f / m.ior;
        alpha = ggx_alpha(m.roughness);
        delta = m.roughness < kDeltaRoughness;
    }
    // Reflectance towards the mirror direction, for a half-vector cosine c.
    float plastic_fresnel(float c) const { return f0 > 0.f ? fresnel_dielectric(c, spec_eta) : 0.f; }
    Vec3 specular(float c) const {
        return schlick(metal_base, c) * metal + Vec3(1, 1, 1) * (plastic * plastic_fresnel(c) +
                                                             glass * fresnel_dielectric(c, eta));
    }
    // The diffuse under the specular layer keeps what the layer does not reflect: 1 minus the
    // layer's directional albedo E(cos_o, roughness, f0) -- Cycles' albedo scaling -- not 1
    // minus the macro-surface Fresnel, which reaches 1 at grazing views and made floors seen
    // at a low angle 6 % darker than Cycles (measured, benchmarks/frame_time.py).
    Vec3 diffuse(float cos_o) const { return base * (plastic * (1.f - specular_albedo(cos_o))); }
    // E of a GGX layer with Fresnel, by Karis' analytic fit of the split-sum table ("Physically
    // Based Shading on Mobile", 2014): f0 A + B. B, the grazing part, belongs to a reflecting
    // layer only: it fades out with f0 below a common dielectric's 0.04, so level 0 stays
    // pure Lambert.
    float specular_albedo(float cos_o) const {
        if (!(f0 > 0.f)) return 0.f;
        const float rough = std::sqrt(alpha);  // back to the Principled roughness
        const float r0 = -rough + 1.f, r1 = -0.0275f * rough + 0.0425f, r2 = -0.572f * rough + 1.04f,
                    r3 = 0.022f * rough - 0.04f;
        const float a004 = std::fmin(r0 * r0, std::exp2(-9.28f * cos_o)) * r0 + r1;
        const float a = -1.04f * a004 + r2, b = 1.04f * a004 + r3;
        return std::clamp(f0 * a + b * std::fmin(1.f, f0 / 0.04f), 0.f, 1.f);
    }
    Vec3 transmission(float c) const { return base * (glass * (1.f - fresnel_dielectric(c, eta))); }
    // The glossy lobes' reflection from wo towards wi (both about n, cos_o = n . wo and
    // cos_i = n . wi > 0): the GGX microfacet BRDF, Smith's G1 each way. Lamps, emissive
    // triangles and the environment light all shade with it.
    Vec3 glossy_brdf(Vec3 n, Vec3 wo, float cos_o, Vec3 wi, float cos_i) const {
        const Vec3 h = normalize(wo + wi);
        const float ch = std::fmax(dot(n, h), 0.f);
        const float g = ggx_g1(cos_o, alpha) * ggx_g1(cos_i, alpha);
        return specular(std::fmax(dot(wo, h), 0.f)) * (ggx_d(ch, alpha) * g / (4.f * cos_o * cos_i));
    }
    // The glossy lobes' albedo seen from cos_o: the Glossy Color pass (Cycles' is the
    // closures' albedo). Mirror-smooth, the Fresnel reflectance itself.
    Vec3 glossy_albedo(float cos_o) const {
        if (delta) return specular(cos_o);
        return schlick(metal_base, cos_o) * metal +
               Vec3(1, 1, 1) * (plastic * specular_albedo(cos_o) + glass * fresnel_dielectric(cos_o, eta));
    }
    // Cycles' bsdf_blur (Filter Glossy): the roughness (alpha) raised to at least `a`; a
    // mirror-smooth lobe so blurred is sampled like any rough one.
    void blur(float a) {
        if (a > alpha) alpha = a, delta = false;
    }
};

// How the path goes on from a point: one sampled continuation among the lobes that are not
// traced exactly, picked in proportion to these weights (each lobe's albedo luminance, 0 for
// a lobe out of bounces or not sampled); all 0 where the path ends.
struct Integrator::LobePicks {
    float diffuse = 0.f, glossy = 0.f, transmission = 0.f, sum = 0.f;
};

// The cloud a ray travels inside once it has crossed the surface at `sp` (refracted, or
// passed through a see-through point): entering a splat cloud it is inside it, and its next
// layer there is the exit (the swapped-facing rule); leaving, it is outside again. Meshes
// need no flag: their triangles' winding tells in and out.
int Integrator::inside_after_crossing(const SurfacePoint &sp, int inside_before) const {
    if (!scene_.instance(sp.instance).splats) return inside_before;
    return sp.front ? sp.instance : -1;
}

Integrator::Integrator(const RenderScene &scene, const Camera &camera, const Film &film,
                       const IntegratorSettings &settings, RenderCounters &counters)
    : scene_(scene), camera_(camera), film_(film), settings_(settings), counters_(counters),
      filter_(settings.filter_type, settings.filter_width),
      camera_inside_(scene.locate_camera(Vec3(float(camera.position[0]), float(camera.position[1]),
                                              float(camera.position[2])))),
      lit_scene_(!scene.lights().empty() || scene.any_emission() ||
                 (luminance(settings.world) > 0.f &&
                  (settings.world_visibility & (kVisDiffuse | kVisGlossy | kVisTransmission)))),
      mesh_lights_(settings.mesh_light_strategy != IntegratorSettings::kBsdfOnly && !scene.mesh_lights().empty()
                       ? &scene.mesh_lights()
                       : nullptr),
      environment_light_(settings.environment && settings.environment->sampled() && !settings.sky_ao &&
                                 settings.mesh_light_strategy != IntegratorSettings::kBsdfOnly
                             ? settings.environment
                             : nullptr),
      // Cycles' Integrator::device_update: the clamps times 3, since they bound R + G + B.
      clamp_direct_(settings.clamp_direct > 0.f ? 3.f * settings.clamp_direct : kInfinity),
      clamp_indirect_(settings.clamp_indirect > 0.f ? 3.f * settings.clamp_indirect : kInfinity),
      filter_glossy_(settings.filter_glossy > 0.f ? 1.f / settings.filter_glossy : 0.f),
      timed_(scene.any_motion() || camera.moves()) {
    if (film.cryptomatte.enabled()) {
        // Its slots are sums until each pixel's finish(), whatever the buffers held (0: free).
        const size_t floats = size_t(film.w) * size_t(film.h) * 2 * size_t(film.cryptomatte.slots);
        for (float *buf : film.cryptomatte.out)
            if (buf) std::fill(buf, buf + floats, 0.f);
    }
    if (settings.progressive()) {
        const size_t pixels = size_t(film.w) * size_t(film.h);
        half_.assign(pixels, Vec3());
        taken_.assign(pixels, 0u);
        converged_.assign(pixels, uint8_t(0));
        // Combined and the Shadow Catcher pass are formed from these sums in finish().
        if (scene.any_catcher()) catcher_.assign(pixels, CatcherSums());
        if (light_split()) light_.assign(pixels, LightSums());
        // The buffers hold sums until finish().
        auto zero = [&](float *buf, int channels) {
            if (buf) std::fill(buf, buf + pixels * size_t(channels), 0.f);
        };
        zero(film.combined, 4), zero(film.diffcol, 3), zero(film.emit, 3), zero(film.shadow, 3);
        zero(film.environment, 3), zero(film.mist, 1);
        zero(film.aov.buffer, film.aov.channels);
    }
}

// The time in the shutter of a uniform number u: the shutter table's inverse CDF, linearly
// interpolated between its entries, or u itself for a box shutter.
float Integrator::shutter_time(float u) const {
    const int n = settings_.shutter_table_size;
    if (!settings_.shutter_table || n < 2) return u;
    const float x = u * float(n - 1);
    const int i = std::min(int(x), n - 2);
    const float f = x - float(i);
    return settings_.shutter_table[i] + (settings_.shutter_table[i + 1] - settings_.shutter_table[i]) * f;
}

void Integrator::render_tile(size_t tile, const std::atomic<bool> *stop) const {
    Tally tally;
    // Blocks of 4x4 pixels: each sample's camera rays of a block are one packet.
    for_each_block(film_, settings_.tile_size, tile,
                   [&](const int *cols, const int *rows, int n) { shade_block(cols, rows, n, tally, stop); });
    add_tally(tally);
}

void Integrator::add_tally(const Tally &tally) const {
    counters_.camera += tally.camera, counters_.shadow += tally.shadow, counters_.reflection += tally.reflection;
    counters_.refraction += tally.refraction, counters_.diffuse += tally.diffuse;
    counters_.transparent += tally.transparent;
    const TraversalStats &s = tally.stats;
    counters_.nodes += s.nodes, counters_.discs += s.discs, counters_.triangles += s.triangles;
    counters_.layer_queries += s.layer_queries, counters_.far_rejections += s.far_rejections;
    counters_.interpolations += s.interpolations;
}

// Every sample of n pixels (cols[k], rows[k]), then their passes.
void Integrator::shade_block(const int *cols, const int *rows, int n, Tally &tally,
                             const std::atomic<bool> *stop) const {
    const int samples = settings_.samples;
    Pixel acc[kPacketRays];
    if (!shade_samples(cols, rows, n, 0, samples, acc, tally, stop)) return;
    const float inv = 1.f / float(samples);
    const bool catchers = scene_.any_catcher();
    for (int k = 0; k < n; ++k) {
        const Pixel &a = acc[k];
        const size_t p = size_t(rows[k]) * size_t(film_.w) + size_t(cols[k]);
        auto put3 = [&](float *buf, Vec3 v) {
            if (buf) buf[3 * p] = v.x, buf[3 * p + 1] = v.y, buf[3 * p + 2] = v.z;
        };
        // The sums into the film, then finished as a progressive render's are (the samples
        // added their AOVs straight into the film).
        if (film_.combined) {
            float *o = film_.combined + 4 * p;
            o[0] = a.sum.x, o[1] = a.sum.y, o[2] = a.sum.z, o[3] = a.alpha;
        }
        put3(film_.diffcol, a.diffcol), put3(film_.emit, a.emit), put3(film_.shadow, a.shadow);
        put3(film_.environment, a.environment);
        if (film_.mist) film_.mist[p] = a.mist;
        finish_pixel(p, inv, a.alpha, catchers ? &a.catcher : nullptr, light_split() ? &a.light : nullptr);
        write_centre(a.centre, p);
    }
}

// Samples [s0, s1) of n pixels (cols[k], rows[k]) added to acc: sample by sample, the n
// camera rays' first hits in one packet query (settings.packets), then each pixel's path.
// Sample s takes the same random numbers whichever round renders it.
bool Integrator::shade_samples(const int *cols, const int *rows, int n, int s0, int s1, Pixel *acc, Tally &tally,
                               const std::atomic<bool> *stop) const {
    const int samples = settings_.samples;
    const bool half = settings_.adaptive;
    const bool catchers = scene_.any_catcher();
    auto backdrop = [&](Vec3 d) { return world_seen(kVisCamera, d); };
    const bool split = light_split();
    const bool crypto = film_.cryptomatte.enabled();
    // Each pixel's sample 0, by which its pixel points are moved so that it is the centre.
    uint32_t first[2 * kPacketRays];
    if (samples > 1)
        for (int k = 0; k < n; ++k)
            Sampler(pixel_id_of(cols[k], rows[k]), 0u, settings_.seed).get_bits(Sampler::kCamera, first + 2 * k, 2);
    for (int s = s0; s < s1; ++s) {
        // Checked a sample at a time: one tile of a many-sample render takes seconds, and a
        // stop (the viewport closing, Python exiting) must not wait for it.
        if (stop && stop->load(std::memory_order_relaxed)) return false;
        // Each pixel's sample: its point in the pixel (the filter's offset) and on the lens,
        // one 4D point of the pixel's camera dimensions.
        const bool lens = camera_.has_lens();
        double offsets[2 * kPacketRays], lens_xy[2 * kPacketRays];
        for (int k = 0; k < n; ++k) {
            const uint32_t pixel = pixel_id_of(cols[k], rows[k]);
            uint32_t u[4];
            Sampler(pixel, uint32_t(s), settings_.seed).get_bits(Sampler::kCamera, u, lens ? 4 : 2);
            double *o = offsets + 2 * k;
            o[0] = o[1] = 0.0;
            if (samples > 1) {
                // The pixel's points moved (toroidally: a shifted stratified set stays one) so
                // that sample 0 is the pixel centre, whose passes are Depth, Normal and Index.
                o[0] = filter_.offset(Sampler::to_unit(u[0] - first[2 * k] + 0x80000000u));
                o[1] = filter_.offset(Sampler::to_unit(u[1] - first[2 * k + 1] + 0x80000000u));
            }
            if (lens) lens_point(camera_, Sampler::to_unit(u[2]), Sampler::to_unit(u[3]), &lens_xy[2 * k], &lens_xy[2 * k + 1]);
        }
        // Motion blur: each ray's time in the shutter, its own stratified dimension (the
        // others' numbers unchanged), and the camera where it is then.
        float times[kPacketRays];
        if (timed_)
            for (int k = 0; k < n; ++k) {
                float t = shutter_time(Sampler(pixel_id_of(cols[k], rows[k]), uint32_t(s), settings_.seed).get1(Sampler::kTime));
                const float duration = settings_.rolling_shutter_duration;
                if (duration >= 0.f) {
                    // Cycles' rolling shutter: the row's own instant, (row + 1) / height from
                    // the top (Cycles' 1 - y / height, its y counted from the bottom), blended
                    // with the sampled time by the duration.
                    const float row = float(film_.y0 + rows[k] + 1) / float(film_.height);
                    t = (t - 0.5f) * duration + (row - 0.5f) * (1.f - duration) + 0.5f;
                }
                times[k] = t;
            }
        Ray rays[kPacketRays];
        if (camera_.moves()) {
            for (int k = 0; k < n; ++k) {
                const Camera now = camera_.at(times[k]);
                if (lens) block_lens_rays(now, film_, cols + k, rows + k, 1, offsets + 2 * k, lens_xy + 2 * k, rays + k);
                else block_rays(now, film_, cols + k, rows + k, 1, offsets + 2 * k, rays + k);
            }
        } else if (lens) {
            block_lens_rays(camera_, film_, cols, rows, n, offsets, lens_xy, rays);
        } else {
            block_rays(camera_, film_, cols, rows, n, offsets, rays);
        }
        SurfacePoint hits[kPacketRays];
        if (settings_.packets)
            scene_.intersect_camera(rays, n, settings_.method, camera_inside_.data(), hits, &tally.stats,
                                    timed_ ? times : nullptr);
        for (int k = 0; k < n; ++k) {
            // A pixel the panorama does not see: nothing is traced or added (Cycles': black,
            // alpha 0, no pass written).
            if (Camera::is_none(rays[k])) continue;
            const Sampler rng(pixel_id_of(cols[k], rows[k]), uint32_t(s), settings_.seed);
            Primary prim;
            if (film_.aov.on()) prim.aov = film_.aov.pixel(size_t(rows[k]) * size_t(film_.w) + size_t(cols[k]));
            ++tally.camera;
            Pixel &a = acc[k];
            PathState path;
            path.from.time = timed_ ? times[k] : 0.f;
            if (split) path.split = &a.light;
            const Vec3 c = radiance(rays[k], path, rng, &prim, tally, settings_.packets ? &hits[k] : nullptr);
            const Vec3 v = c * prim.alpha;  // premultiplied: a holdout or a transparent film adds nothing
            a.sum = a.sum + v;
            if (half && sample_is_class_a(uint32_t(s))) a.half = a.half + v * 2.f;
            a.alpha += prim.alpha;
            if (catchers) {
                if (prim.catcher) {
                    // Cycles' shadow catcher split: the same camera ray again, in a scene of
                    // catchers only, with the same random numbers, so that where nothing else
                    // changes the catcher's light both paths are the same path (a ratio of
                    // exactly 1: no noise outside the shadows).
                    PathState alone;
                    alone.from.catcher_only = true;
                    alone.from.time = path.from.time;
                    ++tally.camera;
                    CatcherSums &cs = a.catcher;
                    cs.alone = cs.alone + radiance(rays[k], alone, rng, nullptr, tally);
                    cs.full = cs.full + c, cs.samples += 1.f;
                    cs.background = cs.background + backdrop(rays[k].d);
                } else {
                    CatcherSums &cs = a.catcher;
                    cs.matte = cs.matte + v, cs.matte_alpha += prim.alpha;
                    if (!prim.hit) cs.background = cs.background + backdrop(rays[k].d);
                }
            }
            a.diffcol = a.diffcol + prim.diffcol, a.emit = a.emit + prim.emit;
            a.environment = a.environment + prim.environment, a.mist += prim.mist;
            a.light.ao += prim.ao;
            const float lit = prim.unshadowed > 0.f ? prim.lit / prim.unshadowed : 1.f;
            a.shadow = a.shadow + Vec3(lit, lit, lit);
            // Each sample counts 1 for the name it meets (Cycles' matte weight: the camera
            // ray's throughput, 1, times the opacity, 1 where alpha is sampled stochastically).
            if (crypto && prim.instance >= 0)
                film_.cryptomatte.add(size_t(rows[k]) * size_t(film_.w) + size_t(cols[k]), prim.instance,
                                      prim.material, 1.f);
            if (s == 0)
                a.centre = prim, a.centre.t = prim.hit ? float(camera_.at(timed_ ? times[k] : 0.f).depth(rays[k], prim.t)) : 0.f;
        }
    }
    return true;
}

// Progressive rendering. A round adds samples [s0, s1) of the tile's pixels still sampling
// to the film's sums; its pixels never belong to another tile, so rounds run tiles at once.
void Integrator::render_tile_samples(size_t tile, int s0, int s1, const std::atomic<bool> *stop) {
    Tally tally;
    for_each_block(film_, settings_.tile_size, tile, [&](const int *block_cols, const int *block_rows, int count) {
        // The block's pixels still sampling: one packet, converged pixels left out.
        int cols[kPacketRays], rows[kPacketRays], n = 0;
        for (int k = 0; k < count; ++k)
            if (!converged_[size_t(block_rows[k]) * size_t(film_.w) + size_t(block_cols[k])])
                cols[n] = block_cols[k], rows[n] = block_rows[k], ++n;
        if (n == 0) return;
        Pixel acc[kPacketRays];
        if (!shade_samples(cols, rows, n, s0, s1, acc, tally, stop)) return;
        for (int k = 0; k < n; ++k) {
            const Pixel &a = acc[k];
            const size_t p = size_t(rows[k]) * size_t(film_.w) + size_t(cols[k]);
            float *o = film_.combined + 4 * p;
            o[0] += a.sum.x, o[1] += a.sum.y, o[2] += a.sum.z, o[3] += a.alpha;
            auto add3 = [&](float *buf, Vec3 v) {
                if (buf) buf[3 * p] += v.x, buf[3 * p + 1] += v.y, buf[3 * p + 2] += v.z;
            };
            add3(film_.diffcol, a.diffcol), add3(film_.emit, a.emit), add3(film_.shadow, a.shadow);
            add3(film_.environment, a.environment);
            if (film_.mist) film_.mist[p] += a.mist;
            half_[p] = half_[p] + a.half;
            if (!catcher_.empty()) catcher_[p].add(a.catcher);
            if (!light_.empty()) light_[p].add(a.light, settings_.light_groups.count);
            taken_[p] += uint32_t(s1 - s0);
            if (s0 == 0) write_centre(a.centre, p);  // the centre sample's passes
        }
    });
    add_tally(tally);
}

int Integrator::align_samples(int start, int wanted) const {
    if (!settings_.adaptive) return wanted;
    // The 0-based sample after which the first check is due, then every kAdaptiveStep.
    const int first = (settings_.adaptive_min_samples + 1) | (kAdaptiveStep - 1);
    if (start + wanted <= first) return wanted;
    const int next = std::max(first, start | (kAdaptiveStep - 1));
    return std::min(next - start + 1, wanted);
}

bool Integrator::need_check(int sample) const {
    return settings_.adaptive && sample > settings_.adaptive_min_samples &&
           (sample & (kAdaptiveStep - 1)) == (kAdaptiveStep - 1);
}

size_t Integrator::check_convergence() {
    const int w = film_.w, h = film_.h;
    // Cycles' film_adaptive_sampling_convergence_check: the difference between the estimate
    // of all samples (I) and of the class-A half (A), relative to the square root of the
    // intensity (to the intensity itself above R + G + B = 1, where more noise cannot show).
    for (size_t p = 0; p < size_t(w) * size_t(h); ++p) {
        if (converged_[p]) continue;  // a converged pixel stays so, unless a neighbour undoes it
        const float *I = film_.combined + 4 * p;
        const Vec3 A = half_[p];
        const float scale = 1.f / float(taken_[p]);
        const float difference =
            (std::fabs(I[0] - A.x) + std::fabs(I[1] - A.y) + std::fabs(I[2] - A.z)) * scale;
        const float intensity = (I[0] + I[1] + I[2]) * scale;
        const float normalise = intensity < 1.f ? std::sqrt(intensity) : intensity;
        // Cycles' epsilon against a division by zero.
        converged_[p] = difference / (0.0001f + normalise) < settings_.adaptive_threshold;
    }
    // Cycles' film_adaptive_sampling_filter_x then _y: a pixel next to one still sampling
    // samples again (a 3x3 box, in two passes).
    auto spread = [&](size_t start, size_t step, int count) {
        bool previous = false;  // the pixel before was still sampling
        for (int i = 0; i < count; ++i) {
            uint8_t &c = converged_[start + size_t(i) * step];
            if (!c) {
                if (i > 0 && !previous) converged_[start + size_t(i - 1) * step] = 0;
                previous = true;
            } else {
                if (previous) c = 0;
                previous = false;
            }
        }
    };
    for (int y = 0; y < h; ++y) spread(size_t(y) * size_t(w), 1, w);
    for (int x = 0; x < w; ++x) spread(size_t(x), size_t(w), h);
    size_t active = 0;
    for (uint8_t c : converged_) active += !c;
    return active;
}

uint64_t Integrator::finish() {
    uint64_t total = 0;
    for (size_t p = 0; p < taken_.size(); ++p) {
        total += taken_[p];
        if (!taken_[p]) continue;  // never sampled: a stopped render, discarded by the caller
        // Until here Combined held every sample's full path, the catcher's included: the
        // adaptive check's estimate, as in Cycles, which measures the noise of Combined "as if
        // there were no catchers in the scene" (kernel/film/light_passes.h).
        finish_pixel(p, 1.f / float(taken_[p]), film_.combined[4 * p + 3], catcher_.empty() ? nullptr : &catcher_[p],
                     light_.empty() ? nullptr : &light_[p]);
    }
    return total;
}

// A pixel's passes from the sums the film holds (`inv` one over the samples; alpha_sum the
// coverage's sum), the shadow catchers' and the light passes' from theirs (null: none): the
// means, and the passes Cycles' film forms from sums (film/read.h).
void Integrator::finish_pixel(size_t p, float inv, float alpha_sum, const CatcherSums *catcher,
                              const LightSums *light) const {
    if (catcher) {
        write_catcher(*catcher, inv, alpha_sum * inv, p);
    } else {
        if (film_.combined)
            for (int c = 0; c < 4; ++c) film_.combined[4 * p + size_t(c)] *= inv;
        if (film_.shadow_catcher)
            for (int c = 0; c < 3; ++c) film_.shadow_catcher[3 * p + size_t(c)] = 1.f;  // nothing to darken
    }
    for (float *buf : {film_.diffcol, film_.emit, film_.shadow, film_.environment})
        if (buf)
            for (int c = 0; c < 3; ++c) buf[3 * p + size_t(c)] *= inv;
    if (film_.mist) film_.mist[p] = 1.f - film_.mist[p] * inv;
    if (film_.aov.on()) film_.aov.scale(p, inv);
    if (light) write_light(*light, inv, p);
    if (film_.cryptomatte.enabled()) film_.cryptomatte.finish(p, inv);
}

// The passes of the pixel-centre sample (Cycles' data passes, written at its sample 0).
void Integrator::write_centre(const Primary &c, size_t p) const {
    auto put3 = [&](float *buf, Vec3 v) {
        if (buf) buf[3 * p] = v.x, buf[3 * p + 1] = v.y, buf[3 * p + 2] = v.z;
    };
    put3(film_.normal, c.hit ? c.normal : Vec3());
    put3(film_.position, c.hit ? c.position : Vec3());
    if (film_.depth) film_.depth[p] = c.hit ? c.t : kBackgroundDepth;
    if (film_.index) film_.index[p] = c.hit ? c.index : 0.f;
    if (film_.material_index) film_.material_index[p] = c.hit ? c.material_index : 0.f;
    if (film_.splat_count) film_.splat_count[p] = float(c.splats);
    put3(film_.uv, c.hit ? c.uv : Vec3());
    // Instances are far fewer than 2^24: instance + 1 is exact in a float.
    if (film_.instance) film_.instance[p] = c.hit && c.instance >= 0 ? float(c.instance + 1) : 0.f;
}

// Cycles' mist (kernel/film/data_passes.h): the distance from the camera (along its view
// axis for an orthographic one: camera_distance), mapped to 0..1 from the mist's start over
// its depth, raised to the falloff. Cycles accumulates 1 - mist and writes 1 - the mean.
float Integrator::mist_term(Vec3 p) const {
    const double d[3] = {double(p.x) - camera_.position[0], double(p.y) - camera_.position[1],
                         double(p.z) - camera_.position[2]};
    const double distance =
        camera_.orthographic
            ? std::fabs(d[0] * camera_.forward[0] + d[1] * camera_.forward[1] + d[2] * camera_.forward[2])
            : std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    float mist = std::clamp((float(distance) - settings_.mist_start) * settings_.mist_inv_depth, 0.f, 1.f);
    const float falloff = settings_.mist_falloff;
    if (falloff == 2.f) mist = mist * mist;
    else if (falloff == 0.5f) mist = std::sqrt(mist);
    else if (falloff != 1.f) mist = std::pow(mist, falloff);
    return 1.f - mist;
}

// Combined and the Shadow Catcher pass of a pixel of a scene with shadow catchers, formed as
// Cycles' film does (kernel/film/read.h: film_calculate_shadow_catcher and
// film_calculate_shadow_catcher_matte_with_shadow). The catcher's shadow is the ratio of its
// light with everything to its light with catchers only (1 where it has no sample, per
// channel 1 where the catcher alone is black), alpha-overed on white by the pixel's
// coverage. Combined is the matte -- everything but the catcher -- and, without the Shadow
// Catcher pass (Cycles' approximate shadow catcher), the shadow's strength as alpha:
// 1 - average(shadow) where the matte does not cover; on an opaque film, the world behind
// it shows through that alpha instead (alpha 1). `sums` over the pixel's samples, `inv` one
// over their count, `alpha` the pixel's (mean) alpha.
void Integrator::write_catcher(const CatcherSums &sums, float inv, float alpha, size_t p) const {
    const Vec3 matte = sums.matte * inv, background = sums.background * inv;
    const float matte_alpha = sums.matte_alpha * inv;
    Vec3 shadow(1, 1, 1);
    if (sums.samples > 0.f) {
        // A ratio of sums: the count cancels.
        auto ratio = [](float a, float b) { return b != 0.f ? a / b : 1.f; };
        const Vec3 full = sums.full, alone = sums.alone;
        shadow = Vec3(ratio(full.x, alone.x), ratio(full.y, alone.y), ratio(full.z, alone.z));
        const float covered = std::clamp(alpha, 0.f, 1.f);
        shadow = Vec3(1, 1, 1) * (1.f - covered) + shadow * covered;
    }
    if (film_.shadow_catcher) {
        float *o = film_.shadow_catcher + 3 * p;
        o[0] = shadow.x, o[1] = shadow.y, o[2] = shadow.z;
    }
    if (!film_.combined) return;
    float *o = film_.combined + 4 * p;
    const float ma = std::clamp(matte_alpha, 0.f, 1.f);
    Vec3 rgb = matte;
    float out_alpha = matte_alpha;
    if (!film_.shadow_catcher) {
        const float strength = 1.f - std::clamp((shadow.x + shadow.y + shadow.z) / 3.f, 0.f, 1.f);
        out_alpha = (1.f - ma) * strength + ma;
        if (!settings_.film_transparent) rgb = rgb + background * (1.f - out_alpha), out_alpha = 1.f;
    }
    o[0] = rgb.x, o[1] = rgb.y, o[2] = rgb.z, o[3] = out_alpha;
}

Vec3 Integrator::radiance(Ray ray, PathState st, const Sampler &rng, Primary *primary, Tally &tally,
                          const SurfacePoint *first) const {
    const IntegratorSettings &cfg = settings_;
    SurfacePoint sp, passed;  // `passed`: the last surface passed through, which st.from points into
    Material mat;
    Vec3 base;
    float opacity = 1.f;
    // Surfaces with alpha < 1 are passed through stochastically (transparent bounces).
    // The camera ray writes shader AOVs at each surface until one stops it (AovFilm::done_after).
    const AovSink aov{&film_.aov, primary && st.camera ? primary->aov : nullptr};
    bool aov_writing = aov.pixel != nullptr;
    Vec3 lamps;  // lamps seen directly on the way (camera, mirror and glass rays only)
    for (;;) {
        if (first) sp = *first, first = nullptr;  // the camera packet's answer for this ray
        else
            sp = scene_.intersect(ray, cfg.method, st.kind, st.from, st.camera ? camera_inside_.data() : nullptr,
                                  &tally.stats);
        if (st.specular && !cfg.headlight) {
            // A pointer range, as a range-for: the end is not reloaded each lamp.
            const Light *first_lamp = scene_.lights().data(), *end = first_lamp + scene_.lights().size();
            for (const Light *light = first_lamp; light != end; ++light)
                if (light->visibility & st.kind) {
                    const Vec3 seen = lamp_radiance(*light, ray, sp.t);
                    lamps = lamps + seen;
                    // (With Clamp on, each lamp is clamped alone here; Combined clamps their sum.)
                    if (st.split)
                        tap(st, clamped(seen, st.weight, st.bounces > 1),
                            cfg.light_groups.of_lamp(size_t(light - first_lamp)), true);
                }
        }
        if (!sp.valid()) {
            // Cycles' Environment pass: the world a camera ray leaves into, on a transparent
            // film too (its background pass is evaluated there for that pass alone).
            if (primary && st.camera && film_.environment)
                primary->environment = clamped(world_seen(st.kind, ray.d), st.weight, st.bounces > 1);
            if (st.camera && cfg.film_transparent) {
                if (primary) primary->alpha = 0.f;
                return Vec3();
            }
            // Cycles clamps light that a ray finds with the ray's bounce - 1: light reaching
            // the first surface is direct, whether sampled there or found by its bounce ray.
            const Vec3 world = clamped(world_missed(st, ray.d), st.weight, st.bounces > 1);
            if (st.split) tap(st, world, cfg.light_groups.world, true);
            return world + clamped(lamps, st.weight, st.bounces > 1);
        }
        if (st.camera && scene_.instance(sp.instance).holdout) {  // a hole in the image
            if (primary) primary->alpha = 0.f, primary->hit = true, primary->t = sp.t;
            return Vec3();
        }
        float path[kLightPathFloats];
        if (scene_.any_light_path()) light_path_of(st, sp.t, false, st.transparent, path);
        const NodeQueries queries(*this, sp, st.from, rng, tally, st.min_pdf);
        mat = scene_.material_at(sp, ray.d * -1.f, &camera_, st.from.time, aov_writing ? &aov : nullptr,
                                 scene_.any_light_path() ? path : nullptr, &queries);
        base = mat.use_point_colour && sp.has_point_colour ? sp.point_colour : mat.base;
        opacity = mat.alpha * (mat.use_point_alpha ? sp.point_alpha : 1.f);
        if (aov_writing && film_.aov.done_after(opacity)) aov_writing = false;
        if (opacity >= 1.f || st.transparent >= cfg.transparent_bounces ||
            rng.get1(Sampler::kTransparent + Sampler::kDimStride * uint32_t(st.transparent)) < opacity)
            break;
        ++st.transparent, ++tally.transparent;
        passed = sp;
        st.from = Origin{passed.instance, passed.prim, passed.members, passed.n_members,
                         inside_after_crossing(passed, st.from.inside), false, st.from.catcher_only,
                         st.from.time};
        const float travelled = sp.t;
        ray.o = sp.p + ray.d * sp.offset;
        ray.tmin = 0.f;
        ray.tmax = ray.tmax - travelled;
        if (!(ray.tmax > 0.f)) {
            const Vec3 world = clamped(world_missed(st, ray.d), st.weight, st.bounces > 1);
            if (primary && st.camera && film_.environment) primary->environment = world;
            if (st.split) tap(st, world, cfg.light_groups.world, true);
            return world;
        }
    }

    const Vec3 wo = ray.d * -1.f;
    // Which side the ray arrived on: for splats the layer's facing, for triangles the winding.
    const bool entering = sp.front;
    // An open cloud met from behind (SplatScene::open_back) is a back face, as in Cycles:
    // its normals turn towards the ray below, and so does its Normal pass.
    const bool open_back = scene_.open_back(sp);
    Vec3 n = sp.ns, ng = sp.ng;
    if (dot(ng, wo) < 0.f) ng = ng * -1.f;
    if (dot(n, wo) < 0.f) n = n * -1.f;  // two-sided shading
    Lobes blurred(mat, base, entering);
    // Cycles' Filter Glossy: after a bounce into a direction of small pdf (a diffuse or rough
    // one), glossy lobes get at least the roughness sqrt(1 - pdf / Filter Glossy) / 2, so that
    // the caustic paths that make fireflies are found by light sampling instead.
    if (filter_glossy_ > 0.f && st.min_pdf < kInfinity) {
        const float blur_pdf = filter_glossy_ * st.min_pdf;
        if (blur_pdf < 1.f) blurred.blur(std::sqrt(1.f - blur_pdf) * 0.5f);
    }
    const Lobes &lobes = blurred;
    const float cos_o = std::fmax(dot(n, wo), 1e-6f);
    const Vec3 diffuse_albedo = lobes.diffuse(cos_o);

    Vec3 emitted = mat.emission;  // two-sided, like Cycles' Emission shader
    if (st.mis_pdf > 0.f && mesh_lights_) {  // (the environment light sets mis_pdf too)
        // Shadow rays could have found this point too: the power heuristic shares it between
        // the two ways (pdfs in solid angle at the point the ray left; n shadow samples count n).
        // Met edge on, the point is one light sampling never picks (kEdgeOnCosine): all its own.
        const float area_pdf = mesh_lights_->area_pdf(sp.instance, sp.prim, mat, sp.front);
        const float cos_l = std::fabs(dot(sp.ng, ray.d));
        if (area_pdf > 0.f && cos_l > kEdgeOnCosine) {
            const Vec3 to = sp.p - st.mis_from;
            const float light_pdf = area_pdf * dot(to, to) / cos_l * float(cfg.shadow_samples);
            emitted = emitted * (cfg.mesh_light_strategy == IntegratorSettings::kLightOnly
                                     ? 0.f
                                     : power_heuristic(st.mis_pdf, light_pdf));
        }
    }
    // Clamped after the MIS weight, as Cycles' film_clamp_light sees the weighted emission.
    const Vec3 emission = clamped(emitted, st.weight, st.bounces > 1);
    if (primary && st.camera) {
        // Cycles writes a back face's normal turned towards the viewer (it flips N with Ng).
        primary->hit = true, primary->t = sp.t, primary->normal = open_back ? sp.ns * -1.f : sp.ns;
        primary->diffcol = diffuse_albedo, primary->emit = emission;
        primary->index = scene_.instance(sp.instance).pass_index, primary->splats = sp.n_members;
        primary->catcher = scene_.instance(sp.instance).shadow_catcher;
        primary->position = sp.p, primary->material_index = mat.pass_index;
        primary->instance = sp.instance, primary->material = sp.material;
        if (film_.mist) primary->mist = mist_term(sp.p);
        if (film_.uv) {
            if (const TriangleMesh *mesh = scene_.instance(sp.instance).mesh) {
                const Vec3 uv = mesh->uv(sp.prim, sp.b1, sp.b2);
                primary->uv = Vec3(uv.x, uv.y, 1.f);
            }
        }
        if (st.split) {
            // Cycles' colour passes: the lobes' albedos seen from the camera.
            LightSums &ls = *st.split;
            ls.color[kLobeDiffuse] = ls.color[kLobeDiffuse] + diffuse_albedo;
            ls.color[kLobeGlossy] = ls.color[kLobeGlossy] + lobes.glossy_albedo(cos_o);
            ls.color[kLobeTransmission] = ls.color[kLobeTransmission] + lobes.transmission(cos_o);
        }
    }
    if (st.split) tap(st, emission, cfg.light_groups.of_instance(sp.instance), true);
    Vec3 L = emission + clamped(lamps, st.weight, st.bounces > 1);
    if (cfg.headlight) return L + base * std::fabs(dot(sp.ns, wo));

    Origin here = leaving(sp, st.from, &sp.offset);
    if (primary && st.camera && film_.ao) primary->ao = ao_term(sp, here, n, ng, rng, tally);
    auto spawn = [&](Vec3 dir) {
        Ray r;
        const Vec3 side = (dot(dir, ng) >= 0.f) ? ng : ng * -1.f;
        r.o = sp.p + side * sp.offset;
        r.d = dir;
        r.tmin = 0.f;
        r.tmax = kInfinity;
        return r;
    };

    // How the path goes on below: one sampled continuation among the lobes that are not traced
    // exactly, picked by these weights. Known before the light sampling, whose MIS needs them.
    LobePicks picks;
    if (lit_scene_ && st.bounces < cfg.max_bounces && st.bounces < kMaxDepth) {
        picks.diffuse = !cfg.sky_ao && st.diffuse < cfg.diffuse_bounces ? luminance(diffuse_albedo) : 0.f;
        picks.glossy = !lobes.delta && st.glossy < cfg.glossy_bounces ? luminance(lobes.specular(cos_o)) : 0.f;
        picks.transmission =
            !lobes.delta && st.transmission < cfg.transmission_bounces ? luminance(lobes.transmission(cos_o)) : 0.f;
        picks.sum = picks.diffuse + picks.glossy + picks.transmission;
    }

    L = L + direct_light(sp, here, n, ng, wo, cos_o, lobes, picks, rng, st.camera ? primary : nullptr, tally,
                         st.weight, st.bounces > 0, st);

    // Nothing in the scene gives light (no lamp, a black world, no emission): no further ray
    // can bring any back, so none is traced.
    if (!lit_scene_) return L;
    if (st.bounces >= cfg.max_bounces || st.bounces >= kMaxDepth) return L;

    // Continues the path with `weight`, by Russian roulette when its throughput is small.
    // `pdf`: the sampled direction's (Filter Glossy's min_ray_pdf); infinite for a mirror or
    // clear glass (Cycles gives those 1e6, which no Filter Glossy up to its maximum of 10 uses).
    // `mis_pdf`: the same density when mesh lights were sampled here too, else 0.
    // `branch`: which of the rays from here it is (kSampled, or a mirror or glass ray), for
    // the next vertex's random numbers.
    auto follow = [&](Vec3 dir, Vec3 weight, uint32_t kind, int PathState::*counter, int inside,
                      uint64_t Tally::*count, bool specular, float pdf, float mis_pdf, uint32_t branch) {
        const Sampler next_rng = rng.bounce(branch);
        PathState next = st;
        next.camera = false;
        next.kind = kind;
        next.bounces += 1;
        next.*counter += 1;
        next.from = here;
        next.from.inside = inside;
        next.from.back = here.back && kind != kVisTransmission;  // a refracted ray crosses to the front
        next.throughput = st.throughput * luminance(weight);
        // Lamps are seen only along a chain of mirror/glass rays from the camera: after a
        // diffuse or rough bounce, a lamp seen through a mirror is a caustic, which light
        // sampling cannot find and which would only add fireflies (not traced, like the
        // glass's shadow).
        next.specular = st.specular && specular;
        next.singular = specular;
        next.mis_pdf = mis_pdf, next.mis_from = sp.p;
        if (next.throughput < kRouletteThroughput) {
            const float survive = next.throughput / kRouletteThroughput;
            if (!(next_rng.get1(Sampler::kRoulette) < survive)) return;
            weight = weight * (1.f / survive);
            next.throughput = kRouletteThroughput;
        }
        next.weight = st.weight * weight;
        next.min_pdf = std::fmin(st.min_pdf, pdf);
        if (st.split && st.lobe == kLobeNone)  // the first bounce names the light passes of all that follows
            next.lobe = kind == kVisDiffuse ? kLobeDiffuse : kind == kVisGlossy ? kLobeGlossy : kLobeTransmission;
        ++(tally.*count);
        L = L + weight * radiance(spawn(dir), next, next_rng, nullptr, tally);
    };
    const int inside_after = inside_after_crossing(sp, st.from.inside);

    // Mirror and clear glass: both rays, each weighted by its Fresnel term.
    if (lobes.delta) {
        const Vec3 spec = lobes.specular(cos_o);
        if (luminance(spec) > 0.f && st.glossy < cfg.glossy_bounces)
            follow(reflect(wo, n), spec, kVisGlossy, &PathState::glossy, st.from.inside, &Tally::reflection, true,
                   kInfinity, 0.f, kMirror);
        Vec3 wt;
        const Vec3 trans = lobes.transmission(cos_o);
        if (luminance(trans) > 0.f && st.transmission < cfg.transmission_bounces && refract(wo, n, lobes.eta, &wt))
            follow(wt, trans, kVisTransmission, &PathState::transmission, inside_after, &Tally::refraction, true,
                   kInfinity, 0.f, kGlass);
    }

    // Sky light by ambient occlusion replaces the diffuse bounce.
    const Vec3 sky = world_seen(kVisDiffuse);
    if (cfg.sky_ao && luminance(diffuse_albedo) > 0.f && luminance(sky) > 0.f) {
        const Vec3 skylight =
            clamped(diffuse_albedo * sky * sky_occlusion(sp, here, n, ng, rng, tally, st), st.weight, st.bounces > 0);
        L = L + skylight;
        if (st.split) tap(st, skylight, cfg.light_groups.world, false, kLobeDiffuse);
    }

    // One sampled continuation among the lobes that are not traced exactly.
    const float w_diffuse = picks.diffuse, w_glossy = picks.glossy, w_trans = picks.transmission,
                w_sum = picks.sum;
    if (w_sum > 0.f) {
        float bsdf_u[3];
        rng.get(Sampler::kBsdf, bsdf_u, 3);
        // The direction from the pair whose strata are finest (Sobol's dimensions 0 and 1).
        const float u1 = bsdf_u[0], u2 = bsdf_u[1];
        float u = bsdf_u[2] * w_sum;
        // The sampled reflection's density, computed only where it is needed: Cycles'
        // min_ray_pdf for Filter Glossy (infinite without it), and the MIS weight of mesh
        // lights (0 without them: emission the ray meets counts in full).
        float pdf = kInfinity, mis_pdf = 0.f;
        auto densities = [&](Vec3 wi) {
            if (!(filter_glossy_ > 0.f) && !mesh_lights_ && !environment_light_) return;
            const float p = reflection_pdf(lobes, n, wo, cos_o, wi, picks);
            if (filter_glossy_ > 0.f) pdf = p;
            if (mesh_lights_ || environment_light_) mis_pdf = p;
        };
        if (u < w_diffuse) {
            const Vec3 wi = sample_cosine(n, u1, u2);
            if (dot(wi, ng) > 0.f) {
                densities(wi);
                follow(wi, diffuse_albedo * (w_sum / w_diffuse * bump_shadowing(sp, wi)), kVisDiffuse,
                       &PathState::diffuse, st.from.inside,
                       &Tally::diffuse, false, pdf, mis_pdf, kSampled);
            }
        } else if ((u -= w_diffuse) < w_glossy) {
            const Vec3 m = sample_ggx_vndf(n, wo, lobes.alpha, u1, u2);
            const Vec3 wi = reflect(wo, m);
            if (dot(wi, n) > 0.f && dot(wi, ng) > 0.f) {
                // VNDF sampling: the estimator is F(wo.m) G1(wi).
                const Vec3 w = lobes.specular(std::fmax(dot(wo, m), 0.f)) * ggx_g1(dot(wi, n), lobes.alpha);
                densities(wi);
                follow(wi, w * (w_sum / w_glossy), kVisGlossy, &PathState::glossy, st.from.inside,
                       &Tally::reflection, false, pdf, mis_pdf, kSampled);
            }
        } else {
            const Vec3 m = sample_ggx_vndf(n, wo, lobes.alpha, u1, u2);
            Vec3 wt;
            if (refract(wo, m, lobes.eta, &wt) && dot(wt, n) < 0.f) {
                const Vec3 w = lobes.transmission(std::fmax(dot(wo, m), 0.f)) * ggx_g1(-dot(wt, n), lobes.alpha);
                if (filter_glossy_ > 0.f) {
                    // The VNDF's pdf of m times the refraction's Jacobian (Walter et al. 2007).
                    const float om = dot(wo, m), tm = dot(wt, m), den = om + lobes.eta * tm;
                    pdf = (w_trans / w_sum) * ggx_g1(cos_o, lobes.alpha) * std::fmax(om, 0.f) *
                          ggx_d(std::fmax(dot(n, m), 0.f), lobes.alpha) / cos_o * lobes.eta * lobes.eta *
                          std::fabs(tm) / std::fmax(den * den, 1e-12f);
                }
                follow(wt, w * (w_sum / w_trans), kVisTransmission, &PathState::transmission, inside_after,
                       &Tally::refraction, false, pdf, 0.f, kSampled);
            }
        }
    }
    return L;
}

// A camera pixel's footprint at p, as Cycles' ray differential gives it at a camera ray's hit
// (camera.h, differential.h): the distance from the camera times the angle between the ray
// through p and its neighbours one pixel over (x and y averaged); an orthographic pixel's own
// size. A panorama: the distance times the pixel's extent in its image coordinates (an
// approximation). Cycles carries differentials along the path; here every point gets the
// footprint the camera would see there.
float Integrator::pixel_width(Vec3 p) const {
    const Camera &c = camera_;
    const double *m = c.local_from_camera;
    const double d[3] = {double(p.x) - m[3], double(p.y) - m[7], double(p.z) - m[11]};
    double q[3];  // p in camera space (looking down -Z)
    for (int k = 0; k < 3; ++k) {
        const double len = std::sqrt(m[k] * m[k] + m[4 + k] * m[4 + k] + m[8 + k] * m[8 + k]);
        q[k] = (m[k] * d[0] + m[4 + k] * d[1] + m[8 + k] * d[2]) / (len > 0 ? len : 1.0);
    }
    const double px = std::fabs(c.frustum[1] - c.frustum[0]) / std::max(film_.width, 1);
    const double py = std::fabs(c.frustum[3] - c.frustum[2]) / std::max(film_.height, 1);
    if (c.orthographic && !c.panoramic()) return float(0.5 * (px + py));
    const double distance = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2]);
    if (c.panoramic() || !(-q[2] > 0.0)) return float(distance * 0.5 * (px + py));
    // The directions through p and one pixel over on the unit plane, normalised, apart.
    const double u = q[0] / -q[2], v = q[1] / -q[2];
    auto apart = [&](double du, double dv) {
        const double a = std::sqrt(u * u + v * v + 1.0), b = std::sqrt((u + du) * (u + du) + (v + dv) * (v + dv) + 1.0);
        const double x = (u + du) / b - u / a, y = (v + dv) / b - v / a, z = 1.0 / b - 1.0 / a;
        return std::sqrt(x * x + y * y + z * z);
    };
    return float(distance * 0.5 * (apart(px, 0.0) + apart(0.0, py)));
}

Origin Integrator::leaving(const SurfacePoint &sp, const Origin &path, float *offset) const {
    // Where rays leave this point from: the splats that formed it are excluded (the paper's
    // wrong-reflection rule), and a triangle's point is moved off the surface on the side
    // the new ray goes. Without wrong-hit elimination (the general method, the baseline of
    // the A/B comparison) splat rays leave as in plain splat ray tracing: nothing excluded,
    // the origin moved off the disc by a small fraction of its radius -- and they do hit the
    // neighbouring discs, which is what the paper's wrong shadows and reflections are.
    Origin here{sp.instance, sp.prim, sp.members, sp.n_members, path.inside, false, path.catcher_only, path.time};
    *offset = sp.offset;
    if (!settings_.method.wrong_hit_elimination && sp.n_members > 0) {
        here.members = nullptr, here.n_members = 0;
        *offset = kPlainSplatOffset * sp.radius;
    } else if (scene_.open_back(sp)) {
        // Rays leaving an open sheet's back on that side (lamps, sky, reflection, diffuse:
        // every ray but the refracted one) meet the neighbouring discs from their front.
        // Wrong-hit elimination, which ignores back-facing discs only, would take those for
        // a surface: the sheet shadowed itself (a depth frame oriented away from its sensor,
        // lit from the sensor's side: 35-40 % of its pixels black). On this side the sheet's
        // back is its outside: these rays query it with the facing swapped (Origin::back), the
        // mirror image of what rays leaving its front see.
        here.back = true;
    }
    return here;
}

Ray Integrator::shadow_ray(const SurfacePoint &sp, Vec3 ng, Vec3 wi, float distance) {
    Ray r;
    r.o = sp.p + ng * sp.offset;
    r.d = wi;
    r.tmin = 0.f;
    // Stop just short of the light's surface: a lamp is not geometry here, and an emissive
    // triangle must not shadow itself.
    r.tmax = std::isinf(distance) ? kInfinity : distance * (1.f - 1e-4f);
    return r;
}

// The pdf of the BSDF as Cycles' is for a direction (every sampled lobe, by its pick),
// computed as the Filter Glossy min_ray_pdf has always been.
float Integrator::reflection_pdf(const Lobes &lobes, Vec3 n, Vec3 wo, float cos_o, Vec3 wi, const LobePicks &picks) {
    if (!(picks.sum > 0.f)) return 0.f;  // the path ends here: no reflection is sampled
    const float diffuse_pdf = std::fmax(dot(n, wi), 0.f) / kPi;  // cosine-weighted
    const float glossy_pdf = picks.glossy > 0.f ? ggx_reflection_pdf(n, wo, wi, cos_o, lobes.alpha) : 0.f;
    return (picks.diffuse * diffuse_pdf + picks.glossy * glossy_pdf) / picks.sum;
}

Vec3 Integrator::direct_light(const SurfacePoint &sp, const Origin &from, Vec3 n, Vec3 ng, Vec3 wo, float cos_o,
                              const Lobes &lobes, const LobePicks &picks, const Sampler &rng,
                              Primary *primary, Tally &tally, Vec3 weight, bool indirect,
                              const PathState &st) const {
    const std::vector<Light> &lights = scene_.lights();
    if (lights.empty() && !mesh_lights_ && !environment_light_) return Vec3();  // nothing to sample: no work
    const Vec3 diffuse = lobes.diffuse(cos_o) * (1.f / kPi);
    const bool glossy = !lobes.delta && luminance(lobes.specular(cos_o)) > 0.f;
    if (luminance(diffuse) <= 0.f && !glossy) return Vec3();  // mirror, glass, pure emitter
    const int k = settings_.shadow_samples;
    const float share = 1.f / float(k);
    // The reflection towards wi (cos_i = n . wi > 0): the diffuse and the glossy lobe.
    auto glossy_brdf = [&](Vec3 wi, float cos_i) { return lobes.glossy_brdf(n, wo, cos_o, wi, cos_i); };
    // Clamped, each lamp's light here is one contribution, as each of Cycles' shadow rays is
    // (Cycles picks one lamp per shadow ray; this engine samples every lamp).
    const bool clamp = (indirect ? clamp_indirect_ : clamp_direct_) < kInfinity;
    const bool split = st.split != nullptr;  // read once: the stores below may alias it
    auto tap_split = [&](Vec3 all, Vec3 diffuse_part, Vec3 added, int group) {
        tap_sampled(st, all, diffuse_part, added, group);
    };
    Vec3 L;
    for (size_t i = 0; i < lights.size(); ++i) {
        const Light &light = lights[i];
        Vec3 lamp, lamp_diffuse;  // lamp_diffuse, and lamp without the clamp: light passes only
        for (int s = 0; s < k; ++s) {
            float u[2];
            rng.get(Sampler::kLamp + Sampler::kDimStride * uint32_t(i), u, 2, uint32_t(s), uint32_t(k));
            const float u1 = u[0], u2 = u[1];
            const LightSample ls = sample_light(light, sp.p, u1, u2);
            if (!ls.valid) continue;
            const float cos_i = dot(n, ls.wi);
            if (cos_i <= 0.f || dot(ng, ls.wi) <= 0.f) continue;  // below the surface
            const Vec3 shadowed = diffuse * bump_shadowing(sp, ls.wi);
            Vec3 f = shadowed;
            if (glossy) f = f + glossy_brdf(ls.wi, cos_i);
            const Vec3 c = f * ls.irradiance * (cos_i * share);
            if (!(luminance(c) > 0.f)) continue;
            Vec3 visible(1, 1, 1);
            if (light.cast_shadow) {
                ++tally.shadow;
                visible = shadow_transmittance(shadow_ray(sp, ng, ls.wi, ls.distance), from, tally, &st);
            }
            if (clamp) lamp = lamp + c * visible;
            else L = L + c * visible;
            if (split) {
                if (!clamp) lamp = lamp + c * visible;
                lamp_diffuse = lamp_diffuse + shadowed * ls.irradiance * visible * (cos_i * share);
            }
            if (primary) primary->unshadowed += luminance(c), primary->lit += luminance(c * visible);
        }
        if (clamp) L = L + clamped(lamp, weight, indirect);
        if (split) tap_split(lamp, lamp_diffuse, clamp ? clamped(lamp, weight, indirect) : lamp,
                                settings_.light_groups.of_lamp(i));
    }
    // Emissive triangles: a point of one picked by power, weighed against the chance that
    // the path's own sampled reflection finds it (the weight its emission gets in radiance()).
    if (mesh_lights_) {
        const bool light_only = settings_.mesh_light_strategy == IntegratorSettings::kLightOnly;
        for (int s = 0; s < k; ++s) {
            float u[3];
            rng.get(Sampler::kMeshLight, u, 3, uint32_t(s), uint32_t(k));
            const float u0 = u[2], u1 = u[0], u2 = u[1];  // the point from the finest pair
            MeshLightSample ls = mesh_lights_->sample(sp.p, u0, u1, u2);
            if (!ls.valid) continue;
            const Instance &emitter = scene_.instance(ls.instance);
            // A catcher-only path shades the catchers as if nothing else were there: another
            // object's emission is not in it (its rays cannot meet one either), as Cycles
            // flags the emissive triangles of a non-catcher SHADER_EXCLUDE_SHADOW_CATCHER.
            if (from.catcher_only && !emitter.shadow_catcher) continue;
            const float cos_i = dot(n, ls.wi);
            if (cos_i <= 0.f || dot(ng, ls.wi) <= 0.f) continue;  // below the surface
            // A programmed emitter was picked by its estimate: what it really emits at the
            // point, towards this one, is its program's (the pdf stays the estimate's).
            if (ls.programmed)
                ls.emission = scene_.emitted_on_triangle(ls.instance, ls.tri, ls.b1, ls.b2, ls.wi * -1.f, &camera_,
                                                         from.time);
            // As Cycles excludes them: an emitter hidden from diffuse (glossy) rays lights no
            // diffuse (glossy) lobe -- the rays of that lobe could never meet it either.
            const Vec3 shadowed = emitter.visibility & kVisDiffuse ? diffuse * bump_shadowing(sp, ls.wi) : Vec3();
            Vec3 f = shadowed;
            if (glossy && (emitter.visibility & kVisGlossy)) f = f + glossy_brdf(ls.wi, cos_i);
            const float light_pdf = ls.pdf * float(k);
            const float w =
                light_only ? 1.f : power_heuristic(light_pdf, reflection_pdf(lobes, n, wo, cos_o, ls.wi, picks));
            const Vec3 c = f * ls.emission * (cos_i * w / light_pdf);
            if (!(luminance(c) > 0.f)) continue;
            ++tally.shadow;
            // Not in the Shadow pass, which is the lamps' (a closed emitter's far side, shadowed
            // by its near side, would darken it everywhere).
            const Vec3 through = shadow_transmittance(shadow_ray(sp, ng, ls.wi, ls.distance), from, tally, &st);
            const Vec3 lit = c * through;
            // Clamped, each sample is one of Cycles' shadow rays (one emitter picked, its light
            // weighed by MIS, then film_clamp_light): the whole estimate it is, k times its share.
            const Vec3 added = clamp ? clamped(lit * float(k), weight, indirect) * share : lit;
            L = L + added;
            if (split) {
                const Vec3 diffuse_part = shadowed * ls.emission * through * (cos_i * w / light_pdf);
                tap_split(lit, diffuse_part, added, settings_.light_groups.of_instance(ls.instance));
            }
        }
    }
    if (environment_light_)
        L = L + environment_light(sp, from, n, ng, wo, cos_o, lobes, picks, rng, tally, weight, indirect, st);
    return L;
}

Vec3 Integrator::world_missed(const PathState &st, Vec3 d) const {
    const Vec3 world = world_seen(st.kind, d);
    // A sampled diffuse or glossy bounce (mis_pdf > 0) could have been drawn by the
    // environment light too: the power heuristic shares the direction between the two ways.
    if (!environment_light_ || !(st.mis_pdf > 0.f)) return world;
    if (settings_.mesh_light_strategy == IntegratorSettings::kLightOnly) return Vec3();
    const float light_pdf = environment_light_->pdf(d) * float(settings_.shadow_samples);
    return world * power_heuristic(st.mis_pdf, light_pdf);
}

Vec3 Integrator::environment_light(const SurfacePoint &sp, const Origin &from, Vec3 n, Vec3 ng, Vec3 wo,
                                   float cos_o, const Lobes &lobes, const LobePicks &picks, const Sampler &rng,
                                   Tally &tally, Vec3 weight, bool indirect, const PathState &st) const {
    const uint32_t vis = settings_.world_visibility;
    // As a world hidden from diffuse (glossy) rays lights no diffuse (glossy) lobe in Cycles.
    const Vec3 diffuse = vis & kVisDiffuse ? lobes.diffuse(cos_o) * (1.f / kPi) : Vec3();
    const bool glossy = (vis & kVisGlossy) && !lobes.delta && luminance(lobes.specular(cos_o)) > 0.f;
    if (luminance(diffuse) <= 0.f && !glossy) return Vec3();
    const int k = settings_.shadow_samples;
    const float share = 1.f / float(k);
    const bool clamp = (indirect ? clamp_indirect_ : clamp_direct_) < kInfinity;
    Vec3 L;
    for (int s = 0; s < k; ++s) {
        float u[2];
        rng.get(Sampler::kEnvironment, u, 2, uint32_t(s), uint32_t(k));
        const EnvironmentSample es = environment_light_->sample(u[0], u[1]);
        if (!es.valid) continue;
        const float cos_i = dot(n, es.wi);
        if (cos_i <= 0.f || dot(ng, es.wi) <= 0.f) continue;  // below the surface
        const Vec3 shadowed = diffuse * bump_shadowing(sp, es.wi);
        Vec3 f = shadowed;
        if (glossy) f = f + lobes.glossy_brdf(n, wo, cos_o, es.wi, cos_i);
        const float light_pdf = es.pdf * float(k);
        const float w = settings_.mesh_light_strategy == IntegratorSettings::kLightOnly
                            ? 1.f
                            : power_heuristic(light_pdf, reflection_pdf(lobes, n, wo, cos_o, es.wi, picks));
        const Vec3 c = f * es.radiance * (cos_i * w / light_pdf);
        if (!(luminance(c) > 0.f)) continue;
        ++tally.shadow;
        const Vec3 through = shadow_transmittance(shadow_ray(sp, ng, es.wi, kInfinity), from, tally, &st);
        const Vec3 lit = c * through;
        const Vec3 added = clamp ? clamped(lit * float(k), weight, indirect) * share : lit;
        L = L + added;
        if (st.split) {
            // The world's light reaching a surface is Direct light in Cycles' passes, as a
            // lamp's, all in the world's group.
            const Vec3 diffuse_part = shadowed * es.radiance * through * (cos_i * w / light_pdf);
            tap_sampled(st, lit, diffuse_part, added, settings_.light_groups.world);
        }
    }
    return L;
}

// The fraction of the sky the point sees, by cosine-distributed occlusion rays: with the
// cosine in the pdf, the diffuse integral of a uniform sky is albedo x world x that fraction.
// Each open direction weighed by the bump shadowing term, as the diffuse bounce this replaces
// is (and as Cycles' own replacement, Fast GI's AO bounces, samples and evaluates the BSDF
// with it); Cycles' AO pass and additive AO skip it, and so does ao_term.
Vec3 Integrator::sky_occlusion(const SurfacePoint &sp, const Origin &from, Vec3 n, Vec3 ng, const Sampler &rng,
                               Tally &tally, const PathState &st) const {
    Vec3 open;
    const int k = settings_.ao_samples;
    for (int i = 0; i < k; ++i) {
        float u[2];
        rng.get(Sampler::kOcclusion, u, 2, uint32_t(i), uint32_t(k));
        const Vec3 wi = sample_cosine(n, u[0], u[1]);
        if (dot(wi, ng) <= 0.f) continue;
        Ray r;
        r.o = sp.p + ng * sp.offset;
        r.d = wi;
        ++tally.diffuse;
        // A Light Path node on a blocker sees a shadow ray of this path, as on every shadow ray.
        open = open + shadow_transmittance(r, from, tally, &st) * bump_shadowing(sp, wi);
    }
    return open * (1.f / float(k));
}

Vec3 Integrator::shadow_transmittance(Ray ray, Origin from, Tally &tally, const PathState *st) const {
    const Method &method = settings_.method;
    if (!scene_.any_transparent()) return scene_.occluded(ray, method, from, &tally.stats) ? Vec3() : Vec3(1, 1, 1);
    // Some materials are partly transparent: walk the blockers, attenuating by their alpha.
    Vec3 t(1, 1, 1);
    SurfacePoint sp, previous;  // `from` points into `previous` while `sp` is being found
    for (int k = 0; k <= settings_.transparent_bounces; ++k) {
        sp = scene_.intersect(ray, method, kVisShadow, from, nullptr, &tally.stats);
        if (!sp.valid()) return t;
        float path[kLightPathFloats];
        const bool light_path = st && scene_.any_light_path();
        if (light_path) light_path_of(*st, sp.t, true, st->transparent + k, path);
        const Material m = scene_.material_at(sp, ray.d * -1.f, &camera_, from.time, nullptr,
                                              light_path ? path : nullptr);
        const float a = m.alpha * (m.use_point_alpha ? sp.point_alpha : 1.f);
        if (a >= 1.f) return Vec3();
        t = t * (1.f - a);
        previous = sp;
        from = Origin{previous.instance, previous.prim, previous.members, previous.n_members,
                      inside_after_crossing(previous, from.inside), false, from.catcher_only,
                      from.time};
        ray.o = sp.p + ray.d * sp.offset;
        ray.tmax -= sp.t;
        if (!(ray.tmax > 0.f)) return t;
    }
    return Vec3();
}

}  // namespace splat

namespace splat {

// Where a path's light goes in Cycles' light passes (kernel/film/light_passes.h): by the lobe
// of the path's first bounce, Direct when it reached the first surface straight from its
// source -- sampled there, or found by the first bounce's ray (emission, a lamp, the world) --
// Indirect otherwise. What the camera itself sees is the Emission and Environment passes.
// Every piece counts in its light group, whatever the depth.
void Integrator::tap(const PathState &st, Vec3 c, int group, bool found, int lobe) const {
    LightSums &sums = *st.split;
    const Vec3 v = st.weight * c;  // what the pixel gets of it
    if (group >= 0 && group < settings_.light_groups.count) sums.group[group] = sums.group[group] + v;
    const int l = st.lobe != kLobeNone ? st.lobe : lobe;
    if (l == kLobeNone) return;
    if (st.bounces == (found ? 1 : 0)) sums.direct[l] = sums.direct[l] + v;
    else sums.indirect[l] = sums.indirect[l] + v;
}

// Light sampled at a surface (a lamp's, emissive triangles', the world's): `all` reached it, of
// which `diffuse_part` lit the diffuse lobe and the rest the glossy one; `added` is what the
// path got of it after the clamp, which scales all channels alike. Nothing when all is 0
// (shadowed: nothing to split).
void Integrator::tap_sampled(const PathState &st, Vec3 all, Vec3 diffuse_part, Vec3 added, int group) const {
    const float total = luminance(all);
    if (!(total > 0.f)) return;
    const float scale = luminance(added) / total;
    tap(st, diffuse_part * scale, group, false, kLobeDiffuse);
    tap(st, (all - diffuse_part) * scale, group, false, kLobeGlossy);
}

float Integrator::ao_term(const SurfacePoint &sp, const Origin &from, Vec3 n, Vec3 ng, const Sampler &rng,
                          Tally &tally) const {
    float u[2];
    rng.get(Sampler::kAoPass, u, 2);
    const Vec3 wi = sample_cosine(n, u[0], u[1]);
    if (dot(wi, ng) <= 0.f) return 0.f;  // Cycles adds nothing for a direction under the surface
    Ray r;
    r.o = sp.p + ng * sp.offset;
    r.d = wi;
    r.tmin = 0.f;
    r.tmax = settings_.ao_distance;
    ++tally.shadow;
    return scene_.occluded(r, settings_.method, from, &tally.stats) ? 0.f : 1.f;
}

// Cycles' film read (kernel/film/read.h, film_get_pass_pixel_divide_even_color): the direct
// and indirect passes are the ratio of their sums to the colour's (0 where the colour is 0);
// the colours, AO and the groups are means.
void Integrator::write_light(const LightSums &sums, float inv, size_t p) const {
    const size_t plane = size_t(film_.w) * size_t(film_.h) * 3;
    auto put = [&](float *buf, Vec3 v) { buf[3 * p] = v.x, buf[3 * p + 1] = v.y, buf[3 * p + 2] = v.z; };
    if (film_.light) {
        auto divide = [](float a, float b) { return b != 0.f ? a / b : 0.f; };
        for (int l = 0; l < kLobes; ++l) {
            const Vec3 col = sums.color[l];
            for (int which = 0; which < 2; ++which) {
                const Vec3 v = which == 0 ? sums.direct[l] : sums.indirect[l];
                put(film_.light + plane * size_t(which * kLobes + l),
                    Vec3(divide(v.x, col.x), divide(v.y, col.y), divide(v.z, col.z)));
            }
            put(film_.light + plane * size_t(2 * kLobes + l), col * inv);
        }
    }
    if (film_.ao) put(film_.ao, Vec3(1, 1, 1) * (sums.ao * inv));
    if (film_.light_groups)
        for (int g = 0; g < settings_.light_groups.count; ++g) put(film_.light_groups + plane * size_t(g), sums.group[g] * inv);
}

}  // namespace splat
