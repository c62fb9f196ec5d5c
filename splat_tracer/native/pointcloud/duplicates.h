// Exact duplicate positions in a point cloud (spacing.first_of_duplicates): the importer
// merges every point into the first row at its position, since piles of coincident points
// make the k-nearest-neighbour search pathological.
#pragma once

#include <cstddef>
#include <cstdint>

namespace splat {

// first[i] = 1 when no row before i has row i's position, else 0, for the n x 3 `points`.
// Two positions are equal when their three coordinates are equal as numbers: -0.0 equals
// 0.0 and an infinity itself, and a row with a NaN coordinate equals no row (it is always
// first). The result is a function of the points alone (the same for any `threads`, 0: all
// cores). Throws InputError beyond 2^32 - 1 rows.
//
// Each row gets a 64-bit hash of its coordinates; (hash, row) records are partitioned by
// the hash's top bits into buckets small enough for the cache, each bucket is sorted by
// hash on its own (rows stay ascending within a hash), and only the rows of a run of equal
// hashes are compared by value. Linear time unless hashes collide; a pathological pile of
// distinct rows with one hash is sorted by value, O(n log n).
void first_of_duplicates(const double *points, size_t n, uint8_t *first, int threads);
// The same for float32 points (a float32 file's coordinates, not widened first): the same
// answer as for the same points in float64.
void first_of_duplicates(const float *points, size_t n, uint8_t *first, int threads);

}  // namespace splat
