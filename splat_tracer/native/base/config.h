// Build configuration, decided here once for every file: which SIMD code paths the core is
// compiled with. A file that tests one of these macros includes this header itself, so that
// a path is never silently left out by a missing include.
#pragma once

// SPLAT_NO_SIMD (given by whoever builds, -DSPLAT_NO_SIMD): the plain-float paths on x86-64
// too, to check that they give the same results as the SSE2 ones.

// SPLAT_SSE2: four floats in one SSE register (simd.h's F4, the disc and packet tests).
// Every x86-64 has SSE2; elsewhere (the macOS arm64 build, compiled without SSE) the same
// code runs on plain floats.
#if (defined(__SSE2__) || defined(_M_X64) || defined(_M_AMD64)) && !defined(SPLAT_NO_SIMD)
#define SPLAT_SSE2 1
#endif

// SPLAT_AVX2_KERNELS: eight-wide copies of the packet kernels are compiled as well, and
// chosen at run time where the CPU has AVX2 (simd.cpp): the shipped binaries' baseline stays
// SSE2. They need GCC/Clang's per-function target attribute, on x86.
#if defined(SPLAT_SSE2) && defined(__GNUC__) && (defined(__x86_64__) || defined(__i386__))
#define SPLAT_AVX2_KERNELS 1
#endif
