// Transforms over the shutter (motion blur). A moving instance or camera carries its
// transform at evenly spaced times of the shutter ("motion steps", the first at the shutter's
// opening, the last at its closing), each decomposed as Cycles' transform_motion_decompose
// does -- a translation, a rotation (unit quaternion) and a stretch (scale and shear, the
// polar decomposition's symmetric factor) -- so that a time between two steps interpolates
// translation and stretch linearly and the rotation by slerp: a spinning object keeps its
// size, which a blend of the matrices would shrink. All in double: a step's decomposition
// and its composition back agree to about 1e-15.
#pragma once

#include <algorithm>
#include <cmath>

namespace splat {

struct MotionKey {
    double t[3] = {0, 0, 0};
    double q[4] = {1, 0, 0, 0};  // (w, x, y, z), unit
    double s[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};  // row-major 3x3
};

namespace motion {

inline double det3(const double a[9]) {
    return a[0] * (a[4] * a[8] - a[5] * a[7]) - a[1] * (a[3] * a[8] - a[5] * a[6]) + a[2] * (a[3] * a[7] - a[4] * a[6]);
}

// inv = a^-1 (row-major 3x3); false when a is singular or not finite.
inline bool invert3(const double a[9], double inv[9]) {
    const double d = det3(a);
    if (!(std::isfinite(d) && d != 0.0)) return false;
    const double r = 1.0 / d;
    inv[0] = (a[4] * a[8] - a[5] * a[7]) * r, inv[1] = (a[2] * a[7] - a[1] * a[8]) * r,
    inv[2] = (a[1] * a[5] - a[2] * a[4]) * r;
    inv[3] = (a[5] * a[6] - a[3] * a[8]) * r, inv[4] = (a[0] * a[8] - a[2] * a[6]) * r,
    inv[5] = (a[2] * a[3] - a[0] * a[5]) * r;
    inv[6] = (a[3] * a[7] - a[4] * a[6]) * r, inv[7] = (a[1] * a[6] - a[0] * a[7]) * r,
    inv[8] = (a[0] * a[4] - a[1] * a[3]) * r;
    return true;
}

inline void rotation_of(const double q[4], double r[9]) {
    const double w = q[0], x = q[1], y = q[2], z = q[3];
    r[0] = 1 - 2 * (y * y + z * z), r[1] = 2 * (x * y - w * z), r[2] = 2 * (x * z + w * y);
    r[3] = 2 * (x * y + w * z), r[4] = 1 - 2 * (x * x + z * z), r[5] = 2 * (y * z - w * x);
    r[6] = 2 * (x * z - w * y), r[7] = 2 * (y * z + w * x), r[8] = 1 - 2 * (x * x + y * y);
}

// The unit quaternion of a proper rotation matrix (Shepperd's method: the largest of the
// four squares is taken first, so no division by a value near 0).
inline void quaternion_of(const double r[9], double q[4]) {
    const double tr = r[0] + r[4] + r[8];
    if (tr > 0) {
        const double s = 2.0 * std::sqrt(tr + 1.0);
        q[0] = 0.25 * s, q[1] = (r[7] - r[5]) / s, q[2] = (r[2] - r[6]) / s, q[3] = (r[3] - r[1]) / s;
    } else if (r[0] > r[4] && r[0] > r[8]) {
        const double s = 2.0 * std::sqrt(1.0 + r[0] - r[4] - r[8]);
        q[0] = (r[7] - r[5]) / s, q[1] = 0.25 * s, q[2] = (r[1] + r[3]) / s, q[3] = (r[2] + r[6]) / s;
    } else if (r[4] > r[8]) {
        const double s = 2.0 * std::sqrt(1.0 + r[4] - r[0] - r[8]);
        q[0] = (r[2] - r[6]) / s, q[1] = (r[1] + r[3]) / s, q[2] = 0.25 * s, q[3] = (r[5] + r[7]) / s;
    } else {
        const double s = 2.0 * std::sqrt(1.0 + r[8] - r[0] - r[4]);
        q[0] = (r[3] - r[1]) / s, q[1] = (r[2] + r[6]) / s, q[2] = (r[5] + r[7]) / s, q[3] = 0.25 * s;
    }
    const double n = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    for (int k = 0; k < 4; ++k) q[k] /= n;
}

// A row-major 3x4 affine transform as (translation, rotation, stretch); false when its 3x3
// part is singular or not finite. The rotation is the polar decomposition's orthogonal
// factor (Newton's iteration R <- (R + R^-T) / 2, quadratic, a dozen steps at most for any
// invertible matrix the caller accepts); a mirror (determinant < 0) goes into the stretch,
// so that the rotation stays proper and has a quaternion.
inline bool decompose(const double m[12], MotionKey &key) {
    double a[9] = {m[0], m[1], m[2], m[4], m[5], m[6], m[8], m[9], m[10]};
    double r[9];
    std::copy(a, a + 9, r);
    for (int it = 0; it < 64; ++it) {
        double inv[9];
        if (!invert3(r, inv)) return false;
        double change = 0, size = 0;
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) {
                const double next = 0.5 * (r[3 * i + j] + inv[3 * j + i]);
                change = std::max(change, std::fabs(next - r[3 * i + j]));
                size = std::max(size, std::fabs(next));
                r[3 * i + j] = next;
            }
        // Converged to a few ulps of the entries (which are 1 in size for an orthogonal R).
        if (change <= 4e-16 * size) break;
    }
    if (det3(r) < 0)
        for (double &v : r) v = -v;
    // stretch = R^T A
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            key.s[3 * i + j] = r[i] * a[j] + r[3 + i] * a[3 + j] + r[6 + i] * a[6 + j];
    quaternion_of(r, key.q);
    key.t[0] = m[3], key.t[1] = m[7], key.t[2] = m[11];
    for (double v : key.s)
        if (!std::isfinite(v)) return false;
    return true;
}

// Makes successive keys' quaternions lie in one hemisphere (q and -q are one rotation), so
// that slerp between them takes the short way round.
inline void align_quaternions(MotionKey *keys, int n) {
    for (int i = 1; i < n; ++i) {
        const double *p = keys[i - 1].q;
        double *q = keys[i].q;
        if (p[0] * q[0] + p[1] * q[1] + p[2] * q[2] + p[3] * q[3] < 0)
            for (int k = 0; k < 4; ++k) q[k] = -q[k];
    }
}

inline void slerp(const double a[4], const double b[4], double t, double out[4]) {
    const double c = std::min(1.0, a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3]);
    double wa = 1 - t, wb = t;
    // Below ~1e-4 rad apart, sin(angle) loses its digits: a normalised lerp is as exact.
    if (c < 1.0 - 1e-8) {
        const double angle = std::acos(c), s = std::sin(angle);
        wa = std::sin((1 - t) * angle) / s, wb = std::sin(t * angle) / s;
    }
    double n = 0;
    for (int k = 0; k < 4; ++k) out[k] = wa * a[k] + wb * b[k], n += out[k] * out[k];
    n = std::sqrt(n);
    for (int k = 0; k < 4; ++k) out[k] /= n;
}

// The transform (row-major 3x4) at shutter time `time` in [0, 1] of n >= 1 keys evenly
// spaced over the shutter (clamped outside it), as Cycles' transform_motion_array_interpolate.
inline void at(const MotionKey *keys, int n, double time, double m[12]) {
    MotionKey k;
    if (n == 1 || !(time > 0.0)) {
        k = keys[0];
    } else if (time >= 1.0) {
        k = keys[n - 1];
    } else {
        const double x = time * (n - 1);
        const int i = std::min(int(x), n - 2);
        const double f = x - i;
        const MotionKey &a = keys[i], &b = keys[i + 1];
        for (int c = 0; c < 3; ++c) k.t[c] = a.t[c] + (b.t[c] - a.t[c]) * f;
        for (int c = 0; c < 9; ++c) k.s[c] = a.s[c] + (b.s[c] - a.s[c]) * f;
        slerp(a.q, b.q, f, k.q);
    }
    double r[9];
    rotation_of(k.q, r);
    for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) m[4 * i + j] = r[3 * i] * k.s[j] + r[3 * i + 1] * k.s[3 + j] + r[3 * i + 2] * k.s[6 + j];
        m[4 * i + 3] = k.t[i];
    }
}

// The inverse of a row-major 3x4 affine transform; false when singular.
inline bool invert_affine(const double m[12], double inv[12]) {
    const double a[9] = {m[0], m[1], m[2], m[4], m[5], m[6], m[8], m[9], m[10]};
    double ai[9];
    if (!invert3(a, ai)) return false;
    for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) inv[4 * i + j] = ai[3 * i + j];
        inv[4 * i + 3] = -(ai[3 * i] * m[3] + ai[3 * i + 1] * m[7] + ai[3 * i + 2] * m[11]);
    }
    return true;
}

}  // namespace motion
}  // namespace splat
