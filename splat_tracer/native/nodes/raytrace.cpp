// The shader nodes that ask the scene for more than the shading point (nodes/raytrace.h).
#include "nodes/raytrace.h"

#include <algorithm>
#include <cmath>

#include "shade/sampling.h"

namespace splat {

namespace {

// Two unit tangents of unit n, as Cycles' make_orthonormals picks them (the Wireframe's
// footprint and the Bevel's axes are measured along them, so the same pair as Cycles').
void cycles_orthonormals(Vec3 n, Vec3 *a, Vec3 *b) {
    const Vec3 t = (n.x != n.y || n.x != n.z) ? Vec3(n.z - n.y, n.x - n.z, n.y - n.x)   // (1,1,1) x n
                                              : Vec3(n.z - n.y, n.x + n.z, -n.y - n.x);  // (-1,1,1) x n
    *a = normalize(t);
    *b = cross(n, *a);
}

}  // namespace

// Cycles' Ambient Occlusion node (svm_ao): the share of `samples` cosine-distributed rays about
// the normal (turned inwards for Inside) that meet nothing within `distance`. Without a scene
// to trace (ShadingQueries absent), 1: unoccluded, as Cycles gives where it cannot trace.
float ambient_occlusion(const ShaderGlobals &sg, Vec3 n, float distance, int samples, int flags, uint32_t key) {
    if (sg.queries && (flags & 4)) distance = sg.queries->ao_distance();  // Cycles' global radius
    if (!sg.queries || !(distance > 0.f) || samples < 1) return 1.f;
    const float len2 = dot(n, n);
    n = len2 > 0.f && std::isfinite(len2) ? n * (1.f / std::sqrt(len2)) : sg.N;
    if (flags & 1) n = n * -1.f;
    int open = 0;
    for (int i = 0; i < samples; ++i) {
        float u[2];
        sg.queries->random(key, u, 2, uint32_t(i), uint32_t(samples));
        if (!sg.queries->occluded(sample_cosine(n, u[0], u[1]), distance, (flags & 2) != 0)) ++open;
    }
    return float(open) / float(samples);
}

// Cycles' Wireframe node: 1 where the point lies within size / 2 of one of its triangle's
// edges (every edge of the triangle: a triangulated quad shows its diagonal, as in Cycles),
// size in scene units or, with Pixel Size, in pixels of the camera's footprint there. Cycles
// compares the squared distance, |edge x (P - corner)|^2 < |edge|^2 (size / 2)^2: so does this.
// Not a mesh's triangle (a point cloud's splat): 0, as Cycles gives off triangles.
float wireframe(const ShaderGlobals &sg, float size, bool pixel_size) {
    if (!sg.has_triangle) return 0.f;
    float width = 1.f;
    if (pixel_size) {
        // Cycles spreads the footprint along the surface (two perpendicular tangents of its
        // geometric normal, Cycles' make_orthonormals) and measures them across the view.
        const float w = sg.queries ? sg.queries->pixel_width(sg.P) : 0.f;
        Vec3 a, b;
        cycles_orthonormals(sg.Ng, &a, &b);
        width = w * 0.5f * (length(a - sg.I * dot(a, sg.I)) + length(b - sg.I * dot(b, sg.I)));
    }
    width *= 0.5f * size;
    width *= width;
    for (int i = 0; i < 3; ++i) {
        const Vec3 &a = sg.triangle[i], &b = sg.triangle[i ? i - 1 : 2];
        const Vec3 edge = a - b, crs = cross(edge, sg.P - a);
        if (dot(crs, crs) < dot(edge, edge) * width) return 1.f;
    }
    return 0.f;
}

// Cycles' Bevel node (svm_bevel): the shading normal averaged over the surfaces of the
// point's own mesh within `radius`, found by rays along the normal (or, a quarter each, along
// two tangents: multiple importance sampling of the three axes) through points of a disk
// about the point, spread by the cubic profile 10 (R - r)^3 / (pi R^5). Cycles' way, from its
// definitions; it keeps the nearest 4 surfaces along each ray where Cycles keeps a random 4
// of all (the same below 5). Without rays to trace, after a rough bounce (Cycles skips it
// once min_ray_pdf < 8) or for a cloud, the shading normal.
Vec3 bevel(const ShaderGlobals &sg, float radius, int samples, uint32_t key) {
    if (!sg.queries || !sg.has_triangle || !(radius > 0.f) || samples < 1) return sg.N;
    constexpr float kMinRayPdf = 8.f;  // Cycles' threshold: a blurry path does not see the bevel
    if (sg.queries->min_ray_pdf() < kMinRayPdf) return sg.N;
    constexpr int kMaxHits = 4;  // Cycles' LOCAL_MAX_HITS
    auto profile = [radius](float r) {  // the cubic profile's density over the disk
        if (r >= radius) return 0.f;
        const float f = radius - r, r2 = radius * radius;
        return 10.f * f * f * f / (r2 * r2 * radius * kPi);
    };
    // The profile's radius for a uniform xi: the root in 0..1 of its cumulative distribution
    // 10x^2 - 20x^3 + 15x^4 - 4x^5 = xi, by Newton's iteration (a few steps: its slope
    // 20x(1-x)^3 is gentle inside 0.02..0.98).
    auto sample_radius = [](float xi) {
        float x = 0.25f;
        for (int i = 0; i < 10; ++i) {
            const float x2 = x * x, x3 = x2 * x, nx = 1.f - x;
            const float f = 10.f * x2 - 20.f * x3 + 15.f * x2 * x2 - 4.f * x2 * x3 - xi;
            const float slope = 20.f * x * nx * nx * nx;
            if (std::fabs(f) < 1e-6f || slope == 0.f) break;
            x = std::fmin(std::fmax(x - f / slope, 0.f), 1.f);
        }
        return x;
    };
    // The frame about the geometric normal, Cycles' pair, so that the axes match.
    const Vec3 ng = sg.Ng;
    Vec3 t0, b0;
    cycles_orthonormals(ng, &t0, &b0);
    Vec3 sum;
    for (int i = 0; i < samples; ++i) {
        float u[2];
        sg.queries->random(key, u, 2, uint32_t(i), uint32_t(samples));
        Vec3 axis = ng, t = t0, b = b0;
        float pick[3];  // the chances of the normal, the first and the second tangent as the axis
        if (u[0] < 0.5f) {
            pick[0] = 0.5f, pick[1] = pick[2] = 0.25f, u[0] *= 2.f;
        } else if (u[0] < 0.75f) {
            std::swap(axis, t);
            pick[0] = 0.25f, pick[1] = 0.5f, pick[2] = 0.25f, u[0] = (u[0] - 0.5f) * 4.f;
        } else {
            std::swap(axis, b);
            pick[0] = pick[1] = 0.25f, pick[2] = 0.5f, u[0] = (u[0] - 0.75f) * 4.f;
        }
        const float phi = 2.f * kPi * u[0], disk_r = sample_radius(u[1]) * radius;
        const float height = std::sqrt(std::fmax(radius * radius - disk_r * disk_r, 0.f));
        const Vec3 o = sg.P + axis * height + t * (disk_r * std::cos(phi)) + b * (disk_r * std::sin(phi));
        ShadingQueries::LocalHit hits[kMaxHits];
        const int n = sg.queries->local_hits(o, axis * -1.f, 2.f * height, hits, kMaxHits);
        const float disk_pdf = profile(disk_r);
        for (int h = 0; h < n; ++h) {
            const float pn = pick[0] * std::fabs(dot(axis, hits[h].ng)), pt = pick[1] * std::fabs(dot(t, hits[h].ng)),
                        pb = pick[2] * std::fabs(dot(b, hits[h].ng));
            const float denom = pn * pn + pt * pt + pb * pb;
            if (!(denom > 0.f) || !(disk_pdf > 0.f)) continue;
            // The power heuristic over the three axes (pn cancels in weight / pdf).
            const float w = pn / denom * profile(length(hits[h].p - sg.P)) / disk_pdf;
            sum = sum + hits[h].n * w;
        }
    }
    const float len2 = dot(sum, sum);
    if (!(len2 > 0.f) || !std::isfinite(len2)) return sg.N;
    const Vec3 n = sum * (1.f / std::sqrt(len2));
    return sg.backfacing > 0.f ? n * -1.f : n;
}

}  // namespace splat
