// Shader AOVs (the view layer's AOVs, written by materials' AOV Output nodes), as Cycles
// writes them (kernel/svm/aov.h, kernel/film/aov_passes.h): on the camera ray's surfaces
// up to and including the first one that stops its data passes -- a surface whose alpha is
// at least the view layer's Alpha Threshold (any surface when the threshold is 0) -- each
// surface's AOV Output nodes add their value; a colour AOV adds (r, g, b, 1). The sums are
// divided by the pixel's samples like the other averaged passes, so a pixel whose surfaces
// write nothing keeps 0.
//
// Self-contained: the integrator hands a sink to RenderScene::material_at while the camera
// ray is still writing, and scales the pixel's sums at the end; with no AOV asked for (or
// none written by any material) nothing here runs.
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "nodes/program.h"

namespace splat {

struct AovFilm {
    float *buffer = nullptr;  // channels floats a pixel, rows top first (as the other passes)
    int channels = 0;
    // Per AOV key (the scene's list of AOV names): the first channel of its pass and its
    // width (4: a colour AOV's RGBA, 1: a value AOV), or offset -1 when not asked for.
    std::vector<int32_t> offset, width;
    float alpha_threshold = 0.5f;  // the view layer's pass_alpha_threshold (Cycles' default 0.5)

    bool on() const { return buffer != nullptr; }
    float *pixel(size_t p) const { return buffer + p * size_t(channels); }
    // Whether the camera ray stops writing after a surface of this opacity (Cycles'
    // PATH_RAY_SINGLE_PASS_DONE, set by film_write_data_passes).
    bool done_after(float opacity) const { return alpha_threshold == 0.f || opacity >= alpha_threshold; }
    void scale(size_t p, float inv) const {
        float *px = pixel(p);
        for (int c = 0; c < channels; ++c) px[c] *= inv;
    }
};

// Where one camera-ray sample writes: the film's layout and its pixel's sums.
struct AovSink {
    const AovFilm *film;
    float *pixel;

    // The program's AOV Output nodes, from its registers `r` after it ran. A non-finite value
    // is written as 0: one NaN would otherwise spoil the pixel's every sample.
    void write(const NodeProgram &prog, const float *r) const {
        auto finite = [](float v) { return std::isfinite(v) ? v : 0.f; };
        for (const AovWrite &a : prog.aovs) {
            if (size_t(a.key) >= film->offset.size()) continue;
            const int32_t o = film->offset[size_t(a.key)];
            if (o < 0) continue;
            float *px = pixel + o;
            if (film->width[size_t(a.key)] == 4) {
                for (int k = 0; k < 3; ++k) px[k] += finite(r[a.colour + k]);
                px[3] += 1.f;
            } else {
                px[0] += finite(r[a.value]);
            }
        }
    }
};

}  // namespace splat
