#include "shade/render.h"

#include <algorithm>
#include <cmath>

#include "bvh/packet.h"

namespace splat {

size_t Renderer::tile_count() const {
    const int ts = settings_.tile_size;
    return size_t((target_.w + ts - 1) / ts) * size_t((target_.h + ts - 1) / ts);
}

void Renderer::render_tile(size_t tile) const {
    const int ts = settings_.tile_size;
    const int tiles_x = (target_.w + ts - 1) / ts;
    const int tx = int(tile % tiles_x) * ts, ty = int(tile / tiles_x) * ts;
    // In blocks of 4x4 pixels: one ray packet each (packet.h).
    for_each_block(tx, ty, std::min(tx + ts, target_.w), std::min(ty + ts, target_.h),
                   [&](const int *cols, const int *rows, int n) {
                       Ray rays[kPacketRays];
                       for (int k = 0; k < n; ++k)
                           rays[k] = camera_.ray(target_.x0 + cols[k] + 0.5, target_.y0 + rows[k] + 0.5,
                                                 target_.width, target_.height);
                       const bool inside[kPacketRays] = {};
                       SurfaceHit hits[kPacketRays];
                       if (settings_.packets) find_surfaces(scene_, rays, n, settings_.method, inside, nullptr, 0, hits);
                       else
                           for (int k = 0; k < n; ++k) hits[k] = find_surface(scene_, rays[k], settings_.method);
                       for (int k = 0; k < n; ++k) shade_pixel(cols[k], rows[k], rays[k], hits[k]);
                   });
}

// Simple shading until lights and materials arrive: a headlight (a light at the eye),
// so radiance = base colour x |cos| between the ray and the splat normal.
void Renderer::shade_pixel(int col, int row, const Ray &ray, const SurfaceHit &hit) const {
    const size_t p = size_t(row) * target_.w + col;
    float *rgba = target_.rgba + 4 * p;
    if (!hit.valid()) {
        std::copy(settings_.background, settings_.background + 4, rgba);
        if (target_.depth) target_.depth[p] = settings_.background_depth;
        if (target_.normal) std::fill(target_.normal + 3 * p, target_.normal + 3 * p + 3, 0.f);
        return;
    }
    const Vec3 n = hit.normal;
    const Vec3 c = hit.colour * std::fabs(dot(n, ray.d));
    rgba[0] = c.x, rgba[1] = c.y, rgba[2] = c.z, rgba[3] = 1.f;
    if (target_.depth) target_.depth[p] = float(camera_.planar_depth(ray, hit.t));
    if (target_.normal) {
        float *out = target_.normal + 3 * p;
        out[0] = n.x, out[1] = n.y, out[2] = n.z;
    }
}

}  // namespace splat
