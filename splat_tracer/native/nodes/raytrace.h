// The shader nodes that need more than the shading point: Ambient Occlusion and Bevel trace
// rays through ShaderGlobals::queries (the integrator's, nodes/program.h), Wireframe reads the
// mesh triangle and the pixel's footprint. Evaluated by NodeProgram::run.
#pragma once

#include <cstdint>

#include "nodes/program.h"

namespace splat {

// The AO node's AO output: the share of `samples` rays about `normal` (flags: 1 Inside, 2
// Only Local) that meet nothing within `distance`; `key` tells its random numbers apart.
float ambient_occlusion(const ShaderGlobals &sg, Vec3 normal, float distance, int samples, int flags, uint32_t key);
// The Wireframe node's Fac.
float wireframe(const ShaderGlobals &sg, float size, bool pixel_size);
// The Bevel node's Normal (before a linked Normal input is added).
Vec3 bevel(const ShaderGlobals &sg, float radius, int samples, uint32_t key);

}  // namespace splat
