// The ε-window query: in one BVH traversal, the first layer of splats a ray meets
// (docs/ALGORITHM.md, "Visibility computation").
//
// Definitions, for a ray and a facing `f` that may begin a layer:
//   first  - the nearest hit of facing f (wrong-intersection elimination: hits of the other
//            facing before it are artefacts of discs poking out of an edge, and ignored);
//   layer  - first and every hit of facing f within ε x r_first behind it (its members);
//   next   - the nearest hit after first within the window that is not a member (it has the
//            other facing), if any. The far phase (visibility.cpp) walks on from the
//            window's end with further queries when it needs what lies behind.
//
// The query keeps the hits in (tmin, cut] sorted in a fixed buffer, where cut shrinks as
// hits arrive: while no first is known, cut = tmax; then cut = t_first + ε x the largest
// radius in the scene -- not the layer's end, which a nearer first with a larger radius,
// met later in the traversal, could move out past hits already dropped (the result then
// depended on the order the traversal met the hits). Boxes beyond cut are pruned, which is
// what makes the query cost little more than a nearest-hit query.
#pragma once

#include <cstdint>

#include "base/ray.h"

namespace splat {

// Hits kept per ray. A layer of overlapping splats holds ~5-15 (about pi (r/D)^2 discs
// cover a point for radius r and spacing D, times the slant of the view); when the buffer
// is full the farthest hit is dropped and `overflow` is set, so a layer is then made of
// its nearest kMaxLayerHits discs. Rays cost this much stack each: 32 x 24 bytes.
constexpr int kMaxLayerHits = 32;
// The most per-point attributes (floats: a colour attribute takes three) a cloud carries for
// the node programs' Attribute nodes, blended at a hit as the colour is; a fixed bound keeps
// a hit's blend on the stack. Twelve: four attributes as the Blender export carries them
// (three floats each, whatever their type: render/nodes.py attribute_layout), e.g. a scan's
// intensity, classification, return number and a second colour.
constexpr int kMaxPointAttributes = 12;

struct LayerHit {
    float t;
    float dist;    // from the hit point to the disc centre
    float radius;  // of the disc
    int32_t id;
    uint32_t slot;  // where the splat is stored (SplatScene::splat): no lookup by id
    bool front;
};

struct LayerQuery {
    // Inputs.
    bool layer_front = true;  // facing that may begin a layer: front for rays from outside,
                              // back for rays travelling inside an object (refraction)
    bool any_facing = false;  // wrong-intersection elimination off: the layer begins at the
                              // nearest hit whatever its facing, and has that facing
    float epsilon = 1.f;      // layer depth, in radii of the first splat
    float max_radius = 0.f;   // the largest radius any splat offered may have (0: trust each
                              // first's own, exact only if hits arrive in order)
    const int32_t *exclude = nullptr;  // splat ids this ray must not hit (secondary rays)
    int n_exclude = 0;

    // Outputs: hits sorted by t, from `first` on.
    LayerHit hits[kMaxLayerHits];
    int count = 0;
    bool overflow = false;

    bool excluded(int32_t id) const {
        for (int i = 0; i < n_exclude; ++i)
            if (exclude[i] == id) return true;
        return false;
    }

    // Derived from `hits` (valid after SplatScene::gather_layer()).
    int first = -1;          // index of the first hit, or -1: no layer
    int next = -1;           // index of the next hit (within the window), or -1: none
    bool facing = true;      // the layer's facing
    float layer_end = 0.f;   // t_first + epsilon * r_first
    float cut = kInfinity;   // hits beyond this are not needed

    // Inserts a hit (if it can matter) and updates first/next/cut.
    void add(const LayerHit &h);
    bool member(int i) const { return i >= first && hits[i].front == facing && hits[i].t <= layer_end; }

  private:
    void update();
};

}  // namespace splat
