// Triangle meshes beside the splats (floors, props, turntables): the same BVH builder and
// traversal, a ray/triangle test, and the shading data a renderer needs.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "bvh/bvh.h"

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
    // indices, or null (all 0). Throws InputError for an index out of range, a non-finite
    // or out-of-range value. Degenerate (zero-area) triangles are kept but never hit.
    TriangleMesh(const float *vertices, size_t nv, const int32_t *triangles, size_t nt, const float *corner_normals,
                 const int32_t *material, int threads);

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
    // Bound on the rounding error of point(h), per axis: a secondary ray starting there is
    // moved this far off the surface (pbrt-v4's error bounds for barycentric interpolation).
    Vec3 point_error(const MeshHit &h) const;
    // The UV map (Cycles' UV pass): nt x 3 x 2 corner UVs, copied; throws InputError for a
    // value that is not finite. Without it, uv() gives (0, 0).
    void set_corner_uvs(const float *uvs);
    void uv(int32_t tri, float b1, float b2, float *u, float *v) const;

  private:
    struct PackedTriangle {  // BVH order
        Vec3 v0, e1, e2;
        int32_t id;
    };
    std::vector<PackedTriangle> tris_;
    std::vector<Vec3> v0_, v1_, v2_;  // input order, for shading
    std::vector<Vec3> normals_;       // 3 per triangle, or empty
    std::vector<float> uvs_;          // 3 x 2 per triangle, or empty
    std::vector<int32_t> material_;
    AABB bounds_;
    BVH bvh_;
};

}  // namespace splat
