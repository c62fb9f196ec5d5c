#include "splats/splat_scene.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "base/config.h"
#include "base/parallel.h"
#include "bvh/packet.h"

namespace splat {
namespace {

bool finite3(const float *v) { return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]); }
bool in_range3(const float *v) { return within_range(v[0]) && within_range(v[1]) && within_range(v[2]); }

[[noreturn]] void bad_splat(size_t i, const char *what) {
    throw InputError("splat " + std::to_string(i) + ": " + what);
}

}  // namespace

SplatScene::SplatScene(const float *centres, const float *normals, const float *radii,
                       const float *colours, const uint8_t *closed, size_t n, int threads, const float *alphas) {
    if (n >= size_t(INT32_MAX)) throw InputError("too many splats (ids are 32-bit)");
    threads = resolve_threads(threads);
    closed_.assign(n, 0);
    if (closed)
        for (size_t i = 0; i < n; ++i) closed_[i] = closed[i] ? 1 : 0, any_closed_ |= closed[i] != 0;
    has_colours_ = colours != nullptr;
    if (alphas) {
        alphas_.assign(alphas, alphas + n);
        for (size_t i = 0; i < n; ++i)
            if (!(alphas_[i] >= 0.f && alphas_[i] <= 1.f)) bad_splat(i, "alpha must be in 0..1");
    }
    if (colours) colours_.resize(n);
    // Checked and bounded in chunks on every thread; the first bad splat in input order is
    // the one reported, whichever thread met it first.
    constexpr size_t kChunk = 1 << 16;
    const size_t chunks = (n + kChunk - 1) / kChunk;
    // Left uninitialised: the threads of the loop below touch their pages first.
    Buffer<BuildPrim> prims(n);
    Buffer<PackedSplat> packed(n);  // input order, until the leaf order is known
    std::vector<size_t> bad(chunks, n);
    std::vector<const char *> why(chunks, nullptr);
    std::vector<AABB> chunk_bounds(chunks);
    std::vector<float> chunk_max_radius(chunks, 0.f);
    parallel_for(
        chunks, threads,
        [&](size_t k) {
            for (size_t i = k * kChunk, end = std::min(n, i + kChunk); i < end; ++i) {
                const float *c = centres + 3 * i, *nv = normals + 3 * i;
                const char *err = nullptr;
                if (!finite3(c)) err = "centre is not finite";
                else if (!in_range3(c)) err = "centre is beyond 1e18 (recentre the coordinates first)";
                else if (!finite3(nv)) err = "normal is not finite";
                else if (!(within_range(radii[i]) && radii[i] > 0.f)) err = "radius must be > 0 and at most 1e18";
                const double len = err ? 1.0 : std::sqrt(double(nv[0]) * nv[0] + double(nv[1]) * nv[1] + double(nv[2]) * nv[2]);
                if (!err && !(len > 0.0)) err = "normal has zero length";
                else if (!err && colours && !finite3(colours + 3 * i)) err = "colour is not finite";
                if (err) {
                    bad[k] = i, why[k] = err;
                    return;
                }
                const Vec3 nn(float(nv[0] / len), float(nv[1] / len), float(nv[2] / len));
                packed[i] = PackedSplat{Vec3(c[0], c[1], c[2]), radii[i], nn, int32_t(i)};
                const AABB box = disc_bounds(packed[i].c, nn, radii[i]);
                prims[i] = BuildPrim(box, uint32_t(i));
                chunk_bounds[k].grow(box);
                chunk_max_radius[k] = std::max(chunk_max_radius[k], radii[i]);
                if (colours) colours_[i] = Vec3(colours[3 * i], colours[3 * i + 1], colours[3 * i + 2]);
            }
        },
        [](size_t) { return true; });
    for (size_t k = 0; k < chunks; ++k) {
        if (why[k]) bad_splat(bad[k], why[k]);
        bounds_.grow(chunk_bounds[k]);
        max_radius_ = std::max(max_radius_, chunk_max_radius[k]);
    }
    bvh_.build(prims.data(), n, threads);
    // The splats in leaf order, written over the build records (read each before it is
    // overwritten): the same size, and their pages are already there.
    static_assert(sizeof(BuildPrim) == sizeof(PackedSplat), "splats are packed over the build records");
    slot_.allocate(n);
    parallel_for(
        chunks, threads,
        [&](size_t k) {
            for (size_t s = k * kChunk, end = std::min(n, s + kChunk); s < end; ++s) {
                const uint32_t i = prims[s].id;  // leaf order
                std::memcpy(static_cast<void *>(&prims[s]), &packed[i], sizeof(PackedSplat));
                slot_[i] = uint32_t(s);
            }
        },
        [](size_t) { return true; });
    splats_.adopt(prims);
}

void SplatScene::set_attributes(const float *values, int count) {
    if (count < 0 || count > kMaxPointAttributes)
        throw InputError("point attributes: " + std::to_string(count) + " per splat (0.." +
                         std::to_string(kMaxPointAttributes) + ")");
    const size_t n = size() * size_t(count);
    for (size_t i = 0; i < n; ++i)
        if (!std::isfinite(values[i])) bad_splat(i / size_t(count), "attribute is not finite");
    attributes_.assign(values, values + n);
    attribute_count_ = count;
}

size_t SplatScene::memory_bytes() const {
    return splats_.bytes() + slot_.bytes() +
           colours_.capacity() * sizeof(Vec3) + closed_.capacity() + alphas_.capacity() * sizeof(float) +
           attributes_.capacity() * sizeof(float) +
           bvh_.memory_bytes();
}

// The discs of leaf [first, first + count) tested against `ray`; `visit(splat, hit)` for
// each hit. Returns the discs tested.
template <class Visit>
uint32_t SplatScene::test_leaf(const Ray &ray, const DiscRay &disc_ray, uint32_t first, uint32_t count,
                               Visit &&visit) const {
    uint32_t k = first;
    const uint32_t end = first + count;
#ifdef SPLAT_SSE2
    // Four discs at a time (the same arithmetic as intersect_disc), in leaf order; the last
    // group takes the leaf's last four discs, skipping those already seen.
    if (count >= 4) {
        for (;;) {
            const uint32_t base = std::min(k, end - 4);
            const float *d[4];
            for (int j = 0; j < 4; ++j) d[j] = &splats_[base + j].c.x;
            float t[4], dist2[4];
            int mask = intersect_discs4(disc_ray, d, t, dist2) & (0xf << (k - base));
            while (mask) {
                const int j = __builtin_ctz(unsigned(mask));
                mask &= mask - 1;
                const PackedSplat &s = splats_[base + j];
                visit(s, DiscHit{t[j], dist2[j], dot(ray.d, s.n) < 0.f});
            }
            k = base + 4;
            if (k >= end) break;
        }
    }
#else
    (void)disc_ray;
#endif
    for (; k < end; ++k) {
        const PackedSplat &s = splats_[k];
        DiscHit h;
        if (intersect_disc(ray, s.c, s.n, s.r, &h)) visit(s, h);
    }
    return count;
}

// Every splat query is the shared BVH traversal with a visitor per disc hit.
template <class Visit>
void SplatScene::traverse(const Ray &ray, const float &limit, Visit &&visit, TraversalStats *stats) const {
    uint64_t discs = 0;
    const DiscRay disc_ray(ray);
    traverse_bvh(
        bvh_, ray, limit,
        [&](uint32_t first, uint32_t count) {
            discs += test_leaf(ray, disc_ray, first, count, visit);
            return false;
        },
        stats ? &stats->nodes : nullptr);
    if (stats) stats->discs += discs;
}

// The same for a packet of coherent rays (packet.h): `visit(i, splat, hit, limit)` for ray
// i, which may lower limit (the ray's pruning distance).
template <class Visit>
void SplatScene::traverse_packet(const Ray *rays, const PacketRays &soa, int n, Visit &&visit,
                                 TraversalStats *stats) const {
    uint64_t discs = 0;
#ifdef SPLAT_AVX2_KERNELS
    const bool avx2 = simd_avx2();
#endif
#ifdef SPLAT_SSE2
    (void)rays;  // the kernels read the packet by component
#else
    alignas(16) unsigned char store[kPacketRays * sizeof(DiscRay)];
    DiscRay *disc_rays = reinterpret_cast<DiscRay *>(store);
    for (int i = 0; i < n; ++i) new (&disc_rays[i]) DiscRay(rays[i]);
#endif
    splat::traverse_packet(
        bvh_, soa, n,
        [&](uint32_t mask, uint32_t first, uint32_t count, float *limit) {
            discs += uint64_t(count) * uint64_t(__builtin_popcount(mask));
#ifdef SPLAT_SSE2
            // Disc by disc against the packet's rays four (or eight) at a time, the lanes
            // being rays: no transposes, and each disc is loaded once for all its rays.
            auto on_hit = [&](int i, uint32_t k, const DiscHit &h) { visit(i, splats_[first + k], h, limit[i]); };
#ifdef SPLAT_AVX2_KERNELS
            if (avx2) intersect_disc_rays_avx2(soa, mask, &splats_[first].c.x, count, on_hit);
            else
#endif
                intersect_disc_rays(soa, mask, &splats_[first].c.x, count, on_hit);
#else
            for (uint32_t m = mask; m; m &= m - 1) {
                const int i = __builtin_ctz(m);
                test_leaf(rays[i], disc_rays[i], first, count,
                          [&](const PackedSplat &s, const DiscHit &h) { visit(i, s, h, limit[i]); });
            }
#endif
        },
        stats ? &stats->nodes : nullptr);
    if (stats) stats->discs += discs;
}

void SplatScene::intersect_packet(const Ray *rays, int n, Hit *out, TraversalStats *stats) const {
    const PacketRays soa(rays, n);
    if (!packet_coherent(soa, n, length(bounds_.extent()))) {
        for (int i = 0; i < n; ++i) out[i] = intersect(rays[i], stats);
        return;
    }
    for (int i = 0; i < n; ++i) out[i] = Hit();
    traverse_packet(
        rays, soa, n,
        [&](int i, const PackedSplat &s, const DiscHit &h, float &limit) {
            // Without a branch (which hit of a leaf is nearer is a coin toss for the predictor).
            Hit &b = out[i];
            const bool c = closer(h.t, s.id, b);
            b.t = c ? h.t : b.t, b.id = c ? s.id : b.id, b.front = c ? h.front : b.front;
            limit = b.t;
        },
        stats);
}

void SplatScene::gather_layer_packet(const Ray *rays, int n, LayerQuery *qs, TraversalStats *stats) const {
    const PacketRays soa(rays, n);
    if (!packet_coherent(soa, n, length(bounds_.extent()))) {
        for (int i = 0; i < n; ++i) gather_layer(rays[i], qs[i], false, stats);
        return;
    }
    for (int i = 0; i < n; ++i) begin_layer(rays[i], qs[i]);
    traverse_packet(
        rays, soa, n,
        [&](int i, const PackedSplat &s, const DiscHit &h, float &limit) {
            offer(qs[i], s, h);
            limit = fmin2(qs[i].cut, rays[i].tmax);  // the cut may lie past tmax: never look there
        },
        stats);
}

Hit SplatScene::intersect(const Ray &ray, TraversalStats *stats) const {
    Hit best;
    traverse(
        ray, best.t,
        [&](const PackedSplat &s, const DiscHit &h) {
            if (closer(h.t, s.id, best)) best.t = h.t, best.id = s.id, best.front = h.front;
        },
        stats);
    return best;
}

void SplatScene::begin_layer(const Ray &ray, LayerQuery &q) const {
    q.cut = ray.tmax;
    q.max_radius = max_radius_;
}

void SplatScene::offer(LayerQuery &q, const PackedSplat &s, const DiscHit &h) const {
    // Beyond the cut first: most hits offered late in the traversal are, and need no sqrt.
    if (h.t <= q.cut && !q.excluded(s.id))
        q.add(LayerHit{h.t, std::sqrt(h.dist2), s.r, s.id, uint32_t(&s - splats_.data()), h.front});
}

void SplatScene::gather_layer(const Ray &ray, LayerQuery &q, bool brute_force, TraversalStats *stats) const {
    begin_layer(ray, q);
    if (brute_force) {
        for (const PackedSplat &s : splats_) {
            DiscHit h;
            if (intersect_disc(ray, s.c, s.n, s.r, &h)) offer(q, s, h);
        }
        return;
    }
    traverse(ray, q.cut, [&](const PackedSplat &s, const DiscHit &h) { offer(q, s, h); }, stats);
}

Hit SplatScene::intersect_brute_force(const Ray &ray) const {
    Hit best;
    for (const PackedSplat &s : splats_) {
        DiscHit h;
        if (intersect_disc(ray, s.c, s.n, s.r, &h) && closer(h.t, s.id, best)) {
            best.t = h.t, best.id = s.id, best.front = h.front;
        }
    }
    return best;
}

}  // namespace splat
