// Python binding of the neighbour search: `_core.PointIndex` (neighbours.h). Queries take
// the rows of the indexed points to ask about (the caller walks the tree's order in chunks, which
// keeps each chunk's queries in the same part of the tree and lets it report progress and
// cancel between chunks) and fill arrays the caller allocated. splat_tracer/pointcloud/neighbours.py wraps
// it (PointIndex); every input is validated here too.
#include <atomic>
#include <cmath>
#include <vector>

#include "base/buffer.h"
#include "base/ray.h"
#include "pointcloud/neighbours.h"
#include "python/py_util.h"

namespace splat::py {
namespace {

struct PointIndexObject {
    PyObject_HEAD
    PointIndex *index;
};

PointIndex &index_of(PyObject *self) { return *reinterpret_cast<PointIndexObject *>(self)->index; }

// Rows per task: enough work to amortise the task counter, few enough to balance 2+ threads
// on one of the importer's chunks (2^18 rows; the closed guess's, a few thousand).
constexpr size_t kRowsPerTask = 512;

// Runs task(t) for t in [0, tasks) on `threads` threads, without the GIL (stopped, with a
// RuntimeError, when Python is exiting).
template <class Task>
bool for_tasks(size_t tasks, int threads, Task &&task) {
    return without_gil([&] { parallel_until_exit(tasks, threads, task); });
}

// Runs fn(i) for i in [0, m) in tasks of kRowsPerTask.
template <class Fn>
bool for_rows(size_t m, int threads, Fn &&fn) {
    return for_tasks((m + kRowsPerTask - 1) / kRowsPerTask, threads, [&](size_t t) {
        for (size_t i = t * kRowsPerTask; i < std::min(m, (t + 1) * kRowsPerTask); ++i) fn(i);
    });
}

// Runs fn(i, slot, d2, slots) for each row i (its point at `slot`) with its point's k
// nearest others (squared distances and slots, nearest first), without the GIL. Rows that
// follow one another in the tree's order (what the importer asks: chunks of `order`, or a
// sample of runs of it) go a leaf at a time (PointIndex::leaf_nearest), lone rows one search
// each. by_id: per-point data fn reads by input id (3 floats each: normals), or null; the
// next piece's is asked for ahead (walking the tree's order reads it at random: a cache
// miss per point, 0.27 us of the 1.27 us a 10M-point cloud's radii took).
template <class Fn>
bool for_neighbours(const PointIndex &index, const int32_t *rows, size_t m, int k, int threads, Fn &&fn,
                    const float *by_id = nullptr) {
    struct Piece {
        size_t row, slot, count;  // rows [row, row + count) are slots [slot, slot + count), in one leaf
    };
    std::vector<Piece> pieces;
    // The importer's rows are one run of the order (a chunk of it): then the pieces are that
    // run cut at the leaves' ends, found without looking up each row's slot (at random in
    // a 40 MB table at 10M points: 0.22 s a pass over the cloud, on the calling thread
    // alone, before the threads start).
    const size_t first = m ? index.slot(uint32_t(rows[0])) : 0;
    bool one_run = first + m <= index.size();
    for (size_t i = 0; one_run && i < m; ++i) one_run = index.id(uint32_t(first + i)) == uint32_t(rows[i]);
    if (one_run) {
        for (size_t s = first; s < first + m;) {
            const size_t end = std::min(index.leaf_end(s), first + m);
            pieces.push_back({s - first, s, end - s});
            s = end;
        }
    }
    for (size_t i = 0; !one_run && i < m;) {
        const size_t s = index.slot(uint32_t(rows[i])), end = index.leaf_end(s);
        size_t c = 1;
        while (i + c < m && s + c < end && index.id(uint32_t(s + c)) == uint32_t(rows[i + c])) ++c;
        pieces.push_back({i, s, c});
        i += c;
    }
    // Tasks of about kRowsPerTask rows: a piece holds 1 to kLeafSize of them.
    std::vector<size_t> task_start{0};
    for (size_t p = 0, rows_in_task = 0; p < pieces.size(); ++p) {
        rows_in_task += pieces[p].count;
        if (rows_in_task >= kRowsPerTask && p + 1 < pieces.size()) task_start.push_back(p + 1), rows_in_task = 0;
    }
    task_start.push_back(pieces.size());
    return for_tasks(task_start.size() - 1, threads, [&](size_t t) {
        std::vector<float> d2(PointIndex::kLeafSize * size_t(k));
        std::vector<uint32_t> slots(d2.size());
        float guess = 0.f;  // passed from leaf to leaf along a run (PointIndex::leaf_nearest)
        for (size_t p = task_start[t]; p < task_start[t + 1]; ++p) {
            const Piece &pc = pieces[p];
            if (by_id && p + 1 < pieces.size())
                for (size_t j = 0; j < pieces[p + 1].count; ++j) prefetch(by_id + 3 * size_t(rows[pieces[p + 1].row + j]));
            if (p == task_start[t] || pieces[p - 1].slot + pieces[p - 1].count != pc.slot) guess = 0.f;  // a new run
            if (pc.count == 1 && (p + 1 == pieces.size() || pc.slot + 1 != pieces[p + 1].slot) && guess == 0.f) {
                index.nearest_of(uint32_t(pc.slot), k, d2.data(), slots.data());  // a lone row: its own search
                fn(pc.row, uint32_t(pc.slot), d2.data(), slots.data());
                continue;
            }
            index.leaf_nearest(pc.slot, pc.slot + pc.count, k, d2.data(), slots.data(), guess);
            for (size_t j = 0; j < pc.count; ++j) fn(pc.row + j, uint32_t(pc.slot + j), &d2[j * k], &slots[j * k]);
        }
    });
}

// rows: int32 (m,), every entry a point of the index. Sets an exception otherwise.
bool get_rows(PyObject *obj, const PointIndex &index, View &rows) {
    Py_ssize_t any[1] = {-1};
    if (!get_array(obj, "rows", 'i', 1, any, false, rows)) return false;
    const int32_t *r = rows.data<int32_t>();
    for (Py_ssize_t i = 0; i < rows.dim(0); ++i)
        if (r[i] < 0 || size_t(r[i]) >= index.size())
            return PyErr_Format(PyExc_ValueError, "rows[%zd] = %d is not a point of the index (0..%zu)", i, int(r[i]),
                                index.size() - 1),
                   false;
    return true;
}

// k neighbours of a point of the index (others: at most size - 1). Sets an exception otherwise.
bool check_k(int k, size_t available, const char *name = "k") {
    if (k < 1 || k > PointIndex::kMaxK || size_t(k) > available)
        return PyErr_Format(PyExc_ValueError, "%s must be in 1..%zu (the points available, at most %d), got %d", name,
                            std::min<size_t>(available, PointIndex::kMaxK), PointIndex::kMaxK, k),
               false;
    return true;
}

// The gap-closing rule's parameters (covering_radius). Sets an exception when unusable.
bool check_cover(int cover_k, int k, float hole, float max_gap) {
    if (cover_k < 2 || cover_k > k)
        return PyErr_Format(PyExc_ValueError, "cover_k must be in 2..%d, got %d", k, cover_k), false;
    if (!(std::isfinite(hole) && hole > 0.f && std::isfinite(max_gap) && max_gap > 0.f))
        return PyErr_Format(PyExc_ValueError, "hole and max_gap must be positive numbers"), false;
    return true;
}

// Whether a normal is a direction, finite and not zero (any length: the queries normalise it).
bool is_direction(const float *n) {
    const double len2 = double(n[0]) * n[0] + double(n[1]) * n[1] + double(n[2]) * n[2];
    return std::isfinite(len2) && len2 > 0.0;  // a float's square never overflows a double
}

bool bad_normal(Py_ssize_t id) {
    return PyErr_Format(PyExc_ValueError, "normals[%zd] must be a direction (finite, not zero)", id), false;
}

// The smallest input id whose normal is not a direction, noted by the rows' workers as they
// read the normals: checking the rows' normals before the work would read each at random,
// a cache miss apiece (a tenth of a 10M-point cloud's radii).
struct BadNormals {
    std::atomic<int64_t> first{-1};
    // Whether normal n (of input id) is usable; notes it otherwise.
    bool usable(const float *n, int64_t id) {
        if (is_direction(n)) return true;
        int64_t cur = first.load();
        while ((cur < 0 || id < cur) && !first.compare_exchange_weak(cur, id)) {
        }
        return false;
    }
    // False with the exception set when a normal was not usable.
    bool check() const { return first.load() < 0 || bad_normal(Py_ssize_t(first.load())); }
};

PyObject *PointIndex_new(PyTypeObject *type, PyObject *args, PyObject *kwargs) {
    static const char *kwlist[] = {"points", "threads", nullptr};
    PyObject *op;
    int threads = 0;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "O|i", const_cast<char **>(kwlist), &op, &threads)) return nullptr;
    if (!check_threads(threads)) return nullptr;
    View p;
    Py_ssize_t s3[2] = {-1, 3};
    if (!get_array(op, "points", 'f', 2, s3, false, p)) return nullptr;
    PointIndex *index = nullptr;
    if (!without_gil([&] { index = new PointIndex(p.data<float>(), size_t(p.dim(0)), threads); })) return nullptr;
    auto alloc = reinterpret_cast<allocfunc>(PyType_GetSlot(type, Py_tp_alloc));
    PyObject *self = alloc(type, 0);
    if (!self) {
        delete index;
        return nullptr;
    }
    reinterpret_cast<PointIndexObject *>(self)->index = index;
    return self;
}

void PointIndex_dealloc(PyObject *self) {
    delete reinterpret_cast<PointIndexObject *>(self)->index;
    PyTypeObject *type = Py_TYPE(self);
    reinterpret_cast<freefunc>(PyType_GetSlot(type, Py_tp_free))(self);
    Py_DECREF(type);
}

PyObject *PointIndex_size(PyObject *self, void *) { return PyLong_FromSize_t(index_of(self).size()); }

PyObject *PointIndex_order(PyObject *self, PyObject *arg) {
    const PointIndex &index = index_of(self);
    View out;
    Py_ssize_t s[1] = {Py_ssize_t(index.size())};
    if (!get_array(arg, "out", 'i', 1, s, true, out)) return nullptr;
    int32_t *o = out.data<int32_t>();
    for (size_t s = 0; s < index.size(); ++s) o[s] = int32_t(index.id(uint32_t(s)));
    Py_RETURN_NONE;
}

// knn(rows, k, dist, ids, threads=0): the k nearest other points of each row's point.
PyObject *PointIndex_knn(PyObject *self, PyObject *args, PyObject *kwargs) {
    static const char *kwlist[] = {"rows", "k", "dist", "ids", "threads", nullptr};
    PyObject *orows, *odist, *oids;
    int k, threads = 0;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OiOO|i", const_cast<char **>(kwlist), &orows, &k, &odist, &oids,
                                     &threads))
        return nullptr;
    const PointIndex &index = index_of(self);
    View rows, dist, ids;
    if (!check_threads(threads) || !get_rows(orows, index, rows) || !check_k(k, index.size() - 1)) return nullptr;
    Py_ssize_t s[2] = {rows.dim(0), k};
    if (!get_array(odist, "dist", 'f', 2, s, true, dist) || !get_array(oids, "ids", 'i', 2, s, true, ids) ||
        !check_separate({{dist, "dist"}, {ids, "ids"}}, {{rows, "rows"}}))
        return nullptr;
    const int32_t *r = rows.data<int32_t>();
    float *d = dist.data<float>();
    uint32_t *n = reinterpret_cast<uint32_t *>(ids.data<int32_t>());
    if (!for_neighbours(index, r, size_t(rows.dim(0)), k, threads, [&](size_t i, uint32_t, const float *d2, const uint32_t *nb) {
            for (int j = 0; j < k; ++j) d[i * k + j] = std::sqrt(d2[j]), n[i * k + j] = index.id(nb[j]);
        }))
        return nullptr;
    Py_RETURN_NONE;
}

// knn_at(positions, k, dist, ids, threads=0): the k nearest points of the index to each position.
PyObject *PointIndex_knn_at(PyObject *self, PyObject *args, PyObject *kwargs) {
    static const char *kwlist[] = {"positions", "k", "dist", "ids", "threads", nullptr};
    PyObject *opos, *odist, *oids;
    int k, threads = 0;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OiOO|i", const_cast<char **>(kwlist), &opos, &k, &odist, &oids,
                                     &threads))
        return nullptr;
    const PointIndex &index = index_of(self);
    View pos, dist, ids;
    Py_ssize_t s3[2] = {-1, 3};
    if (!check_threads(threads) || !get_array(opos, "positions", 'f', 2, s3, false, pos) || !check_k(k, index.size()))
        return nullptr;
    Py_ssize_t s[2] = {pos.dim(0), k};
    if (!get_array(odist, "dist", 'f', 2, s, true, dist) || !get_array(oids, "ids", 'i', 2, s, true, ids) ||
        !check_separate({{dist, "dist"}, {ids, "ids"}}, {{pos, "positions"}}))
        return nullptr;
    const float *p = pos.data<float>();
    // Within 1e18 like the points (a distance to a position at 1e38 overflows float: no
    // candidate would ever be nearer than "infinitely far", and k would not be found).
    for (Py_ssize_t i = 0; i < 3 * pos.dim(0); ++i)
        if (!within_range(p[i]))
            return PyErr_Format(PyExc_ValueError, "positions[%zd] is not finite or beyond 1e18", i / 3);
    float *d = dist.data<float>();
    uint32_t *n = reinterpret_cast<uint32_t *>(ids.data<int32_t>());
    if (!for_rows(size_t(pos.dim(0)), threads, [&](size_t i) {
            float *di = d + i * k;
            uint32_t *ni = n + i * k;
            index.nearest(p + 3 * i, PointIndex::kNone, k, di, ni);
            for (int j = 0; j < k; ++j) di[j] = std::sqrt(di[j]), ni[j] = index.id(ni[j]);
        }))
        return nullptr;
    Py_RETURN_NONE;
}

// covering(rows, normals, spacing, k, hole, max_gap, out, threads=0): see covering_radius.
// normals (N,3) and spacing (N,) float32 are per point of the index, by input id.
PyObject *PointIndex_covering(PyObject *self, PyObject *args, PyObject *kwargs) {
    static const char *kwlist[] = {"rows", "normals", "spacing", "k", "hole", "max_gap", "out", "threads", nullptr};
    PyObject *orows, *onrm, *ospacing, *oout;
    int k, threads = 0;
    float hole, max_gap;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOOiffO|i", const_cast<char **>(kwlist), &orows, &onrm, &ospacing,
                                     &k, &hole, &max_gap, &oout, &threads))
        return nullptr;
    const PointIndex &index = index_of(self);
    View rows, nrm, sp, out;
    if (!check_threads(threads) || !get_rows(orows, index, rows) || !check_k(k, index.size() - 1)) return nullptr;
    Py_ssize_t sn[2] = {Py_ssize_t(index.size()), 3}, ss[1] = {Py_ssize_t(index.size())}, so[1] = {rows.dim(0)};
    if (!get_array(onrm, "normals", 'f', 2, sn, false, nrm) || !get_array(ospacing, "spacing", 'f', 1, ss, false, sp) ||
        !get_array(oout, "out", 'f', 1, so, true, out) ||
        !check_separate({{out, "out"}}, {{rows, "rows"}, {nrm, "normals"}, {sp, "spacing"}}))
        return nullptr;
    if (!check_cover(k, k, hole, max_gap)) return nullptr;
    const int32_t *r = rows.data<int32_t>();
    const float *n = nrm.data<float>(), *s = sp.data<float>();
    for (Py_ssize_t i = 0; i < rows.dim(0); ++i) {  // only the rows asked about are read
        if (!(std::isfinite(s[r[i]]) && s[r[i]] >= 0.f))
            return PyErr_Format(PyExc_ValueError, "spacing[%d] must be finite and >= 0", int(r[i]));
    }
    float *o = out.data<float>();
    BadNormals bad;
    if (!for_neighbours(index, r, size_t(rows.dim(0)), k, threads, [&](size_t i, uint32_t self, const float *, const uint32_t *nb) {
            const uint32_t id = uint32_t(r[i]);
            const float *ni = n + 3 * size_t(id);
            o[i] = bad.usable(ni, id) ? covering_radius(index, self, nb, k, ni, s[id], hole, max_gap) : 0.f;
        }, n) || !bad.check())
        return nullptr;
    Py_RETURN_NONE;
}

// radii(rows, spacing_k, spacing, normals=None, cover_k=0, hole=0, max_gap=0, cover=None,
// threads=0, by_row=False): each row's distance to its spacing_k-th nearest other point and,
// with normals ((N,3) directions, by input id) and cover, its gap-closing radius among its
// cover_k nearest (covering_radius, with that distance as the spacing): one search for both.
// spacing and cover hold one value per entry of rows (m,), or with by_row one per point of
// the index (N,), written at the row's own place: the importer's chunks of the tree's order
// then need no scatter of the results in Python (numpy's, on one thread: 0.35 s at 10M
// points); the rows must then be distinct (a row listed twice would be written by two
// threads at once, with the same values). cover_cap > 0: each gap-closing radius is kept
// between the spacing and cover_cap times it.
PyObject *PointIndex_radii(PyObject *self, PyObject *args, PyObject *kwargs) {
    static const char *kwlist[] = {"rows", "spacing_k", "spacing", "normals", "cover_k", "hole", "max_gap", "cover",
                                   "threads", "by_row", "cover_cap", nullptr};
    PyObject *orows, *ospacing, *onrm = Py_None, *ocover = Py_None;
    int spacing_k, cover_k = 0, threads = 0, by_row = 0;
    float hole = 0.f, max_gap = 0.f, cover_cap = 0.f;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OiO|OiffOipf", const_cast<char **>(kwlist), &orows, &spacing_k,
                                     &ospacing, &onrm, &cover_k, &hole, &max_gap, &ocover, &threads, &by_row,
                                     &cover_cap))
        return nullptr;
    if (!(cover_cap == 0.f || (std::isfinite(cover_cap) && cover_cap >= 1.f)))
        return PyErr_Format(PyExc_ValueError, "cover_cap must be 0 (none) or at least 1, got %g", double(cover_cap));
    const PointIndex &index = index_of(self);
    View rows, sp, nrm, cov;
    if (!check_threads(threads) || !get_rows(orows, index, rows) || !check_k(spacing_k, index.size() - 1, "spacing_k"))
        return nullptr;
    Py_ssize_t so[1] = {by_row ? Py_ssize_t(index.size()) : rows.dim(0)}, sn[2] = {Py_ssize_t(index.size()), 3};
    if (!get_array(ospacing, "spacing", 'f', 1, so, true, sp)) return nullptr;
    const bool covering = ocover != Py_None;
    if (covering != (onrm != Py_None))
        return PyErr_Format(PyExc_ValueError, "the gap-closing radii need both normals and cover");
    if (covering) {
        if (!check_k(cover_k, index.size() - 1, "cover_k") || !check_cover(cover_k, cover_k, hole, max_gap) ||
            !get_array(onrm, "normals", 'f', 2, sn, false, nrm) || !get_array(ocover, "cover", 'f', 1, so, true, cov))
            return nullptr;
    }
    if (!check_separate({{sp, "spacing"}, {cov, "cover"}}, {{rows, "rows"}, {nrm, "normals"}})) return nullptr;
    const int k = std::max(spacing_k, covering ? cover_k : 0);
    const int32_t *r = rows.data<int32_t>();
    const size_t m = size_t(rows.dim(0));
    const float *n = covering ? nrm.data<float>() : nullptr;
    float *s = sp.data<float>(), *c = covering ? cov.data<float>() : nullptr;
    // by_row: the values go to (m,) arrays first and are scattered to their rows after the
    // search, in a loop of their own: written at random rows from inside the search, their
    // cache misses slowed the search itself (10M points: 3.6 s against 3.3 s for the search
    // and numpy's scatter). Likewise the rows' normals are gathered in the rows' order first,
    // on the threads: read by id from inside the search, each was a cache and TLB miss that
    // a prefetch a leaf ahead did not hide (4 % of the radii at 10M points).
    Buffer<float> s_rows, c_rows, n_rows;
    try {  // a refused allocation is a MemoryError, never an exception out of this function
        if (by_row) {
            s_rows.allocate(m), s = s_rows.data();
            if (c) c_rows.allocate(m), c = c_rows.data();
        }
        if (c) n_rows.allocate(3 * m);
    } catch (const std::bad_alloc &) {
        return PyErr_NoMemory();
    }
    if (c && !for_rows(m, threads, [&](size_t i) {
            const float *from = n + 3 * size_t(r[i]);
            n_rows[3 * i] = from[0], n_rows[3 * i + 1] = from[1], n_rows[3 * i + 2] = from[2];
        }))
        return nullptr;
    BadNormals bad;
    if (!for_neighbours(index, r, m, k, threads, [&](size_t i, uint32_t self, const float *d2, const uint32_t *nb) {
            s[i] = std::sqrt(d2[spacing_k - 1]);
            if (!c) return;
            const float *ni = &n_rows[3 * i];
            c[i] = bad.usable(ni, r[i]) ? covering_radius(index, self, nb, cover_k, ni, s[i], hole, max_gap) : 0.f;
            // at least the spacing, at most cover_cap times it (spacing.analyse's rule; float
            // products, as numpy's on float32 arrays)
            if (cover_cap > 0.f) c[i] = std::min(std::max(c[i], s[i]), cover_cap * s[i]);
        }) || !bad.check())
        return nullptr;
    if (by_row) {
        float *s_out = sp.data<float>(), *c_out = covering ? cov.data<float>() : nullptr;
        if (!for_rows(m, threads, [&](size_t i) {
                s_out[r[i]] = s[i];
                if (c_out) c_out[r[i]] = c[i];
            }))
            return nullptr;
    }
    Py_RETURN_NONE;
}

// widest_gaps(rows, k, normals, out, threads=0): each row's widest_gap among its k nearest
// others; normals (N,3) float32 by input id (its neighbours' are read too, and checked).
PyObject *PointIndex_widest_gaps(PyObject *self, PyObject *args, PyObject *kwargs) {
    static const char *kwlist[] = {"rows", "k", "normals", "out", "threads", nullptr};
    PyObject *orows, *onrm, *oout;
    int k, threads = 0;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OiOO|i", const_cast<char **>(kwlist), &orows, &k, &onrm, &oout,
                                     &threads))
        return nullptr;
    const PointIndex &index = index_of(self);
    View rows, nrm, out;
    if (!check_threads(threads) || !get_rows(orows, index, rows) || !check_k(k, index.size() - 1)) return nullptr;
    Py_ssize_t sn[2] = {Py_ssize_t(index.size()), 3}, so[1] = {rows.dim(0)};
    if (!get_array(onrm, "normals", 'f', 2, sn, false, nrm) || !get_array(oout, "out", 'f', 1, so, true, out) ||
        !check_separate({{out, "out"}}, {{rows, "rows"}, {nrm, "normals"}}))
        return nullptr;
    const float *n = nrm.data<float>();
    float *o = out.data<float>();
    const int32_t *r = rows.data<int32_t>();
    // The normals read (the row's and its neighbours') are checked as they are read, not all
    // N first: the importer asks about a few thousand rows of a 10M-point cloud at a time.
    BadNormals bad;
    if (!for_neighbours(index, r, size_t(rows.dim(0)), k, threads, [&](size_t i, uint32_t self, const float *, const uint32_t *nb) {
            bool usable = bad.usable(n + 3 * size_t(r[i]), r[i]);
            for (int j = 0; j < k; ++j) {
                const uint32_t id = index.id(nb[j]);
                usable &= bad.usable(n + 3 * size_t(id), id);
            }
            o[i] = usable ? float(widest_gap(index, self, nb, k, n)) : 0.f;
        }, n) || !bad.check())
        return nullptr;
    Py_RETURN_NONE;
}

// pca(rows, k, normals, graph=None, spacing_k=0, spacing=None, cover_k=0, hole=0, max_gap=0,
// cover=None, threads=0): each row's PCA normal over itself and its k nearest (float64
// (m,3), unoriented); graph (m, g) int32: the row itself then its g - 1 nearest (g - 1 <=
// k); spacing (m,) float32: the distance to its spacing_k-th nearest other point
// (spacing_k <= k); cover (m,) float32: its gap-closing radius among its cover_k nearest,
// with its PCA normal and that spacing.
PyObject *PointIndex_pca(PyObject *self, PyObject *args, PyObject *kwargs) {
    static const char *kwlist[] = {"rows",  "k",    "normals", "graph", "spacing_k", "spacing", "cover_k",
                                   "hole", "max_gap", "cover", "threads", nullptr};
    PyObject *orows, *onrm, *ograph = Py_None, *ospacing = Py_None, *ocover = Py_None;
    int k, spacing_k = 0, cover_k = 0, threads = 0;
    float hole = 0.f, max_gap = 0.f;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OiO|OiOiffOi", const_cast<char **>(kwlist), &orows, &k, &onrm,
                                     &ograph, &spacing_k, &ospacing, &cover_k, &hole, &max_gap, &ocover, &threads))
        return nullptr;
    const PointIndex &index = index_of(self);
    View rows, nrm, graph, sp, cov;
    if (!check_threads(threads) || !get_rows(orows, index, rows) || !check_k(k, index.size() - 1)) return nullptr;
    const Py_ssize_t m = rows.dim(0);
    Py_ssize_t sn[2] = {m, 3}, sg[2] = {m, -1}, ss[1] = {m};
    if (!get_array(onrm, "normals", 'd', 2, sn, true, nrm)) return nullptr;
    if (ograph != Py_None) {
        if (!get_array(ograph, "graph", 'i', 2, sg, true, graph)) return nullptr;
        if (graph.dim(1) < 1 || graph.dim(1) > k + 1)
            return PyErr_Format(PyExc_ValueError, "graph must have 1..k+1 = %d columns, got %zd", k + 1, graph.dim(1));
    }
    if (ospacing != Py_None) {
        if (!get_array(ospacing, "spacing", 'f', 1, ss, true, sp)) return nullptr;
        if (spacing_k < 1 || spacing_k > k)
            return PyErr_Format(PyExc_ValueError, "spacing_k must be in 1..k = %d, got %d", k, spacing_k);
    }
    if (ocover != Py_None) {  // the gap-closing radius with the PCA normal and that spacing
        if (!sp.held) return PyErr_Format(PyExc_ValueError, "the gap-closing radii need the spacing");
        if (!check_cover(cover_k, k, hole, max_gap) || !get_array(ocover, "cover", 'f', 1, ss, true, cov))
            return nullptr;
    }
    if (!check_separate({{nrm, "normals"}, {graph, "graph"}, {sp, "spacing"}, {cov, "cover"}}, {{rows, "rows"}}))
        return nullptr;
    const int32_t *r = rows.data<int32_t>();
    double *normals = nrm.data<double>();
    int32_t *g = graph.held ? graph.data<int32_t>() : nullptr;
    const Py_ssize_t gw = graph.held ? graph.dim(1) : 0;
    float *s = sp.held ? sp.data<float>() : nullptr, *c = cov.held ? cov.data<float>() : nullptr;
    if (!for_neighbours(index, r, size_t(m), k, threads, [&](size_t i, uint32_t self_slot, const float *d2, const uint32_t *slots) {
            double *ni = normals + 3 * i;
            pca_normal(index, self_slot, slots, k, ni);
            if (g) {
                g[i * gw] = r[i];
                for (Py_ssize_t j = 1; j < gw; ++j) g[i * gw + j] = int32_t(index.id(slots[j - 1]));
            }
            if (s) s[i] = std::sqrt(d2[spacing_k - 1]);
            if (c) {
                const float nf[3] = {float(ni[0]), float(ni[1]), float(ni[2])};
                c[i] = covering_radius(index, self_slot, slots, cover_k, nf, s[i], hole, max_gap);
            }
        }))
        return nullptr;
    Py_RETURN_NONE;
}

#define METHOD(name, doc) \
    {#name, reinterpret_cast<PyCFunction>(reinterpret_cast<void (*)()>(PointIndex_##name)), METH_VARARGS | METH_KEYWORDS, doc}

PyMethodDef PointIndex_methods[] = {
    {"order", PointIndex_order, METH_O, "order(out): fills out (int32 (N,)) with the points' ids in the tree's order."},
    METHOD(widest_gaps, "widest_gaps(rows, k, normals, out, threads=0): the widest angle between angularly "
                        "adjacent neighbours among each row's k nearest, in its tangent plane (the boundary test)."),
    METHOD(knn, "knn(rows, k, dist, ids, threads=0): the k nearest other points of each row's point, nearest first."),
    METHOD(knn_at, "knn_at(positions, k, dist, ids, threads=0): the k nearest points to each position."),
    METHOD(covering, "covering(rows, normals, spacing, k, hole, max_gap, out, threads=0): gap-closing radii."),
    METHOD(radii, "radii(rows, spacing_k, spacing, normals=None, cover_k=0, hole=0, max_gap=0, cover=None, threads=0, "
                  "by_row=False, cover_cap=0): k-NN spacing and gap-closing radii from one search."),
    METHOD(pca, "pca(rows, k, normals, graph=None, spacing_k=0, spacing=None, cover_k=0, hole=0, max_gap=0, cover=None, "
                "threads=0): PCA normals, and what the import needs from the same search."),
    {nullptr, nullptr, 0, nullptr},
};
#undef METHOD

PyGetSetDef PointIndex_getset[] = {
    {"size", PointIndex_size, nullptr, "Number of points.", nullptr},
    {nullptr, nullptr, nullptr, nullptr, nullptr},
};

PyType_Slot PointIndex_slots[] = {
    {Py_tp_new, reinterpret_cast<void *>(PointIndex_new)},
    {Py_tp_dealloc, reinterpret_cast<void *>(PointIndex_dealloc)},
    {Py_tp_methods, PointIndex_methods},
    {Py_tp_getset, PointIndex_getset},
    {Py_tp_doc, const_cast<char *>("PointIndex(points, threads=0): a k-d tree of float32 (N,3) points for "
                                   "k-nearest-neighbour queries (see splat_tracer/pointcloud/neighbours.py).")},
    {0, nullptr},
};

PyType_Spec PointIndex_spec = {"splat_tracer._core.PointIndex", sizeof(PointIndexObject), 0, Py_TPFLAGS_DEFAULT,
                               PointIndex_slots};

}  // namespace

int add_neighbour_types(PyObject *module) {
    PyObject *type = PyType_FromSpec(&PointIndex_spec);
    if (!type) return -1;
    if (PyModule_AddObject(module, "PointIndex", type) < 0) {
        Py_DECREF(type);
        return -1;
    }
    return PyModule_AddIntConstant(module, "MAX_NEIGHBOURS", PointIndex::kMaxK);
}

}  // namespace splat::py
