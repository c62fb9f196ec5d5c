// Shared by the binding files: buffer-protocol views with checked dtype, layout and shape,
// running C++ without the GIL, and the method read by field name. Built against the limited API.
#pragma once

#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdint>
#include <cstring>
#include <initializer_list>
#include <mutex>
#include <new>
#include <stdexcept>
#include <string>
#include <thread>

#include "base/errors.h"
#include "base/parallel.h"
#include "scene/camera.h"
#include "splats/splat_scene.h"
#include "splats/visibility.h"

namespace splat::py {

// ---------------------------------------------------------------------------------------
// Buffers

// A buffer view that releases itself.
struct View {
    Py_buffer buf{};
    bool held = false;
    ~View() {
        if (held) PyBuffer_Release(&buf);
    }
    template <class T>
    T *data() const { return static_cast<T *>(buf.buf); }
    Py_ssize_t dim(int i) const { return buf.shape[i]; }
};

// Element kinds accepted, by struct-module format letter.
inline bool format_matches(const char *format, Py_ssize_t itemsize, char kind) {
    if (!format) format = "B";
    char order = '@';
    if (*format == '@' || *format == '=' || *format == '<' || *format == '>' || *format == '!') order = *format++;
    const bool little = [] { uint16_t one = 1; return *reinterpret_cast<uint8_t *>(&one) == 1; }();
    if ((order == '>' || order == '!') && little) return false;
    if (order == '<' && !little) return false;
    if (std::strlen(format) != 1) return false;
    const char f = format[0];
    switch (kind) {
        case 'f': return f == 'f' && itemsize == 4;
        case 'd': return f == 'd' && itemsize == 8;
        case 'i': return (f == 'i' || f == 'l') && itemsize == 4;
        case 'B': return (f == 'B' || f == '?') && itemsize == 1;
        case 'q': return (f == 'q' || f == 'l' || f == 'Q' || f == 'L') && itemsize == 8;
    }
    return false;
}

inline const char *kind_name(char kind) {
    switch (kind) {
        case 'f': return "float32";
        case 'd': return "float64";
        case 'i': return "int32";
        case 'B': return "uint8 or bool";
        case 'q': return "int64";
    }
    return "?";
}

// Gets a C-contiguous buffer of `kind` with `ndim` dimensions; a positive entry of
// `shape` must match exactly, -1 means any. Sets a Python exception and returns false
// otherwise.
inline bool get_array(PyObject *obj, const char *name, char kind, int ndim, const Py_ssize_t *shape,
               bool writable, View &view) {
    int flags = PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0);
    if (PyObject_GetBuffer(obj, &view.buf, flags) != 0) {
        PyErr_Clear();
        PyErr_Format(PyExc_TypeError, "%s must be a C-contiguous%s %s array", name,
                     writable ? " writable" : "", kind_name(kind));
        return false;
    }
    view.held = true;
    if (!format_matches(view.buf.format, view.buf.itemsize, kind)) {
        PyErr_Format(PyExc_TypeError, "%s must have dtype %s (got format '%s')", name, kind_name(kind),
                     view.buf.format ? view.buf.format : "B");
        return false;
    }
    if (view.buf.ndim != ndim) {
        PyErr_Format(PyExc_ValueError, "%s must have %d dimension(s), got %d", name, ndim, view.buf.ndim);
        return false;
    }
    for (int i = 0; i < ndim; ++i) {
        if (shape[i] >= 0 && view.buf.shape[i] != shape[i]) {
            PyErr_Format(PyExc_ValueError, "%s has size %zd along axis %d, expected %zd", name,
                         view.buf.shape[i], i, shape[i]);
            return false;
        }
    }
    return true;
}

// A buffer argument and its name, for check_separate.
struct Named {
    const View &view;
    const char *name;
};

// Outputs must share no memory with any input or with one another: an output overlapping an
// input is read after being overwritten (an index then leads anywhere: a segfault), two
// outputs are written by two threads at once. Views not held (an omitted optional argument)
// are skipped. Sets ValueError naming both arguments and returns false otherwise.
inline bool check_separate(std::initializer_list<Named> outputs, std::initializer_list<Named> inputs) {
    auto overlap = [](const View &a, const View &b) {
        if (!a.held || !b.held || a.buf.len <= 0 || b.buf.len <= 0) return false;
        const char *p = static_cast<const char *>(a.buf.buf), *q = static_cast<const char *>(b.buf.buf);
        return p < q + b.buf.len && q < p + a.buf.len;
    };
    for (auto out = outputs.begin(); out != outputs.end(); ++out) {
        for (const Named &in : inputs)
            if (overlap(out->view, in.view))
                return PyErr_Format(PyExc_ValueError, "%s and %s share memory: an output needs a buffer of its own",
                                    out->name, in.name),
                       false;
        for (auto other = outputs.begin(); other != out; ++other)
            if (overlap(out->view, other->view))
                return PyErr_Format(PyExc_ValueError, "%s and %s share memory: each output needs a buffer of its own",
                                    out->name, other->name),
                       false;
    }
    return true;
}

// Runs `fn`, turning a C++ exception into the Python exception type to raise and its
// message: InputError (the caller's bad input) ValueError, bad_alloc MemoryError, anything
// else RuntimeError. Returns nullptr when fn returned. Touches no Python object: it may run
// without the GIL.
template <class F>
PyObject *run_native(F &&fn, std::string &message) {
    try {
        fn();
    } catch (const InputError &e) {
        return message = e.what(), PyExc_ValueError;
    } catch (const std::bad_alloc &) {
        return message = "out of memory", PyExc_MemoryError;
    } catch (const std::exception &e) {
        return message = e.what(), PyExc_RuntimeError;
    }
    return nullptr;
}

// ---------------------------------------------------------------------------------------
// Native work at interpreter exit
//
// A thread that takes the GIL back once Python's finalization has begun is ended by CPython
// (3.11 to 3.13: PyThread_exit_thread, a pthread_exit whose forced unwind through these C++
// frames aborts the process; later versions hang the thread instead). A daemon thread inside
// a render or an import when the main thread exits would do exactly that. So the module
// registers at_exit() with `atexit`, whose callbacks run before finalization begins: it asks
// every native loop to stop, refuses new calls, and waits (bounded) for the calls in flight
// to take the GIL back and return. A call still running when the wait ends parks its thread
// at its end without touching Python again: the process exits around it.

// Shared by every call of every instance of the module (process-wide), never destroyed: a
// parked thread may outlive static destruction.
struct ExitState {
    std::mutex mutex;
    std::condition_variable changed;
    std::atomic<bool> exiting{false};  // at_exit ran: native loops stop, new calls are refused
    bool closed = false;               // at_exit returned: no call may take the GIL back
    int calls = 0;                     // calls that released the GIL and have not returned
    int taking = 0;                    // of those, threads holding or waiting for the GIL
    // How long at_exit waits for the calls in flight. Stopped loops notice within a poll
    // (50 ms) and a task; the wait only matters for work that has no poll (building a BVH
    // or a k-d tree), which is safe to abandon by parking.
    std::chrono::milliseconds wait{2000};
};

inline ExitState &exit_state() {
    static ExitState *state = new ExitState;
    return *state;
}

// Whether Python is exiting: native loops poll this and stop. Any thread, no GIL needed.
inline bool exiting() { return exit_state().exiting.load(std::memory_order_relaxed); }

inline constexpr const char *kExitingMessage = "Python is exiting: native work stopped";

// Thrown by a native loop that stopped because Python is exiting; run_native makes it the
// RuntimeError above.
struct ExitStop : std::runtime_error {
    ExitStop() : std::runtime_error(kExitingMessage) {}
};

// The GIL released for one call's native work, taken back only while that is safe (see
// above). release() once with the GIL, then without it any number of take() / give() pairs
// (progress callbacks), then finish().
class GilRelease {
  public:
    GilRelease() = default;
    GilRelease(const GilRelease &) = delete;
    GilRelease &operator=(const GilRelease &) = delete;

    // With the GIL: releases it. False with RuntimeError set when Python is exiting.
    bool release() {
        ExitState &s = exit_state();
        {
            std::lock_guard<std::mutex> lock(s.mutex);
            if (s.exiting) return PyErr_SetString(PyExc_RuntimeError, kExitingMessage), false;
            ++s.calls;
        }
        saved_ = PyEval_SaveThread();
        return true;
    }
    // Without the GIL: takes it (for a progress callback). Never returns once at_exit has
    // returned: the thread parks.
    void take() {
        ExitState &s = exit_state();
        {
            std::unique_lock<std::mutex> lock(s.mutex);
            if (s.closed) {
                lock.unlock();
                for (;;) std::this_thread::sleep_for(std::chrono::hours(1));
            }
            ++s.taking;
        }
        PyEval_RestoreThread(saved_);
    }
    // With the GIL, after take(): releases it again to go on with the work.
    void give() {
        done_taking(false);
        saved_ = PyEval_SaveThread();
    }
    // Without the GIL: takes it back at the end of the call (or parks, as take()).
    void finish() {
        take();
        done_taking(true);
    }

  private:
    static void done_taking(bool returned) {
        ExitState &s = exit_state();
        std::lock_guard<std::mutex> lock(s.mutex);
        --s.taking;
        if (returned) --s.calls;
        s.changed.notify_all();
    }
    PyThreadState *saved_ = nullptr;
};

// The module's atexit callback (registered by module_exec): see ExitState. Called with the
// GIL; waits without it.
inline PyObject *at_exit(PyObject *, PyObject *) {
    ExitState &s = exit_state();
    {
        std::lock_guard<std::mutex> lock(s.mutex);
        if (s.closed) Py_RETURN_NONE;  // a second instance of the module: done already
        s.exiting = true;
    }
    Py_BEGIN_ALLOW_THREADS
    std::unique_lock<std::mutex> lock(s.mutex);
    s.changed.wait_for(lock, s.wait, [&] { return s.calls == 0; });
    // A thread in a progress callback or returning holds or is about to hold the GIL: it is
    // let through (it gives the GIL back within the callback), never cut off holding it.
    s.changed.wait(lock, [&] { return s.taking == 0; });
    s.closed = true;
    lock.unlock();
    Py_END_ALLOW_THREADS
    Py_RETURN_NONE;
}

// parallel_for over `count` tasks with no progress callback, stopping when Python exits
// (ExitStop).
template <class Task>
void parallel_until_exit(size_t count, int threads, Task &&task) {
    if (!parallel_for(count, threads, task, [](size_t) { return !exiting(); })) throw ExitStop();
}

// Runs `fn` without the GIL, turning C++ exceptions into Python ones (run_native). Returns
// false with a Python exception set when `fn` threw, or when Python is exiting.
template <class F>
bool without_gil(F &&fn) {
    std::string message;
    GilRelease gil;
    if (!gil.release()) return false;
    PyObject *type = run_native(fn, message);
    gil.finish();
    if (type) PyErr_SetString(type, message.c_str());
    return type == nullptr;
}

// threads: 0 for all cores, else that many. Sets ValueError and returns false when negative.
inline bool check_threads(int threads) {
    if (threads < 0) return PyErr_Format(PyExc_ValueError, "threads must be >= 0 (0: all cores)"), false;
    return true;
}

// The names of the position rules and kernels as render.method.Method spells them
// (POSITION_RULES, KERNELS), in the order of the enums.
inline constexpr const char *kPositionRuleNames[] = {"FIRST", "NEAR_PHASE", "NEAREST_CENTRE"};
inline constexpr const char *kKernelNames[] = {"LINEAR", "SMOOTH"};

// Field `name` of the method object (a new reference), or null with a TypeError naming it.
inline PyObject *method_field(PyObject *obj, const char *name) {
    PyObject *value = PyObject_GetAttrString(obj, name);
    if (!value) {
        PyErr_Clear();
        PyErr_Format(PyExc_TypeError, "method has no field '%s' (see render.method.Method)", name);
    }
    return value;
}

// A switch: any object's truth value, as Python's bool() takes it.
inline bool method_bool(PyObject *obj, const char *name, bool &out) {
    PyObject *value = method_field(obj, name);
    if (!value) return false;
    const int truth = PyObject_IsTrue(value);
    Py_DECREF(value);
    if (truth < 0) return false;
    out = truth != 0;
    return true;
}

// A number (a float, or anything float() takes without parsing a string).
inline bool method_float(PyObject *obj, const char *name, float &out) {
    PyObject *value = method_field(obj, name);
    if (!value) return false;
    const double v = PyFloat_AsDouble(value);
    Py_DECREF(value);
    if (v == -1.0 && PyErr_Occurred()) {
        PyErr_Clear();
        return PyErr_Format(PyExc_TypeError, "method field '%s' must be a number", name), false;
    }
    out = float(v);
    return true;
}

// One of `names` (a str), as its index.
template <size_t N>
bool method_choice(PyObject *obj, const char *name, const char *const (&names)[N], int &out) {
    PyObject *value = method_field(obj, name);
    if (!value) return false;
    const char *text = PyUnicode_Check(value) ? PyUnicode_AsUTF8AndSize(value, nullptr) : nullptr;
    for (size_t i = 0; text && i < N; ++i) {
        if (std::strcmp(text, names[i]) == 0) {
            Py_DECREF(value);
            out = int(i);
            return true;
        }
    }
    PyErr_Clear();
    std::string choices;
    for (const char *n : names) choices += (choices.empty() ? "" : ", ") + std::string(n);
    PyErr_Format(PyExc_ValueError, "method field '%s' must be one of %s, got %R", name, choices.c_str(), value);
    Py_DECREF(value);
    return false;
}

// The method, read field by field by name from a render.method.Method (or any object with
// its fields); None keeps `m`'s defaults. Returns false with an exception set when a field
// is missing or invalid.
inline bool parse_method(PyObject *obj, Method &m) {
    if (obj == Py_None) return true;
    bool wrong_hit_elimination, normal_interpolation, far_phase;
    int position, kernel;
    float epsilon, crease_angle;
    if (!method_bool(obj, "wrong_hit_elimination", wrong_hit_elimination) ||
        !method_bool(obj, "normal_interpolation", normal_interpolation) || !method_bool(obj, "far_phase", far_phase) ||
        !method_choice(obj, "position", kPositionRuleNames, position) ||
        !method_choice(obj, "kernel", kKernelNames, kernel) || !method_float(obj, "epsilon", epsilon) ||
        !method_float(obj, "crease_angle", crease_angle))
        return false;
    if (!(std::isfinite(epsilon) && epsilon >= 0.f))
        return PyErr_Format(PyExc_ValueError, "epsilon must be finite and >= 0"), false;
    if (!(crease_angle >= 0.f && crease_angle <= 180.f))
        return PyErr_Format(PyExc_ValueError, "crease angle must be between 0 and 180 degrees"), false;
    m.wrong_hit_elimination = wrong_hit_elimination, m.normal_interpolation = normal_interpolation;
    m.far_phase = far_phase, m.position = PositionRule(position), m.kernel = Kernel(kernel), m.epsilon = epsilon;
    m.crease_cos = crease_angle >= 180.f ? -2.f : std::cos(crease_angle * float(M_PI) / 180.f);
    return true;
}

// Runs task(t, stop) for the `tiles` tiles on `threads` threads without the GIL. `progress`
// (None or a callable) runs on this (the calling) thread, with the GIL, between waits, as
// progress(done, total); it returns True to stop. An exception from it stops the work and
// is re-raised. Once a stop is asked (or Python is exiting) `stop` is set: a long tile may
// end early with its pixels unfinished. Returns 1 when every tile was done, 0 when stopped,
// -1 with an exception set (RuntimeError when Python is exiting). A render in rounds (one
// run_tiles each) reports progress(base + done * scale, total) instead.
template <class Task>
int run_tiles(size_t tiles, int threads, PyObject *progress, Task &&task, size_t base = 0, size_t scale = 1,
              size_t total = 0) {
    if (total == 0) total = tiles;
    bool callback_failed = false, completed = false, exit_stop = false;
    std::atomic<bool> stop{false};
    GilRelease gil;
    auto poll = [&](size_t done) {
        bool go_on = true;
        if (exiting()) {
            exit_stop = true, go_on = false;
        } else if (progress != Py_None) {
            gil.take();
            PyObject *res =
                PyObject_CallFunction(progress, "nn", Py_ssize_t(base + done * scale), Py_ssize_t(total));
            if (!res) {
                callback_failed = true, go_on = false;
            } else {
                const int asked = PyObject_IsTrue(res);
                Py_DECREF(res);
                if (asked < 0) callback_failed = true;
                go_on = asked == 0;
            }
            gil.give();
        }
        if (!go_on) stop = true;
        return go_on;
    };
    std::string message;
    PyObject *error_type = nullptr;
    if (!gil.release()) return -1;
    try {
        completed = parallel_for(tiles, threads, [&](size_t t) { task(t, stop); }, poll);
    } catch (const std::bad_alloc &) {
        error_type = PyExc_MemoryError, message = "out of memory";
    } catch (const std::exception &e) {
        error_type = PyExc_RuntimeError, message = e.what();
    }
    // A last report, so that callers see 100 %: still inside the call (between take and
    // give), since the callback may release the GIL and want it back.
    if (progress != Py_None && completed && !error_type) {
        gil.take();
        PyObject *res =
            PyObject_CallFunction(progress, "nn", Py_ssize_t(base + tiles * scale), Py_ssize_t(total));
        if (res) Py_DECREF(res);
        else callback_failed = true;
        gil.give();
    }
    gil.finish();
    if (callback_failed) return -1;  // the callback's exception is still set
    if (exit_stop && !error_type) error_type = PyExc_RuntimeError, message = kExitingMessage;
    if (error_type) {
        PyErr_SetString(error_type, message.c_str());
        return -1;
    }
    return completed ? 1 : 0;
}

// The scalar arguments of a render call: image size, window, tile size, threads, progress.
// Sets an exception and returns false when unusable.
inline bool check_render_args(int width, int height, int x0, int y0, int w, int h, int tile_size, int threads,
                              PyObject *progress) {
    if (width <= 0 || height <= 0) return PyErr_Format(PyExc_ValueError, "image size must be positive"), false;
    // In 64 bits: x0 + w may overflow int for a window near 2^31.
    if (x0 < 0 || y0 < 0 || w <= 0 || h <= 0 || int64_t(x0) + w > width || int64_t(y0) + h > height)
        return PyErr_Format(PyExc_ValueError, "window (%d, %d, %d, %d) is not inside the %dx%d image", x0, y0, w, h,
                            width, height),
               false;
    if (tile_size <= 0 || tile_size > 4096)
        return PyErr_Format(PyExc_ValueError, "tile_size must be in 1..4096"), false;
    if (!check_threads(threads)) return false;
    if (progress != Py_None && !PyCallable_Check(progress))
        return PyErr_Format(PyExc_TypeError, "progress must be callable or None"), false;
    return true;
}

// The arrays of a camera, held while the call runs (for check_separate).
struct CameraViews {
    View m, frustum;
};

// A camera from its parameters (render.camera.Camera): local_from_camera 4x4 (an affine
// matrix), frustum 12 (left, right, bottom, top, clip start, clip end, the projection and
// its 5 parameters: render.camera.Camera.native()), all float64 and finite, and whether it
// is orthographic. Sets an exception and returns false otherwise.
// `views` holds the two arrays while the call runs (for check_separate).
inline bool parse_camera(PyObject *om, PyObject *ofrustum, int orthographic, Camera &cam, CameraViews &views) {
    View &m = views.m, &fr = views.frustum;
    Py_ssize_t s44[2] = {4, 4}, s12[1] = {12};
    if (!get_array(om, "local_from_camera", 'd', 2, s44, false, m) ||
        !get_array(ofrustum, "frustum", 'd', 1, s12, false, fr))
        return false;
    const double *a = m.data<double>(), *f = fr.data<double>();
    for (int k = 0; k < 16; ++k)
        if (!std::isfinite(a[k])) return PyErr_Format(PyExc_ValueError, "local_from_camera must be finite"), false;
    if (a[12] != 0.0 || a[13] != 0.0 || a[14] != 0.0 || a[15] != 1.0)
        return PyErr_Format(PyExc_ValueError, "local_from_camera must be affine (last row 0 0 0 1)"), false;
    for (int k = 0; k < 12; ++k)
        if (!std::isfinite(f[k])) return PyErr_Format(PyExc_ValueError, "frustum must be finite"), false;
    if (!(f[0] < f[1] && f[2] < f[3]))
        return PyErr_Format(PyExc_ValueError, "frustum must have left < right and bottom < top"), false;
    if (!(f[4] < f[5]) || (!orthographic && !(f[4] > 0.0)))
        return PyErr_Format(PyExc_ValueError, "need clip start < clip end (and clip start > 0 for a perspective "
                                              "camera)"), false;
    std::memcpy(cam.local_from_camera, a, sizeof cam.local_from_camera);
    std::memcpy(cam.frustum, f, sizeof cam.frustum);
    cam.clip_start = f[4], cam.clip_end = f[5];
    cam.orthographic = orthographic != 0;
    // The projection and its parameters (render.camera.Panorama.native()).
    const double *pano = f + 7;
    const int kind = int(f[6]);
    bool ok = double(kind) == f[6] && kind >= Camera::kPlanar && kind < Camera::kProjections;
    if (ok && kind == Camera::kFisheyeEquidistant) ok = pano[0] > 0.0;
    if (ok && kind == Camera::kFisheyeEquisolid) ok = pano[0] > 0.0 && pano[1] > 0.0 && pano[2] > 0.0 && pano[3] > 0.0;
    if (!ok || (kind != Camera::kPlanar && orthographic))
        return PyErr_Format(PyExc_ValueError, "frustum[6:] is not a projection (render.camera.Panorama.native())"),
               false;
    cam.projection = kind;
    std::memcpy(cam.pano, pano, sizeof cam.pano);
    if (!cam.derive_axes()) return PyErr_Format(PyExc_ValueError, "local_from_camera has no view axis (-Z)"), false;
    return true;
}

// A camera's thin lens (render.camera.Lens.native()): None (a pinhole) or (radius,
// focus_distance, blades, rotation, ratio), finite, radius >= 0, focus distance and ratio
// > 0, blades 0 or 3..kMaxBlades. Sets an exception and returns false otherwise.
inline bool parse_lens(PyObject *olens, Camera &cam) {
    if (olens == Py_None) return true;
    if (!PyTuple_Check(olens)) return PyErr_Format(PyExc_TypeError, "lens must be None or a tuple (Lens.native())"), false;
    double radius, focus, rotation, ratio;
    int blades;
    if (!PyArg_ParseTuple(olens, "ddidd;lens must be Lens.native(): (radius, focus_distance, blades, rotation, ratio)",
                          &radius, &focus, &blades, &rotation, &ratio))
        return false;
    constexpr int kMaxBlades = 1 << 16;  // Blender allows 16; anything more is a disc to float precision
    if (!(std::isfinite(radius) && std::isfinite(focus) && std::isfinite(rotation) && std::isfinite(ratio)) ||
        !(radius >= 0.0 && focus > 0.0 && ratio > 0.0) || !(blades == 0 || (blades >= 3 && blades <= kMaxBlades)))
        return PyErr_Format(PyExc_ValueError, "lens out of range: need finite values, radius >= 0, focus_distance > 0, "
                                              "ratio > 0 and blades 0 or 3..%d", kMaxBlades), false;
    cam.lens_radius = radius, cam.focus_distance = focus, cam.blades = blades, cam.blade_rotation = rotation;
    cam.aperture_ratio = ratio;
    return true;
}

// The splat scene inside a `_core.SplatCloud` object, or null (no exception set) for anything else.
const SplatScene *as_splat_scene(PyObject *obj);
// Adds `Mesh` and `RenderScene` to the module (py_render.cpp).
int add_render_types(PyObject *module);
// Adds `PointIndex` to the module (py_neighbours.cpp).
int add_neighbour_types(PyObject *module);
// Adds the neighbour-graph functions (py_graph.cpp).
int add_graph_functions(PyObject *module);
// Adds `parse_numbers` (py_numbers.cpp).
int add_number_functions(PyObject *module);

}  // namespace splat::py
