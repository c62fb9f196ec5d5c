// Python bindings of the neighbour-graph routines (graph.h) that normals.orient() uses:
// `_core.spatial_order`, `permute_table`, `take_rows`, `graph_weights`, `spanning_forest`,
// `forest_traversal` and `chain_flips`, and the importer's `first_of_duplicates`
// (duplicates.h). The caller (splat_tracer/pointcloud/) allocates every output; every input is
// validated here too.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <initializer_list>
#include <string>

#include "pointcloud/duplicates.h"
#include "pointcloud/graph.h"
#include "python/py_util.h"

namespace splat::py {
namespace {

// Runs fn(poll) without the GIL. `progress` (None or a callable) is called as
// progress(fraction) on this thread, with the GIL, whenever the work polls; an exception
// from it (the user cancelled) stops the work and is re-raised. The work also stops when
// Python is exiting (RuntimeError; see GilRelease). Returns false with a Python exception
// set on any failure.
template <class Fn>
bool run_graph(PyObject *progress, Fn &&fn) {
    GilRelease gil;
    bool callback_failed = false, exit_stop = false;
    const GraphPoll poll = [&](double fraction) {
        if (exiting()) return exit_stop = true, false;
        if (progress == Py_None) return true;
        gil.take();
        PyObject *res = PyObject_CallFunction(progress, "d", fraction);
        if (res) Py_DECREF(res);
        else callback_failed = true;
        gil.give();
        return !callback_failed;
    };
    std::string message;
    if (!gil.release()) return false;
    PyObject *error_type = run_native([&] { fn(poll); }, message);
    gil.finish();
    if (callback_failed) return false;  // its exception is still set
    if (exit_stop && !error_type) error_type = PyExc_RuntimeError, message = kExitingMessage;
    if (error_type) PyErr_SetString(error_type, message.c_str());
    return error_type == nullptr;
}

bool check_progress(PyObject *progress) {
    if (progress != Py_None && !PyCallable_Check(progress))
        return PyErr_Format(PyExc_TypeError, "progress must be callable or None"), false;
    return true;
}

// (points, out, threads=0): fn(points, n, out, threads) over (N,3) float64 points into an
// (N,) output of element kind `kind` (get_array's letters) and C type Out. kFloat32Too: float32
// points are passed as they are (fn takes either pointer type).
template <class Out, bool kFloat32Too = false, class Fn>
PyObject *per_point(PyObject *args, PyObject *kwargs, char kind, Fn &&fn) {
    static const char *kwlist[] = {"points", "out", "threads", nullptr};
    PyObject *op, *oout;
    int threads = 0;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OO|i", const_cast<char **>(kwlist), &op, &oout, &threads))
        return nullptr;
    if (!check_threads(threads)) return nullptr;
    View p, out;
    Py_ssize_t s3[2] = {-1, 3};
    const bool single = kFloat32Too && [&] {
        View probe;
        return get_array(op, "points", 'f', 2, s3, false, probe) || (PyErr_Clear(), false);
    }();
    if (!get_array(op, "points", single ? 'f' : 'd', 2, s3, false, p)) return nullptr;
    Py_ssize_t sn[1] = {p.dim(0)};
    if (!get_array(oout, "out", kind, 1, sn, true, out) || !check_separate({{out, "out"}}, {{p, "points"}})) return nullptr;
    if (!run_graph(Py_None, [&](const GraphPoll &) {
            if constexpr (kFloat32Too) {
                if (single) return fn(p.data<float>(), size_t(p.dim(0)), out.data<Out>(), threads);
            }
            fn(p.data<double>(), size_t(p.dim(0)), out.data<Out>(), threads);
        }))
        return nullptr;
    Py_RETURN_NONE;
}

PyObject *spatial_order_py(PyObject *, PyObject *args, PyObject *kwargs) {
    return per_point<int32_t>(args, kwargs, 'i', [](const double *p, size_t n, int32_t *out, int threads) {
        spatial_order(p, n, out, threads);
    });
}

PyObject *permute_table_py(PyObject *, PyObject *args, PyObject *kwargs) {
    static const char *kwlist[] = {"table", "order", "first", "out", "threads", nullptr};
    PyObject *otable, *oorder, *oout;
    Py_ssize_t first;
    int threads = 0;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOnO|i", const_cast<char **>(kwlist), &otable, &oorder, &first,
                                     &oout, &threads))
        return nullptr;
    if (!check_threads(threads)) return nullptr;
    View table, order, out;
    Py_ssize_t s2[2] = {-1, -1};
    if (!get_array(otable, "table", 'i', 2, s2, false, table)) return nullptr;
    const Py_ssize_t n = table.dim(0);
    Py_ssize_t sn[1] = {n}, so[2] = {n, -1};
    if (!get_array(oorder, "order", 'i', 1, sn, false, order) || !get_array(oout, "out", 'i', 2, so, true, out) ||
        !check_separate({{out, "out"}}, {{table, "table"}, {order, "order"}}))
        return nullptr;
    if (first < 0 || first + out.dim(1) > table.dim(1))
        return PyErr_Format(PyExc_ValueError, "columns %zd to %zd are not all in the table's %zd", first,
                            first + out.dim(1) - 1, table.dim(1));
    if (!run_graph(Py_None, [&](const GraphPoll &) {
            permute_table(table.data<int32_t>(), size_t(n), size_t(table.dim(1)), size_t(first), size_t(out.dim(1)),
                          order.data<int32_t>(), out.data<int32_t>(), threads);
        }))
        return nullptr;
    Py_RETURN_NONE;
}

PyObject *take_rows_py(PyObject *, PyObject *args, PyObject *kwargs) {
    static const char *kwlist[] = {"array", "order", "out", "threads", nullptr};
    PyObject *oa, *oorder, *oout;
    int threads = 0;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOO|i", const_cast<char **>(kwlist), &oa, &oorder, &oout, &threads))
        return nullptr;
    if (!check_threads(threads)) return nullptr;
    View a, order, out;
    Py_ssize_t s2[2] = {-1, -1}, s1[1] = {-1};
    if (!get_array(oa, "array", 'd', 2, s2, false, a) || !get_array(oorder, "order", 'i', 1, s1, false, order))
        return nullptr;
    Py_ssize_t so[2] = {order.dim(0), a.dim(1)};
    if (!get_array(oout, "out", 'd', 2, so, true, out) || !check_separate({{out, "out"}}, {{a, "array"}, {order, "order"}})) return nullptr;
    if (!run_graph(Py_None, [&](const GraphPoll &) {
            take_rows(a.data<double>(), size_t(a.dim(0)), size_t(a.dim(1)), order.data<int32_t>(),
                      size_t(order.dim(0)), out.data<double>(), threads);
        }))
        return nullptr;
    Py_RETURN_NONE;
}

// first_of_duplicates(points, out, threads=0): points (N,3) float64 or float32.
PyObject *first_of_duplicates_py(PyObject *, PyObject *args, PyObject *kwargs) {
    return per_point<uint8_t, true>(args, kwargs, 'B', [](const auto *p, size_t n, uint8_t *out, int threads) {
        first_of_duplicates(p, n, out, threads);
    });
}

PyObject *graph_weights(PyObject *, PyObject *args, PyObject *kwargs) {
    static const char *kwlist[] = {"points", "normals", "neighbours", "across", "out", "threads", "progress", nullptr};
    PyObject *op, *on, *onbr, *oout, *progress = Py_None;
    double across;
    int threads = 0;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOOdO|iO", const_cast<char **>(kwlist), &op, &on, &onbr, &across,
                                     &oout, &threads, &progress))
        return nullptr;
    if (!check_threads(threads) || !check_progress(progress)) return nullptr;
    if (!std::isfinite(across)) return PyErr_Format(PyExc_ValueError, "across must be finite");
    View p, n, nbr, out;
    Py_ssize_t s3[2] = {-1, 3};
    if (!get_array(op, "points", 'd', 2, s3, false, p)) return nullptr;
    const Py_ssize_t count = p.dim(0);
    Py_ssize_t sn[2] = {count, 3}, sk[2] = {count, -1};
    if (!get_array(on, "normals", 'd', 2, sn, false, n) || !get_array(onbr, "neighbours", 'i', 2, sk, false, nbr))
        return nullptr;
    Py_ssize_t so[2] = {count, nbr.dim(1)};
    if (!get_array(oout, "out", 'f', 2, so, true, out) || !check_separate({{out, "out"}}, {{p, "points"}, {n, "normals"}, {nbr, "neighbours"}})) return nullptr;
    if (!run_graph(progress, [&](const GraphPoll &poll) {
            neighbour_edge_weights(p.data<double>(), n.data<double>(), size_t(count), nbr.data<int32_t>(),
                                          size_t(nbr.dim(1)), across, out.data<float>(), threads, poll);
        }))
        return nullptr;
    Py_RETURN_NONE;
}

PyObject *spanning_forest(PyObject *, PyObject *args, PyObject *kwargs) {
    static const char *kwlist[] = {"neighbours", "weights", "out_edges", "out_labels", "threads", "progress", nullptr};
    PyObject *onbr, *ow, *oedges, *olabels, *progress = Py_None;
    int threads = 0;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOOO|iO", const_cast<char **>(kwlist), &onbr, &ow, &oedges,
                                     &olabels, &threads, &progress))
        return nullptr;
    if (!check_threads(threads) || !check_progress(progress)) return nullptr;
    View nbr, w, edges, labels;
    Py_ssize_t sk[2] = {-1, -1};
    if (!get_array(onbr, "neighbours", 'i', 2, sk, false, nbr)) return nullptr;
    const Py_ssize_t count = nbr.dim(0), k = nbr.dim(1);
    Py_ssize_t sw[2] = {count, k}, se[2] = {std::max<Py_ssize_t>(count - 1, 0), 2}, sl[1] = {count};
    if (!get_array(ow, "weights", 'f', 2, sw, false, w) || !get_array(oedges, "out_edges", 'i', 2, se, true, edges) ||
        !get_array(olabels, "out_labels", 'i', 1, sl, true, labels) ||
        !check_separate({{edges, "out_edges"}, {labels, "out_labels"}}, {{nbr, "neighbours"}, {w, "weights"}}))
        return nullptr;
    size_t n_edges = 0, n_components = 0;
    if (!run_graph(progress, [&](const GraphPoll &poll) {
            minimum_spanning_forest(nbr.data<int32_t>(), w.data<float>(), size_t(count), size_t(k),
                                    edges.data<int32_t>(), labels.data<int32_t>(), n_edges, n_components, threads, poll);
        }))
        return nullptr;
    return Py_BuildValue("nn", Py_ssize_t(n_edges), Py_ssize_t(n_components));
}

PyObject *forest_traversal_py(PyObject *, PyObject *args, PyObject *kwargs) {
    static const char *kwlist[] = {"edges", "anchors", "out_parent", "out_order", "progress", nullptr};
    PyObject *oedges, *oanchors, *oparent, *oorder, *progress = Py_None;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOOO|O", const_cast<char **>(kwlist), &oedges, &oanchors, &oparent,
                                     &oorder, &progress))
        return nullptr;
    if (!check_progress(progress)) return nullptr;
    View edges, anchors, parent, order;
    Py_ssize_t se[2] = {-1, 2}, s1[1] = {-1};
    if (!get_array(oedges, "edges", 'i', 2, se, false, edges) || !get_array(oanchors, "anchors", 'B', 1, s1, false, anchors))
        return nullptr;
    const Py_ssize_t count = anchors.dim(0);
    Py_ssize_t sn[1] = {count};
    if (!get_array(oparent, "out_parent", 'i', 1, sn, true, parent) ||
        !get_array(oorder, "out_order", 'i', 1, sn, true, order) ||
        !check_separate({{parent, "out_parent"}, {order, "out_order"}}, {{edges, "edges"}, {anchors, "anchors"}}))
        return nullptr;
    size_t reached = 0;
    if (!run_graph(progress, [&](const GraphPoll &poll) {
            forest_traversal(edges.data<int32_t>(), size_t(edges.dim(0)), size_t(count), anchors.data<uint8_t>(),
                             parent.data<int32_t>(), order.data<int32_t>(), reached, poll);
        }))
        return nullptr;
    return PyLong_FromSize_t(reached);
}

PyObject *chain_flips_py(PyObject *, PyObject *args, PyObject *kwargs) {
    static const char *kwlist[] = {"order", "parent", "flip", "out_negative", nullptr};
    PyObject *oorder, *oparent, *oflip, *oneg;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOOO", const_cast<char **>(kwlist), &oorder, &oparent, &oflip, &oneg))
        return nullptr;
    View order, parent, flip, neg;
    Py_ssize_t s1[1] = {-1};
    if (!get_array(oorder, "order", 'i', 1, s1, false, order) || !get_array(oparent, "parent", 'i', 1, s1, false, parent))
        return nullptr;
    Py_ssize_t sn[1] = {parent.dim(0)};
    if (!get_array(oflip, "flip", 'B', 1, sn, false, flip) || !get_array(oneg, "out_negative", 'B', 1, sn, true, neg) ||
        !check_separate({{neg, "out_negative"}}, {{order, "order"}, {parent, "parent"}, {flip, "flip"}}))
        return nullptr;
    if (!run_graph(Py_None, [&](const GraphPoll &) {
            chain_flips(order.data<int32_t>(), size_t(order.dim(0)), parent.data<int32_t>(), flip.data<uint8_t>(),
                        size_t(parent.dim(0)), neg.data<uint8_t>());
        }))
        return nullptr;
    Py_RETURN_NONE;
}

template <class F>
PyCFunction keywords(F f) {
    return reinterpret_cast<PyCFunction>(reinterpret_cast<void (*)()>(f));
}

PyMethodDef graph_methods[] = {
    {"spatial_order", keywords(spatial_order_py), METH_VARARGS | METH_KEYWORDS,
     "spatial_order(points, out, threads=0)\n--\n\nThe points' indices in Morton order (graph.h)."},
    {"permute_table", keywords(permute_table_py), METH_VARARGS | METH_KEYWORDS,
     "permute_table(table, order, first, out, threads=0)\n--\n\n"
     "out[r] = the new numbers (by order) of table[order[r], first:first + out.shape[1]]."},
    {"take_rows", keywords(take_rows_py), METH_VARARGS | METH_KEYWORDS,
     "take_rows(array, order, out, threads=0)\n--\n\nout[r] = array[order[r]] for float64 (n,c) arrays, in parallel."},
    {"first_of_duplicates", keywords(first_of_duplicates_py), METH_VARARGS | METH_KEYWORDS,
     "first_of_duplicates(points, out, threads=0)\n--\n\n"
     "out[i] = 1 when no earlier row of the float64 or float32 (n,3) points has row i's position (duplicates.h)."},
    {"graph_weights", keywords(graph_weights), METH_VARARGS | METH_KEYWORDS,
     "graph_weights(points, normals, neighbours, across, out, threads=0, progress=None)\n--\n\n"
     "Weights of the neighbour table's edges (graph.h): float64 (n,3) points and normals, int32 (n,k) "
     "neighbours, float32 (n,k) out."},
    {"spanning_forest", keywords(spanning_forest), METH_VARARGS | METH_KEYWORDS,
     "spanning_forest(neighbours, weights, out_edges, out_labels, threads=0, progress=None)\n--\n\n"
     "Minimum spanning forest of the neighbour table's graph; returns (edge_count, component_count)."},
    {"forest_traversal", keywords(forest_traversal_py), METH_VARARGS | METH_KEYWORDS,
     "forest_traversal(edges, anchors, out_parent, out_order, progress=None)\n--\n\n"
     "Breadth-first traversal from every anchor at once; returns the number of vertices reached."},
    {"chain_flips", keywords(chain_flips_py), METH_VARARGS | METH_KEYWORDS,
     "chain_flips(order, parent, flip, out_negative)\n--\n\n"
     "Signs along a traversal: each vertex's parent's, flipped where flip is set."},
    {nullptr, nullptr, 0, nullptr},
};

}  // namespace

int add_graph_functions(PyObject *module) { return PyModule_AddFunctions(module, graph_methods); }

}  // namespace splat::py
