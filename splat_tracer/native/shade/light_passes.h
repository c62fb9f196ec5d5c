// Cycles' light passes (Diffuse/Glossy/Transmission Direct, Indirect and Color, AO) and light
// groups (one Combined per group): where each piece of light a camera sample brings goes.
// Kept apart from the path integrator, which only "taps" light into them (Integrator::tap):
// none of this is touched unless the film asks for a light pass or a light group.
#pragma once

#include <vector>

#include "base/vec3.h"

namespace splat {

// The lobe of a path's first bounce, which names the light pass its light goes to (-1: none
// yet -- the camera's own vertex, whose emission and world are the Emission and Environment
// passes).
enum PassLobe : int { kLobeNone = -1, kLobeDiffuse = 0, kLobeGlossy = 1, kLobeTransmission = 2, kLobes = 3 };

// The most light groups a render writes. A fixed bound keeps a pixel's sums in the camera
// packet's stack arrays (no allocation per block); the export reports the groups past it as
// not written. 16 is more than a shot's usual key/fill/rim/practicals/sky split.
constexpr int kMaxLightGroups = 16;

// Which light group each light source belongs to (-1: none). Empty vectors: no light groups.
struct LightGroupMap {
    int count = 0;              // groups written (<= kMaxLightGroups)
    std::vector<int> lamp;      // per lamp of the scene
    std::vector<int> instance;  // per instance: its emission's group
    int world = -1;
    int of_lamp(size_t i) const { return i < lamp.size() ? lamp[i] : -1; }
    int of_instance(int i) const { return i >= 0 && size_t(i) < instance.size() ? instance[size_t(i)] : -1; }
};

// One pixel's (or one sample's) sums. As Cycles' render buffers: the direct and indirect
// passes hold light x colour (what the pixel gets); the film divides them by the colour's sum
// on output, so that (Direct + Indirect) x Color gives the light back.
struct LightSums {
    Vec3 direct[kLobes], indirect[kLobes], color[kLobes];
    float ao = 0.f;
    Vec3 group[kMaxLightGroups];
    void add(const LightSums &o, int groups) {
        for (int l = 0; l < kLobes; ++l)
            direct[l] = direct[l] + o.direct[l], indirect[l] = indirect[l] + o.indirect[l],
            color[l] = color[l] + o.color[l];
        ao += o.ao;
        for (int g = 0; g < groups; ++g) group[g] = group[g] + o.group[g];
    }
};

}  // namespace splat
