#include "scene/mesh.h"

#include <cmath>
#include <string>

#include "base/errors.h"

namespace splat {
namespace {

// Moller-Trumbore. Returns t in (tmin, tmax) and the barycentrics, or false. A ray in the
// triangle's plane (|det| below a scale-relative bound) misses: it sees a zero-area sliver.
inline bool intersect_triangle(const Ray &ray, Vec3 v0, Vec3 e1, Vec3 e2, float *t_out, float *b1, float *b2,
                               bool *front) {
    const Vec3 p = cross(ray.d, e2);
    const float det = dot(e1, p);
    // |det| = |d . (e1 x e2)| = 2 area |cos|: relative to the triangle's own size.
    if (!(std::fabs(det) > 1e-12f * dot(e1, e1) * std::sqrt(dot(e2, e2)) + 1e-37f)) return false;
    const float inv = 1.f / det;
    const Vec3 s = ray.o - v0;
    const float u = dot(s, p) * inv;
    if (!(u >= 0.f && u <= 1.f)) return false;
    const Vec3 q = cross(s, e1);
    const float v = dot(ray.d, q) * inv;
    if (!(v >= 0.f && u + v <= 1.f)) return false;
    const float t = dot(e2, q) * inv;
    if (!(t > ray.tmin && t < ray.tmax)) return false;
    *t_out = t, *b1 = u, *b2 = v, *front = det > 0.f;  // det = e1 . (d x e2) = -d . (e1 x e2)
    return true;
}

bool finite_in_range(const float *v, size_t n) {
    for (size_t i = 0; i < n; ++i)
        if (!within_range(v[i])) return false;
    return true;
}

}  // namespace

TriangleMesh::TriangleMesh(const float *vertices, size_t nv, const int32_t *triangles, size_t nt,
                           const float *corner_normals, const int32_t *material, int threads,
                           const float *corner_uv) {
    if (nt >= size_t(INT32_MAX)) throw InputError("too many triangles (ids are 32-bit)");
    if (!finite_in_range(vertices, 3 * nv)) throw InputError("a vertex coordinate is not finite or beyond 1e18");
    v0_.resize(nt), v1_.resize(nt), v2_.resize(nt);
    std::vector<AABB> boxes(nt);
    for (size_t i = 0; i < nt; ++i) {
        Vec3 *corner[3] = {&v0_[i], &v1_[i], &v2_[i]};
        for (int k = 0; k < 3; ++k) {
            const int32_t vi = triangles[3 * i + k];
            if (vi < 0 || size_t(vi) >= nv)
                throw InputError("triangle " + std::to_string(i) + ": vertex index " + std::to_string(vi) +
                                 " is not in 0.." + std::to_string(nv) + "-1");
            *corner[k] = Vec3(vertices[3 * vi], vertices[3 * vi + 1], vertices[3 * vi + 2]);
            boxes[i].grow(*corner[k]);
        }
        bounds_.grow(boxes[i]);
    }
    if (corner_normals) {
        normals_.resize(3 * nt);
        for (size_t i = 0; i < 3 * nt; ++i) {
            const Vec3 n(corner_normals[3 * i], corner_normals[3 * i + 1], corner_normals[3 * i + 2]);
            // A zero or broken corner normal falls back to the face's own.
            normals_[i] = std::isfinite(dot(n, n)) && dot(n, n) > 0.f ? normalize(n) : geometric_normal(int32_t(i / 3));
        }
    }
    if (corner_uv) {
        if (!finite_in_range(corner_uv, 6 * nt)) throw InputError("a UV coordinate is not finite or beyond 1e18");
        uv_.assign(corner_uv, corner_uv + 6 * nt);
    }
    if (material) {
        material_.assign(material, material + nt);
        for (size_t i = 0; i < nt; ++i)
            if (material_[i] < 0) throw InputError("triangle " + std::to_string(i) + ": negative material index");
    }
    bvh_.build(boxes, threads);
    tris_.resize(nt);
    for (size_t k = 0; k < nt; ++k) {
        const uint32_t i = bvh_.prim_order[k];
        tris_[k] = PackedTriangle{v0_[i], v1_[i] - v0_[i], v2_[i] - v0_[i], int32_t(i)};
    }
}

MeshHit TriangleMesh::intersect(const Ray &ray, int32_t skip, TraversalStats *stats) const {
    MeshHit best;
    uint64_t tests = 0;
    traverse_bvh(
        bvh_, ray, best.t,
        [&](uint32_t first, uint32_t count) {
            tests += count;
            for (uint32_t k = first, end = first + count; k < end; ++k) {
                const PackedTriangle &tr = tris_[k];
                float t, b1, b2;
                bool front;
                if (tr.id != skip && intersect_triangle(ray, tr.v0, tr.e1, tr.e2, &t, &b1, &b2, &front) &&
                    (t < best.t || (t == best.t && tr.id < best.tri)))
                    best.t = t, best.tri = tr.id, best.b1 = b1, best.b2 = b2, best.front = front;
            }
            return false;
        },
        stats ? &stats->nodes : nullptr);
    if (stats) stats->triangles += tests;
    return best;
}

bool TriangleMesh::occluded(const Ray &ray, int32_t skip, TraversalStats *stats) const {
    bool hit = false;
    uint64_t tests = 0;
    const float limit = ray.tmax;
    traverse_bvh(
        bvh_, ray, limit,
        [&](uint32_t first, uint32_t count) {
            for (uint32_t k = first, end = first + count; k < end; ++k) {
                const PackedTriangle &tr = tris_[k];
                float t, b1, b2;
                bool front;
                ++tests;
                if (tr.id != skip && intersect_triangle(ray, tr.v0, tr.e1, tr.e2, &t, &b1, &b2, &front))
                    return hit = true;
            }
            return false;
        },
        stats ? &stats->nodes : nullptr);
    if (stats) stats->triangles += tests;
    return hit;
}

Vec3 TriangleMesh::point(const MeshHit &h) const {
    const float b0 = 1.f - h.b1 - h.b2;
    return v0_[h.tri] * b0 + v1_[h.tri] * h.b1 + v2_[h.tri] * h.b2;
}

Vec3 TriangleMesh::point_error(const MeshHit &h) const {
    // gamma(7) (|b0 v0| + |b1 v1| + |b2 v2|), pbrt-v4's bound for this interpolation.
    constexpr float kGamma7 = rounding_gamma(7);
    const float b0 = 1.f - h.b1 - h.b2;
    const Vec3 a = vabs(v0_[h.tri] * b0) + vabs(v1_[h.tri] * h.b1) + vabs(v2_[h.tri] * h.b2);
    return a * kGamma7;
}

void TriangleMesh::set_attributes(const float *corner_values, int count) {
    if (count < 0 || count > kMaxPointAttributes)
        throw InputError("mesh attributes: " + std::to_string(count) + " per corner (0.." +
                         std::to_string(kMaxPointAttributes) + ")");
    const size_t n = 3 * v0_.size() * size_t(count);  // v0_: every input triangle, degenerate ones too
    for (size_t i = 0; i < n; ++i)
        if (!std::isfinite(corner_values[i]))
            throw InputError("triangle " + std::to_string(i / (3 * size_t(count))) + ": attribute is not finite");
    attributes_.assign(corner_values, corner_values + n);
    attribute_count_ = count;
}

bool TriangleMesh::uv_tangent(int32_t tri, Vec3 *tangent, float *sign) const {
    if (uv_.empty()) return false;
    const float *t = &uv_[6 * size_t(tri)];
    const Vec3 e1 = v1_[tri] - v0_[tri], e2 = v2_[tri] - v0_[tri];
    const float du1 = t[2] - t[0], dv1 = t[3] - t[1], du2 = t[4] - t[0], dv2 = t[5] - t[1];
    const float det = du1 * dv2 - du2 * dv1;
    if (!(std::fabs(det) > 0.f)) return false;
    const float inv = 1.f / det;
    *tangent = (e1 * dv2 - e2 * dv1) * inv;                    // dP/du
    const Vec3 bitangent = (e2 * du1 - e1 * du2) * inv;        // dP/dv
    *sign = dot(cross(cross(e1, e2), *tangent), bitangent) < 0.f ? -1.f : 1.f;
    return std::isfinite(dot(*tangent, *tangent)) && dot(*tangent, *tangent) > 0.f;
}

Vec3 TriangleMesh::geometric_normal(int32_t tri) const {
    return normalize(cross(v1_[tri] - v0_[tri], v2_[tri] - v0_[tri]));
}

Vec3 TriangleMesh::shading_normal(const MeshHit &h) const {
    if (normals_.empty()) return geometric_normal(h.tri);
    const float b0 = 1.f - h.b1 - h.b2;
    const Vec3 n = normals_[3 * h.tri] * b0 + normals_[3 * h.tri + 1] * h.b1 + normals_[3 * h.tri + 2] * h.b2;
    return dot(n, n) > 0.f ? normalize(n) : geometric_normal(h.tri);
}

}  // namespace splat
