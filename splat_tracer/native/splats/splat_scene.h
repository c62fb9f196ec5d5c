// The splat scene: discs (centre, unit normal, radius, colour) in one local frame, and
// the BVH over their tight bounds. Immutable once built, so any number of threads may
// trace it at once.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "base/buffer.h"
#include "base/errors.h"
#include "bvh/bvh.h"
#include "splats/disc.h"
#include "splats/layer.h"

namespace splat {

// One splat as the traversal reads it: 32 bytes, stored in BVH leaf order.
struct PackedSplat {
    Vec3 c;
    float r;
    Vec3 n;
    int32_t id;  // index in the input arrays
};
static_assert(sizeof(PackedSplat) == 32 && offsetof(PackedSplat, r) == 12 && offsetof(PackedSplat, n) == 16,
              "the disc tests read a splat as 8 floats: c.x, c.y, c.z, r, n.x, n.y, n.z, id");

class SplatScene {
  public:
    // `centres`, `normals` (any non-zero length; normalised here) and `colours` are n x 3
    // row-major, `radii` has n entries; `colours` may be null (white); `closed` (n flags:
    // the splat belongs to a closed, hole-free object) may be null (all open). Throws
    // InputError naming the first offending splat when a value is not finite, a normal is
    // zero or a radius is not positive.
    // `alphas` (n opacities in 0..1, the points' own alpha) may be null (all opaque).
    SplatScene(const float *centres, const float *normals, const float *radii,
               const float *colours, const uint8_t *closed, size_t n, int threads, const float *alphas = nullptr);

    size_t size() const { return splats_.size(); }
    const AABB &bounds() const { return bounds_; }
    const BVH &bvh() const { return bvh_; }

    // Attributes by input id. Centres, normals and radii are stored once, in leaf order
    // (the packed splats); slot_ maps an input id to its place there.
    const PackedSplat &splat(uint32_t slot) const { return splats_[slot]; }  // by place (LayerHit::slot)
    Vec3 centre(int32_t id) const { return splats_[slot_[id]].c; }
    Vec3 normal(int32_t id) const { return splats_[slot_[id]].n; }
    float radius(int32_t id) const { return splats_[slot_[id]].r; }
    bool closed(int32_t id) const { return closed_[id] != 0; }
    // A hit on splat `id` from the side its normal does not face, on an open cloud: a one-sided
    // scan seen from behind (or oriented the wrong way, as depth frames come). Shading treats it
    // as Cycles treats a back face (the normal turned towards the ray), and rays leaving it on
    // that side see the sheet with its facing swapped (docs/ALGORITHM.md, "Open clouds are
    // two-sided"). On a closed cloud a back hit is the method's business (a wrong hit, an exit).
    bool open_back(int32_t id, bool front) const { return !front && !closed(id); }
    bool any_closed() const { return any_closed_; }    // the far phase has work here
    bool has_colours() const { return has_colours_; }  // per-point colours were given
    Vec3 colour(int32_t id) const { return has_colours_ ? colours_[id] : Vec3(1.f, 1.f, 1.f); }
    float alpha(int32_t id) const { return alphas_.empty() ? 1.f : alphas_[id]; }
    bool has_alphas() const { return !alphas_.empty(); }
    // The points' other attributes a scene's node programs read (Attribute node): `count`
    // floats per splat (n x count row-major, input order, count <= kMaxPointAttributes), each
    // finite; blended at a hit as the colour is. Throws InputError naming the first bad splat.
    void set_attributes(const float *values, int count);
    int attribute_count() const { return attribute_count_; }
    const float *attributes(int32_t id) const { return attributes_.data() + size_t(id) * size_t(attribute_count_); }

    // Bytes kept after the build: the splats, their attributes and the BVH.
    size_t memory_bytes() const;

    // Nearest hit in (ray.tmin, ray.tmax), either facing.
    Hit intersect(const Ray &ray, TraversalStats *stats = nullptr) const;
    // The same answer by testing every splat: the reference the tests compare against.
    Hit intersect_brute_force(const Ray &ray) const;

    // The ε-window query (layer.h): fills q with the first layer and the hit after it.
    // brute_force offers every splat to the query instead: the tests' reference.
    void gather_layer(const Ray &ray, LayerQuery &q, bool brute_force = false, TraversalStats *stats = nullptr) const;

    // intersect() and gather_layer() for n <= kPacketRays rays at once (packet.h): the same
    // answers, found in one traversal when the rays are coherent (a tile of camera rays),
    // else ray by ray. The queries' inputs (facing, epsilon, exclusions) are set by the caller.
    void intersect_packet(const Ray *rays, int n, Hit *out, TraversalStats *stats = nullptr) const;
    void gather_layer_packet(const Ray *rays, int n, LayerQuery *qs, TraversalStats *stats = nullptr) const;

  private:
    template <class Visit>
    void traverse(const Ray &ray, const float &limit, Visit &&visit, TraversalStats *stats = nullptr) const;
    template <class Visit>
    void traverse_packet(const Ray *rays, const PacketRays &soa, int n, Visit &&visit, TraversalStats *stats) const;
    // A layer query's start on this scene, and a disc hit offered to it (gather_layer's and
    // the packets' one rule).
    void begin_layer(const Ray &ray, LayerQuery &q) const;
    void offer(LayerQuery &q, const PackedSplat &s, const DiscHit &h) const;
    template <class Visit>
    uint32_t test_leaf(const Ray &ray, const DiscRay &disc_ray, uint32_t first, uint32_t count, Visit &&visit) const;

    Buffer<PackedSplat> splats_;  // BVH order
    Buffer<uint32_t> slot_;       // input id -> index in splats_
    std::vector<Vec3> colours_;        // input order; empty without per-point colours
    std::vector<uint8_t> closed_;
    std::vector<float> alphas_;
    std::vector<float> attributes_;  // input order, attribute_count_ per splat
    int attribute_count_ = 0;
    bool any_closed_ = false, has_colours_ = false;
    float max_radius_ = 0.f;  // bounds any layer's window (LayerQuery::max_radius)
    AABB bounds_;
    BVH bvh_;
};

}  // namespace splat
