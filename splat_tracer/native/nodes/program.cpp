// The shader-node interpreter. Node definitions follow Blender's manual and Cycles' SVM (read
// to learn them; this is a separate implementation): each case's comment names the node.
#include "nodes/program.h"
#include "nodes/voronoi.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "base/errors.h"
#include "nodes/noise.h"
#include "nodes/cie1931.h"
#include "nodes/gabor.h"
#include "nodes/raytrace.h"

namespace splat {

namespace {

constexpr float kPi = 3.14159265358979323846f;

// ----------------------------------------------------------------------------------------
// Operand kinds, per opcode, for validate(): a register of width 1 or 3, an enumeration
// below a bound, a table, or unused.
enum Kind : int8_t { kNone = 0, kR1, kR3, kR5, kEnum, kRW };  // kRW: `bound` consecutive registers
struct Layout {
    Kind kind[kNodeWidth - 1];
    int32_t bound[kNodeWidth - 1];  // kEnum: values 0..bound-1
};

// The Noise node's register block: NoiseParams, eight floats.
constexpr int32_t kNoiseParams = int32_t(sizeof(NoiseParams) / sizeof(float));
constexpr int kMathOps = 41, kVectorOps = 29, kBlends = 19;  // render/nodes.py MATH_OPS, VECTOR_OPS, BLENDS

const Layout &layout(Op op) {
    // Unsized, and counted below: a missing row would otherwise be a row of kNone, an
    // opcode whose operands go unchecked.
    static const Layout table[] = {
        /* Global */ {{kR3, kEnum}, {0, int32_t(Global::Count)}},
        /* Copy */ {{kR1, kR1, kEnum}, {0, 0, 4}},
        /* Math */ {{kR1, kR1, kR1, kR1, kEnum, kEnum}, {0, 0, 0, 0, kMathOps, 2}},
        /* VectorMath */ {{kR3, kR1, kR3, kR3, kR3, kR1, kEnum}, {0, 0, 0, 0, 0, 0, kVectorOps}},
        /* MixFloat */ {{kR1, kR1, kR1, kR1, kEnum}, {0, 0, 0, 0, 2}},
        /* MixVector */ {{kR3, kR3, kR3, kR3, kEnum, kEnum}, {0, 0, 0, 0, 2, 2}},
        /* MixColour */ {{kR3, kR1, kR3, kR3, kEnum, kEnum, kEnum}, {0, 0, 0, 0, kBlends, 2, 2}},
        /* MapRange */ {{kR1, kR1, kR5, kEnum, kEnum}, {0, 0, 0, 4, 2}},
        /* Clamp */ {{kR1, kR1, kR1, kR1, kEnum}, {0, 0, 0, 0, 2}},
        /* Ramp (checked apart) */ {{kR3, kR1, kR1, kNone, kNone, kEnum}, {0, 0, 0, 0, 0, 2}},
        /* HueSatVal */ {{kR3, kR1, kR1, kR1, kR1, kR3}, {}},
        /* Invert */ {{kR3, kR1, kR3}, {}},
        /* BrightContrast */ {{kR3, kR3, kR1, kR1}, {}},
        /* Gamma */ {{kR3, kR3, kR1}, {}},
        /* RGBToBW */ {{kR1, kR3}, {}},
        /* Combine */ {{kR3, kR1, kR1, kR1}, {}},
        /* RGBToHSV */ {{kR3, kR3}, {}},
        /* HSVToRGB */ {{kR3, kR3}, {}},
        /* Mapping */ {{kR3, kR3, kR3, kR3, kR3, kEnum}, {0, 0, 0, 0, 0, 4}},
        /* Checker */ {{kR3, kR1, kR3, kR3, kR3, kR1}, {}},
        /* Gradient */ {{kR3, kR1, kR3, kEnum}, {0, 0, 0, 7}},
        /* Fresnel */ {{kR1, kR1, kR3}, {}},
        /* LayerWeight */ {{kR1, kR1, kR1, kR3}, {}},
        /* Noise (dimensions 1-4) */
        {{kR1, kR3, kR3, kRW, kEnum, kEnum, kEnum}, {0, 0, 0, kNoiseParams, 5, int32_t(NoiseType::Count), 4}},
        /* WhiteNoise */ {{kR1, kR3, kR3, kEnum}, {0, 0, 0, 4}},
        /* Scale */ {{kR3, kR3, kR1}, {}},
        /* Curves (checked apart) */ {{kR3, kR1, kR3, kNone, kNone, kR1, kEnum}, {0, 0, 0, 0, 0, 0, 2}},
        /* Image (image checked apart) */
        {{kR3, kR1, kR3, kNone, kEnum, kEnum}, {0, 0, 0, 0, int32_t(ImageInterpolation::Count),
                                                int32_t(ImageExtension::Count)}},
        /* Voronoi */
        {{kRW, kR3, kR1, kRW, kEnum, kEnum, kEnum},
         {9, 0, 0, 8, int32_t(VoronoiMetric::Count), int32_t(VoronoiFeature::Count), 4}},
        /* Wave */ {{kR1, kR3, kR5, kR1, kEnum, kEnum}, {0, 0, 0, 0, 8, 3}},
        /* Magic */ {{kR3, kR1, kR3, kR1, kR1, kEnum}, {0, 0, 0, 0, 0, 11}},
        /* NormalMap */ {{kR3, kR3, kR1, kEnum}, {0, 0, 0, 3}},
        /* Brick */ {{kR3, kR1, kR3, kRW, kRW, kEnum, kEnum}, {0, 0, 0, 9, 8, 100, 100}},
        /* Blackbody */ {{kR3, kR1}, {}},
        /* Bump (first row checked apart) */ {{kR3, kR1, kR1, kR1, kR3, kNone, kEnum}, {0, 0, 0, 0, 0, 0, 2}},
        /* Attribute (width checked apart; column kMaxPointAttributes: never carried, reads 0) */
        {{kR3, kR1, kEnum, kEnum}, {0, 0, kMaxPointAttributes + 1, 4}},
        /* ImageProject */ {{kR3, kR3, kEnum}, {0, 0, 4}},
        /* ImageBox (image checked apart) */
        {{kR3, kR1, kR3, kNone, kEnum, kEnum, kR1}, {0, 0, 0, 0, int32_t(ImageInterpolation::Count),
                                                     int32_t(ImageExtension::Count)}},
        /* ImageTiles (table checked apart; image indices at run time) */
        {{kR3, kR1, kR3, kNone, kNone, kEnum, kEnum}, {0, 0, 0, 0, 0, int32_t(ImageInterpolation::Count),
                                                       int32_t(ImageExtension::Count)}},
        /* Transform */ {{kR3, kR3, kRW}, {0, 0, 12}},
        /* VectorRotate */ {{kR3, kR3, kR3, kR3, kR1, kR3, kEnum}, {0, 0, 0, 0, 0, 0, 10}},
        /* RGBToHSL */ {{kR3, kR3}, {}},
        /* HSLToRGB */ {{kR3, kR3}, {}},
        /* Wavelength */ {{kR3, kR1}, {}},
        /* ObjectSpace */ {{kR3, kR3, kEnum}, {0, 0, 6}},
        /* VectorMapRange */ {{kR3, kR3, kRW, kEnum, kEnum}, {0, 0, 15, 4, 2}},
        /* Gabor */ {{kR3, kR3, kRW, kR3, kEnum}, {0, 0, 4, 0, 2}},
        /* ObjectValue (the output's width checked apart; first kMaxObjectValues: never carried, 0) */ {{kNone, kEnum, kEnum}, {0, kMaxObjectValues + 1, 5}},
        /* LightPath */ {{kRW}, {kLightPathFloats}},
        /* Tangent */ {{kR3, kEnum, kR3}, {0, 5}},
        /* AmbientOcclusion */ {{kR3, kR1, kR3, kR1, kR3, kEnum, kEnum}, {0, 0, 0, 0, 0, kMaxAoSamples + 1, 8}},
        /* Wireframe */ {{kR1, kR1, kEnum}, {0, 0, 2}},
        /* Bevel */ {{kR3, kR1, kR3, kEnum, kEnum}, {0, 0, 0, kMaxAoSamples + 1, 2}},
    };
    static_assert(sizeof(table) / sizeof(table[0]) == size_t(Op::Count), "one operand layout per opcode, in Op order");
    return table[int(op)];
}

// The Tangent node (Geometry > Tangent: kind 2), as Cycles' svm_node_tangent: kinds 0-2 the
// direction around the X, Y or Z axis through the middle of the generated coordinates,
// taken from object space as a normal is and made perpendicular to the shading normal; kind
// 3 the UV map's tangent (already perpendicular to it), 0 without a UV map; 4 the object-space
// tangent `given` (a named UV map's), 0 where it is 0 (a geometry without that map).
Vec3 tangent(const ShaderGlobals &sg, int32_t kind, Vec3 given) {
    if (kind == 3) return sg.tangent;
    const Vec3 g = sg.generated - Vec3(0.5f, 0.5f, 0.5f);
    const Vec3 t = kind == 4 ? given
                   : kind == 0 ? Vec3(0.f, -g.z, g.y)
                   : kind == 1 ? Vec3(-g.z, 0.f, g.x)
                               : Vec3(-g.y, g.x, 0.f);
    const Vec3 side = cross(sg.object_to_world_normal(t), sg.N);
    const float len = length(side);
    if (!(len > 0.f)) return Vec3();  // on the axis or along the normal: no direction (Cycles' safe 0)
    return cross(sg.N, side * (1.f / len));
}

inline float saturate(float x) { return std::fmin(std::fmax(x, 0.f), 1.f); }
inline float lerp(float a, float b, float t) { return (1.f - t) * a + t * b; }
inline Vec3 lerp(Vec3 a, Vec3 b, float t) { return a * (1.f - t) + b * t; }
inline Vec3 load3(const float *r, int32_t i) { return {r[i], r[i + 1], r[i + 2]}; }
inline void store3(float *r, int32_t i, Vec3 v) { r[i] = v.x, r[i + 1] = v.y, r[i + 2] = v.z; }
inline float fract(float x) { return x - std::floor(x); }
inline float safe_divide(float a, float b) { return b != 0.f ? a / b : 0.f; }
inline Vec3 vsaturate(Vec3 v) { return {saturate(v.x), saturate(v.y), saturate(v.z)}; }

// Rec. 709 luminance: the scene-linear colour space's Y (Blender's default, and Cycles'
// rgb_to_y for it) -- RGB to BW and colour-to-float conversions.
inline float luma(Vec3 c) { return 0.2126729f * c.x + 0.7151522f * c.y + 0.0721750f * c.z; }

// ----------------------------------------------------------------------------------------
// Math node (Blender's operations, in render/nodes.py MATH_OPS order).

float wrap(float value, float max, float min) {
    const float range = max - min;
    return range != 0.f ? value - range * std::floor((value - min) / range) : min;
}
float pingpong(float a, float b) { return b != 0.f ? std::fabs(fract((a - b) / (b * 2.f)) * b * 2.f - b) : 0.f; }
float smooth_min(float a, float b, float k) {
    if (k == 0.f) return std::fmin(a, b);
    const float h = std::fmax(k - std::fabs(a - b), 0.f) / k;
    return std::fmin(a, b) - h * h * h * k * (1.f / 6.f);
}

float math(int op, float a, float b, float c) {
    switch (op) {
        case 0: return a + b;                                           // ADD
        case 1: return a - b;                                           // SUBTRACT
        case 2: return a * b;                                           // MULTIPLY
        case 3: return safe_divide(a, b);                               // DIVIDE
        case 4: return a * b + c;                                       // MULTIPLY_ADD
        case 5:                                                         // POWER
            if (a >= 0.f) return std::pow(a, b);
            return std::fmod(b, 1.f) == 0.f ? std::pow(a, b) : 0.f;    // a real result only
        case 6: return (a > 0.f && b > 0.f) ? safe_divide(std::log(a), std::log(b)) : 0.f;  // LOGARITHM
        case 7: return a > 0.f ? std::sqrt(a) : 0.f;                    // SQRT
        case 8: return a > 0.f ? 1.f / std::sqrt(a) : 0.f;              // INVERSE_SQRT
        case 9: return std::fabs(a);                                    // ABSOLUTE
        case 10: return std::exp(a);                                    // EXPONENT
        case 11: return std::fmin(a, b);                                // MINIMUM
        case 12: return std::fmax(a, b);                                // MAXIMUM
        case 13: return a < b ? 1.f : 0.f;                              // LESS_THAN
        case 14: return a > b ? 1.f : 0.f;                              // GREATER_THAN
        case 15: return a > 0.f ? 1.f : a < 0.f ? -1.f : 0.f;           // SIGN
        case 16: return std::fabs(a - b) <= std::fmax(c, 1e-5f) ? 1.f : 0.f;  // COMPARE (epsilon at least Blender's)
        case 17: return smooth_min(a, b, c);                            // SMOOTH_MIN
        case 18: return -smooth_min(-a, -b, c);                         // SMOOTH_MAX
        case 19: return std::floor(a + 0.5f);                           // ROUND
        case 20: return std::floor(a);                                  // FLOOR
        case 21: return std::ceil(a);                                   // CEIL
        case 22: return std::trunc(a);                                  // TRUNCATE
        case 23: return a - std::floor(a);                              // FRACT
        case 24: return b != 0.f ? std::fmod(a, b) : 0.f;               // MODULO (truncated)
        case 25: return b != 0.f ? a - std::floor(a / b) * b : 0.f;    // FLOORED_MODULO
        case 26: return wrap(a, b, c);                                  // WRAP (value, max, min)
        case 27: return std::floor(safe_divide(a, b)) * b;              // SNAP
        case 28: return pingpong(a, b);                                 // PINGPONG
        case 29: return std::sin(a);                                    // SINE
        case 30: return std::cos(a);                                    // COSINE
        case 31: return std::tan(a);                                    // TANGENT
        case 32: return std::asin(std::fmin(std::fmax(a, -1.f), 1.f));  // ARCSINE (clamped input)
        case 33: return std::acos(std::fmin(std::fmax(a, -1.f), 1.f));  // ARCCOSINE
        case 34: return std::atan(a);                                   // ARCTANGENT
        case 35: return std::atan2(a, b);                               // ARCTAN2
        case 36: return std::sinh(a);                                   // SINH
        case 37: return std::cosh(a);                                   // COSH
        case 38: return std::tanh(a);                                   // TANH
        case 39: return a * (kPi / 180.f);                              // RADIANS
        default: return a * (180.f / kPi);                              // DEGREES
    }
}

// ----------------------------------------------------------------------------------------
// Vector Math node (render/nodes.py VECTOR_OPS order); value: the float output.

Vec3 vfloor(Vec3 a) { return {std::floor(a.x), std::floor(a.y), std::floor(a.z)}; }

void vector_math(int op, Vec3 a, Vec3 b, Vec3 c, float s, Vec3 *v, float *f) {
    *v = Vec3(), *f = 0.f;
    switch (op) {
        case 0: *v = a + b; break;                                       // ADD
        case 1: *v = a - b; break;                                       // SUBTRACT
        case 2: *v = a * b; break;                                       // MULTIPLY
        case 3: *v = {safe_divide(a.x, b.x), safe_divide(a.y, b.y), safe_divide(a.z, b.z)}; break;  // DIVIDE
        case 4: *v = a * b + c; break;                                   // MULTIPLY_ADD
        case 5: *v = cross(a, b); break;                                 // CROSS_PRODUCT
        case 6: {                                                        // PROJECT (a onto b)
            const float bb = dot(b, b);
            *v = bb != 0.f ? b * (dot(a, b) / bb) : Vec3();
            break;
        }
        case 7: {                                                        // REFLECT (a about the normal b)
            const Vec3 n = normalize(b);
            *v = a - n * (2.f * dot(n, a));
            break;
        }
        case 8: {                                                        // REFREACT (a through normal b, eta s)
            const Vec3 n = normalize(b);
            const float d = dot(n, a), k = 1.f - s * s * (1.f - d * d);
            *v = k < 0.f ? Vec3() : a * s - n * (s * d + std::sqrt(k));
            break;
        }
        case 9: *v = dot(c, b) < 0.f ? a : a * -1.f; break;             // FACEFORWARD (a, incident b, reference c)
        case 10: *f = dot(a, b); break;                                  // DOT_PRODUCT
        case 11: *f = length(a - b); break;                              // DISTANCE
        case 12: *f = length(a); break;                                  // LENGTH
        case 13: *v = a * s; break;                                      // SCALE
        case 14: *v = normalize(a); break;                               // NORMALIZE
        case 15: *v = vabs(a); break;                                    // ABSOLUTE
        case 16:                                                         // POWER (per component, as Math)
            *v = {math(5, a.x, b.x, 0), math(5, a.y, b.y, 0), math(5, a.z, b.z, 0)};
            break;
        case 17: *v = {math(15, a.x, 0, 0), math(15, a.y, 0, 0), math(15, a.z, 0, 0)}; break;  // SIGN
        case 18: *v = vmin(a, b); break;                                 // MINIMUM
        case 19: *v = vmax(a, b); break;                                 // MAXIMUM
        case 20: *v = vfloor(a); break;                                  // FLOOR
        case 21: *v = {std::ceil(a.x), std::ceil(a.y), std::ceil(a.z)}; break;  // CEIL
        case 22: *v = a - vfloor(a); break;                              // FRACTION
        case 23: *v = {math(24, a.x, b.x, 0), math(24, a.y, b.y, 0), math(24, a.z, b.z, 0)}; break;  // MODULO
        case 24: *v = {wrap(a.x, b.x, c.x), wrap(a.y, b.y, c.y), wrap(a.z, b.z, c.z)}; break;  // WRAP
        case 25: *v = {math(27, a.x, b.x, 0), math(27, a.y, b.y, 0), math(27, a.z, b.z, 0)}; break;  // SNAP
        default: {                                                       // SINE, COSINE, TANGENT
            const int m = 29 + (op - 26);
            *v = {math(m, a.x, 0, 0), math(m, a.y, 0, 0), math(m, a.z, 0, 0)};
        }
    }
}

// ----------------------------------------------------------------------------------------
// Mix node's colour blend modes (render/nodes.py BLENDS order), factor t.

Vec3 blend(int mode, float t, Vec3 a, Vec3 b) {
    const float tm = 1.f - t;
    switch (mode) {
        case 0: return lerp(a, b, t);                                    // MIX
        case 1: return lerp(a, vmin(a, b), t);                           // DARKEN
        case 2: return lerp(a, a * b, t);                                // MULTIPLY
        case 3: {                                                        // BURN
            Vec3 o = a;
            for (int i = 0; i < 3; ++i) {
                const float tmp = tm + t * b[i];
                o[i] = tmp <= 0.f ? 0.f : saturate(1.f - (1.f - a[i]) / tmp);
            }
            return o;
        }
        case 4: return lerp(a, vmax(a, b), t);                           // LIGHTEN
        case 5: {                                                        // SCREEN
            Vec3 o;
            for (int i = 0; i < 3; ++i) o[i] = 1.f - (tm + t * (1.f - b[i])) * (1.f - a[i]);
            return o;
        }
        case 6: {                                                        // DODGE
            Vec3 o = a;
            for (int i = 0; i < 3; ++i)
                if (a[i] != 0.f) {
                    const float tmp = 1.f - t * b[i];
                    o[i] = tmp <= 0.f ? 1.f : std::fmin(a[i] / tmp, 1.f);
                }
            return o;
        }
        case 7: return a + b * t;                                        // ADD
        case 8: {                                                        // OVERLAY
            Vec3 o;
            for (int i = 0; i < 3; ++i)
                o[i] = a[i] < 0.5f ? a[i] * (tm + 2.f * t * b[i]) : 1.f - (tm + 2.f * t * (1.f - b[i])) * (1.f - a[i]);
            return o;
        }
        case 9: {                                                        // SOFT_LIGHT
            const Vec3 one(1, 1, 1);
            const Vec3 screen = one - (one - b) * (one - a);
            return a * tm + ((one - a) * b * a + a * screen) * t;
        }
        case 10: return a + (b * 2.f - Vec3(1, 1, 1)) * t;               // LINEAR_LIGHT
        case 11: return lerp(a, vabs(a - b), t);                         // DIFFERENCE
        case 12: return vmax(lerp(a, a + b - a * b * 2.f, t), Vec3());   // EXCLUSION
        case 13: return a - b * t;                                       // SUBTRACT
        case 14: {                                                       // DIVIDE
            Vec3 o = a;
            for (int i = 0; i < 3; ++i)
                if (b[i] != 0.f) o[i] = tm * a[i] + t * a[i] / b[i];
            return o;
        }
        case 15: {                                                       // HUE
            const Vec3 h2 = rgb_to_hsv(b);
            if (h2.y == 0.f) return a;
            Vec3 h = rgb_to_hsv(a);
            h.x = h2.x;
            return lerp(a, hsv_to_rgb(h), t);
        }
        case 16: {                                                       // SATURATION
            Vec3 h = rgb_to_hsv(a);
            if (h.y == 0.f) return a;
            h.y = tm * h.y + t * rgb_to_hsv(b).y;
            return hsv_to_rgb(h);
        }
        case 17: {                                                       // COLOR
            const Vec3 h2 = rgb_to_hsv(b);
            if (h2.y == 0.f) return a;
            Vec3 h = rgb_to_hsv(a);
            h.x = h2.x, h.y = h2.y;
            return lerp(a, hsv_to_rgb(h), t);
        }
        default: {                                                       // VALUE
            Vec3 h = rgb_to_hsv(a);
            h.z = tm * h.z + t * rgb_to_hsv(b).z;
            return hsv_to_rgb(h);
        }
    }
}

// ----------------------------------------------------------------------------------------
// Map Range, Mapping, Fresnel.

float smoothstep(float e0, float e1, float x) {
    if (x < e0) return 0.f;
    if (x >= e1) return 1.f;
    const float t = (x - e0) / (e1 - e0);
    return t * t * (3.f - 2.f * t);
}
float smootherstep(float e0, float e1, float x) {
    const float t = saturate((x - e0) / (e1 - e0));
    return t * t * t * (t * (t * 6.f - 15.f) + 10.f);
}

float map_range(float v, const float *p, int mode, bool clamp) {
    const float from_min = p[0], from_max = p[1], to_min = p[2], to_max = p[3], steps = p[4];
    if (from_max == from_min) return 0.f;
    float f = (v - from_min) / (from_max - from_min);
    if (mode == 1) f = steps > 0.f ? std::floor(f * (steps + 1.f)) / steps : 0.f;
    else if (mode == 2)
        f = from_min > from_max ? 1.f - smoothstep(from_max, from_min, v) : smoothstep(from_min, from_max, v);
    else if (mode == 3)
        f = from_min > from_max ? 1.f - smootherstep(from_max, from_min, v) : smootherstep(from_min, from_max, v);
    float result = to_min + f * (to_max - to_min);
    if (clamp && mode <= 1)
        result = to_max > to_min ? std::fmin(std::fmax(result, to_min), to_max)
                                 : std::fmin(std::fmax(result, to_max), to_min);
    return result;
}

// Euler XYZ rotation (Blender's: X first, then Y, then Z), and its inverse.
Vec3 rotate_xyz(Vec3 v, Vec3 e, bool inverse) {
    const float cx = std::cos(e.x), sx = std::sin(e.x), cy = std::cos(e.y), sy = std::sin(e.y), cz = std::cos(e.z),
                sz = std::sin(e.z);
    // R = Rz Ry Rx, rows:
    const float m[9] = {cy * cz, sy * sx * cz - cx * sz, sy * cx * cz + sx * sz,
                        cy * sz, sy * sx * sz + cx * cz, sy * cx * sz - sx * cz,
                        -sy,     cy * sx,                cy * cx};
    if (inverse)
        return {m[0] * v.x + m[3] * v.y + m[6] * v.z, m[1] * v.x + m[4] * v.y + m[7] * v.z,
                m[2] * v.x + m[5] * v.y + m[8] * v.z};
    return {m[0] * v.x + m[1] * v.y + m[2] * v.z, m[3] * v.x + m[4] * v.y + m[5] * v.z,
            m[6] * v.x + m[7] * v.y + m[8] * v.z};
}

Vec3 mapping(int type, Vec3 v, Vec3 loc, Vec3 rot, Vec3 scale) {
    switch (type) {
        case 0: return rotate_xyz(v * scale, rot, false) + loc;                 // POINT
        case 1: {                                                               // TEXTURE (the inverse of POINT)
            const Vec3 r = rotate_xyz(v - loc, rot, true);
            return {safe_divide(r.x, scale.x), safe_divide(r.y, scale.y), safe_divide(r.z, scale.z)};
        }
        case 2: return rotate_xyz(v * scale, rot, false);                       // VECTOR
        default:                                                                // NORMAL
            return normalize(rotate_xyz({safe_divide(v.x, scale.x), safe_divide(v.y, scale.y),
                                         safe_divide(v.z, scale.z)}, rot, false));
    }
}

// Fresnel reflectance of a dielectric for cos of the incidence and relative IOR eta.
float fresnel_cos(float cosi, float eta) {
    const float c = std::fabs(cosi);
    float g = eta * eta - 1.f + c * c;
    if (g <= 0.f) return 1.f;  // total internal reflection
    g = std::sqrt(g);
    const float a = (g - c) / (g + c), b = (c * (g + c) - 1.f) / (c * (g - c) + 1.f);
    return 0.5f * a * a * (1.f + b * b);
}

// ----------------------------------------------------------------------------------------
// Textures.

float checker(Vec3 p) {
    // Nudged as Blender does, so that integer coordinates (a plane at z = 0) fall on one
    // side of the cell boundary the same way in both renderers.
    auto cell = [](float x) { return std::abs(int(std::floor((x + 0.000001f) * 0.999999f))) % 2; };
    return ((cell(p.x) == cell(p.y)) == (cell(p.z) == 1)) ? 1.f : 0.f;
}

float gradient(Vec3 p, int type) {
    switch (type) {
        case 0: return p.x;                                                     // LINEAR
        case 1: { const float r = std::fmax(p.x, 0.f); return r * r; }          // QUADRATIC
        case 2: { const float r = saturate(p.x), t = r * r; return 3.f * t - 2.f * t * r; }  // EASING
        case 3: return (p.x + p.y) * 0.5f;                                      // DIAGONAL
        case 4: return std::atan2(p.y, p.x) / (2.f * kPi) + 0.5f;               // RADIAL
        case 5: { const float r = std::fmax(0.999999f - length(p), 0.f); return r * r; }  // QUADRATIC_SPHERE
        default: return std::fmax(0.999999f - length(p), 0.f);                  // SPHERICAL
    }
}

float white_noise(Vec3 p, int dims, Vec3 *colour) {
    const uint32_t x = float_bits(p.x), y = float_bits(p.y), z = float_bits(p.z);
    auto hash = [&](uint32_t extra) {  // the vector, then one more word for each colour channel
        if (dims == 1) return extra ? hash_words(2, x, extra, 0) : hash_words(1, x, 0, 0);
        if (dims == 2) return extra ? hash_words(3, x, y, extra) : hash_words(2, x, y, 0);
        return extra ? hash_uint4(x, y, z, extra) : hash_words(3, x, y, z);
    };
    // Blender's colour: the value, then the vector with 1 and 2 appended as one more word.
    const float value = to_unit(hash(0));
    *colour = {value, to_unit(hash(float_bits(1.f))), to_unit(hash(float_bits(2.f)))};
    return value;
}

float wave(Vec3 p, const float *q, float phase, int kind, int profile) {
    // q: scale (applied by the caller), distortion, detail, detail scale, detail roughness.
    p = (p + Vec3(0.000001f, 0.000001f, 0.000001f)) * 0.999999f;  // Blender's nudge off unit coordinates
    float n;
    if (kind < 4) {
        n = kind == 0 ? p.x * 20.f : kind == 1 ? p.y * 20.f : kind == 2 ? p.z * 20.f : (p.x + p.y + p.z) * 10.f;
    } else {
        Vec3 r = p;
        if (kind == 4) r.x = 0.f;
        else if (kind == 5) r.y = 0.f;
        else if (kind == 6) r.z = 0.f;
        n = length(r) * 20.f;
    }
    n += phase;
    if (q[1] != 0.f)
        n += q[1] * (noise_fbm(p * q[3], std::fmin(std::fmax(q[2], 0.f), 15.f), std::fmax(q[4], 0.f), 2.f, true) * 2.f - 1.f);
    if (profile == 0) return 0.5f + 0.5f * std::sin(n - 0.5f * kPi);  // SIN
    n /= 2.f * kPi;
    if (profile == 1) return n - std::floor(n);                       // SAW
    return std::fabs(n - std::floor(n + 0.5f));                       // TRI
}

Vec3 magic(Vec3 p, int depth, float distortion) {
    float x = std::sin((p.x + p.y + p.z) * 5.f);
    float y = std::cos((-p.x + p.y - p.z) * 5.f);
    float z = -std::cos((-p.x - p.y + p.z) * 5.f);
    const float d = distortion;
    if (depth > 0) {
        x *= d, y *= d, z *= d;
        y = -std::cos(x - y + z) * d;
        if (depth > 1) {
            x = std::cos(x - y - z) * d;
            if (depth > 2) {
                z = std::sin(-x - y - z) * d;
                if (depth > 3) {
                    x = -std::cos(-x + y - z) * d;
                    if (depth > 4) {
                        y = -std::sin(-x + y + z) * d;
                        if (depth > 5) {
                            y = -std::cos(-x + y + z) * d;
                            if (depth > 6) {
                                x = std::cos(x + y + z) * d;
                                if (depth > 7) {
                                    z = std::sin(x + y - z) * d;
                                    if (depth > 8) {
                                        x = -std::cos(-x - y + z) * d;
                                        if (depth > 9) y = -std::sin(x - y + z) * d;
                                    }
                                }
                            }
                        }
                    }
                }
            }
        }
    }
    if (d != 0.f) x /= 2.f * d, y /= 2.f * d, z /= 2.f * d;
    return {0.5f - x, 0.5f - y, 0.5f - z};
}

// Blender's integer noise for a brick's tint (0..1).
float brick_noise(uint32_t n) {
    n = (n + 1013u) & 0x7fffffffu;
    n = (n >> 13) ^ n;
    const uint32_t nn = (n * (n * n * 60493u + 19990303u) + 1376312589u) & 0x7fffffffu;
    return 0.5f * (float(nn) / 1073741824.f);
}

// Blender's Brick texture at p (already scaled): (tint, mortar) per its definition.
void brick(Vec3 p, const float *q, int offset_frequency, int squash_frequency, float *tint, float *mortar) {
    const float mortar_size = q[1], mortar_smooth = q[2], bias = q[3], row_height = q[5];
    float brick_width = q[4];
    const float offset_amount = q[6], squash_amount = q[7];
    const int row = int(std::floor(p.y / row_height));
    float offset = 0.f;
    if (offset_frequency && squash_frequency) {
        brick_width *= (row % squash_frequency) ? 1.f : squash_amount;
        offset = (row % offset_frequency) ? 0.f : brick_width * offset_amount;
    }
    const int column = int(std::floor((p.x + offset) / brick_width));
    const float x = (p.x + offset) - brick_width * float(column), y = p.y - row_height * float(row);
    *tint = saturate(brick_noise((uint32_t(row) << 16) + (uint32_t(column) & 0xFFFFu)) + bias);
    float d = std::fmin(std::fmin(x, y), std::fmin(brick_width - x, row_height - y));
    if (d >= mortar_size) {
        *mortar = 0.f;
    } else if (mortar_smooth == 0.f) {
        *mortar = 1.f;
    } else {
        d = 1.f - d / mortar_size;
        const float t = saturate(d / mortar_smooth);
        *mortar = t * t * (3.f - 2.f * t);
    }
}

// Planck's law weighted by the CIE 1931 2-degree observer's tabulated colour-matching
// functions (cie1931.h, 5 nm steps), in linear Rec. 709 (its XYZ matrix, D65 white) scaled
// to luminance 1; before the clamp of negative channels. This is the definition Blender's
// blackbody is a fit of (within 0.4 % per channel over 800-12000 K, measured: docs/nodes.md).
Vec3 planck_rec709(double kelvin) {
    constexpr double kC2 = 1.438776877e-2;  // second radiation constant h c / k (m K)
    double xyz[3] = {0, 0, 0};
    for (int i = 0; i < kCieRows; ++i) {
        const double l = (kCieFirstNm + kCieStepNm * i) * 1e-9;
        const double radiance = 1.0 / (l * l * l * l * l * std::expm1(kC2 / (l * kelvin)));
        for (int k = 0; k < 3; ++k) xyz[k] += radiance * kCie1931[i][k];
    }
    const double x = xyz[0] / xyz[1], z = xyz[2] / xyz[1];
    return {float(3.2404542 * x - 1.5371385 - 0.4985314 * z), float(-0.9692660 * x + 1.8760108 + 0.0415560 * z),
            float(0.0556434 * x - 0.2040259 + 1.0572252 * z)};
}

}  // namespace

Vec3 blackbody_rec709(float kelvin) {
    // Cycles' range: below 800 K and above 12000 K its colour holds.
    constexpr float kLow = 800.f, kHigh = 12000.f;
    constexpr int kRows = 512;  // over 1/T, where the colour varies smoothly: interpolation error < 1e-4
    struct Table {
        Vec3 rows[kRows];
        Table() {
            for (int i = 0; i < kRows; ++i) {
                const double inv = 1.0 / kHigh + (1.0 / kLow - 1.0 / kHigh) * i / (kRows - 1);
                rows[i] = planck_rec709(1.0 / inv);
            }
        }
    };
    static const Table table;  // built once, thread-safe (C++11 static initialisation)
    if (!(kelvin == kelvin)) kelvin = kLow;  // NaN
    kelvin = std::fmin(std::fmax(kelvin, kLow), kHigh);
    const float f = (1.f / kelvin - 1.f / kHigh) / (1.f / kLow - 1.f / kHigh) * float(kRows - 1);
    const int i = std::min(std::max(int(f), 0), kRows - 2);
    const Vec3 c = lerp(table.rows[i], table.rows[i + 1], std::fmin(std::fmax(f - float(i), 0.f), 1.f));
    return vmax(c, Vec3());
}

Vec3 rgb_to_hsv(Vec3 rgb) {
    const float cmax = std::fmax(rgb.x, std::fmax(rgb.y, rgb.z));
    const float cmin = std::fmin(rgb.x, std::fmin(rgb.y, rgb.z));
    const float delta = cmax - cmin;
    const float s = cmax != 0.f ? delta / cmax : 0.f;
    float h = 0.f;
    if (s != 0.f) {
        const Vec3 c = (Vec3(cmax, cmax, cmax) - rgb) * (1.f / delta);
        if (rgb.x == cmax) h = c.z - c.y;
        else if (rgb.y == cmax) h = 2.f + c.x - c.z;
        else h = 4.f + c.y - c.x;
        h /= 6.f;
        if (h < 0.f) h += 1.f;
    }
    return {h, s, cmax};
}

Vec3 hsv_to_rgb(Vec3 hsv) {
    float h = hsv.x;
    const float s = hsv.y, v = hsv.z;
    if (s == 0.f) return {v, v, v};
    if (h == 1.f) h = 0.f;
    h *= 6.f;
    const float i = std::floor(h), f = h - i;
    const float p = v * (1.f - s), q = v * (1.f - s * f), t = v * (1.f - s * (1.f - f));
    switch (int(i)) {
        case 0: return {v, t, p};
        case 1: return {q, v, p};
        case 2: return {p, v, t};
        case 3: return {p, q, v};
        case 4: return {t, p, v};
        default: return {v, p, q};
    }
}

void NodeProgram::validate() {
    const int64_t n = int64_t(data.size());
    if (code.size() % kNodeWidth) throw InputError(name + ": node code is not whole instructions");
    if (n > kMaxNodeRegisters) throw InputError(name + ": node program has too many registers");
    std::vector<int> bump_depth(code.size() / kNodeWidth, 0);
    for (size_t row = 0; row < code.size() / kNodeWidth; ++row) {
        const int32_t *c = &code[row * kNodeWidth];
        auto fail = [&](const char *what) {
            throw InputError(name + ": node instruction " + std::to_string(row) + ": " + what);
        };
        if (c[0] < 0 || c[0] >= int32_t(Op::Count)) fail("unknown opcode");
        const Op op = Op(c[0]);
        const Layout &l = layout(op);
        for (int k = 0; k < kNodeWidth - 1; ++k) {
            const int32_t v = c[k + 1];
            const int width = l.kind[k] == kR1   ? 1
                              : l.kind[k] == kR3 ? 3
                              : l.kind[k] == kR5 ? 5
                              : l.kind[k] == kRW ? l.bound[k]
                                                 : 0;
            if (width && (v < 0 || int64_t(v) + width > n)) fail("register out of range");
            if (l.kind[k] == kEnum && (v < 0 || v >= l.bound[k])) fail("value out of range");
        }
        if (op == Op::Copy && int64_t(c[2]) + c[3] > n) fail("copy out of range");
        if (op == Op::Copy && int64_t(c[1]) + c[3] > n) fail("copy out of range");
        if (op == Op::Ramp && (c[5] < 2 || c[4] < 0 || int64_t(c[4]) + 4 * int64_t(c[5]) > n)) fail("bad ramp table");
        if (op == Op::NormalMap || (op == Op::Tangent && c[2] == 3)) uses_tangent = true;
        if (op == Op::Attribute && (c[4] != 1 && c[4] != 3)) fail("attribute width must be 1 or 3");
        // Noise keeps the dimension count itself (Voronoi keeps it less one): 0 is no count.
        if (op == Op::Noise && c[5] < 1) fail("noise dimensions must be 1 to 4");
        if (op == Op::Bump) {
            // The height's rows come before the Bump's, and any Bump among them keeps its own
            // rows inside them: ranges nest, at most kMaxBumpDepth deep (each level costs 3x).
            if (c[6] < 0 || size_t(c[6]) > row) fail("bump rows out of range");
            int depth = 1;
            for (size_t inner = size_t(c[6]); inner < row; ++inner) {
                const int32_t *d = &code[inner * kNodeWidth];
                if (d[0] != int32_t(Op::Bump)) continue;
                if (d[6] < c[6]) fail("bump rows overlap");
                depth = std::max(depth, bump_depth[inner] + 1);
            }
            if (depth > kMaxBumpDepth) fail("bump nodes nested too deep");
            bump_depth[row] = depth;
            uses_bump = true;
        }
        if (op == Op::ObjectValue && (c[3] < 1 || c[1] < 0 || int64_t(c[1]) + c[3] > n)) fail("bad object value");
        if (op == Op::LightPath) uses_light_path = true;
        if (op == Op::Wireframe || op == Op::Bevel) uses_triangle = true;
        if (op == Op::Global && c[2] == int32_t(Global::Camera)) uses_camera = true;
        if (op == Op::Global && c[2] == int32_t(Global::Window)) uses_window = true;
        if (op == Op::ImageTiles && (c[5] < 1 || c[4] < 0 || int64_t(c[4]) + 2 * int64_t(c[5]) > n))
            fail("bad tile table");
        if (op == Op::ImageBox && (c[4] < 0 || size_t(c[4]) >= images.size() || !images[size_t(c[4])]))
            fail("image out of range");
        if (op == Op::Image && (c[4] < 0 || size_t(c[4]) >= images.size() || !images[size_t(c[4])]))
            fail("image out of range");
        if (op == Op::Curves && (c[5] < 2 || c[4] < 0 || int64_t(c[4]) + 4 * int64_t(c[5]) > n || int64_t(c[6]) + 2 > n))
            fail("bad curve table");
    }
    for (int k = 0; k < int(Output::Count); ++k) {
        const int32_t o = outputs[k];
        const int width = (k == int(Output::Base) || k == int(Output::Emission) || k == int(Output::Normal) ||
                           k == int(Output::MetalColour))
                              ? 3
                              : 1;
        if (o < -1 || (o >= 0 && int64_t(o) + width > n)) throw InputError(name + ": node output out of range");
    }
    aov_only = std::all_of(outputs, outputs + int(Output::Count), [](int32_t o) { return o < 0; });
    for (const AovWrite &a : aovs)
        if (a.key < 0 || a.colour < 0 || int64_t(a.colour) + 3 > n || a.value < 0 || int64_t(a.value) + 1 > n)
            throw InputError(name + ": AOV output out of range");
}

namespace {

// An Image Texture's sphere (kind 0) and tube (1) projections: the vector, taken from the
// texture space's 0..1 box to -1..1, mapped to (u, v) as Cycles' map_to_sphere and map_to_tube
// define them (u around the Z axis, starting behind -Y; v up the sphere or along Z). An
// Environment Texture's equirectangular (2) and mirror ball (3) projections of the vector's
// direction, as Cycles' direction_to_equirectangular and direction_to_mirrorball.
Vec3 image_projection(Vec3 co, int kind) {
    if (kind >= 2) {
        const float len = length(co);
        if (!(len > 0.f)) return Vec3();  // Cycles' safe_normalize: the zero vector stays
        const Vec3 d = co * (1.f / len);
        if (kind == 2)  // u: a full turn about Z from -X (0) through -Y, +X (0.5), +Y; v: from -Z up
            return {0.5f - std::atan2(d.y, d.x) * (0.5f / kPi),
                    1.f - std::acos(std::fmin(std::fmax(d.z, -1.f), 1.f)) * (1.f / kPi), 0.f};
        // A unit ball seen along +Y reflects the view towards d where its normal is along
        // d - (0, 1, 0); that normal's (x, z) is the point of the ball's image, 0..1 across.
        Vec3 b = d - Vec3(0.f, 1.f, 0.f);
        const float div = 2.f * std::sqrt(std::fmax(-0.5f * b.y, 0.f));
        if (div > 0.f) b = b * (1.f / div);
        return {0.5f * (b.x + 1.f), 0.5f * (b.z + 1.f), 0.f};
    }
    const Vec3 p = (co - Vec3(0.5f, 0.5f, 0.5f)) * 2.f;
    if (kind == 0) {
        const float l = dot(p, p);
        if (!(l > 0.f)) return Vec3();
        const float u = (p.x == 0.f && p.y == 0.f) ? 0.f : 0.5f - std::atan2(p.x, p.y) * (0.5f / kPi);
        const float v = 1.f - std::acos(std::fmin(std::fmax(p.z / std::sqrt(l), -1.f), 1.f)) * (1.f / kPi);
        return {u, v, 0.f};
    }
    const float len = std::sqrt(p.x * p.x + p.y * p.y);
    if (!(len > 0.f)) return Vec3();
    return {(1.f - std::atan2(p.x / len, p.y / len) / kPi) * 0.5f, (p.z + 1.f) * 0.5f, 0.f};
}

// The box projection (Cycles' svm_node_tex_image_box): the object-space normal, as
// barycentric weights over the three axes' faces, picks one face's lookup near an axis and
// blends two or three within `blend` of the edges (seven zones of the triangle).
RGBA image_box(const TextureImage &image, Vec3 co, Vec3 signed_n, float blend, ImageInterpolation interpolation,
               ImageExtension extension) {
    Vec3 n = vabs(signed_n);
    const float sum = n.x + n.y + n.z;
    if (!(sum > 0.f)) n = Vec3(1.f, 0.f, 0.f);
    else n = n * (1.f / sum);
    blend = saturate(blend);
    const float limit = 0.5f * (1.f + blend);
    Vec3 w;
    if (n.x > limit * (n.x + n.y) && n.x > limit * (n.x + n.z)) {
        w.x = 1.f;
    } else if (n.y > limit * (n.x + n.y) && n.y > limit * (n.y + n.z)) {
        w.y = 1.f;
    } else if (n.z > limit * (n.x + n.z) && n.z > limit * (n.y + n.z)) {
        w.z = 1.f;
    } else if (blend > 0.f) {
        if (n.z < (1.f - limit) * (n.y + n.x)) {  // between two faces: X and Y
            w.x = saturate((n.x / (n.x + n.y) - 0.5f * (1.f - blend)) / blend);
            w.y = 1.f - w.x;
        } else if (n.x < (1.f - limit) * (n.y + n.z)) {  // Y and Z
            w.y = saturate((n.y / (n.y + n.z) - 0.5f * (1.f - blend)) / blend);
            w.z = 1.f - w.y;
        } else if (n.y < (1.f - limit) * (n.x + n.z)) {  // X and Z
            w.x = saturate((n.x / (n.x + n.z) - 0.5f * (1.f - blend)) / blend);
            w.z = 1.f - w.x;
        } else {  // all three
            const float k = 1.f / (2.f * limit - 1.f);
            w = Vec3(((2.f - limit) * n.x + (limit - 1.f)) * k, ((2.f - limit) * n.y + (limit - 1.f)) * k,
                     ((2.f - limit) * n.z + (limit - 1.f)) * k);
        }
    } else {
        w.x = 1.f;  // exactly on an edge without blending: one face, as Cycles falls back
    }
    RGBA out;
    auto add = [&](float weight, float u, float v) {
        if (!(weight > 0.f)) return;
        const RGBA t = image.sample(u, v, interpolation, extension);
        out.r += weight * t.r, out.g += weight * t.g, out.b += weight * t.b, out.a += weight * t.a;
    };
    // Each face's (u, v) turned so that no face's image is mirrored (Cycles' orientation).
    add(w.x, signed_n.x < 0.f ? 1.f - co.y : co.y, co.z);
    add(w.y, signed_n.y > 0.f ? 1.f - co.x : co.x, co.z);
    add(w.z, signed_n.z > 0.f ? 1.f - co.y : co.y, co.x);
    return out;
}

// A table of `size` RGBA rows sampled evenly over 0..1, read at f (linearly between rows when
// `interpolate`); outside 0..1 it holds its ends.
void table_lookup(const float *t, int size, float f, bool interpolate, float *rgba) {
    f = saturate(f) * float(size - 1);
    const int i = std::min(std::max(int(f), 0), size - 1);
    const float frac = f - float(i);
    for (int k = 0; k < 4; ++k) {
        rgba[k] = t[4 * i + k];
        if (interpolate && frac > 0.f && i + 1 < size) rgba[k] = (1.f - frac) * rgba[k] + frac * t[4 * (i + 1) + k];
    }
}

// A curve's baked table (RGB, Vector, Float Curves) at f (0..1 over the table's range): as
// table_lookup within it; beyond it, when `extrapolate`, on along the slope of the two end rows
// (Cycles' rgb_ramp_lookup with a curve mapping's Extrapolated extension), else held.
float curve_lookup(const float *t, int size, float f, int channel, bool extrapolate) {
    if (extrapolate && (f < 0.f || f > 1.f)) {
        const float end = f < 0.f ? t[channel] : t[4 * (size - 1) + channel];
        const float next = f < 0.f ? t[4 + channel] : t[4 * (size - 2) + channel];
        return end + (end - next) * (f < 0.f ? -f : f - 1.f) * float(size - 1);
    }
    float rgba[4];
    table_lookup(t, size, f, true, rgba);
    return rgba[channel];
}

// Rotation of p about a unit axis by angle (right-handed: Rodrigues' formula).
Vec3 rotate_about(Vec3 p, Vec3 axis, float angle) {
    const float c = std::cos(angle), s = std::sin(angle);
    return p * c + cross(axis, p) * s + axis * (dot(axis, p) * (1.f - c));
}

// Blender's Vector Rotate node; kind 0 axis-angle, 1-3 the X, Y, Z axis, 4 Euler XYZ.
Vec3 vector_rotate(Vec3 v, Vec3 center, Vec3 axis, float angle, Vec3 euler, int kind, bool invert) {
    if (kind == 4) return rotate_xyz(v - center, euler, invert) + center;
    if (kind >= 1) axis = Vec3(kind == 1 ? 1.f : 0.f, kind == 2 ? 1.f : 0.f, kind == 3 ? 1.f : 0.f);
    const float len = length(axis);
    if (len == 0.f) return v;  // no axis: unrotated, as Cycles
    return rotate_about(v - center, axis * (1.f / len), invert ? -angle : angle) + center;
}

// Blender's HSL (Separate/Combine Color): hue 0..1, lightness capped at 1 as Blender caps it.
Vec3 rgb_to_hsl(Vec3 c) {
    const float hi = std::fmax(c.x, std::fmax(c.y, c.z)), lo = std::fmin(c.x, std::fmin(c.y, c.z));
    const float l = std::fmin(1.f, 0.5f * (hi + lo));
    if (hi == lo) return {0.f, 0.f, l};
    const float d = hi - lo;
    const float s = l > 0.5f ? d / (2.f - hi - lo) : d / (hi + lo);
    float h;
    if (hi == c.x) h = (c.y - c.z) / d + (c.y < c.z ? 6.f : 0.f);
    else if (hi == c.y) h = (c.z - c.x) / d + 2.f;
    else h = (c.x - c.y) / d + 4.f;
    return {h / 6.f, s, l};
}
Vec3 hsl_to_rgb(Vec3 hsl) {
    // Each channel's hue ramp (a trapezoid over the hue circle, unwrapped), scaled by chroma
    // about the lightness.
    const float h6 = hsl.x * 6.f;
    const Vec3 ramp = vsaturate({std::fabs(h6 - 3.f) - 1.f, 2.f - std::fabs(h6 - 2.f), 2.f - std::fabs(h6 - 4.f)});
    const float chroma = (1.f - std::fabs(2.f * hsl.z - 1.f)) * hsl.y;
    return (ramp - Vec3(0.5f, 0.5f, 0.5f)) * chroma + Vec3(hsl.z, hsl.z, hsl.z);
}

// Blender's Wavelength node: the CIE 1931 colour-matching functions (cie1931.h, the table
// Cycles rounds to 4 decimals) linearly between 5 nm rows over 380-780 nm (black outside), in
// linear Rec. 709 (its XYZ matrix, D65 white: Blender's XYZ role), scaled by 1 / 2.52 (Cycles'
// scale keeping every component of the spectrum locus <= 1), negative channels clamped to 0.
Vec3 wavelength_rec709(float nm) {
    constexpr float kFirst = 380.f, kLastRow = 80.f;  // rows 380 .. 780 nm (Cycles: 780 itself is black)
    const float f = (nm - kFirst) / float(kCieStepNm);
    if (!(f >= 0.f) || !(f < kLastRow)) return Vec3();
    const int i = int(f), base = (int(kFirst) - kCieFirstNm) / kCieStepNm + i;
    const float t = f - float(i);
    float xyz[3];
    for (int k = 0; k < 3; ++k) xyz[k] = (1.f - t) * kCie1931[base][k] + t * kCie1931[base + 1][k];
    const Vec3 rgb(3.2404542f * xyz[0] - 1.5371385f * xyz[1] - 0.4985314f * xyz[2],
                   -0.9692660f * xyz[0] + 1.8760108f * xyz[1] + 0.0415560f * xyz[2],
                   0.0556434f * xyz[0] - 0.2040259f * xyz[1] + 1.0572252f * xyz[2]);
    return vmax(rgb * (1.f / 2.52f), Vec3());
}

// A vector between the render's frame and the shaded object's space (Vector Transform).
// normal_matrix is the transpose of the world-to-object linear map W; a point goes through
// the shading point's pair (P, object); a normal by the inverse transpose, normalised.
Vec3 object_space(const ShaderGlobals &sg, Vec3 v, int kind, bool to_world) {
    const float *m = sg.normal_matrix;
    auto by_w = [m](Vec3 a) {  // W a
        return Vec3(m[0] * a.x + m[3] * a.y + m[6] * a.z, m[1] * a.x + m[4] * a.y + m[7] * a.z,
                    m[2] * a.x + m[5] * a.y + m[8] * a.z);
    };
    // W^-1 b, or W^-T b: a matrix with columns a0..a2 has as inverse the rows (a1 x a2, a2 x a0,
    // a0 x a1) / det. W's columns are (m0 m1 m2), (m3 m4 m5), (m6 m7 m8); W^T's are W's rows.
    auto solve_w = [m](Vec3 b, bool transposed) {
        Vec3 a0(m[0], m[1], m[2]), a1(m[3], m[4], m[5]), a2(m[6], m[7], m[8]);
        if (transposed) a0 = Vec3(m[0], m[3], m[6]), a1 = Vec3(m[1], m[4], m[7]), a2 = Vec3(m[2], m[5], m[8]);
        const float det = dot(a0, cross(a1, a2));
        if (!(std::fabs(det) > 0.f)) return b;  // a degenerate object: left as it is
        return Vec3(dot(b, cross(a1, a2)), dot(b, cross(a2, a0)), dot(b, cross(a0, a1))) * (1.f / det);
    };
    Vec3 out;
    if (kind == 0) out = to_world ? sg.P + solve_w(v - sg.object, false) : sg.object + by_w(v - sg.P);
    else if (kind == 1) out = to_world ? solve_w(v, false) : by_w(v);
    else {
        out = to_world ? sg.object_to_world_normal(v) : solve_w(v, true);
        const float len = length(out);
        out = len > 0.f ? out * (1.f / len) : out;
    }
    return out;
}

// Map Range in vector mode, one component: unlike the float mode, Cycles divides safely (a
// zero source range maps to To Min), and its smooth steps are of the clamped factor, unclamped.
float vector_map_range(float v, const float *p, int mode, bool clamp) {
    const float from_min = p[0], from_max = p[3], to_min = p[6], to_max = p[9], steps = p[12];
    float f = safe_divide(v - from_min, from_max - from_min);
    if (mode == 1) f = steps > 0.f ? std::floor(f * (steps + 1.f)) / steps : 0.f;
    else if (mode == 2) f = saturate(f), f = (3.f - 2.f * f) * f * f;
    else if (mode == 3) f = saturate(f), f = f * f * f * (f * (f * 6.f - 15.f) + 10.f);
    const float result = to_min + f * (to_max - to_min);
    if (!clamp || mode >= 2) return result;
    return to_min > to_max ? std::fmin(std::fmax(result, to_max), to_min) : std::fmin(std::fmax(result, to_min), to_max);
}

}  // namespace

void NodeProgram::run(const ShaderGlobals &sg, float *r) const {
    std::memcpy(r, data.data(), data.size() * sizeof(float));
    run_rows(sg, r, 0, code.size() / kNodeWidth);
}

void NodeProgram::run_rows(const ShaderGlobals &sg, float *r, size_t begin, size_t end) const {
    for (size_t row = begin; row < end; ++row) {
        const int32_t *c = &code[row * kNodeWidth];
        switch (Op(c[0])) {
            case Op::Global: {
                Vec3 v;
                switch (Global(c[2])) {
                    case Global::Position: v = sg.P; break;
                    case Global::Normal: v = sg.N; break;
                    case Global::TrueNormal: v = sg.Ng; break;
                    case Global::Incoming: v = sg.I; break;
                    case Global::Object: v = sg.object; break;
                    case Global::ObjectNormal: v = sg.object_normal; break;
                    case Global::Generated: v = sg.generated; break;
                    case Global::UV: v = sg.uv; break;
                    case Global::PointColour: v = sg.point_colour; break;
                    case Global::PointAlpha: v = Vec3(sg.point_alpha, sg.point_alpha, sg.point_alpha); break;
                    case Global::Reflection: v = sg.N * (2.f * dot(sg.N, sg.I)) - sg.I; break;
                    case Global::Camera: v = sg.camera; break;
                    case Global::Window: v = sg.window; break;
                    case Global::Parametric: v = sg.parametric; break;
                    default: v = Vec3(sg.backfacing, sg.backfacing, sg.backfacing); break;
                }
                store3(r, c[1], v);
                break;
            }
            case Op::Copy: std::memmove(r + c[1], r + c[2], size_t(c[3]) * sizeof(float)); break;
            case Op::Math: {
                const float v = math(c[5], r[c[2]], r[c[3]], r[c[4]]);
                r[c[1]] = c[6] ? saturate(v) : v;
                break;
            }
            case Op::VectorMath: {
                Vec3 v;
                float f;
                vector_math(c[7], load3(r, c[3]), load3(r, c[4]), load3(r, c[5]), r[c[6]], &v, &f);
                store3(r, c[1], v);
                r[c[2]] = f;
                break;
            }
            case Op::MixFloat: {
                const float t = c[5] ? saturate(r[c[2]]) : r[c[2]];
                r[c[1]] = lerp(r[c[3]], r[c[4]], t);
                break;
            }
            case Op::MixVector: {
                Vec3 t = c[6] ? load3(r, c[2]) : Vec3(r[c[2]], r[c[2]], r[c[2]]);
                if (c[5]) t = vsaturate(t);
                const Vec3 a = load3(r, c[3]), b = load3(r, c[4]);
                store3(r, c[1], a * (Vec3(1, 1, 1) - t) + b * t);
                break;
            }
            case Op::MixColour: {
                const float t = c[6] ? saturate(r[c[2]]) : r[c[2]];
                const Vec3 v = blend(c[5], t, load3(r, c[3]), load3(r, c[4]));
                store3(r, c[1], c[7] ? vsaturate(v) : v);
                break;
            }
            case Op::MapRange: r[c[1]] = map_range(r[c[2]], r + c[3], c[4], c[5] != 0); break;
            case Op::Clamp: {
                float lo = r[c[3]], hi = r[c[4]];
                if (c[5] == 1 && lo > hi) std::swap(lo, hi);
                r[c[1]] = std::fmin(std::fmax(r[c[2]], lo), hi);
                break;
            }
            case Op::Ramp: {
                float rgba[4];
                table_lookup(r + c[4], c[5], r[c[3]], c[6] != 0, rgba);
                store3(r, c[1], {rgba[0], rgba[1], rgba[2]});
                r[c[2]] = rgba[3];
                break;
            }
            case Op::HueSatVal: {
                const Vec3 in = load3(r, c[6]);
                Vec3 h = rgb_to_hsv(in);
                h.x = fract(h.x + r[c[2]] + 0.5f);
                h.y = saturate(h.y * r[c[3]]);
                h.z *= r[c[4]];
                const float fac = r[c[5]];
                store3(r, c[1], vmax(hsv_to_rgb(h) * fac + in * (1.f - fac), Vec3()));
                break;
            }
            case Op::Invert: {
                const Vec3 in = load3(r, c[3]);
                store3(r, c[1], lerp(in, Vec3(1, 1, 1) - in, r[c[2]]));
                break;
            }
            case Op::BrightContrast: {
                const float a = 1.f + r[c[4]], b = r[c[3]] - r[c[4]] * 0.5f;
                const Vec3 in = load3(r, c[2]);
                store3(r, c[1], vmax(in * a + Vec3(b, b, b), Vec3()));
                break;
            }
            case Op::Gamma: {
                Vec3 v = load3(r, c[2]);
                const float g = r[c[3]];
                for (int i = 0; i < 3; ++i)
                    if (v[i] > 0.f) v[i] = std::pow(v[i], g);
                store3(r, c[1], v);
                break;
            }
            case Op::RGBToBW: r[c[1]] = luma(load3(r, c[2])); break;
            case Op::Combine: store3(r, c[1], {r[c[2]], r[c[3]], r[c[4]]}); break;
            case Op::RGBToHSV: store3(r, c[1], rgb_to_hsv(load3(r, c[2]))); break;
            case Op::HSVToRGB: store3(r, c[1], hsv_to_rgb(load3(r, c[2]))); break;
            case Op::Mapping:
                store3(r, c[1], mapping(c[6], load3(r, c[2]), load3(r, c[3]), load3(r, c[4]), load3(r, c[5])));
                break;
            case Op::Checker: {
                const float f = checker(load3(r, c[3]) * r[c[6]]);
                store3(r, c[1], f == 1.f ? load3(r, c[4]) : load3(r, c[5]));
                r[c[2]] = f;
                break;
            }
            case Op::Gradient: {
                const float f = saturate(gradient(load3(r, c[3]), c[4]));
                store3(r, c[1], {f, f, f});
                r[c[2]] = f;
                break;
            }
            case Op::Fresnel: {
                float eta = std::fmax(r[c[2]], 1e-5f);
                if (sg.backfacing != 0.f) eta = 1.f / eta;
                r[c[1]] = fresnel_cos(dot(sg.I, load3(r, c[3])), eta);
                break;
            }
            case Op::LayerWeight: {
                float blend_ = r[c[3]];
                const Vec3 n = load3(r, c[4]);
                float eta = std::fmax(1.f - blend_, 1e-5f);
                eta = sg.backfacing != 0.f ? eta : 1.f / eta;
                r[c[1]] = fresnel_cos(dot(sg.I, n), eta);
                float f = std::fabs(dot(sg.I, n));
                if (blend_ != 0.5f) {
                    blend_ = std::fmin(std::fmax(blend_, 0.f), 1.f - 1e-5f);
                    blend_ = blend_ < 0.5f ? 2.f * blend_ : 0.5f / (1.f - blend_);
                    f = std::pow(f, blend_);
                }
                r[c[2]] = 1.f - f;
                break;
            }
            case Op::Noise: {  // Blender's Noise Texture node (nodes/noise.h)
                NoiseParams q;
                std::memcpy(&q, r + c[4], sizeof q);
                Vec3 colour;
                r[c[1]] = noise_texture(c[5], NoiseType(c[6]), load3(r, c[3]), q, c[7] & 1, c[7] & 2 ? &colour : nullptr);
                if (c[7] & 2) store3(r, c[2], colour);  // the Color output is read
                break;
            }
            case Op::WhiteNoise: {
                Vec3 colour;
                r[c[1]] = white_noise(load3(r, c[3]), c[4], &colour);
                store3(r, c[2], colour);
                break;
            }
            case Op::Scale: store3(r, c[1], load3(r, c[2]) * r[c[3]]); break;
            case Op::Curves: {
                // RGB Curves: each channel through its curve (table rows: r, g, b curves and the
                // combined curve, sampled over the range [min, max]), then mixed by fac.
                const float lo = r[c[6]], hi = r[c[6] + 1];
                const float scale = hi > lo ? 1.f / (hi - lo) : 1.f;
                const Vec3 in = load3(r, c[3]);
                Vec3 out;
                for (int i = 0; i < 3; ++i) out[i] = curve_lookup(r + c[4], c[5], (in[i] - lo) * scale, i, c[7] != 0);
                const float fac = r[c[2]];
                store3(r, c[1], lerp(in, out, fac));
                break;
            }
            case Op::Image: {
                const Vec3 uv = load3(r, c[3]);
                const RGBA t = images[size_t(c[4])]->sample(uv.x, uv.y, ImageInterpolation(c[5]), ImageExtension(c[6]));
                store3(r, c[1], {t.r, t.g, t.b});
                r[c[2]] = t.a;
                break;
            }
            case Op::Transform: {
                const Vec3 p = load3(r, c[2]);
                const float *m = r + c[3];
                store3(r, c[1], {m[0] * p.x + m[1] * p.y + m[2] * p.z + m[3], m[4] * p.x + m[5] * p.y + m[6] * p.z + m[7],
                                 m[8] * p.x + m[9] * p.y + m[10] * p.z + m[11]});
                break;
            }
            case Op::ImageProject: store3(r, c[1], image_projection(load3(r, c[2]), c[3])); break;
            case Op::Tangent: store3(r, c[1], tangent(sg, c[2], load3(r, c[3]))); break;
            case Op::ImageBox: {
                const RGBA t = image_box(*images[size_t(c[4])], load3(r, c[3]), sg.object_normal, r[c[7]],
                                         ImageInterpolation(c[5]), ImageExtension(c[6]));
                store3(r, c[1], {t.r, t.g, t.b});
                r[c[2]] = t.a;
                break;
            }
            case Op::ImageTiles: {
                const Vec3 uv = load3(r, c[3]);
                // Cycles' choice: the integer parts truncated towards zero, tiles 1001 + 10 v + u
                // for u in 0..9; the coordinates then relative to the tile found.
                RGBA t{1.f, 0.f, 1.f, 1.f};  // magenta: no such tile, or not loaded (Cycles' missing image)
                const float tx = std::trunc(uv.x), ty = std::trunc(uv.y);
                if (tx >= 0.f && ty >= 0.f && tx < 10.f && ty < 1e6f) {
                    const float tile = 1001.f + 10.f * ty + tx;
                    const float *table = r + c[4];
                    for (int i = 0; i < c[5]; ++i) {
                        if (table[2 * i] != tile) continue;
                        const float index = table[2 * i + 1];
                        if (index >= 0.f && index < float(images.size()) && images[size_t(index)])
                            t = images[size_t(index)]->sample(uv.x - tx, uv.y - ty, ImageInterpolation(c[6]),
                                                              ImageExtension(c[7]));
                        break;
                    }
                }
                store3(r, c[1], {t.r, t.g, t.b});
                r[c[2]] = t.a;
                break;
            }
            case Op::Voronoi: {
                const float *q = r + c[4];  // scale detail roughness lacunarity smoothness exponent randomness normalize
                const VoronoiOutputs o =
                    voronoi_texture(load3(r, c[2]), r[c[3]], c[7] + 1, VoronoiFeature(c[6]), VoronoiMetric(c[5]),
                                    {q[0], q[1], q[2], q[3], q[4], q[5], q[6], q[7] != 0.f});
                r[c[1]] = o.distance;
                store3(r, c[1] + 1, o.colour);
                store3(r, c[1] + 4, o.position);
                r[c[1] + 7] = o.w;
                r[c[1] + 8] = o.radius;
                break;
            }
            case Op::Wave: {
                const float *q = r + c[3];
                r[c[1]] = wave(load3(r, c[2]) * q[0], q, r[c[4]], c[5], c[6]);
                break;
            }
            case Op::Magic: {
                const Vec3 v = magic(load3(r, c[3]) * r[c[4]], c[6], r[c[5]]);
                store3(r, c[1], v);
                r[c[2]] = (v.x + v.y + v.z) * (1.f / 3.f);
                break;
            }
            case Op::NormalMap: {
                // Blender's Normal Map node: colour (0..1) -> a vector in -1..1 in the chosen space.
                const Vec3 c3 = load3(r, c[2]);
                Vec3 v = (c3 - Vec3(0.5f, 0.5f, 0.5f)) * 2.f;
                const bool back = sg.backfacing != 0.f;
                const float strength = r[c[3]];
                Vec3 n;
                if (c[4] == 0) {  // tangent space: the UV map's frame about the surface's own normal
                    if (dot(sg.tangent, sg.tangent) == 0.f) {
                        n = sg.N;
                    } else {
                        // Strength in the tangent frame, as Cycles 5 applies it there: the
                        // sideways part scaled, the normal part blended from 1.
                        if (strength != 1.f) {  // (at 1, v as it was, to the bit)
                            v.x *= strength, v.y *= strength;
                            v.z = 1.f + (v.z - 1.f) * std::fmin(std::fmax(strength, 0.f), 1.f);
                        }
                        const Vec3 b = cross(sg.surface_normal, sg.tangent) * sg.tangent_sign;
                        n = normalize(sg.tangent * v.x + b * v.y + sg.surface_normal * v.z);
                        if (back) n = n * -1.f;  // as the normal the viewer sees is turned
                    }
                } else {  // object space (through the transform sg.to_world_normal), or world
                    n = normalize(c[4] == 1 ? sg.object_to_world_normal(v) : v);
                    if (back) n = n * -1.f;
                    // Strength: a blend from the shading normal (no frame to apply it in).
                    if (strength != 1.f) n = normalize(sg.N + (n - sg.N) * std::fmax(strength, 0.f));
                }
                if (!(dot(n, n) > 0.f) || !std::isfinite(dot(n, n))) n = sg.N;
                store3(r, c[1], n);
                break;
            }
            case Op::Brick: {
                const float *q = r + c[5];
                if (!(q[4] != 0.f) || !(q[5] != 0.f)) {  // a zero-sized brick: all mortar
                    store3(r, c[1], load3(r, c[4] + 6));
                    r[c[2]] = 1.f;
                    break;
                }
                float tint, m;
                brick(load3(r, c[3]) * q[0], q, c[6], c[7], &tint, &m);
                Vec3 colour = load3(r, c[4]);
                if (m != 1.f) colour = colour * (1.f - tint) + load3(r, c[4] + 3) * tint;
                store3(r, c[1], colour * (1.f - m) + load3(r, c[4] + 6) * m);
                r[c[2]] = m;
                break;
            }
            case Op::Blackbody: store3(r, c[1], blackbody_rec709(r[c[2]])); break;
            case Op::Attribute: {
                // Cycles' Attribute node: a float attribute is its Color and Vector in every
                // component and its Fac; a vector's or colour's Fac is its components' average.
                // A column the point does not carry reads 0, as a missing attribute does there.
                Vec3 v;
                float fac = 0.f;
                if (c[3] + c[4] <= sg.attribute_count) {
                    const float *a = sg.attributes + c[3];
                    v = c[4] == 1 ? Vec3(a[0], a[0], a[0]) : Vec3(a[0], a[1], a[2]);
                    fac = c[4] == 1 ? a[0] : (a[0] + a[1] + a[2]) * (1.f / 3.f);
                }
                store3(r, c[1], v);
                r[c[2]] = fac;
                break;
            }
            case Op::Bump: {
                // Blender's Bump node: the height here and at two nearby points of the surface
                // give its gradient along the surface (Mikkelsen, "Bump Mapping Unparameterized
                // Surfaces on the GPU", 2010, as Cycles computes it from its ray differentials).
                const float hc = r[c[2]];
                float h[2] = {hc, hc};
                for (int k = 0; k < 2; ++k)
                    if (size_t(c[6]) < row) {
                        run_rows(sg.offset(k), r, size_t(c[6]), row);
                        h[k] = r[c[2]];
                    }
                r[c[2]] = hc;
                const Vec3 n_in = load3(r, c[5]), dx = sg.bump[0].P, dy = sg.bump[1].P;
                const Vec3 rx = cross(dy, n_in), ry = cross(n_in, dx);
                const float det = dot(dx, rx);
                const Vec3 gradient = rx * (h[0] - hc) + ry * (h[1] - hc);
                const float distance = c[7] ? -r[c[4]] : r[c[4]], strength = std::fmax(r[c[3]], 0.f);
                Vec3 n = n_in * std::fabs(det) - gradient * (det < 0.f ? -distance : distance);
                const float len2 = dot(n, n);
                if (len2 > 0.f && std::isfinite(len2)) n = normalize(normalize(n) * strength + n_in * (1.f - strength));
                else n = n_in;
                if (!(dot(n, n) > 0.f) || !std::isfinite(dot(n, n))) n = sg.N;
                store3(r, c[1], n);
                break;
            }
            case Op::VectorRotate:
                store3(r, c[1], vector_rotate(load3(r, c[2]), load3(r, c[3]), load3(r, c[4]), r[c[5]], load3(r, c[6]),
                                              c[7] % 5, c[7] >= 5));
                break;
            case Op::RGBToHSL: store3(r, c[1], rgb_to_hsl(load3(r, c[2]))); break;
            case Op::HSLToRGB: store3(r, c[1], hsl_to_rgb(load3(r, c[2]))); break;
            case Op::Wavelength: store3(r, c[1], wavelength_rec709(r[c[2]])); break;
            case Op::ObjectSpace: store3(r, c[1], object_space(sg, load3(r, c[2]), c[3] % 3, c[3] >= 3)); break;
            case Op::VectorMapRange: {
                const Vec3 v = load3(r, c[2]);
                Vec3 out;
                for (int i = 0; i < 3; ++i) out[i] = vector_map_range(v[i], r + c[3] + i, c[4], c[5] != 0);
                store3(r, c[1], out);
                break;
            }
            case Op::Gabor: {
                const float *p = r + c[3];
                const GaborOutputs g = gabor_texture(load3(r, c[2]), p[0], p[1], p[2], p[3], load3(r, c[4]), c[5] != 0);
                store3(r, c[1], {g.value, g.phase, g.intensity});
                break;
            }
            case Op::ObjectValue:
                for (int k = 0; k < c[3]; ++k)
                    r[c[1] + k] = c[2] + k < sg.object_value_count ? sg.object_values[c[2] + k] : 0.f;
                break;
            case Op::LightPath: {
                // Without the integrator's word: a camera ray's first surface (depths 0).
                static const float kCameraRay[kLightPathFloats] = {1.f};
                const float *l = sg.light_path ? sg.light_path : kCameraRay;
                for (int k = 0; k < kLightPathFloats; ++k) r[c[1] + k] = l[k];
                break;
            }
            case Op::AmbientOcclusion: {
                const float ao = ambient_occlusion(sg, load3(r, c[5]), r[c[4]], c[6], c[7], uint32_t(row));
                store3(r, c[1], load3(r, c[3]) * ao);
                r[c[2]] = ao;
                break;
            }
            case Op::Wireframe: r[c[1]] = wireframe(sg, r[c[2]], c[3] != 0); break;
            case Op::Bevel: {
                Vec3 n = bevel(sg, r[c[2]], c[4], uint32_t(row));
                // A linked Normal: Cycles adds the bevel's change of the normal to it.
                if (c[5]) n = normalize(load3(r, c[3]) + (n - sg.N));
                if (!(dot(n, n) > 0.f) || !std::isfinite(dot(n, n))) n = sg.N;
                store3(r, c[1], n);
                break;
            }
            default: break;  // unreachable: validate() refused it
        }
    }
}

}  // namespace splat
