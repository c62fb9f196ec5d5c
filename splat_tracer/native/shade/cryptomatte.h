// Cryptomatte (Psyop's open standard, as Cycles writes it): for each pixel and each kind of
// name (object, material, asset), the ids met by its camera samples with the share of the
// samples that met each. An id is a name's MurmurHash3_32 seen as a float (computed by the
// caller: render/cryptomatte.py); coverage is the fraction of the pixel's samples whose
// first surface carries it, so the pixel filter, depth of field and stochastic alpha all
// anti-alias the matte as they do Combined.
//
// Self-contained on purpose: the film holds a CryptomatteFilm, the integrator calls add()
// once per camera sample that meets a surface and finish() once per pixel; nothing else of
// the film changes, and with no Cryptomatte pass enabled() is false and nothing is called.
#pragma once

#include <cstddef>
#include <cstdint>

namespace splat {

struct CryptomatteFilm {
    // The three kinds, in the order Blender's view layer lists them.
    enum Kind { kObject = 0, kMaterial = 1, kAsset = 2, kKinds = 3 };
    // Each kind's output: `slots` (id, coverage) pairs a pixel (w x h x 2 slots floats, row
    // major as the film's other buffers, zeroed by the caller), or null when not wanted.
    float *out[kKinds] = {nullptr, nullptr, nullptr};
    int slots = 0;
    // The ids: 2 a scene instance (its object's, its asset's), 1 a material-table entry.
    const float *instance_ids = nullptr;
    const float *material_ids = nullptr;

    bool enabled() const { return out[kObject] || out[kMaterial] || out[kAsset]; }

    // One camera sample of window pixel p met `instance` with material `material`. An id
    // already in the pixel's slots gains the weight; a new one takes the first free slot;
    // when all are taken it is dropped, as Cycles' film_write_cryptomatte_slots does (the
    // first `slots` distinct ids of the pixel are kept, then sorted by coverage). 0 marks a
    // free slot: no name's id is 0 (the exponent fix of uint32_to_float32 makes 0 bits a
    // small normal number).
    void add(size_t p, int instance, int material, float weight) const {
        const float ids[kKinds] = {instance_ids[2 * size_t(instance)], material_ids[size_t(material)],
                                   instance_ids[2 * size_t(instance) + 1]};
        for (int k = 0; k < kKinds; ++k) {
            if (!out[k]) continue;
            float *pair = out[k] + p * 2 * size_t(slots);
            for (int s = 0; s < slots; ++s, pair += 2) {
                if (pair[0] == 0.f) {
                    pair[0] = ids[k], pair[1] = weight;
                    break;
                }
                if (pair[0] == ids[k]) {
                    pair[1] += weight;
                    break;
                }
            }
        }
    }

    // The pixel's sums become coverages (times inv, 1 / the pixel's samples), its pairs
    // sorted by coverage, largest first (the standard's order: a reader may stop at the
    // first pair below what it needs). Equal coverages keep their order: the sort is stable.
    void finish(size_t p, float inv) const {
        for (int k = 0; k < kKinds; ++k) {
            if (!out[k]) continue;
            float *pairs = out[k] + p * 2 * size_t(slots);
            int used = 0;
            while (used < slots && pairs[2 * used] != 0.f) pairs[2 * used + 1] *= inv, ++used;
            for (int i = 1; i < used; ++i) {  // insertion sort: a handful of slots
                const float id = pairs[2 * i], c = pairs[2 * i + 1];
                int j = i;
                for (; j > 0 && pairs[2 * (j - 1) + 1] < c; --j)
                    pairs[2 * j] = pairs[2 * (j - 1)], pairs[2 * j + 1] = pairs[2 * (j - 1) + 1];
                pairs[2 * j] = id, pairs[2 * j + 1] = c;
            }
        }
    }
};

}  // namespace splat
