#include "splat_scene.h"

#include <cmath>

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
    normals_.resize(n);
    closed_.assign(n, 0);
    if (closed)
        for (size_t i = 0; i < n; ++i) closed_[i] = closed[i] ? 1 : 0, any_closed_ |= closed[i] != 0;
    has_colours_ = colours != nullptr;
    if (alphas) {
        alphas_.assign(alphas, alphas + n);
        for (size_t i = 0; i < n; ++i)
            if (!(alphas_[i] >= 0.f && alphas_[i] <= 1.f)) bad_splat(i, "alpha must be in 0..1");
    }
    colours_.assign(n, Vec3(1.f, 1.f, 1.f));
    radii_.assign(radii, radii + n);
    std::vector<AABB> boxes(n);
    std::vector<Vec3> &centre = centres_;
    centre.resize(n);
    for (size_t i = 0; i < n; ++i) {
        const float *c = centres + 3 * i, *nv = normals + 3 * i;
        if (!finite3(c)) bad_splat(i, "centre is not finite");
        if (!in_range3(c)) bad_splat(i, "centre is beyond 1e18 (recentre the coordinates first)");
        if (!finite3(nv)) bad_splat(i, "normal is not finite");
        if (!(within_range(radii[i]) && radii[i] > 0.f)) bad_splat(i, "radius must be > 0 and at most 1e18");
        const double len = std::sqrt(double(nv[0]) * nv[0] + double(nv[1]) * nv[1] + double(nv[2]) * nv[2]);
        if (!(len > 0.0)) bad_splat(i, "normal has zero length");
        normals_[i] = Vec3(float(nv[0] / len), float(nv[1] / len), float(nv[2] / len));
        if (colours) {
            const float *col = colours + 3 * i;
            if (!finite3(col)) bad_splat(i, "colour is not finite");
            colours_[i] = Vec3(col[0], col[1], col[2]);
        }
        centre[i] = Vec3(c[0], c[1], c[2]);
        boxes[i] = disc_bounds(centre[i], normals_[i], radii[i]);
        bounds_.grow(boxes[i]);
    }
    bvh_.build(boxes, threads);
    splats_.resize(n);
    for (size_t k = 0; k < n; ++k) {
        const uint32_t i = bvh_.prim_order[k];
        splats_[k] = PackedSplat{centre[i], radii_[i], normals_[i], int32_t(i)};
    }
}

// Every splat query is the shared BVH traversal with a visitor per disc hit.
template <class Visit>
void SplatScene::traverse(const Ray &ray, const float &limit, Visit &&visit, TraversalStats *stats) const {
    uint64_t discs = 0;
    traverse_bvh(
        bvh_, ray, limit,
        [&](uint32_t first, uint32_t count) {
            discs += count;
            for (uint32_t k = first, end = first + count; k < end; ++k) {
                const PackedSplat &s = splats_[k];
                DiscHit h;
                if (intersect_disc(ray, s.c, s.n, s.r, &h)) visit(s, h);
            }
            return false;
        },
        stats ? &stats->nodes : nullptr);
    if (stats) stats->discs += discs;
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

void SplatScene::gather_layer(const Ray &ray, LayerQuery &q, bool brute_force, TraversalStats *stats) const {
    auto offer = [&](const PackedSplat &s, const DiscHit &h) {
        if (!q.excluded(s.id)) q.add(LayerHit{h.t, std::sqrt(h.dist2), s.r, s.id, h.front});
    };
    q.cut = ray.tmax;
    if (brute_force) {
        for (const PackedSplat &s : splats_) {
            DiscHit h;
            if (intersect_disc(ray, s.c, s.n, s.r, &h)) offer(s, h);
        }
        return;
    }
    traverse(ray, q.cut, offer, stats);
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
