#include "pointcloud/duplicates.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "base/buffer.h"
#include "base/parallel.h"
#include "base/errors.h"

namespace splat {
namespace {

// Odd 64-bit multipliers (from splitmix64), one per axis, that mix a row's coordinates'
// bits into one hash: equal rows have equal hashes, and unequal rows rarely do (a collision
// costs only time: rows with equal hashes are compared by value).
constexpr uint64_t kMultiplier[3] = {0x9E3779B97F4A7C15ull, 0xBF58476D1CE4E5B9ull, 0x94D049BB133111EBull};

// Buckets: 2^kMaxBucketBits at most, fewer for small clouds so that a bucket holds at least
// kBucketRecords records on average. Each part of the scatter writes to every bucket at
// once, and more write streams than about a thousand cost more than they save: at 10M
// points 256 to 1024 buckets scattered in 22-28 ms and sorted in 36 ms, 4096 buckets in 37
// and 40 ms (best of 3, two threads). A bucket of ~10k 8-byte records and its scratch
// (160 KiB) sort in a core's L2 cache.
constexpr size_t kBucketRecords = 4096;
constexpr int kMaxBucketBits = 10;
// Rows per part of the hashing and scattering passes at least (smaller parts cost more in
// their bucket counters than they share out); at most kPartsPerThread parts a thread, to
// balance threads slowed by other work.
constexpr size_t kMinPartRows = size_t(1) << 16;
constexpr size_t kPartsPerThread = 4;
// Below this many records (small clouds) a bucket is sorted by std::sort: four radix passes
// over 256 counters each would cost more than they save.
constexpr size_t kRadixFrom = 256;

// A coordinate's bits with -0.0 made +0.0 (x + 0.0 is +0.0 for x = -0.0 and x for every
// other x, NaN included), so that equal values have equal bits (NaN aside).
inline uint64_t coordinate_bits(double v) {
    v += 0.0;
    uint64_t b;
    std::memcpy(&b, &v, sizeof b);
    return b;
}

// Coord: double, or float (each value converted to double, exactly: the same hash as the
// same points in float64).
template <class Coord>
inline uint64_t row_hash(const Coord *p) {
    uint64_t h = 0;
    for (int a = 0; a < 3; ++a) {
        uint64_t b = coordinate_bits(double(p[a]));
        // The high half folded into the low first: a multiplication only carries bits
        // upward, and coordinates read from float32 have their 29 low mantissa bits zero,
        // which would leave the hash 35 bits (a 10M-point float32 scan then had ~1,500
        // false collisions in the numpy version this replaces).
        b ^= b >> 32;
        h ^= b * kMultiplier[a];  // wraps modulo 2^64
    }
    return h;
}

template <class Coord>
inline bool same_position(const Coord *p, const Coord *q) { return p[0] == q[0] && p[1] == q[1] && p[2] == q[2]; }

// A record is one 64-bit word: 32 bits of its row's hash above the row number, so that
// sorting records sorts them by hash and then by row.
inline uint64_t hash_of(uint64_t record) { return record >> 32; }
inline size_t row_of(uint64_t record) { return size_t(record & 0xffffffffu); }

// Sorts the m records by their whole value, i.e. by hash and then row; `scratch` has room
// for m. Returns the array that holds the result (records or scratch).
uint64_t *sort_records(uint64_t *records, uint64_t *scratch, size_t m) {
    if (m < kRadixFrom) {
        std::sort(records, records + m);
        return records;
    }
    // An LSD radix sort on the hash half only, 8 bits a pass: the records arrive in row
    // order (the scatter is stable) and every pass is stable, so rows stay ascending within
    // a hash. All four histograms come from one read; a pass whose digit is the same for
    // every record (all of a pile of copies of one row) moves nothing and is skipped.
    size_t count[4][256] = {};
    for (size_t i = 0; i < m; ++i) {
        const uint64_t h = hash_of(records[i]);
        ++count[0][h & 255], ++count[1][(h >> 8) & 255], ++count[2][(h >> 16) & 255], ++count[3][h >> 24];
    }
    uint64_t *src = records, *dst = scratch;
    for (int pass = 0; pass < 4; ++pass) {
        const int shift = 32 + 8 * pass;
        size_t *c = count[pass];
        if (c[(src[0] >> shift) & 255] == m) continue;
        size_t at = 0;
        for (int d = 0; d < 256; ++d) at += std::exchange(c[d], at);
        for (size_t i = 0; i < m; ++i) dst[c[(src[i] >> shift) & 255]++] = src[i];
        std::swap(src, dst);
    }
    return src;
}

// The `len` rows (ascending) of a run of records with one hash: each row equal to an earlier
// one of them is not first. Usually they are all copies of the first row; otherwise (a
// collision) they are sorted by position, then by row.
template <class Coord>
void resolve_run(const uint64_t *run, size_t len, const Coord *points, uint8_t *first) {
    const Coord *p0 = points + 3 * row_of(run[0]);
    size_t k = 1;
    while (k < len && same_position(points + 3 * row_of(run[k]), p0)) ++k;
    if (k == len) {
        for (size_t j = 1; j < len; ++j) first[row_of(run[j])] = 0;
        return;
    }
    struct Entry {
        uint64_t bits[3];
        size_t row;
    };
    std::vector<Entry> entries;
    entries.reserve(len);
    for (size_t j = 0; j < len; ++j) {
        const size_t row = row_of(run[j]);
        const Coord *p = points + 3 * row;
        if (std::isnan(p[0]) || std::isnan(p[1]) || std::isnan(p[2])) continue;  // equal to no row
        entries.push_back({{coordinate_bits(double(p[0])), coordinate_bits(double(p[1])), coordinate_bits(double(p[2]))},
                           row});
    }
    // Any total order does: equal positions (equal bits, now that -0.0 is +0.0 and NaN is
    // out) end up together, the earliest row first.
    std::sort(entries.begin(), entries.end(), [](const Entry &a, const Entry &b) {
        return std::tie(a.bits[0], a.bits[1], a.bits[2], a.row) < std::tie(b.bits[0], b.bits[1], b.bits[2], b.row);
    });
    for (size_t j = 1; j < entries.size(); ++j)
        if (std::equal(entries[j].bits, entries[j].bits + 3, entries[j - 1].bits)) first[entries[j].row] = 0;
}

// Marks the rows of one bucket's sorted records: each run of equal hashes is resolved.
template <class Coord>
void resolve_bucket(const uint64_t *sorted, size_t m, const Coord *points, uint8_t *first) {
    auto in_run = [&](size_t i) {
        const uint64_t h = hash_of(sorted[i]);
        return (i > 0 && hash_of(sorted[i - 1]) == h) || (i + 1 < m && hash_of(sorted[i + 1]) == h);
    };
    // The points of runs are read in random order (a copy can be anywhere in the file): the
    // rows of runs kPrefetchAhead records ahead are asked for, so that the misses overlap
    // (10M rows of 1M positions: 113 ms for the buckets against 136 ms without).
    for (size_t i = 0; i < std::min(m, kPrefetchAhead); ++i)
        if (in_run(i)) prefetch(points + 3 * row_of(sorted[i]));
    for (size_t i = 0; i < m;) {
        const uint64_t h = hash_of(sorted[i]);
        size_t end = i + 1;
        while (end < m && hash_of(sorted[end]) == h) ++end;
        for (size_t a = i + kPrefetchAhead; a < std::min(m, end + kPrefetchAhead); ++a)
            if (in_run(a)) prefetch(points + 3 * row_of(sorted[a]));
        if (end - i > 1) resolve_run(sorted + i, end - i, points, first);
        i = end;
    }
}

template <class Coord>
void first_of_duplicates_of(const Coord *points, size_t n, uint8_t *first, int threads) {
    if (n > UINT32_MAX) throw InputError("at most 4294967295 points (32-bit row numbers)");
    if (n < 2) {
        if (n == 1) first[0] = 1;
        return;
    }
    int bits = 0;
    while (bits < kMaxBucketBits && (n >> (bits + 1)) >= kBucketRecords) ++bits;
    const size_t buckets = size_t(1) << bits;
    auto bucket_of = [bits](uint64_t h) { return bits ? size_t(h >> (64 - bits)) : size_t(0); };
    // A record keeps the 32 hash bits below the bucket's (the bucket's own are the same for
    // all its records).
    auto record = [bits](uint64_t h, size_t row) { return ((h << bits) >> 32 << 32) | uint64_t(row); };

    const size_t workers = size_t(resolve_threads(threads));
    const size_t parts = std::max<size_t>(1, std::min(n / kMinPartRows, kPartsPerThread * workers));
    auto part_begin = [&](size_t p) { return n * p / parts; };  // n < 2^32, p <= parts: no overflow
    auto run = [&](size_t tasks, auto &&task) { parallel_for(tasks, threads, task, [](size_t) { return true; }); };

    // Pass 1: how many rows of each part fall in each bucket. The hashes are not kept: the
    // scatter computes them again from the points, which costs less than writing and reading
    // 8 bytes a row more (10M points, two threads, 4 KiB pages: 19 and 49 ms for the two
    // passes and 37 ms for the buckets, against 66, 61 and 79 ms with a hash array that
    // also served as the buckets' sorting scratch, out of cache).
    Buffer<uint64_t> records(n);
    records.prefer_huge_pages();  // the scatter: 35 ms instead of 49 at 10M points
    std::vector<size_t> cursor(parts * buckets, 0);  // part-major: part p's counters together
    run(parts, [&](size_t p) {
        size_t *count = cursor.data() + p * buckets;
        for (size_t i = part_begin(p), end = part_begin(p + 1); i < end; ++i) {
            ++count[bucket_of(row_hash(points + 3 * i))];
            first[i] = 1;
        }
    });
    // Each bucket's records in one range, part 0's rows first, then part 1's...: in row order.
    std::vector<size_t> bucket_start(buckets + 1);
    size_t at = 0;
    for (size_t b = 0; b < buckets; ++b) {
        bucket_start[b] = at;
        for (size_t p = 0; p < parts; ++p) at += std::exchange(cursor[p * buckets + b], at);
    }
    bucket_start[buckets] = at;
    // Pass 2: the records scattered to their buckets.
    run(parts, [&](size_t p) {
        size_t *next = cursor.data() + p * buckets;
        for (size_t i = part_begin(p), end = part_begin(p + 1); i < end; ++i) {
            const uint64_t h = row_hash(points + 3 * i);
            records[next[bucket_of(h)]++] = record(h, i);
        }
    });
    // Pass 3: each bucket sorted and its runs of equal hashes resolved. A row is in one
    // bucket: threads never write one flag. The usual bucket's scratch is the block of the
    // thread's heap that the previous bucket freed, still in cache; one far above the average
    // (a pile of copies of one row) gets pages of its own, given back when freed (buffer.h
    // says why).
    const size_t average = n / buckets;
    run(buckets, [&](size_t b) {
        const size_t begin = bucket_start[b], m = bucket_start[b + 1] - begin;
        if (m < 2) return;
        Buffer<uint64_t> scratch(m < kRadixFrom ? 0 : m, m > 4 * average);
        const uint64_t *sorted = sort_records(records.data() + begin, scratch.data(), m);
        resolve_bucket(sorted, m, points, first);
    });
}

}  // namespace

void first_of_duplicates(const double *points, size_t n, uint8_t *first, int threads) {
    first_of_duplicates_of(points, n, first, threads);
}

void first_of_duplicates(const float *points, size_t n, uint8_t *first, int threads) {
    first_of_duplicates_of(points, n, first, threads);
}

}  // namespace splat
