// Camera rays from the camera's own parameters, in double precision: a pinhole or an
// orthographic camera, its image rectangle (sensor fit, lens shift and any view zoom
// already folded in by whoever built it: render.camera.Camera), its clipping range and
// optionally a thin lens (depth of field), whose rays are those of Cycles'
// camera_sample_perspective and camera_sample_orthographic.
// No projection matrix is inverted: with a clipping range of 1e8 or more, a float32
// projection (Blender's) unprojects its far plane to w = 0, and even a double one loses
// the far plane at the ranges Blender allows (1e-6 to 3.4e38).
#pragma once

#include <cmath>

#include "base/ray.h"

namespace splat {

struct Camera {
    // Row-major 3x4: camera space (looking down -Z, +Y up) to the scene's local frame.
    double local_from_camera[12];
    // The image rectangle (left, right, bottom, top) on the plane at unit distance in front
    // of a pinhole camera, or on the view plane of an orthographic one (scene units).
    double frustum[4];
    double clip_start, clip_end;  // distances along the view axis; clip_start < clip_end
    bool orthographic = false;
    double position[3];  // the camera's centre (local frame)
    double forward[3];   // unit view axis: planar depth = (p - position) . forward
    // The thin lens (render.camera.Lens), in camera space; lens_radius 0: a pinhole.
    double lens_radius = 0.0;     // the aperture's radius (scene units)
    double focus_distance = 1.0;  // the plane in focus, along the view axis from the camera
    int blades = 0;               // 0: a disc; >= 3: a regular polygon
    double blade_rotation = 0.0;  // radians
    double aperture_ratio = 1.0;  // anamorphic: the aperture's x extent is divided by it

    bool has_lens() const { return lens_radius > 0.0; }

    // position and forward from local_from_camera; false when its view axis has no length.
    bool derive_axes() {
        const double *m = local_from_camera;
        double len = std::sqrt(m[2] * m[2] + m[6] * m[6] + m[10] * m[10]);
        for (int r = 0; r < 3; ++r) position[r] = m[4 * r + 3], forward[r] = len > 0 ? -m[4 * r + 2] / len : 0.0;
        return len > 0 && std::isfinite(len);
    }

    // Ray through raster position (px, py) of a width x height image, raster y downwards
    // (the centre of the pixel in column j, row i from the top is (j + 0.5, i + 0.5)). It
    // starts on the near clipping plane and ends on the far one. Double precision here,
    // float from here on: the local frame keeps the coordinates small.
    Ray ray(double px, double py, int width, int height) const {
        const double fx = px / width, fy = 1.0 - py / height;
        const double u = frustum[0] + (frustum[1] - frustum[0]) * fx;
        const double v = frustum[2] + (frustum[3] - frustum[2]) * fy;
        // Camera space: a pinhole's ray leaves its centre along (u, v, -1) and is clipped
        // at clip_start and clip_end times that vector; an orthographic ray leaves (u, v)
        // along -Z.
        const double dir[3] = {orthographic ? 0.0 : u, orthographic ? 0.0 : v, -1.0};
        const double start[3] = {orthographic ? u : u * clip_start, orthographic ? v : v * clip_start, -clip_start};
        return local_ray(start, dir);
    }

    // ray() through the point (lx, ly) of the lens (camera space: shade/film.h's
    // lens_point): it leaves that point towards where the pinhole ray meets the plane in
    // focus (for an orthographic camera, the plane focus_distance in front of the camera),
    // starts where Cycles' starts (on the near plane: the perspective ray clip_start along
    // the view axis of its pinhole ray, as Cycles' z_inv measures it) and runs as far.
    Ray ray_through_lens(double px, double py, int width, int height, double lx, double ly) const {
        const double fx = px / width, fy = 1.0 - py / height;
        const double u = frustum[0] + (frustum[1] - frustum[0]) * fx;
        const double v = frustum[2] + (frustum[3] - frustum[2]) * fy;
        const double f = focus_distance;
        double dir[3], start[3];  // camera space
        if (orthographic) {
            // A unit direction from (u + lx, v + ly, 0) to (u, v, -f), started on the near plane.
            const double len = std::sqrt(lx * lx + ly * ly + f * f);
            dir[0] = -lx / len, dir[1] = -ly / len, dir[2] = -f / len;
            const double reach = clip_start / -dir[2];
            start[0] = u + lx + dir[0] * reach, start[1] = v + ly + dir[1] * reach, start[2] = -clip_start;
        } else {
            // From (lx, ly, 0) to f (u, v, -1), scaled to the length of (u, v, -1) so that
            // the clip distances measure it as they measure the pinhole ray.
            dir[0] = u * f - lx, dir[1] = v * f - ly, dir[2] = -f;
            const double scale = std::sqrt(u * u + v * v + 1.0) /
                                 std::sqrt(dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]);
            for (double &c : dir) c *= scale;
            start[0] = lx + dir[0] * clip_start, start[1] = ly + dir[1] * clip_start, start[2] = dir[2] * clip_start;
        }
        return local_ray(start, dir);
    }

    // A camera-space ray (its start and its unnormalised direction, whose length the clip
    // distances measure) in the scene's local space, in float.
    Ray local_ray(const double start[3], const double dir[3]) const {
        const double *m = local_from_camera;
        double o[3], d[3];
        for (int r = 0; r < 3; ++r) {
            o[r] = m[4 * r] * start[0] + m[4 * r + 1] * start[1] + m[4 * r + 2] * start[2] + m[4 * r + 3];
            d[r] = m[4 * r] * dir[0] + m[4 * r + 1] * dir[1] + m[4 * r + 2] * dir[2];
        }
        const double len = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
        Ray ray;
        ray.o = Vec3(float(o[0]), float(o[1]), float(o[2]));
        ray.d = Vec3(float(d[0] / len), float(d[1] / len), float(d[2] / len));
        ray.tmin = 0.f;
        ray.tmax = float((clip_end - clip_start) * len);  // inf beyond float's range: unclipped
        return ray;
    }

    double planar_depth(const Ray &r, float t) const {
        double p[3] = {double(r.o.x) + double(r.d.x) * t, double(r.o.y) + double(r.d.y) * t,
                       double(r.o.z) + double(r.d.z) * t};
        return (p[0] - position[0]) * forward[0] + (p[1] - position[1]) * forward[1] +
               (p[2] - position[2]) * forward[2];
    }
};

}  // namespace splat
