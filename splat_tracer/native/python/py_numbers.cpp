// Python binding of the number-table parser (pointcloud/numbers.h): `_core.parse_numbers`,
// which the text readers call through splat_tracer/pointcloud/readers/numbers.py.
#include <string>

#include "pointcloud/numbers.h"
#include "python/py_util.h"

namespace splat::py {
namespace {

// A bytearray of `bytes` bytes (uninitialised), or null with MemoryError set.
PyObject *new_bytes(size_t bytes) {
    if (bytes > size_t(PY_SSIZE_T_MAX)) return PyErr_NoMemory();
    return PyByteArray_FromStringAndSize(nullptr, Py_ssize_t(bytes));
}

// parse_numbers(data, threads=0, chunk_bytes=1 MiB) -> (values, per_line, bad_lines):
// bytearrays holding float64 values, int64 token counts per line and int64 line numbers
// (see parse_number_table). `data` is any contiguous buffer, read in place.
PyObject *parse_numbers_py(PyObject *, PyObject *args, PyObject *kwargs) {
    static const char *kwlist[] = {"data", "threads", "chunk_bytes", nullptr};
    PyObject *odata;
    int threads = 0;
    // Pieces of 1 MiB: enough of them to keep every core busy from a few MiB on, and each
    // a small share of its worker's time spent starting it.
    Py_ssize_t chunk_bytes = Py_ssize_t(1) << 20;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "O|in", const_cast<char **>(kwlist), &odata, &threads,
                                     &chunk_bytes))
        return nullptr;
    if (!check_threads(threads)) return nullptr;
    if (chunk_bytes < 1) return PyErr_Format(PyExc_ValueError, "chunk_bytes must be >= 1");
    if (PyUnicode_Check(odata)) return PyErr_Format(PyExc_TypeError, "data must be bytes (a buffer), not str");
    View data;
    if (PyObject_GetBuffer(odata, &data.buf, PyBUF_C_CONTIGUOUS) != 0) {
        PyErr_Clear();
        return PyErr_Format(PyExc_TypeError, "data must be a C-contiguous buffer (bytes, bytearray, memoryview)");
    }
    data.held = true;
    NumberTable table;
    if (!without_gil([&] {
            if (!parse_number_table(static_cast<const char *>(data.buf.buf), size_t(data.buf.len), size_t(chunk_bytes),
                                    threads, [] { return !exiting(); }, table))
                throw ExitStop();
        }))
        return nullptr;
    PyObject *values = new_bytes(table.values() * sizeof(double));
    PyObject *per_line = values ? new_bytes(table.lines() * sizeof(int64_t)) : nullptr;
    PyObject *bad = per_line ? new_bytes(table.bad_lines() * sizeof(int64_t)) : nullptr;
    if (!bad) {
        Py_XDECREF(values);
        Py_XDECREF(per_line);
        return nullptr;
    }
    double *v = reinterpret_cast<double *>(PyByteArray_AsString(values));
    int64_t *l = reinterpret_cast<int64_t *>(PyByteArray_AsString(per_line));
    int64_t *b = reinterpret_cast<int64_t *>(PyByteArray_AsString(bad));
    if (!without_gil([&] { table.copy(v, l, b, threads); })) {
        Py_DECREF(values), Py_DECREF(per_line), Py_DECREF(bad);
        return nullptr;
    }
    return Py_BuildValue("NNN", values, per_line, bad);
}

PyMethodDef number_methods[] = {
    {"parse_numbers", reinterpret_cast<PyCFunction>(reinterpret_cast<void (*)()>(parse_numbers_py)),
     METH_VARARGS | METH_KEYWORDS,
     "parse_numbers(data, threads=0, chunk_bytes=1<<20) -> (values, per_line, bad_lines): the whitespace-separated "
     "decimal numbers of a text buffer as float64 bytes, each line's count of tokens and the lines holding a token "
     "that is not a number (int64 bytes)."},
    {nullptr, nullptr, 0, nullptr},
};

}  // namespace

int add_number_functions(PyObject *module) { return PyModule_AddFunctions(module, number_methods); }

}  // namespace splat::py
