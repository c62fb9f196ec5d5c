#include "shade/render.h"

#include <algorithm>
#include <cmath>

namespace splat {

void Renderer::render_tile(size_t tile) const {
    for_each_block(film_, settings_.tile_size, tile, [&](const int *cols, const int *rows, int n) {
        Ray rays[kPacketRays];
        block_rays(camera_, film_, cols, rows, n, nullptr, rays);
        const bool inside[kPacketRays] = {};
        SurfaceHit hits[kPacketRays];
        if (settings_.packets) find_surfaces(scene_, rays, n, settings_.method, inside, nullptr, 0, hits);
        else
            for (int k = 0; k < n; ++k) hits[k] = find_surface(scene_, rays[k], settings_.method);
        for (int k = 0; k < n; ++k) shade_pixel(cols[k], rows[k], rays[k], hits[k]);
    });
}

// A headlight (a light at the eye): radiance = base colour x |cos| between the ray and the
// splat normal. An open cloud seen from behind is a back face (SplatScene::open_back): its
// normal is written turned towards the ray, as Cycles writes a back face's.
void Renderer::shade_pixel(int col, int row, const Ray &ray, const SurfaceHit &hit) const {
    const size_t p = size_t(row) * film_.w + col;
    float *rgba = film_.combined + 4 * p;
    if (!hit.valid()) {
        // Past everything: the background; a pixel the panorama does not see: black, alpha 0.
        if (Camera::is_none(ray)) std::fill(rgba, rgba + 4, 0.f);
        else std::copy(settings_.background, settings_.background + 4, rgba);
        if (film_.depth) film_.depth[p] = kBackgroundDepth;
        if (film_.normal) std::fill(film_.normal + 3 * p, film_.normal + 3 * p + 3, 0.f);
        return;
    }
    const Vec3 n = scene_.open_back(hit.id, hit.front) ? hit.normal * -1.f : hit.normal;
    const Vec3 c = hit.colour * std::fabs(dot(n, ray.d));
    rgba[0] = c.x, rgba[1] = c.y, rgba[2] = c.z, rgba[3] = 1.f;
    if (film_.depth) film_.depth[p] = float(camera_.depth(ray, hit.t));
    if (film_.normal) {
        float *out = film_.normal + 3 * p;
        out[0] = n.x, out[1] = n.y, out[2] = n.z;
    }
}

}  // namespace splat
