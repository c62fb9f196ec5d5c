// Four floats in one SSE register where the target has SSE2 (every x86-64), else four
// plain floats with the same semantics: the code that uses it stays portable (the macOS
// arm64 build is compiled without SSE) and gives the same results on both paths.
// Which path is compiled: base/config.h (SPLAT_SSE2, SPLAT_NO_SIMD).
#pragma once

#include <cstdint>
#include <cstring>

#include "base/config.h"

#ifdef SPLAT_SSE2
#include <emmintrin.h>
#endif

namespace splat {

#ifdef SPLAT_SSE2
struct F4 {
    __m128 v;
    F4() = default;
    F4(__m128 x) : v(x) {}
    static F4 load(const float *p) { return _mm_loadu_ps(p); }
    static F4 broadcast(float x) { return _mm_set1_ps(x); }
    // Lanes 0-2 from p[0..2] and 0 in lane 3 (p[3] must be readable: one 16-byte load).
    static F4 load3(const float *p) {
        return _mm_and_ps(_mm_loadu_ps(p), _mm_castsi128_ps(_mm_set_epi32(0, -1, -1, -1)));
    }
    void store(float *p) const { _mm_storeu_ps(p, v); }
};
inline F4 operator+(F4 a, F4 b) { return _mm_add_ps(a.v, b.v); }
inline F4 operator-(F4 a, F4 b) { return _mm_sub_ps(a.v, b.v); }
inline F4 operator*(F4 a, F4 b) { return _mm_mul_ps(a.v, b.v); }
// min4(a, b) = a < b ? a : b and max4(a, b) = a > b ? a : b, per lane (minps/maxps: the
// second operand when either is NaN).
inline F4 min4(F4 a, F4 b) { return _mm_min_ps(a.v, b.v); }
inline F4 max4(F4 a, F4 b) { return _mm_max_ps(a.v, b.v); }
// Every lane of a when `which`, else of b (no branch).
inline F4 select4(bool which, F4 a, F4 b) {
    const __m128 m = _mm_castsi128_ps(_mm_set1_epi32(-int32_t(which)));
    return _mm_or_ps(_mm_and_ps(m, a.v), _mm_andnot_ps(m, b.v));
}
// Per lane x > y ? a : b, and x < y ? a : b (false for NaN: b).
inline F4 select_gt(F4 x, F4 y, F4 a, F4 b) {
    const __m128 m = _mm_cmpgt_ps(x.v, y.v);
    return _mm_or_ps(_mm_and_ps(m, a.v), _mm_andnot_ps(m, b.v));
}
inline F4 select_lt(F4 x, F4 y, F4 a, F4 b) { return select_gt(y, x, a, b); }
// Bit i set where lane i of a <= lane i of b.
inline int mask_le(F4 a, F4 b) { return _mm_movemask_ps(_mm_cmple_ps(a.v, b.v)); }
// Lane i of a where bit i of `bits` (0..15) is set, else of b.
inline F4 select_bits(int bits, F4 a, F4 b) {
    const __m128i lanes = _mm_set_epi32(8, 4, 2, 1);
    const __m128 m = _mm_castsi128_ps(
        _mm_cmpeq_epi32(_mm_and_si128(_mm_set1_epi32(bits), lanes), lanes));
    return _mm_or_ps(_mm_and_ps(m, a.v), _mm_andnot_ps(m, b.v));
}
// The largest lane (no NaN lanes).
inline float hmax4(F4 a) {
    const __m128 b = _mm_max_ps(a.v, _mm_movehl_ps(a.v, a.v));
    return _mm_cvtss_f32(_mm_max_ss(b, _mm_shuffle_ps(b, b, 1)));
}
// Lanes truncated towards zero (the caller clamps them into int range first).
inline void truncate4(F4 a, int32_t out[4]) { _mm_storeu_si128(reinterpret_cast<__m128i *>(out), _mm_cvttps_epi32(a.v)); }
#else
struct F4 {
    float v[4];
    static F4 load(const float *p) {
        F4 r;
        std::memcpy(r.v, p, sizeof r.v);
        return r;
    }
    static F4 broadcast(float x) { return F4{{x, x, x, x}}; }
    static F4 load3(const float *p) { return F4{{p[0], p[1], p[2], 0.f}}; }
    void store(float *p) const { std::memcpy(p, v, sizeof v); }
};
#define SPLAT_F4_OP(name, expr)                          \
    inline F4 name(F4 a, F4 b) {                         \
        F4 r;                                            \
        for (int i = 0; i < 4; ++i) r.v[i] = (expr);     \
        return r;                                        \
    }
SPLAT_F4_OP(operator+, a.v[i] + b.v[i])
SPLAT_F4_OP(operator-, a.v[i] - b.v[i])
SPLAT_F4_OP(operator*, a.v[i] * b.v[i])
SPLAT_F4_OP(min4, a.v[i] < b.v[i] ? a.v[i] : b.v[i])
SPLAT_F4_OP(max4, a.v[i] > b.v[i] ? a.v[i] : b.v[i])
#undef SPLAT_F4_OP
inline F4 select4(bool which, F4 a, F4 b) { return which ? a : b; }
inline F4 select_gt(F4 x, F4 y, F4 a, F4 b) {
    F4 r;
    for (int i = 0; i < 4; ++i) r.v[i] = x.v[i] > y.v[i] ? a.v[i] : b.v[i];
    return r;
}
inline F4 select_lt(F4 x, F4 y, F4 a, F4 b) { return select_gt(y, x, a, b); }
inline int mask_le(F4 a, F4 b) {
    int m = 0;
    for (int i = 0; i < 4; ++i) m |= (a.v[i] <= b.v[i]) << i;
    return m;
}
inline void truncate4(F4 a, int32_t out[4]) {
    for (int i = 0; i < 4; ++i) out[i] = int32_t(a.v[i]);
}
inline F4 select_bits(int bits, F4 a, F4 b) {
    F4 r;
    for (int i = 0; i < 4; ++i) r.v[i] = (bits >> i & 1) ? a.v[i] : b.v[i];
    return r;
}
inline float hmax4(F4 a) {
    float m = a.v[0];
    for (int i = 1; i < 4; ++i) m = a.v[i] > m ? a.v[i] : m;
    return m;
}
#endif

// Whether the packet kernels run their AVX2 versions (disc.h): decided once at load time
// from the CPU (with the OS saving its registers), unless the environment variable
// SPLAT_SIMD=SSE2 asks for the baseline; use_avx2() switches it (a test seam, between renders).
bool simd_avx2();
bool use_avx2(bool on);  // returns the previous setting; on = true only where the CPU has AVX2

}  // namespace splat
