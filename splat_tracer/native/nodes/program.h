// Shader-node programs: a material's node tree compiled once at export (by
// splat_tracer/blender/export/nodes.py through splat_tracer/render/nodes.py) into a flat list of
// instructions over a register file of floats, evaluated at every shading point a ray meets --
// the idea of Cycles' SVM, with this engine's own encoding.
//
// Encoding (mirrored by render/nodes.py: OPS and the operand comments there are the one list):
// - `code`: rows of kWidth int32, [opcode, operands...]; operands are register indices (a
//   vec3 takes three consecutive registers), enumeration values or table offsets, as each
//   opcode says.
// - `data`: the registers' initial values: constants, the unlinked sockets' values and the
//   read-only tables (Color Ramp stops, curves), so that a program is one copy and a loop.
// - `outputs`: for each material input (Output below) the register that holds it, or -1 when
//   the material's constant value stands.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "base/vec3.h"
#include "nodes/image.h"
#include "splats/layer.h"

namespace splat {

constexpr int kNodeWidth = 8;          // int32 per instruction
constexpr int kMaxNodeRegisters = 4096;  // a program's registers live on the stack (16 KiB)
// An instance's own values (Instance::object_values, render/nodes.py OBJECT_INFO): Object
// Info's location (3), colour (3), alpha, pass index and random, then 4 floats (RGBA) per
// object, instancer or view-layer attribute the scene's programs read, at most this many.
constexpr int kObjectInfoFloats = 9;
constexpr int kMaxObjectAttributes = 16;
constexpr int kMaxObjectValues = kObjectInfoFloats + 4 * kMaxObjectAttributes;
// Light Path: what the ray that met the point is (render/nodes.py LIGHT_PATH, the node's
// outputs in order): is camera, shadow, diffuse, glossy, singular, reflection, transmission,
// volume scatter; ray length; ray, diffuse, glossy, transparent, transmission depth.
constexpr int kLightPathFloats = 14;

// What a program asks of the scene beyond the shading point (the Ambient Occlusion node's
// rays, the Wireframe node's pixel footprint): supplied by the integrator for the surface a
// path's ray meets, so that the nodes depend on this and not on the integrator. Where there
// is none (shadow rays through partly transparent surfaces, emitters sampled as lights, as
// Cycles evaluates those shaders without ray tracing), AO reads 1 and the footprint is 0.
class ShadingQueries {
  public:
    virtual ~ShadingQueries() = default;
    // `count` (<= 4) numbers in [0, 1) of the path's sampler for the purpose `key` (the
    // instruction's row), the `sub`-th of `subs` draws per sample: converging, deterministic.
    virtual void random(uint32_t key, float *u, int count, uint32_t sub, uint32_t subs) const = 0;
    // Whether a ray from the shading point along unit `d` meets a surface (the scene's shadow
    // rays' rules: splats by the paper's visibility rules, meshes off their own triangle)
    // within `distance`; `only_local`: only the shading point's own object counts.
    virtual bool occluded(Vec3 d, float distance, bool only_local) const = 0;
    // The width of a pixel's footprint at `p` across the camera ray (scene units).
    virtual float pixel_width(Vec3 p) const = 0;
    // A surface of the shading point's own object (Bevel): point, geometric and shading
    // normal, scene frame, unit, as the geometry has them (not turned towards anything).
    struct LocalHit {
        Vec3 p, ng, n;
    };
    // Up to `max` surfaces of the shading point's own mesh along the segment from `o` along
    // unit `d` within `distance`, nearest first (Cycles' local intersection); a point
    // cloud's: none. Returns how many.
    virtual int local_hits(Vec3 o, Vec3 d, float distance, LocalHit *out, int max) const = 0;
    // World > Light Settings > Distance (Cycles' ao_bounces_distance): an AO node's reach
    // when its Distance is 0 and unlinked.
    virtual float ao_distance() const = 0;
    // The smallest pdf of the directions the path took so far (Cycles' min_ray_pdf; infinite
    // at the camera and after mirror-like bounces).
    virtual float min_ray_pdf() const = 0;
};

// What a program reads from the shading point (Texture Coordinate, Geometry, Attribute).
struct ShaderGlobals {
    Vec3 P;          // position, scene frame
    Vec3 N;          // shading normal, towards the viewer's side (as Cycles flips a back face's)
    Vec3 Ng;         // geometric normal, same side
    Vec3 I;          // towards the viewer (unit)
    Vec3 object;     // position in the object's space
    Vec3 object_normal;  // N in the object's space (unit)
    Vec3 generated;  // object-space position in the geometry's bounds, 0..1
    Vec3 uv;         // the mesh's UV map (u, v, 0); 0 on clouds
    Vec3 point_colour;   // the points' own colour (0 where there is none)
    // The points' other attributes (SplatScene::set_attributes), blended at this point; an
    // Attribute instruction reading past attribute_count gets 0, as Cycles gives a missing one.
    const float *attributes = nullptr;
    int attribute_count = 0;
    float point_alpha = 1.f;
    float backfacing = 0.f;  // 1 when the ray met the back of the surface
    Vec3 tangent;            // the UV map's tangent (unit, perpendicular to the surface's normal); 0 without
    float tangent_sign = 1.f;  // the bitangent is tangent_sign x (normal x tangent)
    Vec3 surface_normal;     // the surface's shading normal, not turned towards the viewer
    Vec3 camera;             // position in the camera's space (Cycles': +Z along the view), 0 without a camera
    Vec3 window;             // Cycles' Window coordinates (0..1 over the camera's frame, z 0), 0 without a camera
    // Geometry > Parametric: Cycles' (1 - u - v, u, 0) of the triangle's corners; elsewhere (a
    // splat) what Cycles gives on its points, whose u and v are 0.
    Vec3 parametric = Vec3(1.f, 0.f, 0.f);
    // Object-space normals to the scene's: the transpose of the world-to-object matrix, by rows.
    float normal_matrix[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    // The instance's values (kObjectInfoFloats and its object attributes); null: none, read as 0.
    const float *object_values = nullptr;
    int object_value_count = 0;
    // The ray that met this point (kLightPathFloats); null: a camera ray's first surface.
    const float *light_path = nullptr;
    // The Bump node's two nearby shading points: for each, how far every position-dependent
    // global moves from this point (all zero when the program has no Bump node).
    struct Offset {
        Vec3 P, object, generated, uv, camera, window;
    };
    Offset bump[2];
    const ShadingQueries *queries = nullptr;  // null: none (see ShadingQueries)
    // The mesh triangle's corners in the scene frame (Wireframe; set when the program
    // uses_triangle and the point is a mesh's).
    bool has_triangle = false;
    Vec3 triangle[3];
    ShaderGlobals offset(int k) const {
        ShaderGlobals s = *this;
        const Offset &d = bump[k];
        s.P = P + d.P, s.object = object + d.object, s.generated = generated + d.generated, s.uv = uv + d.uv;
        s.camera = camera + d.camera, s.window = window + d.window;
        return s;
    }
    Vec3 object_to_world_normal(Vec3 n) const {
        const float *m = normal_matrix;
        return {m[0] * n.x + m[1] * n.y + m[2] * n.z, m[3] * n.x + m[4] * n.y + m[5] * n.z,
                m[6] * n.x + m[7] * n.y + m[8] * n.z};
    }
};

enum class Global : int32_t {
    Position = 0, Normal, TrueNormal, Incoming, Object, ObjectNormal, Generated, UV, PointColour, PointAlpha,
    Reflection, Backfacing, Camera, Window, Parametric, Count
};

// The material inputs a program may drive (render/nodes.py OUTPUTS, same order).
enum class Output : int32_t {
    Base = 0, Metallic, Roughness, IOR, Transmission, Alpha, Emission, SpecularLevel, Normal, MetalColour, Count
};

enum class Op : int32_t {
    Global = 0,     // out, Global
    Copy,           // out, in, width
    Math,           // out, a, b, c, MathOp, clamp
    VectorMath,     // out_vector, out_value, a, b, c, scale, VectorOp
    MixFloat,       // out, fac, a, b, clamp_factor
    MixVector,      // out, fac, a, b, clamp_factor, non_uniform (fac is a vec3 then)
    MixColour,      // out, fac, a, b, Blend, clamp_factor, clamp_result
    MapRange,       // out, value, from_min (5 consecutive: from_min from_max to_min to_max steps), mode, clamp
    Clamp,          // out, value, min, max, mode (0 min-max, 1 range)
    Ramp,           // out_colour, out_alpha, fac, table, size, interpolate (tables of rgba rows over 0..1)
    HueSatVal,      // out, hue, saturation, value, fac, colour
    Invert,         // out, fac, colour
    BrightContrast, // out, colour, bright, contrast
    Gamma,          // out, colour, gamma
    RGBToBW,        // out, colour
    Combine,        // out, x, y, z  (three floats into a vec3)
    RGBToHSV,       // out, colour
    HSVToRGB,       // out, colour (h, s, v)
    Mapping,        // out, vector, location, rotation, scale, type (0 point, 1 texture, 2 vector, 3 normal)
    Checker,        // out_colour, out_fac, vector, colour1, colour2, scale
    Gradient,       // out_colour, out_fac, vector, type
    Fresnel,        // out, ior, normal
    LayerWeight,    // out_fresnel, out_facing, blend, normal
    Noise,          // out_fac, out_colour, vector, params (8: scale detail roughness lacunarity distortion w offset
                    // gain), dimensions (1-4), NoiseType, flags (1: normalize, 2: the Color output is read --
                    // otherwise not computed)
    WhiteNoise,     // out_value, out_colour, vector, dimensions (1-3: the vector's first components)
    Scale,          // out, vector, factor (vec3 x float)
    Curves,         // out, fac, colour, table, size (r g b combined tables; RGB Curves), range (min, max regs),
                    // extrapolate (1: beyond the range, on along the end rows' slope, as Cycles; 0: held)
    Image,          // out_colour, out_alpha, vector, image (index in images), ImageInterpolation, ImageExtension
    Voronoi,        // out (9: distance, colour, position, w, radius), vector, w, params (8: scale detail roughness
                    // lacunarity smoothness exponent randomness normalize), VoronoiMetric, VoronoiFeature,
                    // dimensions - 1 (nodes/voronoi.h)
    Wave,           // out_fac, vector, params (scale distortion detail detail_scale detail_roughness), phase, kind, profile
                    // (kind: 0-3 bands X Y Z diagonal, 4-7 rings X Y Z spherical)
    Magic,          // out_colour, out_fac, vector, scale, distortion, depth
    NormalMap,      // out, colour, strength, space (0 tangent, 1 object, 2 world)
    Brick,          // out_colour, out_fac, vector, colours (9: colour 1, colour 2, mortar), params (8: scale,
                    // mortar size, mortar smooth, bias, brick width, row height, offset, squash),
                    // offset frequency, squash frequency
    Blackbody,      // out, temperature (K)
    Bump,           // out, height, strength, distance, normal, first row of the height's instructions, invert
                    // (the rows from `first` up to this one compute the height: run again at the two
                    // offset points of ShaderGlobals::bump)
    Attribute,      // out_colour, out_fac, first (column of ShaderGlobals::attributes), width (1: float, 3: vector
                    // or colour): Cycles' Attribute node (a float fills the colour; Fac averages a vector)
    ImageProject,   // out, vector, kind: the vector to an image's (u, v, 0) -- 0 sphere, 1 tube (an Image
                    // Texture's projections: Cycles' map_to_sphere / map_to_tube of the vector in -1..1),
                    // 2 equirectangular, 3 mirror ball (an Environment Texture's, of the vector's direction)
    ImageBox,       // out_colour, out_alpha, vector, image, ImageInterpolation, ImageExtension, blend: the box
                    // projection, three lookups blended by the object-space normal (Cycles' tex_image_box)
    ImageTiles,     // out_colour, out_alpha, vector, table, count, ImageInterpolation, ImageExtension: a UDIM
                    // image, `count` rows (tile number, image index; index -1: not loaded) from `table`;
                    // the tile from the vector's integer part, magenta outside the tiles (as Cycles)
    Transform,      // out, vector, matrix (12 registers: a row-major 3x4 affine map), applied to the vector
                    // as a point (Texture Coordinate's Object output with another object chosen)
    VectorRotate,   // out, vector, center, axis, angle, rotation (Euler XYZ), kind + 5 x invert (kind: 0 axis-angle,
                    // 1-3 X Y Z axis, 4 Euler XYZ): Cycles' Vector Rotate
    RGBToHSL,       // out, colour
    HSLToRGB,       // out, colour (h, s, l)
    Wavelength,     // out, wavelength (nm): Cycles' Wavelength node, linear Rec. 709
    ObjectSpace,    // out, vector, kind + 3 x to_world (kind: 0 point, 1 vector, 2 normal): the vector between the
                    // render's frame and the shaded object's space (ShaderGlobals object, normal_matrix)
    VectorMapRange, // out, vector, params (15: from_min from_max to_min to_max steps, vec3 each), mode, clamp
    Gabor,          // out (3: value, phase, intensity), vector, params (4: scale frequency anisotropy orientation_2d),
                    // orientation_3d, dimensions (0: 2-D, 1: 3-D) (nodes/gabor.h)
    ObjectValue,    // out, first, width (1-4): ShaderGlobals::object_values[first, first + width) (Object Info,
                    // Attribute of type object / instancer / view layer); past object_value_count: 0
    LightPath,      // out (kLightPathFloats registers): ShaderGlobals::light_path
    Tangent,        // out, kind, vector: kind 0-2 radial about X Y Z of the generated coordinates, 3 the UV
                    // map's tangent, 4 the object-space tangent in `vector` (a named map's); the Tangent node
                    // and Geometry > Tangent (radial Z), as Cycles' svm_node_tangent
    AmbientOcclusion,  // out_colour, out_ao, colour, distance, normal, samples, flags (1 inside, 2 only local,
                    // 4 the world's distance: Distance 0 and unlinked):
                    // Cycles' AO node, `samples` cosine-distributed rays about the normal (ShadingQueries)
    Wireframe,      // out_fac, size, pixel_size (0 world units, 1 pixels): 1 within size / 2 of the mesh
                    // triangle's edges (Cycles' wireframe), 0 elsewhere and on point clouds
    Bevel,          // out, radius, normal, samples, normal_linked: Cycles' bevel normal from the surfaces of
                    // the point's own mesh within radius (ShadingQueries::local_hits)
    Count
};

// One AOV Output node (render/nodes.py Builder.aov): after the program runs, its Color
// (3 registers) and Value (1) are the shader AOV `key` -- an index into the scene's list of
// AOV names, mapped to the film's channels by the render (shade/aov.h).
struct AovWrite {
    int32_t key, colour, value;
};

struct NodeProgram {
    std::vector<int32_t> code;  // rows of kNodeWidth
    std::vector<float> data;    // initial registers
    int32_t outputs[int(Output::Count)];
    std::vector<AovWrite> aovs;  // AOV Output nodes (checked by validate)
    std::vector<std::shared_ptr<const TextureImage>> images;  // shared between programs of a scene
    bool uses_tangent = false;  // a Normal Map reads the UV map's tangent (set by validate)
    bool uses_camera = false;   // a Texture Coordinate reads the camera's space (set by validate)
    bool uses_window = false;   // a Texture Coordinate reads Window (set by validate)
    bool aov_only = false;      // drives no material input: runs only for its AOVs (set by validate)
    bool uses_bump = false;     // a Bump node needs ShaderGlobals::bump (set by validate)
    bool uses_light_path = false;  // a Light Path node reads ShaderGlobals::light_path (set by validate)
    bool uses_triangle = false;  // a Wireframe node reads ShaderGlobals::triangle (set by validate)
    std::string name;           // the material's, for errors

    // Checks every instruction's operands against the register file (and enumerations),
    // so that evaluation never reads or writes outside it; throws InputError naming the row.
    void validate();
    // Runs the program at one shading point; `r` holds data.size() floats and receives the
    // registers (the outputs are read from there).
    void run(const ShaderGlobals &sg, float *r) const;

  private:
    void run_rows(const ShaderGlobals &sg, float *r, size_t begin, size_t end) const;
};

// Blender's colour helpers, shared by the nodes and their tests.
Vec3 rgb_to_hsv(Vec3 rgb);
Vec3 hsv_to_rgb(Vec3 hsv);
// The Blackbody node's colour of a temperature in K: linear Rec. 709 of luminance 1 (as Cycles
// normalises it), negative channels clamped to 0, the temperature held within 800-12000 K.
Vec3 blackbody_rec709(float kelvin);

constexpr int kMaxBumpDepth = 3;  // Bump nodes inside a Bump's height: each level triples its cost
constexpr int kMaxAoSamples = 128;  // the Ambient Occlusion and Bevel nodes' Samples: Blender's limit (both)

}  // namespace splat
