#include "scene/render_scene.h"

#include <cmath>
#include <new>

#include "bvh/packet.h"

namespace splat {

Placement Instance::moving_at(float time, Affine scratch[2]) const {
    double w[12], o[12];
    motion::at(motion.data(), int(motion.size()), time, w);
    // The keys were checked invertible (the bindings); an interpolated stretch between two
    // invertible ones can still be singular (a mirror half way): the frame's transforms then.
    if (!motion::invert_affine(w, o)) return {&to_world, &to_object};
    for (int k = 0; k < 12; ++k) scratch[0].m[k] = float(w[k]), scratch[1].m[k] = float(o[k]);
    return {&scratch[0], &scratch[1]};
}

// The box a moving instance's geometry (`local`: its object-space box) sweeps over the
// shutter: the boxes at times spaced so that no step turns more than 22.5 degrees (8 times a
// key interval; slerp turns at most 180 between keys), widened by the most a corner moves
// between two of them -- a corner's path between two times strays from the chord by less
// than the chord's length at such small turns, so the box holds the whole sweep.
static AABB swept_bounds(const Instance &inst, const AABB &local) {
    AABB world;
    const int n = int(inst.motion.size());
    const int times = 8 * (n - 1) + 1;
    float pad = 0.f;
    Vec3 prev[8];
    for (int i = 0; i < times; ++i) {
        PlacementScratch scratch;
        const Placement at = inst.at(float(double(i) / (times - 1)), scratch.a);
        for (int c = 0; c < 8; ++c) {
            const Vec3 p = at.to_world->point(Vec3(c & 1 ? local.hi.x : local.lo.x, c & 2 ? local.hi.y : local.lo.y,
                                                   c & 4 ? local.hi.z : local.lo.z));
            world.grow(p);
            if (i > 0) pad = std::fmax(pad, length(p - prev[c]));
            prev[c] = p;
        }
    }
    world.lo = world.lo - Vec3(pad, pad, pad), world.hi = world.hi + Vec3(pad, pad, pad);
    return world;
}

RenderScene::RenderScene(std::vector<Instance> instances, std::vector<Material> materials, std::vector<Light> lights,
                         int threads, std::vector<NodeProgram> programs)
    : instances_(std::move(instances)), materials_(std::move(materials)), lights_(std::move(lights)),
      programs_(std::move(programs)) {
    if (materials_.empty()) materials_.push_back(Material());
    for (NodeProgram &p : programs_) p.validate(), any_light_path_ |= p.uses_light_path;
    for (Material &m : materials_) {
        if (m.program >= int(programs_.size())) m.program = -1;
        const bool programmed_alpha = m.program >= 0 && programs_[m.program].outputs[int(Output::Alpha)] >= 0;
        any_transparent_ |= m.alpha < 1.f || m.use_point_alpha || programmed_alpha;
        any_emission_ |= m.emits() || (m.program >= 0 && programs_[m.program].outputs[int(Output::Emission)] >= 0);
    }
    std::vector<AABB> boxes(instances_.size());
    for (size_t i = 0; i < instances_.size(); ++i) {
        Instance &inst = instances_[i];
        if (inst.shadow_catcher) inst.visibility |= (inst.visibility & kVisAll) << kCatcherShift, any_catcher_ = true;
        const AABB local = inst.splats ? inst.splats->bounds() : inst.mesh->bounds();
        AABB world;
        any_motion_ |= inst.moves();
        if (!local.empty() && inst.moves()) {
            world = swept_bounds(inst, local);
        } else if (!local.empty()) {
            for (int c = 0; c < 8; ++c)
                world.grow(inst.to_world.point(Vec3(c & 1 ? local.hi.x : local.lo.x, c & 2 ? local.hi.y : local.lo.y,
                                                    c & 4 ? local.hi.z : local.lo.z)));
            // The corners went through float arithmetic: widen by a few ulps of their size.
            const Vec3 pad = (vabs(world.lo) + vabs(world.hi)) * 4e-7f;
            world.lo = world.lo - pad, world.hi = world.hi + pad;
        }
        if (!local.empty() && inst.moves()) {
            const Vec3 pad = (vabs(world.lo) + vabs(world.hi)) * 4e-7f;  // as above
            world.lo = world.lo - pad, world.hi = world.hi + pad;
        }
        inst.bounds = world;
        // An empty geometry gets a degenerate box far away from nothing: never entered.
        boxes[i] = world.empty() ? AABB{Vec3(0, 0, 0), Vec3(0, 0, 0)} : world;
    }
    top_.build(boxes, threads);
    // After the bounds: a programmed emitter's estimate runs its program, which reads them.
    if (any_emission_) mesh_lights_ = MeshLights(instances_, materials_, this, threads);
}

Vec3 RenderScene::emitted_on_triangle(int instance, int32_t tri, float b1, float b2, Vec3 wo, const Camera *camera,
                                      float time) const {
    const Instance &inst = instances_[size_t(instance)];
    MeshHit h;
    h.tri = tri, h.b1 = b1, h.b2 = b2;
    // The point, its normals and its program all in the frame's placement: that is where
    // MeshLights put the triangle, where the shadow ray is aimed and what the pdf was measured
    // on (a moving emitter is lit from there, docs/ALGORITHM.md). Its object-space point is
    // then exactly the triangle's own, so that Object, Generated and UV -- what a textured
    // emitter is laid out by -- are those a ray meeting the same point at any time reads.
    const Placement frame{&inst.to_world, &inst.to_object};
    SurfacePoint sp;
    sp.t = 0.f, sp.instance = instance, sp.prim = tri, sp.b1 = b1, sp.b2 = b2;
    sp.ng = normalize(inst.to_object.transposed_vector(inst.mesh->geometric_normal(tri)));
    sp.ns = normalize(inst.to_object.transposed_vector(inst.mesh->shading_normal(h)));
    sp.front = h.front = dot(sp.ng, wo) > 0.f;
    sp.p = inst.to_world.point(inst.mesh->point(h));
    sp.material = inst.material_of(inst.mesh->material(tri));
    const Material &m = materials_[size_t(sp.material)];
    // Cycles evaluates a sampled emitter's shader with PATH_RAY_EMISSION alone: every Light
    // Path output 0 (its depths too, where Cycles gives the path's).
    static const float kEmissionRay[kLightPathFloats] = {};
    const Material out = m.program >= 0 ? evaluate_program(m, sp, wo, nullptr, camera, time, nullptr, kEmissionRay,
                                                           &frame)
                                        : m;
    return out.emission * out.alpha;
}

Material RenderScene::evaluate_program(const Material &m, const SurfacePoint &sp, Vec3 wo, Vec3 *normal_out,
                                       const Camera *camera, float time, const AovSink *aov,
                                       const float *light_path, const Placement *placement,
                                       const ShadingQueries *queries) const {
    const NodeProgram &prog = programs_[m.program];
    const Instance &inst = instances_[sp.instance];
    // A moving instance's object space is where it is at the ray's time: the point was found
    // there (take_mesh_hit, take_splat_hit), so its object and Generated coordinates are the
    // same at every time, as Cycles' are.
    PlacementScratch scratch;
    const Placement at = placement ? *placement : inst.at(time, scratch.a);
    const Affine &to_world = *at.to_world, &to_object = *at.to_object;
    ShaderGlobals sg;
    sg.P = sp.p, sg.I = wo;
    // Cycles turns a back face's normals towards the viewer: so do the nodes' normals.
    const bool back = dot(sp.ng, wo) < 0.f;
    sg.Ng = back ? sp.ng * -1.f : sp.ng;
    sg.N = dot(sp.ns, wo) < 0.f ? sp.ns * -1.f : sp.ns;
    sg.backfacing = back ? 1.f : 0.f;
    sg.object = to_object.point(sp.p);
    sg.object_normal = normalize(to_world.transposed_vector(sg.N));
    // Generated coordinates: the object-space position within the geometry's bounds (Blender's
    // automatic texture space).
    const AABB box = inst.splats ? inst.splats->bounds() : inst.mesh->bounds();
    if (!box.empty())
        for (int k = 0; k < 3; ++k) {
            const float size = box.hi[k] - box.lo[k];
            sg.generated[k] = size > 0.f ? (sg.object[k] - box.lo[k]) / size : 0.5f;
        }
    sg.surface_normal = sp.ns;
    // Into the camera's frame by the transpose of its rotation (its axes are unit and
    // orthogonal), with Z negated: Cycles' camera space looks along +Z. A moving camera
    // is where it is at the ray's time.
    double moved[12];
    const double *c = nullptr;
    if (camera && (prog.uses_camera || prog.uses_window)) {
        if (camera->moves()) motion::at(camera->motion, camera->motion_steps, time, moved);
        c = camera->moves() ? moved : camera->local_from_camera;
    }
    auto camera_space_of = [](const double *m, Vec3 p, bool direction) {
        const double d[3] = {double(p.x) - (direction ? 0.0 : m[3]), double(p.y) - (direction ? 0.0 : m[7]),
                             double(p.z) - (direction ? 0.0 : m[11])};
        Vec3 out;
        for (int k = 0; k < 3; ++k) {
            const double len = std::sqrt(m[k] * m[k] + m[4 + k] * m[4 + k] + m[8 + k] * m[8 + k]);
            const double v = (m[k] * d[0] + m[4 + k] * d[1] + m[8 + k] * d[2]) / (len > 0 ? len : 1.0);
            out[k] = float(k == 2 ? -v : v);
        }
        return out;
    };
    auto camera_space = [&](Vec3 p, bool direction) { return camera_space_of(c, p, direction); };
    if (camera && prog.uses_camera) sg.camera = camera_space(sp.p, false);
    // Window: Cycles' camera_world_to_ndc, 0..1 over the camera's whole frame (its shift
    // included, a border not: the frustum is the full frame's), z 0. A planar camera projects
    // the point onto its frame (divided by the depth, as Cycles' perspective divide is, 0 at
    // depth 0); a panorama gives its own coordinates of the direction to the point. The
    // camera where it is at the frame's time, motion blur or not: Cycles' one world-to-NDC
    // transform.
    auto window = [&](Vec3 p) {
        const Vec3 q = camera_space_of(camera->local_from_camera, p, false);
        const double *f = camera->frustum;
        double u, v;
        if (camera->panoramic()) {
            const double len = std::sqrt(double(q.x) * q.x + double(q.y) * q.y + double(q.z) * q.z);
            if (!(len > 0.0)) return Vec3();
            const double d[3] = {q.x / len, q.y / len, -q.z / len};  // back to looking down -Z
            camera->panorama_uv(d, &u, &v);
            return Vec3(float(u), float(v), 0.f);
        }
        if (camera->orthographic) {
            u = q.x, v = q.y;
        } else {
            if (q.z == 0.f) return Vec3();
            u = double(q.x) / q.z, v = double(q.y) / q.z;
        }
        return Vec3(float((u - f[0]) / (f[1] - f[0])), float((v - f[2]) / (f[3] - f[2])), 0.f);
    };
    if (camera && prog.uses_window) sg.window = window(sp.p);
    for (int row = 0; row < 3; ++row)  // to_object^T: object-space normals into the scene frame
        for (int col = 0; col < 3; ++col) sg.normal_matrix[3 * row + col] = to_object.m[4 * col + row];
    if (inst.mesh) {
        sg.uv = inst.mesh->uv(sp.prim, sp.b1, sp.b2);
        sg.parametric = Vec3(1.f - sp.b1 - sp.b2, sp.b1, 0.f);  // Cycles' u, v are our b1, b2
        Vec3 t;
        float sign;
        if (prog.uses_tangent && inst.mesh->uv_tangent(sp.prim, &t, &sign)) {
            // Into the scene frame, then perpendicular to the shading normal (Gram-Schmidt), as
            // a tangent interpolated over a smooth surface is.
            t = to_world.vector(t);
            t = t - sp.ns * dot(sp.ns, t);
            if (dot(t, t) > 0.f) sg.tangent = normalize(t), sg.tangent_sign = sign;
        }
    }
    sg.queries = queries;
    if (prog.uses_triangle && inst.mesh) {  // Wireframe: the triangle where it is at the ray's time
        inst.mesh->vertices(sp.prim, &sg.triangle[0], &sg.triangle[1], &sg.triangle[2]);
        for (Vec3 &v : sg.triangle) v = to_world.point(v);
        sg.has_triangle = true;
    }
    if (sp.has_point_colour) sg.point_colour = sp.point_colour;
    sg.point_alpha = sp.point_alpha;
    sg.attributes = sp.attributes, sg.attribute_count = sp.n_attributes;
    sg.object_values = inst.object_values.data(), sg.object_value_count = int(inst.object_values.size());
    sg.light_path = light_path;
    float mesh_attributes[kMaxPointAttributes];
    if (inst.mesh && inst.mesh->attribute_count() > 0) {  // interpolated over the triangle, as Cycles does
        inst.mesh->attributes(sp.prim, sp.b1, sp.b2, mesh_attributes);
        sg.attributes = mesh_attributes, sg.attribute_count = inst.mesh->attribute_count();
    }
    if (prog.uses_bump) {
        // The Bump node's two nearby points: along two perpendicular directions in the plane of
        // the surface, a fixed fraction of the object's size away. Cycles offsets by a tenth of
        // the pixel's footprint; for a height that varies smoothly at that scale both give its
        // gradient. A fraction of the object's size (the frame its textures are laid out in)
        // keeps the offset far below a texture's features whatever the scene's units, and the
        // floor of a few float ulps of the position keeps it resolvable far from the origin.
        constexpr float kBumpOffset = 1e-4f, kPositionUlps = 1.5e-5f;  // 1.5e-5: ~128 ulps of |P|
        const float size = inst.bounds.empty() ? 0.f : length(inst.bounds.hi - inst.bounds.lo);
        const float eps = std::fmax(kBumpOffset * size, kPositionUlps * max_component(vabs(sp.p)));
        // An orthonormal pair about the geometric normal (Duff et al., "Building an
        // Orthonormal Basis, Revisited", 2017).
        const Vec3 n = sg.Ng;
        const float sign = std::copysign(1.f, n.z), a = -1.f / (sign + n.z), b = n.x * n.y * a;
        const Vec3 tangents[2] = {{1.f + sign * n.x * n.x * a, sign * b, -sign * n.x},
                                  {b, sign + n.y * n.y * a, -n.y}};
        for (int k = 0; k < 2; ++k) {
            ShaderGlobals::Offset &d = sg.bump[k];
            d.P = tangents[k] * (eps > 0.f ? eps : 1e-6f);
            d.object = to_object.vector(d.P);
            if (!box.empty())
                for (int i = 0; i < 3; ++i) {
                    const float extent = box.hi[i] - box.lo[i];
                    d.generated[i] = extent > 0.f ? d.object[i] / extent : 0.f;
                }
            if (inst.mesh) {  // the UV map's change across the triangle for that step
                Vec3 v0, v1, v2;
                inst.mesh->vertices(sp.prim, &v0, &v1, &v2);
                const Vec3 e1 = v1 - v0, e2 = v2 - v0;
                const float a11 = dot(e1, e1), a12 = dot(e1, e2), a22 = dot(e2, e2);
                const float det = a11 * a22 - a12 * a12;
                if (det > 0.f) {
                    const float r1 = dot(e1, d.object), r2 = dot(e2, d.object);
                    const float db1 = (a22 * r1 - a12 * r2) / det, db2 = (a11 * r2 - a12 * r1) / det;
                    d.uv = inst.mesh->uv(sp.prim, sp.b1 + db1, sp.b2 + db2) - sg.uv;
                }
            }
            if (camera && prog.uses_camera) d.camera = camera_space(d.P, true);
            if (camera && prog.uses_window) d.window = window(sp.p + d.P) - sg.window;
        }
    }
    float r[kMaxNodeRegisters];
    prog.run(sg, r);
    if (aov && !prog.aovs.empty()) aov->write(prog, r);
    Material out = m;
    auto scalar = [&](Output o, float lo, float hi, float &field) {
        const int32_t i = prog.outputs[int(o)];
        if (i >= 0 && std::isfinite(r[i])) field = std::fmin(std::fmax(r[i], lo), hi);
    };
    auto colour = [&](Output o, Vec3 &field) {
        const int32_t i = prog.outputs[int(o)];
        if (i < 0) return;
        for (int k = 0; k < 3; ++k)  // as the export clamps constants: >= 0, within the coordinate limit
            if (std::isfinite(r[i + k])) field[k] = std::fmin(std::fmax(r[i + k], 0.f), kMaxCoordinate);
    };
    colour(Output::Base, out.base);
    colour(Output::Emission, out.emission);
    if (prog.outputs[int(Output::MetalColour)] >= 0) {
        if (!out.own_metal) out.metal_colour = out.base;
        colour(Output::MetalColour, out.metal_colour);
        out.own_metal = true;
    }
    scalar(Output::Metallic, 0.f, 1.f, out.metallic);
    scalar(Output::Roughness, 0.f, 1.f, out.roughness);
    scalar(Output::Transmission, 0.f, 1.f, out.transmission);
    scalar(Output::Alpha, 0.f, 1.f, out.alpha);
    scalar(Output::IOR, 1e-3f, kMaxCoordinate, out.ior);  // render/shading.py's smallest IOR
    scalar(Output::SpecularLevel, 0.f, kMaxCoordinate, out.specular_level);
    if (prog.outputs[int(Output::Base)] >= 0) out.use_point_colour = false;  // the nodes read them
    const int32_t normal = prog.outputs[int(Output::Normal)];
    if (normal >= 0 && normal_out) {
        const Vec3 n(r[normal], r[normal + 1], r[normal + 2]);
        if (std::isfinite(dot(n, n)) && dot(n, n) > 0.f) *normal_out = normalize(n);
    }
    if (prog.outputs[int(Output::Alpha)] >= 0) out.use_point_alpha = false;
    return out;
}

Ray RenderScene::to_object(const Affine &to_object, const Ray &ray, float *scale) {
    Ray r;
    r.o = to_object.point(ray.o);
    const Vec3 d = to_object.vector(ray.d);
    const float s = length(d);
    r.d = d * (1.f / s);
    r.tmin = ray.tmin * s;
    r.tmax = ray.tmax * s;  // inf stays inf
    *scale = s;
    return r;
}

std::vector<uint8_t> RenderScene::locate_camera(Vec3 eye) const {
    // A point is inside a closed surface when rays from it in every direction first meet the
    // surface from behind. Six axis rays, five of which must agree: one may slip through a
    // gap between discs or graze an edge.
    std::vector<uint8_t> camera_inside(instances_.size(), 0);
    for (size_t i = 0; i < instances_.size(); ++i) {
        const Instance &inst = instances_[i];
        if (!inst.splats || !inst.splats->any_closed()) continue;
        const Vec3 o = inst.to_object.point(eye);
        int behind = 0;
        for (int k = 0; k < 6; ++k) {
            Ray r;
            r.o = o;
            r.d = Vec3(k == 0 ? 1.f : k == 1 ? -1.f : 0.f, k == 2 ? 1.f : k == 3 ? -1.f : 0.f,
                       k == 4 ? 1.f : k == 5 ? -1.f : 0.f);
            const Hit h = inst.splats->intersect(r);
            behind += h.valid() && !h.front && inst.splats->closed(h.id);
        }
        camera_inside[i] = behind >= 5;
    }
    return camera_inside;
}

// Visits, front to back, each instance visible to `ray_kind` whose box the ray enters before
// `limit`: visit(index, instance, its placement at the ray's time, ray in object space,
// distance scale, starts on it?) returns true to stop (an occluder found).
template <class Visit>
void RenderScene::for_each_instance(const Ray &ray, const float &limit, uint32_t ray_kind, const Origin &from,
                                    TraversalStats *stats, Visit &&visit) const {
    if (instances_.empty()) return;
    if (from.catcher_only) ray_kind <<= kCatcherShift;  // only shadow catchers are seen
    const Vec3 inv_d(1.f / ray.d.x, 1.f / ray.d.y, 1.f / ray.d.z);
    traverse_bvh(
        top_, ray, limit,
        [&](uint32_t first, uint32_t count) {
            for (uint32_t k = first; k < first + count; ++k) {
                const int index = int(top_.prim_order[k]);
                const Instance &inst = instances_[index];
                if (!(inst.visibility & ray_kind)) continue;
                // A leaf holds several instances: the ray's entering the leaf's box does not
                // mean it enters each one's (a layer query where it does not finds nothing,
                // at a traversal's cost: a quarter of a bunny-on-a-floor frame's queries).
                if (intersect_box(inst.bounds, ray.o, inv_d, ray.tmin, limit) == kInfinity) continue;
                PlacementScratch scratch;
                const Placement at = inst.at(from.time, scratch.a);
                float s;
                Ray local = to_object(*at.to_object, ray, &s);
                if (visit(index, inst, at, local, s, from.instance == index)) return true;
            }
            return false;
        },
        stats ? &stats->nodes : nullptr);
}

// Which of two surfaces at one distance a ray sees: the instance with the smaller index, so
// that the answer does not depend on the order the instances are visited in (the packet
// query visits them in another order than a ray alone).
inline bool nearer(float t, int index, const SurfacePoint &best) {
    return t < best.t || (t == best.t && index < best.instance);
}

// A mesh hit `h` of instance `index` (ray in object space, `s` its distance scale) becomes
// `best` when nearer.
void RenderScene::take_mesh_hit(int index, const Instance &inst, Placement at, const MeshHit &h, float s,
                                SurfacePoint &best) const {
    if (!h.valid() || !nearer(h.t / s, index, best)) return;
    best.t = h.t / s, best.instance = index, best.prim = h.tri, best.front = h.front, best.b1 = h.b1, best.b2 = h.b2;
    best.n_members = 0, best.has_point_colour = false, best.point_alpha = 1.f, best.n_attributes = 0;
    const Vec3 ng = normalize(at.to_object->transposed_vector(inst.mesh->geometric_normal(h.tri)));
    const Vec3 ns = normalize(at.to_object->transposed_vector(inst.mesh->shading_normal(h)));
    best.ng = ng, best.ns = ns;
    // The point is the triangle's own (barycentric interpolation, then the instance
    // transform), not ray.o + t d: that one carries the rounding of t and of the ray's
    // origin -- about an ulp of the camera's distance, not of p -- and a shadow ray from a
    // point that fell below the surface met the neighbouring triangle (black pixels on a UV
    // sphere near its pole).
    const Vec3 po = inst.mesh->point(h);
    best.p = at.to_world->point(po);
    // Start secondary rays off the surface by the interpolation's error bound carried into
    // the scene frame, plus the transform's own rounding (gamma(3) (|M| |po| +
    // |translation|), per axis).
    const Vec3 obj_err = inst.mesh->point_error(h);
    const Affine &M = *at.to_world;
    const Vec3 abs_po = vabs(po);
    auto abs_row = [&](int r, Vec3 v) {
        return std::fabs(M.m[4 * r]) * v.x + std::fabs(M.m[4 * r + 1]) * v.y + std::fabs(M.m[4 * r + 2]) * v.z;
    };
    constexpr float kGamma3 = rounding_gamma(3);
    float err = 0.f;
    for (int r = 0; r < 3; ++r)
        err = std::fmax(err, abs_row(r, obj_err) + kGamma3 * (abs_row(r, abs_po) + std::fabs(M.m[4 * r + 3])));
    best.offset = 2.f * (err + max_component(vabs(best.p)) * 1.2e-7f);
    best.material = inst.material_of(inst.mesh->material(h.tri));
}

// A splat surface `h` of instance `index` met by `ray` (scene frame) becomes `best` when nearer.
void RenderScene::take_splat_hit(int index, const Instance &inst, Placement at, const Ray &ray, const SurfaceHit &h,
                                 float s, SurfacePoint &best) const {
    if (!h.valid() || !nearer(h.t / s, index, best)) return;
    best.t = h.t / s, best.instance = index, best.prim = h.id, best.front = h.front;
    best.ng = normalize(at.to_object->transposed_vector(inst.splats->normal(h.id)));
    best.ns = normalize(at.to_object->transposed_vector(h.normal));
    best.p = ray.o + ray.d * best.t;
    best.offset = 0;  // splat rays leave by excluding the members instead
    best.radius = inst.splats->radius(h.id) / s;
    best.point_colour = h.colour, best.has_point_colour = inst.splats->has_colours();
    best.point_alpha = h.alpha;
    best.n_attributes = inst.splats->attribute_count();
    std::copy_n(h.attributes, best.n_attributes, best.attributes);
    best.material = inst.material_offset;
    best.n_members = h.n_members;
    for (int m = 0; m < h.n_members; ++m) best.members[m] = h.members[m];
}

// How far a mesh query needs to look behind the nearest surface so far (scene distance
// `limit`, object scale `s`): a little past it, so that a hit at the same distance -- which
// the smaller instance index may win -- is still found whatever the rounding of limit x s
// and of t / s (fl(t / s) <= limit allows t up to limit x s x (1 + 2^-24); 8 half-ulps of
// slack, taken on the magnitude so that it also points away for a negative limit).
inline float mesh_reach(float limit, float s) {
    const float r = limit * s;
    return r + std::fabs(r) * (8 * kUnitRoundoff);
}

SurfacePoint RenderScene::intersect(const Ray &ray, const Method &method, uint32_t ray_kind, const Origin &from,
                                    const uint8_t *camera_inside, TraversalStats *stats) const {
    SurfacePoint best;
    float limit = ray.tmax;
    for_each_instance(ray, limit, ray_kind, from, stats,
                      [&](int index, const Instance &inst, Placement at, Ray &local, float s, bool self) {
                          if (inst.mesh) {
                              local.tmax = std::fmin(local.tmax, mesh_reach(limit, s));
                              take_mesh_hit(index, inst, at,
                                            inst.mesh->intersect(local, self ? from.triangle : -1, stats), s, best);
                          } else {
                              // The whole ray, not cut at the nearest surface so far: the layer's
                              // window may reach past it (its members, and the far phase's exit),
                              // and what the ray sees must not depend on the instances' order.
                              const bool inside = from.inside == index || (self && from.back) ||
                                                  (camera_inside && camera_inside[index]);
                              take_splat_hit(index, inst, at, ray,
                                             find_surface(*inst.splats, local, method, inside,
                                                          self ? from.members : nullptr, self ? from.n_members : 0,
                                                          false, stats),
                                             s, best);
                          }
                          limit = std::fmin(best.t, ray.tmax);  // as the packet query bounds it
                          return false;
                      });
    return best;
}

void RenderScene::intersect_camera(const Ray *rays, int n, const Method &method, const uint8_t *camera_inside,
                                   SurfacePoint *out, TraversalStats *stats, const float *times) const {
    for (int i = 0; i < n; ++i) new (&out[i]) SurfacePoint;
    // The camera-visible instances each ray enters (its own box test, through the top-level
    // tree as a packet), then each instance's rays together.
    struct Entered {
        int index;
        uint32_t rays;
    };
    constexpr int kMaxEntered = 64;  // instances one packet meets; more go ray by ray
    Entered entered[kMaxEntered];
    int n_entered = 0;
    bool overflow = false;
    const PacketRays soa(rays, n);
    traverse_packet(
        top_, soa, n,
        [&](uint32_t mask, uint32_t first, uint32_t count, float *) {
            for (uint32_t k = first; k < first + count; ++k) {
                const int index = int(top_.prim_order[k]);
                if (!(instances_[index].visibility & kVisCamera)) continue;
                int e = 0;
                while (e < n_entered && entered[e].index != index) ++e;
                if (e == n_entered) {
                    if (n_entered == kMaxEntered) {
                        overflow = true;
                        continue;
                    }
                    entered[n_entered++] = Entered{index, 0};
                }
                entered[e].rays |= mask;
            }
        },
        stats ? &stats->nodes : nullptr);
    if (overflow) {  // a packet crossing more than kMaxEntered instances' boxes: ray by ray
        for (int i = 0; i < n; ++i) {
            Origin from;
            from.time = times ? times[i] : 0.f;
            out[i] = intersect(rays[i], method, kVisCamera, from, camera_inside, stats);
        }
        return;
    }
    for (int e = 0; e < n_entered; ++e) {
        const int index = entered[e].index;
        const Instance &inst = instances_[index];
        Ray local[kPacketRays];
        float scale[kPacketRays];
        int ray_of[kPacketRays], m = 0;
        // Each ray's placement of the instance: one for all unless it moves.
        PlacementScratch scratch[kPacketRays];
        Placement at[kPacketRays];
        for (uint32_t bits = entered[e].rays; bits; bits &= bits - 1) {
            const int i = __builtin_ctz(bits);
            // Behind the ray's nearest surface so far (instances come roughly front to back):
            // skipped, as the ray alone skips it.
            const Vec3 inv(soa.inv_d[0][i], soa.inv_d[1][i], soa.inv_d[2][i]);
            const float limit = std::fmin(out[i].t, rays[i].tmax);  // as intersect() bounds it
            if (intersect_box(inst.bounds, rays[i].o, inv, rays[i].tmin, limit) == kInfinity) continue;
            ray_of[m] = i;
            at[m] = inst.at(times ? times[i] : 0.f, scratch[m].a);
            local[m] = to_object(*at[m].to_object, rays[i], &scale[m]);
            ++m;
        }
        if (inst.mesh) {
            for (int j = 0; j < m; ++j) {
                SurfacePoint &best = out[ray_of[j]];
                const float limit = std::fmin(best.t, rays[ray_of[j]].tmax);
                local[j].tmax = std::fmin(local[j].tmax, mesh_reach(limit, scale[j]));
                take_mesh_hit(index, inst, at[j], inst.mesh->intersect(local[j], -1, stats), scale[j], best);
            }
        } else {
            bool inside[kPacketRays];
            for (int j = 0; j < m; ++j) inside[j] = camera_inside[index] != 0;
            SurfaceHit hits[kPacketRays];
            find_surfaces(*inst.splats, local, m, method, inside, nullptr, 0, hits, stats);
            for (int j = 0; j < m; ++j)
                take_splat_hit(index, inst, at[j], rays[ray_of[j]], hits[j], scale[j], out[ray_of[j]]);
        }
    }
}

int RenderScene::local_hits(int index, Ray ray, float time, ShadingQueries::LocalHit *out, int max,
                            TraversalStats *stats) const {
    if (index < 0 || size_t(index) >= instances_.size() || !instances_[size_t(index)].mesh) return 0;
    const Instance &inst = instances_[size_t(index)];
    PlacementScratch scratch;
    const Placement at = inst.at(time, scratch.a);
    float s;
    Ray local = to_object(*at.to_object, ray, &s);
    int n = 0;
    int32_t skip = -1;
    while (n < max) {  // each next surface beyond the last (its triangle skipped)
        const MeshHit h = inst.mesh->intersect(local, skip, stats);
        if (!h.valid()) break;
        out[n].p = at.to_world->point(inst.mesh->point(h));
        out[n].ng = normalize(at.to_object->transposed_vector(inst.mesh->geometric_normal(h.tri)));
        out[n].n = normalize(at.to_object->transposed_vector(inst.mesh->shading_normal(h)));
        ++n;
        local.tmin = h.t, skip = h.tri;
    }
    return n;
}

bool RenderScene::occluded(const Ray &ray, const Method &method, const Origin &from, TraversalStats *stats,
                           int only_instance) const {
    bool blocked = false;
    const float limit = ray.tmax;
    for_each_instance(ray, limit, kVisShadow, from, stats,
                      [&](int index, const Instance &inst, Placement, Ray &local, float, bool self) {
                          if (only_instance >= 0 && index != only_instance) return false;
                          if (inst.mesh) return blocked = inst.mesh->occluded(local, self ? from.triangle : -1, stats);
                          // Splats block only where the visibility rules put a surface: a fringe
                          // disc (far phase) or the splats the ray starts from never cast a shadow.
                          const SurfaceHit h = find_surface(*inst.splats, local, method,
                                                            from.inside == index || (self && from.back),
                                                            self ? from.members : nullptr,
                                                            self ? from.n_members : 0, false, stats);
                          return blocked = h.valid() && h.t < local.tmax;
                      });
    return blocked;
}

}  // namespace splat
