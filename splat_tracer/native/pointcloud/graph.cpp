#include "pointcloud/graph.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "base/buffer.h"
#include "base/parallel.h"
#include "base/errors.h"

namespace splat {
namespace {

// Items (rows, edges, components) per parallel task: enough that a task's overhead (an atomic
// increment) vanishes against its work, few enough that two threads balance and progress
// moves every few milliseconds.
constexpr size_t kChunk = size_t(1) << 16;
// Vertices visited between two progress calls of the (sequential) traversal: about 50 ms
// (the whole walk over 10M points took 0.5 s).
constexpr size_t kTraversalPoll = size_t(1) << 20;
// "No edge": above every real key, whose high half is a finite weight's order bits.
constexpr uint64_t kNoEdge = ~uint64_t(0);

// Thrown on the calling thread when poll() asks to stop; the entry points return false.
struct Stopped {};

void check(const GraphPoll &poll, double fraction) {
    if (!poll(fraction)) throw Stopped{};
}

// fn(begin, end) over [0, count) in chunks of kChunk on `threads` threads, polling with the
// fractions lo..hi meanwhile.
template <class Fn>
void for_chunks(size_t count, int threads, const GraphPoll &poll, double lo, double hi, Fn &&fn) {
    const size_t chunks = (count + kChunk - 1) / kChunk;
    const bool done = parallel_for(
        chunks, threads, [&](size_t c) { fn(c * kChunk, std::min(count, (c + 1) * kChunk)); },
        [&](size_t d) { return poll(lo + (hi - lo) * double(d) / double(std::max<size_t>(chunks, 1))); });
    if (!done) throw Stopped{};
}

// Compaction in parallel: task c of for_chunks(count) gets the chunk [begin, end) and writes
// what it keeps through fill(begin, end, w) from w = out + begin * room (room: most kept per
// item), returning its end; the chunks' runs are then moved together to the start of out
// (room for count * room). `out` may be the array fill reads when room is 1 (a chunk never
// writes ahead of what it has read). Returns how many were kept.
template <class Fill>
size_t compact(size_t count, size_t room, uint32_t *out, Fill &&fill, int threads, const GraphPoll &poll, double lo,
               double hi) {
    std::vector<size_t> kept((count + kChunk - 1) / kChunk);
    for_chunks(count, threads, poll, lo, hi, [&](size_t begin, size_t end) {
        uint32_t *w = out + begin * room;
        kept[begin / kChunk] = size_t(fill(begin, end, w) - w);
    });
    size_t at = 0;
    for (size_t c = 0; c < kept.size(); ++c) {
        if (at != c * kChunk * room) std::memmove(out + at, out + c * kChunk * room, kept[c] * sizeof(uint32_t));
        at += kept[c];
    }
    return at;
}

// The position of the first entry for which bad(entry) holds, or `count`: a parallel scan.
template <class Bad>
size_t first_bad(size_t count, int threads, const GraphPoll &poll, double lo, double hi, Bad &&bad) {
    std::atomic<size_t> first{count};
    for_chunks(count, threads, poll, lo, hi, [&](size_t begin, size_t end) {
        for (size_t i = begin; i < end && i < first.load(std::memory_order_relaxed); ++i)
            if (bad(i)) {
                size_t cur = first.load();
                while (i < cur && !first.compare_exchange_weak(cur, i)) {
                }
                break;
            }
    });
    return first.load();
}

void check_table(const int32_t *nbr, size_t n, size_t k, int threads, const GraphPoll &poll, double lo, double hi) {
    const size_t bad = first_bad(n * k, threads, poll, lo, hi, [&](size_t e) { return nbr[e] < 0 || size_t(nbr[e]) >= n; });
    if (bad < n * k)
        throw InputError("neighbour table row " + std::to_string(bad / k) + ", column " + std::to_string(bad % k) +
                         ": " + std::to_string(nbr[bad]) + " is not a point index (0 to " + std::to_string(n - 1) + ")");
}

// A float's bits as an unsigned number in the float's own order (negative values included;
// -0 made +0 first, so that equal weights tie and only the edge number decides).
inline uint32_t order_bits(float w) {
    w += 0.0f;
    uint32_t b;
    std::memcpy(&b, &w, sizeof b);
    return (b & 0x80000000u) ? ~b : (b | 0x80000000u);
}

inline void atomic_min(std::atomic<uint64_t> &a, uint64_t v) {
    uint64_t cur = a.load(std::memory_order_relaxed);
    while (v < cur && !a.compare_exchange_weak(cur, v, std::memory_order_relaxed)) {
    }
}

// Spreads the low 21 bits of x to every third bit (one axis of a Morton code).
inline uint64_t spread3(uint64_t x) {
    x &= 0x1fffff;
    x = (x | (x << 32)) & 0x1f00000000ffffull;
    x = (x | (x << 16)) & 0x1f0000ff0000ffull;
    x = (x | (x << 8)) & 0x100f00f00f00f00full;
    x = (x | (x << 4)) & 0x10c30c30c30c30c3ull;
    x = (x | (x << 2)) & 0x1249249249249249ull;
    return x;
}

}  // namespace

void spatial_order(const double *points, size_t n, int32_t *order, int threads) {
    if (n > size_t(INT32_MAX)) throw InputError("at most 2147483647 points (int32 indices)");
    if (n == 0) return;
    double lo[3], hi[3];
    for (int a = 0; a < 3; ++a) lo[a] = hi[a] = points[a];
    for (size_t i = 0; i < n; ++i)
        for (int a = 0; a < 3; ++a) {
            const double v = points[3 * i + a];
            if (!std::isfinite(v)) throw InputError("point " + std::to_string(i) + ": its position is not finite");
            lo[a] = std::min(lo[a], v), hi[a] = std::max(hi[a], v);
        }
    // 11 bits per axis: 2048 cells along the box's sides, a few points per occupied cell for
    // a 10M-point surface (locality is all that matters here), and the 33-bit key beside a
    // 31-bit index fits one 64-bit word: sorting those words sorts by key, then by index.
    constexpr int kBits = 11;
    constexpr uint64_t kCells = uint64_t(1) << kBits;
    double scale[3];
    for (int a = 0; a < 3; ++a) scale[a] = hi[a] > lo[a] ? double(kCells) / (hi[a] - lo[a]) : 0.0;
    Buffer<uint64_t> key(n), tmp(n);
    const GraphPoll never_stop = [](double) { return true; };
    for_chunks(n, threads, never_stop, 0.0, 0.0, [&](size_t begin, size_t end) {
        for (size_t i = begin; i < end; ++i) {
            uint64_t code = 0;
            for (int a = 0; a < 3; ++a) {
                // Clamped before the conversion: points spanning +-1e308 overflow the
                // difference to inf, times a zero scale is NaN (found by fuzz_core under UBSan).
                const double t = (points[3 * i + a] - lo[a]) * scale[a];
                const uint64_t c = t > 0.0 ? (t < double(kCells - 1) ? uint64_t(t) : kCells - 1) : 0;
                code |= spread3(c) << a;
            }
            key[i] = (code << 31) | i;
        }
    });
    // LSD radix sort on the key bits only (three passes of 11 bits): the words start in index
    // order and each pass is stable, so equal keys stay in index order.
    constexpr int kDigit = 11;
    for (int shift = 31; shift < 31 + 3 * kBits; shift += kDigit) {
        std::vector<size_t> count((size_t(1) << kDigit) + 1, 0);
        for (size_t i = 0; i < n; ++i) ++count[((key[i] >> shift) & ((1u << kDigit) - 1)) + 1];
        for (size_t d = 1; d < count.size(); ++d) count[d] += count[d - 1];
        for (size_t i = 0; i < n; ++i) tmp[count[(key[i] >> shift) & ((1u << kDigit) - 1)]++] = key[i];
        std::swap(key, tmp);
    }
    for (size_t i = 0; i < n; ++i) order[i] = int32_t(key[i] & 0x7fffffffu);
}

void permute_table(const int32_t *table, size_t n, size_t stride, size_t first, size_t k, const int32_t *order,
                   int32_t *out, int threads) {
    if (first + k > stride) throw InputError("columns beyond the table's width");
    const GraphPoll never_stop = [](double) { return true; };
    // rank: the inverse of order. Scattered on one thread: a repeated entry would have two
    // threads write one place, a data race.
    Buffer<int32_t> rank(n);
    std::fill(rank.begin(), rank.end(), -1);
    for (size_t r = 0; r < n; ++r) {
        const int32_t v = order[r];
        if (v < 0 || size_t(v) >= n || rank[size_t(v)] >= 0)
            throw InputError("order is not a permutation of the points (entry " + std::to_string(r) + ": " +
                             std::to_string(v) + ")");
        rank[size_t(v)] = int32_t(r);
    }
    std::atomic<size_t> bad{SIZE_MAX};
    for_chunks(n, threads, never_stop, 0.0, 0.0, [&](size_t begin, size_t end) {
        for (size_t r = begin; r < end; ++r) {
            // Rows are read in random order, and so are their entries' ranks: each is asked
            // for ahead (the row kPrefetchAhead rows ahead, the ranks of the row half as far
            // ahead, whose row has arrived by then), so that the misses overlap instead of
            // queueing. 10M points: 1.2 s against 2.0-3.8 s without (best of 4, shared machine).
            if (r + kPrefetchAhead < end) prefetch(table + size_t(order[r + kPrefetchAhead]) * stride + first);
            if (r + kPrefetchAhead / 2 < end) {
                const int32_t *ahead = table + size_t(order[r + kPrefetchAhead / 2]) * stride + first;
                for (size_t s = 0; s < k; ++s)
                    if (ahead[s] >= 0 && size_t(ahead[s]) < n) prefetch(rank.data() + ahead[s]);
            }
            const int32_t *row = table + size_t(order[r]) * stride + first;
            for (size_t s = 0; s < k; ++s) {
                const int32_t j = row[s];
                if (j < 0 || size_t(j) >= n) {
                    size_t at = size_t(order[r]) * stride + first + s, cur = bad.load();
                    while (at < cur && !bad.compare_exchange_weak(cur, at)) {
                    }
                    out[r * k + s] = 0;
                    continue;
                }
                out[r * k + s] = rank[size_t(j)];
            }
        }
    });
    if (bad.load() != SIZE_MAX) {
        const size_t at = bad.load();
        throw InputError("neighbour table row " + std::to_string(at / stride) + ", column " +
                         std::to_string(at % stride) + ": " + std::to_string(table[at]) +
                         " is not a point index (0 to " + std::to_string(n - 1) + ")");
    }
}

void take_rows(const double *src, size_t n, size_t columns, const int32_t *order, size_t count, double *out,
               int threads) {
    const size_t bad = first_bad(count, threads, [](double) { return true; }, 0.0, 0.0,
                                 [&](size_t r) { return order[r] < 0 || size_t(order[r]) >= n; });
    if (bad < count)
        throw InputError("order entry " + std::to_string(bad) + ": " + std::to_string(order[bad]) +
                         " is not a row (0 to " + std::to_string(n == 0 ? 0 : n - 1) + ")");
    for_chunks(count, threads, [](double) { return true; }, 0.0, 0.0, [&](size_t begin, size_t end) {
        for (size_t r = begin; r < end; ++r) {
            if (r + kPrefetchAhead < end) prefetch(src + size_t(order[r + kPrefetchAhead]) * columns);
            std::memcpy(out + r * columns, src + size_t(order[r]) * columns, columns * sizeof(double));
        }
    });
}

bool neighbour_edge_weights(const double *points, const double *normals, size_t n, const int32_t *nbr, size_t k,
                            double across, float *out, int threads, const GraphPoll &poll) {
    try {
        check(poll, 0.0);  // a cancel is seen at least once, however short the work
        const size_t bad = first_bad(n, threads, poll, 0.0, 0.1, [&](size_t i) {
            for (int a = 0; a < 3; ++a)
                if (!std::isfinite(points[3 * i + a]) || !std::isfinite(normals[3 * i + a])) return true;
            return false;
        });
        if (bad < n) {
            const bool at_point = !(std::isfinite(points[3 * bad]) && std::isfinite(points[3 * bad + 1]) &&
                                    std::isfinite(points[3 * bad + 2]));
            throw InputError("point " + std::to_string(bad) + ": its " + (at_point ? "position" : "normal") +
                             " is not finite");
        }
        check_table(nbr, n, k, threads, poll, 0.1, 0.2);
        for_chunks(n, threads, poll, 0.2, 1.0, [&](size_t begin, size_t end) {
            for (size_t i = begin; i < end; ++i)
                for (size_t s = 0; s < k; ++s) {
                    const size_t j = size_t(nbr[i * k + s]);
                    // The same operands in the same order for (i, j) and (j, i): bitwise the
                    // same weight, so that the edge number alone breaks the tie.
                    const double *pa = points + 3 * std::min(i, j), *pb = points + 3 * std::max(i, j);
                    const double *na = normals + 3 * std::min(i, j), *nb = normals + 3 * std::max(i, j);
                    double d[3] = {pb[0] - pa[0], pb[1] - pa[1], pb[2] - pa[2]};
                    // 1e-300: coincident points have no direction (the term is then 0), as in numpy's version.
                    const double inv = 1.0 / std::max(std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]), 1e-300);
                    d[0] *= inv, d[1] *= inv, d[2] *= inv;
                    const double nn = std::fabs(na[0] * nb[0] + na[1] * nb[1] + na[2] * nb[2]);
                    const double ad = std::fabs(na[0] * d[0] + na[1] * d[1] + na[2] * d[2]);
                    const double bd = std::fabs(nb[0] * d[0] + nb[1] * d[1] + nb[2] * d[2]);
                    out[i * k + s] = float(1.0 - nn + across * 0.5 * (ad + bd));
                }
        });
    } catch (const Stopped &) {
        return false;
    }
    return true;
}

bool minimum_spanning_forest(const int32_t *nbr, const float *weights, size_t n, size_t k, int32_t *edges,
                             int32_t *labels, size_t &edge_count, size_t &component_count, int threads,
                             const GraphPoll &poll) {
    edge_count = component_count = 0;
    const uint64_t total = uint64_t(n) * k;
    // Edge numbers travel in the low half of a 64-bit key (weight order bits above them).
    if (total > UINT32_MAX)
        throw InputError("the neighbour table has " + std::to_string(total) +
                         " entries; at most 4294967295 fit (use fewer neighbours or split the cloud)");
    if (n > size_t(INT32_MAX)) throw InputError("at most 2147483647 points (int32 indices)");
    if (n == 0) return true;
    try {
        check(poll, 0.0);
        check_table(nbr, n, k, threads, poll, 0.0, 0.02);
        const size_t bad = first_bad(total, threads, poll, 0.02, 0.04, [&](size_t e) { return !std::isfinite(weights[e]); });
        if (bad < total)
            throw InputError("weight of row " + std::to_string(bad / k) + ", column " + std::to_string(bad % k) +
                             " is not finite");

        // Boruvka: every component takes its lightest edge to another (keys (weight, edge
        // number) are distinct, so these edges form no cycle but the pairs of components that
        // chose the same edge), the components so joined merge, repeat. At least half of the
        // components merge each round; edges inside a component are dropped as they appear.
        // comp[v]: v's component, named by one of its vertices (its root); roots: the
        // components that still have edges out; hook: where a root merges to this round.
        Buffer<uint32_t> comp(n), roots(n), hook(n), jump(n), live;
        std::unique_ptr<std::atomic<uint64_t>[]> best(new std::atomic<uint64_t>[n]);
        for_chunks(n, threads, poll, 0.04, 0.05, [&](size_t begin, size_t end) {
            for (size_t v = begin; v < end; ++v) comp[v] = roots[v] = uint32_t(v);
        });
        auto key_of = [&](uint32_t e) { return (uint64_t(order_bits(weights[e])) << 32) | e; };
        // A component's lightest edge so far, from edge e = (i, j).
        auto offer = [&](uint32_t e, uint32_t i) {
            const uint32_t ci = comp[i], cj = comp[uint32_t(nbr[e])];
            if (ci == cj) return;
            const uint64_t key = key_of(e);
            atomic_min(best[ci], key);
            atomic_min(best[cj], key);
        };
        // Table entry e = (i, j) has a parallel entry of a smaller key (j in row i again, or
        // i in row j: most k-NN edges are mutual): it can never be in the forest (the lighter
        // of the two closes a cycle with it first) and is left out after the first round.
        // Row j is only searched for i > j, whose entry numbers are the larger: with weights
        // symmetric (graph_weights') that finds every mutual pair, for half the reads. (10M
        // terrain points: 30M edges left after the first round instead of 52M.)
        auto shadowed = [&](uint32_t e, uint32_t i, uint32_t j) {
            const uint32_t *row_i = reinterpret_cast<const uint32_t *>(nbr) + size_t(i) * k;
            const uint32_t *row_j = reinterpret_cast<const uint32_t *>(nbr) + size_t(j) * k;
            for (size_t t = 0; t < k; ++t) {
                const uint32_t a = uint32_t(size_t(i) * k + t);
                if (a != e && row_i[t] == j && key_of(a) < key_of(e)) return true;
            }
            if (i > j)
                for (size_t t = 0; t < k; ++t)
                    if (row_j[t] == i && key_of(uint32_t(size_t(j) * k + t)) < key_of(e)) return true;
            return false;
        };
        size_t n_roots = n, n_live = size_t(total), m = 0;
        bool implicit = true;  // the first round's edges are every table entry, row by row: no list yet
        while (n_roots > 0 && n_live > 0) {
            // Progress: by the share of the table's edges no longer live (the rounds' cost).
            const double lo = 0.05 + 0.9 * (1.0 - double(n_live) / double(total));
            const double step = (0.95 - lo) / 5.0;
            for_chunks(n_roots, threads, poll, lo, lo, [&](size_t begin, size_t end) {
                for (size_t r = begin; r < end; ++r) best[roots[r]].store(kNoEdge, std::memory_order_relaxed);
            });
            if (implicit)
                for_chunks(n, threads, poll, lo, lo + 3 * step, [&](size_t begin, size_t end) {
                    for (size_t i = begin; i < end; ++i)
                        for (size_t s = 0; s < k; ++s) offer(uint32_t(i * k + s), uint32_t(i));
                });
            else
                for_chunks(n_live, threads, poll, lo, lo + 3 * step, [&](size_t begin, size_t end) {
                    for (size_t idx = begin; idx < end; ++idx) offer(live[idx], live[idx] / uint32_t(k));
                });
            // Each root hooks to the component across its lightest edge; of two roots that
            // chose the same edge, the smaller stays a root.
            for_chunks(n_roots, threads, poll, lo + 3 * step, lo + 3 * step, [&](size_t begin, size_t end) {
                for (size_t r = begin; r < end; ++r) {
                    const uint32_t c = roots[r];
                    const uint64_t key = best[c].load(std::memory_order_relaxed);
                    if (key == kNoEdge) {
                        hook[c] = c;
                        continue;
                    }
                    const uint32_t e = uint32_t(key), ci = comp[e / k];
                    const uint32_t other = ci == c ? comp[uint32_t(nbr[e])] : ci;
                    const bool mutual = best[other].load(std::memory_order_relaxed) == key;
                    hook[c] = mutual && c < other ? c : other;
                }
            });
            // The forest's new edges, one per hooked root, in the order of the roots.
            {
                const size_t chunks = (n_roots + kChunk - 1) / kChunk;
                std::vector<size_t> at(chunks + 1, 0);
                for_chunks(n_roots, threads, poll, lo + 3 * step, lo + 3 * step, [&](size_t begin, size_t end) {
                    size_t c = 0;
                    for (size_t r = begin; r < end; ++r) c += hook[roots[r]] != roots[r];
                    at[begin / kChunk + 1] = c;
                });
                for (size_t c = 0; c < chunks; ++c) at[c + 1] += at[c];
                for_chunks(n_roots, threads, poll, lo + 3 * step, lo + 3 * step, [&](size_t begin, size_t end) {
                    int32_t *w = edges + 2 * (m + at[begin / kChunk]);
                    for (size_t r = begin; r < end; ++r) {
                        const uint32_t c = roots[r];
                        if (hook[c] == c) continue;
                        const uint32_t e = uint32_t(best[c].load(std::memory_order_relaxed));
                        *w++ = int32_t(e / k), *w++ = nbr[e];
                    }
                });
                m += at[chunks];
            }
            // Hooks followed to the new roots by pointer jumping (log of the chains' length
            // passes; each reads one array and writes the other).
            for (bool changed = true; changed;) {
                std::atomic<bool> any{false};
                for_chunks(n_roots, threads, poll, lo + 3 * step, lo + 4 * step, [&](size_t begin, size_t end) {
                    bool local = false;
                    for (size_t r = begin; r < end; ++r) {
                        const uint32_t c = roots[r], h = hook[c], hh = hook[h];
                        jump[c] = hh;
                        local |= hh != h;
                    }
                    if (local) any = true;
                });
                std::swap(hook, jump);
                changed = any.load();
            }
            for_chunks(n, threads, poll, lo + 4 * step, lo + 4 * step, [&](size_t begin, size_t end) {
                for (size_t v = begin; v < end; ++v) comp[v] = hook[comp[v]];
            });
            // Next round: the roots still with a way out, the edges between components.
            n_roots = compact(
                n_roots, 1, roots.data(),
                [&](size_t begin, size_t end, uint32_t *w) {
                    for (size_t r = begin; r < end; ++r) {
                        const uint32_t c = roots[r];
                        if (hook[c] == c && best[c].load(std::memory_order_relaxed) != kNoEdge) *w++ = c;
                    }
                    return w;
                },
                threads, poll, lo + 4 * step, lo + 4 * step);
            if (implicit) {
                live.allocate(n_live);  // pages are touched only as far as edges survive
                n_live = compact(
                    n, k, live.data(),
                    [&](size_t begin, size_t end, uint32_t *w) {
                        for (size_t i = begin; i < end; ++i)
                            for (size_t s = 0; s < k; ++s) {
                                const uint32_t e = uint32_t(i * k + s), j = uint32_t(nbr[e]);
                                if (comp[i] != comp[j] && !shadowed(e, uint32_t(i), j)) *w++ = e;
                            }
                        return w;
                    },
                    threads, poll, lo + 4 * step, lo + 5 * step);
            } else {
                n_live = compact(
                    n_live, 1, live.data(),
                    [&](size_t begin, size_t end, uint32_t *w) {
                        for (size_t idx = begin; idx < end; ++idx) {
                            const uint32_t e = live[idx];
                            if (comp[e / k] != comp[uint32_t(nbr[e])]) *w++ = e;
                        }
                        return w;
                    },
                    threads, poll, lo + 4 * step, lo + 5 * step);
            }
            implicit = false;
        }
        // Components numbered in the order of their smallest vertex.
        check(poll, 0.95);
        live.release();
        uint32_t *number = jump.data();
        for_chunks(n, threads, poll, 0.95, 0.95, [&](size_t begin, size_t end) {
            for (size_t v = begin; v < end; ++v) number[v] = UINT32_MAX;
        });
        uint32_t next = 0;
        for (size_t v = 0; v < n; ++v) {
            uint32_t &c = number[comp[v]];
            if (c == UINT32_MAX) c = next++;
            labels[v] = int32_t(c);
        }
        edge_count = m;
        component_count = next;
        check(poll, 1.0);
    } catch (const Stopped &) {
        return false;
    }
    return true;
}

bool forest_traversal(const int32_t *edges, size_t m, size_t n, const uint8_t *anchors, int32_t *parent,
                      int32_t *order, size_t &reached, const GraphPoll &poll) {
    reached = 0;
    if (m > (UINT32_MAX - 1) / 2)
        throw InputError("at most 2147483647 edges (got " + std::to_string(m) + ")");
    for (size_t e = 0; e < 2 * m; ++e)
        if (edges[e] < 0 || size_t(edges[e]) >= n)
            throw InputError("edge " + std::to_string(e / 2) + ": " + std::to_string(edges[e]) +
                             " is not a vertex (0 to " + std::to_string(n == 0 ? 0 : n - 1) + ")");
    try {
        check(poll, 0.0);
        // The adjacency as CSR: start[v] .. start[v + 1] in `adj`, in the edge list's order.
        Buffer<uint32_t> start(n + 1), adj(2 * m);
        std::fill(start.begin(), start.end(), 0u);
        for (size_t e = 0; e < m; ++e) ++start[size_t(edges[2 * e]) + 1], ++start[size_t(edges[2 * e + 1]) + 1];
        for (size_t v = 0; v < n; ++v) start[v + 1] += start[v];
        for (size_t e = 0; e < m; ++e) {
            const uint32_t a = uint32_t(edges[2 * e]), b = uint32_t(edges[2 * e + 1]);
            adj[start[a]++] = b;
            adj[start[b]++] = a;
        }
        // start[v] is now v's end, i.e. v + 1's start: shifted back.
        for (size_t v = n; v > 0; --v) start[v] = start[v - 1];
        start[0] = 0;
        check(poll, 0.3);

        size_t tail = 0;
        for (size_t v = 0; v < n; ++v) {
            parent[v] = anchors[v] ? int32_t(v) : -1;
            if (anchors[v]) order[tail++] = int32_t(v);
        }
        for (size_t head = 0; head < tail; ++head) {
            const uint32_t u = uint32_t(order[head]);
            for (uint32_t a = start[u], end = start[u + 1]; a < end; ++a) {
                const uint32_t w = adj[a];
                if (parent[w] < 0) parent[w] = int32_t(u), order[tail++] = int32_t(w);
            }
            if ((head + 1) % kTraversalPoll == 0) check(poll, 0.3 + 0.7 * double(head) / double(n));
        }
        std::fill(order + tail, order + n, -1);
        reached = tail;
        check(poll, 1.0);
    } catch (const Stopped &) {
        return false;
    }
    return true;
}

void chain_flips(const int32_t *order, size_t count, const int32_t *parent, const uint8_t *flip, size_t n,
                 uint8_t *negative) {
    if (count > n) throw InputError("order has more entries than there are vertices");
    for (size_t v = 0; v < n; ++v) negative[v] = flip[v] != 0;
    Buffer<uint8_t> done(n);
    std::fill(done.begin(), done.end(), uint8_t(0));
    for (size_t i = 0; i < count; ++i) {
        const int32_t v = order[i];
        if (v < 0 || size_t(v) >= n)
            throw InputError("order entry " + std::to_string(i) + ": " + std::to_string(v) + " is not a vertex");
        const int32_t p = parent[v];
        if (p < 0 || size_t(p) >= n)
            throw InputError("vertex " + std::to_string(v) + ": parent " + std::to_string(p) + " is not a vertex");
        if (done[size_t(v)]) throw InputError("vertex " + std::to_string(v) + " appears twice in order");
        if (p != v) {
            if (!done[size_t(p)])
                throw InputError("vertex " + std::to_string(v) + " comes before its parent " + std::to_string(p) +
                                 " in order");
            negative[v] = negative[p] ^ negative[v];
        }
        done[size_t(v)] = 1;
    }
}

}  // namespace splat
