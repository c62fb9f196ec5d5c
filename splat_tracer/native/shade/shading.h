// Materials (a simplified Principled BSDF) and lamps in Blender's units. The packed float
// rows come from splat_tracer/render/shading.py: MATERIAL_FIELDS and LIGHT_FIELDS there are the
// column lists, mirrored by the k* indices here.
#pragma once

#include <cmath>
#include <cstdint>

#include "base/ray.h"
#include "base/vec3.h"
#include "shade/sampling.h"

namespace splat {

constexpr int kMaterialFields = 20;
constexpr int kLightFields = 22;

// Below this roughness a lobe is a perfect mirror or clear glass: traced by recursive
// reflection/refraction rays rather than sampled (GGX with alpha = roughness^2 < 1e-4 is
// narrower than a pixel's footprint at any distance that matters).
constexpr float kDeltaRoughness = 0.01f;

struct Material {
    Vec3 base{0.8f, 0.8f, 0.8f};
    float metallic = 0, roughness = 0.5f, ior = 1.5f, transmission = 0, alpha = 1;
    Vec3 emission;
    float specular_level = 0.5f;
    bool use_point_colour = false, use_point_alpha = false;
    // The sides of a mesh's triangles whose emission is sampled as a light (1 front, 2 back:
    // Cycles' Emission Sampling, Auto resolved by render/shading.py); 0: found by rays only.
    int emission_sides = 0;
    float pass_index = 0;  // Blender's material pass index: the Material Index pass
    // The metallic lobe's own colour (own_metal; packed as -1s when it is the base colour's):
    // a Mix Shader of a diffuse and a glossy keeps each closure's colour (render/shading.py).
    Vec3 metal_colour;
    bool own_metal = false;
    // Cycles' Bump Map Correction: the bump shadowing term where a program tilts the normal.
    bool bump_correction = true;
    // Its node program in the scene's table (RenderScene::material_at), or -1: the constant
    // values above are the material. Not part of the packed row (programs come apart).
    int program = -1;

    static Material from_row(const float *r) {
        Material m;
        m.base = Vec3(r[0], r[1], r[2]);
        m.metallic = r[3], m.roughness = r[4], m.ior = r[5], m.transmission = r[6], m.alpha = r[7];
        m.emission = Vec3(r[8], r[9], r[10]);
        m.specular_level = r[11], m.use_point_colour = r[12] != 0.f, m.use_point_alpha = r[13] != 0.f;
        m.emission_sides = int(r[14]) & 3;
        m.pass_index = r[15];
        m.own_metal = r[16] >= 0.f && r[17] >= 0.f && r[18] >= 0.f;
        if (m.own_metal) m.metal_colour = Vec3(r[16], r[17], r[18]);
        m.bump_correction = r[19] != 0.f;
        return m;
    }
    bool emits() const { return emission.x > 0.f || emission.y > 0.f || emission.z > 0.f; }
};

enum class LightType : int { Point = 0, Spot = 1, Sun = 2, Area = 3 };
enum class AreaShape : int { Square = 0, Rectangle = 1, Disk = 2, Ellipse = 3 };

struct Light {
    LightType type = LightType::Point;
    Vec3 rgb;             // colour x power (W) or x strength (sun, W/m^2)
    Vec3 position, axis;  // axis: the way it shines (the lamp's local -Z)
    Vec3 u, v;            // area: unit edge axes (lamp X and Y)
    float radius = 0;     // point/spot sphere radius; sun: half its angular diameter
    float size_u = 1, size_v = 1;
    AreaShape shape = AreaShape::Square;
    float cos_half_spot = -1, spot_smooth = 0;
    bool cast_shadow = true, soft_falloff = true;
    uint32_t visibility = 13;  // ray kinds that see the lamp itself (render_scene.h's kVis* bits)

    static Light from_row(const float *r);
    float area() const {  // of an area lamp (Cycles' definition per shape)
        const bool round = shape == AreaShape::Disk || shape == AreaShape::Ellipse;
        return round ? 0.25f * kPi * size_u * size_v : size_u * size_v;
    }
};

// One light sample seen from a shading point: direction, distance (inf for the sun) and the
// irradiance it brings on a surface facing it, already divided by the sample's pdf.
struct LightSample {
    Vec3 wi;
    float distance = 0;
    Vec3 irradiance;  // W/m^2 per unit cosine at the receiver
    bool valid = false;
};

// Samples `light` from point p with two uniform numbers. Units (measured against Cycles):
// point and spot: intensity P / (4 pi), falloff 1 / (d^2 + r^2) with Soft Falloff, else
// 1 / d^2; spot: times smoothstep((cos - cos_half) / ((1 - cos_half) blend)); sun: S W/m^2
// whatever its angle; area: one-sided radiance P / (pi A).
LightSample sample_light(const Light &light, Vec3 p, float u1, float u2);

// The radiance of the lamp itself where the ray meets it before `tmax` (a sun: only rays that
// leave the scene), 0 elsewhere. As Cycles shows lamps (measured): an area lamp's front
// P / (pi A), a point or spot sphere P / (4 pi^2 r^2) (a spot's masked by its cone towards
// the viewer), a sun's disc S / (pi sin^2(angle / 2)). Lamps without a size are not seen.
Vec3 lamp_radiance(const Light &light, const Ray &ray, float tmax);

// --------------------------------------------------------------------------------------
// BSDF: Lambert diffuse under a GGX specular layer (the exact dielectric Fresnel of an IOR
// whose f0 is the material IOR's scaled by the specular level, as Cycles does), GGX metal
// (Schlick with the base colour), and a dielectric (exact Fresnel) for transmission.

struct ShadingFrame {
    Vec3 n;  // shading normal, on the side of wo
    Vec3 wo;  // towards the viewer
    float cos_o;
};

float fresnel_dielectric(float cos_i, float eta);  // eta = n_transmitted / n_incident
inline float schlick_weight(float c) {
    const float m = std::fmax(0.f, std::fmin(1.f, 1.f - c));
    const float m2 = m * m;
    return m2 * m2 * m;
}
inline float ggx_alpha(float roughness) { return std::fmax(roughness * roughness, 1e-4f); }
float ggx_d(float cos_h, float alpha);
float ggx_g1(float cos_v, float alpha);
// A microfacet normal from the distribution of visible normals (Heitz 2018), about n.
Vec3 sample_ggx_vndf(Vec3 n, Vec3 wo, float alpha, float u1, float u2);

inline float luminance(Vec3 c) { return 0.2126f * c.x + 0.7152f * c.y + 0.0722f * c.z; }

}  // namespace splat
