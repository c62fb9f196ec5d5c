#include "base/simd.h"

#include <atomic>
#include <cstdlib>
#include <cstring>

#include "base/config.h"

#ifdef SPLAT_AVX2_KERNELS
#include <cpuid.h>
#endif

namespace splat {
namespace {

bool cpu_has_avx2() {
#ifdef SPLAT_AVX2_KERNELS
    // CPUID and XGETBV directly: __builtin_cpu_supports() answers 0 in the Zig-built
    // binaries (their compiler-rt never fills in its CPU model).
    unsigned a, b, c, d;
    if (!__get_cpuid(1, &a, &b, &c, &d)) return false;
    const bool osxsave = c >> 27 & 1, avx = c >> 28 & 1;
    if (!osxsave || !avx) return false;
    unsigned lo, hi;
    __asm__ volatile("xgetbv" : "=a"(lo), "=d"(hi) : "c"(0));  // which registers the OS saves
    if ((lo & 6) != 6) return false;                            // XMM and YMM state
    if (!__get_cpuid_count(7, 0, &a, &b, &c, &d)) return false;
    return b >> 5 & 1;  // AVX2
#else
    return false;
#endif
}

std::atomic<bool> &avx2_flag() {
    static std::atomic<bool> flag([] {
        const char *env = std::getenv("SPLAT_SIMD");
        return cpu_has_avx2() && !(env && std::strcmp(env, "SSE2") == 0);
    }());
    return flag;
}

}  // namespace

bool simd_avx2() { return avx2_flag().load(std::memory_order_relaxed); }

bool use_avx2(bool on) { return avx2_flag().exchange(on && cpu_has_avx2(), std::memory_order_relaxed); }

}  // namespace splat
