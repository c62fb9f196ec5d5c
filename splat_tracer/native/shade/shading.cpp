#include "shade/shading.h"

#include <algorithm>

namespace splat {

Light Light::from_row(const float *r) {
    Light l;
    l.type = LightType(int(r[0]));
    l.rgb = Vec3(r[1], r[2], r[3]);
    l.position = Vec3(r[4], r[5], r[6]);
    l.axis = normalize(Vec3(r[7], r[8], r[9]));
    l.u = normalize(Vec3(r[10], r[11], r[12]));
    l.v = cross(l.u, l.axis);  // the lamp's Y: Z x X with Z = -axis
    l.radius = r[13], l.size_u = r[14], l.size_v = r[15];
    l.shape = AreaShape(int(r[16]));
    const float half = r[17], blend = r[18];
    l.cos_half_spot = std::cos(half);
    l.spot_smooth = (1.f - l.cos_half_spot) * blend;
    l.cast_shadow = r[19] != 0.f, l.soft_falloff = r[20] != 0.f;
    l.visibility = uint32_t(r[21]);
    return l;
}

namespace {

float smoothstep01(float t) {
    t = std::clamp(t, 0.f, 1.f);
    return t * t * (3.f - 2.f * t);
}

}  // namespace

LightSample sample_light(const Light &l, Vec3 p, float u1, float u2) {
    LightSample s;
    switch (l.type) {
        case LightType::Point:
        case LightType::Spot: {
            const Vec3 to_centre = l.position - p;
            const float d2 = dot(to_centre, to_centre);
            if (!(d2 > 0.f)) return s;
            Vec3 target = l.position;
            const Vec3 w = to_centre * (1.f / std::sqrt(d2));
            if (l.radius > 0.f) {
                // A point of the sphere's disk facing p: soft shadows.
                const Vec3 t = orthogonal(w), b = cross(w, t);
                float x, y;
                sample_disk(u1, u2, &x, &y);
                target = l.position + (t * x + b * y) * l.radius;
            }
            const Vec3 to = target - p;
            const float dist = length(to);
            if (!(dist > 0.f)) return s;
            s.wi = to * (1.f / dist);
            s.distance = dist;
            float falloff = 1.f / d2;
            if (l.radius > 0.f) {
                // The disk of radius r facing p with radiance P / (4 pi^2 r^2), integrated over
                // its area: the estimator is (P / 4 pi) cos_l / dist^2 (times the receiver's
                // cosine, applied by the caller), whose mean on a receiver facing the lamp is
                // exactly (P / 4 pi) / (d^2 + r^2), Soft Falloff's law. Without Soft Falloff
                // the law is 1 / d^2: the same estimator scaled by (d^2 + r^2) / d^2.
                // (Weighting by 1 / (d^2 + r^2) alone left the receiver's cosine towards the
                // sampled point, not the centre, in the mean: up to r^2 / 4 d^2 too dark.)
                const float cos_l = std::fmax(dot(s.wi, w), 0.f);
                falloff = cos_l / (dist * dist);
                if (!l.soft_falloff) falloff *= (d2 + l.radius * l.radius) / d2;
            }
            if (l.type == LightType::Spot) {
                const float c = dot(s.wi * -1.f, l.axis);
                if (c <= l.cos_half_spot) return s;
                if (l.spot_smooth > 0.f) falloff *= smoothstep01((c - l.cos_half_spot) / l.spot_smooth);
            }
            s.irradiance = l.rgb * (falloff / (4.f * kPi));
            s.valid = true;
            return s;
        }
        case LightType::Sun: {
            // Any angle gives the same irradiance (measured); the angle only softens shadows.
            const float cos_max = std::cos(l.radius);
            s.wi = l.radius > 0.f ? sample_cone(l.axis * -1.f, cos_max, u1, u2) : l.axis * -1.f;
            s.distance = kInfinity;
            // Directions uniform in the cone bring a mean receiver cosine of cos(theta) times
            // (1 + cos_max) / 2; dividing that factor out keeps S cos(theta) for any angle.
            s.irradiance = l.rgb * (l.radius > 0.f ? 2.f / (1.f + cos_max) : 1.f);
            s.valid = true;
            return s;
        }
        case LightType::Area: {
            float x, y;
            if (l.shape == AreaShape::Disk || l.shape == AreaShape::Ellipse) {
                sample_disk(u1, u2, &x, &y);
                x *= 0.5f, y *= 0.5f;
            } else {
                x = u1 - 0.5f, y = u2 - 0.5f;
            }
            const Vec3 q = l.position + l.u * (x * l.size_u) + l.v * (y * l.size_v);
            const Vec3 to = q - p;
            const float d2 = dot(to, to);
            if (!(d2 > 0.f)) return s;
            const float dist = std::sqrt(d2);
            s.wi = to * (1.f / dist);
            const float cos_l = dot(s.wi * -1.f, l.axis);  // one-sided: emits along axis
            if (cos_l <= 0.f) return s;
            const float area = l.area();
            // radiance P / (pi A), pdf 1 / A, solid angle per area cos_l / d^2.
            s.distance = dist;
            s.irradiance = l.rgb * (cos_l / (kPi * d2));
            s.valid = area > 0.f;
            return s;
        }
    }
    return s;
}

Vec3 lamp_radiance(const Light &l, const Ray &ray, float tmax) {
    switch (l.type) {
        case LightType::Sun: {
            if (!std::isinf(tmax) || !(l.radius > 0.f)) return Vec3();
            if (dot(ray.d, l.axis * -1.f) < std::cos(l.radius)) return Vec3();
            const float s = std::sin(l.radius);
            return l.rgb * (1.f / (kPi * s * s));
        }
        case LightType::Point:
        case LightType::Spot: {
            if (!(l.radius > 0.f)) return Vec3();
            const Vec3 oc = l.position - ray.o;
            const float b = dot(oc, ray.d), c = dot(oc, oc) - l.radius * l.radius;
            const float disc = b * b - c;
            if (disc < 0.f) return Vec3();
            const float t = c > 0.f ? b - std::sqrt(disc) : b + std::sqrt(disc);
            if (!(t > ray.tmin && t < tmax)) return Vec3();
            float mask = 1.f;
            if (l.type == LightType::Spot) {
                const float cs = dot(normalize(ray.o - l.position), l.axis);
                if (cs <= l.cos_half_spot) return Vec3();
                if (l.spot_smooth > 0.f) mask = smoothstep01((cs - l.cos_half_spot) / l.spot_smooth);
            }
            return l.rgb * (mask / (4.f * kPi * kPi * l.radius * l.radius));
        }
        case LightType::Area: {
            const float dn = dot(ray.d, l.axis);
            if (!(dn < 0.f)) return Vec3();  // one-sided: seen from the side it shines to
            const float t = dot(l.position - ray.o, l.axis) / dn;
            if (!(t > ray.tmin && t < tmax)) return Vec3();
            const Vec3 q = ray.o + ray.d * t - l.position;
            const float x = dot(q, l.u) / l.size_u, y = dot(q, l.v) / l.size_v;  // in -0.5..0.5 inside
            const bool round = l.shape == AreaShape::Disk || l.shape == AreaShape::Ellipse;
            const bool inside = round ? x * x + y * y <= 0.25f : std::fabs(x) <= 0.5f && std::fabs(y) <= 0.5f;
            const float area = l.area();
            return inside && area > 0.f ? l.rgb * (1.f / (kPi * area)) : Vec3();
        }
    }
    return Vec3();
}

float fresnel_dielectric(float cos_i, float eta) {
    cos_i = std::clamp(cos_i, 0.f, 1.f);
    const float sin2_t = (1.f - cos_i * cos_i) / (eta * eta);
    if (sin2_t >= 1.f) return 1.f;  // total internal reflection
    const float cos_t = std::sqrt(1.f - sin2_t);
    const float rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    const float rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    return 0.5f * (rs * rs + rp * rp);
}

float ggx_d(float cos_h, float alpha) {
    if (cos_h <= 0.f) return 0.f;
    const float a2 = alpha * alpha, c2 = cos_h * cos_h;
    const float d = c2 * (a2 - 1.f) + 1.f;
    return a2 / (kPi * d * d);
}

float ggx_g1(float cos_v, float alpha) {
    if (cos_v <= 0.f) return 0.f;
    const float a2 = alpha * alpha, c2 = cos_v * cos_v;
    return 2.f / (1.f + std::sqrt(1.f + a2 * (1.f - c2) / c2));
}

Vec3 sample_ggx_vndf(Vec3 n, Vec3 wo, float alpha, float u1, float u2) {
    const Vec3 t = orthogonal(n), b = cross(n, t);
    const Vec3 v(dot(wo, t), dot(wo, b), dot(wo, n));  // wo in the local frame
    const Vec3 vh = normalize(Vec3(alpha * v.x, alpha * v.y, v.z));
    const float len2 = vh.x * vh.x + vh.y * vh.y;
    const Vec3 t1 = len2 > 0.f ? Vec3(-vh.y, vh.x, 0.f) * (1.f / std::sqrt(len2)) : Vec3(1.f, 0.f, 0.f);
    const Vec3 t2 = cross(vh, t1);
    const float r = std::sqrt(u1), phi = 2.f * kPi * u2;
    const float p1 = r * std::cos(phi);
    float p2 = r * std::sin(phi);
    const float s = 0.5f * (1.f + vh.z);
    p2 = (1.f - s) * std::sqrt(std::fmax(0.f, 1.f - p1 * p1)) + s * p2;
    const Vec3 nh = t1 * p1 + t2 * p2 + vh * std::sqrt(std::fmax(0.f, 1.f - p1 * p1 - p2 * p2));
    const Vec3 m = normalize(Vec3(alpha * nh.x, alpha * nh.y, std::fmax(1e-6f, nh.z)));
    return normalize(t * m.x + b * m.y + n * m.z);
}

}  // namespace splat
