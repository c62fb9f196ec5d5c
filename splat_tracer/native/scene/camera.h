// Camera rays from an inverse view-projection matrix: one model for perspective and
// orthographic cameras, with sensor fit, lens shift and clipping already folded in by
// whoever built the matrix (Blender's camera.calc_matrix_camera, or core.Camera).
#pragma once

#include <cmath>

#include "base/ray.h"

namespace splat {

struct Camera {
    // Row-major 4x4 taking normalised device coordinates (x, y in [-1, 1], y up; z = -1 on
    // the near clipping plane, +1 on the far one, OpenGL convention) to homogeneous points
    // of the scene's local frame.
    double local_from_ndc[16];
    double position[3];  // the camera's centre (local frame)
    double forward[3];   // unit view axis: planar depth = (p - position) . forward

    void unproject(double x, double y, double z, double out[3]) const {
        const double *m = local_from_ndc;
        double w = m[12] * x + m[13] * y + m[14] * z + m[15];
        for (int r = 0; r < 3; ++r) out[r] = (m[4 * r] * x + m[4 * r + 1] * y + m[4 * r + 2] * z + m[4 * r + 3]) / w;
    }

    // Ray through raster position (px, py) of a width x height image, raster y downwards
    // (the centre of the pixel in column j, row i from the top is (j + 0.5, i + 0.5)). It
    // starts on the near clipping plane and ends on the far one. Double precision here,
    // float from here on: the local frame keeps the coordinates small.
    Ray ray(double px, double py, int width, int height) const {
        const double x = 2.0 * px / width - 1.0, y = 1.0 - 2.0 * py / height;
        double a[3], b[3];
        unproject(x, y, -1.0, a);
        unproject(x, y, 1.0, b);
        const double d[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
        const double len = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
        Ray r;
        r.o = Vec3(float(a[0]), float(a[1]), float(a[2]));
        r.d = Vec3(float(d[0] / len), float(d[1] / len), float(d[2] / len));
        r.tmin = 0.f;
        r.tmax = float(len);
        return r;
    }

    double planar_depth(const Ray &r, float t) const {
        double p[3] = {double(r.o.x) + double(r.d.x) * t, double(r.o.y) + double(r.d.y) * t,
                       double(r.o.z) + double(r.d.z) * t};
        return (p[0] - position[0]) * forward[0] + (p[1] - position[1]) * forward[1] +
               (p[2] - position[2]) * forward[2];
    }
};

}  // namespace splat
