#include "visibility.h"

#include <algorithm>
#include <cmath>

namespace splat {
namespace {

float angle_between(Vec3 a, Vec3 b) {
    const float la = length(a), lb = length(b);
    if (!(la > 0.f && lb > 0.f)) return 0.5f * float(M_PI);
    return std::acos(std::clamp(dot(a, b) / (la * lb), -1.f, 1.f));
}

float kernel_weight(Kernel k, float dist, float radius) {
    const float x = std::clamp(dist / radius, 0.f, 1.f);
    if (k == Kernel::Smooth) {
        const float s = 1.f - x * x;
        return s * s;
    }
    return 1.f - x;
}

SurfaceHit single_splat(const SplatScene &scene, const Hit &h) {
    SurfaceHit s;
    if (!h.valid()) return s;
    s.t = h.t, s.id = h.id, s.front = h.front;
    s.normal = scene.normal(h.id), s.colour = scene.colour(h.id), s.alpha = scene.alpha(h.id);
    s.n_members = 1, s.members[0] = h.id;
    return s;
}

// The surface point and shading of an accepted layer.
SurfaceHit resolve_layer(const SplatScene &scene, const LayerQuery &q, const Method &m) {
    int idx[kMaxLayerHits];
    int n = 0;
    for (int i = q.first; i < q.count; ++i)
        if (q.member(i)) idx[n++] = i;

    int chosen = q.first;  // always a member: idx[0] == q.first
    if (m.position == PositionRule::NearestCentre) {
        for (int k = 1; k < n; ++k)
            if (q.hits[idx[k]].dist < q.hits[chosen].dist) chosen = idx[k];
    } else if (m.position == PositionRule::NearPhase) {
        // Walk the members in ray order, two at a time: concave keeps the nearer hit,
        // convex the farther one; the survivor meets the next member.
        for (int k = 1; k < n; ++k) {
            const int32_t a = q.hits[chosen].id, b = q.hits[idx[k]].id;
            const float omega = near_phase_omega(scene.centre(a), scene.normal(a), scene.centre(b), scene.normal(b));
            if (omega > float(M_PI)) chosen = idx[k];
        }
    }

    SurfaceHit s;
    const LayerHit &h = q.hits[chosen];
    s.t = h.t, s.id = h.id, s.front = h.front, s.overflow = q.overflow;
    s.normal = scene.normal(h.id), s.colour = scene.colour(h.id), s.alpha = scene.alpha(h.id);
    s.n_members = n;
    for (int k = 0; k < n; ++k) s.members[k] = q.hits[idx[k]].id;
    if (m.interpolate && n > 1) {
        Vec3 nsum, csum;
        float wsum = 0.f, asum = 0.f;
        for (int k = 0; k < n; ++k) {
            const LayerHit &mh = q.hits[idx[k]];
            const float w = kernel_weight(m.kernel, mh.dist, mh.radius);
            nsum = nsum + scene.normal(mh.id) * w;
            csum = csum + scene.colour(mh.id) * w;
            asum += scene.alpha(mh.id) * w;
            wsum += w;
        }
        // All members hit exactly on their rims (weight 0): keep the chosen splat's own.
        if (wsum > 0.f && length(nsum) > 0.f) {
            s.normal = normalize(nsum);
            s.colour = csum * (1.f / wsum);
            s.alpha = asum / wsum;
        }
    }
    return s;
}

}  // namespace

float near_phase_omega(Vec3 cj, Vec3 nj, Vec3 ck, Vec3 nk) {
    return angle_between(ck - cj, nj) + angle_between(cj - ck, nk);
}

SurfaceHit find_surface(const SplatScene &scene, Ray ray, const Method &m, bool inside, const int32_t *exclude,
                        int n_exclude, bool brute_force, TraversalStats *stats) {
    if (m.is_general() && !inside && n_exclude == 0)
        return single_splat(scene, brute_force ? scene.intersect_brute_force(ray) : scene.intersect(ray, stats));
    for (int attempt = 0; attempt < m.max_layers; ++attempt) {
        LayerQuery q;
        q.layer_front = !inside;
        q.any_facing = !m.eliminate_wrong_hits;
        q.epsilon = m.epsilon;
        q.exclude = exclude, q.n_exclude = n_exclude;
        q.far_phase = m.far_phase;
        q.closed = scene.closed_flags();
        scene.gather_layer(ray, q, brute_force, stats);
        if (stats) ++stats->layer_queries;
        if (q.first < 0) {
            // Only discs of the other facing on the whole ray. On a closed object those are
            // wrong hits (fringe discs poking out at an edge) and the ray misses. An open
            // object (a one-sided scan: a roof, a wall, terrain) seen from behind is a real
            // surface: the ray takes its back-facing layer -- so an open scan is seen from
            // both sides and shadows what is beneath it, as any renderer's two-sided surface.
            // Not for a ray leaving this very cloud (it excludes the splats it starts from):
            // the neighbours it meets from behind are the paper's wrong reflections and
            // shadows (grazing shadow rays speckled an open Suzanne with acne).
            if (!inside && n_exclude == 0 && q.count > 0 && !scene.closed(q.hits[0].id)) {
                inside = true;  // its layer begins with a back-facing hit
                --attempt;      // the same search, not a rejection
                continue;
            }
            return SurfaceHit();
        }
        const bool closed = scene.closed(q.hits[q.first].id);
        if (m.far_phase && closed) {
            // A ray that truly enters a closed surface leaves it: the next hit after the
            // layer must have the other facing. Otherwise the layer is a fringe disc or a
            // grazed edge: look further along the ray.
            // A ray inside an object (roles swapped) meets the exit layer, after which there
            // may be nothing at all; the layer is a fringe only when another layer of the
            // same facing (a further exit) follows it.
            const bool next_same = q.next >= 0 && q.hits[q.next].front == q.facing;
            const bool accepted = inside ? !next_same : (q.next >= 0 && !next_same);
            if (!accepted) {
                if (stats) ++stats->far_rejections;
                ray.tmin = q.layer_end;
                if (!(ray.tmin < ray.tmax)) return SurfaceHit();
                continue;
            }
        }
        SurfaceHit s = resolve_layer(scene, q, m);
        if (stats && m.interpolate && s.n_members > 1) ++stats->interpolations;
        return s;
    }
    return SurfaceHit();
}

}  // namespace splat
