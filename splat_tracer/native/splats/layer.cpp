#include "splats/layer.h"

namespace splat {

void LayerQuery::add(const LayerHit &h) {
    if (h.t > cut) return;
    // Sorted insertion; equal distances ordered by id, as everywhere in the core.
    int pos = count;
    while (pos > 0 && (hits[pos - 1].t > h.t || (hits[pos - 1].t == h.t && hits[pos - 1].id > h.id))) --pos;
    const bool full = count == kMaxLayerHits;
    if (full) {
        overflow = true;
        if (pos == count) return;  // farther than every kept hit: dropped
        --count;                   // else the farthest kept hit is dropped
    }
    for (int i = count; i > pos; --i) hits[i] = hits[i - 1];
    hits[pos] = h;
    ++count;
    // Most hits change little, and update()'s scans were a tenth of the full method's time:
    if (!full && first >= 0 && pos > first) {
        // Behind the layer's first hit: the first, the window and the cut stay; the hit
        // may be the new `next` (a hit of the other facing within the window).
        if (next >= pos) ++next;
        if (h.t <= layer_end && h.front != facing && (next < 0 || pos < next)) next = pos;
        return;
    }
    if (!full && !(any_facing || h.front == layer_front)) {
        // In front of the first hit (or before any), of the facing that cannot begin a
        // layer: everything stays, one place further on.
        if (first >= 0) ++first, next += next >= 0;
        return;
    }
    update();
}

// Hits before `first` are kept: they have the wrong facing, but a hit found later may
// become the new first in front of them, and then one of them may be its `next`.
void LayerQuery::update() {
    first = -1;
    for (int i = 0; i < count; ++i) {
        if (any_facing || hits[i].front == layer_front) {
            first = i;
            break;
        }
    }
    if (first < 0) return;  // cut stays where it was (tmax)
    facing = hits[first].front;
    layer_end = hits[first].t + epsilon * hits[first].radius;
    // Any later first is nearer, so its window ends before t_first + ε x max_radius.
    cut = hits[first].t + epsilon * (max_radius > hits[first].radius ? max_radius : hits[first].radius);
    while (count > 0 && hits[count - 1].t > cut) --count;
    next = -1;  // after the trim: only hits within the window count
    for (int i = first + 1; i < count && hits[i].t <= layer_end; ++i) {
        if (!member(i)) {
            next = i;
            break;
        }
    }
}

}  // namespace splat
