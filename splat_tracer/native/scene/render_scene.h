// A renderable scene: geometry (splat clouds and triangle meshes, each with its own BVH,
// built once and shared) placed by instances (transform, materials, ray visibility), a
// top-level BVH over the instances, the materials and the lamps.
//
// Every query is in the scene's local frame (the caller subtracts a float64 origin). A ray
// enters an instance by the inverse transform and is renormalised there, so discs are
// intersected in object space: exact for any affine transform, non-uniform scale included.
#pragma once

#include <cstdint>
#include <vector>

#include "bvh/bvh.h"
#include "nodes/program.h"
#include "shade/aov.h"
#include "scene/camera.h"
#include "scene/mesh.h"
#include "scene/mesh_lights.h"
#include "scene/motion.h"
#include "shade/shading.h"
#include "splats/splat_scene.h"
#include "splats/visibility.h"

namespace splat {

// Ray kinds an instance may be hidden from (Blender's Object > Visibility > Ray Visibility).
enum RayVisibility : uint32_t {
    kVisCamera = 1,
    kVisDiffuse = 2,
    kVisGlossy = 4,
    kVisTransmission = 8,
    kVisShadow = 16,
    kVisAll = 31,
};
// A shadow catcher's ray visibility is held twice: its own bits, and the same bits this many
// places higher. A ray of a catcher-only path (Origin::catcher_only: the path that shades a
// catcher as if nothing else were in the scene, the denominator of the Shadow Catcher pass)
// asks for its kind shifted up, so that only catchers answer it -- in the same test that
// ray visibility already makes. Cycles' SHADOW_CATCHER_VISIBILITY_SHIFT, for the same reason.
constexpr uint32_t kCatcherShift = 5;

struct Affine {  // row-major 3x4: p' = M p + t
    float m[12] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
    Vec3 point(Vec3 p) const {
        return {m[0] * p.x + m[1] * p.y + m[2] * p.z + m[3], m[4] * p.x + m[5] * p.y + m[6] * p.z + m[7],
                m[8] * p.x + m[9] * p.y + m[10] * p.z + m[11]};
    }
    Vec3 vector(Vec3 v) const {
        return {m[0] * v.x + m[1] * v.y + m[2] * v.z, m[4] * v.x + m[5] * v.y + m[6] * v.z,
                m[8] * v.x + m[9] * v.y + m[10] * v.z};
    }
    Vec3 transposed_vector(Vec3 v) const {  // M^T v: normals go object -> world by to_object^T
        return {m[0] * v.x + m[4] * v.y + m[8] * v.z, m[1] * v.x + m[5] * v.y + m[9] * v.z,
                m[2] * v.x + m[6] * v.y + m[10] * v.z};
    }
};

// An instance's transforms at one time of the shutter.
struct Placement {
    const Affine *to_world, *to_object;
};

// Room for Instance::at's interpolated transforms, left uninitialised: an instance that does
// not move never touches it, and a packet's 16 of them cost nothing then.
union PlacementScratch {
    Affine a[2];
    PlacementScratch() {}
};

struct Instance {
    const SplatScene *splats = nullptr;  // exactly one of these two
    const TriangleMesh *mesh = nullptr;
    // The transforms at the frame's time: the only ones of an instance that does not move;
    // those of a moving one's mesh lights and of locate_camera.
    Affine to_world, to_object;
    // Motion blur: to_world at evenly spaced times over the shutter (motion.h); empty when
    // the instance does not move, and then it costs nothing.
    std::vector<MotionKey> motion;
    int material_offset = 0, material_count = 1;  // the instance's slots in the material table
    uint32_t visibility = kVisAll;
    bool holdout = false;        // camera rays that see it get alpha 0
    // Object > Visibility > Shadow Catcher: it receives the other objects' shadows and
    // reflections but is itself left out of Combined (the integrator's write_catcher).
    bool shadow_catcher = false;
    float pass_index = 0;        // Object Index pass
    // What its node programs read of it (Object Info, object and instancer attributes): laid
    // out as ShaderGlobals::object_values; empty when no program reads any (costs nothing).
    std::vector<float> object_values;
    AABB bounds;                 // in the scene frame

    bool moves() const { return !motion.empty(); }
    // The transforms at shutter time `time` (0 opens it, 1 closes it): its own when it does
    // not move, else interpolated into `scratch`.
    Placement at(float time, Affine scratch[2]) const {
        return motion.empty() ? Placement{&to_world, &to_object} : moving_at(time, scratch);
    }
    Placement moving_at(float time, Affine scratch[2]) const;

    // The material table index of a mesh triangle's slot (a slot past the object's: its first).
    int material_of(int32_t slot) const { return material_offset + (slot < material_count ? slot : 0); }
};

// Where a secondary ray starts, so that it does not meet that surface again.
struct Origin {
    int instance = -1;
    int32_t triangle = -1;              // the mesh triangle it leaves
    const int32_t *members = nullptr;  // or the splats that formed its point
    int n_members = 0;
    int inside = -1;  // the splat cloud a refracted ray travels inside (the swapped-facing rule)
    // It leaves an open cloud's back on that side (SplatScene::open_back): its queries of that
    // same cloud swap the facing too. Only of that cloud and only this ray: the next surface
    // point makes a new Origin.
    bool back = false;
    // The ray belongs to a catcher-only path: only shadow catchers are in its scene
    // (kCatcherShift). Unlike the fields above, it is the path's, and carried along it.
    bool catcher_only = false;
    // The path's time in the shutter (motion blur: 0 opens it, 1 closes it), where the moving
    // instances are; carried along the path as catcher_only is.
    float time = 0.f;
};

struct SurfacePoint {
    float t = kInfinity;
    int instance = -1;
    int32_t prim = -1;   // splat or triangle id within the instance's geometry
    bool front = false;  // the side the normal points to faces the ray
    Vec3 p, ng, ns;      // point, geometric and shading normal (scene frame, unit)
    // Whether a node program replaced ns (Bump, Normal Map) in a material whose Bump Map
    // Correction is on, and the surface's own shading normal it replaced (Cycles' sd->N):
    // what the bump shadowing term compares them by.
    bool bumped = false;
    Vec3 ns_surface;
    float offset = 0;    // how far a secondary ray must start off the surface (triangles always;
                         // splats only without wrong-hit elimination, see the integrator)
    float radius = 0;    // splats: the chosen splat's radius in the scene frame
    Vec3 point_colour;
    float point_alpha = 1.f;  // the points' own opacity (1 on meshes and clouds without alpha)
    bool has_point_colour = false;
    int n_attributes = 0;  // the cloud's point attributes, blended (SurfaceHit::attributes); none on meshes
    float attributes[kMaxPointAttributes];
    int material = 0;    // index in the material table
    // Meshes: barycentric coordinates of the triangle's vertices 1 and 2 (where node programs
    // and the UV pass read the UV map).
    float b1 = 0, b2 = 0;
    int n_members = 0;   // splats that formed the point
    int32_t members[kMaxLayerHits];

    bool valid() const { return instance >= 0; }
};

class RenderScene {
  public:
    // `programs`: the materials' node programs (Material::program indexes them), validated.
    RenderScene(std::vector<Instance> instances, std::vector<Material> materials, std::vector<Light> lights,
                int threads, std::vector<NodeProgram> programs = {});

    const Instance &instance(int i) const { return instances_[i]; }
    size_t instance_count() const { return instances_.size(); }
    const Material &material(int i) const { return materials_[i]; }
    size_t material_count() const { return materials_.size(); }
    // The material at a surface point seen from direction `wo` (towards the viewer) at shutter
    // time `time` (motion blur: where a moving instance is then): its node program run there,
    // or the constant material when it has none. The one place the integrator asks for a
    // material's inputs. A program that drives the normal (Normal Map) replaces sp.ns with it.
    // `camera`: the render's, for the Camera texture coordinate. `aov`: where the program's
    // AOV Output nodes write (a camera ray still writing its shader AOVs), or null.
    // `light_path`: the ray's kind and depths for a Light Path node (kLightPathFloats; null: a
    // camera ray's first surface); only needed where any_light_path(). `queries`: the rays a
    // program may trace from the point (Ambient Occlusion), or null.
    Material material_at(SurfacePoint &sp, Vec3 wo, const Camera *camera = nullptr, float time = 0.f,
                         const AovSink *aov = nullptr, const float *light_path = nullptr,
                         const ShadingQueries *queries = nullptr) const {
        const Material &m = materials_[sp.material];
        // A program written for its AOVs alone runs only where they are written.
        if (m.program < 0 || (!aov && programs_[size_t(m.program)].aov_only)) return m;
        const Vec3 surface = sp.ns;
        Material out = evaluate_program(m, sp, wo, &sp.ns, camera, time, aov, light_path, nullptr, queries);
        sp.bumped = out.bump_correction && (sp.ns.x != surface.x || sp.ns.y != surface.y || sp.ns.z != surface.z);
        sp.ns_surface = surface;
        return out;
    }
    // Whether a node program drives what material `m` emits: its emission, or the opacity of a
    // constant emission (what a ray takes away is emission x opacity).
    bool programmed_emission(const Material &m) const {
        if (m.program < 0) return false;
        const NodeProgram &p = programs_[size_t(m.program)];
        return p.outputs[int(Output::Emission)] >= 0 || (p.outputs[int(Output::Alpha)] >= 0 && m.emits());
    }
    // What a ray from direction `wo` (towards the viewer) takes away at the point of triangle
    // `tri` of mesh instance `instance` with barycentrics (b1, b2) of its vertices 1 and 2:
    // emission x opacity, its node program run there in the frame's placement at every
    // `time` (MeshLights places the triangles there; `time` only moves a moving camera, for
    // the Camera coordinate). For emitters sampled as lights (MeshLights).
    Vec3 emitted_on_triangle(int instance, int32_t tri, float b1, float b2, Vec3 wo, const Camera *camera = nullptr,
                             float time = 0.f) const;
    const std::vector<Light> &lights() const { return lights_; }
    const MeshLights &mesh_lights() const { return mesh_lights_; }  // emissive triangles sampled as lights
    bool any_transparent() const { return any_transparent_; }
    bool any_emission() const { return any_emission_; }  // a material emits light
    bool any_catcher() const { return any_catcher_; }    // an instance is a shadow catcher
    bool any_motion() const { return any_motion_; }      // an instance moves over the shutter
    bool any_light_path() const { return any_light_path_; }  // a node program has a Light Path node
    // The point is an open cloud's back (SplatScene::open_back); never a mesh's.
    bool open_back(const SurfacePoint &sp) const {
        const Instance &inst = instances_[sp.instance];
        return inst.splats && inst.splats->open_back(sp.prim, sp.front);
    }

    // Per instance, 1 where a closed cloud encloses `eye`: that cloud's camera rays start
    // inside it. Kept by each render (the integrator), not by the scene: renders of one scene
    // from different cameras may run at once.
    std::vector<uint8_t> locate_camera(Vec3 eye) const;

    // The nearest surface along the ray among the instances visible to `ray_kind`.
    // camera_inside: locate_camera's flags for a camera ray, null for any other.
    SurfacePoint intersect(const Ray &ray, const Method &method, uint32_t ray_kind, const Origin &from,
                           const uint8_t *camera_inside, TraversalStats *stats) const;
    // intersect() for n <= kPacketRays camera rays (a 4x4 pixel block): the same answers,
    // each instance's rays traced together as a packet (packet.h). times: each ray's time
    // in the shutter (null: 0).
    void intersect_camera(const Ray *rays, int n, const Method &method, const uint8_t *camera_inside,
                          SurfacePoint *out, TraversalStats *stats, const float *times = nullptr) const;
    // Whether anything visible to shadow rays blocks the ray in (tmin, tmax); only instance
    // `only_instance` when >= 0 (the Ambient Occlusion node's Only Local).
    bool occluded(const Ray &ray, const Method &method, const Origin &from, TraversalStats *stats,
                  int only_instance = -1) const;

    // Up to `max` surfaces of instance `index` along the ray (scene frame) within its
    // (tmin, tmax), nearest first, where the instance is at `time`: Cycles' local intersection
    // (the Bevel node). A mesh's only; a cloud has none.
    int local_hits(int index, Ray ray, float time, ShadingQueries::LocalHit *out, int max,
                   TraversalStats *stats) const;

  private:
    // `placement`: where the instance is for the program (object space, normals, tangent);
    // null: where it is at `time`. A moving camera is where it is at `time` either way.
    Material evaluate_program(const Material &m, const SurfacePoint &sp, Vec3 wo, Vec3 *normal_out,
                              const Camera *camera, float time, const AovSink *aov,
                              const float *light_path = nullptr, const Placement *placement = nullptr,
                              const ShadingQueries *queries = nullptr) const;
    template <class Visit>
    void for_each_instance(const Ray &ray, const float &limit, uint32_t ray_kind, const Origin &from,
                           TraversalStats *stats, Visit &&visit) const;
    void take_mesh_hit(int index, const Instance &inst, Placement at, const MeshHit &h, float s,
                       SurfacePoint &best) const;
    void take_splat_hit(int index, const Instance &inst, Placement at, const Ray &ray, const SurfaceHit &h, float s,
                        SurfacePoint &best) const;
    // The ray in an instance's object space: unit direction, distances scaled by `scale`.
    static Ray to_object(const Affine &to_object, const Ray &ray, float *scale);

    std::vector<Instance> instances_;
    std::vector<Material> materials_;
    std::vector<Light> lights_;
    std::vector<NodeProgram> programs_;
    MeshLights mesh_lights_;
    BVH top_;
    bool any_transparent_ = false, any_emission_ = false, any_catcher_ = false, any_motion_ = false;
    bool any_light_path_ = false;
};

}  // namespace splat
