// Python bindings of the core: `splat_tracer._core`.
//
// Built against the CPython limited API (Py_LIMITED_API = 3.11, abi3) so that one binary
// loads in every Blender from 4.2 (Python 3.11) to 5.2 (Python 3.13). Arrays travel
// through the buffer protocol: the caller (splat_tracer/render/, splat_tracer/pointcloud/) allocates every output
// with numpy, so this file never needs numpy's C API. Every input is validated here as
// well, since the module may be called directly: bad input raises, it never crashes.
#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include <atomic>
#include <cmath>
#include <cstring>
#include <memory>
#include <new>
#include <string>
#include <vector>

#include "base/config.h"
#include "base/parallel.h"
#include "base/simd.h"
#include "bvh/packet.h"
#include "python/py_util.h"
#include "shade/environment.h"
#include "shade/render.h"
#include "splats/splat_scene.h"

namespace {

using namespace splat;
using namespace splat::py;

// ---------------------------------------------------------------------------------------
// Rays

// Origins and directions must be finite, directions non-zero; sets ValueError naming the
// first bad ray otherwise.
bool check_rays(const float *origins, const float *directions, Py_ssize_t count) {
    for (Py_ssize_t i = 0; i < count; ++i) {
        const float *a = origins + 3 * i, *b = directions + 3 * i;
        if (!(within_range(a[0]) && within_range(a[1]) && within_range(a[2])))
            return PyErr_Format(PyExc_ValueError, "ray %zd: origin is not finite or beyond 1e18", i), false;
        // Non-zero: any non-zero finite float component gives a length make_ray can divide
        // by (it squares in double, where even 1e-45 squared is far from underflowing).
        if (!(std::isfinite(b[0]) && std::isfinite(b[1]) && std::isfinite(b[2])) ||
            !(b[0] != 0.f || b[1] != 0.f || b[2] != 0.f))
            return PyErr_Format(PyExc_ValueError, "ray %zd: direction must be finite and non-zero", i), false;
    }
    return true;
}

// The scalar arguments every ray batch takes; sets ValueError when they are unusable.
bool check_batch_args(double tmin, double tmax, int threads) {
    if (std::isnan(tmin) || std::isnan(tmax) || !(tmin < tmax))
        return PyErr_Format(PyExc_ValueError, "need tmin < tmax, both numbers"), false;
    if (!check_threads(threads)) return false;
    return true;
}

Ray make_ray(const float *origins, const float *directions, size_t i, double tmin, double tmax) {
    Ray ray;
    ray.o = Vec3(origins[3 * i], origins[3 * i + 1], origins[3 * i + 2]);
    // Normalised in double: any finite non-zero float direction (1e-30 or 1e30 long) works.
    const double dx = directions[3 * i], dy = directions[3 * i + 1], dz = directions[3 * i + 2];
    const double inv = 1.0 / std::sqrt(dx * dx + dy * dy + dz * dz);  // one division, not three
    ray.d = Vec3(float(dx * inv), float(dy * inv), float(dz * inv));
    ray.tmin = float(tmin), ray.tmax = float(tmax);
    return ray;
}

// ---------------------------------------------------------------------------------------
// Scene

struct SplatCloudObject {
    PyObject_HEAD
    SplatScene *scene;
    int threads;
};

PyObject *SplatCloud_new(PyTypeObject *type, PyObject *args, PyObject *kwargs) {
    static const char *kwlist[] = {"centres", "normals", "radii", "colours", "closed", "threads", "alphas", "attributes", nullptr};
    PyObject *oc, *on, *orad, *ocol = Py_None, *oclosed = Py_None, *oalpha = Py_None, *oattr = Py_None;
    int threads = 0;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOO|OOiOO", const_cast<char **>(kwlist), &oc, &on, &orad,
                                     &ocol, &oclosed, &threads, &oalpha, &oattr))
        return nullptr;
    if (!check_threads(threads)) return nullptr;
    View c, n, r, col, closed, alpha, attr;
    Py_ssize_t s3[2] = {-1, 3};
    if (!get_array(oc, "centres", 'f', 2, s3, false, c)) return nullptr;
    const Py_ssize_t count = c.dim(0);
    Py_ssize_t sn[2] = {count, 3}, s1[1] = {count};
    if (!get_array(on, "normals", 'f', 2, sn, false, n)) return nullptr;
    if (!get_array(orad, "radii", 'f', 1, s1, false, r)) return nullptr;
    if (ocol != Py_None && !get_array(ocol, "colours", 'f', 2, sn, false, col)) return nullptr;
    if (oclosed != Py_None && !get_array(oclosed, "closed", 'B', 1, s1, false, closed)) return nullptr;
    if (oalpha != Py_None && !get_array(oalpha, "alphas", 'f', 1, s1, false, alpha)) return nullptr;
    // The point attributes the node programs read (SplatScene::set_attributes): n x k.
    Py_ssize_t sa[2] = {count, -1};
    if (oattr != Py_None && !get_array(oattr, "attributes", 'f', 2, sa, false, attr)) return nullptr;

    SplatScene *scene = nullptr;
    if (!without_gil([&] {
            scene = new SplatScene(c.data<float>(), n.data<float>(), r.data<float>(),
                                   col.held ? col.data<float>() : nullptr,
                                   closed.held ? closed.data<uint8_t>() : nullptr, size_t(count), threads,
                                   alpha.held ? alpha.data<float>() : nullptr);
            if (attr.held && attr.dim(1) > 0) scene->set_attributes(attr.data<float>(), int(attr.dim(1)));
        })) {
        delete scene;  // null, or built before its attributes were refused
        return nullptr;
    }
    auto alloc = reinterpret_cast<allocfunc>(PyType_GetSlot(type, Py_tp_alloc));
    PyObject *self = alloc(type, 0);
    if (!self) {
        delete scene;
        return nullptr;
    }
    reinterpret_cast<SplatCloudObject *>(self)->scene = scene;
    reinterpret_cast<SplatCloudObject *>(self)->threads = threads;
    return self;
}

void SplatCloud_dealloc(PyObject *self) {
    delete reinterpret_cast<SplatCloudObject *>(self)->scene;
    PyTypeObject *type = Py_TYPE(self);
    auto free_fn = reinterpret_cast<freefunc>(PyType_GetSlot(type, Py_tp_free));
    free_fn(self);
    Py_DECREF(type);
}

const SplatScene &scene_of(PyObject *self) { return *reinterpret_cast<SplatCloudObject *>(self)->scene; }

int threads_arg(PyObject *self, int requested) {
    return requested > 0 ? requested : reinterpret_cast<SplatCloudObject *>(self)->threads;
}

// Calls per_ray(i) for every ray of a batch of `count`, in chunks of `chunk` rays spread over
// the threads, without the GIL. Returns false with a Python exception set on failure.
template <class PerRay>
bool for_each_ray(PyObject *self, int threads, Py_ssize_t count, size_t chunk, PerRay &&per_ray) {
    const size_t chunks = (size_t(count) + chunk - 1) / chunk;
    return without_gil([&] {
        parallel_until_exit(chunks, threads_arg(self, threads), [&](size_t c) {
            const size_t end = std::min(size_t(count), (c + 1) * chunk);
            for (size_t i = c * chunk; i < end; ++i) per_ray(i);
        });
    });
}

// Consecutive rays in groups of kPacketRays (a packet, traced together when coherent:
// packet.h), or one by one when `packets` is false: per_group(first, n) on the threads.
template <class PerGroup>
bool for_each_group(PyObject *self, int threads, Py_ssize_t count, size_t chunk, bool packets, PerGroup &&per_group) {
    const size_t group = packets ? size_t(kPacketRays) : 1;
    return for_each_ray(self, threads, (count + Py_ssize_t(group) - 1) / Py_ssize_t(group), chunk / group,
                        [&](size_t g) { per_group(g * group, std::min(group, size_t(count) - g * group)); });
}

PyObject *SplatCloud_trace(PyObject *self, PyObject *args, PyObject *kwargs) {
    static const char *kwlist[] = {"origins", "directions", "tmin", "tmax", "out_t", "out_id",
                                   "out_front", "out_normal", "threads", "brute_force", "out_stats", "packets",
                                   nullptr};
    PyObject *oo, *od, *ot, *oid, *ofr, *onrm = Py_None, *ostats = Py_None;
    double tmin, tmax;
    int threads = 0, brute = 0, packets = 1;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOddOOO|OipOp", const_cast<char **>(kwlist), &oo, &od, &tmin,
                                     &tmax, &ot, &oid, &ofr, &onrm, &threads, &brute, &ostats, &packets))
        return nullptr;
    View stats_view;
    Py_ssize_t s2[1] = {2};
    if (ostats != Py_None && !get_array(ostats, "out_stats", 'q', 1, s2, true, stats_view)) return nullptr;
    if (!check_batch_args(tmin, tmax, threads)) return nullptr;
    View o, d, t, id, fr, nrm;
    Py_ssize_t s3[2] = {-1, 3};
    if (!get_array(oo, "origins", 'f', 2, s3, false, o)) return nullptr;
    const Py_ssize_t count = o.dim(0);
    Py_ssize_t sn[2] = {count, 3}, s1[1] = {count};
    if (!get_array(od, "directions", 'f', 2, sn, false, d)) return nullptr;
    if (!get_array(ot, "out_t", 'f', 1, s1, true, t)) return nullptr;
    if (!get_array(oid, "out_id", 'i', 1, s1, true, id)) return nullptr;
    if (!get_array(ofr, "out_front", 'B', 1, s1, true, fr)) return nullptr;
    if (onrm != Py_None && !get_array(onrm, "out_normal", 'f', 2, sn, true, nrm)) return nullptr;
    if (!check_separate({{t, "out_t"}, {id, "out_id"}, {fr, "out_front"}, {nrm, "out_normal"}, {stats_view, "out_stats"}},
                        {{o, "origins"}, {d, "directions"}}))
        return nullptr;

    const SplatScene &scene = scene_of(self);
    const float *po = o.data<float>(), *pd = d.data<float>();
    if (!check_rays(po, pd, count)) return nullptr;
    float *pt = t.data<float>(), *pn = nrm.held ? nrm.data<float>() : nullptr;
    int32_t *pid = id.data<int32_t>();
    uint8_t *pfr = fr.data<uint8_t>();
    // Rays per task: small enough to balance the threads, large enough to amortise a task.
    constexpr size_t kChunk = 1024;
    std::atomic<uint64_t> total_nodes{0}, total_discs{0};
    if (!for_each_group(self, threads, count, kChunk, packets && !brute, [&](size_t first, size_t n) {
            Ray rays[kPacketRays];
            Hit hits[kPacketRays];
            for (size_t k = 0; k < n; ++k) rays[k] = make_ray(po, pd, first + k, tmin, tmax);
            TraversalStats st;
            if (brute) hits[0] = scene.intersect_brute_force(rays[0]);
            else if (n == 1) hits[0] = scene.intersect(rays[0], &st);
            else scene.intersect_packet(rays, int(n), hits, &st);
            if (stats_view.held) total_nodes += st.nodes, total_discs += st.discs;
            for (size_t k = 0; k < n; ++k) {
                const size_t i = first + k;
                const Hit &h = hits[k];
                pt[i] = h.t, pid[i] = h.id, pfr[i] = h.front ? 1 : 0;
                if (pn) {
                    const Vec3 nv = h.valid() ? scene.normal(h.id) : Vec3();
                    pn[3 * i] = nv.x, pn[3 * i + 1] = nv.y, pn[3 * i + 2] = nv.z;
                }
            }
        }))
        return nullptr;
    if (stats_view.held) {
        int64_t *out = stats_view.data<int64_t>();
        out[0] = int64_t(total_nodes.load()), out[1] = int64_t(total_discs.load());
    }
    Py_RETURN_NONE;
}

PyObject *SplatCloud_trace_surface(PyObject *self, PyObject *args, PyObject *kwargs) {
    static const char *kwlist[] = {"origins", "directions", "tmin", "tmax", "method", "out_t", "out_id",
                                   "out_front", "out_normal", "out_colour", "out_members", "inside", "exclude",
                                   "threads", "brute_force", "packets", nullptr};
    PyObject *oo, *od, *ometh, *ot, *oid, *ofr, *onrm, *ocol, *omem = Py_None, *oin = Py_None, *oex = Py_None;
    double tmin, tmax;
    int threads = 0, brute = 0, packets = 1;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOddOOOOOO|OOOipp", const_cast<char **>(kwlist), &oo, &od, &tmin,
                                     &tmax, &ometh, &ot, &oid, &ofr, &onrm, &ocol, &omem, &oin, &oex, &threads, &brute,
                                     &packets))
        return nullptr;
    if (!check_batch_args(tmin, tmax, threads)) return nullptr;
    Method method;
    if (ometh == Py_None) return PyErr_Format(PyExc_TypeError, "method is required");
    if (!parse_method(ometh, method)) return nullptr;
    View o, d, t, id, fr, nrm, col, mem, in, ex;
    Py_ssize_t s3[2] = {-1, 3};
    if (!get_array(oo, "origins", 'f', 2, s3, false, o)) return nullptr;
    const Py_ssize_t count = o.dim(0);
    Py_ssize_t sn[2] = {count, 3}, s1[1] = {count}, sm[2] = {count, kMaxLayerHits}, sx[2] = {count, -1};
    if (!get_array(od, "directions", 'f', 2, sn, false, d)) return nullptr;
    if (!get_array(ot, "out_t", 'f', 1, s1, true, t)) return nullptr;
    if (!get_array(oid, "out_id", 'i', 1, s1, true, id)) return nullptr;
    if (!get_array(ofr, "out_front", 'B', 1, s1, true, fr)) return nullptr;
    if (!get_array(onrm, "out_normal", 'f', 2, sn, true, nrm)) return nullptr;
    if (!get_array(ocol, "out_colour", 'f', 2, sn, true, col)) return nullptr;
    if (omem != Py_None && !get_array(omem, "out_members", 'i', 2, sm, true, mem)) return nullptr;
    if (oin != Py_None && !get_array(oin, "inside", 'B', 1, s1, false, in)) return nullptr;
    if (oex != Py_None && !get_array(oex, "exclude", 'i', 2, sx, false, ex)) return nullptr;
    if (!check_separate({{t, "out_t"}, {id, "out_id"}, {fr, "out_front"}, {nrm, "out_normal"}, {col, "out_colour"},
                         {mem, "out_members"}},
                        {{o, "origins"}, {d, "directions"}, {in, "inside"}, {ex, "exclude"}}))
        return nullptr;
    const int n_ex = ex.held ? int(ex.dim(1)) : 0;
    if (ex.held) {
        const int32_t *e = ex.data<int32_t>();
        const int64_t n_splats = int64_t(scene_of(self).size());
        for (Py_ssize_t k = 0; k < count * n_ex; ++k)
            if (e[k] < -1 || e[k] >= n_splats)
                return PyErr_Format(PyExc_ValueError, "exclude[%zd, %zd] = %d is not a splat id (0..%lld) or -1",
                                    k / n_ex, k % n_ex, int(e[k]), (long long)(n_splats - 1));
    }

    const float *po = o.data<float>(), *pd = d.data<float>();
    if (!check_rays(po, pd, count)) return nullptr;
    const SplatScene &scene = scene_of(self);
    float *pt = t.data<float>(), *pn = nrm.data<float>(), *pc = col.data<float>();
    int32_t *pid = id.data<int32_t>(), *pm = mem.held ? mem.data<int32_t>() : nullptr;
    const int32_t *pex = ex.held ? ex.data<int32_t>() : nullptr;
    const uint8_t *pin = in.held ? in.data<uint8_t>() : nullptr;
    uint8_t *pfr = fr.data<uint8_t>();
    // Fewer rays per task than trace(): a layer query costs more and varies more per ray.
    constexpr size_t kChunk = 512;
    if (!for_each_group(self, threads, count, kChunk, packets && !brute, [&](size_t first, size_t n) {
            Ray rays[kPacketRays];
            bool inside[kPacketRays];
            const int32_t *excl[kPacketRays];
            // Storage only: find_surface(s) build every hit (a default-built array was built twice).
            alignas(SurfaceHit) unsigned char storage[kPacketRays * sizeof(SurfaceHit)];
            SurfaceHit *hits = reinterpret_cast<SurfaceHit *>(storage);
            for (size_t k = 0; k < n; ++k) {
                const size_t i = first + k;
                rays[k] = make_ray(po, pd, i, tmin, tmax);
                inside[k] = pin && pin[i];
                excl[k] = pex ? pex + i * n_ex : nullptr;
            }
            if (n == 1) new (&hits[0]) SurfaceHit(find_surface(scene, rays[0], method, inside[0], excl[0], n_ex, brute));
            else find_surfaces(scene, rays, int(n), method, inside, excl, n_ex, hits);
            for (size_t k = 0; k < n; ++k) {
                const size_t i = first + k;
                const SurfaceHit &h = hits[k];
                pt[i] = h.t, pid[i] = h.id, pfr[i] = h.front ? 1 : 0;
                for (int c = 0; c < 3; ++c) pn[3 * i + c] = h.normal[c], pc[3 * i + c] = h.colour[c];
                if (pm) {
                    int32_t *row = pm + i * kMaxLayerHits;
                    for (int c = 0; c < kMaxLayerHits; ++c) row[c] = c < h.n_members ? h.members[c] : -1;
                }
            }
        }))
        return nullptr;
    Py_RETURN_NONE;
}

PyObject *SplatCloud_render(PyObject *self, PyObject *args, PyObject *kwargs) {
    static const char *kwlist[] = {"local_from_camera", "frustum", "orthographic", "width", "height", "window",
                                   "background", "out_rgba", "out_depth", "out_normal", "threads",
                                   "progress", "tile_size", "method", "packets", nullptr};
    PyObject *om, *ofrustum, *orgba, *odepth = Py_None, *onormal = Py_None, *progress = Py_None,
             *ometh = Py_None;
    int orthographic, width, height, x0, y0, w, h, threads = 0, tile_size = kDefaultTileSize, packets = 1;
    float bg[4];
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOpii(iiii)(ffff)O|OOiOiOp", const_cast<char **>(kwlist), &om,
                                     &ofrustum, &orthographic, &width, &height, &x0, &y0, &w, &h, &bg[0], &bg[1],
                                     &bg[2], &bg[3], &orgba, &odepth, &onormal, &threads, &progress, &tile_size, &ometh,
                                     &packets))
        return nullptr;
    if (!check_render_args(width, height, x0, y0, w, h, tile_size, threads, progress)) return nullptr;
    Camera cam;
    CameraViews cam_views;
    if (!parse_camera(om, ofrustum, orthographic, cam, cam_views)) return nullptr;
    View rgba, depth, normal;
    Py_ssize_t sr[3] = {h, w, 4}, sd[2] = {h, w}, sn[3] = {h, w, 3};
    if (!get_array(orgba, "out_rgba", 'f', 3, sr, true, rgba)) return nullptr;
    if (odepth != Py_None && !get_array(odepth, "out_depth", 'f', 2, sd, true, depth)) return nullptr;
    if (onormal != Py_None && !get_array(onormal, "out_normal", 'f', 3, sn, true, normal)) return nullptr;
    if (!check_separate({{rgba, "out_rgba"}, {depth, "out_depth"}, {normal, "out_normal"}},
                        {{cam_views.m, "local_from_camera"}, {cam_views.frustum, "frustum"}}))
        return nullptr;
    for (float v : bg)
        if (!std::isfinite(v)) return PyErr_Format(PyExc_ValueError, "background must be finite");

    Film film;
    film.width = width, film.height = height, film.x0 = x0, film.y0 = y0, film.w = w, film.h = h;
    film.combined = rgba.data<float>();
    film.depth = depth.held ? depth.data<float>() : nullptr;
    film.normal = normal.held ? normal.data<float>() : nullptr;
    RenderSettings settings;
    if (!parse_method(ometh, settings.method)) return nullptr;
    std::copy(bg, bg + 4, settings.background);
    settings.tile_size = tile_size;
    settings.packets = packets != 0;
    Renderer renderer(scene_of(self), cam, film, settings);
    const size_t tiles = renderer.tile_count();

    const int completed = run_tiles(tiles, threads_arg(self, threads), progress,
                                    [&](size_t t, const std::atomic<bool> &) { renderer.render_tile(t); });
    if (completed < 0) return nullptr;
    return PyBool_FromLong(completed);
}

PyObject *SplatCloud_len(PyObject *self, void *) { return PyLong_FromSize_t(scene_of(self).size()); }

PyObject *SplatCloud_bounds(PyObject *self, void *) {
    const AABB &b = scene_of(self).bounds();
    if (b.empty()) Py_RETURN_NONE;
    return Py_BuildValue("((ddd)(ddd))", b.lo.x, b.lo.y, b.lo.z, b.hi.x, b.hi.y, b.hi.z);
}

PyObject *SplatCloud_bvh_stats(PyObject *self, PyObject *) {
    const BVH &bvh = scene_of(self).bvh();
    Py_ssize_t leaves = 0, max_leaf = 0;
    for (const WideNode &n : bvh.nodes)
        for (int k = 0; k < 4; ++k)
            if (n.count[k]) ++leaves, max_leaf = std::max<Py_ssize_t>(max_leaf, n.count[k]);
    return Py_BuildValue("{s:n,s:n,s:i,s:n,s:n}", "nodes", Py_ssize_t(bvh.nodes.size()), "leaves", leaves, "depth",
                         bvh.depth(), "max_leaf_size", max_leaf, "bytes", Py_ssize_t(scene_of(self).memory_bytes()));
}

PyMethodDef SplatCloud_methods[] = {
    {"trace", reinterpret_cast<PyCFunction>(reinterpret_cast<void (*)()>(SplatCloud_trace)), METH_VARARGS | METH_KEYWORDS,
     "trace(origins, directions, tmin, tmax, out_t, out_id, out_front, out_normal=None, threads=0, "
     "brute_force=False)\n--\n\nNearest hit per ray, written into the out_ arrays (see render/splats.py)."},
    {"render", reinterpret_cast<PyCFunction>(reinterpret_cast<void (*)()>(SplatCloud_render)), METH_VARARGS | METH_KEYWORDS,
     "render(local_from_camera, frustum, orthographic, width, height, window, background, out_rgba, "
     "out_depth=None, out_normal=None, threads=0, progress=None, tile_size=32, method=None, packets=True)\n--\n\n"
     "Renders a window of an image; returns False when progress() asked to stop."},
    {"trace_surface", reinterpret_cast<PyCFunction>(reinterpret_cast<void (*)()>(SplatCloud_trace_surface)),
     METH_VARARGS | METH_KEYWORDS,
     "trace_surface(origins, directions, tmin, tmax, method, out_t, out_id, out_front, out_normal, out_colour, "
     "out_members=None, inside=None, exclude=None, threads=0, brute_force=False, packets=True)\n--\n\n"
     "The surface each ray sees under the visibility method (a render.method.Method, read by field name)."},
    {"bvh_stats", SplatCloud_bvh_stats, METH_NOARGS, "Node count, leaf count, depth and largest leaf of the BVH; bytes the scene keeps."},
    {nullptr, nullptr, 0, nullptr},
};

PyGetSetDef SplatCloud_getset[] = {
    {"size", SplatCloud_len, nullptr, "Number of splats.", nullptr},
    {"bounds", SplatCloud_bounds, nullptr, "((xmin, ymin, zmin), (xmax, ymax, zmax)) of all discs, or None.", nullptr},
    {nullptr, nullptr, nullptr, nullptr, nullptr},
};

PyType_Slot SplatCloud_slots[] = {
    {Py_tp_new, reinterpret_cast<void *>(SplatCloud_new)},
    {Py_tp_dealloc, reinterpret_cast<void *>(SplatCloud_dealloc)},
    {Py_tp_methods, SplatCloud_methods},
    {Py_tp_getset, SplatCloud_getset},
    {Py_tp_doc, const_cast<char *>("SplatCloud(centres, normals, radii, colours=None, closed=None, threads=0, alphas=None, attributes=None): splats and their BVH.")},
    {0, nullptr},
};

PyType_Spec SplatCloud_spec = {"splat_tracer._core.SplatCloud", sizeof(SplatCloudObject), 0, Py_TPFLAGS_DEFAULT, SplatCloud_slots};

PyObject *hardware_threads(PyObject *, PyObject *) { return PyLong_FromLong(resolve_threads(0)); }

// Which code path the box and disc tests were compiled for (simd.h): what the benchmarks print.
PyObject *simd_path(PyObject *, PyObject *) {
#ifdef SPLAT_SSE2
    return PyUnicode_FromString(simd_avx2() ? "SSE2, packet kernels in AVX2" : "SSE2");
#else
    return PyUnicode_FromString("plain floats");
#endif
}

PyObject *use_avx2_seam(PyObject *, PyObject *arg) {
    const int on = PyObject_IsTrue(arg);
    if (on < 0) return nullptr;
    return PyBool_FromLong(use_avx2(on != 0));
}

PyObject *set_thread_budget(PyObject *, PyObject *arg) {
    const long budget = PyLong_AsLong(arg);
    if (budget == -1 && PyErr_Occurred()) return nullptr;
    if (budget < -1 || budget > INT32_MAX) return PyErr_Format(PyExc_ValueError, "budget must be >= -1");
    thread_budget() = int(budget);
    Py_RETURN_NONE;
}

// Test seam: how long the exit hook waits for native calls in flight (ExitState::wait);
// returns the previous wait. 0 makes any call still running at exit park its thread.
PyObject *set_exit_wait(PyObject *, PyObject *arg) {
    const double seconds = PyFloat_AsDouble(arg);
    if (seconds == -1.0 && PyErr_Occurred()) return nullptr;
    if (!(seconds >= 0.0 && seconds <= 3600.0)) return PyErr_Format(PyExc_ValueError, "wait must be in 0..3600 s");
    ExitState &s = exit_state();
    std::lock_guard<std::mutex> lock(s.mutex);
    const double previous = double(s.wait.count()) / 1000.0;
    s.wait = std::chrono::milliseconds(int64_t(seconds * 1000.0));
    return PyFloat_FromDouble(previous);
}

// The camera's pixel-centre rays (Camera::ray), row-major from the top row, into out_origins
// and out_directions (float32, width*height x 3): render.camera.Camera.rays. A pixel a
// panorama does not see gets a zero direction.
PyObject *camera_rays(PyObject *, PyObject *args, PyObject *kwargs) {
    static const char *kwlist[] = {"local_from_camera", "frustum", "orthographic", "width", "height", "out_origins",
                                   "out_directions", nullptr};
    PyObject *om, *ofrustum, *oo, *od;
    int orthographic, width, height;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOpiiOO", const_cast<char **>(kwlist), &om, &ofrustum,
                                     &orthographic, &width, &height, &oo, &od))
        return nullptr;
    if (width < 1 || height < 1 || int64_t(width) * height > (int64_t(1) << 31))
        return PyErr_Format(PyExc_ValueError, "width and height must be positive (at most 2^31 pixels)");
    Camera cam;
    CameraViews cam_views;
    if (!parse_camera(om, ofrustum, orthographic, cam, cam_views)) return nullptr;
    View origins, directions;
    Py_ssize_t shape[2] = {Py_ssize_t(width) * height, 3};
    if (!get_array(oo, "out_origins", 'f', 2, shape, true, origins) ||
        !get_array(od, "out_directions", 'f', 2, shape, true, directions) ||
        !check_separate({{origins, "out_origins"}, {directions, "out_directions"}},
                        {{cam_views.m, "local_from_camera"}, {cam_views.frustum, "frustum"}}))
        return nullptr;
    float *o = origins.data<float>(), *d = directions.data<float>();
    for (int i = 0; i < height; ++i)
        for (int j = 0; j < width; ++j) {
            const Ray ray = cam.ray(j + 0.5, i + 0.5, width, height);
            const size_t p = 3 * (size_t(i) * size_t(width) + size_t(j));
            const bool none = Camera::is_none(ray);
            o[p] = ray.o.x, o[p + 1] = ray.o.y, o[p + 2] = ray.o.z;
            d[p] = none ? 0.f : ray.d.x, d[p + 1] = none ? 0.f : ray.d.y, d[p + 2] = none ? 0.f : ray.d.z;
        }
    Py_RETURN_NONE;
}

// Test seam of the environment light (shade/environment.h): the map of `image` (h, w, 3
// float32) draws a direction from each row of `uniforms` (n, 2) into out_directions (n, 3)
// with its density in out_pdf (n); for each row of `directions` (m, 3, unit), the density
// sample() has there into out_pdf_at (m) and the bilinear radiance into out_radiance (m, 3).
PyObject *environment_map(PyObject *, PyObject *args) {
    PyObject *oimage, *ou, *od, *oout_d, *oout_pdf, *oout_pdf_at, *oout_rad;
    if (!PyArg_ParseTuple(args, "OOOOOOO", &oimage, &ou, &od, &oout_d, &oout_pdf, &oout_pdf_at, &oout_rad))
        return nullptr;
    View image, u, d, out_d, out_pdf, out_pdf_at, out_rad;
    const Py_ssize_t s_image[3] = {-1, -1, 3}, s_u[2] = {-1, 2}, s_d[2] = {-1, 3};
    if (!get_array(oimage, "image", 'f', 3, s_image, false, image) || !get_array(ou, "uniforms", 'f', 2, s_u, false, u) ||
        !get_array(od, "directions", 'f', 2, s_d, false, d))
        return nullptr;
    const Py_ssize_t n = u.buf.shape[0], m = d.buf.shape[0], h = image.buf.shape[0], w = image.buf.shape[1];
    const Py_ssize_t s_nd[2] = {n, 3}, s_n[1] = {n}, s_m[1] = {m}, s_md[2] = {m, 3};
    if (!get_array(oout_d, "out_directions", 'f', 2, s_nd, true, out_d) ||
        !get_array(oout_pdf, "out_pdf", 'f', 1, s_n, true, out_pdf) ||
        !get_array(oout_pdf_at, "out_pdf_at", 'f', 1, s_m, true, out_pdf_at) ||
        !get_array(oout_rad, "out_radiance", 'f', 2, s_md, true, out_rad))
        return nullptr;
    if (w < 2 || h < 2 || w > 65536 || h > 32768)
        return PyErr_Format(PyExc_ValueError, "image must be 2..65536 wide and 2..32768 high");
    const float *px = image.data<float>();
    for (Py_ssize_t k = 0; k < w * h * 3; ++k)
        if (!(std::isfinite(px[k]) && px[k] >= 0.f)) return PyErr_Format(PyExc_ValueError, "image must be finite, >= 0");
    const float *pu = u.data<float>();
    for (Py_ssize_t k = 0; k < n * 2; ++k)
        if (!(pu[k] >= 0.f && pu[k] < 1.f)) return PyErr_Format(PyExc_ValueError, "uniforms must be in [0, 1)");
    std::string message;
    if (PyObject *type = run_native(
            [&] {
                const EnvironmentMap map(px, int(w), int(h));
                float *o = out_d.data<float>(), *p = out_pdf.data<float>();
                for (Py_ssize_t k = 0; k < n; ++k) {
                    const EnvironmentSample s = map.sample(pu[2 * k], pu[2 * k + 1]);
                    o[3 * k] = s.wi.x, o[3 * k + 1] = s.wi.y, o[3 * k + 2] = s.wi.z;
                    p[k] = s.valid ? s.pdf : 0.f;
                }
                const float *dd = d.data<float>();
                float *pa = out_pdf_at.data<float>(), *r = out_rad.data<float>();
                for (Py_ssize_t k = 0; k < m; ++k) {
                    const Vec3 dir(dd[3 * k], dd[3 * k + 1], dd[3 * k + 2]);
                    pa[k] = map.pdf(dir);
                    const Vec3 c = map.lookup(dir);
                    r[3 * k] = c.x, r[3 * k + 1] = c.y, r[3 * k + 2] = c.z;
                }
            },
            message))
        return PyErr_SetString(type, message.c_str()), nullptr;
    Py_RETURN_NONE;
}

PyMethodDef module_methods[] = {
    {"_environment_map", environment_map, METH_VARARGS,
     "Test seam: _environment_map(image, uniforms, directions, out_directions, out_pdf, out_pdf_at, out_radiance): "
     "the environment light's sampling and lookup (shade/environment.h)."},
    {"camera_rays", reinterpret_cast<PyCFunction>(reinterpret_cast<void (*)()>(camera_rays)),
     METH_VARARGS | METH_KEYWORDS,
     "camera_rays(local_from_camera, frustum, orthographic, width, height, out_origins, out_directions): the "
     "camera's pixel-centre rays (render.camera.Camera.rays)."},
    {"hardware_threads", hardware_threads, METH_NOARGS, "Number of threads used when threads=0."},
    {"simd_path", simd_path, METH_NOARGS,
     "The instruction sets the BVH's box and disc tests use: 'SSE2', 'SSE2, packet kernels in AVX2' (chosen at "
     "run time) or 'plain floats'."},
    {"_use_avx2", use_avx2_seam, METH_O,
     "Test seam: whether the packet kernels may use AVX2 (only where the CPU has it); returns the previous "
     "setting."},
    {"_set_thread_budget", set_thread_budget, METH_O,
     "Test seam: the core may start this many more threads, then thread creation fails as if the system "
     "refused it (-1: no limit)."},
    {"_set_exit_wait", set_exit_wait, METH_O,
     "Test seam: seconds the exit hook waits for native calls in flight; returns the previous wait."},
    {nullptr, nullptr, 0, nullptr},
};

PyMethodDef at_exit_def = {"_at_exit", at_exit, METH_NOARGS,
                           "Stops native work before Python finalizes (registered with atexit on import)."};

// Registers at_exit with the atexit module (see ExitState).
int register_at_exit(PyObject *module) {
    PyObject *hook = PyCFunction_NewEx(&at_exit_def, nullptr, nullptr);
    if (!hook) return -1;
    PyObject *atexit = PyImport_ImportModule("atexit");
    PyObject *res = atexit ? PyObject_CallMethod(atexit, "register", "O", hook) : nullptr;
    Py_XDECREF(atexit);
    Py_XDECREF(res);
    if (!res || PyModule_AddObject(module, "_at_exit", hook) < 0) {
        Py_DECREF(hook);
        return -1;
    }
    return 0;
}

int module_exec(PyObject *module) {
    if (register_at_exit(module) < 0) return -1;
    PyObject *type = PyType_FromSpec(&SplatCloud_spec);
    if (!type) return -1;
    if (PyModule_AddObject(module, "SplatCloud", type) < 0) {
        Py_DECREF(type);
        return -1;
    }
    if (PyModule_AddObject(module, "PARALLEL_COSINE", PyFloat_FromDouble(kParallelCosine)) < 0) return -1;
    if (PyModule_AddIntConstant(module, "MAX_LAYER_HITS", kMaxLayerHits) < 0) return -1;
    if (PyModule_AddObject(module, "MAX_COORDINATE", PyFloat_FromDouble(kMaxCoordinate)) < 0) return -1;
    if (PyModule_AddIntConstant(module, "PACKET_RAYS", kPacketRays) < 0) return -1;
    if (add_neighbour_types(module) < 0) return -1;
    if (add_graph_functions(module) < 0) return -1;
    if (add_number_functions(module) < 0) return -1;
    return add_render_types(module);
}

PyModuleDef_Slot module_slots[] = {{Py_mod_exec, reinterpret_cast<void *>(module_exec)}, {0, nullptr}};

PyModuleDef module_def = {PyModuleDef_HEAD_INIT, "_core", "Native core of splat_tracer (see render/ and pointcloud/).", 0,
                          module_methods, module_slots, nullptr, nullptr, nullptr};

}  // namespace

const SplatScene *splat::py::as_splat_scene(PyObject *obj) {
    // A Scene of any instance of this module: the same binary imported under two names (the
    // add-on as bl_ext.*.splat_tracer beside splat_tracer) runs module_exec twice, and
    // a type check against the newest Scene type refused a Scene made by the first. The
    // deallocator identifies the type and its layout whichever module made it.
    if (PyType_GetSlot(Py_TYPE(obj), Py_tp_dealloc) != reinterpret_cast<void *>(SplatCloud_dealloc)) return nullptr;
    return reinterpret_cast<SplatCloudObject *>(obj)->scene;
}

PyMODINIT_FUNC PyInit__core(void) { return PyModuleDef_Init(&module_def); }
