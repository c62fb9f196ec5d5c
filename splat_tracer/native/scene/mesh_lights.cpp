#include "scene/mesh_lights.h"

#include <algorithm>
#include <cmath>

#include "scene/render_scene.h"

namespace splat {

MeshLights::MeshLights(const std::vector<Instance> &instances, const std::vector<Material> &materials)
    : sampled_(instances.size(), 0) {
    for (size_t i = 0; i < instances.size(); ++i) {
        const Instance &inst = instances[i];
        if (!inst.mesh || !(inst.visibility & (kVisDiffuse | kVisGlossy))) continue;
        // Most scenes have no emitter at all: look at the instance's materials before its triangles.
        bool any = false;
        for (int k = 0; k < inst.material_count; ++k) {
            const Material &m = materials[size_t(inst.material_offset + k)];
            any |= m.emission_sides != 0 && emitted_power_density(m) > 0.f;
        }
        if (!any) continue;
        const TriangleMesh &mesh = *inst.mesh;
        for (size_t t = 0; t < mesh.size(); ++t) {
            const int material = inst.material_of(mesh.material(int32_t(t)));
            const Material &m = materials[size_t(material)];
            const float density = emitted_power_density(m);
            if (m.emission_sides == 0 || !(density > 0.f)) continue;
            Vec3 a, b, c;
            mesh.vertices(int32_t(t), &a, &b, &c);
            a = inst.to_world.point(a), b = inst.to_world.point(b), c = inst.to_world.point(c);
            Emitter e;
            e.v0 = a, e.e1 = b - a, e.e2 = c - a;
            const Vec3 cr = cross(e.e1, e.e2);
            e.area = 0.5f * length(cr);
            if (!(e.area > 0.f) || !std::isfinite(e.area)) continue;  // never hit, never sampled
            // The front side as the ray tests it: the object-space winding carried by the
            // normal transform, which keeps its side under a mirroring (negative) scale,
            // where the cross product of the placed edges turns over.
            e.n = normalize(inst.to_object.transposed_vector(mesh.geometric_normal(int32_t(t))));
            e.emission = m.emission * m.alpha;
            e.density = density;
            e.sides = uint8_t(m.emission_sides);
            e.instance = int(i), e.tri = int32_t(t);
            tris_.push_back(e);
            sampled_[i] = 1;
        }
    }
    cdf_.resize(tris_.size() + 1, 0.0);
    for (size_t k = 0; k < tris_.size(); ++k)
        cdf_[k + 1] = cdf_[k] + double(tris_[k].area) * double(tris_[k].density);
    total_ = cdf_.back();
}

MeshLightSample MeshLights::sample(Vec3 p, float u0, float u1, float u2) const {
    MeshLightSample s;
    if (tris_.empty()) return s;
    const double x = double(u0) * total_;
    const size_t k = std::min(size_t(std::upper_bound(cdf_.begin() + 1, cdf_.end(), x) - (cdf_.begin() + 1)),
                              tris_.size() - 1);
    const Emitter &e = tris_[k];
    // A uniform point of the triangle: barycentrics (1 - r, r (1 - u2), r u2), r = sqrt(u1).
    const float r = std::sqrt(u1);
    const Vec3 q = e.v0 + e.e1 * (r * (1.f - u2)) + e.e2 * (r * u2);
    const Vec3 to = q - p;
    const float d2 = dot(to, to);
    if (!(d2 > 0.f)) return s;
    const float dist = std::sqrt(d2);
    s.wi = to * (1.f / dist);
    const float cn = dot(e.n, s.wi);  // < 0: p is on the front side
    const float cos_l = std::fabs(cn);
    const int side = cn < 0.f ? 1 : 2;
    if (!(cos_l > kEdgeOnCosine)) return s;
    s.distance = dist;
    s.emission = e.emission;
    s.instance = e.instance;
    // pick (density A / total) x area density (1 / A) x area -> solid angle (d^2 / cos).
    s.pdf = float(double(e.density) / total_) * d2 / cos_l;
    s.valid = (side & e.sides) != 0 && s.pdf > 0.f;
    return s;
}

float MeshLights::area_pdf(int instance, const Material &m, bool front) const {
    if (instance < 0 || size_t(instance) >= sampled_.size() || !sampled_[size_t(instance)]) return 0.f;
    if (!(m.emission_sides & (front ? 1 : 2))) return 0.f;
    return float(double(emitted_power_density(m)) / total_);
}

std::vector<MeshLights::Pick> MeshLights::picks() const {
    std::vector<Pick> out;
    for (size_t k = 0; k < tris_.size(); ++k) out.push_back(Pick{tris_[k].instance, tris_[k].tri, (cdf_[k + 1] - cdf_[k]) / total_});
    return out;
}

}  // namespace splat
