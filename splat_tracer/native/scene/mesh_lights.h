// Emissive triangles as lights: the triangles of mesh instances whose material emits, picked
// by power (a CDF over area x emitted luminance) and sampled uniformly by area, so that the
// integrator can aim shadow rays at them (next-event estimation) and weigh the emission its
// other rays happen to meet against it (multiple importance sampling).
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
    Vec3 emission;       // radiance leaving the light point towards the shading point
    float pdf = 0;       // solid-angle density of wi (pick x area density x distance^2 / cos)
    int instance = -1;
    bool valid = false;
};

class MeshLights {
  public:
    // The emissive triangles of `instances` (scene frame) whose material samples the side
    // emission comes from (Material::emission_sides), in instances that diffuse or glossy
    // rays can see: an emitter hidden from both lights nothing by those rays.
    MeshLights() = default;
    MeshLights(const std::vector<Instance> &instances, const std::vector<Material> &materials);

    bool empty() const { return tris_.empty(); }
    size_t size() const { return tris_.size(); }
    // Picks a triangle with u0 (probability power / total), a uniform point of it with u1,
    // u2, seen from p. Invalid when p is on a side the material does not sample, or level
    // with the triangle.
    MeshLightSample sample(Vec3 p, float u0, float u1, float u2) const;
    // The density sample() has, per unit area, anywhere on a triangle of instance `instance`
    // with material `m` seen from its `front` side (the winding's); 0 where it never samples.
    float area_pdf(int instance, const Material &m, bool front) const;
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
        Vec3 emission;    // the material's, times its opacity
        float density;    // emitted_power_density of its material
        uint8_t sides;    // Material::emission_sides
        int instance;
        int32_t tri;
    };
    std::vector<Emitter> tris_;
    std::vector<double> cdf_;              // cumulative power, cdf_[i + 1] after triangle i
    double total_ = 0;
    std::vector<uint8_t> sampled_;         // per instance: some of its triangles are here
};

// The weight of a material's emission in the light distribution, per unit area: luminance
// of what a ray that meets the surface takes away on average (emission x opacity: a ray
// passes a surface of alpha a with probability 1 - a).
inline float emitted_power_density(const Material &m) { return luminance(m.emission) * m.alpha; }

}  // namespace splat
