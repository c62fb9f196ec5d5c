#include "splats/visibility.h"

#include <algorithm>
#include <cmath>
#include <new>
#include <type_traits>

#include "bvh/packet.h"

namespace splat {
namespace {

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
    std::copy_n(scene.attributes(h.id), scene.attribute_count(), s.attributes);
    return s;
}

// The surface point and shading of an accepted layer, into s (the hits are written where
// they go: a SurfaceHit is 170 bytes, and copies of it were 8 % of the full method's time).
void resolve_layer(const SplatScene &scene, const LayerQuery &q, const Method &m, SurfaceHit &s) {
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
        // convex the farther one; the survivor meets the next member. Convex and concave
        // as the ray sees them: an open cloud's back layer (SplatScene::open_back) is judged
        // with its normals turned towards the ray -- a ridge seen from behind is a valley --
        // so that its back shows the surface point its front would (a closed cloud's back
        // layers, exits, keep the rule as it was).
        const float towards = scene.open_back(q.hits[q.first].id, q.facing) ? -1.f : 1.f;
        for (int k = 1; k < n; ++k) {
            const PackedSplat &a = scene.splat(q.hits[chosen].slot), &b = scene.splat(q.hits[idx[k]].slot);
            if (near_phase_convex(a.c, a.n * towards, b.c, b.n * towards)) chosen = idx[k];
        }
    }

    const LayerHit &h = q.hits[chosen];
    s.t = h.t, s.id = h.id, s.front = h.front, s.overflow = q.overflow;
    s.normal = scene.splat(h.slot).n, s.colour = scene.colour(h.id), s.alpha = scene.alpha(h.id);
    const int n_attributes = scene.attribute_count();
    std::copy_n(scene.attributes(h.id), n_attributes, s.attributes);
    s.n_members = n;
    for (int k = 0; k < n; ++k) s.members[k] = q.hits[idx[k]].id;
    if (m.normal_interpolation && n > 1) {
        Vec3 nsum, csum;
        float wsum = 0.f, asum = 0.f, attr_sum[kMaxPointAttributes] = {};
        // At a crease the layer holds discs of both faces: blending them all rounds the edge
        // over about a radius. With a crease angle, only the surface splat's side blends.
        const Vec3 own = scene.splat(h.slot).n;
        for (int k = 0; k < n; ++k) {
            const LayerHit &mh = q.hits[idx[k]];
            const Vec3 mn = scene.splat(mh.slot).n;
            if (dot(mn, own) < m.crease_cos) continue;
            const float w = kernel_weight(m.kernel, mh.dist, mh.radius);
            nsum = nsum + mn * w;
            csum = csum + scene.colour(mh.id) * w;
            asum += scene.alpha(mh.id) * w;
            const float *attr = scene.attributes(mh.id);
            for (int a = 0; a < n_attributes; ++a) attr_sum[a] += attr[a] * w;
            wsum += w;
        }
        // All members hit exactly on their rims (weight 0): keep the chosen splat's own.
        if (wsum > 0.f && length(nsum) > 0.f) {
            s.normal = normalize(nsum);
            s.colour = csum * (1.f / wsum);
            s.alpha = asum / wsum;
            for (int a = 0; a < n_attributes; ++a) s.attributes[a] = attr_sum[a] / wsum;
        }
    }
}

// Whether the layer's first hit lies inside the sampled surface rather than beyond its edge
// (docs/ALGORITHM.md, "Far phase: which layers it tests"). A fringe disc pokes out past an
// edge or a silhouette: the hit point is then covered only by discs whose centres all lie
// on one side of it. Inside the surface the centres surround it. Such a layer is real
// whatever follows it on the ray -- which keeps the far phase away from shells that cross
// (a belt through a body) and parts thinner than the layer window, where "what follows"
// is another shell's surface, and saves most rays the search behind the layer.
bool inside_sampled_surface(const SplatScene &scene, const Ray &ray, const LayerQuery &q) {
    // Lopsidedness of the member centres around the hit, |sum of offsets| / sum of their
    // lengths, in the tangent plane: 0 when they surround it, about 0.64 for centres spread
    // evenly over a half disc (a point on a straight edge), 1 on one side. Below this, the
    // point is surrounded. Measured (ALGORITHM.md): fringe hits beyond a cube's edge have a
    // median of 0.76, hits on its faces 0.17 (0.72 at the 99th percentile, near edges:
    // those go on to the walk below, which accepts them); 0.3 to 0.6 tried.
    constexpr float kSurrounded = 0.6f;
    const LayerHit &h0 = q.hits[q.first];
    const Vec3 p = ray.o + ray.d * h0.t;
    const Vec3 n0 = scene.splat(h0.slot).n;
    Vec3 sum;
    float total = 0.f;
    for (int i = q.first; i < q.count; ++i) {
        if (!q.member(i)) continue;
        Vec3 v = scene.splat(q.hits[i].slot).c - p;
        v = v - n0 * dot(v, n0);
        sum = sum + v;
        total += length(v);
    }
    return total > 0.f && length(sum) < kSurrounded * total;
}

// How many surfaces a window of same-facing hits crosses: 2 when its members' normals
// split by more than 60 degrees from the first's (the exits of two crossing shells meet in
// one window near their crossing), else 1. 60: a smooth surface's members differ by a few
// degrees; the shells of the benchmark cross at about 90.
int surfaces_in_window(const SplatScene &scene, const LayerQuery &w) {
    constexpr float kSplitCos = 0.5f;  // cos 60 degrees
    const Vec3 n0 = scene.splat(w.hits[w.first].slot).n;
    for (int i = w.first + 1; i < w.count; ++i)
        if (w.member(i) && dot(scene.splat(w.hits[i].slot).n, n0) < kSplitCos) return 2;
    return 1;
}

// The far phase (docs/ALGORITHM.md, "Far phase: counting entries and exits"): whether the
// layer `q` of a closed object is real. A ray that enters closed surfaces leaves them all;
// one inside an object leaves by the exit layer and does not meet a further exit. So, walking
// on layer by layer (each a window of same-facing hits, as the query makes them), entries
// count +1 and exits -1 (a window whose members' normals split counts as two surfaces, see
// surfaces_in_window): the layer is real when the count comes back to 0, a fringe when the
// hits end first (for a ray inside: the layer is a fringe when the next layer is another
// exit). The paper's rule is the first step of this walk; counting on keeps a layer that is
// followed by a second shell's entry (a finger in a palm) instead of rejecting it as the
// paper's "front, front" does. One layer query per layer walked, only for layers that may
// be fringes.
bool far_phase_accepts(const SplatScene &scene, Ray ray, const LayerQuery &q, const Method &m, bool inside,
                       const int32_t *exclude, int n_exclude, bool brute_force, TraversalStats *stats) {
    if (inside_sampled_surface(scene, ray, q)) return true;
    // A hit of the other facing inside the window: the ray left again at once (a part
    // thinner than the window) or, inside, met an entry.
    if (q.next >= 0) return true;
    // Layers walked before giving up (and rejecting, as the paper's rule would): each is one
    // more shell surface on the ray; 16 is far more than real models nest.
    constexpr int kMaxWalk = 16;
    int depth = 1;  // shells entered and not yet left (rays from outside)
    ray.tmin = q.layer_end;
    for (int k = 0; k < kMaxWalk && ray.tmin < ray.tmax; ++k) {
        LayerQuery w;
        w.any_facing = true;  // the nearest hit starts the window, whatever its facing
        w.epsilon = m.epsilon;
        w.exclude = exclude, w.n_exclude = n_exclude;
        scene.gather_layer(ray, w, brute_force, stats);
        if (stats) ++stats->layer_queries;
        // Nothing more: an exit with nothing behind is real, an entry never left a fringe.
        if (w.first < 0) return inside;
        const bool same = w.facing == q.facing;
        if (inside) return !same;
        const int surfaces = surfaces_in_window(scene, w);
        depth += same ? surfaces : -surfaces;
        if (depth <= 0) return true;
        // Hits of the other facing inside the window (`next` is the first of them; the query
        // looks for it within the window only): both faces of a part thinner than the
        // window, or two shells crossing. The window is an entry and an exit; skipping to its
        // end without counting both would lose that exit.
        if (w.next >= 0) {
            depth += same ? -1 : 1;
            if (depth == 0) return true;
        }
        ray.tmin = w.layer_end;
    }
    return false;
}

}  // namespace

bool near_phase_convex(Vec3 cj, Vec3 nj, Vec3 ck, Vec3 nk) {
    // omega = acos(x) + acos(y) with x, y the two angles' cosines; acos decreases and
    // acos(-y) = pi - acos(y), so omega > pi exactly when x + y < 0: no acos (two per member
    // pair were a tenth of the full method's time). Both cosines share the length
    // |c_k - c_j| (positive, or both angles count as right: omega = pi, not convex), which
    // cancels, and the scene's normals are unit (SplatScene normalises them).
    return dot(ck - cj, nj - nk) < 0.f;
}

namespace {

static_assert(std::is_trivially_destructible<LayerQuery>::value && std::is_trivially_destructible<SurfaceHit>::value,
              "queries and surface hits are rebuilt in place");

// Whether find_surface() answers a ray with its plain nearest hit (no layer to gather).
bool nearest_hit_suffices(const Method &m, bool inside, int n_exclude) {
    return m.is_general() && !inside && n_exclude == 0;
}

// Makes q a fresh query of this ray: its inputs set, no hits (built in place: a copy of
// the hit buffer, 700 bytes, cost 4 % of a packet's work).
void begin_query(LayerQuery &q, const Method &m, bool inside, const int32_t *exclude, int n_exclude) {
    new (&q) LayerQuery;
    q.layer_front = !inside;
    q.any_facing = !m.wrong_hit_elimination;
    q.epsilon = m.epsilon;
    q.exclude = exclude, q.n_exclude = n_exclude;
}

// find_surface() after its first layer query, `q` (gathered for this ray, `inside` and
// these exclusions by the caller, alone or in a packet).
void resolve_surface(const SplatScene &scene, Ray ray, const Method &m, bool inside, const int32_t *exclude,
                     int n_exclude, bool brute_force, TraversalStats *stats, LayerQuery &q, SurfaceHit &out) {
    new (&out) SurfaceHit;  // no hit (its member list left unwritten)
    if (stats) ++stats->layer_queries;
    if (q.count == 0) return;  // nothing on the ray (most camera rays of a scan): a miss
    bool fresh = true;  // q is this attempt's query
    for (int attempt = 0; attempt < m.max_layers; ++attempt, fresh = false) {
        if (!fresh) {
            begin_query(q, m, inside, exclude, n_exclude);
            scene.gather_layer(ray, q, brute_force, stats);
            if (stats) ++stats->layer_queries;
        }
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
            return;
        }
        if (m.far_phase && scene.closed(q.hits[q.first].id) &&
            !far_phase_accepts(scene, ray, q, m, inside, exclude, n_exclude, brute_force, stats)) {
            if (stats) ++stats->far_rejections;
            ray.tmin = q.layer_end;  // a fringe or a grazed edge: look further along the ray
            if (!(ray.tmin < ray.tmax)) return;
            continue;
        }
        resolve_layer(scene, q, m, out);
        if (stats && m.normal_interpolation && out.n_members > 1) ++stats->interpolations;
        return;
    }
}

}  // namespace

SurfaceHit find_surface(const SplatScene &scene, Ray ray, const Method &m, bool inside, const int32_t *exclude,
                        int n_exclude, bool brute_force, TraversalStats *stats) {
    if (nearest_hit_suffices(m, inside, n_exclude))
        return single_splat(scene, brute_force ? scene.intersect_brute_force(ray) : scene.intersect(ray, stats));
    LayerQuery q;
    begin_query(q, m, inside, exclude, n_exclude);
    scene.gather_layer(ray, q, brute_force, stats);
    SurfaceHit s;
    resolve_surface(scene, ray, m, inside, exclude, n_exclude, brute_force, stats, q, s);
    return s;
}

void find_surfaces(const SplatScene &scene, const Ray *rays, int n, const Method &m, const bool *inside,
                   const int32_t *const *exclude, int n_exclude, SurfaceHit *out, TraversalStats *stats) {
    // Which rays find_surface() would answer with a plain nearest hit: all or none of them,
    // else (a general-method batch mixing inside rays in) ray by ray.
    int plain = 0;
    for (int i = 0; i < n; ++i) plain += nearest_hit_suffices(m, inside[i], n_exclude);
    if (plain == n) {
        Hit hits[kPacketRays];
        scene.intersect_packet(rays, n, hits, stats);
        for (int i = 0; i < n; ++i) new (&out[i]) SurfaceHit(single_splat(scene, hits[i]));
        return;
    }
    if (plain > 0) {
        for (int i = 0; i < n; ++i)
            new (&out[i]) SurfaceHit(
                find_surface(scene, rays[i], m, inside[i], exclude ? exclude[i] : nullptr, n_exclude, false, stats));
        return;
    }
    // Storage only: begin_query() builds each query in place (a default-built array was
    // built twice, a tenth of a miss's cost).
    alignas(LayerQuery) unsigned char storage[kPacketRays * sizeof(LayerQuery)];
    LayerQuery *qs = reinterpret_cast<LayerQuery *>(storage);
    for (int i = 0; i < n; ++i) begin_query(qs[i], m, inside[i], exclude ? exclude[i] : nullptr, n_exclude);
    scene.gather_layer_packet(rays, n, qs, stats);
    for (int i = 0; i < n; ++i)
        resolve_surface(scene, rays[i], m, inside[i], exclude ? exclude[i] : nullptr, n_exclude, false, stats, qs[i],
                        out[i]);
}

}  // namespace splat
