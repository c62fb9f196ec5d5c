#include "scene/mesh_lights.h"

#include <algorithm>
#include <cmath>

#include "base/parallel.h"
#include "scene/render_scene.h"

namespace splat {

// A programmed emitter's estimate: the program run at up to kEstimatePoints points of each
// triangle (the centres of a square grid of strata, uniform by area), at most kEstimateBudget
// runs over the scene: a mesh of more programmed triangles than that gets one run (a
// centroid) per run of consecutive triangles, which share it -- the estimate only shapes
// where samples go. A run costs 0.3 us (a Checker) to 30 us (a Noise of detail 15, its
// colour) on one core: at most about half a second at the worst, shared by the threads.
constexpr int kEstimatePoints = 16;
constexpr size_t kEstimateBudget = size_t(1) << 14;
// A triangle estimated darker than this fraction of the programmed emitters' mean (area
// weighted) is picked as if it were that bright: a triangle whose bright parts fell between
// the estimate's points stays reachable by shadow rays (so that light sampling alone stays
// unbiased), at the cost of at most this share of the samples for the truly dark ones.
constexpr double kEstimateFloor = 0.01;

MeshLights::MeshLights(const std::vector<Instance> &instances, const std::vector<Material> &materials,
                       const RenderScene *scene, int threads)
    : sampled_(instances.size(), 0) {
    size_t n_programmed = 0;
    for (size_t i = 0; i < instances.size(); ++i) {
        const Instance &inst = instances[i];
        if (!inst.mesh || !(inst.visibility & (kVisDiffuse | kVisGlossy))) continue;
        auto programmed = [&](const Material &m) { return scene && scene->programmed_emission(m); };
        // Most scenes have no emitter at all: look at the instance's materials before its triangles.
        bool any = false;
        for (int k = 0; k < inst.material_count; ++k) {
            const Material &m = materials[size_t(inst.material_offset + k)];
            any |= m.emission_sides != 0 && (emitted_power_density(m) > 0.f || programmed(m));
        }
        if (!any) continue;
        const TriangleMesh &mesh = *inst.mesh;
        for (size_t t = 0; t < mesh.size(); ++t) {
            const int material = inst.material_of(mesh.material(int32_t(t)));
            const Material &m = materials[size_t(material)];
            const bool by_program = programmed(m);
            const float density = emitted_power_density(m);
            if (m.emission_sides == 0 || !(density > 0.f || by_program)) continue;
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
            e.emission = by_program ? Vec3() : m.emission * m.alpha;
            e.density = by_program ? 0.f : density;  // programmed: estimated below
            e.sides = uint8_t(m.emission_sides);
            e.programmed = by_program;
            e.instance = int(i), e.tri = int32_t(t);
            tris_.push_back(e);
            n_programmed += by_program;
        }
    }
    // Instances with a programmed emitter, even one left to rays below: area_pdf answers their
    // triangles from the table (a program's emission at a hit is not what picked it).
    std::vector<uint8_t> has_programmed(instances.size(), 0);
    if (n_programmed > 0) {
        std::vector<size_t> programmed;  // indices in tris_
        for (size_t k = 0; k < tris_.size(); ++k)
            if (tris_[k].programmed) programmed.push_back(k), has_programmed[size_t(tris_[k].instance)] = 1;
        int grid = 1;  // grid x grid points per triangle
        while ((grid + 1) * (grid + 1) <= kEstimatePoints &&
               size_t((grid + 1) * (grid + 1)) * programmed.size() <= kEstimateBudget)
            ++grid;
        const size_t stride = (programmed.size() + kEstimateBudget - 1) / kEstimateBudget;  // 1 within the budget
        const size_t groups = (programmed.size() + stride - 1) / stride;
        std::vector<float> estimate(groups, 0.f);
        auto estimate_group = [&](size_t g) {
            const Emitter &e = tris_[programmed[g * stride]];
            // Seen from a side it samples, straight on (the programs' Incoming and Backfacing).
            const Vec3 wo = e.sides & 1 ? e.n : e.n * -1.f;
            double lum = 0;
            for (int gy = 0; gy < grid; ++gy)
                for (int gx = 0; gx < grid; ++gx) {
                    // sample()'s warp of the stratum's centre: a uniform point by area.
                    const float r = std::sqrt((float(gx) + 0.5f) / float(grid)), u2 = (float(gy) + 0.5f) / float(grid);
                    lum += double(luminance(scene->emitted_on_triangle(e.instance, e.tri, r * (1.f - u2), r * u2, wo)));
                }
            const float d = float(lum / double(grid * grid));
            estimate[g] = std::isfinite(d) && d > 0.f ? d : 0.f;
        };
        constexpr size_t kChunk = 64;  // groups per task: a task is worth a thread's pull
        parallel_for(
            (groups + kChunk - 1) / kChunk, threads,
            [&](size_t c) {
                for (size_t g = c * kChunk; g < std::min(groups, (c + 1) * kChunk); ++g) estimate_group(g);
            },
            [](size_t) { return true; });
        double sum = 0, area = 0;
        for (size_t i = 0; i < programmed.size(); ++i) {
            Emitter &e = tris_[programmed[i]];
            e.density = estimate[i / stride];
            sum += double(e.density) * double(e.area), area += double(e.area);
        }
        // The floor is the scene's mean: only when every programmed triangle is estimated
        // dark (floor 0) are they left to the rays that meet them (MIS gives those rays their
        // whole emission where area_pdf is 0); otherwise each gets at least the floor.
        const float floor = float(kEstimateFloor * (area > 0 ? sum / area : 0.0));
        tris_.erase(std::remove_if(tris_.begin(), tris_.end(), [&](Emitter &e) {
                        if (e.programmed) e.density = std::fmax(e.density, floor);
                        return e.programmed && !(e.density > 0.f);
                    }),
                    tris_.end());
    }
    for (const Emitter &e : tris_) sampled_[size_t(e.instance)] = 1;
    cdf_.resize(tris_.size() + 1, 0.0);
    for (size_t k = 0; k < tris_.size(); ++k)
        cdf_[k + 1] = cdf_[k] + double(tris_[k].area) * double(tris_[k].density);
    total_ = cdf_.back();
    if (n_programmed > 0 && total_ > 0) {
        // Per-triangle densities for area_pdf, in the instances that hold a programmed emitter.
        tri_pdf_first_.assign(instances.size(), -1);
        for (size_t i = 0; i < instances.size(); ++i)
            if (has_programmed[i]) {
                tri_pdf_first_[i] = int64_t(tri_pdf_.size());
                tri_pdf_.resize(tri_pdf_.size() + instances[i].mesh->size(), 0.f);
            }
        for (const Emitter &e : tris_) {
            const int64_t first = tri_pdf_first_[size_t(e.instance)];
            if (first >= 0) tri_pdf_[size_t(first + e.tri)] = float(double(e.density) / total_);
        }
    }
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
    s.tri = e.tri, s.b1 = r * (1.f - u2), s.b2 = r * u2, s.programmed = e.programmed;
    // pick (density A / total) x area density (1 / A) x area -> solid angle (d^2 / cos).
    s.pdf = float(double(e.density) / total_) * d2 / cos_l;
    s.valid = (side & e.sides) != 0 && s.pdf > 0.f;
    return s;
}

float MeshLights::area_pdf(int instance, int32_t tri, const Material &m, bool front) const {
    if (instance < 0 || size_t(instance) >= sampled_.size() || !sampled_[size_t(instance)]) return 0.f;
    if (!(m.emission_sides & (front ? 1 : 2))) return 0.f;
    if (!tri_pdf_first_.empty() && tri_pdf_first_[size_t(instance)] >= 0) {
        // (its mesh's size was counted in: tri is one of its triangles, a hit's)
        return tri < 0 ? 0.f : tri_pdf_[size_t(tri_pdf_first_[size_t(instance)] + tri)];
    }
    return float(double(emitted_power_density(m)) / total_);
}

std::vector<MeshLights::Pick> MeshLights::picks() const {
    std::vector<Pick> out;
    for (size_t k = 0; k < tris_.size(); ++k) out.push_back(Pick{tris_[k].instance, tris_[k].tri, (cdf_[k + 1] - cdf_[k]) / total_});
    return out;
}

}  // namespace splat
