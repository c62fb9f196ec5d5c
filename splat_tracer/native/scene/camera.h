// Camera rays from the camera's own parameters, in double precision: a pinhole or an
// orthographic camera, its image rectangle (sensor fit, lens shift and any view zoom
// already folded in by whoever built it: render.camera.Camera), its clipping range and
// optionally a thin lens (depth of field), whose rays are those of Cycles'
// camera_sample_perspective and camera_sample_orthographic.
// No projection matrix is inverted: with a clipping range of 1e8 or more, a float32
// projection (Blender's) unprojects its far plane to w = 0, and even a double one loses
// the far plane at the ranges Blender allows (1e-6 to 3.4e38).
// A panoramic camera (render.camera.Panorama) maps the image to directions as Cycles'
// kernel/camera/projection.h does; its rays all leave the camera's centre (or its lens).
#pragma once

#include <algorithm>
#include <cmath>

#include "base/ray.h"
#include "scene/motion.h"

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
    // The projection: render.camera.PROJECTIONS' index (kPlanar: pinhole or orthographic,
    // as `orthographic` says) and its parameters (render.camera.Panorama.native()). For a
    // panorama, frustum is the image's (u, v) rectangle in Cycles' panorama coordinates
    // ((0, 1, 0, 1) shifted by the lens shift), which the projection maps to directions.
    enum Projection { kPlanar = 0, kEquirectangular, kFisheyeEquidistant, kFisheyeEquisolid, kMirrorball, kProjections };
    int projection = kPlanar;
    double pano[5] = {0, 0, 0, 0, 0};

    // Motion blur: local_from_camera at evenly spaced times over the shutter (motion.h),
    // held by the caller for the render; null when the camera does not move.
    const MotionKey *motion = nullptr;
    int motion_steps = 0;

    bool has_lens() const { return lens_radius > 0.0; }
    bool moves() const { return motion != nullptr && motion_steps > 0; }

    // This camera at shutter time `time` (0 opens it, 1 closes it).
    Camera at(double time) const {
        Camera c = *this;
        if (moves()) {
            motion::at(motion, motion_steps, time, c.local_from_camera);
            c.derive_axes();
        }
        return c;
    }
    bool panoramic() const { return projection != kPlanar; }

    // A pixel a panorama does not see (outside a fisheye's circle, or beyond a mirror
    // ball): Cycles traces nothing there and writes black with alpha 0. none() is that
    // ray: it has no length, and is_none() tells it.
    static Ray none() {
        Ray ray;
        ray.o = Vec3(0.f, 0.f, 0.f), ray.d = Vec3(0.f, 0.f, -1.f), ray.tmin = 0.f, ray.tmax = 0.f;
        return ray;
    }
    static bool is_none(const Ray &ray) { return !(ray.tmax > 0.f); }

    // The unit camera-space direction (looking down -Z, +Y up) of panorama coordinates
    // (u, v) in [0, 1] (v upwards), or false where the projection sees nothing. Cycles'
    // panorama space looks down +X with +Z up (+Y to the left); its blender/camera.cpp
    // turns it into Blender's camera space, so x_cycles = -z, y_cycles = -x, z_cycles = y
    // (a mirror ball: x_cycles = x, y_cycles = z, z_cycles = y), which is folded in here.
    bool panorama_direction(double u, double v, double d[3]) const {
        switch (projection) {
            case kEquirectangular: {
                // pano = (longitude min, max, latitude min, max), radians: u runs the
                // longitude from min to max (positive towards the camera's +X), v the
                // latitude from min to max (positive upwards).
                const double lon = pano[0] + (pano[1] - pano[0]) * u, lat = pano[2] + (pano[3] - pano[2]) * v;
                d[0] = std::cos(lat) * std::sin(lon), d[1] = std::sin(lat), d[2] = -std::cos(lat) * std::cos(lon);
                return true;
            }
            case kFisheyeEquidistant:
            case kFisheyeEquisolid: {
                // Equidistant: pano = (field of view); the image's unit square is the
                // circle's [-1, 1] square, the angle from the view axis is r fov / 2.
                // Equisolid: pano = (lens, field of view, sensor width, sensor height) (lens
                // and sensor in mm): r on the sensor is 2 lens sin(angle / 2), cut at fov / 2.
                double x, y, theta;
                if (projection == kFisheyeEquidistant) {
                    x = (u - 0.5) * 2.0, y = (v - 0.5) * 2.0;
                    const double r = std::sqrt(x * x + y * y);
                    if (r > 1.0) return false;
                    theta = r * pano[0] * 0.5;
                } else {
                    x = (u - 0.5) * pano[2], y = (v - 0.5) * pano[3];
                    const double r = std::sqrt(x * x + y * y);
                    if (r > 2.0 * pano[0] * std::sin(pano[1] * 0.25)) return false;
                    theta = 2.0 * std::asin(std::min(r / (2.0 * pano[0]), 1.0));
                }
                const double r = std::sqrt(x * x + y * y), s = std::sin(theta);
                d[0] = r > 0.0 ? s * x / r : 0.0, d[1] = r > 0.0 ? s * y / r : 0.0, d[2] = -std::cos(theta);
                return true;
            }
            case kMirrorball: {
                // Cycles' mirror ball: (u, v) in [0, 1]^2 is a unit ball's disc, (x, y, z)
                // the ball's normal there; the direction is the normal's reflection of
                // Cycles' incoming ray, so that the disc's centre looks down the view axis
                // and its rim straight back.
                const double x = 2.0 * u - 1.0, y = 2.0 * v - 1.0, rr = x * x + y * y;
                if (rr > 1.0) return false;
                const double z = std::sqrt(std::max(1.0 - rr, 0.0));
                d[0] = 2.0 * z * x, d[1] = 2.0 * z * y, d[2] = 1.0 - 2.0 * z * z;
                return true;
            }
            default:
                return false;
        }
    }

    // The inverse of panorama_direction: the panorama coordinates (u, v) of a camera-space
    // direction d (unit), as Cycles' direction_to_panorama gives them (its Window texture
    // coordinates): unclamped, so that a direction the panorama does not see lies outside
    // 0..1 as Cycles' does.
    void panorama_uv(const double d[3], double *u, double *v) const {
        *u = *v = 0.0;
        switch (projection) {
            case kEquirectangular: {
                const double lon = std::atan2(d[0], -d[2]), lat = std::asin(std::min(std::max(d[1], -1.0), 1.0));
                if (pano[1] != pano[0]) *u = (lon - pano[0]) / (pano[1] - pano[0]);
                if (pano[3] != pano[2]) *v = (lat - pano[2]) / (pano[3] - pano[2]);
                return;
            }
            case kFisheyeEquidistant:
            case kFisheyeEquisolid: {
                const double theta = std::acos(std::min(std::max(-d[2], -1.0), 1.0)), phi = std::atan2(d[1], d[0]);
                if (projection == kFisheyeEquidistant) {
                    const double r = pano[0] > 0.0 ? theta / pano[0] : 0.0;
                    *u = r * std::cos(phi) + 0.5, *v = r * std::sin(phi) + 0.5;
                } else {
                    const double r = 2.0 * pano[0] * std::sin(theta * 0.5);
                    *u = pano[2] > 0.0 ? r * std::cos(phi) / pano[2] + 0.5 : 0.5;
                    *v = pano[3] > 0.0 ? r * std::sin(phi) / pano[3] + 0.5 : 0.5;
                }
                return;
            }
            case kMirrorball: {
                // d = 2 z (x, y, z) - (0, 0, 1) for the ball's normal (x, y, z): z from d's last
                // component, then x and y.
                const double z = std::sqrt(std::max(0.5 * (1.0 - d[2]), 0.0));
                const double x = z > 0.0 ? d[0] / (2.0 * z) : 0.0, y = z > 0.0 ? d[1] / (2.0 * z) : 0.0;
                *u = 0.5 * (x + 1.0), *v = 0.5 * (y + 1.0);
                return;
            }
            default:
                return;
        }
    }

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
    // A panorama's ray leaves the camera's centre along its pixel's direction, from
    // clip_start to clip_end along it; none() where the projection sees nothing.
    Ray ray(double px, double py, int width, int height) const {
        const double fx = px / width, fy = 1.0 - py / height;
        const double u = frustum[0] + (frustum[1] - frustum[0]) * fx;
        const double v = frustum[2] + (frustum[3] - frustum[2]) * fy;
        if (panoramic()) {
            double dir[3];
            if (!panorama_direction(u, v, dir)) return none();
            const double start[3] = {dir[0] * clip_start, dir[1] * clip_start, dir[2] * clip_start};
            return local_ray(start, dir);
        }
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
        if (panoramic()) {
            // Cycles' camera_sample_panorama: the lens is the disc across the pixel's
            // direction D (axes U, V: Cycles' panorama axis x_cycles made perpendicular to
            // D, and D x U); the ray leaves the lens point towards f D (a sphere in focus).
            double d[3];
            if (!panorama_direction(u, v, d)) return none();
            double a[3] = {0.0, 0.0, -1.0};  // x_cycles in camera space (see panorama_direction)
            if (projection == kMirrorball) a[0] = 1.0, a[2] = 0.0;
            const double ad = a[0] * d[0] + a[1] * d[1] + a[2] * d[2];
            double U[3] = {a[0] - ad * d[0], a[1] - ad * d[1], a[2] - ad * d[2]};
            double ul = std::sqrt(U[0] * U[0] + U[1] * U[1] + U[2] * U[2]);
            // D along x_cycles (where Cycles' normalize(0) is undefined): take camera +X,
            // which is perpendicular to it.
            if (!(ul > 1e-12)) U[0] = 1.0, U[1] = U[2] = 0.0, ul = 1.0;
            for (double &c : U) c /= ul;
            // V = D x U; the mirror ball's axes are a reflection of Cycles' (x, z, y), so
            // its cross product changes sign.
            const double sign = projection == kMirrorball ? -1.0 : 1.0;
            const double V[3] = {sign * (d[1] * U[2] - d[2] * U[1]), sign * (d[2] * U[0] - d[0] * U[2]),
                                 sign * (d[0] * U[1] - d[1] * U[0])};
            double p[3], len = 0.0;
            for (int k = 0; k < 3; ++k) p[k] = U[k] * lx + V[k] * ly, dir[k] = d[k] * f - p[k], len += dir[k] * dir[k];
            len = std::sqrt(len);
            for (int k = 0; k < 3; ++k) dir[k] /= len, start[k] = p[k] + dir[k] * clip_start;
        } else if (orthographic) {
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

    // The Depth pass: the distance along the view axis, or for a panorama the distance
    // from the camera's centre (Cycles' camera_z_depth).
    double depth(const Ray &r, float t) const {
        double p[3] = {double(r.o.x) + double(r.d.x) * t, double(r.o.y) + double(r.d.y) * t,
                       double(r.o.z) + double(r.d.z) * t};
        if (panoramic())
            return std::sqrt((p[0] - position[0]) * (p[0] - position[0]) + (p[1] - position[1]) * (p[1] - position[1]) +
                             (p[2] - position[2]) * (p[2] - position[2]));
        return (p[0] - position[0]) * forward[0] + (p[1] - position[1]) * forward[1] +
               (p[2] - position[2]) * forward[2];
    }
};

}  // namespace splat
