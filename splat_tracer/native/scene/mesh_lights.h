// Emissive triangles as lights: the triangles of mesh instances whose material emits, picked
// by power (a CDF over area x emitted luminance) and sampled uniformly by area, so that the
// integrator can aim shadow rays at them (next-event estimation) and weigh the emission its
// other rays happen to meet against it (multiple importance sampling).
//
// An emitter whose emission (or opacity) a node program drives is weighed by an estimate of
// its power -- the program run at a few points of each triangle when the scene is built, as
// Cycles evaluates the shader to estimate each emissive triangle's power for its light tree
// -- and the integrator runs the program at the point it samples (emission_on_triangle), so
// that the estimate decides where the samples go, never what they bring.
//
// A CDF, not Cycles' light tree: the tree also weighs each emitter by its distance and
// orientation from the shading point, which matters when many small emitters spread over a
// scene; for the panels and strips that light scans, power alone is what separates them.
#pragma once

#include <cstdint>
#include <vector>

#include "base/vec3.h"
#include "shade/shading.h"

namespace splat {

struct Instance;

// A point in a triangle's own plane (on another triangle of a flat panel) sees it edge on: a
// cosine within the rounding of unit vectors (a few 1e-8) is that, not light, and is never
// sampled (any light at a cosine of 1e-6 is 1e-6 of a facing one's).
constexpr float kEdgeOnCosine = 1e-6f;

// One point chosen on an emissive triangle, seen from a shading point.
struct MeshLightSample {
    Vec3 wi;             // unit, from the shading point towards the light point
    float distance = 0;  // to the light point
    Vec3 emission;       // radiance leaving the light point towards the shading point (0 when
                         // `programmed`: the caller runs the program there, emission_on_triangle)
    float pdf = 0;       // solid-angle density of wi (pick x area density x distance^2 / cos)
    int instance = -1;
    int32_t tri = -1;    // the triangle and the point's barycentrics of its vertices 1 and 2
    float b1 = 0, b2 = 0;
    bool programmed = false;  // a node program drives the emission (or opacity) there
    bool valid = false;
};

class RenderScene;

class MeshLights {
  public:
    // The emissive triangles of `instances` (scene frame) whose material samples the side
    // emission comes from (Material::emission_sides), in instances that diffuse or glossy
    // rays can see: an emitter hidden from both lights nothing by those rays.
    MeshLights() = default;
    // `scene`: where the programmed emitters' estimates are run (RenderScene::emitted_on_triangle),
    // on `threads` threads (0: all cores); null leaves them out.
    MeshLights(const std::vector<Instance> &instances, const std::vector<Material> &materials,
               const RenderScene *scene = nullptr, int threads = 1);

    bool empty() const { return tris_.empty(); }
    size_t size() const { return tris_.size(); }
    // Picks a triangle with u0 (probability power / total), a uniform point of it with u1,
    // u2, seen from p. Invalid when p is on a side the material does not sample, or level
    // with the triangle.
    MeshLightSample sample(Vec3 p, float u0, float u1, float u2) const;
    // The density sample() has, per unit area, anywhere on triangle `tri` of instance
    // `instance` with material `m` seen from its `front` side (the winding's); 0 where it
    // never samples.
    float area_pdf(int instance, int32_t tri, const Material &m, bool front) const;
    // Each sampled triangle and the probability that sample() picks it (for tests).
    struct Pick {
        int instance;
        int32_t tri;
        double probability;
    };
    std::vector<Pick> picks() const;

  private:
    struct Emitter {
        Vec3 v0, e1, e2;  // scene frame
        Vec3 n;           // unit geometric normal, on the winding's front side (scene frame)
        float area;
        Vec3 emission;    // the material's, times its opacity (0 when programmed)
        float density;    // emitted_power_density of its material, or the program's estimate
        uint8_t sides;    // Material::emission_sides
        bool programmed;
        int instance;
        int32_t tri;
    };
    std::vector<Emitter> tris_;
    std::vector<double> cdf_;              // cumulative power, cdf_[i + 1] after triangle i
    double total_ = 0;
    std::vector<uint8_t> sampled_;         // per instance: some of its triangles are here
    // Instances with a programmed emitter: the offset of their triangles' area densities in
    // tri_pdf_ (per triangle, as area_pdf answers); -1 for the others, which area_pdf answers
    // from their material alone.
    std::vector<int64_t> tri_pdf_first_;
    std::vector<float> tri_pdf_;
};

// The weight of a material's emission in the light distribution, per unit area: luminance
// of what a ray that meets the surface takes away on average (emission x opacity: a ray
// passes a surface of alpha a with probability 1 - a).
inline float emitted_power_density(const Material &m) { return luminance(m.emission) * m.alpha; }

}  // namespace splat
