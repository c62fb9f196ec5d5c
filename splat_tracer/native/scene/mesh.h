// Triangle meshes beside the splats (floors, props, turntables): the same BVH builder and
// traversal, a ray/triangle test, and the shading data a renderer needs.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "bvh/bvh.h"
#include "splats/layer.h"  // kMaxPointAttributes

namespace splat {

struct MeshHit {
    float t = kInfinity;
    int32_t tri = -1;    // triangle index in the input order
    float b1 = 0, b2 = 0;  // barycentric coordinates of vertices 1 and 2
    bool front = false;  // d . (e1 x e2) < 0: the side the winding's normal points to

    bool valid() const { return tri >= 0; }
};

class TriangleMesh {
  public:
    // `vertices`: nv x 3; `triangles`: nt x 3 vertex indices; `corner_normals`: nt x 3 x 3
    // shading normals (one per triangle corner, as Blender's corner normals: smooth, flat
    // and sharp edges all expressed), or null for flat shading; `material`: nt slot
    // indices, or null (all 0); `corner_uv`: nt x 3 x 2 texture coordinates (the active UV
    // map, one per corner), or null (0 everywhere). Throws InputError for an index out of range, a non-finite
    // or out-of-range value. Degenerate (zero-area) triangles are kept but never hit.
    TriangleMesh(const float *vertices, size_t nv, const int32_t *triangles, size_t nt, const float *corner_normals,
                 const int32_t *material, int threads, const float *corner_uv = nullptr);

    size_t size() const { return tris_.size(); }
    const AABB &bounds() const { return bounds_; }
    const BVH &bvh() const { return bvh_; }

    // Nearest hit in (tmin, tmax), skipping triangle `skip` (the one a secondary ray leaves).
    MeshHit intersect(const Ray &ray, int32_t skip, TraversalStats *stats) const;
    // Any hit in (tmin, tmax) other than `skip`.
    bool occluded(const Ray &ray, int32_t skip, TraversalStats *stats) const;

    Vec3 point(const MeshHit &h) const;
    void vertices(int32_t tri, Vec3 *v0, Vec3 *v1, Vec3 *v2) const { *v0 = v0_[tri], *v1 = v1_[tri], *v2 = v2_[tri]; }
    Vec3 geometric_normal(int32_t tri) const;  // unit, along e1 x e2
    Vec3 shading_normal(const MeshHit &h) const;
    int32_t material(int32_t tri) const { return material_.empty() ? 0 : material_[tri]; }
    // The direction of increasing u on a triangle (object space, unnormalised) and the sign of
    // the direction of increasing v relative to n x that (1 or -1): the UV map's tangent
    // frame, per triangle. False without a UV map or where the UVs are degenerate.
    bool uv_tangent(int32_t tri, Vec3 *tangent, float *sign) const;
    // The UV map at barycentric (b1, b2) of a triangle, as (u, v, 0); 0 without a UV map.
    Vec3 uv(int32_t tri, float b1, float b2) const {
        if (uv_.empty()) return Vec3();
        const float *t = &uv_[6 * size_t(tri)], b0 = 1.f - b1 - b2;
        return {b0 * t[0] + b1 * t[2] + b2 * t[4], b0 * t[1] + b1 * t[3] + b2 * t[5], 0.f};
    }
    // The attributes a scene's node programs read (Attribute node), per triangle corner:
    // nt x 3 x count floats (count <= kMaxPointAttributes), each finite (a vertex's, a face's
    // or a corner's value, as the export spreads them over the corners). Throws InputError.
    void set_attributes(const float *corner_values, int count);
    int attribute_count() const { return attribute_count_; }
    // Interpolated at barycentric (b1, b2) of a triangle into out[attribute_count()].
    void attributes(int32_t tri, float b1, float b2, float *out) const {
        const size_t k = size_t(attribute_count_);
        const float *a = attributes_.data() + 3 * k * size_t(tri), b0 = 1.f - b1 - b2;
        for (size_t i = 0; i < k; ++i) out[i] = b0 * a[i] + b1 * a[k + i] + b2 * a[2 * k + i];
    }
    // Bound on the rounding error of point(h), per axis: a secondary ray starting there is
    // moved this far off the surface (pbrt-v4's error bounds for barycentric interpolation).
    Vec3 point_error(const MeshHit &h) const;

  private:
    struct PackedTriangle {  // BVH order
        Vec3 v0, e1, e2;
        int32_t id;
    };
    std::vector<PackedTriangle> tris_;
    std::vector<Vec3> v0_, v1_, v2_;  // input order, for shading
    std::vector<Vec3> normals_;       // 3 per triangle, or empty
    std::vector<int32_t> material_;
    std::vector<float> uv_;           // 6 per triangle, or empty
    std::vector<float> attributes_;   // 3 x attribute_count_ per triangle
    int attribute_count_ = 0;
    AABB bounds_;
    BVH bvh_;
};

}  // namespace splat
