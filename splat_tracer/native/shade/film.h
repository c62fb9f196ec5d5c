// The film: the rendered window of an image and its output buffers, cut into square tiles
// (the unit of work a thread takes, and of progress) and each tile into blocks of 4x4
// pixels (one camera-ray packet, packet.h). One definition for both renderers: the
// integrator (integrator.h) and the headlight preview of one splat cloud (render.h).
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>

#include "base/ray.h"
#include "scene/camera.h"
#include "shade/aov.h"
#include "shade/cryptomatte.h"
#include "shade/sampling.h"
#include "splats/visibility.h"

namespace splat {

// What Cycles writes in Z where nothing is hit.
constexpr float kBackgroundDepth = 1e10f;
// A tile's side in pixels when the caller does not choose one (the bindings' default).
constexpr int kDefaultTileSize = 32;

// Where the pixels go. The image is width x height; the rendered window is the w x h
// rectangle whose top-left pixel is (x0, y0) (column, row from the top), so a border render
// fills only part of the frame. Buffers are w x h, row-major, top row first; any but
// `combined` may be null (not wanted, and then not computed). The headlight renderer writes
// combined, depth and normal only.
struct Film {
    int width = 0, height = 0, x0 = 0, y0 = 0, w = 0, h = 0;
    float *combined = nullptr;  // 4 floats a pixel: scene-linear colour and alpha
    float *depth = nullptr;     // planar depth along the view axis (Cycles' Z); kBackgroundDepth on a miss
    float *normal = nullptr;    // 3 floats: the surface normal, world orientation
    float *diffcol = nullptr, *emit = nullptr, *shadow = nullptr;  // 3 floats each
    float *index = nullptr, *splat_count = nullptr;                // 1 float each
    // 3 floats: Cycles' Shadow Catcher pass (what a photograph is multiplied by: 1 unshadowed).
    // Asked for, it also makes Combined leave the catcher's shadow out, as Cycles does when
    // the pass is on (integrator.cpp, write_catcher).
    float *shadow_catcher = nullptr;
    // Cycles' data passes of the camera ray's first opaque hit, from the pixel-centre sample
    // (Cycles' sample 0; 0 where nothing is hit): its position, 3 floats in the scene's local
    // frame (the caller moves it to world space), and its material's pass index, 1 float.
    float *position = nullptr, *material_index = nullptr;
    // 1 float: Cycles' Mist -- 0 at the mist's start, 1 at start + depth along the distance
    // from the camera (IntegratorSettings::mist_*), 1 where nothing is hit; averaged over samples.
    float *mist = nullptr;
    // 3 floats: Cycles' Environment -- the world as camera rays that leave the scene see it
    // (black where they meet a surface, as Cycles' background pass), averaged over samples.
    float *environment = nullptr;
    // Cycles' light passes (shade/light_passes.h), averaged over samples: 9 planes of w x h x 3
    // floats -- Diffuse, Glossy, Transmission (PassLobe order) Direct, then Indirect, then
    // Color -- all or none (the direct and indirect ones are divided by the colour's sums).
    float *light = nullptr;
    // 3 floats: Cycles' Ambient Occlusion pass (IntegratorSettings::ao_distance).
    float *ao = nullptr;
    // IntegratorSettings::light_groups.count planes of w x h x 3 floats: each light group's
    // Combined (Cycles' "Combined_<group>"), averaged over samples.
    float *light_groups = nullptr;
    // 3 floats: Cycles' UV pass -- the mesh's UV map at the pixel-centre sample's first hit
    // (U, V, A = 1 on a mesh), 0 on clouds and where nothing is hit.
    float *uv = nullptr;
    // 1 float: the pixel-centre sample's first opaque hit's instance + 1 (0 on a miss): with
    // Position, what the Vector pass is computed from (the caller knows each instance's motion).
    float *instance = nullptr;
    // Cryptomatte's object, material and asset passes (shade/cryptomatte.h), integrator only.
    CryptomatteFilm cryptomatte;
    // The view layer's shader AOVs (shade/aov.h); off unless a material writes one asked for.
    AovFilm aov;
};

// What both renderers take the same way.
struct FrameSettings {
    Method method;  // which surface each pixel shows (visibility.h)
    int tile_size = kDefaultTileSize;
    bool packets = true;  // each block's camera rays found as one packet (packet.h); the same image
};

// The film's tiles: tile_size pixels a side, row by row from the window's top left, cut short
// at its right and bottom edges.
inline size_t tile_count(const Film &film, int tile_size) {
    const int64_t ts = tile_size;
    return size_t((film.w + ts - 1) / ts) * size_t((film.h + ts - 1) / ts);
}

// The pixels of tile `tile` in blocks of 4x4, rows of blocks from the top (cut short at the
// tile's edges): block(cols, rows, n) with each of the block's n pixels' column and row in
// the window, row by row -- one camera-ray packet each.
template <class Block>
void for_each_block(const Film &film, int tile_size, size_t tile, Block &&block) {
    const int ts = tile_size;
    const int tiles_x = int((int64_t(film.w) + ts - 1) / ts);
    const int x0 = int(tile % size_t(tiles_x)) * ts, y0 = int(tile / size_t(tiles_x)) * ts;
    const int x1 = std::min(x0 + ts, film.w), y1 = std::min(y0 + ts, film.h);
    constexpr int kBlock = 4;
    static_assert(kBlock * kBlock == kPacketRays, "a block is one packet");
    for (int by = y0; by < y1; by += kBlock)
        for (int bx = x0; bx < x1; bx += kBlock) {
            int cols[kPacketRays], rows[kPacketRays], n = 0;
            for (int row = by; row < std::min(by + kBlock, y1); ++row)
                for (int col = bx; col < std::min(bx + kBlock, x1); ++col, ++n) cols[n] = col, rows[n] = row;
            block(cols, rows, n);
        }
}

// The camera rays of a block's n pixels (window column and row), pixel k's through its
// centre moved by (offsets[2k], offsets[2k + 1]) pixels (its sample's offset; null: centres).
inline void block_rays(const Camera &camera, const Film &film, const int *cols, const int *rows, int n,
                       const double *offsets, Ray *rays) {
    for (int k = 0; k < n; ++k) {
        const double dx = offsets ? offsets[2 * k] : 0.0, dy = offsets ? offsets[2 * k + 1] : 0.0;
        rays[k] = camera.ray(film.x0 + cols[k] + 0.5 + dx, film.y0 + rows[k] + 0.5 + dy, film.width, film.height);
    }
}

// The point of a camera's lens (camera-space x, y) for uniform numbers u1, u2 in [0, 1):
// Cycles' camera_sample_aperture -- a uniform point of the unit disc (concentric map) or of
// the polygon of camera.blades corners, its x divided by the aperture ratio -- times the
// aperture's radius.
inline void lens_point(const Camera &camera, float u1, float u2, double *x, double *y) {
    float bx, by;
    if (camera.blades >= 3) sample_polygon(camera.blades, float(camera.blade_rotation), u1, u2, &bx, &by);
    else sample_disk(u1, u2, &bx, &by);
    *x = double(bx) / camera.aperture_ratio * camera.lens_radius, *y = double(by) * camera.lens_radius;
}

// block_rays() through the lens: pixel k's ray leaves the lens at (lens[2k], lens[2k + 1]).
inline void block_lens_rays(const Camera &camera, const Film &film, const int *cols, const int *rows, int n,
                            const double *offsets, const double *lens, Ray *rays) {
    for (int k = 0; k < n; ++k)
        rays[k] = camera.ray_through_lens(film.x0 + cols[k] + 0.5 + offsets[2 * k],
                                          film.y0 + rows[k] + 0.5 + offsets[2 * k + 1], film.width, film.height,
                                          lens[2 * k], lens[2 * k + 1]);
}

}  // namespace splat
